"""Deviatoric stage of the triaxial test from a packing CSV: particle-steps per second of
cpp_dem, and of Yade on the same packing when ``yade`` is on the PATH. Not a test.

    .venv/bin/python bench/triaxial_bench.py --packing results/triaxial/packing_isotropic.csv
    .venv/bin/python bench/triaxial_bench.py --n 3000          # makes a packing first

Both codes: the spheres of the CSV in the box they span, linear law (E 4.5 MPa, k_s/k_n 0.33,
phi 32 deg, 2650 kg/m^3; 001 App. B), frictionless walls, local damping 0.2, the same fixed
dt; an isotropic stage to the cell pressure (75 kPa) with servo walls, then axial (z)
compression at a constant strain rate with x and y held; ``--steps`` deviatoric steps are
timed after ``--warmup`` untimed ones. Prints one JSON line per thread count, with the axis
stresses of both codes after the timed steps as a physics cross-check.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases"))

import cpp_dem as dem  # noqa: E402
from cpp_dem import measure  # noqa: E402
from cpp_dem.protocols import prep
from cpp_dem.protocols.triaxial import build_box_sample, isotropic_stage  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

YOUNG, POISSON, PHI, RHO, DAMPING = 4.5e6, 0.33, 32.0, 2650.0, 0.2


def make_packing(n: int, out: Path) -> Path:
    """Runs the triaxial case's preparation (smoke-sized for n grains) and returns the CSV of
    its isotropic packing."""
    d = out / f"tx_n{n}"
    csv = d / "packing_isotropic.csv"
    if not csv.exists():
        subprocess.run([sys.executable, str(ROOT / "cases" / "triaxial.py"), "--n", str(n),
                        "--stop-strain", "0.001", "--out", str(d)], check=True)
    return csv


def run_ours(c, r, lo, hi, args, threads: int) -> dict:
    dem.set_num_threads(threads)
    s = build_box_sample(c, r, lo, hi, young=YOUNG, poisson=POISSON, friction_deg=PHI,
                         density=RHO, local_damping=DAMPING)
    sc, walls, ctl = s.scene, s.walls, s.controller
    sc.set_auto_timestep(safety=0.5, period=0)
    sc.dt = args.dt
    iso = isotropic_stage(s, args.pressure)
    ctl.reset_strain(sc)
    ctl.set_stress(0, args.pressure)
    ctl.set_stress(1, args.pressure)
    ctl.set_strain_rate(2, args.strain_rate)
    ctl.enabled = True
    sc.run(args.warmup)
    t0 = time.perf_counter()
    sc.run(args.steps)
    el = time.perf_counter() - t0
    return {"n_particles": len(r), "threads": threads, "steps": args.steps, "wall_s": el,
            "particle_steps_per_s": len(r) * args.steps / el, "iso_steps": iso.steps,
            "sigma_Pa": measure.axis_stresses(sc, walls).tolist(),
            "contacts": sc.num_active_contacts}


def run_yade(csv: Path, lo, hi, args, threads: int, yade: str) -> dict:
    cfg = {"packing": str(csv), "box_lo": list(map(float, lo)), "box_hi": list(map(float, hi)),
           "young": YOUNG, "poisson": POISSON, "density": RHO, "friction_rad": math.radians(PHI),
           "damping": DAMPING, "dt": args.dt, "pressure": args.pressure,
           "strain_rate": args.strain_rate, "steps": args.steps, "warmup": args.warmup,
           "max_iso_steps": 200000, "verlet": 0.1 * args.mean_radius,
           "max_vel": args.max_vel}
    with tempfile.TemporaryDirectory() as tmp:
        cfg_path = Path(tmp) / "cfg.json"
        cfg_path.write_text(json.dumps(cfg))
        cmd = [yade, "-n", f"-j{threads}", "-x", str(ROOT / "bench" / "yade_triaxial.py"),
               str(cfg_path)]
        print("[triaxial_bench]  " + " ".join(cmd), file=sys.stderr, flush=True)
        res = subprocess.run(cmd, capture_output=True, text=True)
    for line in res.stdout.splitlines():
        if line.startswith("YADE_RESULT "):
            return json.loads(line[len("YADE_RESULT "):])
    raise RuntimeError("yade run failed:\n" + res.stdout[-2000:] + res.stderr[-2000:])


def main() -> None:
    ap = _cli.BenchParser(description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--packing", type=Path, help="CSV x,y,z,r (m) of an isotropic sample")
    ap.add_argument("--n", type=int, default=3000, help="grains, when no --packing is given")
    ap.add_argument("--pressure", type=float, default=75e3, help="cell pressure, Pa")
    ap.add_argument("--strain-rate", type=float, default=0.1, help="axial strain rate, 1/s")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--no-yade", action="store_true")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "bench_cache")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    csv = args.packing or make_packing(args.n, args.out)
    c, r = dem.read_packing_csv(csv)
    lo = (c - r[:, None]).min(axis=0)
    hi = (c + r[:, None]).max(axis=0)
    args.mean_radius = float(r.mean())
    args.dt = 0.5 * float(np.min(r)) * math.sqrt(RHO / YOUNG)  # half the p-wave step
    args.max_vel = 1e-4 * args.mean_radius / args.dt
    yade = None if args.no_yade else shutil.which("yade")
    for th in args.threads:
        row = {"bench": "triaxial_deviatoric", "packing": str(csv), "dt_s": args.dt,
               **run_ours(c, r, lo, hi, args, th)}
        if yade:
            y = run_yade(csv, lo, hi, args, th, yade)
            row.update(y)
            row["ratio"] = row["particle_steps_per_s"] / y["yade_particle_steps_per_s"]
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    sys.exit(_cli.run(main))
