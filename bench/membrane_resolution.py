"""What the cylinder's membrane resolution changes, and what it costs (issue 65): the triaxial
case's cylindrical specimen with its membrane's triangles at two sizes, paired over packing
seeds. Not a test: runs the case, prints JSON lines and writes one JSON file.

For each seed and each side (``--sides``, in smallest grain radii: 1, the case's default,
finer than the grains; 2, as wide as the smallest grain, the membrane's limit),
``cases/triaxial.py --smoke --n N --seed S --specimen cylinder --membrane-side SIDE
--stop-strain E --strain-rate R`` runs into ``<--runs>/side<SIDE>_s<seed>/`` (a run whose
summary.json is there is read, not run again; ``--jobs`` at a time, one thread each). The
same seed gives the same grains and the same mould compaction: the runs differ from the
membrane on. Read from each run: the deviator q (Pa), the volumetric strain (-) and the
membrane's correction (Pa) at the ``--at`` axial strains (linear between rows), the wall
time of the preparation and of the loading (s), the loading's steps and the membrane's
nodes. Then, per measure and strain, the paired difference of the coarser side less the
finer over the seeds, with its standard error and Student's t (resolved at 95 % when
|t| > t(0.975, n - 1)), and the finer run's wall time over the coarser's per seed.

    .venv/bin/python bench/membrane_resolution.py --seeds 1,2,3,4,5 \
        --out docs/data/membrane_resolution.json
    .venv/bin/python bench/membrane_resolution.py --smoke --out /tmp/mr.json
    .venv/bin/python bench/membrane_resolution.py --table docs/data/membrane_resolution.json
"""

from __future__ import annotations

import csv
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)
import _report  # noqa: E402
from geogrid_dem.stats import paired_difference, resolved  # noqa: E402


#: the measures read at each axial strain: (the CSV's column, the table's name, its scale
#: from SI, its digits)
MEASURES = (("deviatoric_stress", "q, kPa", 1e-3, 2),
            ("volumetric_strain", "volumetric strain, %", 100, 3),
            ("membrane_correction", "membrane correction, kPa", 1e-3, 2))


def run_one(a, side: float, seed: int) -> dict:
    """The case's run for (side, seed), or its earlier run's files; its readings."""
    d = Path(a.runs) / f"side{side:g}_s{seed}"
    if not (d / "summary.json").exists():
        _cli.run_triaxial_case(["--smoke", "--n", str(a.n), "--seed", str(seed), "--specimen",
                                "cylinder", "--membrane-side", repr(side), "--stop-strain",
                                repr(a.stop_strain), "--strain-rate", repr(a.strain_rate),
                                "--threads", "1", "--out", str(d), "--overwrite"],
                               f"--membrane-side {side:g}, seed {seed}")
    rows = list(csv.DictReader(open(d / "triaxial.csv")))
    e = np.array([float(r["axial_strain"]) for r in rows])
    out: dict = {"side": side, "seed": seed}
    for key, *_ in MEASURES:
        v = np.array([float(r[key]) for r in rows])
        out[key] = [float(np.interp(s, e, v)) if s <= e[-1] else None for s in a.at]
    s = json.loads((d / "summary.json").read_text())
    out.update(num_grains=s["num_grains"], membrane_nodes=s["membrane"]["nodes"],
               link_length_m=s["membrane"]["link_length_m"],
               held_membrane_correction_pa=s["held"]["membrane_correction_pa"],
               q_peak_pa=s["q_peak_Pa"], grains_outside_max=s["grains_outside_max"],
               platen_difference_max=s["platen_difference_max"],
               deviatoric_steps=s["deviatoric_steps"],
               wall_time_preparation_s=s["wall_time_preparation_s"],
               wall_time_deviatoric_s=s["wall_time_deviatoric_s"],
               wall_time_total_s=s["wall_time_total_s"])
    return out


def paired(runs: list[dict], at: list[float], fine: float, coarse: float) -> list[dict]:
    """coarse - fine per seed, per measure and strain, and the fine run's wall time over the
    coarse one's (the loading's, and the whole run's): n, mean, se, t, resolved."""
    by = {(r["side"], r["seed"]): r for r in runs}
    seeds = sorted({r["seed"] for r in runs if (fine, r["seed"]) in by
                    and (coarse, r["seed"]) in by})
    out = []
    for key, *_ in MEASURES:
        for i, s in enumerate(at):
            d = [by[coarse, k][key][i] - by[fine, k][key][i] for k in seeds
                 if by[coarse, k][key][i] is not None and by[fine, k][key][i] is not None]
            p = paired_difference(d)
            out.append({"measure": key, "axial_strain": s, **p,
                        "resolved": resolved(p["t"], p["n"])})
    for key in ("q_peak_pa", "held_membrane_correction_pa"):
        p = paired_difference([by[coarse, k][key] - by[fine, k][key] for k in seeds])
        out.append({"measure": key, "axial_strain": None, **p,
                    "resolved": resolved(p["t"], p["n"])})
    for key in ("wall_time_deviatoric_s", "wall_time_total_s"):
        ratios = [by[fine, k][key] / by[coarse, k][key] for k in seeds]
        out.append({"measure": f"speedup_{key}", "n": len(ratios),
                    "mean": float(np.mean(ratios)) if ratios else math.nan,
                    "min": float(np.min(ratios)) if ratios else math.nan,
                    "max": float(np.max(ratios)) if ratios else math.nan})
    return out


