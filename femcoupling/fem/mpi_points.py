"""The hierarchical FEM under MPI: the mesh split over the ranks, the DEM elements on Dask
through rank 0 (issue 38, item 5; docs/coupling_mpi.md).

A :class:`femcoupling.fem.model.FemModel` (DEM elements at its points, on any body of
:mod:`femcoupling.fem.bodies`) given ``comm=MPI.COMM_WORLD`` builds its mesh on that
communicator: each rank assembles its part (PETSc; the LU is PETSc's own on the gathered
matrix, on every rank: ``femcoupling.fem.quadrature.PARALLEL_LU``). The elements stay where they are
without MPI: in one ``ElementPool`` whose Dask client lives on rank 0 (the other ranks pass
``elements=None``). Two pieces join the two:

- :class:`PointPartition`: which element each of a rank's quadrature points is. The serial
  model numbers its points (cell, point) in the serial mesh's order; a rank's point is given
  the number of the serial point at the same place (matched by coordinates, to 1e-9 of the
  domain's size). So element k is the same place, and the same seed, on any number of ranks.
  ``gather`` puts the ranks' per-point arrays together in element order on every rank.
- :class:`RootMaterial`: the elements' material (``ElementPoolMaterial``) held on rank 0 and
  seen by every rank. A trial's increments (all points, in element order) go to the pool
  from rank 0; the stresses, tangents and counters come back to every rank by broadcast, so
  every rank takes the same Newton decisions. An element that fails on rank 0 raises
  ``NewtonFailure`` on every rank.

The FEM's sums run in another order on more ranks (a node's contributions are added rank by
rank), so a run on 2 ranks is the serial run to rounding in the FEM, and to the DEM's
relaxation noise in the elements' stresses (tests/test_hierarchical_mpi.py measures both).
"""

from __future__ import annotations

import numpy as np

from femcoupling import _dolfinx
from femcoupling._checks import FemInputError
from femcoupling.fem.quadrature import NewtonFailure

__all__ = ["PointPartition", "RootMaterial", "bcast_from_root", "check_on_root", "on_root",
           "wait_for_root", "world"]

#: The longest sleep (s) between two polls of a rank that waits for rank 0 (wait_for_root).
IDLE_POLL_MAX_S = 2e-3


def world():
    """``MPI.COMM_WORLD``, imported in the order the FEM stack needs (``femcoupling._dolfinx``):
    one rank under plain ``python``, N under ``mpiexec -n N``."""
    return _dolfinx.load().MPI.COMM_WORLD


def wait_for_root(comm) -> None:
    """A barrier of ``comm`` at which the ranks that arrive first sleep between polls (from
    10 us, doubling, to IDLE_POLL_MAX_S) instead of spinning in MPI's progress loop.

    Rank 0 runs the elements (on Dask) while the other ranks wait, for seconds to minutes.
    MPICH's blocking calls spin while they wait: on one machine each waiting rank then
    holds a core that the Dask workers need. So every wait for rank 0's elements goes
    through here, and what rank 0 then sends arrives at once (``bcast_from_root``).
    None or one rank: returns at once."""
    import time

    if comm is None or comm.size == 1:
        return
    req = comm.Ibarrier()
    delay = 1e-5
    while not req.Test():
        time.sleep(delay)
        delay = min(2.0 * delay, IDLE_POLL_MAX_S)


def bcast_from_root(comm, obj):
    """``comm.bcast(obj, root=0)``, the ranks that wait for rank 0 idle (``wait_for_root``)
    until it is ready to send."""
    wait_for_root(comm)
    return comm.bcast(obj, root=0)


def on_root(comm, make):
    """``make()`` on rank 0 of ``comm`` (an mpi4py communicator, or None: serial), None on the
    other ranks: the element pool, whose Dask client lives on rank 0. Every rank returns
    when rank 0 has made it (the others idle meanwhile: ``wait_for_root``)."""
    out = make() if comm is None or comm.rank == 0 else None
    wait_for_root(comm)
    return out


def check_on_root(comm, pool) -> None:
    """Raises FemInputError unless ``pool`` is given on rank 0 of ``comm`` and None on the
    others."""
    if (pool is None) != (comm.rank != 0):
        raise FemInputError(f"pool: {'None' if pool is None else 'given'} on rank "
                            f"{comm.rank}; under MPI the element pool lives on rank 0 only "
                            "(pool=None on the others: femcoupling.fem.mpi_points.on_root)")


