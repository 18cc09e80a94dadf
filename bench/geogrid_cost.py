"""Cost per step of a geogrid of ~10^4 members in ~10^4 grains, against the same grains
without the geogrid (issue: deformable geogrid). Not a test: prints JSON lines.

    .venv/bin/python bench/geogrid_cost.py [--grains 10000] [--nodes 71] [--steps 2000]

Both scenes are built the same way (same grains, same box, same dt: the grid scene's
critical step), settled for a few hundred steps, then timed over --steps steps in the same
process. The ratio is time per step with grid / without.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

import cpp_dem as dem
from cpp_dem.build import geogrid
import sys
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def build(n_grains: int, nodes: int, with_grid: bool, seed: int = 1):
    r = 0.0045
    rc = 1e-3
    spacing = 2 * r - 1e-5  # grains touch: the timed steps have a full contact network
    per_side = nodes
    side = 0.35
    n_xy = int(side / spacing)
    layers = max(2, int(math.ceil(n_grains / n_xy**2)))
    below = layers // 2
    if n_grains <= below * n_xy**2:
        raise ValueError(f"n_grains={n_grains}: the scene puts the first {below * n_xy**2} "
                         f"grains ({below} layer(s) of {n_xy} x {n_xy}) below the grid; give "
                         "more, so that grains lie above it too (the box's top follows them)")
    rng = np.random.default_rng(seed)
    s = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
    sand = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                              friction_angle_deg=30))
    grid_mat = s.add_material(dem.linear_material(density=100, young=4e9, poisson=0.3,
                                                  friction_angle_deg=20))
    z_below_top = r + (below - 1) * spacing + r
    z_grid = z_below_top + rc - 1e-5  # the grid touches the grains below and above
    ij = np.stack(np.meshgrid(np.arange(n_xy), np.arange(n_xy), indexing="ij"), -1).reshape(-1, 2)
    centres = []
    for k in range(layers):
        z = r + k * spacing
        if k >= below:
            z = z_grid + rc + r - 1e-5 + (k - below) * spacing
        xy = 0.003 + r + ij * spacing
        centres.append(np.column_stack([xy, np.full(len(xy), z)]))
    c = np.vstack(centres)[:n_grains]
    c[:, :2] += rng.uniform(-1e-6, 1e-6, (len(c), 2))
    top = c[:, 2].max() + r - 1e-5
    s.add_box((0, 0, 0), (side + 0.01, side + 0.01, top), material=sand)
    s.add_spheres(c, np.full(len(c), r), material=sand)
    g = None
    if with_grid:
        p = dem.BeamParams(young=4e9, poisson=0.3, radius=rc)
        g = geogrid.square_grid(s, origin=(0.005, 0.005, z_grid), length=side - 0.01,
                                width=side - 0.01, nodes_x=per_side, nodes_y=per_side, params=p,
                                material=grid_mat, unit_weight=981, node_density_scale=100.0)
    return s, g


def main() -> None:
    ap = _cli.BenchParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grains", type=int, default=10000)
    ap.add_argument("--nodes", type=int, default=71, help="grid nodes per side (71: 9940 members)")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--threads", type=int, default=dem.get_num_threads())
    args = ap.parse_args()
    dem.set_num_threads(args.threads)
    with_grid, g = build(args.grains, args.nodes, True)
    dt = 0.5 * with_grid.critical_dt()
    without, _ = build(args.grains, args.nodes, False)
    results = {}
    for name, s in (("without_grid", without), ("with_grid", with_grid)):
        s.dt = dt
        s.run(300)  # settle the first contacts and the first broad-phase builds
        t0 = time.perf_counter()
        s.run(args.steps)
        el = time.perf_counter() - t0
        results[name] = el / args.steps
        print(json.dumps({"scene": name, "n_grains": int(np.sum(np.array(s.body_kinds) == 0)),
                          "n_members": s.num_grid_links, "threads": args.threads,
                          "steps": args.steps, "dt_s": dt, "s_per_step": el / args.steps,
                          "active_contacts": s.num_active_contacts,
                          "grid_contacts": len(s.grid_contacts()["sphere"]),
                          "collider": s.collider_stats()}), flush=True)
    print(json.dumps({"ratio_with_over_without": results["with_grid"] / results["without_grid"]}))


if __name__ == "__main__":
    sys.exit(_cli.run(main))
