#!/usr/bin/env python3
"""A plane-strain biaxial test by hierarchical FEM x DEM (femcoupling.fem.model.FemModel, issue
18): a rectangle of P1 triangles, a periodic DEM element at each quadrature point (one per cell)
held on Dask workers, confining pressure on the right, the top pushed down in steps.

Prints per load step the Newton iterations and residual, the mean element stresses (tension
positive) and the DEM/FEM time split; writes --out (JSON).

    .venv/bin/python bench/fem_dem_biaxial.py                       # 2 x 2 mesh, 8 elements
    .venv/bin/python bench/fem_dem_biaxial.py --nx 4 --ny 4 --grains 200 --strain 0.02
    .venv/bin/python bench/fem_dem_biaxial.py --scheduler sched.json   # a running cluster
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from _report import write_json  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))


def main(argv=None) -> int:
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from cpp_dem.elements.cluster import dask_client
    from geogrid_dem.studies import biaxial

    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, default=2)
    ap.add_argument("--ny", type=int, default=2)
    ap.add_argument("--grains", type=int, default=150, help="grains per element")
    ap.add_argument("--pressure", type=float, default=100e3, help="confining, Pa")
    ap.add_argument("--strain", type=float, default=0.01, help="total axial strain, -")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scheduler", default=None,
                    help="a running Dask scheduler (address or scheduler file) instead of a "
                         "LocalCluster of --workers")
    ap.add_argument("--rtol", type=float, default=5e-3)
    ap.add_argument("--unbalanced", type=float, default=1e-5,
                    help="the elements relax to this unbalanced force after each increment")
    ap.add_argument("--tangent", default="network",
                    choices=("network", "network-elastic", "secant"),
                    help="the elements' tangent in the Jacobian ("
                         "femcoupling.materials.element_pool."
                         "TANGENTS)")
    ap.add_argument("--prep-friction", type=float, default=0.0,
                    help="friction angle (deg) the elements' grains grow at (0: dense; "
                         "-1: the material's, a loose packing)")
    ap.add_argument("--max-newton", type=int, default=10)
    ap.add_argument("--convergence", default="noise", choices=("noise", "tolerance"),
                    help="--rtol, or within the elements' measured noise when Newton stalls "
                         "above it; or --rtol only")
    ap.add_argument("--relaxation", default="aitken",
                    help="'aitken', 'none' or a fixed factor in (0, 1]")
    ap.add_argument("--out", default="results/bench_runs/fem_dem_biaxial.json")
    ap.add_argument("--records", default=None,
                    help="folder for the run's records: elements.h5, fem.xdmf, steps.csv")
    args = ap.parse_args(argv)
    lx, ly = 0.02, 0.04
    n = 2 * args.nx * args.ny
    opts = {} if args.prep_friction < 0 else {"prep_friction_deg": args.prep_friction}
    with ElementPool.build(n, PeriodicFactory(n=args.grains, stress=args.pressure,
                                              isotropic=True, options=opts),
                           client=dask_client(args.scheduler, args.workers)[0]
                           if args.scheduler else None, workers=args.workers) as pool:
        fd = biaxial.fem_dem_biaxial(
            pool, lx=lx, ly=ly, nx=args.nx, ny=args.ny, pressure=args.pressure,
            strain=args.strain, steps=args.steps, newton_rtol=args.rtol,
            tangent=args.tangent, out=args.records, convergence=args.convergence,
            max_newton=args.max_newton,
            relaxation=(args.relaxation if args.relaxation in ("aitken", "none")
                        else float(args.relaxation)),
            strain_kw={"unbalanced": args.unbalanced, "max_relax_steps": 100_000})
    rows = []
    for eps, r in zip(fd["axial_strain"], fd["steps"]):
        s = r.mean_stress
        rows.append({"eps_y": float(eps), "iterations": r.newton_iterations, "residual": r.residual,
                     "noise_residual": r.noise_residual, "converged_on": r.converged_on,
                     "status": r.status,
                     "sigma_xx": float(s[0]), "sigma_yy": float(s[1]),
                     "q": float(-(s[1] - s[0])), "dem_s": r.dem_s, "fem_s": r.fem_s,
                     "wall_s": r.wall_s})
    m = fd["model"]
    totals = {"newton_iterations": int(sum(h.newton_iterations for h in m.history)),
              "accepted_steps": len(m.history), "load_steps": len(rows),
              "stopped_at_scatter": sum(h.status != "converged" for h in m.history),
              "secants_used": m.secants_used, "bad_tangents": m.bad_tangents,
              "peak_sigma_axial_pa": float(fd["peak_sigma_axial"]) if "peak_sigma_axial" in fd
              else None, "wall_s": fd["wall_s"]}
    print(f"[biaxial] tangent {args.tangent}: {totals['newton_iterations']} Newton iterations "
          f"over {totals['accepted_steps']} accepted steps ({totals['load_steps']} load steps)")
    print(f"[biaxial] wrote {write_json(args.out, {'args': vars(args), 'totals': totals, 'rows': rows})}")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
