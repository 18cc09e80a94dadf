#!/usr/bin/env python3
"""What the element pool (``cpp_dem.elements.pool``, issue 37) costs the client and the
workers per element, measured, and projected to 1000 elements.

A scheduler and ``--workers`` single-threaded workers are started as their own processes
(``dask scheduler`` / ``dask worker`` with a scheduler file, as on a cluster), so this
process is the client alone. ``--elements`` periodic elements of ``--grains`` grains are
built; each load step applies a short increment (``--dem-steps`` DEM steps, no relaxation:
the DEM work is not what is measured) and accepts it, ``--steps`` times, once with the
default (states stay on the workers, spilled to their local disk) and once with
``keep_copies=True`` (every state also in the client). Then one more worker joins and the
next step moves elements to it.

Per element, per accepted load step (apply + accept):

- ``client_bytes``: what the client received (the payload: stresses, digests, states);
- ``client_cpu_s``: the client process's CPU seconds (its event loop included; fitted as
  a + b n over ``--scan`` element counts, see ``client_scan``);
- ``accept_s``: the wall-clock seconds of ``accept()``;

and per element: ``state_bytes`` (its accepted bytes), ``worker_rss_bytes`` (the growth of
a worker's resident memory per element it holds, over a worker that has run an element
once: the element, its accepted bytes and their buffers), ``spill_bytes`` (on the worker's disk: the last two accepts), ``held_bytes``
(element data the client keeps). The projection multiplies them by 1000; the client's CPU
is projected from the fit, with the calls of ``--cluster-workers`` workers.

    .venv/bin/python bench/pool_scaling.py
    .venv/bin/python bench/pool_scaling.py --elements 8 --grains 400 --steps 3

The last line printed is one JSON document of all the numbers.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))

from _report import emit, write_json  # noqa: E402

from cpp_dem.elements.pool import ElementPool, PeriodicFactory  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

DASK = str(Path(sys.executable).with_name("dask"))
PROJECTED = 1000  # elements


def _rss() -> int:
    import psutil

    return psutil.Process().memory_info().rss


def _warm() -> int:
    """Imports and runs once what a host runs (so the memory measured after is the
    elements'), then returns the worker's resident memory (bytes)."""
    from cpp_dem import set_num_threads
    from cpp_dem.elements.periodic import DemElement

    set_num_threads(1)
    el = DemElement.from_bytes(PeriodicFactory(n=30)(0).to_bytes())
    el.apply_strain(np.zeros((3, 3)), steps=10, max_relax_steps=0)
    el.network_tangent()
    del el
    return _rss()


class Cluster:
    """A scheduler and workers, each its own process, found through a scheduler file."""

    def __init__(self, folder: Path) -> None:
        self.sched = folder / "scheduler.json"
        self.env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
        self.procs = [subprocess.Popen(
            [DASK, "scheduler", "--scheduler-file", str(self.sched), "--port", "0",
             "--no-dashboard"], env=self.env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL)]
        for _ in range(300):
            if self.sched.exists():
                break
            time.sleep(0.1)

    def add_worker(self) -> None:
        self.procs.append(subprocess.Popen(
            [DASK, "worker", "--scheduler-file", str(self.sched), "--nthreads", "1",
             "--no-dashboard", "--memory-limit", "0"], env=self.env,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))

    def close(self) -> None:
        for p in self.procs[::-1]:
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()


def measure(client, args, keep_copies: bool, rss0: dict) -> dict:
    incs = [np.array([[0, 0, args.strain], [0, 0, 0], [args.strain, 0, 0]]) * 0.5
            for _ in range(args.elements)]
    kw = {"steps": args.dem_steps, "max_relax_steps": 0}
    with ElementPool.build(args.elements, PeriodicFactory(n=args.grains), client=client,
                           keep_copies=keep_copies) as pool:
        pool.apply_strain(incs, **kw)  # warm-up
        pool.accept()
        rows = []
        for _ in range(args.steps):
            got0, cpu0 = sum(pool.received_bytes().values()), time.process_time()
            pool.apply_strain(incs, **kw)
            t0 = time.perf_counter()
            pool.accept()
            rows.append({"accept_s": time.perf_counter() - t0,
                         "client_cpu_s": time.process_time() - cpu0,
                         "client_bytes": sum(pool.received_bytes().values()) - got0})
        mem = pool.memory()
        grown = [(m["rss_bytes"] - rss0[a]) / m["elements"] for a, m in mem.items()
                 if m["elements"]]
        sizes = [s.size_bytes for s in pool.saved_states()]
        folders = {Path(s.spill).parent for s in pool.saved_states()}  # (this machine's)
        spill = sum(f.stat().st_size for d in folders
                    for f in d.glob("element-*.g*.bin")) / args.elements
        n = args.elements
        out = {"keep_copies": keep_copies,
               "state_bytes": statistics.mean(sizes),
               # (measured on the first pool only: the next one's workers keep the memory
               # the first one freed)
               "worker_rss_bytes": None if keep_copies else statistics.mean(grown),
               "spill_bytes": spill,
               "held_bytes": pool.held_bytes() / n,
               "client_bytes": statistics.median(r["client_bytes"] for r in rows) / n,
               "client_cpu_s": statistics.median(r["client_cpu_s"] for r in rows) / n,
               "accept_s": statistics.median(r["accept_s"] for r in rows),
               "received_by_kind": pool.received_bytes()}
        return out


def late_worker(client, args) -> dict:
    """A pool on the workers there are; one more worker joins; the next step moves elements
    to it (worker to worker): the seconds that step took more than the one after, per
    element moved, and the bytes the client received for the move."""
    incs = [np.array([[0, 0, args.strain], [0, 0, 0], [args.strain, 0, 0]]) * 0.5
            for _ in range(args.elements)]
    kw = {"steps": args.dem_steps, "max_relax_steps": 0}
    with ElementPool.build(args.elements, PeriodicFactory(n=args.grains),
                           client=client) as pool:
        pool.apply_strain(incs, **kw)
        pool.accept()
        args.cluster.add_worker()
        client.wait_for_workers(args.workers + 1, timeout=300)
        t0 = time.perf_counter()
        pool.apply_strain(incs, **kw)
        with_move = time.perf_counter() - t0
        pool.accept()
        t0 = time.perf_counter()
        pool.apply_strain(incs, **kw)
        plain = time.perf_counter() - t0
        return {"moved": len(pool.moves), "workers": len(pool.workers()),
                "move_s_per_element": (with_move - plain) / max(1, len(pool.moves)),
                "move_client_bytes": pool.received_bytes().get("move", 0)}


def client_scan(client, args) -> dict:
    """The client's CPU seconds per accepted step (apply + accept, one actor call of each per
    host and one look at the workers) for ``--scan`` counts of tiny elements (30 grains: the
    client handles the same records whatever an element's size), on the same workers: the
    fit a + b n gives the cost per element (b) and per step (a; divided by the 2 W + 1 calls
    of a step on W workers: the cost per call)."""
    kw = {"steps": 10, "max_relax_steps": 0}
    rows = []
    for n in args.scan:
        incs = [np.array([[0, 0, args.strain], [0, 0, 0], [args.strain, 0, 0]]) * 0.5] * n
        with ElementPool.build(n, PeriodicFactory(n=30), client=client) as pool:
            pool.apply_strain(incs, **kw)
            pool.accept()
            cpu = []
            for _ in range(args.steps + 2):
                c0 = time.process_time()
                pool.apply_strain(incs, **kw)
                pool.accept()
                cpu.append(time.process_time() - c0)
            rows.append({"elements": n, "client_cpu_s": statistics.median(cpu),
                         "hosts": len(pool.workers())})
    (n1, c1), (n2, c2) = [(r["elements"], r["client_cpu_s"]) for r in (rows[0], rows[-1])]
    b = (c2 - c1) / (n2 - n1)
    a = c1 - b * n1
    return {"rows": rows, "per_element_s": b, "per_step_s": a,
            "per_call_s": a / (2 * rows[0]["hosts"] + 1)}


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--elements", type=int, default=8)
    ap.add_argument("--grains", type=int, default=400)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--strain", type=float, default=1e-4, help="shear strain per load step")
    ap.add_argument("--dem-steps", type=int, default=200, help="DEM steps per increment")
    ap.add_argument("--steps", type=int, default=3, help="load steps measured")
    ap.add_argument("--scan", type=int, nargs=2, default=[8, 64],
                    help="element counts (30 grains) of the client-load fit")
    ap.add_argument("--cluster-workers", type=int, default=128,
                    help="workers of the projected cluster (its calls per step)")
    ap.add_argument("--no-late", dest="late", action="store_false",
                    help="skip the late worker's move")
    ap.add_argument("--out", default="results/bench_runs/pool_scaling.json")
    args = ap.parse_args(argv)
    from dask.distributed import Client

    with tempfile.TemporaryDirectory() as tmp:
        cluster = args.cluster = Cluster(Path(tmp))
        try:
            for _ in range(args.workers):
                cluster.add_worker()
            client = Client(scheduler_file=str(cluster.sched))
            client.wait_for_workers(args.workers, timeout=300)
            rss0 = client.run(_warm)
            res = {}
            for keep in (False, True):
                res["copies" if keep else "default"] = r = measure(client, args, keep, rss0)
                print(f"[pool] keep_copies={keep}: per element and accepted step "
                      f"{r['client_bytes']:.0f} B and {1e3 * r['client_cpu_s']:.2f} ms of "
                      f"client CPU; state {r['state_bytes'] / 1e3:.0f} kB"
                      + ("" if keep else f", worker memory {r['worker_rss_bytes'] / 1e6:.2f} "
                         "MB per element"), flush=True)
            res["client_scan"] = r = client_scan(client, args)
            print(f"[pool] client CPU per accepted step: {1e3 * r['per_step_s']:.1f} ms "
                  f"+ {1e3 * r['per_element_s']:.3f} ms per element "
                  f"({1e3 * r['per_call_s']:.2f} ms per actor call)", flush=True)
            if args.late:
                res["late_worker"] = r = late_worker(client, args)
                print(f"[pool] a late worker: {r['moved']} elements moved to it, "
                      f"{r['move_s_per_element']:.3f} s each, {r['move_client_bytes']} B "
                      "through the client", flush=True)
            client.close()
        finally:
            cluster.close()
    del args.cluster
    d, c = res["default"], res["copies"]
    res["projection_1000"] = {
        "elements": PROJECTED, "grains": args.grains,
        "client_bytes_per_step": d["client_bytes"] * PROJECTED,
        "client_bytes_per_step_keep_copies": c["client_bytes"] * PROJECTED,
        "client_held_bytes": d["held_bytes"] * PROJECTED,
        "client_held_bytes_keep_copies": c["held_bytes"] * PROJECTED,
        "workers": args.cluster_workers,
        "client_cpu_s_per_step": (res["client_scan"]["per_call_s"]
                                  * (2 * args.cluster_workers + 1)
                                  + res["client_scan"]["per_element_s"] * PROJECTED),
        "worker_memory_bytes": d["worker_rss_bytes"] * PROJECTED,
        "spill_bytes": d["spill_bytes"] * PROJECTED}
    res["args"] = vars(args)
    p = res["projection_1000"]
    print(f"[pool] 1000 elements of {args.grains} grains: through the client per accepted "
          f"step {p['client_bytes_per_step'] / 1e6:.2f} MB (keep_copies: "
          f"{p['client_bytes_per_step_keep_copies'] / 1e9:.2f} GB), client CPU "
          f"{p['client_cpu_s_per_step']:.2f} s on {args.cluster_workers} workers,"
          f" workers' memory {p['worker_memory_bytes'] / 1e9:.2f} GB in all, spill "
          f"{p['spill_bytes'] / 1e9:.2f} GB", flush=True)
    print(f"[pool] wrote {write_json(args.out, res)}", flush=True)
    emit(res, None)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
