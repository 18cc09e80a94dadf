"""A geogrid layer's effect in the triaxial case, in the cylinder (a disc in a membrane) and in
the box (the thesis's square layer), over packing seeds (issue 65 item 4). Not a test: runs
the case, prints JSON lines and writes one JSON file.

For each seed and each shape (``--shapes``: ``cylinder``, ``box``), ``cases/triaxial.py
--smoke --n N --seed S --specimen SHAPE --stop-strain E --strain-rate R`` runs with
``--geogrid G`` and with ``--clear-layer`` (the same grains removed, no grid: the same packing
without it, as the thesis compares) into ``<--runs>/<shape>_<G or cleared>_s<seed>/`` (a run
whose summary.json is there is read, not run again: an interrupted study goes on where it
stopped; ``--jobs`` at a time). Each run's deviator q (Pa) and volumetric strain (-) are read
from its triaxial.csv at the ``--at`` axial strains (linear between rows); then, per shape,
the paired difference with - without the grid over the seeds, with its standard error and
Student's t (resolved at 95 % when |t| > t(0.975, n - 1)).

    .venv/bin/python bench/triaxial_disc.py --seeds 1,2,3,4,5 --runs results/triaxial_disc_runs \
        --out docs/data/triaxial_disc.json
    .venv/bin/python bench/triaxial_disc.py --smoke --out /tmp/td.json
    .venv/bin/python bench/triaxial_disc.py --table docs/data/triaxial_disc.json \
        --figure docs/img/triaxial_disc.png
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)
import _report  # noqa: E402
from geogrid_dem.stats import paired_difference, resolved  # noqa: E402



def _run_dir(runs: Path, shape: str, grid: str, seed: int) -> Path:
    return runs / f"{shape}_{grid}_s{seed}"


def run_one(a, shape: str, grid: str, seed: int) -> dict:
    """The case's run for (shape, grid, seed), or its earlier run's files; its readings."""
    d = _run_dir(Path(a.runs), shape, grid, seed)
    if not (d / "summary.json").exists():
        which = ["--clear-layer"] if grid == "cleared" else ["--geogrid", grid]
        _cli.run_triaxial_case(["--smoke", "--n", str(a.n), "--seed", str(seed), "--specimen",
                                shape, *which, "--stop-strain", repr(a.stop_strain),
                                "--strain-rate", repr(a.strain_rate), "--threads", "1",
                                "--out", str(d), "--overwrite"],
                               f"{shape}, {' '.join(which)}, seed {seed}")
    rows = list(csv.DictReader(open(d / "triaxial.csv")))
    e = np.array([float(r["axial_strain"]) for r in rows])
    cols = {key: np.array([float(r[key]) for r in rows])
            for key in ("deviatoric_stress", "volumetric_strain")}
    out = {"shape": shape, "grid": grid, "seed": seed}
    for key, v in cols.items():
        out[key] = [float(np.interp(s, e, v)) if s <= e[-1] else None for s in a.at]
    # the curves on a common grid of axial strain (every 0.1 %), for the figure
    grid_e = np.round(np.arange(0.0, e[-1] + 1e-12, 0.001), 6)
    out["curve"] = {"axial_strain": grid_e.tolist(),
                    **{key: np.interp(grid_e, e, v).tolist() for key, v in cols.items()}}
    s = json.loads((d / "summary.json").read_text())
    out["num_grains"] = s["num_grains"]
    # the cylinder's base against its lid (less by what the membrane carries through its
    # friction with the grains, and by the loading's dynamics), from its CSV
    if "base_stress" in rows[0]:
        out["platen_difference_max"] = max(
            abs(float(r["axial_stress"]) - float(r["base_stress"])) / float(r["axial_stress"])
            for r in rows)
    out["geogrid_members"] = s.get("geogrid_members", 0)
    return out


def paired(runs: list[dict], at: list[float], grid: str) -> list[dict]:
    """with - without the grid (its layer cleared) per seed, per shape, measure and strain:
    n, mean, se, t, resolved."""
    by = {(r["shape"], r["grid"], r["seed"]): r for r in runs}
    out = []
    for shape in sorted({r["shape"] for r in runs}):
        seeds = sorted({r["seed"] for r in runs if r["shape"] == shape})
        for key in ("deviatoric_stress", "volumetric_strain"):
            for i, s in enumerate(at):
                d = [by[shape, grid, k][key][i] - by[shape, "cleared", k][key][i] for k in seeds
                     if (shape, grid, k) in by and (shape, "cleared", k) in by
                     and by[shape, grid, k][key][i] is not None
                     and by[shape, "cleared", k][key][i] is not None]
                p = paired_difference(d)
                out.append({"shape": shape, "measure": key, "axial_strain": s, **p,
                            "resolved": resolved(p["t"], p["n"])})
    return out


def table(data: dict) -> list[str]:
    """The docs' table (docs/studies/triaxial_disc.md): per shape, axial strain and measure,
    the means without and with the grid over the seeds, and the paired difference with its
    standard error, t and whether it is resolved at 95 %."""
    runs, at, grid = data["runs"], data["params"]["at"], data["params"]["geogrid"]
    head = ["specimen", "axial strain, %", "measure", "layer cleared", f"{grid} grid",
            "with - without (+- SE)", "t", "resolved (95 %)"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    pairs = {(d["shape"], d["measure"], d["axial_strain"]): d for d in data["paired"]}
    for shape in data["params"]["shapes"]:
        for i, e in enumerate(at):
            for key, name, scale, digits in (("deviatoric_stress", "q, kPa", 1e-3, 1),
                                             ("volumetric_strain", "volumetric strain, %",
                                              100, 3)):
                mean = {}
                for g in ("cleared", grid):
                    v = [r[key][i] for r in runs if r["shape"] == shape and r["grid"] == g
                         and r[key][i] is not None]
                    mean[g] = float(np.mean(v)) if v else None
                d = pairs[shape, key, e]
                res = "yes" if d["resolved"] else ("no" if d["n"] > 1 else "-")
                out.append(f"| {shape} | {100 * e:g} | {name} | "
                           f"{_report.fmt(mean['cleared'], scale, digits)}"
                           f" | {_report.fmt(mean[grid], scale, digits)} | "
                           f"{_report.fmt(d['mean'], scale, digits)} +- {_report.fmt(d['se'], scale, digits)}"
                           f" | {_report.fmt(d['t'], 1, 1)} | {res} |")
    return out


def figure(data: dict, png: Path) -> None:
    """The mean curves over the seeds (q and the volumetric strain against the axial strain)
    of each shape with its grid and with its layer cleared, +- one standard deviation of the
    seeds shaded: the docs' figure (docs/img/triaxial_disc.png)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grid = data["params"]["geogrid"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for shape, colour in (("cylinder", "tab:blue"), ("box", "tab:orange")):
        for g, style in (("cleared", "-"), (grid, "--")):
            runs = [r for r in data["runs"] if r["shape"] == shape and r["grid"] == g]
            if not runs:
                continue
            n = min(len(r["curve"]["axial_strain"]) for r in runs)
            e = 100 * np.array(runs[0]["curve"]["axial_strain"][:n])
            label = f"{shape}, {'layer cleared' if g == 'cleared' else g + ' grid'}"
            for a, key, scale in ((ax[0], "deviatoric_stress", 1e-3),
                                  (ax[1], "volumetric_strain", 100)):
                v = scale * np.array([r["curve"][key][:n] for r in runs])
                m = v.mean(axis=0)
                a.plot(e, m, style, color=colour, label=label)
                if len(runs) > 1:
                    sd = v.std(axis=0, ddof=1)
                    a.fill_between(e, m - sd, m + sd, color=colour, alpha=0.12, lw=0)
    ax[0].set_ylabel("q (kPa)")
    ax[1].set_ylabel("volumetric strain (%, compression +)")
    for a in ax:
        a.set_xlabel("axial strain (%)")
        a.grid(alpha=0.3)
    ax[0].legend(fontsize=8)
    seeds = sorted({r["seed"] for r in data["runs"]})
    fig.suptitle(f"Triaxial, {data['params']['n']} grains at "
                 f"{data['params']['strain_rate']:g} /s: the cylinder in a membrane beside the box\n"
                 f"(the cylinder's q on its corrected cross-section, its volume from the "
                 f"membrane); mean of "
                 f"{len(seeds)} seeds +- 1 sd", fontsize=10)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = _cli.study_parser("triaxial_disc", __doc__, runs=True)
    ap.add_argument("--n", type=int, default=1500, help="grains per specimen (--n of the case)")
    ap.add_argument("--seeds", default="1,2,3,4", help="comma-separated packing seeds")
    ap.add_argument("--shapes", default="cylinder,box", help="cylinder, box or both")
    ap.add_argument("--geogrid", default="square", choices=("square", "triangular"),
                    help="the grid compared with its layer cleared")
    ap.add_argument("--stop-strain", type=float, default=0.04, help="axial strain to reach, -")
    ap.add_argument("--strain-rate", type=float, default=0.1,
                    help="axial strain rate, 1/s (the case's smoke loads at 0.5, where the "
                         "cylinder's lid runs up to 15 %% ahead of its base)")
    ap.add_argument("--at", default="0.01,0.02,0.03,0.04",
                    help="axial strains to read q and the volumetric strain at")
    ap.add_argument("--jobs", type=int, default=2, help="runs at a time (one thread each)")
    ap.add_argument("--smoke", action="store_true",
                    help="300 grains, one seed, the cylinder only, to 1 %%")
    ap.add_argument("--figure", default="", help="with --table: also draw the mean curves "
                    "of that data file into this PNG")
    a = ap.parse_args()
    if a.figure and not a.table:
        raise _cli.BenchInputError(f"--figure={a.figure}: draws a data file's curves; give "
                                   "that file with --table")
    if a.table:
        data = json.loads(Path(a.table).read_text())
        print("\n".join(table(data)))
        if a.figure:
            figure(data, Path(a.figure))
        return
    a.seeds = _cli.numbers(a.seeds, "--seeds", kind=int, lo="nonneg")
    a.at = _cli.numbers(a.at, "--at")
    a.shapes = [s.strip() for s in a.shapes.split(",")]
    bad = [s for s in a.shapes if s not in ("cylinder", "box")]
    if bad or not a.shapes:
        raise _cli.BenchInputError(f"--shapes={','.join(a.shapes)!r}: must be cylinder, box "
                                   "or both, comma-separated")
    if a.smoke:
        a.n, a.seeds, a.stop_strain, a.at, a.shapes = 300, a.seeds[:1], 0.01, [0.005, 0.01], \
            ["cylinder"]
        a.strain_rate = 0.5
    a.runs = a.runs or str(Path(a.out).with_suffix("")) + "_runs"
    jobs = [(shape, g, seed) for seed in a.seeds for shape in a.shapes
            for g in ("cleared", a.geogrid)]
    runs = _report.run_jobs(lambda *j: run_one(a, *j), jobs, a.jobs, hide=("curve",))
    _report.write_study("triaxial_disc.py", a, runs, paired(runs, a.at, a.geogrid), a.out)

if __name__ == "__main__":
    sys.exit(_cli.run(main))
