"""Persistent DEM elements on ``dask.distributed`` workers: the one pool (issues 18 and 37).

An ``ElementPool`` holds many elements (``cpp_dem.elements.interface``: strain-driven
``DemElement``s, docs/periodic.md, or the two-way loop's regions as target-driven
``RunnerElement``s) in the memory of Dask workers, as actors: one actor per worker holds
that worker's elements across load steps, Newton iterations and two-way iterations, so an
element is never rebuilt between calls. The pool

- applies one strain increment per element (``apply_strain``), all workers at once, and
  returns the stresses (Pa, tension positive) and, if asked, the tangents (6 x 6 Voigt, Pa);
  or runs every region's element from its initial to its final FEM state (``run``, pools
  made by ``ElementPool.runners``) and returns the answers;
- ``accept()`` saves every element's state as bytes **on its worker**: kept in the worker's
  memory (for ``reject()``) and written to a spill file, in the worker's local temporary
  directory or in ``state_dir`` (a directory every worker sees: shared storage). The client
  receives only each element's digest and size (tens of bytes), not its state; with
  ``keep_copies=True`` (opt-in) it also keeps a copy of every element's bytes;
- ``reject()`` restores every element to the last accepted state (a rejected Newton
  iteration);
- gives elements to workers that join after it was built: at the next boundary (the first
  ``apply_strain`` after a build, ``accept``, ``reject`` or ``load_states``, when every element
  is at its accepted state) elements move from the busiest hosts, by their accepted bytes, to
  the new workers' hosts, worker to worker (or through their spill files in ``state_dir``);
  ``min_workers=`` waits for that many workers before the elements are built;
- survives a lost worker: its elements are rebuilt on the other workers from their accepted
  state, read from the spill file where a surviving worker can reach it (``state_dir``, or
  the same machine), else from the client's copy (``keep_copies=True``), each checked
  against its digest; the calls since the last accept are redone, so the result is the same
  as an undisturbed run. Where neither is there, ``ElementLostError`` names the elements:
  the pool never restarts an element from a wrong state.

Each element's arithmetic does not depend on where it runs (one thread per worker,
fixed-order sums, the state restored bitwise from its bytes), so the results are bitwise the
same for any number of workers, with late or lost workers.

The default cluster is a ``LocalCluster`` of single-threaded worker processes on this
machine; pass ``client=`` to use any Dask cluster (``dask-jobqueue``'s SLURMCluster or
PBSCluster, ``SSHCluster``, ``dask-mpi``: docs/coupling_element_pool.md). SI units.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import shutil
import tempfile
import time
import uuid
import warnings
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from cpp_dem._core import ParameterError
from cpp_dem.elements.cluster import (alive_workers, check_sendable, closed_on_error,
                                      local_client, wait_for_workers)

#: Seconds to wait for an actor to start on a worker, or for a worker-to-worker move.
START_TIMEOUT_S = 120.0


class ElementError(RuntimeError):
    """An element failed in its DEM work (its worker is alive): the message names the
    elements of that worker's call and the cause."""


class ElementLostError(RuntimeError):
    """Elements whose worker was lost cannot be restarted from their accepted state: no
    surviving worker could read their spill file (or it did not match the accepted state's
    digest), and the client holds no copy (``keep_copies=False``). The message names the
    elements, the worker, the files tried and what would have recovered them."""


#: Seconds to wait for the scheduler to drop a worker whose actor call failed with a
#: communication error (a killed worker), before the failure is taken as the element's.
COMM_LOSS_WAIT_S = 15.0


def _comm_error(e: BaseException) -> bool:
    """Whether ``e`` says the worker could not be reached (rather than that its element
    failed): distributed's CommClosedError, or an OSError such as "Unable to contact
    Actor's worker"."""
    try:
        from distributed.comm.core import CommClosedError
    except ImportError:  # pragma: no cover
        CommClosedError = OSError
    return isinstance(e, (CommClosedError, OSError))


def _recording(call: Callable):
    """``call()`` with the warnings it raises recorded: (its result, [(category, message,
    filename, lineno)]). An element's warnings on a Dask worker would print there, in
    Python's format, once per element; the pool says them again on the client instead
    (:func:`_say_again`), where the run's display shows each kind once."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = call()
    return result, [(w.category, str(w.message), w.filename, w.lineno) for w in caught]


def _say_again(records: list) -> None:
    """Raises on the client, element by element in index order, the warnings the hosts
    recorded (``record["warnings"]``), each message prefixed with its element."""
    for r in sorted(records, key=lambda r: r["index"]):
        for category, message, filename, lineno in r.get("warnings", ()):
            warnings.warn_explicit(f"element {r['index']}: {message}", category, filename,
                                   lineno)


def state_digest(data: bytes) -> str:
    """The digest that identifies an element's saved state (BLAKE2b, 16 bytes, hex)."""
    return hashlib.blake2b(data, digest_size=16).hexdigest()


def _spill_root(state_dir: str | None, pool_id: str) -> Path:
    """The pool's spill directory on this machine: ``state_dir/pool-<id>`` when shared, else
    ``<Dask's temporary-directory or the system's>/cpp_dem-pool-<id>``."""
    if state_dir is not None:
        return Path(state_dir) / f"pool-{pool_id}"
    import dask

    base = dask.config.get("temporary-directory", None) or tempfile.gettempdir()
    return Path(base) / f"cpp_dem-pool-{pool_id}"


def _payload_bytes(obj) -> int:
    """The bytes of the data in ``obj`` (bytes, arrays, strings, numbers, nested in dicts,
    lists and tuples): what a message carrying it weighs, less the framing."""
    if obj is None:
        return 0
    if isinstance(obj, (bytes, bytearray, memoryview)):
        return len(obj)
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if isinstance(obj, str):
        return len(obj)
    if isinstance(obj, dict):
        return sum(_payload_bytes(k) + _payload_bytes(v) for k, v in obj.items())
    if isinstance(obj, (list, tuple)):
        return sum(_payload_bytes(v) for v in obj)
    if isinstance(obj, (int, float, np.number, bool)):
        return 8
    return len(pickle.dumps(obj))


