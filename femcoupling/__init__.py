"""femcoupling: the continuum (FEM) side of the coupled DEM-FEM framework and its coupling
with DEM elements, in three subpackages:

- :mod:`femcoupling.materials`: what the FEM's points are made of. Continuum laws (elastic,
  anisotropic elastic, Drucker-Prager with its return mapping, the geogrid layer's band) and
  DEM elements as materials (one for a region, one per cell on the one Dask pool, the
  reinforced band); all behind one interface at quadrature points.
- :mod:`femcoupling.fem`: the FEM model in dolfinx, ``FemModel`` (``model``), one class for
  every body: the reinforced soil body in gmsh with tagged layers and element regions
  (``geometry``, ``gmsh_mesh``; the model's part ``soil_body`` and its roles
  ``soil_loading``, ``soil_regions``, ``soil_measures``), and the rectangle, box and cylinder
  of ``bodies`` with a DEM element at every quadrature point (``element_body``: the
  hierarchical mode); the solver side every model shares (``solver``), a
  load step's record and the one failure type of every model (``steps``), the quadrature
  spaces and the one Newton (``quadrature``), points under
  MPI (``mpi_points``), and the toolchain check (``elastic_block``).
- :mod:`femcoupling.coupling`: the coupling's named parts. The transfer (``handover``: FEM
  stress -> wall targets, stiffness back), the loops (``twoway``: one-way and two-way over
  element regions), ``relaxation``, ``status`` (how a loop ended), ``records``, the continuum fitted
  to the grains (``continuum_fit``) and ``runner_pool``.

Below them, :mod:`femcoupling._checks` (:class:`FemInputError`, the one error type, and the
input checks) and :mod:`femcoupling._dolfinx` (the one place that imports the FEM stack).

The package imports ``cpp_dem`` (its DEM elements, their pool, its measures) and never
``geogrid_dem``: the cases, and the studies and drivers that compose the two libraries, each
with its own ``Params``, are the application's (``geogrid_dem.studies``). Its modules import
one another at the top of the file and form no cycle (tests/test_layout.py). Import the
modules directly; this namespace holds only :class:`FemInputError`. See docs/fem.md and
docs/multiscale.md.

Units are SI (m, Pa); stresses are tension-positive.

``import femcoupling`` is cheap: it imports neither dolfinx nor gmsh (nor
petsc4py/mpi4py). They are loaded on first use, through
:mod:`femcoupling._dolfinx`, which imports ``dolfinx_solver`` before
``dolfinx`` as the wheel requires.
"""

from femcoupling._checks import FemInputError

__all__ = ["FemInputError"]
