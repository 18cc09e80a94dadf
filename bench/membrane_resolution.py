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

With ``--dt-safety S`` the pair is the time step at one side (``--sides``, one value): the
protocol's step (0.3 of the grains' p-wave estimate in the mould, kept) against S of the
critical step, renewed every 100 steps (the case's ``--dt-safety``), the second into
``side<SIDE>_dt<S>_s<seed>/``; the difference is the renewed step's less the kept one's.
With two sides and ``--dt-safety S`` the pair is both options together: the finer side at
the protocol's step against the coarser at S (the runs of the two studies above, read
again where they are in ``--runs``).

    .venv/bin/python bench/membrane_resolution.py --seeds 1,2,3,4,5 \
        --out docs/data/membrane_resolution.json
    .venv/bin/python bench/membrane_resolution.py --seeds 1,2,3,4,5 --sides 2 --dt-safety 0.5 \
        --out docs/data/membrane_time_step.json
    .venv/bin/python bench/membrane_resolution.py --seeds 1,2,3,4,5 --sides 1,2 --dt-safety 0.5 \
        --out docs/data/membrane_options_together.json
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
from cpp_dem.protocols.cylinder_triaxial import membrane_side_problem  # noqa: E402
from geogrid_dem.stats import paired_difference, resolved  # noqa: E402


#: the measures read at each axial strain: (the CSV's column, the table's name, its scale
#: from SI, its digits)
MEASURES = (("deviatoric_stress", "q, kPa", 1e-3, 2),
            ("volumetric_strain", "volumetric strain, %", 100, 3),
            ("membrane_correction", "membrane correction, kPa", 1e-3, 2))


def variant(side: float, dt_safety: float | None) -> str:
    """A run's variant as the tables name it: its side, and its time step where it is not
    the protocol's."""
    return f"side {side:g}" + ("" if dt_safety is None else f", step {dt_safety:g} renewed")


def _variant_of(r: dict) -> str:
    return variant(r["side"], r.get("dt_safety"))


def _short(label: str) -> str:
    """The variant in a difference's header: the renewed step's fraction, or the side."""
    if "step" in label:
        return label.split("step ")[1].split(" ")[0]
    return label.removeprefix("side ")


def _shorts(fine: str, coarse: str) -> tuple[str, str]:
    """The two variants in a difference's header: the kept step and the renewed one's
    fraction at one side, the two sides at one step, or both options together."""
    if "step" not in coarse:
        return _short(fine), _short(coarse)
    if coarse.startswith(fine + ","):
        return "kept", _short(coarse)
    return fine, coarse.removesuffix(" renewed")


def run_one(a, side: float, seed: int, dt_safety: float | None = None) -> dict:
    """The case's run for (side, seed, time step), or its earlier run's files; its
    readings."""
    dt_tag = "" if dt_safety is None else f"_dt{dt_safety:g}"
    d = Path(a.runs) / f"side{side:g}{dt_tag}_s{seed}"
    if not (d / "summary.json").exists():
        dt_args = [] if dt_safety is None else ["--dt-safety", repr(dt_safety)]
        _cli.run_triaxial_case(["--smoke", "--n", str(a.n), "--seed", str(seed), "--specimen",
                                "cylinder", "--membrane-side", repr(side), *dt_args,
                                "--stop-strain", repr(a.stop_strain), "--strain-rate",
                                repr(a.strain_rate), "--threads", "1", "--out", str(d),
                                "--overwrite"],
                               f"--membrane-side {side:g}{' ' + ' '.join(dt_args)}, "
                               f"seed {seed}")
    rows = list(csv.DictReader(open(d / "triaxial.csv")))
    e = np.array([float(r["axial_strain"]) for r in rows])
    out: dict = {"side": side, "seed": seed}
    if dt_safety is not None:
        out["dt_safety"] = dt_safety
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


def paired(runs: list[dict], at: list[float], fine: str, coarse: str) -> list[dict]:
    """coarse - fine (variants, :func:`variant`) per seed, per measure and strain, and the fine
    run's wall time over the coarse one's (the loading's, and the whole run's): n, mean, se,
    t, resolved."""
    by = {(_variant_of(r), r["seed"]): r for r in runs}
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