def _mean(runs: list[dict], side: float, key: str, i: int | None = None):
    v = [r[key] if i is None else r[key][i] for r in runs if r["side"] == side]
    v = [x for x in v if x is not None]
    return float(np.mean(v)) if v else None


def table(data: dict) -> list[str]:
    """The docs' table (docs/studies/membrane_resolution.md): per measure and axial strain,
    the means at the two sides over the seeds and the paired difference (coarse - fine)
    with its standard error, t and whether it is resolved at 95 %; then the peak, the hold's
    correction, the nodes and the wall times."""
    runs, at = data["runs"], data["params"]["at"]
    fine, coarse = data["params"]["sides"]
    head = ["measure", "axial strain, %", f"side {fine:g}", f"side {coarse:g}",
            f"{coarse:g} - {fine:g} (+- SE)", "t", "resolved (95 %)"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    pairs = {(d["measure"], d.get("axial_strain")): d for d in data["paired"]}

    def line(name, strain, key, scale, digits, i=None):
        d = pairs[key, strain]
        res = "yes" if d["resolved"] else ("no" if d["n"] > 1 else "-")
        out.append(f"| {name} | {strain_txt(strain)} | "
                   f"{_report.fmt(_mean(runs, fine, key, i), scale, digits)} | "
                   f"{_report.fmt(_mean(runs, coarse, key, i), scale, digits)} | "
                   f"{_report.fmt(d['mean'], scale, digits)} +- "
                   f"{_report.fmt(d['se'], scale, digits)} | "
                   f"{_report.fmt(d['t'], 1, 1)} | {res} |")

    def strain_txt(s):
        return "-" if s is None else f"{100 * s:g}"

    for key, name, scale, digits in MEASURES:
        for i, e in enumerate(at):
            line(name, e, key, scale, digits, i)
    line("peak q, kPa", None, "q_peak_pa", 1e-3, 2)
    line("membrane correction at the hold, kPa", None, "held_membrane_correction_pa", 1e-3, 2)
    for key, name, digits in (("membrane_nodes", "membrane nodes", 0),
                              ("deviatoric_steps", "loading steps", 0),
                              ("wall_time_preparation_s", "wall time, preparation, s", 1),
                              ("wall_time_deviatoric_s", "wall time, loading, s", 1)):
        out.append(f"| {name} | - | {_report.fmt(_mean(runs, fine, key), 1, digits)} | "
                   f"{_report.fmt(_mean(runs, coarse, key), 1, digits)} | | | |")
    for d in data["paired"]:
        if d["measure"].startswith("speedup_"):
            what = "loading" if "deviatoric" in d["measure"] else "whole run"
            out.append(f"| side {fine:g} over side {coarse:g}, wall time of the {what} | - | "
                       f"| | {d['mean']:.2f} ({d['min']:.2f}-{d['max']:.2f}) | | |")
    return out


def main() -> None:
    ap = _cli.study_parser("membrane_resolution", __doc__, runs=True)
    ap.add_argument("--n", type=int, default=1500, help="grains per specimen (--n of the case)")
    ap.add_argument("--seeds", default="1,2,3,4,5", help="comma-separated packing seeds")
    ap.add_argument("--sides", default="1,2", help="the two membrane sides compared (the "
                    "case's --membrane-side), finer first")
    ap.add_argument("--stop-strain", type=float, default=0.04, help="axial strain to reach, -")
    ap.add_argument("--strain-rate", type=float, default=0.1, help="axial strain rate, 1/s")
    ap.add_argument("--at", default="0.01,0.02,0.03,0.04",
                    help="axial strains to read the measures at")
    ap.add_argument("--jobs", type=int, default=2, help="runs at a time (one thread each)")
    ap.add_argument("--smoke", action="store_true",
                    help="300 grains, two seeds, to 1 %% at 0.5 /s")
    a = _cli.parse_study(ap, table)
    if a is None:
        return
    a.sides = _cli.numbers(a.sides, "--sides")
    if len(a.sides) != 2 or not a.sides[0] < a.sides[1] \
            or not all(0.75 <= s <= 2.0 for s in a.sides):
        raise _cli.BenchInputError(f"--sides={','.join(f'{s:g}' for s in a.sides)}: must be "
                                   "two sides in [0.75, 2], the finer first")
    if a.smoke:
        a.n, a.seeds, a.stop_strain, a.at, a.strain_rate = 300, a.seeds[:2], 0.01, \
            [0.005, 0.01], 0.5
    a.runs = a.runs or str(Path(a.out).with_suffix("")) + "_runs"
    jobs = [(side, seed) for seed in a.seeds for side in a.sides]
    runs = _report.run_jobs(lambda side, seed: run_one(a, side, seed), jobs, a.jobs)
    _report.write_study("membrane_resolution.py", a, runs, paired(runs, a.at, *a.sides),
                        a.out)

if __name__ == "__main__":
    sys.exit(_cli.run(main))
