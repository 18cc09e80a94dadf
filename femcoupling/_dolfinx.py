"""The one place that imports the FEM stack (dolfinx, petsc4py, mpi4py, ufl).

The ``dolfinx-solver-real`` wheel requires ``import dolfinx_solver`` *before*
``import dolfinx``: it orders ``mpi4py.MPI`` ahead of every compiled module and
refuses a foreign ``petsc4py``. Every module of :mod:`femcoupling` therefore
gets dolfinx, PETSc and MPI from :func:`load` and never imports them itself,
so the ordering is decided here once.

Nothing is imported when this module is imported; :func:`load` does the work
on its first call and caches the result, so ``import femcoupling`` stays cheap
and never pulls in dolfinx (DESIGN.md: "the FEM outer domain is built only
when a scene asks for FEM-derived boundaries").
"""

from __future__ import annotations

import functools
import types
import typing


class FemModules(typing.NamedTuple):
    """The FEM stack's modules, imported in the order the wheel requires."""

    dolfinx: types.ModuleType
    """``dolfinx`` (with ``fem``, ``fem.petsc``, ``io.gmsh``, ``mesh`` loaded)."""
    fem: types.ModuleType
    """``dolfinx.fem``."""
    fem_petsc: types.ModuleType
    """``dolfinx.fem.petsc`` (``LinearProblem``)."""
    io_gmsh: types.ModuleType
    """``dolfinx.io.gmsh`` (``model_to_mesh``)."""
    mesh: types.ModuleType
    """``dolfinx.mesh``."""
    ufl: types.ModuleType
    """``ufl``, the form language."""
    PETSc: types.ModuleType
    """``petsc4py.PETSc`` (the wheel's vendored build)."""
    MPI: types.ModuleType
    """``mpi4py.MPI`` as loaded first by ``dolfinx_solver``."""


@functools.cache
def load() -> FemModules:
    """Import the FEM stack in the required order and return its modules.

    Cached: the import cost is paid once per process.

    Returns:
        A :class:`FemModules` holding dolfinx and its companions.
    """
    import dolfinx_solver  # noqa: F401 - must precede dolfinx: orders MPI, guards petsc4py

    import dolfinx
    import dolfinx.fem
    import dolfinx.fem.petsc
    import dolfinx.io.gmsh
    import dolfinx.mesh
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    return FemModules(
        dolfinx=dolfinx,
        fem=dolfinx.fem,
        fem_petsc=dolfinx.fem.petsc,
        io_gmsh=dolfinx.io.gmsh,
        mesh=dolfinx.mesh,
        ufl=ufl,
        PETSc=PETSc,
        MPI=MPI,
    )
