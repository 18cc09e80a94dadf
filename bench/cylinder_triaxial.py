#!/usr/bin/env python3
"""A 3D hierarchical triaxial test of a cylindrical specimen (issue 38, "3D beyond a box"):
FEM x DEM with a periodic DEM element at the quadrature point of every tetrahedron of the
specimen (``femcoupling.fem.model.FemModel`` on a ``femcoupling.fem.bodies.Cylinder``), held on Dask workers.

The specimen is the quarter x, y >= 0 of a cylinder ``--radius`` by ``--height`` (m)
(``--section full``: the whole cylinder, no symmetry planes), with smooth platens
(``--platens rough``: the ends also held radially): the bottom held vertically, the top
moved down in ``--steps`` equal steps to the axial strain ``--strain``, the curved face
under the confining pressure ``--pressure`` (Pa). Every element is its own packing of
``--grains`` grains (seed + k), prepared to the isotropic confining stress, dense (grown
frictionless, then at their friction: the shear band's elements).

Beside the specimen, its elements (``--alone``: all by default) are run on their own along
the specimen's mean strain path (each step's volume-mean strain increment given to each):
the answer of a specimen whose elements all strained alike (the uniform-strain, Voigt,
assumption). The two differ by what the boundary-value problem adds: the elements' different
stiffnesses share the load, the platens and the pressure act at the boundary.

Writes in --out: ``cylinder_triaxial.csv`` (a row per accepted step, appended and flushed:
axial strain, deviator q = sigma_a - sigma_r, volumetric strain, compression positive, Pa and
-, the status, Newton iterations, seconds), ``cylinder_triaxial.png`` (q and the volumetric
strain against the axial strain, specimen and elements alone), ``cylinder_triaxial.json``,
and the model's records (``records/``: elements.h5, steps.csv, report.md). Prints progress
with an ETA and a final JSON line.

    .venv/bin/python bench/cylinder_triaxial.py --out DIR            # 52 elements of 60 grains
    .venv/bin/python bench/cylinder_triaxial.py --smoke --out DIR    # 52 elements of 30 grains, 2 steps
    .venv/bin/python bench/cylinder_triaxial.py --section full --size 0.035 --out DIR  # 192
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))

from _report import write_json  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

COLUMNS = ("step", "axial_strain", "q_pa", "radial_pa", "volumetric_strain", "status",
           "iterations", "wall_s")


def _invariants(stress_voigt: np.ndarray) -> tuple[float, float]:
    """(q, radial): the deviator sigma_a - sigma_r and the mean radial stress, compression
    positive, Pa, of a Voigt stress (xx, yy, zz, ...) tension positive."""
    radial = -0.5 * (stress_voigt[0] + stress_voigt[1])
    return float(-stress_voigt[2] - radial), radial


def run_alone(factory, n: int, path: list, strain_kw: dict, workers: int) -> np.ndarray:
    """Elements 0 .. n-1 of ``factory``, fresh, run alone along the strain increments
    ``path`` (3 x 3 each), in parallel on a pool of ``workers``; returns (n, len(path), 6)
    Voigt stresses, Pa."""
    from cpp_dem.elements.pool import ElementPool
    from femcoupling.materials.element_pool import voigt_stress

    out = np.zeros((n, len(path), 6))
    with ElementPool.build(n, factory, workers=workers) as pool:
        for j, de in enumerate(path):
            st = pool.apply_strain([de] * n, **strain_kw)
            pool.accept()
            out[:, j] = [voigt_stress(s) for s in st.stresses]
    return out


def plot(rows, q_alone, n_alone: int, path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ea = [0.0] + [r["axial_strain"] for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(np.array(ea) * 100, [0.0] + [r["q_pa"] / 1e3 for r in rows], "o-",
               label="specimen (FEM x DEM)")
    if len(q_alone):
        ax[0].plot(np.array(ea[1:]) * 100, np.asarray(q_alone) / 1e3, "s--",
                   label=f"{n_alone} elements alone on the mean strain, volume mean")
    ax[0].set_xlabel("axial strain, %")
    ax[0].set_ylabel("q = sigma_a - sigma_r, kPa")
    ax[0].legend()
    ax[1].plot(np.array(ea) * 100, [0.0] + [r["volumetric_strain"] * 100 for r in rows], "o-")
    ax[1].set_xlabel("axial strain, %")
    ax[1].set_ylabel("volumetric strain, % (compression +)")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from cpp_dem.progress import Progress
    from femcoupling.fem.bodies import Cylinder, cylinder_cells
    from femcoupling.fem.model import FemModel

    ap = _cli.BenchParser(signed=("alone",), description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--radius", type=float, default=0.025, help="specimen radius, m")
    ap.add_argument("--height", type=float, default=0.1, help="specimen height, m")
    ap.add_argument("--size", type=float, default=0.05, help="tetrahedra size, m")
    ap.add_argument("--grains", type=int, default=60, help="grains per element")
    ap.add_argument("--pressure", type=float, default=100e3, help="confining pressure, Pa")
    ap.add_argument("--strain", type=float, default=0.01, help="final axial strain, -")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1, help="element k's packing: seed + k")
    ap.add_argument("--platens", default="smooth", choices=("smooth", "rough"),
                    help="rough: the ends held radially too")
    ap.add_argument("--section", default="quarter", choices=("quarter", "full"),
                    help="the quarter with its two symmetry planes, or the whole cylinder")
    ap.add_argument("--alone", type=int, default=-1,
                    help="elements also run alone on the mean strain path (the first N; "
                         "0: none; -1, the default: all)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rtol", type=float, default=1e-3)
    ap.add_argument("--max-newton", type=int, default=10)
    ap.add_argument("--smoke", action="store_true", help="30 grains, 2 steps to 0.1 %%")
    ap.add_argument("--out", default="results/bench_runs/cylinder_triaxial")
    args = ap.parse_args(argv)
    if args.smoke:
        args.grains, args.steps, args.strain, args.alone = 30, 2, 0.001, 2
    for name in ("grains", "steps", "workers"):
        if getattr(args, name) < 1:
            ap.error(f"--{name}={getattr(args, name)}: must be >= 1")
    for name in ("radius", "height", "size", "pressure", "strain"):
        if not getattr(args, name) > 0:
            ap.error(f"--{name}={getattr(args, name)}: must be > 0")
    if args.alone < -1:
        ap.error(f"--alone={args.alone}: must be >= -1 (-1: all)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = out / "cylinder_triaxial.csv"
    if table.exists():
        ap.error(f"--out={args.out}: holds a cylinder_triaxial.csv already; give a new folder")
    t0 = time.perf_counter()
    n = cylinder_cells(args.radius, args.height, args.size, args.section)
    # (dense elements, grown frictionless, as the shear band's: loose ones are rough at the
    # scale of Newton's corrections, and a first 0.1 % step stalled above the ceiling)
    factory = PeriodicFactory(n=args.grains, stress=args.pressure, seed=args.seed,
                              isotropic=True, options={"prep_friction_deg": 0.0})
    strain_kw = {"unbalanced": 1e-4, "max_relax_steps": 100_000}
    print(f"[cylinder] {n} elements of {args.grains} grains (the {args.section} of a "
          f"{2 * args.radius:g} x {args.height:g} m specimen); building them on "
          f"{args.workers} workers", flush=True)
    rows, path = [], []
    bar = Progress("cylinder triaxial", first_after_s=0.0)
    with ElementPool.build(n, factory, workers=args.workers) as pool, \
            open(table, "w", newline="") as fh:
        t_build = time.perf_counter() - t0
        print(f"[cylinder] built in {t_build:.0f} s", flush=True)
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        fh.flush()
        body = Cylinder(radius_m=args.radius, height_m=args.height, size_m=args.size,
                        platens=args.platens, section=args.section, confining_pa=args.pressure)
        m = FemModel(body, elements=pool, newton_rtol=args.rtol, max_newton=args.max_newton,
                     strain_kw=strain_kw, out=out / "records", overwrite=True)
        w = m.element_volumes
        failed = None
        for k in range(1, args.steps + 1):
            ea = args.strain * k / args.steps
            before = len(m.history)
            try:
                r = m.step(top_displacement=-ea * args.height)
            except Exception as e:  # noqa: BLE001  (the run stops; what it did is kept)
                failed = f"step {k}: {type(e).__name__}: {e}"
                print(f"[cylinder] {failed}", flush=True)
                break
            new = m.history[before:]  # (a cut step: its halves)
            inc = sum(h.increments for h in new)
            path.append(np.einsum("k,kij->ij", w, inc) / w.sum())
            ev = -float(np.trace(sum(path)))
            q, radial = _invariants(m.volume_mean_stress())
            row = {"step": k, "axial_strain": ea, "q_pa": q, "radial_pa": radial,
                   "volumetric_strain": ev, "status": r.status,
                   "iterations": int(sum(h.newton_iterations for h in new)),
                   "wall_s": time.perf_counter() - t0}
            rows.append(row)
            writer.writerow(row)
            fh.flush()
            bar.update(k / args.steps, f"step {k} of {args.steps}: axial strain {ea:.4g}, "
                                      f"q {q / 1e3:.4g} kPa, {r.status}")
    k_alone = n if args.alone == -1 else min(args.alone, n)
    alone = (run_alone(factory, k_alone, path, strain_kw, args.workers) if path and k_alone
             else np.zeros((0, 0, 6)))
    statuses = {s: sum(h.status == s for h in m.history)
                for s in sorted({h.status for h in m.history})}
    last = rows[-1] if rows else {}
    # the elements alone, volume-weighted as the specimen's mean (their q at every step)
    q_alone_path = (np.einsum("k,ks->s", w[: len(alone)], -alone[:, :, 2] + 0.5 * (
        alone[:, :, 0] + alone[:, :, 1])) / w[: len(alone)].sum() if len(alone)
        else np.zeros(0))
    q_alone = float(q_alone_path[-1]) if len(q_alone_path) and rows else float("nan")
    summary = {"elements": n, "section": args.section, "grains_per_element": args.grains,
               "steps_done": len(rows),
               "failed": failed, "statuses": statuses,
               "axial_strain": last.get("axial_strain", 0.0), "q_pa": last.get("q_pa"),
               "radial_pa": last.get("radial_pa"),
               "volumetric_strain": last.get("volumetric_strain"),
               "q_alone_mean_pa": q_alone, "alone": int(len(alone)),
               "newton_iterations": int(sum(h.newton_iterations for h in m.history)),
               "build_s": t_build, "wall_s": time.perf_counter() - t0}
    if rows:
        plot(rows, q_alone_path, len(alone), out / "cylinder_triaxial.png",
             f"{n} elements of {args.grains} grains, {args.pressure / 1e3:g} kPa")
    write_json(out / "cylinder_triaxial.json",
               {"args": vars(args), **summary, "rows": rows,
                "q_alone_pa": q_alone_path.tolist(), "alone_stresses_pa": alone.tolist(),
                "mean_strain_path": [p.tolist() for p in path]})
    print(json.dumps(summary, default=float), flush=True)
    return 0 if failed is None else 1


if __name__ == "__main__":
    sys.exit(_cli.run(main))
