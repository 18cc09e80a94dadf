"""Density scaling's trade on the 002 element: the same stress path with and without scaling.

    .venv/bin/python bench/quasi_static.py                       # seed 1, the default sweep
    .venv/bin/python bench/quasi_static.py --seeds 1,2,3 --sweep 8 --out results/quasi_static

One clump element of "Microscopic interaction effects of prestressed geogrids in a reinforced
soil element" (002: gravel clumps, Hertz–Mindlin, the woven detailed grid; RE) is prepared
unscaled per seed and servoed to the isotropic --pressure; that state is saved. From it, each
variant runs the same loading: axial (z) compression at the strain rate of --inertial-number
(for the unscaled grains) to --strain, x and y servoed at the pressure (the triaxial
protocol's deviatoric stage). The unscaled run is the reference; the scaled runs turn density
scaling on (cpp_dem.protocols.quasi_static) with target dt = S x the unscaled reference step,
for each S of --sweep. The loading rate is physical (1/s), so a scaled run takes fewer steps.

Per variant: wall time, steps, dt, the wall-stress path against axial strain, the porosity,
the largest inertia factor and the share of bodies scaled, the sample's inertial number
(Scene.density_scaling_stats) and 002's grid measures at the end. The errors are against the
same seed's unscaled run, interpolated onto its strains:
- ``stress_error_rms``: sqrt(mean over the records and the three axes of (sigma - sigma_ref)^2)
  / sqrt(mean of sigma_ref^2), -;
- ``deviator_error_rms``: the same for q = sigma_z - (sigma_x + sigma_y) / 2, -.

The final JSON line summarises the --main setting (mean over seeds): ``speedup`` (unscaled
wall time / scaled), ``stress_error_rms``, ``deviator_error_rms``, the inertial numbers, the
porosities, and the 002 measures with, over the seeds, the unscaled runs' standard deviation
and the paired difference (scaled - unscaled) with its standard error. ``pareto`` lists the
sweep's (error, cost) points that no other point beats on both. Rows go to --out as JSON
lines (one per variant) and a figure pareto_quasi_static.png.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

ROOT = Path(__file__).resolve().parents[1]


def log(msg: str) -> None:
    print(f"[quasi_static] {msg}", file=sys.stderr, flush=True)


def prepare(args, seed: int):
    """The element of ``seed`` grown and servoed unscaled to the isotropic pressure; returns
    (params, sample, grid, checkpoint bytes, preparation seconds)."""
    from cpp_dem import _core
    from cpp_dem.elements.box import make_woven_element, servo_stage
    from geogrid_dem.cases import prs_element_002 as case

    p = replace(case.Params(**case.SMOKE), n=args.n, seed=seed, threads=args.threads,
                geogrid=f"woven-{args.grid}", grains=args.grains, unbalanced=0.05,
                hold_steps=200)
    from cpp_dem.scene import apply_threads

    apply_threads(args.threads)
    t0 = time.perf_counter()
    sample, grid, _ = make_woven_element(p, args.pressure, False, log=lambda m: log(m))
    servo_stage(sample, grid, [args.pressure] * 3, 0, p, lambda **r: None,
                log=lambda m: log(m))
    return p, sample, grid, bytes(_core._checkpoint_save(sample.scene)), time.perf_counter() - t0


def measures(sample, grid, p, ref_pos) -> dict:
    """002's grid measures at the end of a variant (plain numbers)."""
    from cpp_dem.measure import grid_soil

    s = grid_soil.summary(sample.scene, grid, z_grid=0.5 * p.edge, reference_positions=ref_pos)
    f = grid_soil.member_force_profiles(sample.scene, grid)
    return {"contacts_longitudinal_per_m": s["contacts"]["longitudinal_per_m"],
            "grains_touching": s["contacts"]["grains_touching"],
            "out_of_plane_longitudinal_mean_m": s["waviness"]["out_of_plane_longitudinal_mean_m"],
            "grid_force_longitudinal_mean_n": f["longitudinal_force_mean_n"],
            "disp_above_mean_m": s["displacement"]["above_mean_m"],
            "disp_below_mean_m": s["displacement"]["below_mean_m"]}


