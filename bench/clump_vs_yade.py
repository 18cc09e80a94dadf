#!/usr/bin/env python3
"""Clumps against Yade on the same input (issue 15): wall forces and clump motion.

Both codes start from the same state: the same clumps (three member spheres that do not
overlap, so both codes' mass properties are exact sums; cpp_dem's own placement at random
seeded orientations, handed to Yade as the members' world positions for
``O.bodies.appendClumped``), no contacts, the same box (cpp_dem's walls; Yade's zero-thickness
``aabbWalls``), the same linear law (E, k_s/k_n, friction; frictionless walls), the same local
damping, gravity and dt. Stage 1 lets the clumps settle under gravity; stage 2 lowers the top
wall onto the pile at a constant speed. Recorded every ``--every`` steps: the force on the top
and bottom walls and every clump's centre of mass.

Reported: the largest relative difference of the wall forces over stage 2 (relative to the
force at that record), and the largest difference of the clump centres relative to the mean
member radius, per record.

    .venv/bin/python bench/clump_vs_yade.py                      # default scene
    .venv/bin/python bench/clump_vs_yade.py --clumps 40 --out results/bench_runs/clump_vs_yade.json

``--shear-kinematics yade`` runs cpp_dem with Yade's sphere–sphere shear kinematics
(``Scene.shear_kinematics``; Yade's ``Ig2_Sphere_Sphere_ScGeom`` has avoidGranularRatcheting
on by default), so that the two codes integrate the same contact law.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem.build.clumps import ClumpTemplate, clump_cloud, random_orientations
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

HERE = Path(__file__).resolve().parent


def template():
    r = 0.0025
    tpl = ClumpTemplate.from_spheres([[-1.04 * r, 0, 0], [1.04 * r, 0, 0], [0, 1.84 * r, 0]],
                                     [r, r, 0.88 * r], name="tri3")
    assert tpl.fill_accuracy == 0  # disjoint members: exact in both codes
    return tpl


def build(args):
    """The scene, its walls and the template. ``--layout cloud``: a loose random cloud in a
    box of --width x --width x --height (settled by gravity in stage 1); ``lattice``: clumps on
    a cubic lattice (--lattice per side, bounding spheres 5 % apart, random orientations), the
    box tight around it, no gravity (stage 1 then does nothing)."""
    tpl = template()
    sc = dem.Scene(gravity=(0, 0, -9.81) if args.layout != "lattice" else (0, 0, 0),
                   local_damping=args.damping)
    grains = sc.add_material(dem.linear_material(density=2650, young=args.young, poisson=0.3,
                                                 friction_angle_deg=args.friction))
    wall_mat = sc.add_material(dem.linear_material(density=2650, young=args.young, poisson=0.3,
                                                   friction_angle_deg=0.0))
    if args.layout != "lattice":
        lo, hi = np.zeros(3), np.array([args.width, args.width, args.height])
        walls = sc.add_box(lo, hi, material=wall_mat)
        d = np.full(args.clumps, tpl.equivalent_diameter)
        cloud = clump_cloud(tpl, d, lo, hi, seed=args.seed)
        cloud.add_to(sc, tpl, material=grains)
    else:
        n = args.lattice
        a = 2.1 * tpl.bounding_radius
        lo, hi = np.zeros(3), np.full(3, n * a)
        walls = sc.add_box(lo, hi, material=wall_mat)
        k = np.arange(n ** 3)
        x = (np.column_stack([k % n, (k // n) % n, k // (n * n)]) + 0.5) * a
        sc.add_clumps(tpl, x, random_orientations(len(k), args.seed), material=grains)
    sc.dt = args.dt
    sc.verlet_margin = args.verlet
    sc.clump_rotation = args.rotation
    sc.shear_kinematics = args.shear_kinematics
    return sc, walls, tpl, (lo, hi)


def dense_pack(sc, walls, args):
    """The dense layout's shared start: the cloud compacted by cpp_dem's servo walls to the
    isotropic --pressure, frictionless (grains and walls) and without gravity, to an
    unbalanced force of 1e-3; then a fresh scene with the grain friction on, the walls where
    the servo left them, and every clump where it rests, at rest. No contact carries shear
    history, so both codes start with the same contacts in the same state: equal overlaps
    and zero shear springs. Returns (scene, walls, lo, hi) with lo, hi the box's corners (m)."""
    from cpp_dem.protocols import prep

    sc.gravity = (0, 0, 0)
    prep.set_friction(sc, range(sc.num_bodies), sc.material(0), 0.0)
    res = prep.compact_isotropic(sc, walls, args.pressure, unbalanced=1e-3, tol=0.01)
    if not res.converged:
        raise SystemExit(f"error: --pressure={args.pressure:g}: the dense pack did not reach "
                         f"it ({res.axis_stresses} Pa, unbalanced {res.unbalanced_force:.3g})")
    res.extra["controller"].enabled = False
    wp = np.asarray(sc.wall_positions)
    lo = np.array([wp[walls[0]], wp[walls[2]], wp[walls[4]]])
    hi = np.array([wp[walls[1]], wp[walls[3]], wp[walls[5]]])
    print(f"dense pack: {sc.num_clumps} clumps at {res.axis_stresses.round(1).tolist()} Pa, "
          f"porosity {res.porosity:.4f}, unbalanced {res.unbalanced_force:.2e}, box {hi - lo} m")
    fresh, fw, _, _ = build(argparse.Namespace(**{**vars(args), "layout": "cloud"}))
    fresh.gravity = (0, 0, 0)
    for c in range(sc.num_clumps):
        fresh.set_clump_state(c, sc.clump_positions[c], sc.clump_orientations[c],
                              [0, 0, 0], [0, 0, 0])
    for w in range(6):
        fresh.set_wall_position(fw[w], float(wp[walls[w]]))
    return fresh, fw, lo, hi


