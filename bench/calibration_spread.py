"""How far the footing's calibrated continuum moves with the rounding path and the element seeds.

    .venv/bin/python bench/calibration_spread.py                          # 1 and 16 seeds
    .venv/bin/python bench/calibration_spread.py --counts 1,4 --paths default,narrow

The footing-multiscale calibration (``geogrid_dem.studies.footing_multiscale.calibrate``: a
first FEM of the unreinforced body gives the zone's stress path; elements of the zone's grains
are driven along it, the continuum's E and nu the secant of their mean, phi the mean of their
biaxial peaks) at smoke size (``--smoke``'s body, --cell-grains grains an element), fitted on
each count of element seeds of --counts, on each rounding path of --paths, each in its own
process (the paths are read when the libraries load):

- ``default``: this machine's own;
- ``narrow``: the DEM core's narrow vector form (``CPP_DEM_NARROW=1``);
- ``haswell``: OpenBLAS's Haswell kernels (``OPENBLAS_CORETYPE=Haswell``; the CPU must have
  AVX2).

Per (path, count): E (Pa), nu, phi (deg), the seeds' own E (mean, sd) and phi, the path's
final stress, and the wall time; then, per count, each path's E and phi relative to the
default's (``E_vs_default`` = E / E_default - 1). One JSON line per (path, count) to stdout
and --out (appended, flushed as each is done), then a table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

PATHS = {"default": {}, "narrow": {"CPP_DEM_NARROW": "1"},
         "haswell": {"OPENBLAS_CORETYPE": "Haswell"}}

_ONE = """
import json, sys, time
from dataclasses import replace
from geogrid_dem.cases.footing_multiscale import SMOKE
from geogrid_dem.studies.footing_multiscale import FootingParams, calibrate
k, grains = int(sys.argv[1]), int(sys.argv[2])
p = replace(FootingParams(**SMOKE), calibration_seeds=k, cell_grains=grains, seeds=(1,))
t = time.perf_counter()
_, rec = calibrate(p, lambda m: None)
print(json.dumps({"E": rec["young_pa"], "nu": rec["poisson"], "phi": rec["friction_deg"],
                  "seeds_E": [r["young_pa"] for r in rec["per_seed"]],
                  "seeds_phi": [r["friction_deg"] for r in rec["per_seed"]],
                  "path_final_pa": rec["path_final_pa"], "wall_s": time.perf_counter() - t}))
"""


def run_one(path: str, count: int, grains: int) -> dict:
    """One calibration in a fresh process on ``path``."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", **PATHS[path]}
    r = subprocess.run([sys.executable, "-c", _ONE, str(count), str(grains)], env=env,
                       capture_output=True, text=True, timeout=3600)
    if r.returncode != 0:
        raise SystemExit(f"calibration on path {path} with {count} seeds failed:\n"
                         f"{r.stderr[-2000:]}")
    res = json.loads(r.stdout.strip().splitlines()[-1])
    e = res["seeds_E"]
    res.update(path=path, count=count, cell_grains=grains,
               seeds_E_mean=statistics.mean(e),
               seeds_E_sd=statistics.stdev(e) if len(e) > 1 else None)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", default="1,16", help="element seed counts, comma-separated")
    ap.add_argument("--paths", default="default,narrow,haswell",
                    help="rounding paths, comma-separated: " + ", ".join(PATHS))
    ap.add_argument("--cell-grains", type=int, default=80, help="grains an element (>= 50)")
    ap.add_argument("--out", type=Path, default=None, help="JSON lines, appended")
    a = ap.parse_args(argv)
    try:
        counts = [int(c) for c in a.counts.split(",") if c.strip()]
    except ValueError:
        ap.error(f"--counts={a.counts!r}: whole numbers from 1 to 64, comma-separated")
    if not counts or any(not 1 <= c <= 64 for c in counts):
        ap.error(f"--counts={a.counts!r}: whole numbers from 1 to 64, comma-separated")
    paths = [x.strip() for x in a.paths.split(",") if x.strip()]
    if not paths or any(x not in PATHS for x in paths) or len(set(paths)) < len(paths):
        ap.error(f"--paths={a.paths!r}: distinct names of " + ", ".join(PATHS))
    if a.cell_grains < 50:
        ap.error(f"--cell-grains={a.cell_grains}: at least 50")
    rows = []
    t0 = time.perf_counter()
    jobs = [(x, c) for c in counts for x in paths]
    for i, (x, c) in enumerate(jobs):
        rows.append(run_one(x, c, a.cell_grains))
        line = json.dumps(rows[-1])
        print(line, flush=True)
        if a.out:
            with a.out.open("a") as f:
                f.write(line + "\n")
        left = (time.perf_counter() - t0) / (i + 1) * (len(jobs) - i - 1)
        print(f"[calibration_spread] {i + 1}/{len(jobs)} done; about {left:.0f} s left",
              file=sys.stderr, flush=True)
    print(f"\n{'path':>8} {'seeds':>5} {'E MPa':>8} {'phi deg':>8} {'seeds E mean+-sd':>18} "
          f"{'E vs default':>12} {'phi vs default':>14}")
    for r in rows:
        ref = next((q for q in rows if q["path"] == "default" and q["count"] == r["count"]),
                   None)
        sd = "" if r["seeds_E_sd"] is None else f" +- {r['seeds_E_sd'] / 1e6:.2f}"
        vs = ("" if ref is None else f"{r['E'] / ref['E'] - 1:+.4f}",
              "" if ref is None else f"{r['phi'] / ref['phi'] - 1:+.4f}")
        print(f"{r['path']:>8} {r['count']:>5} {r['E'] / 1e6:8.3f} {r['phi']:8.2f} "
              f"{r['seeds_E_mean'] / 1e6:9.2f}{sd:>9} {vs[0]:>12} {vs[1]:>14}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