class PointPartition:
    """A rank's quadrature points as elements (module doc). ``local_xy`` (m, (n_local,
    gdim)): the rank's points in its (cell, point) order; ``serial_xy`` (m, (n, gdim)): the
    serial model's points, in element order; ``size`` (m): the domain's size, the matching's
    scale; ``what``: the points' name in the error (the soil body matches its owned cells'
    centres the same way). ``ids[k]`` is the element of the rank's point k; ``n`` the
    elements in all."""

    def __init__(self, comm, local_xy: np.ndarray, serial_xy: np.ndarray, size: float,
                 what: str = "quadrature points") -> None:
        from scipy.spatial import cKDTree

        self.comm = comm
        self.n = len(serial_xy)
        dist, ids = cKDTree(serial_xy).query(local_xy) if len(local_xy) else (
            np.zeros(0), np.zeros(0, dtype=np.int64))
        tol = 1e-9 * size
        far = float(np.max(dist, initial=0.0))
        every = np.sort(np.concatenate(comm.allgather(np.asarray(ids, np.int64))))
        bad = comm.allreduce(int(far > tol))  # (a sum: the ranks with a far point)
        if bad or not np.array_equal(every, np.arange(self.n)):
            raise RuntimeError(f"the ranks' {what} are not the serial model's: one "
                               f"{far:.3g} m from the nearest (allowed {tol:.3g} m), or "
                               f"{what} missing or matched twice")
        self.ids = np.asarray(ids, np.int64)
        self._all_ids = np.concatenate(comm.allgather(self.ids))

    def gather(self, local: np.ndarray) -> np.ndarray:
        """The ranks' per-point arrays (leading axis: the rank's points) as one array in
        element order, on every rank."""
        parts = self.comm.allgather(np.ascontiguousarray(local))
        out = np.empty((self.n,) + np.shape(local)[1:], dtype=np.result_type(*parts))
        out[self._all_ids] = np.concatenate(parts)
        return out

    def local(self, values: np.ndarray) -> np.ndarray:
        """This rank's rows of a per-element array."""
        return np.asarray(values)[self.ids]


class StartStress:
    """``stress_n`` and ``plastic`` of a material of DEM elements at points that keeps its
    committed stresses as ``stress_start`` (``ElementPoolMaterial``, ``RootMaterial``)."""

    stress_start: np.ndarray

    @property
    def stress_n(self) -> np.ndarray:
        """The committed stresses, (n, ncomp), Voigt, Pa."""
        return self.stress_start

    @property
    def plastic(self) -> np.ndarray:
        """0 at every point: an element's plasticity is in its contacts."""
        return np.zeros(len(self.stress_start))


class RootMaterial(StartStress):
    """A quadrature-point material (``ElementPoolMaterial``) held on rank 0, seen by every rank
    (module doc). ``material``: the material on rank 0, None elsewhere."""

    strain_measure = "gradient"
    #: what the hierarchical model reads of its material, copied to every rank after a call
    SHARED = ("stress", "stress_start", "tangent", "last_step", "bad_tangents", "secants_used",
              "increments", "scatter", "step_dem_s", "step_pool_s", "step_recovered")

    def __init__(self, comm, material) -> None:
        check_on_root(comm, material)
        self.comm, self._m = comm, material
        self._sync()

    def _sync(self) -> None:
        shared = None
        if self._m is not None:
            shared = {k: getattr(self._m, k) for k in self.SHARED}
        self.__dict__.update(self.comm.bcast(shared, root=0))

    def _call(self, name: str, *args):
        """``material.name(*args)`` on rank 0, its NewtonFailure raised on every rank."""
        out, err = None, None
        if self._m is not None:
            try:
                out = getattr(self._m, name)(*args)
            except NewtonFailure as e:
                err = str(e)
        err = bcast_from_root(self.comm, err)
        self._sync()
        if err is not None:
            raise NewtonFailure(err)
        return out

    def trial(self, g: np.ndarray):
        self._call("trial", g)
        return self.stress, self.tangent

    def new_step_counters(self) -> None:
        self._call("new_step_counters")

    def reject(self) -> None:
        self._call("reject")

    def commit(self) -> None:
        self._call("commit")

    def state(self):
        """The elements' accepted states on rank 0 (None on the others)."""
        return self._call("state")

    def set_state(self, data) -> None:
        """``data``: the states, on rank 0 (ignored on the others)."""
        self._call("set_state", data)
