"""Regression: grain–geogrid contacts through the virtual sphere (000 eqs 13-19), node and cylinder, forces split to the nodes.
The scene, the reference and the tolerance are in driver.py (regenerate on purpose there)."""

import driver


def test_geogrid_contact_matches_its_reference():
    driver.check("geogrid_contact")
