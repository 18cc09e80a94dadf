"""Speed-accuracy trade of the 000 pull-out (issue 7, first part). Not a test: one JSON line
per run, then a Markdown table on stderr.

    .venv/bin/python bench/speed_accuracy.py [--knobs scale safety damping velocity]
                                             [--distance 0.02] [--threads 1]

Every run pulls the same sample: the 000 smoke scene (375 spheres, half-size box) prepared
with the default settings; the knob applies to the pull over --distance (varying it in the
preparation too would mix in the sample-to-sample scatter: dt safety 0.2 in the preparation
gave a 37 % higher force at 20 mm, a different packing, not a more accurate pull). One knob varies at a time; the reference is the most
accurate value of that knob with the others at their defaults. Errors are relative to the
reference: the pull-out force at the end of the pull, the mean pull-out force, and the mean
forces of members A1 and A2. Cost is the CPU time of preparation + pull in this process (one
thread: the wall time on an idle machine, not inflated by other jobs); wall time is reported
too. The spheres knob prepares a new sample per count (REFD to the same porosity), so its
error includes the sample-to-sample scatter. --full runs the full 000 scene instead.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np


ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases"))
sys.path.insert(0, str(ROOT / "bench"))

import cpp_dem as dem  # noqa: E402
from _report import emit, markdown_table, pct  # noqa: E402
import pullout_000 as case  # noqa: E402
from cpp_dem.protocols import pullout  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

#: knob -> (values, index of the reference value, Params field or None)
KNOBS = {
    "scale": ([1e3, 3e3, 1e4, "auto", 1e5], 0, "node_density_scale"),
    "safety": ([0.2, 0.35, 0.5, 0.8], 0, "dt_safety"),
    "damping": ([0.05, 0.1, 0.2, 0.4], 0, "damping"),
    "velocity": ([0.0025, 0.005, 0.01, 0.02, 0.05], 0, "velocity"),
    # A new sample per value (REFD to the same porosity): includes the sample-to-sample scatter.
    "spheres": ([3000, 1500, 750, 375], 0, "spheres"),
}


CASE = "pullout"  #: the case name in the JSON lines ("pullout_full" with --full)


def run_pull(base, distance: float, velocity: float, **settings) -> dict:
    """Prepares the sample with the default settings (so every run pulls the same, bitwise
    identical, sample), applies the pull settings with pullout.apply_preset (dt_safety,
    node_density_scale, local_damping; each defaults to what the preparation left) and pulls
    at ``velocity`` (m/s) over ``distance`` (m)."""
    from cpp_dem.presets import Preset

    t0, c0 = time.perf_counter(), time.process_time()
    sample = case.build(base)
    pullout.prepare(sample, stress=base.pressure, porosity=base.porosity,
                    node_density_scale="auto")
    sc = sample.scene
    pullout.apply_preset(sample, Preset(
        "run", dt_safety=settings.get("dt_safety", base.dt_safety),
        node_density_scale=settings.get("node_density_scale", sample.node_density_scale),
        local_damping=settings.get("local_damping", base.damping),
        inertial_number=float("nan")))
    t1 = time.perf_counter()
    rec = pullout.pull(sample, velocity=velocity, distance=distance, record_every=50)
    t2, c2 = time.perf_counter(), time.process_time()
    rho = base.unit_weight / 9.81
    # Initial peak on a uniform 0.5 mm grid of the displacement, so every run is smoothed
    # over the same distance whatever its time step and record spacing.
    grid = np.arange(0.0, float(rec["displacement"][-1]), 5e-4)
    peak_at, peak = pullout.first_peak(grid, np.interp(grid, rec["displacement"],
                                                       rec["pull_force"]))
    return {"velocity_m_s": velocity, "force_end_N": float(rec["pull_force"][-1]),
            "force_peak_N": peak, "peak_at_m": peak_at,
            "force_mean_N": float(rec["pull_force"][1:].mean()),
            "force_max_N": float(rec["pull_force"].max()),
            "A1_mean_N": float(rec["force_A1"][1:].mean()),
            "A2_mean_N": float(rec["force_A2"][1:].mean()),
            "n_spheres": base.spheres, "cpu_s": c2 - c0,
            "grid_kinetic_max_J": float(rec["grid_kinetic_energy"].max()),
            "node_density_scale": sample.node_density_scale, "dt_s": sc.dt,
            "wall_prep_s": t1 - t0, "wall_pull_s": t2 - t1, "wall_s": t2 - t0,
            "inertial_number": pullout.inertial_number(velocity, rho, base.pressure)}


OUTPUTS = ("force_end_N", "force_peak_N", "force_max_N", "force_mean_N", "A1_mean_N",
           "A2_mean_N")


def over_seeds(base, field: str, value, distance: float, seeds: int) -> dict:
    """The knob at ``value`` on samples of seeds 1..``seeds``: the mean of every output and
    CPU time over the samples, and each output's sample standard deviation (``sd_...``)."""
    runs = [one(dataclasses.replace(base, seed=k), field, value, distance)
            for k in range(1, seeds + 1)]
    row = dict(runs[0])
    for k in (*OUTPUTS, "cpu_s", "wall_s"):
        vals = [r[k] for r in runs]
        row[k] = float(sum(vals) / len(vals))
        if k in OUTPUTS:
            m = row[k]
            row[f"sd_{k}"] = float((sum((v - m) ** 2 for v in vals) / (len(vals) - 1)) ** 0.5)
    row["seeds"] = seeds
    return row


