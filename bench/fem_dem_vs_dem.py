#!/usr/bin/env python3
"""FEM x DEM against direct DEM in a plane-strain biaxial test (issue 18;
geogrid_dem.studies.biaxial; docs/studies/biaxial.md).

Three runs from the same grains and path (x at the confining pressure, y held, z shortened):

1. FEM x DEM: an nx x ny rectangle of P1 triangles, a periodic element of --grains grains per
   cell (2 nx ny elements, seeds 1, 2, ...), on Dask workers;
2. each of those elements alone under the homogeneous path (direct DEM, same seeds);
3. --big-seeds periodic cells of all the grains at once (2 nx ny x --grains), the direct DEM
   of a specimen of the same size.

Prints the peak axial stress, the axial and volumetric strain at the peak of each, the seed
scatter, and writes --out (JSON).

    .venv/bin/python bench/fem_dem_vs_dem.py                   # 2 x 2, 8 x 150 grains
    .venv/bin/python bench/fem_dem_vs_dem.py --nx 4 --ny 4      # the docs' larger run
    .venv/bin/python bench/fem_dem_vs_dem.py --seeds 5 --big-seeds 5 --porosity 0.38 --rate 1e-6
                                                  # like for like: porosity, rate, 5 seeds
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from _report import write_json  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))


def main(argv=None) -> int:
    from cpp_dem import measure
    from cpp_dem.elements.periodic import DemElement
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from geogrid_dem.studies import biaxial

    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, default=2)
    ap.add_argument("--ny", type=int, default=2)
    ap.add_argument("--grains", type=int, default=150, help="grains per element")
    ap.add_argument("--pressure", type=float, default=100e3, help="confining, Pa")
    ap.add_argument("--strain", type=float, default=0.04, help="axial strain, -")
    ap.add_argument("--steps", type=int, default=20, help="FEM load steps")
    ap.add_argument("--rtol", type=float, default=1e-3, help="Newton tolerance")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--max-newton", type=int, default=15, help="Newton iterations a step")
    ap.add_argument("--seeds", type=int, default=1,
                    help="FEM x DEM runs, each with its own elements (seeds 1 + 100 s + k)")
    ap.add_argument("--alone-runs", type=int, default=1,
                    help="of the FEM x DEM runs, how many also run each element alone")
    ap.add_argument("--big-seeds", type=int, default=3,
                    help="direct DEM cells of all the grains (0: none)")
    ap.add_argument("--porosity", type=float, default=None,
                    help="prepare every element and every cell of all the grains by REFD to "
                         "this porosity (-; default: grown frictionless, whatever porosity "
                         "that gives at each size)")
    ap.add_argument("--rate", type=float, default=None,
                    help="strain per DEM step of both: the elements take their increments "
                         "at it and the direct DEM is loaded at it (default: the elements at "
                         "2e-6, the direct DEM at --strain-per-step)")
    ap.add_argument("--strain-per-step", type=float, default=5e-7,
                    help="the direct DEM's loading, - per DEM step, without --rate")
    ap.add_argument("--out", default="results/bench_runs/fem_dem_vs_dem.json")
    args = ap.parse_args(argv)
    if args.seeds < 1:
        ap.error(f"--seeds={args.seeds}: must be >= 1")
    if args.porosity is not None and not 0.2 < args.porosity < 0.6:
        ap.error(f"--porosity={args.porosity}: must be in (0.2, 0.6)")
    if args.rate is not None and not 0 < args.rate <= 1e-4:
        ap.error(f"--rate={args.rate}: must be in (0, 1e-4] (strain per DEM step)")
    lx, ly = 0.02, 0.04
    n = 2 * args.nx * args.ny
    opts = ({"prep_friction_deg": 0.0} if args.porosity is None
            else {"porosity": args.porosity})
    strain_kw = {"unbalanced": 1e-5, "max_relax_steps": 100_000}
    if args.rate is not None:
        strain_kw["max_strain_per_step"] = args.rate
    kw = dict(pressure=args.pressure, strain=args.strain,
              strain_per_step=args.rate if args.rate is not None else args.strain_per_step)
    runs = []
    lines = []
    for s in range(args.seeds):
        factory = PeriodicFactory(n=args.grains, stress=args.pressure, seed=1 + 100 * s,
                                  isotropic=True, options=opts)
        t0 = time.perf_counter()
        with ElementPool.build(n, factory, workers=args.workers) as pool:
            # the elements' porosity as prepared (their states fetched once, before the run)
            phis = np.array([measure.porosity(DemElement.from_bytes(b).scene, ())
                             for b in pool.states()])
            fd = biaxial.fem_dem_biaxial(pool, lx=lx, ly=ly, nx=args.nx, ny=args.ny,
                                         pressure=args.pressure, strain=args.strain,
                                         steps=args.steps, newton_rtol=args.rtol,
                                         tangent="network", strain_kw=strain_kw,
                                         max_newton=args.max_newton, stop_on_failure=True)
        fd_s = time.perf_counter() - t0
        run = {"seed_base": 1 + 100 * s, "fem_dem": fd, "alone": [],
               "alone_mean_curve": np.array([]), "porosities": phis, "wall_s": fd_s}
        runs.append(run)
        if fd["failed"] is not None:
            lines.append(f"run {s + 1}/{args.seeds}: FAILED at axial strain "
                         f"{fd['failed']['axial_strain']:.4f} ({fd['failed']['reason'][:120]})")
        new = [f"run {s + 1}/{args.seeds}: FEM x DEM {args.nx} x {args.ny} ({n} elements "
               f"of {args.grains} grains, porosity {phis.mean():.4f} +- "
               f"{phis.std(ddof=1):.4f}): peak {fd['peak_sigma_axial'] / 1e3:.1f} kPa at "
               f"{fd['peak_axial_strain']:.4f}, volumetric strain there "
               f"{fd['peak_volumetric_strain']:.4f}; mean lateral stress "
               f"{np.mean(fd['sigma_lateral']) / 1e3:.2f} kPa (confining "
               f"{args.pressure / 1e3:.1f}); {fd_s:.0f} s"]
        if s < args.alone_runs:
            t0 = time.perf_counter()
            alone = biaxial.direct_biaxial(factory, range(n), **kw)
            alone_s = time.perf_counter() - t0
            # the elements alone: their mean curve on the FEM's strains, and its peak
            eps = fd["axial_strain"]
            mean_curve = np.mean([[biaxial.at_strain(r, e) for e in eps] for r in alone],
                                 axis=0)
            k = int(np.argmax(mean_curve))
            sa = biaxial.summarise(alone)
            run.update(alone=alone, alone_mean_curve=mean_curve)
            new.append(f"  its elements alone (mean curve on the same strains): peak "
                       f"{mean_curve[k] / 1e3:.1f} kPa at {eps[k]:.4f}; their own peaks "
                       f"{sa['peak_sigma_axial']['mean'] / 1e3:.1f} +- "
                       f"{sa['peak_sigma_axial']['std'] / 1e3:.1f} kPa (seed scatter, 1 std); "
                       f"{alone_s:.0f} s")
            for e in (0.01, 0.02, 0.03):
                if e <= args.strain:
                    i = int(np.argmin(abs(eps - e)))
                    new.append(f"  at {eps[i]:.3f}: FEM x DEM "
                               f"{fd['sigma_axial'][i] / 1e3:.1f} kPa, elements' mean "
                               f"{mean_curve[i] / 1e3:.1f} kPa")
        lines += new
        print("[vs] " + "\n[vs] ".join(new), flush=True)
    big = []
    t0 = time.perf_counter()
    if args.big_seeds:
        bigf = PeriodicFactory(n=n * args.grains, stress=args.pressure, isotropic=True,
                               options=opts)
        big = biaxial.direct_biaxial(bigf, [1000 + k for k in range(args.big_seeds)], **kw)
    big_s = time.perf_counter() - t0
    fair = None
    if big:
        sb = biaxial.summarise(big)
        lines.append(f"direct DEM of all the grains ({big[0]['grains']} grains, "
                     f"{args.big_seeds} seeds, porosity "
                     + ", ".join(f"{r['porosity_initial']:.4f}" for r in big)
                     + f"): peak {sb['peak_sigma_axial']['mean'] / 1e3:.1f}"
                     f" +- {sb['peak_sigma_axial']['std'] / 1e3:.1f} kPa at "
                     f"{sb['peak_axial_strain']['mean']:.4f}, volumetric strain there "
                     f"{sb['peak_volumetric_strain']['mean']:.4f} +- "
                     f"{sb['peak_volumetric_strain']['std']:.4f}; {big_s:.0f} s")
        fair = compare(runs, big)
        lines.append(fair["line"])
    for ln in lines:
        print("[vs] " + ln, flush=True)
    strip = lambda d: {a: (b.tolist() if isinstance(b, np.ndarray) else b)  # noqa: E731
                       for a, b in d.items() if a not in ("model", "steps")}
    path = write_json(args.out, {
        "args": vars(args),
        "runs": [{"seed_base": r["seed_base"], "fem_dem": strip(r["fem_dem"]),
                  "alone": [strip(a) for a in r["alone"]],
                  "alone_mean_curve": np.asarray(r["alone_mean_curve"]).tolist(),
                  "porosities": r["porosities"].tolist(), "wall_s": r["wall_s"]}
                 for r in runs],
        "big": [strip(r) for r in big], "comparison": fair, "summary": lines})
    print(f"[vs] wrote {path}")
    return 0


def compare(runs: list, big: list, porosity_tol: float = 0.005) -> dict:
    """FEM x DEM (one peak per run) against the cells of all the grains (one per seed): the
    difference of the mean peaks (Pa) with its standard error (the two seed scatters,
    sqrt(sd1^2 / n1 + sd2^2 / n2)), and the porosities: each run's elements' mean against
    the cells', matched when they differ by at most ``porosity_tol``."""
    # a run that failed counts only if it had passed its peak (the peak 2 load steps or more
    # before its last accepted one)
    ok = [r for r in runs if r["fem_dem"]["failed"] is None
          or int(np.argmax(r["fem_dem"]["sigma_axial"])) <= len(r["fem_dem"]["sigma_axial"]) - 3]
    a = np.array([r["fem_dem"]["peak_sigma_axial"] for r in ok])
    b = np.array([r["peak_sigma_axial"] for r in big])
    sd = lambda v: float(v.std(ddof=1)) if len(v) > 1 else float("nan")  # noqa: E731
    diff = float(a.mean() - b.mean())
    se = math.sqrt(sd(a) ** 2 / len(a) + sd(b) ** 2 / len(b))
    pa = np.array([r["porosities"].mean() for r in ok])
    pb = np.array([r["porosity_initial"] for r in big])
    gap = float(abs(pa.mean() - pb.mean()))
    matched = gap <= porosity_tol
    line = (f"FEM x DEM against all the grains: peak {a.mean() / 1e3:.1f} +- {sd(a) / 1e3:.1f} "
            f"kPa ({len(a)} of {len(runs)} runs; a failed run counts once past its peak) against {b.mean() / 1e3:.1f} +- {sd(b) / 1e3:.1f} kPa "
            f"({len(b)} cells): difference {diff / 1e3:+.1f} +- {se / 1e3:.1f} kPa (standard "
            f"error), {diff / se if se > 0 else float('nan'):+.2f} standard errors; porosity "
            f"{pa.mean():.4f} against {pb.mean():.4f} ("
            + ("matched" if matched else "NOT matched") + f" within {porosity_tol:g})")
    return {"fem_dem_peaks_pa": a.tolist(), "fem_dem_runs_counted": len(a),
            "fem_dem_runs": len(runs), "direct_peaks_pa": b.tolist(),
            "difference_pa": diff, "standard_error_pa": se,
            "fem_dem_porosity": pa.tolist(), "direct_porosity": pb.tolist(),
            "porosity_gap": gap, "porosity_matched": matched, "line": line}


if __name__ == "__main__":
    sys.exit(_cli.run(main))
