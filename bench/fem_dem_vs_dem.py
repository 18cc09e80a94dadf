#!/usr/bin/env python3
"""FEM x DEM against direct DEM in a plane-strain biaxial test (issue 18; femcoupling.biaxial;
docs/multiscale.md).

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
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from _report import write_json  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))


def main(argv=None) -> int:
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from femcoupling import biaxial

    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, default=2)
    ap.add_argument("--ny", type=int, default=2)
    ap.add_argument("--grains", type=int, default=150, help="grains per element")
    ap.add_argument("--pressure", type=float, default=100e3, help="confining, Pa")
    ap.add_argument("--strain", type=float, default=0.04, help="axial strain, -")
    ap.add_argument("--steps", type=int, default=20, help="FEM load steps")
    ap.add_argument("--rtol", type=float, default=1e-3, help="Newton tolerance")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--big-seeds", type=int, default=3,
                    help="direct DEM cells of all the grains (0: none)")
    ap.add_argument("--strain-per-step", type=float, default=5e-7,
                    help="the direct DEM's loading, - per DEM step")
    ap.add_argument("--out", default="results/bench_runs/fem_dem_vs_dem.json")
    args = ap.parse_args(argv)
    lx, ly = 0.02, 0.04
    n = 2 * args.nx * args.ny
    opts = {"prep_friction_deg": 0.0}
    factory = PeriodicFactory(n=args.grains, stress=args.pressure, isotropic=True,
                              options=opts)
    t0 = time.perf_counter()
    with ElementPool.build(n, factory, workers=args.workers) as pool:
        fd = biaxial.fem_dem_biaxial(pool, lx=lx, ly=ly, nx=args.nx, ny=args.ny,
                                     pressure=args.pressure, strain=args.strain,
                                     steps=args.steps, newton_rtol=args.rtol,
                                     tangent="network-elastic",
                                     strain_kw={"unbalanced": 1e-5,
                                                "max_relax_steps": 100_000})
    fd_s = time.perf_counter() - t0
    kw = dict(pressure=args.pressure, strain=args.strain,
              strain_per_step=args.strain_per_step)
    t0 = time.perf_counter()
    alone = biaxial.direct_biaxial(factory, range(n), **kw)
    alone_s = time.perf_counter() - t0
    big = []
    t0 = time.perf_counter()
    if args.big_seeds:
        bigf = PeriodicFactory(n=n * args.grains, stress=args.pressure, isotropic=True,
                               options=opts)
        big = biaxial.direct_biaxial(bigf, [1000 + k for k in range(args.big_seeds)], **kw)
    big_s = time.perf_counter() - t0

    # the elements alone: their mean curve on the FEM's strains, and the peak of that mean
    eps = fd["axial_strain"]
    mean_curve = np.mean([[biaxial.at_strain(r, e) for e in eps] for r in alone], axis=0)
    k = int(np.argmax(mean_curve))
    sa = biaxial.summarise(alone)
    sb = biaxial.summarise(big) if big else None
    lines = [f"FEM x DEM {args.nx} x {args.ny} ({n} elements of {args.grains} grains): peak "
             f"{fd['peak_sigma_axial'] / 1e3:.1f} kPa at {fd['peak_axial_strain']:.4f}, "
             f"volumetric strain there {fd['peak_volumetric_strain']:.4f}; mean lateral "
             f"stress {np.mean(fd['sigma_lateral']) / 1e3:.2f} kPa "
             f"(confining {args.pressure / 1e3:.1f}); {fd_s:.0f} s",
             f"its elements alone (mean curve on the same strains): peak "
             f"{mean_curve[k] / 1e3:.1f} kPa at {eps[k]:.4f}; their own peaks "
             f"{sa['peak_sigma_axial']['mean'] / 1e3:.1f} +- "
             f"{sa['peak_sigma_axial']['std'] / 1e3:.1f} kPa (seed scatter, 1 std), "
             f"volumetric strain at the peak {sa['peak_volumetric_strain']['mean']:.4f} +- "
             f"{sa['peak_volumetric_strain']['std']:.4f}; {alone_s:.0f} s"]
    for e in (0.01, 0.02, 0.03):
        if e <= args.strain:
            i = int(np.argmin(abs(eps - e)))
            lines.append(f"  at {eps[i]:.3f}: FEM x DEM {fd['sigma_axial'][i] / 1e3:.1f} kPa, "
                         f"elements' mean {mean_curve[i] / 1e3:.1f} kPa")
    if sb:
        lines.append(f"direct DEM of all the grains ({big[0]['grains']} grains, "
                     f"{args.big_seeds} seeds): peak {sb['peak_sigma_axial']['mean'] / 1e3:.1f}"
                     f" +- {sb['peak_sigma_axial']['std'] / 1e3:.1f} kPa at "
                     f"{sb['peak_axial_strain']['mean']:.4f}, volumetric strain there "
                     f"{sb['peak_volumetric_strain']['mean']:.4f} +- "
                     f"{sb['peak_volumetric_strain']['std']:.4f}; {big_s:.0f} s")
    for ln in lines:
        print("[vs] " + ln, flush=True)
    strip = lambda d: {a: (b.tolist() if isinstance(b, np.ndarray) else b)  # noqa: E731
                       for a, b in d.items() if a not in ("model", "steps")}
    path = write_json(args.out, {"args": vars(args), "fem_dem": strip(fd),
                                 "alone": [strip(r) for r in alone],
                                 "alone_mean_curve": mean_curve.tolist(),
                                 "big": [strip(r) for r in big], "summary": lines})
    print(f"[vs] wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
