"""The runnable studies of the source texts, shipped with the package: ``geogrid-dem run
NAME`` or ``python -m geogrid_dem.cases.NAME`` (each takes ``--smoke`` and ``--out DIR``).

- ``pullout_000``: geogrid pull-out of 000; ``pullout_001``: pull-out of 001 (and its study);
- ``triaxial``: the triaxial test of 001 ch. 6, with or without geogrid layers;
- ``prs_element``: 002's reinforced vs prestressed element from FEM stresses;
- ``deposition``: spheres deposited into a box under gravity.

``cases/*.py`` in the source tree are thin wrappers around these modules.
"""
