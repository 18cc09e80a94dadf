"""Persistent DEM elements on ``dask.distributed`` workers (issue 18, first part).

An ``ElementPool`` holds many ``DemElement``s (docs/periodic.md) in the memory of Dask
workers, as actors: one actor per worker holds that worker's elements across load steps and
Newton iterations, so an element is never rebuilt between calls. The pool

- applies one strain increment per element (``apply_strain``), all workers at once, and
  returns the stresses (Pa, tension positive) and, if asked, the tangents (6 x 6 Voigt, Pa);
- ``accept()`` saves every element's state as bytes (on the workers and, by default, a copy
  in the client), ``reject()`` restores every element to the last accepted state (a rejected
  Newton iteration);
- survives a lost worker: the lost elements are rebuilt on the other workers from their last
  accepted bytes and the increment in flight is redone, so the result is the same as an
  undisturbed run (each element's arithmetic does not depend on where it runs: one thread
  per worker, fixed-order sums).

The default cluster is a ``LocalCluster`` of single-threaded worker processes on this
machine; pass ``client=`` to use any Dask cluster (``dask-jobqueue``'s SLURMCluster or
PBSCluster, ``SSHCluster``, ``dask-mpi``: docs/multiscale.md). SI units.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from cpp_dem._core import ParameterError
from cpp_dem.elements.cluster import check_sendable, closed_on_error, local_client


class ElementError(RuntimeError):
    """An element failed in its DEM work (its worker is alive): the message names the
    elements of that worker's call and the cause."""


class ElementLostError(RuntimeError):
    """Elements whose worker was lost cannot be restarted from their accepted state: with
    ``keep_copies=False`` that state lived only on the lost worker. The message names the
    elements, the worker and what the client still holds."""


class ElementHost:
    """The actor on one worker: a dict of DemElements by index, and their accepted bytes."""

    def __init__(self) -> None:
        from cpp_dem import set_num_threads

        set_num_threads(1)  # one element at a time per worker process: results as serial
        self.elements: dict = {}
        self.accepted: dict = {}

    def add(self, index: int, data: bytes) -> int:
        from cpp_dem.elements.periodic import DemElement

        self.elements[index] = DemElement.from_bytes(data)
        self.accepted[index] = data
        return index

    def build(self, index: int, factory: Callable) -> bytes:
        """Builds element ``index`` with ``factory(index)`` (a DemElement); returns its bytes."""
        el = factory(index)
        data = el.to_bytes()
        self.elements[index] = el
        self.accepted[index] = data
        return data

    def apply(self, indices, increments, tangent: str | None, strain_kw: dict,
              scatter: bool = False) -> list:
        out = []
        for k, de in zip(indices, increments):
            t0 = time.perf_counter()
            el = self.elements[k]
            s = el.apply_strain(np.asarray(de), **strain_kw)
            d = None
            if tangent == "network":
                d = el.network_tangent()[0]
            elif tangent == "network-elastic":  # sliding contacts taken as stuck: stiffer,
                d = el.network_tangent(sliding="elastic")[0]  # positive past the peak
            elif tangent == "fd":
                d = el.fd_tangent(**strain_kw)
            out.append({"index": k, "stress": s, "tangent": d,
                        "contacts": el.contact_count(), "cpu_s": time.perf_counter() - t0,
                        "steps": el.last_report.steps + el.last_report.relax_steps,
                        "scatter": el.stress_scatter() if scatter else None})
        return out

    def accept(self, indices, send: bool = True) -> dict:
        """Saves the elements' states as accepted; returns their bytes if ``send``."""
        for k in indices:
            self.accepted[k] = self.elements[k].to_bytes()
        return {k: self.accepted[k] for k in indices} if send else {}

    def saved(self, indices) -> dict:
        """The accepted bytes of ``indices``."""
        return {k: self.accepted[k] for k in indices}

    def reject(self, indices) -> None:
        from cpp_dem.elements.periodic import DemElement

        for k in indices:
            self.elements[k] = DemElement.from_bytes(self.accepted[k])


@dataclass
class PeriodicFactory:
    """A picklable element maker for ``ElementPool.build``: element k is
    ``DemElement.periodic(n, stress=stress, seed=seed + k, **options)`` (seed + k: distinct
    packings; give ``same=True`` for one packing everywhere, e.g. a homogeneous field), with
    ``isotropic=True`` then servo-controlled in all six components to the isotropic stress."""

    n: int = 200
    stress: float = 100e3
    seed: int = 1
    same: bool = False
    isotropic: bool = False
    options: dict | None = None

    def __call__(self, index: int):
        import numpy as np

        from cpp_dem.elements.periodic import DemElement

        el = DemElement.periodic(self.n, stress=self.stress,
                                 seed=self.seed + (0 if self.same else index),
                                 **(self.options or {}))
        if self.isotropic:
            # every component to the isotropic state, shear included: a packing's fabric
            # leaves shear stresses of a few per cent, which a FEM's free boundaries cannot
            # carry at the start
            el.apply_stress(-self.stress * np.eye(3))
        return el