def variant(args, p, sample, grid, blob: bytes, speedup: float, safety: float = 0.0) -> dict:
    """The loading from the saved state, unscaled (speedup 0) or scaled; ``safety`` > 0 sets
    the unscaled automatic step's safety (the noise-floor run)."""
    from cpp_dem import _core, measure
    from cpp_dem.protocols import quasi_static, triaxial

    sc = sample.scene
    _core._checkpoint_load(sc, blob)
    if safety:
        sc.set_auto_timestep(safety=safety, period=100)
    if speedup:
        quasi_static.enable(sc, speedup)
    d = float(np.mean(measure.grain_diameters(sc)))
    rho = sc.material(sample.material).density
    rate = args.inertial_number * math.sqrt(args.pressure / rho) / d
    ref_pos = sc.positions.copy()
    step0 = sc.step_count
    t0 = time.perf_counter()
    path = triaxial.deviatoric_stage(sample, args.pressure, rate, args.strain,
                                     record_every=args.record_every)
    wall = time.perf_counter() - t0
    st = quasi_static.report(sc)
    row = {"speedup_setting": speedup, "seed": p.seed, "wall_s": wall,
           "steps": sc.step_count - step0, "dt_s": sc.dt, "strain_rate_per_s": rate,
           "max_factor": st["max_factor"], "scaled_share": st["scaled_share"],
           "inertial_number_sample": st["inertial_number"],
           "inertial_number_loading": args.inertial_number * math.sqrt(st["mean_factor"]),
           "porosity": float(path["porosity"][-1]),
           "path": {k: path[k].tolist() for k in ("axial_strain", "sigma_x", "sigma_y",
                                                  "sigma_z")},
           "measures": measures(sample, grid, p, ref_pos)}
    if speedup:
        quasi_static.disable(sc)
    return row


def binned(path: dict, edges: np.ndarray) -> np.ndarray:
    """The wall stresses (3, bins) averaged over the records in each strain bin, Pa."""
    e = np.asarray(path["axial_strain"])
    k = np.clip(np.digitize(e, edges) - 1, 0, len(edges) - 2)
    inside = (e >= edges[0]) & (e <= edges[-1])
    out = np.full((3, len(edges) - 1), np.nan)
    for a, key in enumerate(("sigma_x", "sigma_y", "sigma_z")):
        v = np.asarray(path[key])
        for b in range(len(edges) - 1):
            sel = inside & (k == b)
            if sel.any():
                out[a, b] = v[sel].mean()
    return out


def errors(row: dict, ref: dict, bins: int) -> dict:
    """The variant's wall-stress path against the reference's: both averaged in ``bins``
    equal bins of axial strain (the records' stick-slip fluctuations averaged out)."""
    top = min(max(ref["path"]["axial_strain"]), max(row["path"]["axial_strain"]))
    edges = np.linspace(0.0, top, bins + 1)
    s_ref, s = binned(ref["path"], edges), binned(row["path"], edges)
    ok = np.all(np.isfinite(s_ref) & np.isfinite(s), axis=0)
    s_ref, s = s_ref[:, ok], s[:, ok]
    q_ref = s_ref[2] - 0.5 * (s_ref[0] + s_ref[1])
    q = s[2] - 0.5 * (s[0] + s[1])
    scale = np.sqrt(np.mean(s_ref ** 2))
    return {"stress_bias": float(np.mean(s - s_ref) / scale),
            "sigma_z_bias": float(np.mean(s[2] - s_ref[2]) / scale),
            "stress_error_rms": float(np.sqrt(np.mean((s - s_ref) ** 2) / np.mean(s_ref ** 2))),
            "deviator_error_rms": float(np.sqrt(np.mean((q - q_ref) ** 2) / np.mean(q_ref ** 2))),
            "speedup": ref["wall_s"] / row["wall_s"]}


def pareto(points: list) -> list:
    """The points (dicts with stress_error_rms and cost) no other point beats on both."""
    out, best = [], float("inf")
    for pt in sorted(points, key=lambda r: (r["stress_error_rms"], r["cost"])):
        if pt["cost"] < best:
            out.append(pt)
            best = pt["cost"]
    return out


def plot(rows: list, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.0), constrained_layout=True)
    pts = [r for r in rows if r["speedup_setting"]]
    ax.loglog([max(r["stress_error_rms"], 1e-4) for r in pts], [1 / r["speedup"] for r in pts],
              "ko", ms=4)
    for r in pts:
        ax.annotate(f"S={r['speedup_setting']:g}", (max(r["stress_error_rms"], 1e-4),
                                                    1 / r["speedup"]), fontsize=7,
                    xytext=(3, 3), textcoords="offset points")
    ax.axvline(0.02, color="0.6", lw=0.8, ls="--")
    ax.set_xlabel("relative rms error of the wall-stress path, -")
    ax.set_ylabel("wall time / unscaled wall time, -")
    ax.set_title("density scaling on the 002 element (each seed's own reference)", fontsize=9)
    fig.savefig(out / "pareto_quasi_static.png", dpi=120)
    plt.close(fig)