def members(sc):
    pos, rad = np.asarray(sc.positions), np.asarray(sc.radii)
    return [[[*pos[m], rad[m]] for m in sc.clump_members(c)] for c in range(sc.num_clumps)]


def run_ours(sc, walls, stages):
    rows = []
    for st in stages:
        if st.get("top_position") is not None:
            sc.set_wall_position(walls[5], st["top_position"])
        sc.set_wall_velocity(walls[5], [0, 0, st["top_velocity"]])
        for _ in range(st["records"]):
            sc.run(st["every"])
            f = np.asarray(sc.wall_forces)
            rows.append({"step": sc.step_count, "top_force": float(f[walls[5]][2]),
                         "bottom_force": float(f[walls[4]][2]),
                         "top_position": float(sc.wall_positions[walls[5]]),
                         "centres": np.asarray(sc.clump_positions).tolist(),
                         "spins": np.asarray(sc.clump_angular_velocities).tolist()})
    return rows


def main() -> int:
    ap = _cli.BenchParser(out="file", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--layout", choices=("cloud", "lattice", "settled", "dense"), default="cloud",
                    help="dense: a dense pack (cpp_dem compacts the cloud by servo walls to "
                         "--pressure, frictionless and without gravity, so no contact carries "
                         "shear history); both codes start from it (member positions, walls, "
                         "overlaps) with friction on and the top wall pressing it slowly, "
                         "the other walls fixed; settled: the cloud settled by cpp_dem first, "
                         "then both codes start "
                         "from that pile (positions, orientations; no velocities, no contact "
                         "history) and the top wall presses it quasi-statically; cloud: both "
                         "codes drop the cloud themselves; lattice: no gravity, clumps on a "
                         "lattice pressed by the top wall")
    ap.add_argument("--lattice", type=int, default=4, help="clumps per side (lattice layout)")
    ap.add_argument("--clumps", type=int, default=30, help="number of clumps (cloud layout)")
    ap.add_argument("--width", type=float, default=0.04, help="box width, m")
    ap.add_argument("--height", type=float, default=0.08, help="box height, m")
    ap.add_argument("--young", type=float, default=1e7, help="E, Pa")
    ap.add_argument("--friction", type=float, default=30.0, help="grain friction angle, deg")
    ap.add_argument("--damping", type=float, default=0.4, help="local damping, -")
    ap.add_argument("--dt", type=float, default=1e-5, help="s")
    ap.add_argument("--verlet", type=float, default=5e-4, help="Verlet margin (both codes), m")
    ap.add_argument("--settle", type=int, default=40000, help="stage 1 steps")
    ap.add_argument("--press", type=int, default=20000, help="stage 2 steps")
    ap.add_argument("--speed", type=float, default=0.01, help="top wall speed in stage 2, m/s")
    ap.add_argument("--pressure", type=float, default=20e3,
                    help="isotropic stress of the dense pack (dense layout), Pa")
    ap.add_argument("--every", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--rotation", choices=("fincham", "yade"), default="yade",
                    help="cpp_dem's clump rotation update: Yade's own variant (the same "
                         "arithmetic) or Fincham's second-order leapfrog (the default in cpp_dem)")
    ap.add_argument("--shear-kinematics", choices=("contact_point", "yade"),
                    default="contact_point",
                    help="cpp_dem's sphere-sphere shear kinematics (Scene.shear_kinematics): its default, "
                         "or Yade's avoidGranularRatcheting formula, which the Yade side uses")
    ap.add_argument("--yade", default="yade")
    ap.add_argument("--dump-contacts-at", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    if shutil.which(args.yade) is None:
        print(f"error: --yade={args.yade}: not found (apt-get install yade)", file=sys.stderr)
        return 2
    sc, walls, tpl, (lo, hi) = build(args)
    if args.layout == "settled":
        # cpp_dem settles the cloud; a fresh scene takes the pile's clumps where they rest
        # (no velocities, no contact history), as Yade will.
        sc.run(args.settle)
        fresh, walls, _, _ = build(argparse.Namespace(**{**vars(args), "layout": "cloud"}))
        for c in range(sc.num_clumps):
            fresh.set_clump_state(c, sc.clump_positions[c], sc.clump_orientations[c],
                                  [0, 0, 0], [0, 0, 0])
        top0 = float((np.asarray(sc.positions)[:, 2] + np.asarray(sc.radii)).max())
        sc = fresh
        args.settle = 0
    if args.layout == "dense":
        sc, walls, lo, hi = dense_pack(sc, walls, args)
        args.settle = 0
    mem = members(sc)
    # Stage 1 settles; stage 2 starts with the top wall just above the highest member.
    if args.layout == "settled":
        pass
    elif args.layout == "dense":
        top0 = float(hi[2])
    elif args.layout == "cloud":
        probe, _, _, _ = build(argparse.Namespace(**vars(args)))
        probe.run(args.settle)
        top0 = float((np.asarray(probe.positions)[:, 2] + np.asarray(probe.radii)).max()) + 0.2e-3
    else:
        args.settle = 0
        top0 = float(hi[2])
    stages = [{"top_velocity": 0.0, "records": args.settle // args.every, "every": args.every}] if args.settle else []
    stages += [
              {"top_position": top0, "top_velocity": -args.speed,
               "records": args.press // args.every, "every": args.every}]
    ours = run_ours(sc, walls, stages)
    cfg = {"young": args.young, "poisson": 0.3, "density": 2650.0,
           "friction_rad": math.radians(args.friction), "box_lo": lo.tolist(),
           "box_hi": hi.tolist(), "clumps": mem,
           "damping": args.damping, "gravity": list(sc.gravity), "verlet": args.verlet,
           "dt": args.dt, "stages": stages, "dump_contacts_at": args.dump_contacts_at}
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "cfg.json")
        json.dump(cfg, open(path, "w"))
        p = subprocess.run([args.yade, "-n", "-j1", "-x", str(HERE / "yade_clumps.py"), path],
                           capture_output=True, text=True, timeout=3600)
    line = [l for l in p.stdout.splitlines() if l.startswith("YADE_RESULT ")]
    if not line:
        print(p.stdout[-3000:], p.stderr[-3000:], file=sys.stderr)
        return 1
    yade = json.loads(line[0][len("YADE_RESULT "):])
    if args.dump_contacts_at:
        sc.run(args.dump_contacts_at - sc.step_count)
        c = sc.contacts()
        print("OURS", sc.step_count)
        for ij, f, fn, nrm in zip(c["ids"], c["force"], c["normal_force"], c["normal"]):
            print("  ", ij.tolist(), np.round(f, 9).tolist())
        print("YADE")
        for a, b, fn, fs in yade["contacts"]:
            print("  ", [a, b], np.round(np.asarray(fn) + np.asarray(fs), 9).tolist())
    m_ours = np.asarray(sc.clump_masses)
    mass_diff = float(np.max(np.abs(np.asarray(yade["mass"]) / m_ours - 1)))
    i_ours = np.sort(np.asarray(sc.clump_inertias), axis=1)
    inertia_diff = float(np.max(np.abs(np.asarray(yade["inertia"]) / i_ours - 1)))
    rbar = float(np.mean(sc.radii))
    table = []
    for o, y in zip(ours, yade["rows"]):
        dc = np.linalg.norm(np.asarray(o["centres"]) - np.asarray(y["centres"]), axis=1).max() / rbar
        if os.environ.get("CLUMP_DEBUG"):
            print("DBG", o["step"], np.asarray(o["spins"])[0], np.asarray(y["spins"])[0])
        ft = abs(o["top_force"] - y["top_force"]) / max(abs(y["top_force"]), 1e-30)
        fb = abs(o["bottom_force"] - y["bottom_force"]) / max(abs(y["bottom_force"]), 1e-30)
        table.append({"step": o["step"], "top_force_ours_N": o["top_force"],
                      "top_force_yade_N": y["top_force"], "top_rel_diff": ft,
                      "bottom_force_ours_N": o["bottom_force"], "bottom_force_yade_N": y["bottom_force"],
                      "bottom_rel_diff": fb, "centre_diff_over_rbar": float(dc)})
    press = [t for t in table if t["step"] > args.settle and abs(t["top_force_yade_N"]) > 0]
    summary = {"rotation": args.rotation, "shear_kinematics": args.shear_kinematics, "clumps": args.clumps, "members": sc.num_bodies, "dt": args.dt,
               "mass_rel_diff": mass_diff, "inertia_rel_diff": inertia_diff,
               "weight_N": float(m_ours.sum() * 9.81),
               "settle_bottom_rel_diff_max": max((t["bottom_rel_diff"] for t in table if args.settle // 2 <= t["step"] <= args.settle), default=float("nan")),
               "press_top_rel_diff_max": max((t["top_rel_diff"] for t in press), default=float("nan")),
               "press_bottom_rel_diff_max": max((t["bottom_rel_diff"] for t in press), default=float("nan")),
               "centre_diff_over_rbar_max": max(t["centre_diff_over_rbar"] for t in table)}
    print("| step | top F ours (N) | top F Yade (N) | rel. diff | bottom F ours (N) | bottom F Yade (N) | rel. diff | max centre diff / r |")
    print("|---|---|---|---|---|---|---|---|")
    for t in table:
        print(f"| {t['step']} | {t['top_force_ours_N']:.5g} | {t['top_force_yade_N']:.5g} | {t['top_rel_diff']:.2e} | "
              f"{t['bottom_force_ours_N']:.5g} | {t['bottom_force_yade_N']:.5g} | {t['bottom_rel_diff']:.2e} | {t['centre_diff_over_rbar']:.2e} |")
    print(json.dumps(summary))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"summary": summary, "rows": table, "args": {k: str(v) for k, v in vars(args).items()}}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
