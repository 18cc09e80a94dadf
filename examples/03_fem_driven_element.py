#!/usr/bin/env python3
"""03 - One-way FEM -> DEM: the stresses of an FEM region drive a DEM element's walls.

A plane-strain fill (half width 4 m, height 3 m, Drucker-Prager soil, unit weight 18 kN/m^3)
with a geogrid layer 0.3 m deep is loaded by a 100 kPa strip footing (half width 0.5 m). The
stress averaged over a 0.1 m element region on the layer, before and after the footing load,
is handed over (tension positive -> compression positive) and a DEM element (a cube of
spheres around a square geogrid) is servo-controlled to those stresses.

Run:   .venv/bin/python examples/03_fem_driven_element.py [--smoke] [--out DIR]
Needs: dolfinx (the `fem` extra; `make setup` installs it).
Writes (in --out): handover.csv (FEM targets and the stresses the element reached, Pa),
element.csv (the element's wall stresses as it runs), element_stresses.png, element.h5
(the element's record) and vtk/ (ParaView).
"""

import argparse
from pathlib import Path

#: Files this script writes in --out (tests/test_examples.py checks them).
OUTPUTS = ["handover.csv", "element.csv", "element_stresses.png", "element.h5"]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
ap.add_argument("--smoke", action="store_true", help="coarse FEM mesh, 300 grains (seconds)")
ap.add_argument("--out", type=Path, default=Path("results/examples/03_fem_driven_element"))
args = ap.parse_args()
out, smoke = args.out, args.smoke
out.mkdir(parents=True, exist_ok=True)

# --- the FEM body, its handover, the DEM element (docs/fem.md shows this part) ---
import numpy as np

from femcoupling.coupling.twoway import one_way
from femcoupling.fem.geometry import ElementRegion, GeogridLayer, ReinforcedSoilBody
from femcoupling.fem.model import FemModel
from femcoupling.materials.continuum import DruckerPrager, GeogridLayerMaterial
from cpp_dem.elements.box import ElementParams, grid_axial_stiffness, run_element

p = ElementParams(n=300 if smoke else 2000, hold_steps=600, unbalanced=0.05)  # DEM element
body = ReinforcedSoilBody(
    width_m=4.0, height_m=3.0, footing_half_width_m=0.5,
    layers=(GeogridLayer(z_m=2.7, x_min_m=0.0, x_max_m=2.0, thickness_m=0.02),),
    regions=(ElementRegion("element", center_m=(0.25, 2.7), size_m=p.edge),),
    mesh_size_m=1.0, fine_size_m=0.05 if smoke else 0.025, fine_radius_m=1.0)  # m
soil = DruckerPrager(young_pa=50e6, poisson=0.3, cohesion_pa=10e3, friction_deg=35.0)
layer = GeogridLayerMaterial(axial_stiffness_n_per_m=grid_axial_stiffness(p))
m = FemModel(body, soil=soil, layers=[layer], unit_weight_n_m3=18e3, newton_rtol=1e-6)
m.set_geostatic()                                   # K0 state under self-weight


def load(model):                                    # the load stage: a 100 kPa footing
    return model.load_footing(pressure_pa=100e3, steps=3)


initial, final = one_way(m, regions=["element"], load=load)   # WallTargets per region
ini, fin = initial["element"], final["element"]
print("handover before the footing:", ini.report())
print("handover after the footing: ", fin.report())
# The element: grown to the initial mean stress, walls to the initial targets, then to the
# final ones (compression positive, Pa). The FEM layer's tension across the region (N/m)
# pulls the grid's ends; a layer in compression leaves them free (a geogrid carries none).
tension = [max(t.grid_tension_n_per_m or 0.0, 0.0) for t in (ini, fin)]
res = run_element(p, [ini.normal_pa, fin.normal_pa], prestressed=False, label="element",
                  out=out, grid_tension=tension)
reached = np.array(res["stress_final_pa"])
print("element reached", np.round(reached / 1e3, 2), "kPa for targets",
      np.round(fin.normal_pa / 1e3, 2), "kPa")
# --- end of the part docs/fem.md shows ---

rows = np.array([ini.normal_pa, fin.normal_pa, res["stress_initial_pa"], reached])
np.savetxt(out / "handover.csv", np.column_stack([np.arange(4), rows]), delimiter=",",
           header="row(0 FEM initial 1 FEM final 2 DEM initial 3 DEM final),"
                  "sigma_x_Pa,sigma_y_Pa,sigma_z_Pa", comments="", fmt="%.6g")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

rec = np.genfromtxt(out / "element.csv", delimiter=",", names=True)
fig, ax = plt.subplots(figsize=(7, 4))
for k, axis in enumerate("xyz"):
    ax.plot(rec["step"], rec[f"sigma_{axis}"] / 1e3, f"C{k}", label=f"wall {axis}")
    ax.plot(rec["step"], rec[f"target_{axis}"] / 1e3, f"C{k}--", lw=0.8)
ax.set_xlabel("DEM step")
ax.set_ylabel("wall stress (kPa, compression +)")
ax.set_title("DEM element driven to the FEM region's stresses (dashed: targets)")
ax.legend()
fig.tight_layout()
fig.savefig(out / "element_stresses.png", dpi=150)
print("wrote", *(out / f for f in OUTPUTS))
