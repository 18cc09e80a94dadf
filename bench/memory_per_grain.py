#!/usr/bin/env python3
"""Memory per grain of the DEM core, per field (issue 63 item 3).

A cubic lattice of k^3 spheres (radius 0.51 of the spacing, so every inner sphere touches
its six neighbours), linear law, between no walls, run for a few steps. For each size (one
fresh process each) it measures:

- the core's own arrays (``Scene.memory_by_field``: capacity x element size of every array,
  by field) per grain, and the fields' shares;
- the process's resident memory added by building and running the scene (VmRSS after the
  run less VmRSS before the scene was made, the lattice's positions and radii made before
  that), per grain;
- the contacts per grain.

and, between the two largest sizes, the marginal resident bytes per grain (the slope: what
one more grain costs, without the interpreter's and the libraries' fixed memory). One JSON
line per size and one for the slope on stdout; a table of the largest fields on stderr.

Usage (from the repository root, in the project venv):
    python bench/memory_per_grain.py                 # k = 30 and 60: 2.7e4 and 2.16e5 grains
    python bench/memory_per_grain.py --k 20 30       # smaller, faster
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

_ONE = r"""
import json, sys
import numpy as np
import cpp_dem as dem
sys.path.insert(0, sys.argv[2])
from _machine import resident_bytes

k = int(sys.argv[1])
# (the lattice's positions and radii, the script's input, are made before the baseline, as
# bench/memory.py loads its packing first: the measure is what the scene adds)
h = 0.01
g = np.arange(k) * h
pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
radii = np.full(len(pos), 0.51 * h)
before = resident_bytes()
s = dem.Scene()
m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                       friction_angle_deg=30))
s.add_spheres(pos, radii, material=m)
s.dt = 1e-7
s.run(5)
after = resident_bytes()
fields = s.memory_by_field()
print(json.dumps({"grains": len(pos), "contacts": int(s.num_active_contacts),
                  "rss_bytes": after - before, "fields": fields}))
"""


def one(k: int) -> dict:
    out = subprocess.run([sys.executable, "-c", _ONE, str(k), str(HERE)], capture_output=True,
                         text=True, check=True, env={"OMP_NUM_THREADS": "1", "PATH": ""})
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--k", type=int, nargs="+", default=[30, 60],
                    help="lattice edges, k^3 grains each (default: 30 60)")
    ap.add_argument("--top", type=int, default=12, help="fields in the stderr table")
    a = ap.parse_args(argv)
    if len(a.k) < 1 or any(k < 3 for k in a.k):
        ap.error(f"--k {a.k}: one or more edges of at least 3")
    rows = []
    for k in sorted(a.k):
        r = one(k)
        n = r["grains"]
        core = sum(r["fields"].values())
        row = {"grains": n, "contacts_per_grain": r["contacts"] / n,
               "core_bytes_per_grain": core / n, "rss_bytes_per_grain": r["rss_bytes"] / n,
               "fields_bytes_per_grain": {f: b / n for f, b in sorted(
                   r["fields"].items(), key=lambda x: -x[1]) if b}}
        rows.append(row)
        print(json.dumps(row), flush=True)
        print(f"{n} grains, {row['contacts_per_grain']:.2f} contacts each: core "
              f"{row['core_bytes_per_grain']:.0f} B/grain, resident "
              f"{row['rss_bytes_per_grain']:.0f} B/grain", file=sys.stderr)
        for f, b in list(row["fields_bytes_per_grain"].items())[:a.top]:
            print(f"  {f:32s} {b:8.1f} B/grain", file=sys.stderr)
    if len(rows) >= 2:
        r0, r1 = rows[-2], rows[-1]
        slope = ((r1["rss_bytes_per_grain"] * r1["grains"] - r0["rss_bytes_per_grain"]
                  * r0["grains"]) / (r1["grains"] - r0["grains"]))
        core = ((r1["core_bytes_per_grain"] * r1["grains"] - r0["core_bytes_per_grain"]
                 * r0["grains"]) / (r1["grains"] - r0["grains"]))
        print(json.dumps({"marginal_rss_bytes_per_grain": slope,
                          "marginal_core_bytes_per_grain": core,
                          "between": [r0["grains"], r1["grains"]]}), flush=True)
        print(f"marginal: resident {slope:.0f} B/grain, core arrays {core:.0f} B/grain "
              f"({r0['grains']} -> {r1['grains']} grains)", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(_cli.run(main))
