"""The coupling of the FEM with DEM elements, in named parts.

- :mod:`femcoupling.coupling.handover`: the transfer, FEM stress -> the DEM element's wall
  targets and back (secant stiffness and tangent); plain NumPy;
- :mod:`femcoupling.coupling.twoway`: the coupled loops over element regions: one-way, and
  two-way with the element's stiffness back to its region; the HDF5 handover history;
- :mod:`femcoupling.coupling.relaxation`: the relaxation of coupled iterations (Aitken);
- :mod:`femcoupling.coupling.status`: how a coupled loop ended (one status from a fixed set,
  with its checks), the exit codes, ``NoiseWarning``;
- :mod:`femcoupling.coupling.records`: the rows a loop appends to its HDF5 records;
- :mod:`femcoupling.coupling.continuum_fit`: the continuum (Drucker-Prager) fitted to a DEM
  element along a region's stress path;
- :mod:`femcoupling.coupling.runner_pool`: the two-way loop's regions on the one Dask pool.

Import the modules directly; this namespace imports nothing.
"""
