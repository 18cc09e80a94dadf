"""Regression: the composed law: linear elastic part with normal and shear dashpots and rolling resistance.
The scene, the reference and the tolerance are in driver.py (regenerate on purpose there)."""

import driver


def test_linear_parts_matches_its_reference():
    driver.check("linear_parts")
