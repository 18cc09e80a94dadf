"""Regression: the linear Cundall–Strack law with Coulomb friction (000 eqs 1-6): the short kernel of the pair and wall passes.
The scene, the reference and the tolerance are in driver.py (regenerate on purpose there)."""

import driver


def test_linear_matches_its_reference():
    driver.check("linear")
