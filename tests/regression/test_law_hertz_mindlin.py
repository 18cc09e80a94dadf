"""Regression: the Hertz–Mindlin law (002 Table 1).
The scene, the reference and the tolerance are in driver.py (regenerate on purpose there)."""

import driver


def test_hertz_mindlin_matches_its_reference():
    driver.check("hertz_mindlin")
