"""femcoupling: the continuum (FEM) side of the coupled DEM-FEM framework.

The package will hold:

- **geometry**: gmsh builds the outer domain, with physical groups tagging the
  regions and boundaries the coupling needs;
- **outer domain**: :func:`dolfinx.io.gmsh.model_to_mesh` turns the gmsh model
  into a dolfinx mesh, and dolfinx solves the continuum (elastic, later
  elastoplastic);
- **stress extraction**: the stress tensor averaged over the cells tagged as a
  DEM element's region;
- **FEM -> DEM handover**: those averages become the targets of the element's
  servo walls (and, in two-way mode, the element's secant stiffness goes back
  to the region's material until the handed-over stresses stop changing).

Modules: :mod:`femcoupling.geometry` (gmsh reinforced-soil body with tagged geogrid
layers and element regions), :mod:`femcoupling.materials` (elastic, Drucker-Prager and
its return mapping), :mod:`femcoupling.elastoplastic` (:class:`SoilModel`: K0 state,
prestress, footing load steps, Newton, extraction, XDMF), :mod:`femcoupling.handover`
(FEM -> DEM servo targets, NumPy only), :mod:`femcoupling.twoway` (one-way, two-way,
HDF5 history), and the first toolchain check :func:`solve_elastic_block`. Import the
submodules directly; this package namespace stays small and cheap. See docs/fem.md.

Units are SI (m, Pa); stresses are tension-positive.

``import femcoupling`` is cheap: it imports neither dolfinx nor gmsh (nor
petsc4py/mpi4py). They are loaded on first use, through
:mod:`femcoupling._dolfinx`, which imports ``dolfinx_solver`` before
``dolfinx`` as the wheel requires.
"""

from femcoupling.elastic import ElasticBlockResult, solve_elastic_block

__all__ = ["ElasticBlockResult", "solve_elastic_block"]
