#!/usr/bin/env python3
"""Seeded generator of the shipped angular gravel grains and their clump templates.

Each grain is the convex hull of n random points: directions uniform on the unit sphere, radii
uniform in [1 - jitter, 1], stretched by the grain's elongation L/I and flatness I/S factors
(1.1-1.35 here). The bounding-box aspect ratios of the results (printed) are L/I = 1.10-1.42 and
I/S = 1.20-1.44, L/S = 1.4-1.8, in the range of crushed gravel. Few points give
large flat facets and sharp edges (angular), more points a rounder grain. The hull is moved to
its centroid, rotated to its principal axes (x: the long axis, the smallest moment) and scaled
to a volume-equivalent diameter of exactly 1 m, then written with float32 coordinates as a
binary STL. Templates are scaled at placement (``template.scaled(d)`` gives a grain of
equivalent mesh diameter d in m).

The template of each grain (``<name>.csv``, ``ClumpTemplate.save``: x, y, z, r in m) is filled
from the float32 vertices as stored, by :func:`cpp_dem.build.clump_mesh.fill_mesh` with the settings
in ``FILL``. Everything is deterministic for a given ``--seed`` (default 20240611).

Run (writes cpp_dem/cpp_dem/build/data/grains/gravel_*.stl and .csv and prints a summary)::

    .venv/bin/python scripts/make_gravel_meshes.py
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from cpp_dem.build import clump_mesh as cm

ROOT = Path(__file__).resolve().parents[1]

SEED = 20240611
#: name: (hull points, elongation L/I, flatness I/S, radial jitter).
GRAINS = {
    "gravel_a": (14, 1.30, 1.20, 0.15),   # very angular: few, large facets
    "gravel_b": (18, 1.15, 1.35, 0.20),   # flat
    "gravel_c": (22, 1.35, 1.10, 0.15),
    "gravel_d": (30, 1.20, 1.20, 0.10),   # more facets, sub-angular
}
#: fill_mesh settings of the shipped templates.
FILL = dict(max_spheres=24, min_radius_ratio=0.2, grid=24)
OUT = ROOT / "cpp_dem" / "cpp_dem" / "build" / "data" / "grains"


def make_grain(name: str, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """The surface mesh of one grain: (vertices (n, 3) float64 holding float32 values, m;
    outward triangles (m, 3)), principal frame, centroid at the origin, d_eq = 1 m."""
    if name not in GRAINS:
        raise KeyError(f"name={name!r}: not one of {', '.join(GRAINS)}")
    n, elong, flat, jitter = GRAINS[name]
    rng = np.random.default_rng([seed, list(GRAINS).index(name)])
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    p = u * rng.uniform(1.0 - jitter, 1.0, size=n)[:, None]
    p *= np.array([elong * flat, flat, 1.0])
    v, t = cm.convex_hull_mesh(p)
    mp = cm.mesh_mass_properties(v, t)
    v = (v - mp.centroid) @ mp.axes
    v *= 1.0 / (6.0 * mp.volume / math.pi) ** (1.0 / 3.0)
    v = v.astype(np.float32).astype(np.float64)
    return cm.check_closed_mesh(v, t)


def make_template(name: str, v: np.ndarray, t: np.ndarray, seed: int = SEED) -> cm.ClumpTemplate:
    """The shipped template of a grain mesh (settings ``FILL``)."""
    return cm.fill_mesh(v, t, seed=seed, name=name, **FILL)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    print("| grain | triangles | L/I | I/S | spheres | r_min/r_max | volume error | "
          "RMS dev / d_eq | max dev / d_eq |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in GRAINS:
        v, t = make_grain(name, a.seed)
        tmpl = make_template(name, v, t, a.seed)
        cm.write_stl(a.out / f"{name}.stl", v, t, name)
        tmpl.save(a.out / f"{name}.csv")
        row = cm.fill_report(v, t, counts=(tmpl.num_members,), seed=a.seed, **{
            k: val for k, val in FILL.items() if k != "max_spheres"})[-1]
        ext = np.sort(np.ptp(v, axis=0))[::-1]
        print(f"| {name} | {len(t)} | {ext[0] / ext[1]:.2f} | {ext[1] / ext[2]:.2f} | "
              f"{tmpl.num_members} | {tmpl.radii.min() / tmpl.radii.max():.2f} | "
              f"{row.volume_error:+.3f} | {row.rms_deviation:.4f} | {row.max_deviation:.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
