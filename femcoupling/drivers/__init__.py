"""Drivers: the FEM side of the cases that couple the continuum with DEM elements.

- `prs_element`: the reinforced-soil element case's FEM model, one-way and two-way runs of
  its element region, hierarchical (one DEM element as the region's material, or one per
  cell on Dask workers) and the calibration of the FEM soil to the grains.
"""
