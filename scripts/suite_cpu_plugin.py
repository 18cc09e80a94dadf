"""The pytest plugin of scripts/suite_cpu.py: appends a JSON line per test to the file named by
SUITE_CPU_OUT, with the CPU seconds (user su, system ss) of the test's process and of the
children it waited for (cu, cs) over the test's set-up, call and tear-down, the wall seconds
and the pytest-xdist worker. A session-scoped fixture's cost is counted in the first test
that asks for it."""

from __future__ import annotations

import json
import os
import resource
import time

import pytest


def _usage() -> tuple:
    s = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime, s.ru_stime, c.ru_utime, c.ru_stime, time.perf_counter()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    before = _usage()
    yield
    d = [b - a for a, b in zip(before, _usage())]
    path = os.environ.get("SUITE_CPU_OUT")
    if path:
        row = {"id": item.nodeid, "worker": os.environ.get("PYTEST_XDIST_WORKER", "master"),
               "su": d[0], "ss": d[1], "cu": d[2], "cs": d[3], "wall": d[4]}
        with open(path, "a") as fh:  # (one short line per write: the workers' lines stay whole)
            fh.write(json.dumps(row) + "\n")