def _check_states(data: list, element_type: type | None) -> None:
    """Refuses, naming ``data[k]``, an element's bytes that are not bytes or, for the
    elements of cpp_dem's element format (``STATE_KIND``: DemElement, LinearElement,
    RunnerElement), not of that format (a pickle, another kind, a checksum that does not
    match): parsed here, nothing in them is run."""
    from cpp_dem.elements import state_format

    if element_type is None:
        from cpp_dem.elements.periodic import DemElement

        element_type = DemElement
    kind = getattr(element_type, "STATE_KIND", None)
    name = getattr(element_type, "__name__", "element")
    for k, d in enumerate(data):
        if not isinstance(d, (bytes, bytearray)):
            raise ParameterError(f"data[{k}]: {type(d).__name__}, expected the bytes of a "
                                 f"saved {name} ({name}.to_bytes)")
        if kind is not None:
            state_format.unpack(d, kind, field=f"data[{k}]")


def _kind(element_type: type) -> type:
    """The interface an element class is driven through: ``TargetElement`` (it has
    ``run``), else ``StrainElement``."""
    from cpp_dem.elements.interface import StrainElement, TargetElement

    return TargetElement if callable(getattr(element_type, "run", None)) else StrainElement


def element_tangent(el, tangent: str | None, strain_kw: dict, fd_components=None):
    """An element's 6 x 6 Voigt tangent (Pa) as ``ElementPool.apply_strain``'s ``tangent``
    names it (None: none); "auto" is "network" (a reinforced cell's too: its sheet's bonds
    are in the network); "fd-forward": forward differences of ``fd_components`` (default
    all six; the others NaN), the band RVEs' tangent before the network took bonds. A pair
    of names: the first for an element without bonds, the second for one with."""
    if isinstance(tangent, tuple):
        tangent = tangent[1 if getattr(getattr(el, "scene", None), "num_bonds", 0) else 0]
    if tangent == "fd-forward":
        return el.fd_tangent(components=range(6) if fd_components is None else fd_components,
                             central=False, **strain_kw)
    if tangent in ("auto", "network"):
        return el.network_tangent()[0]
    if tangent == "network-elastic":  # sliding contacts taken as stuck:
        return el.network_tangent(sliding="elastic")[0]  # stiffer, positive past the peak
    if tangent == "fd":
        return el.fd_tangent(**strain_kw)
    return None


