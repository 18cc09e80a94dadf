"""gmsh on one MPI rank, its mesh distributed by dolfinx: the meshing step every model of
the package shares (the reinforced soil body, :mod:`femcoupling.fem.geometry`; the cylinder of
:mod:`femcoupling.fem.bodies`; the toolchain check,
:mod:`femcoupling.fem.elastic_block`).

gmsh is imported on first use, in the function that needs it; dolfinx through
:mod:`femcoupling._dolfinx`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from femcoupling import _dolfinx

__all__ = ["GMSH_RANK", "gmsh_mesh_on_root"]

#: The rank that builds the gmsh model; ``model_to_mesh`` distributes the mesh from it.
GMSH_RANK = 0


@contextlib.contextmanager
def _gmsh_model(name: str) -> Iterator[Any]:
    """Yield the ``gmsh`` module with a fresh current model called ``name``, quiet.

    Initialises gmsh if needed (and finalises it afterwards); if the caller
    already has a gmsh session, it is reused: the new model is removed and the
    caller's current model and the options touched here are restored on exit.
    """
    import gmsh

    owns_session = not gmsh.isInitialized()
    if owns_session:
        # interruptible=False: the default replaces Python's SIGINT handler for
        # the rest of the process. No config files: the mesh must not depend on
        # the user's gmshrc.
        gmsh.initialize(readConfigFiles=False, interruptible=False)
        # (gmsh sets SIGTERM, SIGHUP, SIGQUIT and SIGPIPE back to their defaults: a
        # SIGTERM then killed a run at once, its manifest left "running"; SIGHUP is left
        # at its default, as gmsh leaves it)
        _dolfinx.restore_python_signal_handlers(("SIGTERM", "SIGINT", "SIGQUIT", "SIGPIPE"))
    touched_options = ("General.Terminal", "Mesh.MeshSizeMin", "Mesh.MeshSizeMax")
    saved_options = {key: gmsh.option.getNumber(key) for key in touched_options}
    previous_model = None if owns_session else gmsh.model.getCurrent()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
        try:
            yield gmsh
        finally:
            gmsh.model.setCurrent(name)
            gmsh.model.remove()
    finally:
        if owns_session:
            gmsh.finalize()
        else:
            for key, value in saved_options.items():
                gmsh.option.setNumber(key, value)
            if previous_model is not None:
                with contextlib.suppress(Exception):
                    gmsh.model.setCurrent(previous_model)


def gmsh_mesh_on_root(comm: Any, name: str, build: Any, *, gdim: int, what: str) -> Any:
    """A dolfinx mesh built by gmsh on one rank and distributed: ``build(gmsh)`` makes the
    geometry, physical groups and mesh in a fresh gmsh model ``name`` (rank 0's name is used
    by every rank) on rank 0 of ``comm``; ``model_to_mesh`` distributes it. Returns its
    ``MeshData`` (mesh, cell_tags, facet_tags). An exception in ``build`` raises
    ``RuntimeError("gmsh failed to <what>: ...")`` on every rank, so that none hangs.
    Collective."""
    fx = _dolfinx.load()
    name = comm.bcast(name, root=GMSH_RANK)
    with contextlib.ExitStack() as stack:
        model, err = None, ""
        if comm.rank == GMSH_RANK:
            try:
                gmsh = stack.enter_context(_gmsh_model(name))
                build(gmsh)
                model = gmsh.model
            except Exception as exc:  # reported on every rank so that none hangs
                err = f"{type(exc).__name__}: {exc}"
        err = comm.bcast(err, root=GMSH_RANK)
        if err:
            raise RuntimeError(f"gmsh failed to {what}: {err}")
        return fx.io_gmsh.model_to_mesh(model, comm, GMSH_RANK, gdim=gdim)
