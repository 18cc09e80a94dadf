#!/usr/bin/env python3
"""04 - The study "Microscopic interaction effects of prestressed geogrids in a reinforced soil
element": reinforced (RE) against prestressed (PRS) soil element on paired seeds, and 002's
findings with their verdicts.

The element (geogrid_dem.cases.prs_element_002): a 0.1 m cube of gravel clumps (Hertz-Mindlin)
around a woven geogrid of bonded spheres, servo walls driven to the stresses of the FEM
structure (a fill under a footing) or to given stresses, loaded at a bounded inertial number
and measured at rest. RE and PRS start from each seed's one grown packing; PRS's longitudinal
members are tensioned to T_p = 2 kN/m and released (the prestress locked in). 002's findings
are paired differences PRS - RE, over the seeds, of what the loading does, with a verdict at
95 % by Student's t (and, below 6 seeds, a check of the machinery, not a finding).

Run:   .venv/bin/python examples/04_prestressed_element_study.py [--smoke] [--out DIR]
       (--smoke: DEM only, given stresses, the standard grid, 250 test-sized clumps, seeds
       1-2, a few minutes; the full run takes the stresses from the FEM and runs both grid forms with
       2000 clumps, docs/prs_element_002.md)
Writes (in --out): findings.csv and findings.png (RE against PRS per seed), and in case/ the
study's own outputs: report.md, summary.json, <grid>_s<seed>_views/_grid/_rose (.png, .pdf),
vtk/.
"""

import argparse
import json
import textwrap
from pathlib import Path

from geogrid_dem.cases import prs_element_002 as study

#: Files this script writes in --out (tests/test_examples.py checks them).
OUTPUTS = ["findings.csv", "findings.png", "case/report.md", "case/summary.json",
           "case/standard_s1_views.png"]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
ap.add_argument("--smoke", action="store_true", help="DEM only, standard grid, 250 clumps")
ap.add_argument("--out", type=Path,
                default=Path("results/examples/04_prestressed_element_study"))
args = ap.parse_args()
args.out.mkdir(parents=True, exist_ok=True)

# The study's own command line: RE and PRS on seeds 1 and 2 (its default), into out/case
# (replaced on a rerun).
argv = ["--out", str(args.out / "case"), "--overwrite"]
if args.smoke:
    # (the standard grid's 29 mm apertures pass the grains of 250 clumps: the detailed grid's
    # 16 mm need 484, docs/prs_element_002.md)
    argv += ["--smoke", "--stresses", "20000,20000,40000", "--grids", "standard", "--n", "250"]
code = study.main(argv)
if code:
    raise SystemExit(f"the study stopped with exit status {code}")
summary = json.loads((args.out / "case" / "summary.json").read_text())
el = summary["elements"]

# Each finding's value per element (the study's own definitions) and its verdict.
with open(args.out / "findings.csv", "w") as f:
    f.write("grid,finding,element,value\n")
    for grid in summary["params"]["grids"]:
        for name, _sign, _compare, value in study.FINDINGS:
            for label in sorted(e for e in el if e.startswith(grid)):
                v = value(el[label])
                f.write(f'{grid},"{name}",{label},{"nan" if v is None else f"{v:.6g}"}\n')
for line in study.findings_table(summary["findings"]):
    print(line)
if len(summary["seeds"]) < study.SEEDS_FOR_FINDINGS:
    print(f"({len(summary['seeds'])} seeds, fewer than {study.SEEDS_FOR_FINDINGS}: these "
          "verdicts check the machinery; they are not findings)")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

rows = summary["findings"]
fig, axes = plt.subplots(1, len(rows), figsize=(3.2 * len(rows), 3.6), squeeze=False)
for ax, f in zip(axes[0], rows):
    value = next(v for n, _s, _c, v in study.FINDINGS if n == f["name"])
    for seed in summary["seeds"]:
        pair = [value(el[f"{f['grid']}_{v}_s{seed}"]) for v in ("RE", "PRS")]
        pair = [float("nan") if x is None else x for x in pair]
        # (a pair left out of the verdict, an element of it not at rest: dashed)
        left = f"{f['grid']}_s{seed}" in (f.get("pairs_left_out") or [])
        ax.plot([0, 1], pair, "o--" if left else "o-", color="0.7" if left else "0.4")
    ax.set_xticks([0, 1], ["RE", "PRS"])
    ax.set_title(textwrap.fill(f"{f['name']}: {f['verdict']}", 30), fontsize=8)
fig.suptitle("002's findings: RE against PRS, one line per seed (paired; dashed: left out, "
             "an element not at rest)")
fig.tight_layout()
fig.savefig(args.out / "findings.png", dpi=150)
print("wrote", *(args.out / f for f in OUTPUTS))