def _mean_se(x) -> tuple:
    """(mean, standard error over the seeds; None for one seed)."""
    x = np.asarray(x, float)
    return float(x.mean()), (float(x.std(ddof=1) / math.sqrt(len(x))) if len(x) > 1 else None)


def summarise(rows: list, args, seeds: list, sweep: list) -> dict:
    """The per-variant lines and the final summary of ``rows`` (see the module docstring)."""
    for r in rows:
        if r["speedup_setting"] != 0:
            r.update(errors(r, next(x for x in rows if x["seed"] == r["seed"]
                                    and x["speedup_setting"] == 0), args.bins))
    for r in rows:
        print(json.dumps({k: v for k, v in r.items() if k != "path"}))
    sweep_rows = []
    for s in sweep:
        rs = [r for r in rows if r["speedup_setting"] == s]
        sweep_rows.append({"speedup_setting": s,
                           "speedup": float(np.mean([r["speedup"] for r in rs])),
                           "cost": float(np.mean([1 / r["speedup"] for r in rs])),
                           "stress_error_rms": float(np.mean([r["stress_error_rms"] for r in rs])),
                           "deviator_error_rms": float(np.mean([r["deviator_error_rms"]
                                                                for r in rs])),
                           "max_factor": float(np.max([r["max_factor"] for r in rs]))})
    if args.out:
        plot(sweep_rows, args.out)
    main_rows = [r for r in rows if r["speedup_setting"] == args.main]
    refs = {r["seed"]: r for r in rows if r["speedup_setting"] == 0}
    floors = {r["seed"]: r["stress_error_rms"] for r in rows if r["speedup_setting"] == -1}
    meas = {}
    for k in main_rows[0]["measures"]:
        base = np.array([refs[r["seed"]]["measures"][k] for r in main_rows])
        diff = np.array([r["measures"][k] for r in main_rows]) - base
        meas[k] = {"unscaled_mean": float(base.mean()),
                   "unscaled_seed_sd": float(base.std(ddof=1)) if len(base) > 1 else None,
                   "paired_difference": float(diff.mean()),
                   "paired_difference_se": (float(diff.std(ddof=1) / math.sqrt(len(diff)))
                                            if len(diff) > 1 else None)}
    final = {"bench": "quasi_static", "seeds": seeds, "n": args.n, "grid": args.grid,
             "grains": args.grains, "pressure_pa": args.pressure, "strain": args.strain,
             "inertial_number_unscaled_loading": args.inertial_number, "main": args.main,
             "speedup": float(np.mean([r["speedup"] for r in main_rows])),
             "stress_error_rms": float(np.mean([r["stress_error_rms"] for r in main_rows])),
             "deviator_error_rms": float(np.mean([r["deviator_error_rms"] for r in main_rows])),
             "noise_floor_stress_rms": float(np.mean([r["stress_error_rms"] for r in rows
                                                      if r["speedup_setting"] == -1])),
             "noise_floor_deviator_rms": float(np.mean([r["deviator_error_rms"] for r in rows
                                                        if r["speedup_setting"] == -1])),
             # the error beyond the floor, sqrt(max(0, e^2 - floor^2)), seed by seed
             # signed: (scaled - unscaled) averaged over the path, relative; mean and standard
             # error over the seeds (the floor's too): a bias of the scaling would show here,
             # the path's chaos averages out
             "stress_bias": _mean_se([r["stress_bias"] for r in main_rows]),
             "sigma_z_bias": _mean_se([r["sigma_z_bias"] for r in main_rows]),
             "noise_floor_stress_bias": _mean_se([r["stress_bias"] for r in rows
                                                   if r["speedup_setting"] == -1]),
             "stress_error_beyond_floor": float(np.mean([math.sqrt(max(0.0, r["stress_error_rms"] ** 2 - floors[r["seed"]] ** 2)) for r in main_rows])),
             "dt_unscaled_s": float(np.mean([refs[r["seed"]]["dt_s"] for r in main_rows])),
             "dt_scaled_s": float(np.mean([r["dt_s"] for r in main_rows])),
             "max_factor": float(np.max([r["max_factor"] for r in main_rows])),
             "scaled_share": float(np.mean([r["scaled_share"] for r in main_rows])),
             "inertial_number_sample_unscaled": float(np.mean(
                 [refs[r["seed"]]["inertial_number_sample"] for r in main_rows])),
             "inertial_number_sample_scaled": float(np.mean(
                 [r["inertial_number_sample"] for r in main_rows])),
             "porosity_unscaled": float(np.mean([refs[r["seed"]]["porosity"] for r in main_rows])),
             "porosity_scaled": float(np.mean([r["porosity"] for r in main_rows])),
             "measures_002": meas, "sweep": sweep_rows,
             "pareto": [{"speedup_setting": r["speedup_setting"], "speedup": r["speedup"],
                         "stress_error_rms": r["stress_error_rms"]}
                        for r in pareto(sweep_rows)]}
    return final


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="folder", prog="bench/quasi_static.py",
                          description=__doc__.split("\n")[0],
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=150, help="clumps before the grid's layer is "
                    "cleared (the 002 smoke size)")
    ap.add_argument("--grid", choices=("detailed", "standard"), default="detailed")
    ap.add_argument("--grains", default="clumps:gravel", help="grains (e.g. clumps:gravel@12)")
    ap.add_argument("--seeds", default="1", help="comma-separated seeds")
    ap.add_argument("--pressure", type=float, default=20e3, help="cell pressure, Pa")
    ap.add_argument("--strain", type=float, default=0.01, help="axial strain to reach, -")
    ap.add_argument("--inertial-number", type=float, default=2e-3,
                    help="loading rate as the unscaled inertial number, -")
    ap.add_argument("--sweep", default="2,4,8,16", help="target dt / unscaled reference dt")
    ap.add_argument("--main", type=float, default=8.0, help="the setting the final line reports")
    ap.add_argument("--record-every", type=int, default=200, help="steps between records")
    ap.add_argument("--bins", type=int, default=20,
                    help="strain bins the paths are averaged in before they are compared")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="folder for rows and the figure")
    ap.add_argument("--reanalyse", type=Path, default=None,
                    help="summarise the rows of an earlier run's quasi_static.jsonl instead of "
                         "running (e.g. with other --bins)")
    args = ap.parse_args(argv)
    if args.reanalyse:
        rows = [json.loads(x) for x in args.reanalyse.read_text().splitlines() if x.strip()]
        seeds = sorted({r["seed"] for r in rows})
        sweep = sorted({r["speedup_setting"] for r in rows if r["speedup_setting"] > 0})
        print(json.dumps(summarise(rows, args, seeds, sweep)))
        return 0
    try:
        sweep = sorted(set(_cli.numbers(args.sweep, "--sweep", minimum=1)) | {args.main})
        seeds = _cli.numbers(args.seeds, "--seeds", kind=int, lo="nonneg")
    except _cli.BenchInputError as e:
        ap.error(str(e))
    if args.main < 1:
        ap.error(f"--main={args.main}: must be >= 1 (a setting of the sweep)")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in seeds:
        p, sample, grid, blob, t_prep = prepare(args, seed)
        log(f"seed {seed}: prepared in {t_prep:.1f} s")
        ref = variant(args, p, sample, grid, blob, 0.0)
        ref.update(stress_error_rms=0.0, deviator_error_rms=0.0, speedup=1.0)
        rows.append(ref)
        log(f"seed {seed}: unscaled {ref['wall_s']:.1f} s, {ref['steps']} steps at dt "
            f"{ref['dt_s']:.3g} s")
        # The noise floor: the unscaled run again at 0.9 x its time step (the automatic
        # step's safety 0.45 for 0.5): physically the same loading; its difference from
        # the reference is the path's own chaos, below which no error can be resolved.
        sample.scene.set_auto_timestep(safety=0.45, period=100)
        fl = variant(args, p, sample, grid, blob, 0.0, safety=0.45)
        sample.scene.set_auto_timestep(safety=0.5, period=100)
        fl.update(errors(fl, ref, args.bins), speedup_setting=-1.0)
        rows.append(fl)
        log(f"seed {seed}: noise floor (unscaled at 0.9 dt): stress "
            f"{100 * fl['stress_error_rms']:.2f} %, deviator {100 * fl['deviator_error_rms']:.2f} %")
        for s in sweep:
            r = variant(args, p, sample, grid, blob, s)
            r.update(errors(r, ref, args.bins))
            rows.append(r)
            log(f"seed {seed}: S={s:g}: {r['wall_s']:.1f} s ({r['speedup']:.2f} x), dt "
                f"{r['dt_s']:.3g} s, largest factor {r['max_factor']:.3g} "
                f"({100 * r['scaled_share']:.0f} % scaled), stress error "
                f"{100 * r['stress_error_rms']:.2f} %, deviator {100 * r['deviator_error_rms']:.2f}"
                f" %, I {r['inertial_number_sample']:.2g}")
        if args.out:
            with open(args.out / "quasi_static.jsonl", "a") as fh:
                for r in rows[-2 - len(sweep):]:
                    fh.write(json.dumps(r) + "\n")
    final = summarise(rows, args, seeds, sweep)
    print(json.dumps(final))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(_cli.run(main))
