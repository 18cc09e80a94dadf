#!/usr/bin/env python3
"""The FEM's LU on one rank: PETSc's own against MUMPS, under several BLAS kernels. Does
another CPU give another result, and what does the choice cost?
(``femcoupling.fem.quadrature.SERIAL_LU``; docs/fem.md, "The same bits on every CPU".)

Each run is the Drucker–Prager soil body of tests/mpi_soil_body.py (self-weight, a
prestressed geogrid layer, a footing pressed to 100 kPa in 4 steps and then pushed 10 mm
in 4; bench/parallel_lu.py's worker), meshed at ``--fine-size`` (m) under the footing, one
process. A BLAS kernel is what another CPU would pick; ``OPENBLAS_CORETYPE`` picks it here.
The packages and kernels run in alternating blocks, ``--runs`` blocks.

For each package: how many distinct results its runs gave over the kernels (the
settlements, stresses and layer force compared bitwise; 1: the same bits on every kernel),
the load steps taken, the FEM's wall time (mean, s) and per Newton iteration. The ratio is
PETSc's over MUMPS's, in the same script.

Prints a table on stderr and a final JSON line; with --out also writes ``serial_lu.json``.

    .venv/bin/python bench/serial_lu.py             # fine size 0.025 m, 3 blocks
    .venv/bin/python bench/serial_lu.py --smoke     # fine size 0.1 m, 1 block
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _cli  # noqa: E402  (one command-line style: bench/_cli.py)
from parallel_lu import add_body_args, fine_size, package_rows, report, run_count  # noqa: E402

PACKAGES = ("petsc", "mumps")
KERNELS = ("default", "Haswell", "Sandybridge")


def worker(lu: str, fine_size: float, out: Path) -> None:
    """One run: ``lu`` ("petsc" or "mumps") as the one-rank LU, then parallel_lu's body."""
    import femcoupling.fem.quadrature as quadrature
    from parallel_lu import worker as body_run

    quadrature.SERIAL_LU = None if lu == "petsc" else lu
    body_run(quadrature.PARALLEL_LU, fine_size, out)


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="folder", description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="fine size 0.1 m, 1 block")
    ap.add_argument("--runs", type=int, default=None, help="blocks (default 3)")
    add_body_args(ap, "serial_lu.json")
    a = ap.parse_args(argv)
    fine = fine_size(ap, a)
    if a.worker:
        worker(a.worker[0], fine, Path(a.worker[1]))
        return 0
    runs = run_count(ap, a, smoke=1, full=3)
    got: dict = {lu: [] for lu in PACKAGES}
    t_start = time.perf_counter()
    total = runs * len(PACKAGES) * len(KERNELS)
    done = 0
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(runs):  # alternating blocks: every package under every kernel
            for kernel in KERNELS:
                for lu in PACKAGES:
                    f = Path(tmp) / f"{lu}_{kernel}_{k}.json"
                    env = {**os.environ, "OMP_NUM_THREADS": "1"}
                    env.pop("OPENBLAS_CORETYPE", None)
                    if kernel != "default":
                        env["OPENBLAS_CORETYPE"] = kernel
                    p = subprocess.run([sys.executable, __file__, "--fine-size", str(fine),
                                        "--worker", lu, str(f)], capture_output=True,
                                       text=True, timeout=3600, env=env)
                    if p.returncode != 0:
                        print(p.stdout[-2000:], p.stderr[-4000:], file=sys.stderr)
                        raise SystemExit(f"the {lu} run under {kernel} failed "
                                         f"(exit {p.returncode})")
                    got[lu].append(json.loads(f.read_text()))
                    done += 1
                    el = time.perf_counter() - t_start
                    print(f"[serial_lu] {done}/{total} runs, ETA {el / done * (total - done):.0f} s",
                          file=sys.stderr, flush=True)
    rows = [{**r, "kernels": list(KERNELS)} for r in package_rows(got)]
    return report(a, "serial_lu", rows, {"fine_size_m": fine,
                                         "dofs": got[PACKAGES[0]][0]["dofs"]})

if __name__ == "__main__":
    sys.exit(_cli.run(main))