class ElementHost:
    """The actor on one worker: a dict of elements by index (``element_type``: a
    ``cpp_dem.elements.interface.PoolElement`` class, None for ``DemElement``), their accepted
    bytes (in memory) and their spill files (the accepted bytes on disk, the last two
    accepts).

    ``spill_dir``: the pool's shared spill directory (``shared=True``: files named by element
    and generation, the same path whichever worker writes them), or None for this worker's
    local temporary directory (a folder of its own under the pool's)."""

    def __init__(self, spill_dir: str | None, pool_id: str, element_type: type | None = None,
                 runner_key: bytes | None = None) -> None:
        from cpp_dem import set_num_threads
        from cpp_dem.elements.interface import trust_runner_key

        set_num_threads(1)  # one element at a time per worker process: results as serial
        if runner_key is not None:  # (the client's: RunnerElement bytes signed there restore)
            trust_runner_key(runner_key)
        if element_type is None:
            from cpp_dem.elements.periodic import DemElement

            element_type = DemElement
        self.element_type = element_type
        self.kind = _kind(element_type)
        self.elements: dict = {}
        self.accepted: dict = {}
        self.shared = spill_dir is not None
        self.host_id = uuid.uuid4().hex[:10]
        root = _spill_root(spill_dir, pool_id)
        self.dir = root if self.shared else root / f"host-{self.host_id}"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.files: dict = {}  # element index -> [(generation, path)] written by this host

    # ---- the spill ---------------------------------------------------------------------
    def _path(self, k: int, generation: int) -> Path:
        return self.dir / f"element-{k:06d}.g{generation}.bin"

    def _spill(self, k: int, data: bytes, generation: int) -> tuple:
        """Writes the accepted bytes of element k (accept number ``generation``) to its spill
        file (atomically: a reader sees the old file or the whole new one) and removes its
        files older than the previous accept (which stays, in case this accept does not
        complete). Returns (digest, size in bytes, path)."""
        path = self._path(k, generation)
        tmp = path.with_name(f"{path.name}.{self.host_id}.tmp")
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
        keep = []
        for g, p in self.files.get(k, []):
            if g < generation - 1:
                p.unlink(missing_ok=True)
            elif p != path:
                keep.append((g, p))
        if self.shared and generation >= 2:  # (written by whichever host had k then)
            self._path(k, generation - 2).unlink(missing_ok=True)
        self.files[k] = keep + [(generation, path)]
        return state_digest(data), len(data), str(path)

    def _set(self, k: int, data: bytes, generation: int, path: str | None = None) -> tuple:
        """Element k restored from its accepted bytes, kept and spilled (not written again
        when ``path`` is already this host's file for that generation)."""
        self.elements[k] = self.element_type.from_bytes(data)
        self.accepted[k] = data
        if path is not None and Path(path) == self._path(k, generation):
            self.files.setdefault(k, []).append((generation, Path(path)))
            return state_digest(data), len(data), path
        return self._spill(k, data, generation)

    # ---- placing elements --------------------------------------------------------------
    def build(self, index: int, factory: Callable, generation: int, send: bool) -> dict:
        """Builds element ``index`` with ``factory(index)`` (an element of the pool's
        ``element_type``, checked by ``interface.check_element``); keeps and spills its
        bytes; returns its record (and the bytes if ``send``)."""
        from cpp_dem.elements.interface import check_element

        el, said = _recording(lambda: check_element(factory(index), self.kind,
                                                    f"factory({index})"))
        data = el.to_bytes()
        self.elements[index] = el
        self.accepted[index] = data
        return {"index": index, "record": self._spill(index, data, generation),
                "bytes": data if send else None, "warnings": said}

    def add(self, index: int, data: bytes, generation: int, digest: str | None = None) -> tuple:
        """Element ``index`` from bytes the client sent; returns its record."""
        if digest is not None and state_digest(data) != digest:
            raise ValueError(f"element {index}: the bytes sent do not match the digest "
                             f"{digest} of its accepted state")
        return self._set(index, data, generation)

    def load(self, items: list, generation: int) -> dict:
        """Restores elements from their spill files: ``items`` is [(index, path, digest)].
        Returns index -> record, or index -> the reason (a string) the file could not be
        used (missing here, unreadable, or not the accepted state)."""
        out = {}
        for k, path, digest in items:
            try:
                data = Path(path).read_bytes()
            except OSError as e:
                out[k] = f"{path}: {e.strerror or e} on this worker"
                continue
            if state_digest(data) != digest:
                out[k] = f"{path}: not the accepted state (its digest differs)"
                continue
            out[k] = self._set(k, data, generation, path)
        return out

    def take(self, indices: list, source: tuple, digests: dict, generation: int) -> dict:
        """Moves elements from another host to this one, worker to worker: ``source`` is that
        host's (worker address, actor key). Returns index -> record."""
        from distributed.actor import Actor

        other = Actor(ElementHost, source[0], source[1])
        got = other.saved(indices).result(timeout=START_TIMEOUT_S)
        out = {}
        for k in indices:
            if state_digest(got[k]) != digests[k]:
                raise ValueError(f"element {k}: the bytes moved from {source[0]} do not match "
                                 "the digest of its accepted state")
            out[k] = self._set(k, got[k], generation)
        return out

    def drop(self, indices) -> None:
        """Forgets elements moved to another host (and their local spill files)."""
        for k in indices:
            self.elements.pop(k, None)
            self.accepted.pop(k, None)
            for _g, p in self.files.pop(k, []):
                if not self.shared:  # (a shared file is the new host's now)
                    p.unlink(missing_ok=True)

    # ---- the increment -----------------------------------------------------------------
    def apply(self, indices, increments, tangent: str | None, strain_kw: dict,
              scatter: bool = False, fd_components=None) -> list:
        out = []
        for k, de in zip(indices, increments):
            t0 = time.perf_counter()
            el = self.elements[k]
            try:  # (the pool's ElementError then names the element that failed)
                (s, d), said = _recording(lambda: (
                    el.apply_strain(np.asarray(de), **strain_kw),
                    element_tangent(el, tangent, strain_kw, fd_components)))
            except Exception as e:  # noqa: BLE001
                raise RuntimeError(f"element {k}: {type(e).__name__}: {e}") from e
            out.append({"index": k, "stress": s, "tangent": d, "warnings": said,
                        "contacts": el.contact_count(), "cpu_s": time.perf_counter() - t0,
                        "steps": el.last_report.steps + el.last_report.relax_steps,
                        "scatter": el.stress_scatter() if scatter else None})
        return out

    def run(self, indices, calls) -> list:
        """Target-driven elements: ``run(*calls[j])`` on element ``indices[j]``. Returns per
        element its answer, or the error it raised (as text: the pool names the element)."""
        out = []
        for k, args in zip(indices, calls):
            t0 = time.perf_counter()
            said = []
            try:
                (answer, said), error = _recording(lambda: self.elements[k].run(*args)), None
            except Exception as e:  # noqa: BLE001 - reported by the pool, naming the element
                answer, error = None, f"{type(e).__name__}: {e}"
            out.append({"index": k, "answer": answer, "error": error, "warnings": said,
                        "cpu_s": time.perf_counter() - t0})
        return out

    def accept(self, indices, generation: int, send: bool = False) -> dict:
        """Saves the elements' states as accepted (in memory and spilled); returns their
        records (digest, size, path) and, if ``send``, their bytes."""
        records, sent = {}, {}
        for k in indices:
            data = self.accepted[k] = self.elements[k].to_bytes()
            records[k] = self._spill(k, data, generation)
            if send:
                sent[k] = data
        return {"records": records, "bytes": sent if send else None}

    def saved(self, indices) -> dict:
        """The accepted bytes of ``indices``."""
        return {k: self.accepted[k] for k in indices}

    def reject(self, indices) -> None:
        for k in indices:
            self.elements[k] = self.element_type.from_bytes(self.accepted[k])

    def memory(self) -> dict:
        """This worker's elements and their accepted bytes: {"elements", "accepted_bytes",
        "rss_bytes" (the worker process's resident memory)}."""
        import psutil

        return {"elements": len(self.elements),
                "accepted_bytes": sum(len(b) for b in self.accepted.values()),
                "rss_bytes": psutil.Process().memory_info().rss}

    def close(self) -> None:
        """Drops the elements and removes this host's spill files."""
        self.drop(list(self.elements))
        for files in self.files.values():
            for _g, p in files:
                p.unlink(missing_ok=True)
        self.files = {}
        if self.shared:
            for p in self.dir.glob(f"*.{self.host_id}.tmp"):
                p.unlink(missing_ok=True)
        else:
            shutil.rmtree(self.dir, ignore_errors=True)
        try:
            (self.dir if self.shared else self.dir.parent).rmdir()  # (if it is empty now)
        except OSError:
            pass


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


@dataclass(frozen=True)
class SavedState:
    """What the client knows of an element's accepted state (its bytes stay on the workers):
    ``generation`` (the number of accepts and loads before it; 0: built or given),
    ``digest`` (``state_digest`` of its bytes), ``size_bytes`` and ``spill`` (the file its
    worker wrote)."""

    generation: int
    digest: str
    size_bytes: int
    spill: str