@dataclass
class PoolStep:
    """What one ``apply_strain`` returned: per element (in index order) the stress (3 x 3,
    Pa, tension positive), the tangent (6 x 6, Pa, or None), the contact count, the seconds
    its DEM work took on its worker (``cpu_s``: wall clock there; a worker runs one element
    at a time on one thread) and its DEM steps; and the wall-clock seconds of the whole
    call; with ``scatter=True`` also each element's stress scatter."""

    stresses: list
    tangents: list
    contacts: list
    cpu_s: list
    steps: list
    wall_s: float
    recovered: list  # indices rebuilt after a lost worker during this call
    #: per element its stress scatter (3 x 3, Pa: ``DemElement.stress_scatter``), if asked
    scatters: list | None = None


class ElementPool:
    """Many DemElements on Dask workers. Build it with ``ElementPool.build(n, factory)``
    (each element made on a worker by ``factory(index)``) or from saved bytes
    (``ElementPool(data_list)``)."""

    def __init__(self, data: Sequence[bytes], *, client=None, workers: int = 2,
                 keep_copies: bool = True) -> None:
        self._connect(client, workers, keep_copies, len(data))
        self._bytes = list(data)  # last accepted states, in the client
        with closed_on_error(self):
            self._start_hosts()
            self._place(range(self.n))

    def _connect(self, client, workers: int, keep_copies: bool, n: int) -> None:
        """The client (a LocalCluster of ``workers`` single-threaded processes when none is
        given) and the empty placement of n elements."""
        self._own_cluster = None
        if client is None:
            client, self._own_cluster = local_client(workers)
        self.client, self.keep_copies, self.n = client, keep_copies, n
        self._hosts: dict = {}  # worker address -> actor
        self._where: dict = {}  # element index -> worker address
        # Elements whose accepted state is newer than the client's copy (keep_copies=False
        # after an accept()): a lost worker's such elements cannot be restarted right.
        self._stale: set = set()
        self._accepts = 0  # accept() calls so far

    @classmethod
    def build(cls, n: int, factory: Callable, *, client=None, workers: int = 2,
              keep_copies: bool = True) -> "ElementPool":
        """n elements made on the workers by ``factory(index)`` (a picklable callable
        returning a DemElement), spread over them; their first states are accepted."""
        if n < 1:
            raise ParameterError(f"n={n}: need at least one element")
        check_sendable(factory, "factory")
        pool = cls.__new__(cls)
        pool._connect(client, workers, keep_copies, n)
        pool._bytes = [None] * n
        with closed_on_error(pool):
            pool._start_hosts()
            addrs = sorted(pool._hosts)
            futures = []
            for k in range(n):
                a = addrs[k % len(addrs)]
                pool._where[k] = a
                futures.append((k, pool._hosts[a].build(k, factory)))
            for k, f in futures:
                pool._bytes[k] = f.result()
        return pool

    # ---- placement ---------------------------------------------------------------------
    def _start_hosts(self) -> None:
        addrs = sorted(self.client.scheduler_info()["workers"])
        if not addrs:
            raise RuntimeError("ElementPool: the Dask cluster has no workers")
        for a in addrs:
            if a in self._hosts:
                continue
            fut = self.client.submit(ElementHost, actor=True, workers=[a], pure=False)
            self._hosts[a] = fut.result()

    def _place(self, indices) -> None:
        """Loads the accepted bytes of ``indices`` onto hosts, spread round-robin."""
        addrs = sorted(self._hosts)
        futures = []
        for j, k in enumerate(sorted(indices)):
            a = addrs[j % len(addrs)]
            self._where[k] = a
            futures.append(self._hosts[a].add(k, self._bytes[k]))
        for f in futures:
            f.result()

    def workers(self) -> list:
        """The addresses of the workers holding elements."""
        return sorted(set(self._where.values()))

    def _by_host(self, indices) -> dict:
        groups: dict = {}
        for k in indices:
            groups.setdefault(self._where[k], []).append(k)
        return groups

    def _recover(self, lost: set) -> list:
        """Rebuilds the elements of the lost workers on the others; returns their indices."""
        for a in lost:
            self._hosts.pop(a, None)
        alive = set(self.client.scheduler_info()["workers"])
        for a in list(self._hosts):
            if a not in alive:
                self._hosts.pop(a)
        self._start_hosts()
        moved = [k for k, a in self._where.items() if a not in self._hosts]
        stale = sorted(k for k in moved if k in self._stale)
        if stale:
            gone = sorted({self._where[k] for k in stale})
            raise ElementLostError(
                f"elements {stale}: lost with worker(s) {gone}; with keep_copies=False their "
                f"accepted state (after accept() number {self._accepts}) was kept only on "
                "that worker, and the client holds an older one (built or loaded, before any "
                "accepted increment): restarting from it would give wrong stresses. Build the "
                "pool with keep_copies=True (the default) to restart lost elements from their "
                "accepted state, or restart the run from saved states (states(), "
                "load_states()).")
        if moved:
            self._place(moved)
        return moved

    # ---- the increment ---------------------------------------------------------------------
    def apply_strain(self, increments, *, tangent: str | None = None, scatter: bool = False,
                     **strain_kw) -> PoolStep:
        """Applies increment ``increments[k]`` (3 x 3 displacement gradient, -) to element k,
        all in parallel; ``tangent``: None, "network" (sliding contacts on the Coulomb cone),
        "network-elastic" (sliding contacts taken as stuck) or "fd"; ``scatter``: also each
        element's stress scatter (``DemElement.stress_scatter``). Keyword arguments go to
        ``DemElement.apply_strain``. A worker lost during the call: its elements are rebuilt
        from their last accepted bytes elsewhere and their increment redone; with
        ``keep_copies=False`` after an ``accept()`` those bytes were on the lost worker only,
        and ElementLostError names the elements instead."""
        if len(increments) != self.n:
            raise ParameterError(f"increments: {len(increments)} given for {self.n} elements")
        if tangent not in (None, "network", "network-elastic", "fd"):
            raise ParameterError(f"tangent={tangent!r}: None, 'network', 'network-elastic' "
                                 "or 'fd'")
        t0 = time.perf_counter()
        results: dict = {}
        todo = list(range(self.n))
        recovered: list = []
        for _attempt in range(3):
            futures = {}
            lost = set()
            for a, ks in self._by_host(todo).items():
                try:  # (an actor whose worker is gone fails here already)
                    futures[a] = self._hosts[a].apply(
                        ks, [np.asarray(increments[k]) for k in ks], tangent, strain_kw,
                        scatter)
                except Exception:  # noqa: BLE001
                    lost.add(a)
            errors = {}
            for a, f in futures.items():
                try:
                    for r in f.result():
                        results[r["index"]] = r
                except Exception as e:  # noqa: BLE001 - the worker is gone, or an element failed
                    lost.add(a)
                    errors[a] = e
            alive = set(self.client.scheduler_info()["workers"])
            for a in list(lost):
                if a in alive and a in errors:
                    # The worker is there: an element itself failed (a blow-up, a bad
                    # increment). The elements of that call are back to their accepted state
                    # after the caller's reject(); say which and why.
                    raise ElementError(f"elements {self._by_host(todo).get(a)} on {a}: "
                                       f"{type(errors[a]).__name__}: {errors[a]}") from errors[a]
            todo = [k for k in range(self.n) if k not in results]
            if not todo:
                break
            # (The elements of a lost host restart from their accepted state, as do the
            # results it had not returned.)
            moved = self._recover(lost)
            recovered += moved
            for k in todo:
                if k not in moved:
                    raise RuntimeError(f"element {k}: no result and its worker is alive")
        if todo:
            raise RuntimeError(f"elements {todo}: lost three times; giving up")
        order = range(self.n)
        return PoolStep([results[k]["stress"] for k in order],
                        [results[k]["tangent"] for k in order],
                        [results[k]["contacts"] for k in order],
                        [results[k]["cpu_s"] for k in order],
                        [results[k]["steps"] for k in order],
                        time.perf_counter() - t0, sorted(recovered),
                        [results[k]["scatter"] for k in order] if scatter else None)

    def accept(self) -> None:
        """Saves every element's current state as its accepted state (on its worker and, with
        keep_copies, in the client, which is what a lost worker's elements restart from)."""
        futures = [self._hosts[a].accept(ks, self.keep_copies)
                   for a, ks in self._by_host(range(self.n)).items()]
        for f in futures:
            got = f.result()
            if self.keep_copies:
                for k, data in got.items():
                    self._bytes[k] = data
        self._accepts += 1
        if not self.keep_copies:
            self._stale = set(range(self.n))

    def reject(self) -> None:
        """Restores every element to its last accepted state."""
        futures = [self._hosts[a].reject(ks) for a, ks in self._by_host(range(self.n)).items()]
        for f in futures:
            f.result()

    def states(self) -> list:
        """The last accepted bytes of every element (index order); with ``keep_copies=False``
        fetched from the workers."""
        if not self._stale:
            return list(self._bytes)
        out = list(self._bytes)
        futures = [self._hosts[a].saved(ks) for a, ks in self._by_host(sorted(self._stale)).items()]
        for f in futures:
            for k, data in f.result().items():
                out[k] = data
        return out

    def load_states(self, data: Sequence[bytes]) -> None:
        """Every element back to the given accepted bytes (index order; ``states()`` of this
        pool earlier), loaded on the workers."""
        if len(data) != self.n:
            raise ParameterError(f"data: {len(data)} states given for {self.n} elements")
        self._bytes = list(data)
        self._stale = set()
        self._place(range(self.n))

    def close(self) -> None:
        """Stops the pool's own LocalCluster and its client; a given ``client=`` stays open
        (its cluster is the caller's)."""
        if self._own_cluster is None:
            return
        try:
            self.client.close()
        finally:
            self._own_cluster.close()

    def __enter__(self) -> "ElementPool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["ElementPool", "ElementError", "ElementHost", "ElementLostError", "PeriodicFactory", "PoolStep"]
