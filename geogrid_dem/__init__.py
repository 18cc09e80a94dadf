"""geogrid_dem: the application above the two libraries.

It holds the ``geogrid-dem`` command line (`cli`), run files, rows and sweeps (`runs`), the
calibration of a case's parameters against target values (`calibrate`), safe results folders
(`rundir`), the runnable studies (`cases`) and what they run that composes the two libraries
(`studies`, each with its own parameters). It is the only package that imports both
``cpp_dem`` (the DEM library) and ``femcoupling`` (the FEM library); the FEM library is imported
only by the cases and modes that need it, so a DEM-only run never loads dolfinx.
"""
