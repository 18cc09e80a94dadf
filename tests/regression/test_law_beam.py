"""Regression: the geogrid's cohesive beam links (000 eqs 7-12): tension, bending and torsion of a cantilever.
The scene, the reference and the tolerance are in driver.py (regenerate on purpose there)."""

import driver


def test_beam_matches_its_reference():
    driver.check("beam")
