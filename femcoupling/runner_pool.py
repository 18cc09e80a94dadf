"""The two-way loop's DEM elements on ``dask.distributed`` workers, kept there between its
iterations (issue 18).

``two_way(workers > 1)`` (or ``client=``) runs each region's ``element_runner`` in an actor
(``RunnerHost``) on a Dask worker: the runner object is sent once, and stays in that worker's
memory for the whole loop, with whatever it keeps there (``PeriodicRegionElement`` keeps its
region's prepared element; the ``prs_element`` case's runner keeps its element at the initial
targets). Region j always runs on the same host, so every iteration after the first starts
from the element kept there instead of preparing it again.

- **Same input, same output.** Each worker runs one thread (``cpp_dem.set_num_threads(1)``
  where the core is there), and the loop gathers the answers in region order: the results
  are bitwise those of the serial loop.
- **A lost worker.** A call whose worker is gone is redone on a new host started on a
  surviving (or restarted) worker, from the runner as it was sent (what the lost worker kept
  is prepared again). A runner that raises on a live worker stops the loop with its region's
  name and the cause.

The default cluster is a ``LocalCluster`` of ``workers`` single-threaded processes; pass
``client=`` for any Dask cluster (docs/multiscale.md). ``log`` gets a line per recovery.
SI units.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["RunnerHost", "RunnerPool"]


class RunnerHost:
    """The actor on one worker: the runner, kept across calls, and how many calls it ran."""

    def __init__(self, runner: Callable) -> None:
        try:
            from cpp_dem import set_num_threads

            set_num_threads(1)  # one element at a time per worker: the serial arithmetic
        except ImportError:  # (a runner that does not use the core)
            pass
        self.runner, self.calls = runner, 0

    def run(self, name: str, initial: Any, final: Any) -> Any:
        self.calls += 1
        return self.runner(name, initial, final)


class RunnerPool:
    """One ``RunnerHost`` per worker, each holding a copy of ``runner``; region ``names[j]``
    runs on host ``j % hosts``, the same host every call. ``run(jobs)`` runs
    ``runner(name, initial, final)`` for every job at once and returns the answers in job
    order. ``close()`` stops the pool's own cluster (not a given client)."""

    def __init__(self, runner: Callable, names: Sequence[str], *, workers: int = 2,
                 client=None, log: Callable[[str], None] | None = None) -> None:
        from cpp_dem.elements.cluster import check_sendable, closed_on_error, local_client

        self.runner, self.names = runner, list(names)
        self.log = log or (lambda msg: None)
        check_sendable(runner, "element_runner")
        self._cluster = None
        if client is None:
            client, self._cluster = local_client(workers)
        self.client = client
        self._hosts: dict = {}  # worker address -> actor
        self._where: dict = {}  # region name -> worker address
        self.recovered: list = []  # (region, lost worker address), every recovery so far
        with closed_on_error(self):
            self._start_hosts()
        addrs = sorted(self._hosts)
        for j, n in enumerate(self.names):
            self._where[n] = addrs[j % len(addrs)]

    def _start_hosts(self) -> None:
        addrs = sorted(self.client.scheduler_info()["workers"])
        if not addrs:
            raise RuntimeError("RunnerPool: the Dask cluster has no workers")
        for a in addrs:
            if a not in self._hosts:
                fut = self.client.submit(RunnerHost, self.runner, actor=True, workers=[a],
                                         pure=False)
                self._hosts[a] = fut.result()

    def workers(self) -> list:
        """The worker addresses the regions run on."""
        return sorted(set(self._where.values()))

    def run(self, jobs: Sequence[tuple]) -> list:
        """``jobs``: (name, initial, final) per region; the answers in job order."""
        results: dict = {}
        todo = list(range(len(jobs)))
        for _attempt in range(3):
            futures, lost, errors = {}, set(), {}
            for k in todo:
                name = jobs[k][0]
                a = self._where[name]
                try:  # (an actor whose worker is gone can fail here already)
                    futures[k] = self._hosts[a].run(*jobs[k])
                except Exception:  # noqa: BLE001
                    lost.add(a)
            for k, f in futures.items():
                try:
                    results[k] = f.result()
                except Exception as e:  # noqa: BLE001 - the worker is gone, or the runner failed
                    errors[k] = e
            alive = set(self.client.scheduler_info()["workers"])
            for k, e in errors.items():
                a = self._where[jobs[k][0]]
                if a in alive:
                    raise RuntimeError(f"region {jobs[k][0]}: its DEM element failed on {a}: "
                                       f"{type(e).__name__}: {e}") from e
                lost.add(a)
            todo = [k for k in range(len(jobs)) if k not in results]
            if not todo:
                return [results[k] for k in range(len(jobs))]
            self._recover(lost, [jobs[k][0] for k in todo])
        raise RuntimeError(f"regions {[jobs[k][0] for k in todo]}: their workers were lost "
                           "three times; giving up")

    def _recover(self, lost: set, names: list) -> None:
        """New hosts for the regions of lost workers, on the workers alive now."""
        import time

        alive: set = set()
        for _ in range(100):  # (a LocalCluster restarts a killed worker: wait for one)
            alive = set(self.client.scheduler_info()["workers"])
            if alive:
                break
            time.sleep(0.1)
        for a in list(self._hosts):
            if a in lost or a not in alive:
                self._hosts.pop(a)
        self._start_hosts()
        addrs = sorted(self._hosts)
        for n in names:
            if self._where[n] not in self._hosts:
                self.recovered.append((n, self._where[n]))
                new = addrs[self.names.index(n) % len(addrs)]
                self.log(f"region {n}: its worker {self._where[n]} was lost; its element runs "
                         f"again on {new}, from the runner as it was sent")
                self._where[n] = new

    def close(self) -> None:
        if self._cluster is not None:
            try:
                self.client.close()
            finally:
                self._cluster.close()

    def __enter__(self) -> "RunnerPool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
