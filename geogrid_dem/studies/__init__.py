"""The studies: what the cases run that composes the DEM library (``cpp_dem``) with the FEM
library (``femcoupling``). Each module owns its parameters; the case in ``geogrid_dem.cases``
parses options, calls it and writes the report.

- `prs_element`: the reinforced-soil element study (``Params``): its FEM model, one-way and
  two-way runs of its element region, hierarchical (one DEM element as the region's
  material, or one per cell on Dask workers) and the calibration of the FEM soil to the
  grains; ``prs-element-002`` builds on it.
- `footing_multiscale`: a footing on unreinforced, RE and PRS soil with a DEM element at every
  cell of the zone under it (``FootingParams``).
- `biaxial`, `footing_dem`: hierarchical FEM x DEM against direct DEM of the same grains, in a
  plane-strain biaxial test and under a small strip footing.
"""
