"""The two-way loop's regions on Dask workers: a compatibility name for the one pool.

``RunnerPool(runner, names)`` is ``cpp_dem.elements.pool.ElementPool.runners(runner, names)``
(each region a ``cpp_dem.elements.interface.RunnerElement``: late workers get regions, a lost
worker's regions restart from their state at the last accept, or from the runner as sent when
it keeps no byte state; see that module's doc) with the call the two-way loop made before it
used the pool directly: ``run(jobs)`` runs ``runner(name, initial, final)`` for every job
``(name, initial, final)``, accepts, and returns the answers in job order. No hosts or
recovery of its own. SI units.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from cpp_dem._core import ParameterError
from cpp_dem.elements.pool import ElementPool

from femcoupling.coupling._inputs import check_client

__all__ = ["RunnerPool"]


class RunnerPool:
    """``ElementPool.runners(runner, names, workers=, client=, log=, **options)`` (``.pool``,
    whose other attributes it passes on) with ``run(jobs)`` taking (name, initial, final)
    per region (any subset, any order) and accepting after it; ``names``: the regions.
    ``client``: None (a LocalCluster of ``workers`` processes) or a
    ``dask.distributed.Client``; anything else (an address: its client is
    ``cpp_dem.elements.cluster.dask_client(address, 0)[0]``) is refused (FemInputError)."""

    def __init__(self, runner: Callable, names: Sequence[str], **options: Any) -> None:
        check_client(options.get("client"))
        self.pool = ElementPool.runners(runner, names, **options)
        self.names = list(names)

    def __getattr__(self, name: str) -> Any:  # workers(), recoveries, moves, client, ...
        if name == "pool":  # (not built: no pool to pass on to)
            raise AttributeError(name)
        return getattr(self.pool, name)

    def run(self, jobs: Sequence[tuple]) -> list:
        """``jobs``: (name, initial, final) per region; the answers in job order."""
        calls: list = [None] * len(self.names)
        for job in jobs:
            if job[0] not in self.names:
                raise ParameterError(f"jobs: region {job[0]!r} is not one of this pool's "
                                     f"names {self.names}")
            calls[self.names.index(job[0])] = tuple(job[1:])
        out = self.pool.run(calls)
        self.pool.accept()
        return [out[self.names.index(job[0])] for job in jobs]

    def close(self) -> None:
        self.pool.close()

    def __enter__(self) -> "RunnerPool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
