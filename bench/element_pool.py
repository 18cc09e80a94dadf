#!/usr/bin/env python3
"""DEM elements on Dask workers (``cpp_dem.elements.pool``, issue 18): parallel efficiency on
1 and 2 local workers, and Dask's overhead per element call.

``--elements`` periodic elements of ``--grains`` grains are built on the workers; each load
step applies one strain increment to every element (a pure shear of ``--strain`` over
``--dem-steps`` DEM steps, no relaxation, so all elements do the same work), ``--steps`` load
steps after a warm-up step. Per load
step: the wall-clock time of the pool's call, and the DEM CPU time each element reported.

- efficiency on W workers = T(1 worker) / (W T(W workers)), per load step (median);
- Dask's overhead = (wall time - the busiest worker's DEM CPU time) / the busiest worker's
  DEM CPU time: what the actor calls, the transfer of increments and results and the
  scheduling cost on top of the DEM work.

    .venv/bin/python bench/element_pool.py
    .venv/bin/python bench/element_pool.py --elements 8 --grains 400
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

from _report import write_json  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))

from cpp_dem.elements.pool import ElementPool, PeriodicFactory  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def run(args, workers: int) -> dict:
    incs = [np.array([[0, 0, args.strain], [0, 0, 0], [args.strain, 0, 0]]) * 0.5
            for _ in range(args.elements)]
    # A fixed number of DEM steps per element and no relaxation, so every element does the
    # same work (with relaxation to a tolerance, one slow element sets the pace).
    kw = {"steps": args.dem_steps, "max_relax_steps": 0}
    with ElementPool.build(args.elements, PeriodicFactory(n=args.grains), workers=workers) as pool:
        pool.apply_strain(incs, **kw)  # warm-up
        pool.accept()
        walls, overheads, busiest = [], [], []
        for _ in range(args.steps):
            st = pool.apply_strain(incs, **kw)
            pool.accept()
            per_worker: dict = {}
            for k, cpu in enumerate(st.cpu_s):
                a = pool._where[k]
                per_worker[a] = per_worker.get(a, 0.0) + cpu
            b = max(per_worker.values())
            walls.append(st.wall_s)
            busiest.append(b)
            overheads.append((st.wall_s - b) / b)
        return {"workers": workers, "wall_s": walls, "busiest_cpu_s": busiest,
                "overhead": overheads, "median_wall_s": statistics.median(walls),
                "median_overhead": statistics.median(overheads),
                "dem_steps_per_element": st.steps}


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--elements", type=int, default=4)
    ap.add_argument("--grains", type=int, default=400)
    ap.add_argument("--strain", type=float, default=2e-3, help="shear strain per load step")
    ap.add_argument("--dem-steps", type=int, default=5000, help="DEM steps per increment")
    ap.add_argument("--steps", type=int, default=3, help="load steps timed")
    ap.add_argument("--out", default="results/bench_runs/element_pool.json")
    args = ap.parse_args(argv)
    res = {"args": vars(args)}
    for w in (1, 2):
        r = run(args, w)
        res[f"workers_{w}"] = r
        print(f"[pool] {w} worker(s): {r['median_wall_s']:.2f} s per load step, Dask overhead "
              f"{100 * r['median_overhead']:.1f} % of the busiest worker's DEM time "
              f"({r['dem_steps_per_element']} DEM steps per element)", flush=True)
    eff = res["workers_1"]["median_wall_s"] / (2 * res["workers_2"]["median_wall_s"])
    res["efficiency_2_workers"] = eff
    print(f"[pool] parallel efficiency on 2 workers: {100 * eff:.1f} %")
    print(f"[pool] wrote {write_json(args.out, res)}")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
