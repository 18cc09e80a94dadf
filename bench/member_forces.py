#!/usr/bin/env python3
"""The geogrid's member forces, A/B: ``Geogrid.member_axial_forces`` (one pass over every
member's section links) against the loop over the members it replaced, on the same scene.

The scene is the prestressed-element case's grid (``cases/prs_element.py``: a square grid of
cylinders, 10 x 10 nodes, 0.1 m square), loaded by random node forces and run a few hundred
steps, so that every link carries a force. The two are timed in alternating blocks of
``--calls`` calls each (``--blocks`` of each); the ratio is old over new of the median block.
Both must give the same forces bitwise, or the script stops.

The case's element calls it at every record and at every prestress servo update: 4373
times in ``cases/prs_element.py --smoke --two-way --soil given`` (measured with cProfile).

    .venv/bin/python bench/member_forces.py [--nodes 10] [--calls 200] [--blocks 5]
    .venv/bin/python bench/member_forces.py --smoke        # a few seconds
Prints a JSON line: the seconds per call of each, the ratio, and ``bitwise_equal``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cpp_dem"))

import cpp_dem as dem  # noqa: E402
from cpp_dem.build import geogrid  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def loop_forces(grid, scene) -> np.ndarray:
    """The former ``Geogrid.member_axial_forces``: a loop over the members."""
    f_link = scene.grid_link_axial_forces
    nodes = scene.grid_link_nodes
    pos = scene.positions
    out = np.zeros(grid.n_members)
    for m, sec in enumerate(grid.member_section_links):
        d = pos[nodes[sec, 1]] - pos[nodes[sec, 0]]
        d /= np.linalg.norm(d, axis=1)[:, None]
        out[m] = np.sum(f_link[sec] * np.abs(d @ grid.member_axis[m]))
    return out


def loaded_grid(nodes: int, seed: int = 1):
    """A square grid of ``nodes`` x ``nodes`` cylinder nodes (0.1 m square, the case's beam
    law), pushed by random node forces for 300 steps: (scene, grid)."""
    s = dem.Scene(local_damping=0.7)
    mat = s.add_material(dem.linear_material(density=1000, young=1e8, poisson=0.3,
                                             friction_angle_deg=30))
    p = dem.BeamParams(young=1e8, poisson=0.3, radius=1.5e-3)
    g = geogrid.square_grid(s, origin=(0, 0, 0), length=0.1, width=0.1, nodes_x=nodes,
                            nodes_y=nodes, params=p, material=mat, density=1000)
    s.set_auto_timestep(0.5, 100)
    ext = np.zeros((s.num_bodies, 3))
    ext[g.nodes] = np.random.default_rng(seed).normal(0, 1e-2, (len(g.nodes), 3))
    s.external_forces = ext
    s.run(300)
    return s, g


def main(argv=None) -> dict:
    ap = _cli.BenchParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=10, help="grid nodes per side (default 10)")
    ap.add_argument("--calls", type=int, default=200, help="calls per timed block")
    ap.add_argument("--blocks", type=int, default=5, help="timed blocks of each")
    ap.add_argument("--smoke", action="store_true", help="20 calls, 2 blocks")
    a = ap.parse_args(argv)
    if a.smoke:
        a.calls, a.blocks = 20, 2
    for name in ("nodes", "calls", "blocks"):
        if getattr(a, name) < (2 if name == "nodes" else 1):
            ap.error(f"--{name}={getattr(a, name)}: too small")
    scene, grid = loaded_grid(a.nodes)
    old, new = loop_forces(grid, scene), grid.member_axial_forces(scene)
    equal = bool(np.array_equal(old, new))
    if not equal or not np.any(new != 0):
        raise SystemExit(f"member forces differ (or are all zero): max |new - old| = "
                         f"{float(np.max(np.abs(new - old))):g} N")
    times: dict = {"old": [], "new": []}
    for _ in range(a.blocks):  # alternating blocks: drift on a busy machine hits both
        for name, fn in (("old", lambda: loop_forces(grid, scene)),
                         ("new", lambda: grid.member_axial_forces(scene))):
            t = time.perf_counter()
            for _ in range(a.calls):
                fn()
            times[name].append((time.perf_counter() - t) / a.calls)
    med = {k: float(np.median(v)) for k, v in times.items()}
    row = {"members": grid.n_members, "links": int(len(scene.grid_link_nodes)),
           "calls_per_block": a.calls, "blocks": a.blocks,
           "old_s_per_call": med["old"], "new_s_per_call": med["new"],
           "ratio_old_over_new": med["old"] / med["new"], "bitwise_equal": equal}
    print(json.dumps(row), flush=True)
    return row


if __name__ == "__main__":
    sys.exit(_cli.run(main))
