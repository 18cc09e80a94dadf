#!/usr/bin/env python3
"""Simple shear: a periodic cell against the core of a large layer bounded by rough walls
(issue 17).

One packing serves both ("compare like with like"): a tall cell (``--layer`` width x height in
mean diameters) of grains prepared periodic in x, y and z to an isotropic ``--sigma`` at rest
(dense: grown at ``--prep-friction``, then the grains' friction restored).
Then, at constant volume and the same shear rate (inertial number ``--inertial``, quasi-static):

- **periodic**: the cell itself, sheared by L_xz = gamma_dot (every other component held);
- **walls**: the same state made periodic in x and y only, its top and bottom slabs
  (``--slab`` mean diameters) glued into rough walls (every DOF blocked) that move at
  +-gamma_dot (z - z_mid) in x. Its **core** (the middle third in z) is measured: the shear
  strain from the grains' displacements (least-squares slope of u_x against z), the stress
  from the contacts with both grains in the core (Love–Weber over the core volume).

Reported: tau / sigma_zz (compression positive) against the shear strain for both, the peak
and the mean over gamma in [0.10, 0.15]. Results to --out (JSON) and a figure beside it.

    .venv/bin/python bench/periodic_shear.py                 # layer 10 x 30 d (~4000 grains)
    .venv/bin/python bench/periodic_shear.py --quick
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

import cpp_dem as dem  # noqa: E402
from cpp_dem.protocols import periodic  # noqa: E402
from cpp_dem.protocols import prep
from cpp_dem.build.packing import loose_cloud  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def log(msg: str) -> None:
    print(f"[shear] {msg}", flush=True)


def material(phi: float) -> dem.Material:
    return dem.linear_material(density=2650.0, young=100e6, poisson=0.3, friction_angle_deg=phi)


def radii(n: int, r: float, spread: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return r * (1.0 + spread * (2.0 * rng.random(n) - 1.0))


def prepare(args):
    """The tall periodic cell at rest at sigma (a scene)."""
    t0 = time.perf_counter()
    d = 2 * args.radius
    lx, hz = args.layer[0] * d, args.layer[1] * d
    n = int(0.25 * lx * lx * hz / (4 / 3 * np.pi * args.radius**3))
    c, r = loose_cloud(radii(n, args.radius, 0.2, args.seed), (0, 0, 0), (lx, lx, hz),
                       seed=args.seed)
    s = periodic.periodic_scene(c, r, np.diag([lx, lx, hz]), material=material(args.friction))
    # Dense: grown and compacted frictionless, so that shearing at constant volume dilates
    # (a loose sample contracts and, at constant volume, liquefies: p -> 0).
    prep.set_friction(s, np.arange(len(r)), s.material(0), args.prep_friction)
    prep.grow_to_stress(s, (), args.sigma)
    periodic.drive_cell(s, stress=(args.sigma,) * 3, unbalanced=1e-3, tol=0.01)
    for b in range(len(r)):
        s.set_body_material(b, 0)
    res = periodic.drive_cell(s, stress=(args.sigma,) * 3, unbalanced=1e-4, tol=0.005)
    s.clear_controllers()
    s.velocity_gradient = np.zeros((3, 3))
    s.set_auto_timestep(0.5, 0)
    log(f"{n} grains at {res.mean_stress:.4g} Pa (converged {res.converged}) in "
        f"{time.perf_counter() - t0:.1f} s")
    return s


def tau_ratio(st) -> float:
    """tau / sigma_zz from a compression-positive stress: -sym(sigma)_xz / sigma_zz."""
    return float(-0.5 * (st[0, 2] + st[2, 0]) / st[2, 2])


def run_periodic(args, blob) -> dict:
    t0 = time.perf_counter()
    s = dem.Scene()
    dem._core._checkpoint_load(s, blob)
    s.mean_spin = not args.no_mean_spin
    s.local_damping = args.damping
    s.velocity_gradient = np.array([[0, 0, args.rate], [0, 0, 0], [0, 0, 0]])
    rows = []
    h0 = np.asarray(s.cell_matrix)
    while True:
        f = np.asarray(s.cell_matrix) @ np.linalg.inv(h0)
        st = np.asarray(s.cell_stress())
        rows.append({"gamma": float(f[0, 2]), "tau_over_sigma": tau_ratio(st),
                     "sigma_zz": float(st[2, 2])})
        if f[0, 2] >= args.gamma:
            break
        s.run(args.every)
    log(f"periodic: {s.step_count} steps, {time.perf_counter() - t0:.1f} s")
    return {"rows": rows}


def run_walls(args, blob) -> dict:
    t0 = time.perf_counter()
    s = dem.Scene()
    dem._core._checkpoint_load(s, blob)
    h = np.asarray(s.cell_matrix)
    s.set_periodic_cell(h, (True, True, False))
    s.local_damping = args.damping
    x = np.asarray(s.positions)
    hz = h[2, 2]
    slab = args.slab * 2 * args.radius
    glued = np.flatnonzero((x[:, 2] < slab) | (x[:, 2] > hz - slab))
    s.block_dofs(glued, "all")
    v = np.zeros_like(x)
    v[glued, 0] = args.rate * (x[glued, 2] - 0.5 * hz)
    ang = np.asarray(s.angular_velocities)
    ang[glued] = 0.0
    s.velocities = v
    s.angular_velocities = ang

    def unwrapped():
        return np.asarray(s.positions) + np.asarray(s.images) @ np.asarray(s.cell_matrix).T

    x0 = unwrapped()
    lo, hi = slab + (hz - 2 * slab) / 3, slab + 2 * (hz - 2 * slab) / 3
    core0 = (x0[:, 2] > lo) & (x0[:, 2] < hi)
    rows = []
    steps = 0
    while True:
        xu = unwrapped()
        slope = float(np.polyfit(xu[core0, 2], xu[core0, 0] - x0[core0, 0], 1)[0])
        cc = s.contacts()
        ids = np.asarray(cc["ids"])
        z = xu[:, 2]
        inside = (ids[:, 1] >= 0)
        inside &= (z[ids[:, 0]] > lo) & (z[ids[:, 0]] < hi)
        inside &= (z[np.maximum(ids[:, 1], 0)] > lo) & (z[np.maximum(ids[:, 1], 0)] < hi)
        st = np.einsum("ki,kj->ij", np.asarray(cc["force"])[inside],
                       np.asarray(cc["branch"])[inside])
        rows.append({"gamma": slope, "tau_over_sigma": tau_ratio(st),
                     "boundary_gamma": float(steps * s.dt * args.rate)})
        if slope >= args.gamma or steps * s.dt * args.rate > 3 * args.gamma:
            break
        s.run(args.every)
        steps += args.every
    log(f"walls: {len(glued)} glued, {int(core0.sum())} in the core; core gamma "
        f"{rows[-1]['gamma']:.3f} (boundaries {rows[-1]['boundary_gamma']:.3f}) in "
        f"{time.perf_counter() - t0:.1f} s")
    return {"rows": rows, "glued": int(len(glued)), "core_grains": int(core0.sum())}


def summary(rows) -> dict:
    g = np.array([r["gamma"] for r in rows])
    t = np.array([r["tau_over_sigma"] for r in rows])
    crit = (g >= 0.10) & (g <= 0.15)
    return {"peak": float(t.max()), "gamma_at_peak": float(g[t.argmax()]),
            "critical_mean": float(t[crit].mean()) if crit.any() else float("nan"),
            "critical_std": float(t[crit].std()) if crit.any() else float("nan")}


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--layer", type=float, nargs=2, default=(10, 30),
                    help="layer width and height in mean diameters")
    ap.add_argument("--slab", type=float, default=1.5,
                    help="thickness of each glued boundary slab, mean diameters")
    ap.add_argument("--radius", type=float, default=1e-3, help="mean radius, m")
    ap.add_argument("--friction", type=float, default=30.0, help="grain friction, deg")
    ap.add_argument("--sigma", type=float, default=100e3, help="normal stress, Pa")
    ap.add_argument("--inertial", type=float, default=1e-3, help="inertial number I, -")
    ap.add_argument("--gamma", type=float, default=0.15, help="shear strain to reach, -")
    ap.add_argument("--every", type=int, default=500, help="steps between records")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--prep-friction", type=float, default=0.0,
                    help="grain friction during the preparation, deg (0: dense)")
    ap.add_argument("--damping", type=float, default=0.2,
                    help="Cundall local damping while shearing (the preparation uses 0.7)")
    ap.add_argument("--no-mean-spin", action="store_true",
                    help="the periodic cell's grains do not carry the mean spin (as Yade)")
    ap.add_argument("--quick", action="store_true", help="layer 8 x 16 d, gamma 0.1")
    ap.add_argument("--out", default="results/bench_runs/periodic_shear.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.layer, args.gamma = (8, 16), 0.1
    args.rate = args.inertial * np.sqrt(args.sigma / 2650.0) / (2 * args.radius)
    log(f"gamma_dot {args.rate:.3g} 1/s (I = {args.inertial})")
    blob = bytes(dem._core._checkpoint_save(prepare(args)))
    per = run_periodic(args, blob)
    wal = run_walls(args, blob)
    res = {"args": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(args).items()},
           "periodic": per, "walls": wal,
           "summary": {"periodic": summary(per["rows"]), "walls": summary(wal["rows"])}}
    for k, v in res["summary"].items():
        log(f"{k}: peak tau/sigma {v['peak']:.3f} at gamma {v['gamma_at_peak']:.3f}, "
            f"gamma 0.10-0.15: {v['critical_mean']:.3f} +- {v['critical_std']:.3f}")
    out = write_json(args.out, res)
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5, 3.5))
        for k, lab in (("periodic", "periodic cell"), ("walls", "core of the layer (rough walls)")):
            rows = res[k]["rows"]
            ax.plot([r["gamma"] for r in rows], [r["tau_over_sigma"] for r in rows], label=lab)
        ax.set_xlabel("shear strain gamma (-)")
        ax.set_ylabel("tau / sigma_n (-)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out.with_suffix(".png"), dpi=120)
    except Exception as e:  # noqa: BLE001 - the figure is optional
        log(f"no figure: {e}")
    log(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
