"""Pareto plots of the speed-accuracy benches (issue 7): cost against error, one series per
knob, the presets marked, the non-dominated points joined.

    .venv/bin/python bench/pareto.py results/speed_accuracy/pullout.jsonl \\
        results/speed_accuracy/triaxial.jsonl --out docs/img

Reads the JSON lines written with --out by bench/speed_accuracy.py (case "pullout") and
bench/triaxial_accuracy.py (case "triaxial") and bench/coupled_accuracy.py (case "coupled");
writes pareto_<case>.png per case found. The
error of a knob's run is against that knob's own reference (its most accurate value, the
other knobs at their defaults); the presets' error is against all knobs at their most
accurate values at once. Errors below FLOOR are drawn at FLOOR (log axis).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

#: case -> (error key, or {knob: key}, label of the error axis)
ERRORS = {
    "pullout": ("err_force_mean_N", "|error| of the mean pull-out force"),
    "pullout_full": ("err_force_mean_N", "|error| of the mean pull-out force"),
    "triaxial": ("err_q_peak", "|error| of the peak deviator q"),
    "coupled": ({"fem_mesh": "err_prs_minus_re", "two_way_tol": "err_vs_last",
                 "preset": "err_vs_reference"},
                "|error| of the handed-over stresses (mesh: PRS − RE; tol: targets)"),
}


def error_of(case: str, r: dict) -> float | None:
    """The plotted error of row ``r`` (None: the row is not a knob run)."""
    key = ERRORS[case][0]
    if isinstance(key, dict):
        key = key.get(r.get("knob"))
    return None if key is None or key not in r else abs(r[key])
FLOOR = 1e-3  #: smallest error drawn (the references themselves), -
MARKERS = "osD^v<>ph*"


def read(paths: list) -> dict:
    """Rows per case from JSONL files; a later row with the same (knob, value) replaces an
    earlier one (re-runs)."""
    cases: dict = {}
    for path in paths:
        for line in Path(path).read_text().splitlines():
            if not line.strip():
                continue
            r = json.loads(line)
            cases.setdefault(r.get("case", "pullout"), {})[(r["knob"], str(r["value"]))] = r
    return {c: list(rows.values()) for c, rows in cases.items()}


def front(points: list) -> list:
    """Non-dominated (error, cost) points, sorted by error."""
    pts = sorted(points)
    out, best = [], float("inf")
    for e, c in pts:
        if c < best:
            out.append((e, c))
            best = c
    return out


def plot(case: str, rows: list, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    label = ERRORS[case][1]
    rows = [r for r in rows if error_of(case, r) is not None]
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    knobs = [k for k in dict.fromkeys(r["knob"] for r in rows) if k != "preset"]
    pts = []
    for i, knob in enumerate(knobs):
        sel = [r for r in rows if r["knob"] == knob]
        e = [max(error_of(case, r), FLOOR) for r in sel]
        c = [r["cpu_s"] for r in sel]
        ax.plot(e, c, MARKERS[i % len(MARKERS)], ls=":", label=knob, alpha=0.8)
        for r, x, y in zip(sel, e, c):
            ax.annotate(str(r["value"]), (x, y), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        pts += list(zip(e, c))
    pre = [r for r in rows if r["knob"] == "preset"]
    if pre:
        e = [max(error_of(case, r), FLOOR) for r in pre]
        c = [r["cpu_s"] for r in pre]
        ax.plot(e, c, "k*", ms=13, label="presets (vs all-accurate reference)")
        for r, x, y in zip(pre, e, c):
            ax.annotate(str(r["value"]), (x, y), fontsize=9, weight="bold", xytext=(5, -10),
                        textcoords="offset points")
        pts += list(zip(e, c))
    if case != "coupled":  # there the two knobs' costs are of different runs
        f = front(pts)
        ax.plot([p[0] for p in f], [p[1] for p in f], "-", color="grey", lw=1, alpha=0.6,
                label="non-dominated")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"{label} (errors < {FLOOR:g} drawn at {FLOOR:g})")
    ax.set_ylabel("CPU time of the run, s (one thread)")
    if case == "coupled":
        ax.set_ylabel("CPU time, s (mesh: FEM of RE + PRS; tol: the two-way run so far)")
    ax.set_title(f"Speed-accuracy, {case}: one knob at a time")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("jsonl", nargs="+", type=Path, help="JSONL files of the benches")
    ap.add_argument("--out", type=Path, default=Path("results/speed_accuracy"),
                    help="directory for pareto_<case>.png")
    a = ap.parse_args(argv)
    for p in a.jsonl:
        if not p.is_file():
            ap.error(f"{p}: no such file")
    a.out.mkdir(parents=True, exist_ok=True)
    for case, rows in read(a.jsonl).items():
        if case not in ERRORS:
            print(f"skipping unknown case {case!r}", file=sys.stderr)
            continue
        png = a.out / f"pareto_{case}.png"
        plot(case, rows, png)
        print(f"{png}: {len(rows)} runs")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
