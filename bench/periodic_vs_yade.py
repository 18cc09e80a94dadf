#!/usr/bin/env python3
"""A periodic cell in cpp_dem and in Yade from the same state (issue 17: the cell stress within
0.5 % over 1e5 steps).

"Compare like with like": a dense periodic packing is prepared once, by cpp_dem
(``periodic.prepare_periodic``, grown at ``--prep-friction``, at rest at ``--stress``); both codes then start from its
positions (wrapped in the cell), radii and cell matrix, with fresh contacts (no shear history
in either), the same linear law (Yade's FrictMat / FrictPhys / CundallStrack is cpp_dem's
``linear_material``: k_n = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2), k_s = poisson k_n), the same dt,
the same Cundall local damping, no gravity, and the same constant velocity gradient:
volume-preserving compression along z, L = diag(r/2, r/2, -r), r = strain / (steps dt)
(``--shear``: a pure shear in x-z, L_xz = L_zx = r/2). L is symmetric, so the mean spin (which
Yade's grains do not carry) plays no part; cpp_dem runs with ``mean_spin = False`` anyway.

Both record the cell stress (Love–Weber over the cell, compression positive), the contact
count and the cell matrix every ``--every`` steps. Reported: the largest and the final
relative differences of sigma_zz, sigma_xx, p and q, each relative to |p| at that record.

    .venv/bin/python bench/periodic_vs_yade.py --quick
    .venv/bin/python bench/periodic_vs_yade.py                 # n 500, 1e5 steps
    .venv/bin/python bench/periodic_vs_yade.py --shear-kinematics yade

``--shear-kinematics yade`` runs cpp_dem with Yade's sphere–sphere shear kinematics
(``Scene.shear_kinematics``; Yade's ``Ig2_Sphere_Sphere_ScGeom`` has avoidGranularRatcheting
on by default), so that the two codes integrate the same contact law.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _report import write_json  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))

import cpp_dem as dem  # noqa: E402
from cpp_dem.protocols import periodic  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def log(msg: str) -> None:
    print(f"[peri-yade] {msg}", flush=True)


def invariants(s: np.ndarray) -> dict:
    sym = 0.5 * (s + s.T)
    p = np.trace(sym) / 3
    dev = sym - p * np.eye(3)
    return {"p": p, "q": float(np.sqrt(1.5 * np.sum(dev * dev))), "zz": sym[2, 2],
            "xx": sym[0, 0], "xz": sym[0, 2]}


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=500)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--stress", type=float, default=100e3, help="preparation stress, Pa")
    ap.add_argument("--steps", type=int, default=100_000)
    ap.add_argument("--every", type=int, default=2000)
    ap.add_argument("--strain", type=float, default=0.02, help="total axial strain, -")
    ap.add_argument("--damping", type=float, default=0.2)
    ap.add_argument("--prep-friction", type=float, default=0.0,
                    help="grain friction while the packing is grown, deg (0: dense)")
    ap.add_argument("--shear", action="store_true", help="pure shear in x-z instead")
    ap.add_argument("--quick", action="store_true", help="n 200, 10000 steps")
    ap.add_argument("--shear-kinematics", choices=("contact_point", "yade"),
                    default="contact_point",
                    help="cpp_dem's sphere-sphere shear kinematics (Scene.shear_kinematics): its default, "
                         "or Yade's avoidGranularRatcheting formula, which the Yade side uses")
    ap.add_argument("--yade", default="yade")
    ap.add_argument("--out", default="results/bench_runs/periodic_vs_yade.json")
    args = ap.parse_args(argv)
    if args.quick:
        args.n, args.steps = 200, 10_000
    if shutil.which(args.yade) is None:
        print(f"error: --yade={args.yade}: not found (apt-get install yade)", file=sys.stderr)
        return 2
    young, poisson, rho, phi = 1e8, 0.3, 2650.0, 30.0
    mat = dem.linear_material(density=rho, young=young, poisson=poisson, friction_angle_deg=phi)
    t0 = time.perf_counter()
    # Dense (grown frictionless, then at 30 deg): at constant volume it dilates against the
    # cell and the stress rises; a loose packing contracts and liquefies (p -> 0), a path
    # that amplifies every difference.
    prepared = periodic.prepare_periodic(args.n, material=mat, stress=args.stress,
                                         radius_mean=1e-3, seed=args.seed, unbalanced=1e-4,
                                         tol=0.005, prep_friction_deg=args.prep_friction)
    dt = 0.5 * float(prepared.critical_dt())
    h = np.asarray(prepared.cell_matrix)
    centres = np.asarray(prepared.positions)
    radii = np.asarray(prepared.radii)
    log(f"prepared {args.n} grains at {args.stress:.4g} Pa in {time.perf_counter() - t0:.1f} s; "
        f"dt {dt:.4g} s")
    rate = args.strain / (args.steps * dt)
    L = (np.array([[0, 0, rate / 2], [0, 0, 0], [rate / 2, 0, 0]]) if args.shear
         else np.diag([rate / 2, rate / 2, -rate]))
    verlet = 0.2 * float(np.mean(radii))

    # ---- cpp_dem --------------------------------------------------------------------------
    s = dem.Scene(local_damping=args.damping)
    m = s.add_material(mat)
    s.add_spheres(centres, radii, material=m)
    s.set_periodic_cell(h)
    s.dt = dt
    s.verlet_margin = verlet
    s.mean_spin = False
    s.shear_kinematics = args.shear_kinematics
    s.velocity_gradient = L
    ours = []

    def record():
        ours.append({"step": s.step_count, "stress": np.asarray(s.cell_stress()).tolist(),
                     "contacts": int(s.num_active_contacts),
                     "hsize": np.asarray(s.cell_matrix).tolist()})

    s.run(1)
    record()
    t = time.perf_counter()
    while s.step_count < args.steps:
        s.run(min(args.every, args.steps - s.step_count))
        record()
    ours_s = time.perf_counter() - t
    log(f"cpp_dem: {args.steps} steps in {ours_s:.1f} s (shear kinematics "
        f"{args.shear_kinematics})")

    # ---- Yade ---------------------------------------------------------------------------
    cfg = {"hsize": h.tolist(), "velgrad": L.tolist(), "centres": centres.tolist(),
           "radii": radii.tolist(), "young": young, "poisson": poisson, "density": rho,
           "friction_rad": float(np.radians(phi)), "dt": dt, "damping": args.damping,
           "verlet": verlet, "steps": args.steps, "every": args.every}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cfg.json"
        path.write_text(json.dumps(cfg))
        t = time.perf_counter()
        p = subprocess.run([args.yade, "-n", "-j1", "-x", str(HERE / "yade_periodic.py"),
                            str(path)], capture_output=True, text=True, timeout=7200)
        yade_s = time.perf_counter() - t
    line = [x for x in p.stdout.splitlines() if x.startswith("YADE_RESULT ")]
    if not line:
        print(p.stdout[-3000:], p.stderr[-3000:], file=sys.stderr)
        raise SystemExit("yade gave no result")
    yade = json.loads(line[0][len("YADE_RESULT "):])
    log(f"yade: {args.steps} steps in {yade_s:.1f} s (homoDeform {yade['homoDeform']})")

    # ---- comparison (records at the same steps) -------------------------------------------
    ys = {r["step"]: r for r in yade["rows"]}
    table: list[dict] = []
    for r in ours:
        y = ys.get(r["step"])
        if y is None:
            continue
        a, b = invariants(np.asarray(r["stress"])), invariants(np.asarray(y["stress"]))
        scale = abs(b["p"])
        table.append({"step": r["step"], "p_ours": float(a["p"]), "p_yade": float(b["p"]),
                      "q_ours": float(a["q"]), "q_yade": float(b["q"]),
                      "d_p": float((a["p"] - b["p"]) / scale),
                      "d_q": float((a["q"] - b["q"]) / scale),
                      "d_zz": float((a["zz"] - b["zz"]) / scale),
                      "d_xx": float((a["xx"] - b["xx"]) / scale),
                      "contacts_ours": r["contacts"], "contacts_yade": y["contacts"],
                      "d_cell": float(np.abs(np.asarray(r["hsize"]) - np.asarray(y["hsize"])).max()
                                      / np.abs(h).max())})
    worst = {k: max(abs(row[k]) for row in table) for k in ("d_p", "d_q", "d_zz", "d_xx", "d_cell")}
    final = table[-1]
    print("| step | p ours (Pa) | p Yade (Pa) | q ours | q Yade | dp/p | dq/p | dσzz/p | contacts |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in table[:: max(1, len(table) // 12)] + [final]:
        print(f"| {row['step']} | {row['p_ours']:.6g} | {row['p_yade']:.6g} | {row['q_ours']:.5g} | "
              f"{row['q_yade']:.5g} | {row['d_p']:+.2e} | {row['d_q']:+.2e} | {row['d_zz']:+.2e} | "
              f"{row['contacts_ours']}/{row['contacts_yade']} |")
    ok = bool(max(worst["d_p"], worst["d_q"], worst["d_zz"], worst["d_xx"]) <= 0.005)
    log(f"largest differences over the run (of |p|): p {worst['d_p']:.2e}, q {worst['d_q']:.2e}, "
        f"sigma_zz {worst['d_zz']:.2e}, sigma_xx {worst['d_xx']:.2e}; cell {worst['d_cell']:.1e}; "
        f"within 0.5 %: {ok}")
    log(f"speed: cpp_dem {1e6 * ours_s / args.steps:.1f} us/step, Yade "
        f"{1e6 * yade['seconds'] / args.steps:.1f} us/step (ratio {yade['seconds'] / ours_s:.1f})")
    out = write_json(args.out, {"args": vars(args), "dt": dt, "rate": rate, "table": table,
                                "worst": worst, "within_half_percent": bool(ok),
                                "ours_s": ours_s, "yade_s": yade["seconds"]})
    log(f"wrote {out}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(_cli.run(main))
