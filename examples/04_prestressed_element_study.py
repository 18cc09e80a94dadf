#!/usr/bin/env python3
"""04 - The study "Microscopic interaction effects of prestressed geogrids in a reinforced soil
element": reinforced (RE) against prestressed (PRS) soil element, and its interaction measures.

The element (geogrid_dem.cases.prs_element_002): a 0.1 m cube of gravel clumps (Hertz-Mindlin)
around a woven geogrid of bonded spheres, servo walls driven to the stresses of the FEM
structure (a fill under a footing) or to given stresses. PRS tensions the longitudinal members
to T_p = 2 kN/m and locks them before the walls are loaded. The measures, RE against PRS:
interlocking (grains in apertures), single-string interaction (grains touching two strings),
alignment (grain contacts per metre, out-of-plane waviness), the uniformity of the tensile
force along the members and the displacement above against below the grid.

Run:   .venv/bin/python examples/04_prestressed_element_study.py [--smoke] [--out DIR]
       (--smoke: DEM only, given stresses, the standard grid form, 60 clumps, about half a
       minute; the full run takes the stresses from the FEM and runs both grid forms with
       2000 clumps: up to about four hours on one core, docs/prs_element_002.md)
Writes (in --out): measures.csv and measures.png (RE against PRS), and in case/ the study's
own outputs: report.md, summary.json, <grid>_<RE|PRS>_views.png, vtk/.
"""

import argparse
import json
import textwrap
from pathlib import Path

from geogrid_dem.cases import prs_element_002 as study

#: Files this script writes in --out (tests/test_examples.py checks them).
OUTPUTS = ["measures.csv", "measures.png", "case/report.md"]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
ap.add_argument("--smoke", action="store_true", help="DEM only, standard grid, 60 clumps")
ap.add_argument("--out", type=Path,
                default=Path("results/examples/04_prestressed_element_study"))
args = ap.parse_args()
args.out.mkdir(parents=True, exist_ok=True)

# The study's own command line: RE and PRS (its default), into out/case (replaced on a rerun).
argv = ["--out", str(args.out / "case"), "--overwrite"]
if args.smoke:
    argv += ["--smoke", "--grids", "standard", "--stresses", "20000,20000,40000", "--n", "60"]
code = study.main(argv)
if code:
    raise SystemExit(f"the study stopped with exit status {code}")
summary = json.loads((args.out / "case" / "summary.json").read_text())

# The measures of each element (name, unit, value from the element's summary).
MEASURES = [
    ("grains in apertures", "-", lambda e: e["interaction"]["apertures"]["grains_in_apertures"]),
    ("grains touching two strings", "-",
     lambda e: e["interaction"]["between_strings"]["grains_touching_two_strings"]),
    ("grain contacts per m, longitudinal", "1/m",
     lambda e: e["interaction"]["contacts"]["longitudinal_per_m"]),
    ("out-of-plane waviness, longitudinal", "um",
     lambda e: 1e6 * e["interaction"]["waviness"]["out_of_plane_longitudinal_mean_m"]),
    ("CoV of the force along the longitudinal members", "-",
     lambda e: e["grid_force_longitudinal_cov_along"]),
    ("mean |u| above the grid", "mm",
     lambda e: 1e3 * e["interaction"]["displacement"]["above_mean_m"]),
    ("mean |u| below the grid", "mm",
     lambda e: 1e3 * e["interaction"]["displacement"]["below_mean_m"]),
]
names = list(summary["elements"])                     # e.g. standard_RE, standard_PRS
with open(args.out / "measures.csv", "w") as f:
    f.write("measure,unit," + ",".join(names) + "\n")
    for label, unit, get in MEASURES:
        values = [get(summary["elements"][n]) for n in names]
        f.write(f"{label},{unit}," + ",".join(f"{v:.6g}" for v in values) + "\n")
        print(f"{label:50s} {unit:4s}", "  ".join(f"{n} {v:9.4g}" for n, v in zip(names, values)))
for finding in summary["findings"]:
    print(f"{finding['grid']}: {finding['finding']}: {finding['here']} "
          f"({'agrees' if finding['agrees'] else 'does not agree'} with the paper)")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, axes = plt.subplots(2, 4, figsize=(11, 6))
axes[-1, -1].axis("off")                              # 7 measures in 8 panels
for ax, (label, unit, get) in zip(axes.flat, MEASURES):
    ax.bar(range(len(names)), [get(summary["elements"][n]) for n in names],
           color=["C1" if n.endswith("PRS") else "C0" for n in names])
    ax.set_xticks(range(len(names)), [n.replace("_", "\n") for n in names], fontsize=7)
    ax.set_title(textwrap.fill(f"{label} ({unit})", 28), fontsize=9)
fig.suptitle("RE (blue) against PRS (orange): interaction measures of the element")
fig.tight_layout()
fig.savefig(args.out / "measures.png", dpi=150)
print("wrote", *(args.out / f for f in OUTPUTS))
