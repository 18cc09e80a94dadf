#!/usr/bin/env python3
"""Cost of a periodic step against a wall-bounded step at the same N and coordination
(issue 17: at most 1.15 x).

Both samples are N spheres of the same PSD and material, prepared to the same isotropic
stress (the periodic one by ``periodic.prepare_periodic``, the wall-bounded one by
``DemElement.box``: radius growth and servo walls in a box of six frictionless walls). Each is
then timed (1 thread, CPU time of this process) in alternating blocks of ``--steps`` steps,
``--rounds`` rounds, in three modes:

- ``hold``: the boundary held (L = 0; the walls still);
- ``strain``: a slow volume-preserving compression at the same strain rate (the periodic cell
  by its velocity gradient, which adds the mean field's pass over the bodies; the box by its
  walls' velocities).

The coordination numbers are reported beside the times: the box has fewer contacts near its
walls, so the ratio is also given per contact.

    .venv/bin/python bench/periodic_cost.py                      # N = 2000
    .venv/bin/python bench/periodic_cost.py --n 4000 --rounds 5
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from _report import write_json  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))

import cpp_dem as dem  # noqa: E402
from cpp_dem import measure  # noqa: E402
from cpp_dem.elements.periodic import DemElement  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--rate", type=float, default=0.5, help="strain rate in 'strain', 1/s")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="results/bench_runs/periodic_cost.json")
    args = ap.parse_args(argv)
    dem.set_num_threads(1)
    t0 = time.perf_counter()
    per = DemElement.periodic(args.n, seed=args.seed)
    box = DemElement.box(args.n, seed=args.seed)
    print(f"[cost] prepared both in {time.perf_counter() - t0:.1f} s", flush=True)
    # The same fixed dt for both (the smaller of their estimates).
    dt = min(per.scene.dt, box.scene.dt)
    for el in (per, box):
        el.scene.set_auto_timestep(0.5, 0)
        el.scene.dt = dt
        el.scene.dt_check_period = 0
    res = {"n": args.n, "dt": dt, "modes": {}}
    for mode in ("hold", "strain"):
        if mode == "strain":
            r = args.rate
            per.scene.velocity_gradient = np.diag([r / 2, r / 2, -r])
            box.controller.enabled = True
            for a, v in enumerate((-r / 2, -r / 2, r)):  # engineering, compression positive
                box.controller.set_strain_rate(a, v)
        times = {"periodic": [], "walls": []}
        contacts = {"periodic": [], "walls": []}
        for k in range(args.rounds):
            order = (("periodic", per), ("walls", box)) if k % 2 == 0 else \
                (("walls", box), ("periodic", per))
            for name, el in order:
                c0 = time.process_time()
                el.scene.run(args.steps)
                times[name].append((time.process_time() - c0) / args.steps)
                contacts[name].append(el.contact_count())
        ratios = [p / w for p, w in zip(times["periodic"], times["walls"])]
        zc = {name: 2.0 * statistics.mean(contacts[name]) / args.n for name in contacts}
        per_contact = [(p / statistics.mean(contacts["periodic"])) /
                       (w / statistics.mean(contacts["walls"]))
                       for p, w in zip(times["periodic"], times["walls"])]
        rec = {"periodic_us_per_step": 1e6 * statistics.median(times["periodic"]),
               "walls_us_per_step": 1e6 * statistics.median(times["walls"]),
               "ratio_periodic_over_walls": statistics.median(ratios),
               "ratio_min": min(ratios), "ratio_max": max(ratios),
               "contacts_per_grain_periodic": zc["periodic"],
               "contacts_per_grain_walls": zc["walls"],
               "ratio_per_contact": statistics.median(per_contact)}
        res["modes"][mode] = rec
        print(f"[cost] {mode}: periodic {rec['periodic_us_per_step']:.1f} us/step "
              f"(Z {zc['periodic']:.2f}), walls {rec['walls_us_per_step']:.1f} us/step "
              f"(Z {zc['walls']:.2f}): ratio {rec['ratio_periodic_over_walls']:.3f} "
              f"({min(ratios):.3f}-{max(ratios):.3f}), per contact "
              f"{rec['ratio_per_contact']:.3f}", flush=True)
    res["box_porosity"] = measure.porosity(box.scene, box.walls)
    res["cell_porosity"] = measure.porosity(per.scene, ())
    print(f"[cost] wrote {write_json(args.out, res)}")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
