#!/usr/bin/env python3
"""Cost per step of clumps against the same spheres free (issue 15: a clump of k members
costs at most 1.3 x k free spheres per step). Not a test: prints a table and JSON lines.

The packing: --clumps clumps of a three-sphere template whose members do not overlap (so the
same spheres can also run free without initial overlaps), dropped in a box under gravity and
settled (local damping 0.3). From that state every block builds two scenes with the same
spheres, velocities, walls and dt: A, the clumps; B, the members as free spheres (a settled
clump pile released as spheres slumps, so B is timed only over --steps steps from the shared
state, while its contacts are still A's; the pairs of members inside a clump, which A never
pairs, are B's extra candidates). Each block times --steps steps after --warmup untimed
ones (CPU time); blocks alternate A | B, B | A, ... for --rounds rounds, so a drift of the
machine's load cancels in the ratio.

    .venv/bin/python bench/clump_cost.py                    # 2000 clumps, 1 thread
    .venv/bin/python bench/clump_cost.py --clumps 4000 --threads 2
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

import cpp_dem as dem
import sys
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)
try:  # the package layout of the revision under test (bench/ab_build.py runs older ones too)
    from cpp_dem.build.clumps import ClumpTemplate, clump_cloud
except ImportError:
    from cpp_dem.clumps import ClumpTemplate, clump_cloud


def template():
    r = 0.002
    return ClumpTemplate.from_spheres([[-1.02 * r, 0, 0], [1.02 * r, 0, 0], [0, 1.8 * r, 0]],
                                      [r, r, 0.9 * r], name="tri3")


def settled(n: int, seed: int, free: bool = False):
    """The clump pile settled under gravity; with ``free``, the same spheres (the members of
    the same loose cloud) as free spheres, settled the same way."""
    tpl = template()
    side = (n * 1.2e-7) ** (1 / 3) * 1.6
    sc = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
    mat = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                              friction_angle_deg=30))
    lo, hi = np.zeros(3), np.array([side, side, 3 * side])
    sc.add_box(lo, hi, material=mat)
    cloud = clump_cloud(tpl, np.full(n, tpl.equivalent_diameter), lo, hi, seed=seed)
    cloud.add_to(sc, tpl, material=mat)
    if free:
        pos, rad = sc.positions, sc.radii
        sc = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
        mat = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                                  friction_angle_deg=30))
        sc.add_box(lo, hi, material=mat)
        sc.add_spheres(pos, rad, material=mat)
    sc.set_auto_timestep(safety=0.5, period=100)
    t = 0
    while t < 40:  # settle to a quiet pile (unbalanced force below 0.05) or 40 rounds
        sc.run(2000)
        t += 1
        u = sc.unbalanced_force()
        if np.isfinite(u) and u < 0.05 and t > 5:
            break
    return sc, (lo, hi), mat


def dense(n: int, seed: int, pressure: float):
    """The clumps compacted by servo walls to the isotropic ``pressure`` (Pa) without gravity
    and frictionless (so no contact carries shear history), to an unbalanced force of 1e-3;
    then the grains' friction (30 deg) back on. A confined pack: more contacts per member
    than the gravity pile."""
    from cpp_dem.protocols import prep

    tpl = template()
    side = (n * 1.2e-7) ** (1 / 3) * 1.6
    sc = dem.Scene(local_damping=0.3)
    mat = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                              friction_angle_deg=30))
    lo, hi = np.zeros(3), np.array([side, side, 3 * side])
    walls = sc.add_box(lo, hi, material=mat)
    cloud = clump_cloud(tpl, np.full(n, tpl.equivalent_diameter), lo, hi, seed=seed)
    cloud.add_to(sc, tpl, material=mat)
    sc.set_auto_timestep(safety=0.5, period=100)
    prep.set_friction(sc, range(sc.num_bodies), sc.material(mat), 0.0)
    res = prep.compact_isotropic(sc, walls, pressure, unbalanced=1e-3)
    if not res.converged:
        raise SystemExit(f"error: --pressure={pressure:g}: not reached ({res.axis_stresses})")
    res.extra["controller"].enabled = False
    for b in range(sc.num_bodies):
        sc.set_body_material(b, mat)
    return sc, (lo, hi), mat


def clone(src, free: bool, hi, hold: bool = False):
    """A new scene with src's spheres (positions, velocities, spins), as clumps or free, and
    src's gravity and wall positions. ``hold``: the free spheres 1e6 times denser, so that
    over a few steps they stay where the clumps held them and keep the clumps' contacts (a
    free sphere's arithmetic per step does not depend on its mass)."""
    sc = dem.Scene(gravity=tuple(src.gravity), local_damping=0.3)
    rho = 2650 * (1e6 if (free and hold) else 1)
    mat = sc.add_material(dem.linear_material(density=rho, young=5e7, poisson=0.3,
                                              friction_angle_deg=30))
    walls = sc.add_box((0, 0, 0), hi, material=mat)
    for w, x in zip(walls, np.asarray(src.wall_positions)):
        sc.set_wall_position(int(w), float(x))
    if free:
        sc.add_spheres(src.positions, src.radii, material=mat)
        sc.velocities = src.velocities
        sc.angular_velocities = src.angular_velocities
    else:
        tpl = template()
        # set_clump_state sets the principal frame itself (add_clumps' orientation is the
        # template frame's): the clumps and their members are where src has them.
        for c in range(src.num_clumps):
            sc.add_clumps(tpl, src.clump_positions[c:c + 1], material=mat)
            sc.set_clump_state(c, src.clump_positions[c], src.clump_orientations[c],
                               src.clump_velocities[c], src.clump_angular_velocities[c])
    sc.dt = src.dt
    return sc


