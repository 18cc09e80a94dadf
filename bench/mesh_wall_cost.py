#!/usr/bin/env python3
"""Cost per step of a triangle-mesh box against the six plane walls of the same box (issue 65
item 5: a mesh of 1e4 triangles should cost little more per step than six planes for the same
grains). Not a test: prints a table and JSON lines.

The grains: --grains spheres settled under gravity in a box of six plane walls (local damping
0.3), until no grain moves faster than 0.01 m/s. From that state every block builds one of two scenes with the same spheres, velocities
and dt: A, the six plane walls; B, the same box as one mesh wall whose faces are cut into
--cells x --cells squares of two triangles each (12 cells^2 triangles: 10 092 at the default
29). Each block times --steps steps after --warmup untimed ones (CPU time); blocks alternate
A | B, B | A, ... for --rounds rounds, so a drift of the machine's load cancels in the ratio.

    .venv/bin/python bench/mesh_wall_cost.py                  # 2000 grains, 10 092 triangles
    .venv/bin/python bench/mesh_wall_cost.py --grains 8000 --cells 40
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import cpp_dem as dem

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)
from cpp_dem.build.packing import loose_cloud  # noqa: E402

R = 0.002  # m


def _material(sc):
    return sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                               friction_angle_deg=30))


def box_mesh(lo, hi, cells: int):
    """The six faces of the box [lo, hi] (m), each cut into cells x cells squares of two
    triangles: (vertices, triangles)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, tris = [], []
    s = np.linspace(0.0, 1.0, cells + 1)
    for axis in range(3):
        a1, a2 = (axis + 1) % 3, (axis + 2) % 3
        for side in (lo[axis], hi[axis]):
            base = len(verts)
            for v in s:
                for u in s:
                    p = np.empty(3)
                    p[axis] = side
                    p[a1] = lo[a1] + u * (hi[a1] - lo[a1])
                    p[a2] = lo[a2] + v * (hi[a2] - lo[a2])
                    verts.append(p)
            for j in range(cells):
                for i in range(cells):
                    a = base + j * (cells + 1) + i
                    tris += [[a, a + 1, a + cells + 2], [a, a + cells + 2, a + cells + 1]]
    return np.array(verts), tris


def settled(n: int, seed: int):
    side = (n * 4.2e-8) ** (1 / 3) * 1.7
    lo, hi = np.zeros(3), np.array([side, side, 2.5 * side])
    sc = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
    mat = _material(sc)
    sc.add_box(lo, hi, material=mat)
    c, r = loose_cloud(np.full(n, R), lo, hi, seed=seed)
    sc.add_spheres(c, r, material=mat)
    sc.dt = 0.3 * sc.critical_dt()
    for _ in range(60):  # until the pile rests (a fall is another measure: rebuild-bound)
        sc.run(5000)
        if np.abs(np.asarray(sc.velocities)).max() < 0.01:  # m/s
            break
    return lo, hi, np.asarray(sc.positions), np.asarray(sc.radii), np.asarray(sc.velocities), sc.dt


def scene(kind: str, state, cells: int):
    lo, hi, x, r, v, dt = state
    sc = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
    mat = _material(sc)
    if kind == "planes":
        sc.add_box(lo, hi, material=mat)
    else:
        sc.add_mesh_wall(*box_mesh(lo, hi, cells), material=mat)
    sc.add_spheres(x, r, material=mat)
    sc.velocities = v
    sc.dt = dt
    return sc


def timed(kind: str, state, cells: int, warmup: int, steps: int) -> float:
    sc = scene(kind, state, cells)
    sc.run(warmup)
    t0 = time.process_time()
    sc.run(steps)
    return (time.process_time() - t0) / steps


def main() -> None:
    ap = _cli.BenchParser(description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grains", type=int, default=2000, help="spheres in the box")
    ap.add_argument("--cells", type=int, default=29, help="squares along each face's side")
    ap.add_argument("--steps", type=int, default=2000, help="timed steps per block")
    ap.add_argument("--warmup", type=int, default=200, help="untimed steps per block")
    ap.add_argument("--rounds", type=int, default=4, help="A | B rounds")
    ap.add_argument("--threads", type=int, default=1, help="core threads")
    ap.add_argument("--seed", type=int, default=1, help="the packing's seed")
    a = ap.parse_args()
    dem.set_num_threads(a.threads)
    state = settled(a.grains, a.seed)
    ratios, t_plane, t_mesh = [], [], []
    for k in range(a.rounds):
        order = ("planes", "mesh") if k % 2 == 0 else ("mesh", "planes")
        t = {kind: timed(kind, state, a.cells, a.warmup, a.steps) for kind in order}
        t_plane.append(t["planes"])
        t_mesh.append(t["mesh"])
        ratios.append(t["mesh"] / t["planes"])
        print(f"[mesh_wall_cost] round {k}: planes {1e6 * t['planes']:.1f} us/step, mesh "
              f"{1e6 * t['mesh']:.1f} us/step, mesh/planes {ratios[-1]:.3f}", flush=True)
    row = {"grains": a.grains, "triangles": 12 * a.cells**2, "threads": a.threads,
           "steps": a.steps, "rounds": a.rounds,
           "planes_us_per_step": 1e6 * statistics.median(t_plane),
           "mesh_us_per_step": 1e6 * statistics.median(t_mesh),
           "mesh_over_planes": statistics.median(ratios),
           "ratio_min": min(ratios), "ratio_max": max(ratios)}
    print(json.dumps(row))


if __name__ == "__main__":
    sys.exit(_cli.run(main))