def one(base, field: str, value, distance: float) -> dict:
    """One knob (a Params field) at ``value`` for the pull, the others at their defaults."""
    if field == "velocity":
        return run_pull(base, distance, value)
    if field == "spheres":
        # Initial radii scaled with the count so the loose cloud fits the box; REFD then grows
        # every sample to the same porosity.
        f = (base.spheres / int(value)) ** (1.0 / 3.0)
        return run_pull(dataclasses.replace(base, spheres=int(value),
                                            radius_mean=base.radius_mean * f,
                                            radius_dispersion=base.radius_dispersion * f),
                        distance, base.velocity)
    key = {"damping": "local_damping"}.get(field, field)
    return run_pull(base, distance, base.velocity, **{key: value})


def with_errors(rows: list, ref: dict, out: Path | None = None) -> None:
    """Adds the relative errors and the cost (CPU time) against ``ref`` to every row, prints
    it and appends it to ``out``."""
    for r in rows:
        for k in OUTPUTS:
            r[f"err_{k}"] = (r[k] - ref[k]) / ref[k]
        r["cost_vs_reference"] = r["cpu_s"] / ref["cpu_s"]
        emit({"case": CASE, **r}, out)


def presets_run(base, distance: float, out: Path | None = None) -> list:
    """The three presets against the most accurate value of every knob at once."""
    from cpp_dem import presets

    rho = base.unit_weight / 9.81
    rows = [{"knob": "preset", "value": "reference",
             **run_pull(base, distance, 0.0025, dt_safety=0.2, node_density_scale=1e3,
                        local_damping=0.05)}]
    for name in presets.PRESETS:
        ps = presets.preset(name)
        rows.append({"knob": "preset", "value": name,
                     **run_pull(base, distance, ps.velocity(density=rho, stress=base.pressure),
                                dt_safety=ps.dt_safety,
                                node_density_scale=ps.node_density_scale,
                                local_damping=ps.local_damping)})
    with_errors(rows, rows[0], out)
    return rows


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="append", description=__doc__.split("\n\n")[0])
    ap.add_argument("--knobs", nargs="*", choices=sorted(KNOBS), default=list(KNOBS))
    ap.add_argument("--distance", type=float, default=0.02, help="pull distance, m")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--full", action="store_true",
                    help="the full 000 scene (3000 spheres, 1 x 0.5 x 0.5 m) instead of the "
                         "smoke scene; the spheres knob then runs 3000, 6000, 9000")
    ap.add_argument("--out", type=Path, default=None,
                    help="append the JSON lines to this file (for bench/pareto.py)")
    ap.add_argument("--seeds", type=int, default=1,
                    help="spheres knob: samples per count (seeds 1..K); rows hold the means "
                         "over the samples and their standard deviations (sd_*)")
    ap.add_argument("--presets", action="store_true",
                    help="measure the presets fast/balanced/accurate against the most "
                         "accurate value of every knob at once, instead of the knobs")
    a = ap.parse_args(argv)
    if a.seeds < 1:
        ap.error(f"--seeds={a.seeds}: must be >= 1")
    dem.set_num_threads(a.threads)
    base = case.Params() if a.full else case.Params(**case.SMOKE)
    if a.full:
        global CASE
        CASE = "pullout_full"
        KNOBS["spheres"] = ([9000, 6000, 3000], 0, "spheres")
    table = presets_run(base, a.distance, a.out) if a.presets else []
    if a.presets:
        a.knobs = []
    for knob in a.knobs:
        values, ref_i, field = KNOBS[knob]
        if a.seeds > 1 and knob == "spheres":
            runs = [{**over_seeds(base, field, v, a.distance, a.seeds), "knob": knob,
                     "value": v} for v in values]
        else:
            runs = [{**one(base, field, v, a.distance), "knob": knob, "value": v}
                    for v in values]
        with_errors(runs, runs[ref_i], a.out)
        table += runs
    markdown_table(table, [
        ("knob", lambda r: str(r["knob"])), ("value", lambda r: str(r["value"])),
        ("CPU (s)", lambda r: f"{r['cpu_s']:.1f}"),
        ("cost / ref", lambda r: f"{r['cost_vs_reference']:.3f}"),
        ("F end (N)", lambda r: f"{r['force_end_N']:.0f}"),
        ("err F end", lambda r: pct(r["err_force_end_N"])),
        ("err F mean", lambda r: pct(r["err_force_mean_N"])),
        ("err F max", lambda r: pct(r["err_force_max_N"])),
        ("F peak (N) at (mm)", lambda r: f"{r['force_peak_N']:.0f} at {1e3 * r['peak_at_m']:.1f}"),
        ("err F peak", lambda r: pct(r["err_force_peak_N"])),
        ("err A1 mean", lambda r: pct(r["err_A1_mean_N"])),
        ("err A2 mean", lambda r: pct(r["err_A2_mean_N"])),
        ("dt (s)", lambda r: f"{r['dt_s']:.2g}"), ("I", lambda r: f"{r['inertial_number']:.2g}")])
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
