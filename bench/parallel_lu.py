#!/usr/bin/env python3
"""The FEM's LU package on 2 MPI ranks: is the same input the same output, and what does it
cost? (``femcoupling.fem.quadrature.PARALLEL_LU``; docs/fem.md, "Under MPI".)

Each run is the Drucker–Prager soil body of tests/mpi_soil_body.py (self-weight, a
prestressed geogrid layer, a footing pressed to 100 kPa in 4 steps and then pushed 10 mm
in 4), meshed at ``--fine-size`` (m) under the footing, on ``--ranks`` ranks under the venv's
mpiexec. The three packages, PETSc's own LU on every rank (the default: each rank factors
the gathered matrix), SuperLU_DIST and MUMPS, run in alternating blocks, ``--runs`` each.
With ``--load`` (the default) two busy processes run beside them, as the other tests do in
the test suite: that is when MUMPS's results changed.

For each package: how many distinct results the runs gave (the settlements, stresses and
layer force compared bitwise; 1 is repeatable), the load steps taken, the wall time of
the FEM's stages (mean, s) and that time per Newton iteration. The ratios are PETSc's
over SuperLU_DIST's, in the same script (the whole run's, and per iteration: the runs' paths
differ, so the iterations differ too). The body's size is printed (degrees of freedom).

Prints a table on stderr and a final JSON line; with --out also writes
``parallel_lu.json`` there.

    .venv/bin/python bench/parallel_lu.py                # fine size 0.025 m, 6 runs each
    .venv/bin/python bench/parallel_lu.py --smoke        # fine size 0.1 m, 2 runs each
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))

from _report import markdown_table, write_json  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

PACKAGES = ("petsc", "superlu_dist", "mumps")


def worker(lu: str, fine_size: float, out: Path) -> None:
    """One run under mpiexec: the body with ``lu`` as the parallel LU ("petsc": PETSc's
    own on every rank, PARALLEL_LU None); rank 0 writes
    ``out`` (JSON: a hash of the results, the steps, the FEM's wall time, the dofs)."""
    import femcoupling.fem.quadrature as quadrature
    from femcoupling.fem.geometry import GeogridLayer, ReinforcedSoilBody
    from femcoupling.fem.mpi_points import world
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import DruckerPrager, GeogridLayerMaterial

    quadrature.PARALLEL_LU = None if lu in (None, "petsc") else lu
    comm = world()
    body = ReinforcedSoilBody(
        width_m=3.0, height_m=2.0, footing_half_width_m=0.5,
        layers=(GeogridLayer(z_m=1.7, x_min_m=0.0, x_max_m=2.0, thickness_m=0.02),),
        mesh_size_m=0.4, fine_size_m=fine_size, fine_radius_m=0.3)
    comm.barrier()
    t0 = time.perf_counter()
    m = FemModel(body, soil=DruckerPrager(young_pa=30e6, poisson=0.3, cohesion_pa=2e3,
                                           friction_deg=35.0),
                  layers=[GeogridLayerMaterial(500e3, prestress_n_per_m=10e3)],
                  unit_weight_n_m3=18e3, max_newton=60, comm=comm)
    m.set_geostatic()
    steps = m.apply_prestress(steps=2)
    steps += m.load_footing(pressure_pa=100e3, steps=4)
    steps += m.load_footing(settlement_m=0.01, steps=4)
    wall = comm.allreduce(time.perf_counter() - t0, op=m._fx.MPI.MAX)
    results = {"settlement_m": [r.footing_settlement_m for r in steps],
               "pressure_pa": [r.footing_pressure_pa for r in steps],
               "point_stress_pa": m.point_stress([[0.0, 1.0]])[0].tolist(),
               "layer_force_n_per_m": m.layer_force_n_per_m(0)}
    dofs = m.V.dofmap.index_map.size_global * m.V.dofmap.index_map_bs
    if comm.rank == 0:
        digest = hashlib.sha256(json.dumps(results).encode()).hexdigest()[:16]
        out.write_text(json.dumps({"hash": digest, "steps": len(steps), "wall_s": wall,
                                   "newton_iterations": sum(r.newton_iterations
                                                            for r in steps),
                                   "dofs": dofs, "statuses": sorted({r.status for r in steps}),
                                   "settlement_m": results["settlement_m"][-1]}))


def add_body_args(ap, out_file: str) -> None:
    """The options of a bench on this body: ``--fine-size``, ``--out`` (for ``out_file``)
    and the hidden ``--worker LU FILE`` (one run)."""
    ap.add_argument("--fine-size", type=float, default=None,
                    help="FEM cell size under the footing, m (default 0.025)")
    ap.add_argument("--out", type=Path, default=None, help=f"folder for {out_file}")
    ap.add_argument("--worker", nargs=2, metavar=("LU", "FILE"), help=argparse.SUPPRESS)


def fine_size(ap, a) -> float:
    """The body's fine size (m): ``--fine-size``, else 0.1 with --smoke and 0.025 without;
    refused unless > 0."""
    fine = a.fine_size if a.fine_size is not None else (0.1 if a.smoke else 0.025)
    if not fine > 0:
        ap.error(f"--fine-size={fine}: must be > 0 (m)")
    return fine


def run_count(ap, a, *, smoke: int, full: int) -> int:
    """``--runs``, else ``smoke`` with --smoke and ``full`` without; refused unless >= 1."""
    runs = a.runs if a.runs is not None else (smoke if a.smoke else full)
    if runs < 1:
        ap.error(f"--runs={runs}: must be >= 1")
    return runs


def package_rows(got: dict) -> list:
    """One row per package of ``got`` (package -> its runs' worker JSON): runs, distinct
    results, load steps, the FEM's mean wall time and its time per Newton iteration."""
    rows = []
    for lu, r in got.items():
        rows.append({"package": lu, "runs": len(r), "distinct_results": len({x["hash"] for x in r}),
                     "steps": sorted({x["steps"] for x in r}),
                     "wall_s_mean": sum(x["wall_s"] for x in r) / len(r),
                     "s_per_newton_iteration": sum(x["wall_s"] for x in r)
                     / sum(x["newton_iterations"] for x in r),
                     "settlements_m": sorted({x["settlement_m"] for x in r})})
    return rows


def package_table(rows: list) -> None:
    """:func:`package_rows`' rows as a table on stderr."""
    markdown_table(rows, [("package", lambda r: r["package"]),
                          ("runs", lambda r: str(r["runs"])),
                          ("distinct results", lambda r: str(r["distinct_results"])),
                          ("steps", lambda r: ",".join(map(str, r["steps"]))),
                          ("FEM wall s", lambda r: f"{r['wall_s_mean']:.2f}"),
                          ("s per Newton iteration",
                           lambda r: f"{r['s_per_newton_iteration']:.3f}")])


def report(a, bench: str, rows: list, fields: dict) -> int:
    """The bench's summary: ``fields``, the rows and the first package's time over the
    second's (whole run and per Newton iteration); as a table on stderr, in
    ``<--out>/<bench>.json`` and as the last line on stdout."""
    first, second = rows[0]["package"], rows[1]["package"]
    summary = {"bench": bench, **fields, "packages": rows,
               f"time_ratio_{first}_over_{second}": rows[0]["wall_s_mean"]
               / rows[1]["wall_s_mean"],
               f"iteration_time_ratio_{first}_over_{second}":
                   rows[0]["s_per_newton_iteration"] / rows[1]["s_per_newton_iteration"]}
    package_table(rows)
    if a.out is not None:
        write_json(a.out / f"{bench}.json", summary)
    print(json.dumps(summary), flush=True)
    return 0


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="folder", description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="fine size 0.1 m, 2 runs each")
    ap.add_argument("--runs", type=int, default=None, help="runs per package (default 6)")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks (at least 2)")
    ap.add_argument("--load", choices=("on", "off"), default="on",
                    help="two busy processes beside the runs (default on)")
    add_body_args(ap, "parallel_lu.json")
    a = ap.parse_args(argv)
    fine = fine_size(ap, a)
    if a.worker:
        worker(a.worker[0], fine, Path(a.worker[1]))
        return 0
    runs = run_count(ap, a, smoke=2, full=6)
    if a.ranks < 2:
        ap.error(f"--ranks={a.ranks}: must be >= 2 (on one rank no parallel LU is used)")
    mpiexec = Path(sys.executable).parent / "mpiexec"
    if not mpiexec.exists():
        ap.error(f"no mpiexec beside {sys.executable} (make setup installs it)")
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(2 if a.load == "on" else 0)]
    got: dict = {lu: [] for lu in PACKAGES}
    t_start = time.perf_counter()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(runs):  # alternating blocks: one run of each package per block
                for lu in PACKAGES:
                    f = Path(tmp) / f"{lu}_{k}.json"
                    p = subprocess.run([str(mpiexec), "-n", str(a.ranks), sys.executable,
                                        __file__, "--fine-size", str(fine), "--worker", lu,
                                        str(f)], capture_output=True, text=True, timeout=3600)
                    if p.returncode != 0:
                        print(p.stdout[-2000:], p.stderr[-4000:], file=sys.stderr)
                        raise SystemExit(f"the {lu} run {k + 1} failed "
                                         f"(exit {p.returncode})")
                    got[lu].append(json.loads(f.read_text()))
                done = (k + 1) / runs
                el = time.perf_counter() - t_start
                print(f"[parallel_lu] block {k + 1}/{runs}, ETA {el / done - el:.0f} s",
                      file=sys.stderr, flush=True)
    finally:
        for b in busy:
            b.kill()
    rows = package_rows(got)
    return report(a, "parallel_lu", rows, {"ranks": a.ranks, "fine_size_m": fine,
                                           "dofs": got[PACKAGES[0]][0]["dofs"],
                                           "load": a.load})


if __name__ == "__main__":
    sys.exit(_cli.run(main))
