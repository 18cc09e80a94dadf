"""Cases' local process pools that stop when the run stops.

A case that runs packings or variants side by side in spawned processes uses
:func:`process_pool` and :func:`results_in_order`:

- **A stop ends the pool at once.** On Ctrl-C, SIGTERM or an error, the pool's processes are
  terminated and the jobs not yet started cancelled; the finished ones are kept (a
  ``ProcessPoolExecutor`` left to shut down by itself runs every queued job first).
- **The main thread keeps seeing signals.** A result is waited for in short timed waits, not
  one unbounded one. Python runs a signal's handler only when the main thread executes
  bytecode; with the FEM run in the main process first (its MPI and solver threads alive), a
  SIGTERM sent during ``ProcessPoolExecutor.map``'s unbounded wait was not acted on until a
  job finished: minutes to hours (measured: ``prs-element-002`` at smoke size, and a six-seed
  ensemble that ignored two SIGTERMs). With timed waits it stops within a second
  (tests/test_case_prs_element_002.py).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
from typing import Callable, Iterable, Iterator

#: The longest a wait for a result goes without letting a signal's handler run, s.
POLL_S = 0.5


@contextlib.contextmanager
def process_pool(n_proc: int) -> Iterator[concurrent.futures.ProcessPoolExecutor]:
    """A pool of ``n_proc`` spawned processes, ended at once by a stop (module docstring)."""
    ex = concurrent.futures.ProcessPoolExecutor(
        max_workers=n_proc, mp_context=multiprocessing.get_context("spawn"))
    try:
        yield ex
    except BaseException:
        procs = list((getattr(ex, "_processes", None) or {}).values())
        ex.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.join(timeout=10)
        raise
    ex.shutdown(wait=True)


def results_in_order(ex: concurrent.futures.Executor, fn: Callable, *iterables: Iterable,
                     poll_s: float = POLL_S) -> Iterator:
    """``ex.map(fn, *iterables)``, its results in order as each is done, waited for in timed
    waits of ``poll_s`` (s) so that a signal's handler runs within about ``poll_s`` (module
    docstring). A job's error is raised when its turn comes."""
    futures = [ex.submit(fn, *args) for args in zip(*iterables)]
    for f in futures:
        yield wait_result(f, poll_s)


def wait_result(f: concurrent.futures.Future, poll_s: float = POLL_S):
    """``f.result()``, waited for in timed waits of ``poll_s`` (s) (module docstring)."""
    while True:
        try:
            return f.result(timeout=poll_s)
        except concurrent.futures.TimeoutError:
            continue