def main() -> int:
    ap = _cli.BenchParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clumps", type=int, default=2000)
    ap.add_argument("--mode", choices=("settled", "same-state"), default="settled",
                    help="settled: each pile settled on its own, timed at rest; same-state: "
                         "both from the clump pile's state, timed over --steps steps")
    ap.add_argument("--pack", choices=("gravity", "dense"), default="gravity",
                    help="same-state mode's shared state: the pile settled under gravity, or "
                         "a dense pack compacted to --pressure by servo walls (no gravity)")
    ap.add_argument("--pressure", type=float, default=100e3, help="dense pack's stress, Pa")
    ap.add_argument("--hold", action="store_true",
                    help="same-state mode: the free spheres 1e6 times denser, so they keep "
                         "the clumps' contacts over the timed steps (like for like)")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=6)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    dem.set_num_threads(args.threads)
    if args.mode == "settled":
        # Each pile settled on its own (the clumps' and the same spheres' free), then timed
        # where it rests, at the same fixed dt (the smaller of the two auto steps).
        a, _, _ = settled(args.clumps, args.seed)
        b, _, _ = settled(args.clumps, args.seed, free=True)
        a.set_auto_timestep(safety=0.5, period=0)
        b.set_auto_timestep(safety=0.5, period=0)
        a.dt = b.dt = min(a.dt, b.dt)
        ta, tb, ca, cb = [], [], [], []
        for k in range(args.rounds):
            for sc in ((a, b) if k % 2 == 0 else (b, a)):
                t0 = time.process_time()
                sc.run(args.steps)
                (ta if sc is a else tb).append((time.process_time() - t0) / args.steps)
                (ca if sc is a else cb).append(sc.num_active_contacts)
    else:
        src, (lo, hi), _ = (settled(args.clumps, args.seed) if args.pack == "gravity"
                            else dense(args.clumps, args.seed, args.pressure))
        ta, tb, ca, cb = [], [], [], []
        for k in range(args.rounds):
            for free in ((False, True) if k % 2 == 0 else (True, False)):
                sc = clone(src, free=free, hi=hi, hold=args.hold)
                sc.run(args.warmup)  # contacts formed, lists built
                t0 = time.process_time()
                sc.run(args.steps)
                (tb if free else ta).append((time.process_time() - t0) / args.steps)
                (cb if free else ca).append(sc.num_active_contacts)
                if not free:
                    a = sc
    k_members = a.num_bodies
    res = {"mode": args.mode, "pack": args.pack, "hold": args.hold, "clumps": a.num_clumps,
           "spheres": k_members, "threads": args.threads,
           "steps_per_block": args.steps, "rounds": args.rounds,
           "clump_us_per_step": 1e6 * statistics.median(ta),
           "free_us_per_step": 1e6 * statistics.median(tb),
           "ratio_clumps_over_free": statistics.median(ta) / statistics.median(tb),
           "ratio_min": min(x / y for x, y in zip(ta, tb)),
           "ratio_max": max(x / y for x, y in zip(ta, tb)),
           "contacts_clumps": int(np.median(ca)), "contacts_free": int(np.median(cb))}
    print("| clumps | spheres | threads | clumps us/step | free spheres us/step | ratio (min-max) | contacts clumps / free |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {res['clumps']} | {k_members} | {args.threads} | {res['clump_us_per_step']:.1f} | "
          f"{res['free_us_per_step']:.1f} | {res['ratio_clumps_over_free']:.3f} "
          f"({res['ratio_min']:.3f}-{res['ratio_max']:.3f}) | {res['contacts_clumps']} / {res['contacts_free']} |")
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
