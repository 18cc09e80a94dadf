"""The Dask plumbing of the element pool (`cpp_dem.elements.pool`, which also hosts the
two-way loop's regions): a local cluster, a client for a running scheduler, the
workers there now and waiting for a number of them, a check that an object can be sent to the
workers, and closing a pool that fails while starting."""

from __future__ import annotations

import contextlib
from pathlib import Path

from cpp_dem._core import ParameterError

def local_client(workers: int):
    """(client, cluster): a ``LocalCluster`` of ``workers`` single-threaded worker processes on
    this machine (Dask spawns them: no fork of an MPI/PETSc process), no dashboard."""
    from dask.distributed import Client, LocalCluster

    if not (isinstance(workers, int) and workers >= 1):
        raise ParameterError(f"workers={workers!r}: must be an integer >= 1")
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    return Client(cluster), cluster


def dask_client(scheduler: str | None, workers: int):
    """(client, cluster): the running scheduler at ``scheduler`` (an address such as
    ``tcp://head:8786``, or the path of a scheduler file that ``dask scheduler
    --scheduler-file``, ``dask-mpi`` or a batch script wrote; cluster None), else
    ``local_client(workers)``."""
    from dask.distributed import Client

    if not scheduler:
        return local_client(workers)
    path = Path(scheduler).expanduser()
    if "://" not in scheduler and path.is_file():
        return Client(scheduler_file=str(path)), None
    if "://" not in scheduler and ":" not in scheduler:
        raise ParameterError(f"scheduler={scheduler!r}: neither an address (tcp://host:port) "
                             "nor an existing scheduler file")
    return Client(scheduler), None


def alive_workers(client) -> list:
    """The addresses of the workers the scheduler has now, sorted (one small message: the
    scheduler's thread count per worker, not its whole worker table)."""
    return sorted(client.nthreads())


def wait_for_workers(client, n: int, timeout_s: float) -> None:
    """Waits until the cluster of ``client`` has at least ``n`` workers (a batch system's
    jobs start when the queue lets them); after ``timeout_s`` seconds raises a RuntimeError
    saying how many came."""
    if not (isinstance(n, int) and n >= 1):
        raise ParameterError(f"min_workers={n!r}: an integer >= 1")
    try:
        client.wait_for_workers(n, timeout=timeout_s)
    except TimeoutError as e:
        raise RuntimeError(f"min_workers={n}: only {len(alive_workers(client))} worker(s) "
                           f"joined within timeout_s={timeout_s:g} s") from e


def check_sendable(obj, name: str) -> None:
    """Refuses what Dask cannot send to a worker (an actor call with it would wait forever:
    the error stays in Dask's communication thread)."""
    from distributed.protocol import pickle as dask_pickle

    try:
        dask_pickle.dumps(obj)
    except Exception as exc:  # noqa: BLE001  (whatever pickling raises)
        raise ParameterError(f"{name}={obj!r:.200}: cannot be sent to the Dask workers "
                             f"({type(exc).__name__}: {exc}); every part of it must "
                             "pickle") from exc


@contextlib.contextmanager
def closed_on_error(pool):
    """A failure while ``pool`` (anything with ``close()``) starts closes it: its own cluster
    stops (else its worker processes outlive the error and the interpreter does not exit)."""
    try:
        yield
    except BaseException:
        pool.close()
        raise
__all__ = ["alive_workers", "check_sendable", "closed_on_error", "dask_client", "local_client",
           "wait_for_workers"]
