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
force of member A1. Wall time is preparation + pull in this process.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases"))

import cpp_dem as dem  # noqa: E402
import pullout_000 as case  # noqa: E402
from cpp_dem import pullout  # noqa: E402

#: knob -> (values, index of the reference value, Params field or None)
KNOBS = {
    "scale": ([1e3, 3e3, 1e4, "auto", 1e5], 0, "node_density_scale"),
    "safety": ([0.2, 0.35, 0.5, 0.8], 0, "dt_safety"),
    "damping": ([0.05, 0.1, 0.2, 0.4], 0, "damping"),
    "velocity": ([0.0025, 0.005, 0.01, 0.02, 0.05], 0, "velocity"),
}


def one(base, field: str, value, distance: float) -> dict:
    """The sample is prepared with the default settings (so every run pulls the same,
    bitwise identical, sample); the knob applies to the pull."""
    t0 = time.perf_counter()
    p = replace(base, **{field: value})
    sample = case.build(base)
    pullout.prepare(sample, stress=base.pressure, porosity=base.porosity,
                    node_density_scale="auto")
    sc = sample.scene
    if field == "node_density_scale":
        pullout.set_node_density_scale(
            sample, pullout.auto_node_density_scale(sample) if value == "auto" else value)
    elif field == "dt_safety":
        sc.set_auto_timestep(safety=value, period=100)
    elif field == "damping":
        sc.local_damping = value
    sc.dt = sc.timestep_safety * sc.critical_dt()
    t1 = time.perf_counter()
    rec = pullout.pull(sample, velocity=p.velocity, distance=distance, record_every=50)
    t2 = time.perf_counter()
    return {"force_end_N": float(rec["pull_force"][-1]),
            "force_mean_N": float(rec["pull_force"][1:].mean()),
            "A1_mean_N": float(rec["force_A1"][1:].mean()),
            "grid_kinetic_max_J": float(rec["grid_kinetic_energy"].max()),
            "node_density_scale": sample.node_density_scale, "dt_s": sample.scene.dt,
            "wall_prep_s": t1 - t0, "wall_pull_s": t2 - t1, "wall_s": t2 - t0,
            "inertial_number": pullout.inertial_number(p.velocity, p.unit_weight / 9.81,
                                                       p.pressure)}


def presets_run(base, distance: float) -> list:
    """The three presets against the most accurate value of every knob at once."""
    from cpp_dem import presets

    rho = base.unit_weight / 9.81
    ref = presets.Preset("reference", dt_safety=0.2, node_density_scale=1e3,
                         local_damping=0.05, inertial_number=float("nan"))
    rows = []
    for ps in [ref] + [presets.preset(n) for n in presets.PRESETS]:
        t0 = time.perf_counter()
        sample = case.build(base)
        pullout.prepare(sample, stress=base.pressure, porosity=base.porosity,
                        node_density_scale="auto")
        sc = sample.scene
        pullout.set_node_density_scale(sample, pullout.auto_node_density_scale(sample)
                                       if ps.node_density_scale == "auto"
                                       else float(ps.node_density_scale))
        sc.set_auto_timestep(safety=ps.dt_safety, period=100)
        sc.local_damping = ps.local_damping
        sc.dt = ps.dt_safety * sc.critical_dt()
        v = 0.0025 if ps.name == "reference" else ps.velocity(density=rho, stress=base.pressure)
        t1 = time.perf_counter()
        rec = pullout.pull(sample, velocity=v, distance=distance, record_every=50)
        t2 = time.perf_counter()
        rows.append({"knob": "preset", "value": ps.name, "velocity_m_s": v,
                     "force_end_N": float(rec["pull_force"][-1]),
                     "force_mean_N": float(rec["pull_force"][1:].mean()),
                     "A1_mean_N": float(rec["force_A1"][1:].mean()), "dt_s": sc.dt,
                     "wall_pull_s": t2 - t1, "wall_s": t2 - t0,
                     "inertial_number": pullout.inertial_number(v, rho, base.pressure)})
    for r in rows:
        for k in ("force_end_N", "force_mean_N", "A1_mean_N"):
            r[f"err_{k}"] = (r[k] - rows[0][k]) / rows[0][k]
        r["cost_vs_reference"] = r["wall_s"] / rows[0]["wall_s"]
        print(json.dumps(r, default=float), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--knobs", nargs="*", choices=sorted(KNOBS), default=list(KNOBS))
    ap.add_argument("--distance", type=float, default=0.02, help="pull distance, m")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--presets", action="store_true",
                    help="measure the presets fast/balanced/accurate against the most "
                         "accurate value of every knob at once, instead of the knobs")
    a = ap.parse_args(argv)
    dem.set_num_threads(a.threads)
    base = case.Params(**case.SMOKE)
    table = presets_run(base, a.distance) if a.presets else []
    if a.presets:
        a.knobs = []
    for knob in a.knobs:
        values, ref_i, field = KNOBS[knob]  # noqa: B007
        runs = []
        for v in values:
            r = one(base, field, v, a.distance)
            r.update(knob=knob, value=v)
            runs.append(r)
        ref = runs[ref_i]
        for r in runs:
            for k in ("force_end_N", "force_mean_N", "A1_mean_N"):
                r[f"err_{k}"] = (r[k] - ref[k]) / ref[k]
            r["cost_vs_reference"] = r["wall_s"] / ref["wall_s"]
            print(json.dumps(r, default=float), flush=True)
            table.append(r)
    print("\n| knob | value | wall (s) | cost / ref | F end (N) | err F end | err F mean | "
          "err A1 mean | dt (s) | I |", file=sys.stderr)
    print("|---|---|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for r in table:
        print(f"| {r['knob']} | {r['value']} | {r['wall_s']:.1f} | {r['cost_vs_reference']:.2f}"
              f" | {r['force_end_N']:.0f} | {100 * r['err_force_end_N']:+.1f} % | "
              f"{100 * r['err_force_mean_N']:+.1f} % | {100 * r['err_A1_mean_N']:+.1f} % | "
              f"{r['dt_s']:.2g} | {r['inertial_number']:.2g} |", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
