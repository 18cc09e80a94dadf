"""DEM elements that a continuum model drives: the servo-walled box element with its geogrid
(`box`), the strain-driven element of a periodic cell or of six walls that returns stress and
tangent (`periodic`, also `cpp_dem.DemElement`), the one interface both are driven through
(`interface`: strain-driven elements, and the two-way loop's region runners), the one pool
that keeps them on Dask workers (`pool`) and its Dask plumbing (`cluster`), and a linear
elastic element behind the same interface (`linear`), whose closed-form answers verify a
hierarchical FEM model apart from the grains."""
