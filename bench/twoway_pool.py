"""The two-way loop's regions on the element pool: wall time on 1 and 2 workers, and that the
answers are bitwise the same. Not a test.

The two-region test body of tests/test_fem_handover.py (4 x 3 m, elastic soil 50 MPa / 0.3,
a 1 m footing), both regions coupled to a dense periodic DEM element
(femcoupling.materials.dem_elements.PeriodicRegionElement, ``--grains`` grains) for ``--iterations``
FEM solves. With ``--workers 1`` the regions run in this process; with more, each region is an
element of ``cpp_dem.elements.pool.ElementPool.runners`` on a LocalCluster (its start
included in the time); each worker, and this process (``--threads``, default 1), runs one
thread. Prints one JSON line per worker count (wall seconds, FEM solves, the
regions' final stresses as hex floats) and whether every count gave the same answers.

    .venv/bin/python bench/twoway_pool.py                 # 100 grains, 3 solves, 1 and 2 workers

SI units.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def run(workers: int, args) -> dict:
    import numpy as np

    from femcoupling.coupling.twoway import RegionWarning, two_way
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    from test_fem_handover import _footing, two_region_model  # (the FEM body of the tests)

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegionWarning)
        res = two_way(two_region_model(), regions=["a", "b"], load=_footing,
                      element_runner=PeriodicRegionElement(n=args.grains, tol=0.01),
                      tol=1e-3, max_iterations=args.iterations, workers=workers)
    wall = time.perf_counter() - t0
    answers = {r: [float(x).hex() for x in np.concatenate(
        [np.ravel(res.responses[r].stress_final_pa), np.ravel(res.responses[r].strain_increment),
         np.ravel(res.targets[r].fem_stress_pa)])] for r in ("a", "b")}
    return {"workers": workers, "wall_s": round(wall, 2), "fem_solves": res.iterations,
            "status": res.status, "answers": answers}


def main() -> None:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grains", type=int, default=100, help="grains per element (default 100)")
    ap.add_argument("--iterations", type=int, default=3,
                    help="FEM solves of the loop, >= 2 (default 3)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2],
                    help="worker counts to run (default 1 2)")
    ap.add_argument("--threads", type=int, default=1,
                    help="OpenMP threads of this process, for --workers 1 (default 1: as each "
                         "worker runs)")
    args = ap.parse_args()
    from cpp_dem import set_num_threads

    set_num_threads(args.threads)
    rows = [run(w, args) for w in args.workers]
    for row in rows:
        print(json.dumps({k: v for k, v in row.items() if k != "answers"}))
    same = all(r["answers"] == rows[0]["answers"] for r in rows)
    print(json.dumps({"bitwise_same": same}))


if __name__ == "__main__":
    sys.exit(_cli.run(main))
