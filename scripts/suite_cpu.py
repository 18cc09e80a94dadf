#!/usr/bin/env python3
"""Where the test suite's CPU goes: runs pytest as `make test` does (two workers, a file per
worker, one OpenMP thread) with a plugin that records each test's CPU time, user and system,
of the test's own process and of the processes it started and waited for (case runs, Dask
workers, MPI ranks). Then prints the totals and the tests that took the most.

    .venv/bin/python scripts/suite_cpu.py [--top N] [--jobs N] [--out FILE] [PATH ...]

PATH: test files or folders (default: tests). --out: the JSON lines written (one per test:
id, worker, and su/ss/cu/cs, the process's and its children's user and system seconds, and
wall, s); default a temporary file. The wall time of a test is inflated when the other
worker shares the cores; its CPU time is not, which is why the suite's time is measured here
(docs/developing.md). A test's system time far above its run alone points at threads or
processes that wait by spinning.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def totals(rows: list[dict]) -> dict:
    """CPU seconds over ``rows``: all, the tests' own processes (user, system) and their
    children."""
    return {"cpu_s": sum(r["su"] + r["ss"] + r["cu"] + r["cs"] for r in rows),
            "own_user_s": sum(r["su"] for r in rows), "own_system_s": sum(r["ss"] for r in rows),
            "children_s": sum(r["cu"] + r["cs"] for r in rows), "tests": len(rows)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", default=["tests"])
    ap.add_argument("--top", type=int, default=25, help="tests to list, by CPU (default 25)")
    ap.add_argument("--jobs", type=int, default=2, help="pytest workers (default 2, as make test)")
    ap.add_argument("--out", type=Path, default=None, help="the JSON lines (default: a temp file)")
    a = ap.parse_args(argv)
    if a.top < 0 or a.jobs < 1:
        ap.error(f"--top={a.top} must be >= 0 and --jobs={a.jobs} >= 1")
    out = a.out or Path(tempfile.mkstemp(prefix="suite_cpu_", suffix=".jsonl")[1])
    out.write_text("")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OMP_WAIT_POLICY": "passive",
           "SUITE_CPU_OUT": str(out),
           "PYTHONPATH": os.pathsep.join([str(ROOT / "scripts"),
                                          os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
    workers = ["-n", str(a.jobs), "--dist", "loadfile"] if a.jobs > 1 else []
    cmd = [sys.executable, "-m", "pytest", "-q", *workers, "-p", "suite_cpu_plugin", *a.paths]
    code = subprocess.call(cmd, cwd=ROOT, env=env)
    rows = [json.loads(ln) for ln in out.read_text().splitlines() if ln.strip()]
    t = totals(rows)
    print(f"\n{t['tests']} tests: {t['cpu_s']:.0f} CPU-s, of which their own processes "
          f"{t['own_user_s']:.0f} user + {t['own_system_s']:.0f} system, their children "
          f"{t['children_s']:.0f}; rows in {out}")
    rows.sort(key=lambda r: -(r["su"] + r["ss"] + r["cu"] + r["cs"]))
    for r in rows[: a.top]:
        print(f"{r['su'] + r['ss'] + r['cu'] + r['cs']:8.1f} s  own {r['su']:6.1f}+{r['ss']:5.1f}"
              f"  children {r['cu']:6.1f}+{r['cs']:5.1f}  {r['id']}")
    return code


if __name__ == "__main__":
    sys.exit(main())
