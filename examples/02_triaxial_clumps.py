#!/usr/bin/env python3
"""02 - A drained triaxial test of clump grains (angular gravel), DEM only.

The grains are rigid clumps of the four shipped gravel templates (24 spheres each), at random
seeded orientations, in a box of six frictionless walls (z is axial):
1. prepare: a loose cloud grows to the cell pressure (radius growth under stress control),
   with a low friction for a denser sample, then the grain friction is set to 32 deg;
2. isotropic: servo walls bring the three axis stresses to the cell pressure;
3. deviatoric: the z walls move in at a constant strain rate while the x and y walls hold the
   cell pressure; the deviator q = sigma_z - (sigma_x + sigma_y) / 2 is recorded.

Run:   .venv/bin/python examples/02_triaxial_clumps.py [--smoke] [--out DIR]
Writes (in --out): triaxial.csv (axial and volumetric strain, q and p in Pa), triaxial.png.
"""

import argparse
from pathlib import Path

import numpy as np

from cpp_dem import measure, set_num_threads
from cpp_dem.build.clump_mesh import shipped_templates
from cpp_dem.build.clumps import bounding_volume_factor, clump_cloud
from cpp_dem.protocols import prep, triaxial

#: Files this script writes in --out (tests/test_examples.py checks them).
OUTPUTS = ["triaxial.csv", "triaxial.png"]
#: This script never imports dolfinx (tests/test_examples.py checks it).
DEM_ONLY = True

ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
ap.add_argument("--smoke", action="store_true", help="200 clumps, to 4 % axial strain")
ap.add_argument("--out", type=Path, default=Path("results/examples/02_triaxial_clumps"))
args = ap.parse_args()
args.out.mkdir(parents=True, exist_ok=True)
if args.smoke:
    set_num_threads(1)  # a small scene: on a shared machine a second thread mostly waits

n, rate, stop = (200, 0.5, 0.04) if args.smoke else (1000, 0.2, 0.10)  # -, 1/s, -
pressure, young, friction = 75e3, 4.5e6, 32.0    # cell pressure Pa, grain E Pa, friction deg

# Equivalent-volume diameters 11-25 mm; a box (1 : 1 : 2) that they fill at 60 % solids.
diameters = np.random.default_rng(1).uniform(0.011, 0.025, n)
side = (np.sum(np.pi / 6 * diameters**3) / 0.6 / 2) ** (1 / 3)
box = np.array([side, side, 2 * side])
templates = list(shipped_templates().values())          # gravel_a .. gravel_d
# The cloud places the clumps' bounding spheres, so it starts from shrunk grains.
shrink = (0.25 / (0.6 * bounding_volume_factor(templates))) ** (1 / 3)
cloud = clump_cloud(templates, diameters * shrink, (0, 0, 0), box, seed=1)
# (centres and radii come from the cloud); members as stiff as the grain's equivalent sphere.
sample = triaxial.build_box_sample(None, None, (0, 0, 0), box, young=young, poisson=0.33,
                                   friction_deg=10.0, density=2650, local_damping=0.2,
                                   clumps=(cloud, templates))
sc, walls = sample.scene, sample.walls
sc.max_overlap_ratio = prep.overlap_limit(pressure, young)
print(f"{sc.num_clumps} clumps ({sc.num_bodies} spheres) in a {np.round(box, 3)} m box; "
      "growing to the cell pressure ...", flush=True)

grow = prep.grow_to_stress(sc, walls, pressure, tol=0.05, unbalanced=0.05, max_strain=1e-4,
                           max_steps=200_000)
prep.set_friction(sc, np.flatnonzero(measure.sphere_mask(sc)), sc.material(sample.material),
                  friction)
print(f"  prepared in {grow.steps} steps, porosity {grow.porosity:.3f}", flush=True)
iso = triaxial.isotropic_stage(sample, pressure)
print(f"  isotropic: axis stresses {np.round(iso.axis_stresses / 1e3, 2)} kPa, "
      f"porosity {iso.porosity:.3f}", flush=True)


def progress(row):
    if row["step"] % 1000 < 50:  # every 1000 steps (a row every 50)
        print(f"  axial strain {100 * row['axial_strain']:5.2f} %: q "
              f"{row['deviatoric_stress'] / 1e3:6.2f} kPa", flush=True)


rows = triaxial.deviatoric_stage(sample, pressure, rate, stop, record_every=50,
                                 on_record=progress)
k = int(np.argmax(rows["deviatoric_stress"]))
print(f"largest q {rows['deviatoric_stress'][k] / 1e3:.2f} kPa at axial strain "
      f"{100 * rows['axial_strain'][k]:.2f} %")

np.savetxt(args.out / "triaxial.csv", np.column_stack(
    [rows["axial_strain"], rows["volumetric_strain"], rows["deviatoric_stress"],
     rows["mean_stress"]]), delimiter=",", comments="", fmt="%.6g",
    header="axial_strain,volumetric_strain,q_Pa,p_Pa")
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, ax = plt.subplots(1, 2, figsize=(10, 4))
ax[0].plot(100 * rows["axial_strain"], rows["deviatoric_stress"] / 1e3)
ax[0].set_ylabel("deviator q (kPa)")
ax[1].plot(100 * rows["axial_strain"], 100 * rows["volumetric_strain"], "C1")
ax[1].set_ylabel("volumetric strain (%, compression +)")
for a in ax:
    a.set_xlabel("axial strain (%)")
    a.grid(alpha=0.3)
fig.suptitle(f"Triaxial test, {sc.num_clumps} gravel clumps, cell pressure "
             f"{pressure / 1e3:g} kPa")
fig.tight_layout()
fig.savefig(args.out / "triaxial.png", dpi=150)
print("wrote", *(args.out / f for f in OUTPUTS))
