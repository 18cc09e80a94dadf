#!/usr/bin/env python3
"""Automatic threads (``--threads 0``) against one thread and every core, on a case's smoke.

For each case it runs ``python cases/<case>.py --smoke`` with ``--threads 1``, ``--threads
N`` (every core) and ``--threads 0`` (automatic: ``cpp_dem.apply_threads``), in alternating
blocks, quiet or with other work keeping ``--busy K`` cores busy (``K`` spinning processes
started by this script), and prints one JSON line per case and condition: each variant's
best and median wall seconds and their ratios to one thread's (below 1: faster than one
thread). The point of automatic threads is that its ratio never exceeds 1 (issue 63 item 4).

Usage (from the repository root, in the project venv):
    python bench/threads_auto.py                          # pullout-000, quiet and 1 busy
    python bench/threads_auto.py --cases pullout-000 triaxial --blocks 3 --busy 0 1
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))  # (the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def _spin() -> None:  # (other work on a core)
    while True:
        pass


def _run(case: str, threads: int, out: Path) -> float:
    script = ROOT / "cases" / f"{case.replace('-', '_')}.py"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, str(script), "--smoke", "--threads", str(threads),
                    "--out", str(out), "--overwrite"], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def measure(case: str, busy: int, blocks: int, cores: int) -> dict:
    """Every variant ``blocks`` times, alternating, with ``busy`` spinning processes."""
    import multiprocessing as mp

    hogs = [mp.Process(target=_spin, daemon=True) for _ in range(busy)]
    for h in hogs:
        h.start()
    variants = {"one": 1, "every_core": cores, "automatic": 0}
    times: dict = {k: [] for k in variants}
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for _ in range(blocks):
                for k, t in variants.items():
                    times[k].append(_run(case, t, Path(tmp) / k))
    finally:
        for h in hogs:
            h.terminate()
    best = {k: min(v) for k, v in times.items()}
    return {"case": case, "busy_cores": busy, "cores": cores, "blocks": blocks,
            "best_s": best, "median_s": {k: statistics.median(v) for k, v in times.items()},
            "ratio_to_one_thread": {k: round(best[k] / best["one"], 3) for k in best},
            "median_ratio_to_one_thread": {
                k: round(statistics.median(v) / statistics.median(times["one"]), 3)
                for k, v in times.items()}}


def main(argv=None) -> None:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0], zero_ok={"busy"})
    ap.add_argument("--cases", nargs="+", default=["pullout-000"],
                    help="cases whose --smoke is timed (default: pullout-000)")
    ap.add_argument("--busy", type=int, nargs="+", default=[0, 1],
                    help="cores kept busy by other work, one condition each (default: 0 1)")
    ap.add_argument("--blocks", type=int, default=3, help="alternating blocks (default: 3)")
    a = ap.parse_args(argv)
    cores = len(os.sched_getaffinity(0))
    if a.blocks < 1 or any(b < 0 or b >= cores for b in a.busy):
        ap.error(f"--blocks must be >= 1 and --busy in [0, {cores - 1}] ({cores} cores)")
    from geogrid_dem.cases import CASES

    scripts = sorted(CASES)
    for case in a.cases:
        if case not in scripts:
            raise _cli.BenchInputError(f"--cases={case}: no such case; one of "
                                       f"{', '.join(scripts)}")
    for case in a.cases:
        for busy in a.busy:
            print(json.dumps(measure(case, busy, a.blocks, cores)), flush=True)


if __name__ == "__main__":
    sys.exit(_cli.run(main))
