"""DEM elements that a continuum model drives: the servo-walled box element with its geogrid
(`box`), the strain-driven element of a periodic cell or of six walls that returns stress and
tangent (`periodic`, also `cpp_dem.DemElement`), the pool that keeps many of them on Dask
workers (`pool`) and the Dask plumbing the pool and the FEM side share (`cluster`)."""
