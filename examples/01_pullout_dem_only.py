#!/usr/bin/env python3
"""01 - A geogrid pull-out test in DEM only (no FEM, no dolfinx).

Spheres in a box of frictionless walls, a flat-ribbed biaxial geogrid (beams and PFacets) at
mid-height, set-up of "Geogrid pull-out modelling using DEM":
1. the grains grow around the held geogrid to the confining stress (REFD: radius expansion,
   then friction lowered until the target porosity);
2. the geogrid is freed, gravity is switched on and the top wall becomes a servo wall that
   holds the confining stress;
3. a clamp holds the front rib and pulls it towards -x at constant velocity; the pull-out
   force is the sum of the clamp's reactions.

Run:   .venv/bin/python examples/01_pullout_dem_only.py [--smoke] [--out DIR]
Writes (in --out): pullout.csv (displacement m, force N, top-wall stress Pa), pullout.png.
"""

import argparse
import math
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem.build import geogrid
from cpp_dem.protocols import prep, pullout

#: Files this script writes in --out (tests/test_examples.py checks them).
OUTPUTS = ["pullout.csv", "pullout.png"]
#: This script never imports dolfinx (tests/test_examples.py checks it).
DEM_ONLY = True

ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
ap.add_argument("--smoke", action="store_true", help="300 spheres, half-size box, 5 mm pull")
ap.add_argument("--out", type=Path, default=Path("results/examples/01_pullout_dem_only"))
args = ap.parse_args()
args.out.mkdir(parents=True, exist_ok=True)
if args.smoke:
    dem.set_num_threads(1)  # a small scene: on a shared machine a second thread mostly waits

n, box, distance = (300, (0.5, 0.25, 0.25), 0.005) if args.smoke else (3000, (1.0, 0.5, 0.5), 0.05)
stress, velocity = 25e3, 0.01     # confining stress on the top wall (Pa), pull velocity (m/s)
lo, hi = np.zeros(3), np.array(box)                   # the box corners, m (x is the pull)
grid_z, rc = 0.5 * box[2], 1e-3                       # geogrid plane and half thickness, m

# Loose grains in two layers, clear of the geogrid plane: radii 12 +- 6 mm.
radii = np.random.default_rng(1).uniform(0.006, 0.018, n)
centres, radii = pullout.layered_cloud(radii, lo, hi, grid_z=grid_z, clearance=1.5 * rc, seed=1)
grain = dem.linear_material(density=2600, young=1e6, poisson=0.5, friction_angle_deg=30)

# The geogrid: 80 mm apertures, 10 mm flat ribs, E = 4 GPa beams (no breakage).
pitch = math.sqrt(6.4e-3) + 0.01
nx, ny = int((box[0] - 0.01) // pitch), int((box[1] - 0.01) // pitch)


def make_grid(scene):
    mat = scene.add_material(dem.linear_material(density=100, young=4e9, poisson=0.3,
                                                 friction_angle_deg=20))
    beam = dem.BeamParams(young=4e9, poisson=0.3, radius=rc, normal_cohesion=0.0,
                          shear_cohesion=0.0)
    y0 = 0.5 * (box[1] - ny * pitch)
    return geogrid.biaxial_geogrid(scene, origin=(0.005, y0, grid_z), apertures_x=nx,
                                   apertures_y=ny, aperture_area=6.4e-3, rib_width=0.01,
                                   params=beam, material=mat, unit_weight=981.0)


# The clamp holds the nodes within one rib width of the front edge.
sample = pullout.build_sample(centres, radii, lo, hi, grain=grain, grid_builder=make_grid,
                              grid_z=grid_z, clamp_depth=0.01, clamp="front",
                              max_overlap_ratio=prep.overlap_limit(stress, grain.young))
print(f"{len(radii)} spheres, geogrid of {len(sample.grid.nodes)} nodes and "
      f"{sample.grid.n_members} members; preparing to {stress / 1e3:g} kPa ...", flush=True)
pullout.prepare(sample, stress=stress, porosity=0.35, node_density_scale="auto",
                log=lambda msg: print(" ", msg, flush=True))


def progress(row):
    if row["step"] % 2000 < 50:  # every 2000 steps (a row every 50)
        print(f"  pulled {1e3 * row['displacement']:5.2f} mm: force {row['pull_force']:8.1f} N,"
              f" top wall {row['top_stress'] / 1e3:5.2f} kPa", flush=True)


rec = pullout.pull(sample, velocity=velocity, distance=distance, record_every=50,
                   on_record=progress)
s = pullout.summarize(rec)
print(f"largest pull-out force {s['max_force_N']:.1f} N, mean {s['mean_force_N']:.1f} N")

np.savetxt(args.out / "pullout.csv", np.column_stack(
    [rec["displacement"], rec["pull_force"], rec["top_stress"]]), delimiter=",",
    header="displacement_m,pull_force_N,top_stress_Pa", comments="", fmt="%.6g")
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, ax = plt.subplots(figsize=(6, 4))
ax.plot(1e3 * rec["displacement"], rec["pull_force"])
ax.set_xlabel("front displacement (mm)")
ax.set_ylabel("pull-out force (N)")
ax.set_title(f"Geogrid pull-out, {len(radii)} spheres, {stress / 1e3:g} kPa")
ax.grid(alpha=0.3)
fig.tight_layout()
fig.savefig(args.out / "pullout.png", dpi=150)
print("wrote", *(args.out / f for f in OUTPUTS))
