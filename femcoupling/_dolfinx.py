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


#: PETSc's options at its initialisation, when :func:`load` is the first to import it: no
#: signal handlers of PETSc's own (see :func:`load`).
PETSC_INIT_ARGS = ["-no_signal_handler"]


def restore_python_signal_handlers(names=("SIGTERM", "SIGINT")) -> None:
    """Puts the dispositions Python has of the signals ``names`` back at the C level, where
    a library below replaced them (on the main thread only: Python runs handlers there
    alone, and only there may set them). Two did: a PETSc initialised before :func:`load`
    (by an ``import petsc4py.PETSc`` of a script's own) installs its own handler of SIGTERM,
    which aborts the process (status 241) instead of letting the run close its files and
    workers; and every ``gmsh.initialize()`` sets SIGTERM, SIGQUIT, SIGPIPE (and SIGHUP)
    back to their defaults, so that a SIGTERM killed the process at once (status -15, the
    manifest left ``running``, the Dask workers orphaned) and a broken pipe killed it
    instead of raising ``BrokenPipeError`` (``femcoupling.fem.elastic_block``)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for name in names:
        sig = getattr(signal, name)
        handler = signal.getsignal(sig)
        if handler is not None:  # (None: installed outside Python; left as it is)
            signal.signal(sig, handler)


@functools.cache
def load() -> FemModules:
    """Import the FEM stack in the required order and return its modules.

    Cached: the import cost is paid once per process.

    Returns:
        A :class:`FemModules` holding dolfinx and its companions.
    """
    import sys

    import dolfinx_solver  # noqa: F401 - must precede dolfinx: orders MPI, guards petsc4py

    if "petsc4py.PETSc" not in sys.modules:
        # PETSc's initialisation installs its own handler of SIGTERM, SIGHUP, SIGSEGV,
        # SIGFPE ... (PetscPushSignalHandler) over Python's: a SIGTERM then printed PETSc's
        # "Caught signal number 15" and aborted the process (exit 241), so a case's SIGTERM
        # handler (geogrid_dem.rundir.run_main: exit 143, manifest "interrupted", Dask
        # workers closed) never ran. -no_signal_handler leaves the signals to Python.
        import petsc4py

        petsc4py.init(PETSC_INIT_ARGS)
    import dolfinx
    import dolfinx.fem
    import dolfinx.fem.petsc
    import dolfinx.io.gmsh
    import dolfinx.mesh
    import ufl
    from mpi4py import MPI
    from petsc4py import PETSc

    restore_python_signal_handlers()
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