def _mean(runs: list[dict], which: str, key: str, i: int | None = None):
    v = [r[key] if i is None else r[key][i] for r in runs if _variant_of(r) == which]
    v = [x for x in v if x is not None]
    return float(np.mean(v)) if v else None


def table(data: dict) -> list[str]:
    """The docs' table (docs/studies/membrane_resolution.md): per measure and axial strain,
    the means at the two sides over the seeds and the paired difference (coarse - fine)
    with its standard error, t and whether it is resolved at 95 %; then the peak, the hold's
    correction, the nodes and the wall times."""
    runs, at = data["runs"], data["params"]["at"]
    fine, coarse = variants(data["params"])
    short = _shorts(fine, coarse)
    head = ["measure", "axial strain, %", fine, coarse,
            f"{short[1]} - {short[0]} (+- SE)", "t", "resolved (95 %)"]
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
            out.append(f"| {fine} over {coarse}, wall time of the {what} | - | "
                       f"| | {d['mean']:.2f} ({d['min']:.2f}-{d['max']:.2f}) | | |")
    return out


def variants(params: dict) -> tuple[str, str]:
    """The two variants a data file compares (:func:`variant`), the finer (or the kept
    step) first."""
    side, dt = params["sides"], params.get("dt_safety")
    if dt is None:
        return variant(side[0], None), variant(side[1], None)
    return variant(side[0], None), variant(side[-1], dt)


def main() -> None:
    ap = _cli.study_parser("membrane_resolution", __doc__, runs=True)
    ap.add_argument("--n", type=int, default=1500, help="grains per specimen (--n of the case)")
    ap.add_argument("--seeds", default="1,2,3,4,5", help="comma-separated packing seeds")
    ap.add_argument("--sides", default="1,2", help="the two membrane sides compared (the "
                    "case's --membrane-side), finer first; with --dt-safety, the one side, "
                    "or two: the finer at the protocol's step, the coarser at --dt-safety")
    ap.add_argument("--dt-safety", type=float, default=None,
                    help="compare the protocol's time step with this fraction of the critical "
                         "step, renewed (the case's --dt-safety), at the one side of --sides")
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
    given = ','.join(f'{s:g}' for s in a.sides)
    allowed = [membrane_side_problem(s) is None for s in a.sides]
    if a.dt_safety is not None:
        if (len(a.sides) not in (1, 2) or not all(allowed)
                or (len(a.sides) == 2 and not a.sides[0] < a.sides[1])):
            raise _cli.BenchInputError(f"--sides={given}: with --dt-safety, one side in "
                                       "[0.75, 2], or two, the finer first (the finer at the "
                                       "protocol's step against the coarser at --dt-safety)")
        if not a.dt_safety <= 1:
            raise _cli.BenchInputError(f"--dt-safety={a.dt_safety:g}: must be in (0, 1]")
    elif len(a.sides) != 2 or not a.sides[0] < a.sides[1] or not all(allowed):
        raise _cli.BenchInputError(f"--sides={given}: must be two sides in [0.75, 2], the "
                                   "finer first")
    if a.smoke:
        a.n, a.seeds, a.stop_strain, a.at, a.strain_rate = 300, a.seeds[:2], 0.01, \
            [0.005, 0.01], 0.5
    a.runs = a.runs or str(Path(a.out).with_suffix("")) + "_runs"
    if a.dt_safety is None:
        jobs = [(side, seed, None) for seed in a.seeds for side in a.sides]
    else:
        jobs = [(side, seed, dt) for seed in a.seeds
                for side, dt in ((a.sides[0], None), (a.sides[-1], a.dt_safety))]
    runs = _report.run_jobs(lambda side, seed, dt: run_one(a, side, seed, dt), jobs, a.jobs)
    params = {"sides": a.sides, "dt_safety": a.dt_safety}
    _report.write_study("membrane_resolution.py", a, runs,
                        paired(runs, a.at, *variants(params)), a.out)

if __name__ == "__main__":
    sys.exit(_cli.run(main))
