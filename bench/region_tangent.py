"""Region mode: the element's tangent against the isotropic secant (issue 18). Not a test.

One FEM body (the two-region test body of tests/test_fem_handover.py: 4 x 3 m, elastic soil
50 MPa / 0.3, 18 kN/m^3, a 1 m footing), one region coupled two ways to a dense periodic DEM
element (femcoupling.materials.dem_elements.PeriodicRegionElement) under a footing pressure. For
each ``--modes`` value the same loop runs with ``two_way(stiffness=mode)`` from the same prepared
element (its bytes are kept in a shared folder), and the bench prints per mode: FEM solves,
whether and on what it converged, the last change, the region's stiffness (isotropic part),
the DEM/FEM normal strain ratio (largest components, as ``check_region``), and how far the
region's in-plane strain increment (xx, zz, xz) is from the element's (largest component
difference over the largest component), with the wall time; with several ``--seeds``, a
summary per mode. One JSON line
per mode on stdout, a Markdown table on stderr; --out FILE.jsonl appends the lines.

    .venv/bin/python bench/region_tangent.py                      # 200 grains, 20 kPa, ~10 s
    .venv/bin/python bench/region_tangent.py --seeds 1 2 3 4 5 6 7 8   # eight seeds, ~2 min

SI units. Compression positive in the element's strains, as ``two_way`` records them.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def run(mode: str, seed: int, args, cache: str) -> dict:
    import numpy as np

    from femcoupling.coupling.twoway import RegionWarning, two_way
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    from test_fem_handover import two_region_model  # (the FEM body of the tests)

    m = two_region_model()
    e0 = m.region_strain(args.region)
    runner = PeriodicRegionElement(n=args.grains, seed=seed, cache_dir=cache,
                                   tol=args.servo_tol)

    def load(model):
        return model.load_footing(pressure_pa=args.pressure, steps=1)

    def log(msg):
        print(f"[region_tangent {mode} seed {seed}] {msg}", file=sys.stderr, flush=True)

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegionWarning)  # (they are in res.warnings)
        res = two_way(m, regions=[args.region], load=load, element_runner=runner,
                      tol=args.tol, max_iterations=args.max_iterations, log=log,
                      stiffness=mode)
    wall = time.perf_counter() - t0
    resp = res.responses[args.region]
    fem = m.region_strain(args.region) - e0  # tension positive
    dem = -np.asarray(resp.info["strain_increment_tensor"])
    idx = ([0, 2, 0], [0, 2, 2])
    mismatch = float(np.abs(dem[idx] - fem[idx]).max() / np.abs(fem[idx]).max())
    E, nu = res.materials[args.region]
    normal = float(np.abs(np.diag(dem)).max() / np.abs(np.diag(fem)).max())
    return {"mode": mode, "seed": seed, "grains": args.grains, "pressure_pa": args.pressure,
            "region": args.region, "fem_solves": res.iterations, "converged": res.converged,
            "converged_on": res.converged_on, "last_change": res.changes[-1],
            "young_pa": E, "poisson": nu, "inplane_strain_mismatch": mismatch,
            "strain_ratio": normal,
            "fem_strain_inplane": fem[idx].tolist(), "dem_strain_inplane": dem[idx].tolist(),
            "warnings": len(res.warnings), "wall_s": wall}


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="append", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--grains", type=int, default=200, help="grains of the element")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1],
                    help="packing seeds of the element (one pair of runs each)")
    ap.add_argument("--pressure", type=float, default=20e3, help="footing pressure, Pa")
    ap.add_argument("--region", default="b", choices=("a", "b"))
    ap.add_argument("--tol", type=float, default=0.02, help="two-way tolerance, relative")
    ap.add_argument("--servo-tol", type=float, default=0.005,
                    help="the element's servo tolerance, relative")
    ap.add_argument("--max-iterations", type=int, default=8)
    ap.add_argument("--modes", nargs="+", default=["tangent", "isotropic"],
                    choices=("tangent", "isotropic"))
    ap.add_argument("--out", help="append the JSON lines to this file")
    args = ap.parse_args(argv)
    if args.grains < 20:
        ap.error(f"--grains {args.grains}: must be >= 20")
    rows, skipped = [], []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as cache:  # (both modes: one prepared element)
            for mode in args.modes:
                try:
                    row = run(mode, seed, args, cache)
                except RuntimeError as exc:  # (a packing that cannot hold the initial state)
                    print(f"[region_tangent] seed {seed} skipped: {exc}", file=sys.stderr)
                    skipped.append(seed)
                    break
                rows.append(row)
                print(json.dumps(row), flush=True)
                if args.out:
                    with open(Path(args.out), "a") as f:
                        f.write(json.dumps(row) + "\n")
    print("\n| mode | seed | FEM solves | converged | last change | E (MPa) | nu | DEM/FEM "
          "normal strain | in-plane strain mismatch | wall s |\n"
          "|---|---|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for r in rows:
        print(f"| {r['mode']} | {r['seed']} | {r['fem_solves']} | {r['converged']} "
              f"({r['converged_on']}) | {r['last_change']:.3g} | {r['young_pa'] / 1e6:.3g} | "
              f"{r['poisson']:.3f} | {r['strain_ratio']:.3g} | "
              f"{r['inplane_strain_mismatch']:.3g} | {r['wall_s']:.0f} |", file=sys.stderr)
    if skipped:
        print(f"\nseeds skipped (their element could not hold the region's initial stress): "
              f"{skipped}", file=sys.stderr)
    if len(args.seeds) > 1 and rows:
        import numpy as np

        print("\n| mode | runs | converged | FEM solves, mean | DEM/FEM normal strain, "
              "median (range) | in-plane mismatch, median (range) |\n"
              "|---|---|---|---|---|---|", file=sys.stderr)
        for mode in args.modes:
            rs = [r for r in rows if r["mode"] == mode]
            sr = np.array([r["strain_ratio"] for r in rs])
            mm = np.array([r["inplane_strain_mismatch"] for r in rs])
            print(f"| {mode} | {len(rs)} | {sum(r['converged'] for r in rs)} | "
                  f"{np.mean([r['fem_solves'] for r in rs]):.1f} | {np.median(sr):.3g} "
                  f"({sr.min():.3g}-{sr.max():.3g}) | {np.median(mm):.3g} "
                  f"({mm.min():.3g}-{mm.max():.3g}) |", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