class ElementPool:
    """Many elements on Dask workers (the one pool of ``cpp_dem.elements.interface``'s
    elements). Build it with ``ElementPool.build(n, factory)`` (each element made on a worker
    by ``factory(index)``), from saved bytes (``ElementPool(data_list)``), or for the two-way
    loop's regions with ``ElementPool.runners(runner, names)``. Strain-driven elements
    (``DemElement``, the default ``element_type``) are driven by ``apply_strain``,
    target-driven ones (``interface.RunnerElement``) by ``run``; both are saved by
    ``accept()``, restored by ``reject()``, moved to late workers and recovered after a lost
    worker the same way.

    Options (``build`` and the constructor):

    - ``client``: a Dask client (any cluster; it stays open at ``close()``), else a
      ``LocalCluster`` of ``workers`` single-threaded processes of the pool's own;
    - ``keep_copies``: also keep every element's accepted bytes in the client (what a lost
      worker's elements restart from when no surviving worker can read their spill file;
      costs the elements' whole state through the client at every ``accept``). Default
      False: the client keeps only digests and sizes;
    - ``state_dir``: a directory every worker can reach (a shared filesystem; a relative
      path is taken from the client's working directory), where the accepted states are
      spilled (``state_dir/pool-<id>/``, the last two accepts); default
      None: each worker's local temporary directory (Dask's ``temporary-directory``, else
      the system's), reachable after a loss only by workers of the same machine;
    - ``min_workers``: wait until the cluster has this many workers (at most ``timeout_s``
      seconds) before placing the elements;
    - ``rebalance``: give elements to workers that joined after the pool was built (default
      True);
    - ``element_type``: the elements' class (its ``from_bytes`` restores them; None:
      ``DemElement``);
    - ``labels``: the elements' names in messages (default ``element <k>``);
    - ``log``: gets a line per element recovered after a lost worker.

    ``close()`` removes the spill files and stops the pool's own cluster."""

    def __init__(self, data: Sequence[bytes], *, client=None, workers: int = 2,
                 keep_copies: bool = False, state_dir: str | os.PathLike | None = None,
                 min_workers: int | None = None, timeout_s: float = 600.0,
                 rebalance: bool = True, element_type: type | None = None,
                 labels: Sequence[str] | None = None,
                 log: Callable[[str], None] | None = None) -> None:
        data = list(data)
        self._connect(client, workers, keep_copies, len(data), state_dir, min_workers,
                      timeout_s, rebalance, element_type, labels, log, states=data)
        with closed_on_error(self):
            self._start_hosts(self._alive())
            addrs = sorted(self._hosts)
            self._where = {k: addrs[k % len(addrs)] for k in range(self.n)}
            self._send(range(self.n), data, 0)

    def _connect(self, client, workers, keep_copies, n, state_dir, min_workers, timeout_s,
                 rebalance, element_type=None, labels=None, log=None, states=None) -> None:
        """Checks the options (and the elements' bytes ``states``, if given), connects (a
        LocalCluster of ``workers`` single-threaded processes when no client is given), waits
        for ``min_workers`` and sets up the empty placement of n elements."""
        if n < 1:
            raise ParameterError(f"n={n}: need at least one element")
        if element_type is not None:
            from cpp_dem.elements.interface import check_element

            if not isinstance(element_type, type):
                raise ParameterError(f"element_type={element_type!r}: a class (DemElement, "
                                     "interface.RunnerElement), or None for DemElement")
            check_element(element_type, _kind(element_type), "element_type")
        if labels is not None:
            labels = list(labels)
            if len(labels) != n or not all(isinstance(x, str) for x in labels):
                raise ParameterError(f"labels={labels!r:.200}: one string per element ({n})")
        if log is not None and not callable(log):
            raise ParameterError(f"log={log!r}: a callable taking a line of text, or None")
        for name, v in (("keep_copies", keep_copies), ("rebalance", rebalance)):
            if not isinstance(v, bool):
                raise ParameterError(f"{name}={v!r}: must be True or False")
        if state_dir is not None and not isinstance(state_dir, (str, os.PathLike)):
            raise ParameterError(f"state_dir={state_dir!r}: a directory path (str or Path) "
                                 "that every worker can reach, or None for the workers' "
                                 "local temporary directories")
        if not (isinstance(timeout_s, (int, float)) and timeout_s > 0):
            raise ParameterError(f"timeout_s={timeout_s!r}: seconds, > 0")
        if min_workers is not None:
            if not (isinstance(min_workers, int) and min_workers >= 1):
                raise ParameterError(f"min_workers={min_workers!r}: an integer >= 1, or None")
            if client is None and min_workers > workers:
                raise ParameterError(f"min_workers={min_workers} > workers={workers}: the "
                                     "pool's own LocalCluster never grows; pass client= for "
                                     "a cluster whose workers join later")
        if states is not None:
            _check_states(states, element_type)
        self.keep_copies, self.rebalance, self.n = keep_copies, rebalance, n
        self.element_type = element_type
        self.kind = _kind(element_type) if element_type is not None else None
        self.labels = labels or [f"element {k}" for k in range(n)]
        self.log = log or (lambda line: None)
        #: how a lost element restarts, said in the log line (``runners`` says it per runner)
        self.restart_note = "its accepted state, and the calls since then redone"
        # (a relative state_dir is taken from the client's working directory)
        self.state_dir = (None if state_dir is None
                          else str(Path(state_dir).expanduser().absolute()))
        self.timeout_s = float(timeout_s)
        self.pool_id = uuid.uuid4().hex[:12]
        # The spill files this machine can see go with the pool: at close(), or when the
        # pool is collected or the client exits without it.
        self._remove_spill = weakref.finalize(
            self, shutil.rmtree, str(_spill_root(self.state_dir, self.pool_id)), True)
        self._hosts: dict = {}  # worker address -> actor
        self._where: dict = {}  # element index -> worker address
        self._saved: list = [None] * n  # SavedState per element
        self._copies: list | None = [None] * n if keep_copies else None
        self._generation = 0  # accepts and loads so far
        self._accepts = 0
        self._log: list = []  # the apply_strain calls since the last accept or reject
        self._clean = True  # every element at its accepted state (a placement boundary)
        self._received: dict = {}  # what the client received, by call: bytes
        self.moves: list = []  # (element, from worker, to worker), every rebalance move
        self.recoveries: list = []  # (element, lost worker, new worker), every recovery
        self._own_cluster = None
        if client is None:
            client, self._own_cluster = local_client(workers)
        self.client = client
        if min_workers is not None:
            with closed_on_error(self):
                wait_for_workers(client, min_workers, self.timeout_s)

    @classmethod
    def build(cls, n: int, factory: Callable, *, client=None, workers: int = 2,
              keep_copies: bool = False, state_dir: str | os.PathLike | None = None,
              min_workers: int | None = None, timeout_s: float = 600.0,
              rebalance: bool = True, element_type: type | None = None,
              labels: Sequence[str] | None = None,
              log: Callable[[str], None] | None = None) -> "ElementPool":
        """n elements made on the workers by ``factory(index)`` (a picklable callable
        returning an element of ``element_type``: a DemElement by default), spread over
        them; their first states are accepted. Options: see the class."""
        if not (isinstance(n, int) and n >= 1):
            raise ParameterError(f"n={n!r}: need at least one element")
        check_sendable(factory, "factory")
        pool = cls.__new__(cls)
        pool._connect(client, workers, keep_copies, n, state_dir, min_workers, timeout_s,
                      rebalance, element_type, labels, log)
        with closed_on_error(pool):
            pool._start_hosts(pool._alive())
            addrs = sorted(pool._hosts)
            futures = []
            for k in range(n):
                a = pool._where[k] = addrs[k % len(addrs)]
                futures.append((k, pool._hosts[a].build(k, factory, 0, keep_copies)))
            built = []
            for k, f in futures:
                got = f.result()
                pool._count("build", got)
                pool._record(k, 0, got["record"], got["bytes"])
                built.append(got)
            _say_again(built)
        return pool

    @classmethod
    def runners(cls, runner: Callable, names: Sequence[str], **options) -> "ElementPool":
        """The two-way loop's regions as target-driven elements: element k is
        ``interface.RunnerElement(runner, names[k])``, its own copy of ``runner`` made on its
        worker, driven by ``run``; labelled ``region <name>`` in messages. A runner with
        ``state()``/``set_state(bytes)`` restarts from its state at the last ``accept()``
        after a lost worker or a move; one without restarts from the runner as it was sent
        (``interface``'s module doc). Options: see the class."""
        from cpp_dem.elements.interface import RunnerElement, RunnerFactory, check_runner

        check_runner(runner)
        check_sendable(runner, "element_runner")  # (before any cluster starts)
        names = list(names) if not isinstance(names, str) else names
        if (not isinstance(names, list) or not names
                or not all(isinstance(x, str) and x for x in names)
                or len(set(names)) != len(names)):
            raise ParameterError(f"names={names!r:.200}: the regions' names, a non-empty list "
                                 "of distinct non-empty strings")
        pool = cls.build(len(names), RunnerFactory(runner, names), element_type=RunnerElement,
                         labels=[f"region {x}" for x in names], **options)
        pool.restart_note = ("its state at the last accept (the runner's state())"
                             if callable(getattr(runner, "state", None)) else
                             "the runner as it was sent (it keeps no byte state: what the "
                             "lost worker kept is prepared again)")
        return pool

    # ---- bookkeeping -------------------------------------------------------------------
    def _count(self, kind: str, obj) -> None:
        self._received[kind] = self._received.get(kind, 0) + _payload_bytes(obj)

    def received_bytes(self) -> dict:
        """The bytes the client has received from the workers so far, by kind of call
        ("build", "apply", "run", "accept", "states", "move", "recover"): the payload (states,
        arrays, digests), less the messages' framing."""
        return dict(self._received)

    def held_bytes(self) -> int:
        """The bytes of element data the pool keeps in the client: the records of the
        accepted states (digests, sizes, file names), the client's copies
        (``keep_copies``), the increments of the calls since the last accept (kept to redo
        them after a loss) and the log of moves."""
        return _payload_bytes([[(s.digest, s.size_bytes, s.spill, s.generation)
                                for s in self._saved if s is not None],
                               self._copies, self._log, self.moves])

    def _record(self, k: int, generation: int, rec: tuple, data: bytes | None = None) -> None:
        digest, size, path = rec
        self._saved[k] = SavedState(generation, digest, int(size), path)
        if self._copies is not None and data is not None:
            self._copies[k] = data

    def saved_states(self) -> list:
        """What the client knows of every element's accepted state (index order): a
        ``SavedState`` each (digest, size, spill file); the bytes are on the workers."""
        return list(self._saved)

    def _alive(self) -> list:
        return alive_workers(self.client)

    def workers(self) -> list:
        """The addresses of the workers holding elements."""
        return sorted(set(self._where.values()))

    def _by_host(self, indices) -> dict:
        groups: dict = {}
        for k in indices:
            groups.setdefault(self._where[k], []).append(k)
        return groups

    def _loads(self) -> dict:
        """Worker address -> the accepted bytes of the elements it holds (every host)."""
        load = {a: 0 for a in self._hosts}
        for k, a in self._where.items():
            if a in load:
                load[a] += self._saved[k].size_bytes if self._saved[k] else 0
        return load

    # ---- placement ---------------------------------------------------------------------
    def _start_hosts(self, addrs) -> list:
        """An ElementHost on every worker of ``addrs`` that has none; returns the new ones
        (a worker that leaves meanwhile is skipped)."""
        new = [a for a in sorted(addrs) if a not in self._hosts]
        from cpp_dem.elements.interface import session_key

        futures = {a: self.client.submit(ElementHost, self.state_dir, self.pool_id,
                                         self.element_type, session_key(), actor=True,
                                         workers=[a], pure=False) for a in new}
        started = []
        for a, fut in futures.items():
            try:
                self._hosts[a] = fut.result(timeout=START_TIMEOUT_S)
                started.append(a)
            except Exception as e:  # noqa: BLE001
                fut.cancel()
                if a in self._alive():  # (else that worker left meanwhile: not a host)
                    raise RuntimeError(f"ElementPool: no element host could start on worker "
                                       f"{a} (state_dir={self.state_dir!r}): "
                                       f"{type(e).__name__}: {e}") from e
        if not self._hosts:
            raise RuntimeError("ElementPool: the Dask cluster has no workers")
        return started

    def _send(self, indices, data, generation: int) -> None:
        """Sends the given bytes of ``indices`` (index order) to their hosts in ``_where``."""
        futures = []
        for k, d in zip(indices, data):
            d = bytes(d)
            futures.append((k, d, self._hosts[self._where[k]].add(k, d, generation,
                                                                   state_digest(d))))
        for k, d, f in futures:
            rec = f.result()
            self._count("load", rec)
            self._record(k, generation, rec, d)
        self._generation = generation

    def _check_workers(self) -> list:
        """At a boundary (every element at its accepted state): elements of workers gone
        meanwhile are recovered (their indices returned), and workers that joined get
        elements (``rebalance``)."""
        before = set(self._hosts)
        alive = self._alive()
        gone = [a for a in self._hosts if a not in alive]
        recovered = self._recover(set(gone)) if gone else []  # (starts hosts where needed)
        if self.rebalance:
            self._start_hosts(alive)
            new = sorted(a for a in self._hosts if a not in before)
            if new:
                self._rebalance(new)
        return recovered

    def _plan(self, new: list) -> list:
        """Moves (element, from, to) that even out the accepted bytes per host, from the
        busiest hosts to the new ones: each move takes the largest element of the busiest
        host that is smaller than the gap to the lightest new host (so the spread shrinks;
        ties by index and address: the same cluster gives the same plan)."""
        load = self._loads()
        held: dict = {a: [] for a in self._hosts}
        for k in sorted(self._where):
            held[self._where[k]].append(k)
        size = {k: (self._saved[k].size_bytes if self._saved[k] else 1) for k in self._where}
        moves = []
        while True:
            dst = min(new, key=lambda a: (load[a], a))
            src = max(self._hosts, key=lambda a: (load[a], a))
            gap = load[src] - load[dst]
            fits = [k for k in held[src] if size[k] < gap]
            if src == dst or not fits:
                return moves
            k = max(fits, key=lambda j: (size[j], -j))
            held[src].remove(k)
            held[dst].append(k)
            load[src] -= size[k]
            load[dst] += size[k]
            moves.append((k, src, dst))

    def _rebalance(self, new: list) -> None:
        """Carries out ``_plan(new)``: through the spill files in ``state_dir`` when there is
        one, else worker to worker (the new host fetches the bytes from the old one), else
        (that failing) through the client. Each element's bytes are checked against its
        digest; an element whose move fails stays where it was."""
        groups: dict = {}
        for k, src, dst in self._plan(new):
            groups.setdefault((src, dst), []).append(k)
        g = self._generation
        got: dict = {}  # element -> its record on the new host

        def collect(futures: dict) -> None:
            for (src, dst), f in futures.items():
                try:
                    res = f.result(timeout=START_TIMEOUT_S)
                except Exception:  # noqa: BLE001 - tried again the next way
                    continue
                self._count("move", res)
                got.update({k: r for k, r in res.items() if not isinstance(r, str)})

        if self.state_dir is not None:  # (the spill files: no transfer between workers)
            collect({(src, dst): self._hosts[dst].load(
                [(k, self._saved[k].spill, self._saved[k].digest) for k in ks], g)
                for (src, dst), ks in groups.items()})
        rest = {sd: [k for k in ks if k not in got] for sd, ks in groups.items()}
        collect({(src, dst): self._hosts[dst].take(
            ks, (src, self._hosts[src].key), {k: self._saved[k].digest for k in ks}, g)
            for (src, dst), ks in rest.items() if ks})
        for (src, dst), ks in sorted(groups.items()):
            ks_left = [k for k in ks if k not in got]
            if ks_left:  # no worker-to-worker link: through the client
                try:
                    data = self._hosts[src].saved(ks_left).result(timeout=START_TIMEOUT_S)
                    self._count("move", data)
                    for k in ks_left:
                        got[k] = self._hosts[dst].add(k, data[k], g,
                                                      self._saved[k].digest).result()
                except Exception:  # noqa: BLE001 - they stay on src (or are recovered later)
                    pass
        drops = []
        for (src, dst), ks in sorted(groups.items()):
            done = [k for k in ks if k in got]
            try:
                drops.append(self._hosts[src].drop(done))
            except Exception:  # noqa: BLE001 - src gone: nothing to drop
                pass
            for k in done:
                self._where[k] = dst
                self._record(k, g, got[k])
                self.moves.append((k, src, dst))
        for f in drops:
            try:
                f.result(timeout=START_TIMEOUT_S)
            except Exception:  # noqa: BLE001
                pass

    def _recover(self, lost: set) -> list:
        """Rebuilds the elements of the lost workers on the others from their accepted
        states, then redoes the calls since the last accept; returns their indices."""
        for a in lost:
            self._hosts.pop(a, None)
        alive = []
        for _ in range(100):  # (a LocalCluster restarts a killed worker: wait for one)
            alive = self._alive()
            if alive:
                break
            time.sleep(0.1)
        for a in list(self._hosts):
            if a not in alive:
                self._hosts.pop(a)
        self._start_hosts(alive)
        moved = sorted(k for k, a in self._where.items() if a not in self._hosts)
        if not moved:
            return []
        gone = {k: self._where[k] for k in moved}
        load = self._loads()
        for k in moved:  # the lightest host each, by accepted bytes (ties by address)
            a = min(load, key=lambda h: (load[h], h))
            self._where[k] = a
            load[a] += self._saved[k].size_bytes
        why: dict = {}
        futures = {a: self._hosts[a].load([(k, self._saved[k].spill, self._saved[k].digest)
                                           for k in ks], self._saved[ks[0]].generation)
                   for a, ks in self._by_host(moved).items()}
        for a, f in futures.items():
            res = f.result()
            self._count("recover", res)
            for k, r in res.items():
                if isinstance(r, str):
                    why[k] = r
                else:
                    self._record(k, self._saved[k].generation, r)
        if why and self._copies is not None:
            fs = {k: self._hosts[self._where[k]].add(k, self._copies[k],
                                                      self._saved[k].generation,
                                                      self._saved[k].digest) for k in why}
            for k, f in fs.items():
                self._record(k, self._saved[k].generation, f.result())
            why = {}
        if why:
            bad = sorted(why)
            workers = sorted({gone[k] for k in bad})
            for k in bad:  # (still lost: the next call tries again, and says so again)
                self._where[k] = gone[k]
            raise ElementLostError(
                f"elements {bad}: lost with worker(s) {workers}, and their accepted state "
                f"(after accept() number {self._accepts}) is not reachable: "
                + "; ".join(f"element {k}: {why[k]}" for k in bad[:5])
                + (" ..." if len(bad) > 5 else "")
                + ". The client keeps no copy (keep_copies=False), and restarting from "
                "another state would give wrong stresses. Give state_dir= a directory every "
                "worker sees (a shared filesystem), or build the pool with keep_copies=True, "
                "to restart lost elements from their accepted state; or restart the run from "
                "saved states (states(), load_states()).")
        for k in moved:
            self.recoveries.append((k, gone[k], self._where[k]))
            self.log(f"{self.labels[k]}: its worker {gone[k]} was lost; it runs on "
                     f"{self._where[k]} from {self.restart_note}")
        self._replay(moved)
        return moved

    def _replay(self, indices) -> None:
        """Redoes the logged calls (``apply_strain``, ``run``) since the last accept on
        ``indices``."""
        for method, payload, extra in self._log:
            futures = [getattr(self._hosts[a], method)(ks, [payload[k] for k in ks], *extra)
                       for a, ks in self._by_host(k for k in indices if k in payload).items()]
            for f in futures:
                f.result()

    def _dispatch(self, method: str, payload: dict, extra: tuple) -> tuple[dict, list]:
        """Calls host ``method(indices, [payload[k] ...], *extra)`` for every element of
        ``payload`` (index -> its part of the call), all workers at once. Called at a
        boundary (after a build, accept, reject or load), it first gives elements to workers
        that joined. A worker lost during the call: its elements are rebuilt elsewhere from
        their accepted states and the calls since the last accept redone
        (``ElementLostError`` where no accepted state is reachable). Returns (index -> the
        host's record, the indices recovered); the call is logged for a later replay."""
        recovered: list = self._check_workers() if self._clean else []
        self._clean = False
        results: dict = {}
        todo = sorted(payload)
        for _attempt in range(3):
            futures = {}
            lost = set()
            for a, ks in self._by_host(todo).items():
                try:  # (an actor whose worker is gone fails here already)
                    futures[a] = getattr(self._hosts[a], method)(ks, [payload[k] for k in ks],
                                                                 *extra)
                except Exception:  # noqa: BLE001
                    lost.add(a)
            errors = {}
            for a, f in futures.items():
                try:
                    got = f.result()
                    self._count(method, got)
                    for r in got:
                        results[r["index"]] = r
                except Exception as e:  # noqa: BLE001 - the worker is gone, or an element failed
                    lost.add(a)
                    errors[a] = e
            alive = set(self._alive()) if lost else set()
            # A worker killed during the call fails its actor's call with a communication
            # error before the scheduler has dropped it: wait for the scheduler's word.
            comm = {a for a in lost if a in alive and a in errors and _comm_error(errors[a])}
            deadline = time.monotonic() + COMM_LOSS_WAIT_S
            while comm & alive and time.monotonic() < deadline:
                time.sleep(0.1)
                alive = set(self._alive())
            for a in list(lost):
                if a in alive and a in errors:
                    # The worker is there: an element itself failed (a blow-up, a bad
                    # increment). The elements of that call are back to their accepted state
                    # after the caller's reject(); say which and why.
                    raise ElementError(f"elements {self._by_host(todo).get(a)} on {a}: "
                                       f"{type(errors[a]).__name__}: {errors[a]}") from errors[a]
            todo = [k for k in sorted(payload) if k not in results]
            if not todo:
                break
            # (The elements of a lost host restart from their accepted state and redo the
            # calls since the last accept, then this one.)
            moved = self._recover(lost)
            recovered += moved
            for k in todo:
                if k not in moved:
                    raise RuntimeError(f"element {k}: no result and its worker is alive")
        if todo:
            raise RuntimeError(f"elements {todo}: lost three times; giving up")
        self._log.append((method, payload, extra))
        _say_again(list(results.values()))
        return results, recovered

    def _require(self, kind_name: str, call: str) -> None:
        """Refuses ``call`` on a pool whose elements are not driven that way."""
        from cpp_dem.elements.interface import StrainElement

        kind = self.kind or StrainElement
        if kind.__name__ != kind_name:
            other = "run()" if call == "apply_strain" else "apply_strain()"
            raise ParameterError(f"{call}: this pool's elements are {kind.__name__}s "
                                 f"({getattr(self.element_type, '__name__', 'DemElement')}); "
                                 f"drive them with {other}")

    # ---- the increment -----------------------------------------------------------------
    def apply_strain(self, increments, *, tangent: str | None = None, scatter: bool = False,
                     fd_components=None, **strain_kw) -> PoolStep:
        """Applies increment ``increments[k]`` (3 x 3 displacement gradient, -) to element k,
        all in parallel; ``tangent``: None, "network" (sliding contacts on the Coulomb cone;
        a reinforced cell's bonds in the network too), "network-elastic" (sliding contacts
        taken as stuck), "fd" (central differences), "fd-forward" (forward differences of
        the Voigt components ``fd_components``, default all six, the others NaN) or "auto"
        (as "network"), or a pair of these: the first for the elements without bonds, the
        second for those with (reinforced cells); ``scatter``: also each
        element's stress scatter (``DemElement.stress_scatter``). Keyword arguments go to
        ``DemElement.apply_strain``. Called at a boundary (after a build, accept, reject or
        load), it first gives elements to workers that joined. A worker lost during the call:
        its elements are rebuilt elsewhere from their accepted states and the calls since
        the last accept redone (``ElementLostError`` where no accepted state is reachable)."""
        self._require("StrainElement", "apply_strain")
        if len(increments) != self.n:
            raise ParameterError(f"increments: {len(increments)} given for {self.n} elements")
        names = (None, "network", "network-elastic", "fd", "fd-forward", "auto")
        if not (tangent in names or (isinstance(tangent, tuple) and len(tangent) == 2
                                     and all(t in names for t in tangent))):
            raise ParameterError(f"tangent={tangent!r}: None, 'network', 'network-elastic', "
                                 "'fd', 'fd-forward' or 'auto', or a pair of them (without "
                                 "bonds, with bonds)")
        # (the increments are kept for a replay)
        increments = {k: np.array(d, copy=True) for k, d in enumerate(increments)}
        t0 = time.perf_counter()
        extra = (tangent, dict(strain_kw), scatter)
        if fd_components is not None:  # (the host's default otherwise: the call as before)
            extra += (tuple(int(c) for c in fd_components),)
        results, recovered = self._dispatch("apply", increments, extra)
        order = range(self.n)
        return PoolStep([results[k]["stress"] for k in order],
                        [results[k]["tangent"] for k in order],
                        [results[k]["contacts"] for k in order],
                        [results[k]["cpu_s"] for k in order],
                        [results[k]["steps"] for k in order],
                        time.perf_counter() - t0, sorted(recovered),
                        [results[k]["scatter"] for k in order] if scatter else None)

    def run(self, calls: Sequence[tuple | None]) -> list:
        """Target-driven elements (``ElementPool.runners``): ``calls[k]`` is the arguments
        of element k's ``run`` (``(initial, final)`` for a region), or None to leave it out;
        all in parallel. Returns the answers in index order (None where left out). Late
        and lost workers as ``apply_strain``. An element that raises on a live worker stops
        the call with an ``ElementError`` naming it (its label) and the cause."""
        self._require("TargetElement", "run")
        calls = list(calls)
        if len(calls) != self.n:
            raise ParameterError(f"calls: {len(calls)} given for {self.n} elements (None "
                                 "for an element left out)")
        payload = {}
        for k, c in enumerate(calls):
            if c is not None:
                if not isinstance(c, tuple):
                    raise ParameterError(f"calls[{k}]: {type(c).__name__}, expected a tuple "
                                         "of run()'s arguments, or None")
                payload[k] = c
        if not payload:
            return [None] * self.n
        t0 = time.perf_counter()
        results, _ = self._dispatch("run", payload, ())
        for k in sorted(results):
            if results[k]["error"] is not None:
                self._log.pop()  # (not a call to redo: the caller stops or rejects)
                raise ElementError(f"{self.labels[k]}: its DEM element failed on "
                                   f"{self._where[k]}: {results[k]['error']}")
        self.last_run_s = time.perf_counter() - t0
        return [results[k]["answer"] if k in results else None for k in range(self.n)]

    def accept(self) -> None:
        """Saves every element's current state as its accepted state, on its worker (in
        memory, and spilled to disk); the client receives each element's digest and size
        only (and, with ``keep_copies``, its bytes). A worker lost meanwhile: its elements
        are recovered (their accepted state, and the calls since) and then accepted."""
        g = self._generation + 1
        todo = list(range(self.n))
        pending: dict = {}  # (the records stay the previous accept's until all have saved)
        for _attempt in range(3):
            futures, lost, errors = {}, set(), {}
            for a, ks in self._by_host(todo).items():
                try:
                    futures[a] = self._hosts[a].accept(ks, g, self.keep_copies)
                except Exception:  # noqa: BLE001 - its worker is gone
                    lost.add(a)
            done = set()
            for a, f in futures.items():
                try:
                    got = f.result()
                except Exception as e:  # noqa: BLE001 - its worker is gone, or its disk failed
                    lost.add(a)
                    errors[a] = e
                    continue
                self._count("accept", got)
                for k, rec in got["records"].items():
                    done.add(k)
                    pending[k] = (rec, (got["bytes"] or {}).get(k))
            todo = [k for k in todo if k not in done]
            if not todo:
                break
            alive = self._alive()
            for a in sorted(lost):
                if a in alive:  # (the worker is there: saving or spilling failed)
                    e = errors.get(a)
                    raise RuntimeError(f"accept: elements {self._by_host(todo).get(a)} on {a}: "
                                       f"{type(e).__name__}: {e}") from e
            self._recover(lost)
        if todo:
            raise RuntimeError(f"elements {todo}: lost three times while accepting; giving up")
        for k, (rec, data) in pending.items():
            self._record(k, g, rec, data)
        self._generation = g
        self._accepts += 1
        self._log = []
        self._clean = True

    def reject(self) -> None:
        """Restores every element to its last accepted state."""
        self._log = []
        for _attempt in range(3):
            futures, lost, errors = {}, set(), {}
            for a, ks in self._by_host(range(self.n)).items():
                try:
                    futures[a] = self._hosts[a].reject(ks)
                except Exception:  # noqa: BLE001 - its worker is gone
                    lost.add(a)
            for a, f in futures.items():
                try:
                    f.result()
                except Exception as e:  # noqa: BLE001
                    lost.add(a)
                    errors[a] = e
            if not lost:
                break
            alive = self._alive()
            for a in sorted(lost):
                if a in alive:
                    e = errors.get(a)
                    raise RuntimeError(f"reject: elements {self._by_host(range(self.n))[a]} on "
                                       f"{a}: {type(e).__name__}: {e}") from e
            self._recover(lost)  # (restored at their accepted state: the rejection itself)
        self._clean = True

    def states(self, indices: Sequence[int] | None = None) -> list:
        """The last accepted bytes of every element (index order), or of the elements
        ``indices`` (in that order): the client's copies with ``keep_copies``, else fetched
        from the workers now (the elements' whole state through the client: an explicit
        call, for saving a run)."""
        ks = list(range(self.n)) if indices is None else [int(k) for k in indices]
        bad = [k for k in ks if not 0 <= k < self.n]
        if bad:
            raise ParameterError(f"indices: {bad[:5]} outside the pool's elements 0..{self.n - 1}")
        if self._copies is not None:
            return [self._copies[k] for k in ks]
        got_all: dict = {}
        futures = [self._hosts[a].saved(g) for a, g in self._by_host(sorted(set(ks))).items()]
        for f in futures:
            got = f.result()
            self._count("states", got)
            got_all.update(got)
        return [got_all[k] for k in ks]

    def load_states(self, data: Sequence[bytes]) -> None:
        """Every element back to the given accepted bytes (index order; ``states()`` of this
        pool earlier), loaded on the workers (and spilled there)."""
        data = list(data)
        if len(data) != self.n:
            raise ParameterError(f"data: {len(data)} states given for {self.n} elements")
        _check_states(data, self.element_type)
        self._log = []
        self._send(range(self.n), data, self._generation + 1)
        self._clean = True

    def memory(self) -> dict:
        """Worker address -> {"elements", "accepted_bytes", "rss_bytes"} of every host."""
        futures = {a: h.memory() for a, h in self._hosts.items()}
        return {a: f.result() for a, f in sorted(futures.items())}

    def close(self) -> None:
        """Removes the spill files, drops the elements from the workers and stops the pool's
        own LocalCluster and its client; a given ``client=`` stays open (its cluster is the
        caller's)."""
        hosts, self._hosts = getattr(self, "_hosts", {}), {}
        futures = []
        for h in hosts.values():
            try:
                futures.append(h.close())
            except Exception:  # noqa: BLE001 - a worker gone: nothing to close there
                pass
        for f in futures:
            try:
                f.result(timeout=30)
            except Exception:  # noqa: BLE001
                pass
        if hasattr(self, "_remove_spill"):  # (lost workers' files here, the shared dir)
            self._remove_spill()
        if getattr(self, "_own_cluster", None) is None:
            return
        try:
            self.client.close()
        finally:
            self._own_cluster.close()

    def __enter__(self) -> "ElementPool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["ElementPool", "ElementError", "ElementHost", "ElementLostError", "PeriodicFactory",
           "PoolStep", "SavedState", "state_digest"]
