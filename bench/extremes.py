"""Stability at the extremes (issue 7), beyond what the quick tests cover. Not a test: each
scenario prints one JSON line with its status ("ok" or the BlowUpError text), the energy
balance error of the measured stage, the wall time and what matters for it.

    .venv/bin/python bench/extremes.py [--only NAME ...] [--threads N]

Scenarios: dt factors 0.5/0.9/1.0/1.2 of the estimate on a confined dense packing;
confinement 300 kPa and 1 MPa; friction 0 and 60 deg in a short triaxial; PSD span 1:20;
grains of 0.5 mm (a 1 x 1 x 2 cm column of the 10 cm box); geogrid/grain stiffness ratios
4e3 (000) and 1e5 in the smoke pull-out of 000. docs/extremes.md has the table.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem import measure
from cpp_dem.protocols import prep
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import build_box_sample, deviatoric_stage, isotropic_stage
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

ROOT = Path(__file__).resolve().parents[1]


def emit(name: str, **kw) -> dict:
    row = {"scenario": name, **kw}
    print(json.dumps(row, default=float), flush=True)
    return row


def energy_error(sc) -> float:
    return float(sc.energies()["balance_error_relative"])


def box_sample(n: int, *, young=4.5e6, phi=32.0, seed=1, side=None):
    """n equal-volume-ish grains (r 4-6 mm) in a cube, as a loose cloud."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.004, 0.006, n)
    side = side or (np.sum(4 / 3 * np.pi * r**3) / 0.25) ** (1 / 3)
    c, r = loose_cloud(r, (0, 0, 0), (side,) * 3, seed=seed)
    return build_box_sample(c, r, (0, 0, 0), (side,) * 3, young=young, poisson=0.3,
                            friction_deg=phi, density=2650.0, local_damping=0.2)


def dt_factors():
    base = box_sample(600)
    sc = base.scene
    sc.max_overlap_ratio = 0.95
    isotropic_stage(base, 100e3, max_steps=100_000)
    pos, rad = sc.positions.copy(), sc.radii.copy()
    lo = np.array([sc.wall_positions[base.walls[2 * a]] for a in range(3)])
    hi = np.array([sc.wall_positions[base.walls[2 * a + 1]] for a in range(3)])
    for f in (0.5, 0.9, 1.0, 1.2):
        s2 = build_box_sample(pos, rad, lo, hi, young=4.5e6, poisson=0.3, friction_deg=32,
                              density=2650.0, local_damping=0.0)
        s2.scene.set_auto_timestep(safety=0.5, period=0)
        s2.scene.run(1)
        s2.scene.dt = f * s2.scene.critical_dt()  # fixed: the dt check watches it
        s2.scene.track_energy = True
        t0 = time.perf_counter()
        try:
            s2.scene.run(20_000)
            status = "ok"
        except dem.BlowUpError as e:
            status = str(e)
        emit(f"dt_factor_{f}", status=status, balance_error=energy_error(s2.scene),
             steps=s2.scene.step_count, wall_s=time.perf_counter() - t0,
             note="undamped confined packing (100 kPa), dt = factor x the estimate at the start")


def confinement():
    for p in (300e3, 1e6):
        s = box_sample(800)
        s.scene.max_overlap_ratio = prep.overlap_limit(p, 4.5e6)
        s.scene.track_energy = True
        t0 = time.perf_counter()
        try:
            res = isotropic_stage(s, p, max_steps=200_000)
            ov = prep.overlap_report(s.scene, s.walls)
            emit(f"confinement_{p / 1e3:g}kPa", status="ok", converged=res.converged,
                 axis_stresses_Pa=res.axis_stresses.tolist(), porosity=res.porosity,
                 max_overlap_ratio=max(ov["pair"], ov["wall"]),
                 balance_error=energy_error(s.scene), steps=s.scene.step_count,
                 wall_s=time.perf_counter() - t0, note="E = 4.5 MPa linear grains")
        except dem.BlowUpError as e:
            emit(f"confinement_{p / 1e3:g}kPa", status=str(e), wall_s=time.perf_counter() - t0)


def friction():
    for phi in (0.0, 60.0):
        s = box_sample(800, phi=phi)
        t0 = time.perf_counter()
        try:
            isotropic_stage(s, 100e3, max_steps=200_000)
            s.scene.track_energy = True
            s.scene.reset_energy()
            rows = deviatoric_stage(s, 100e3, 1.0, 0.05, record_every=200)
            emit(f"friction_{phi:g}deg", status="ok",
                 q_peak_Pa=float(rows["deviatoric_stress"].max()),
                 balance_error=energy_error(s.scene), steps=s.scene.step_count,
                 wall_s=time.perf_counter() - t0)
        except dem.BlowUpError as e:
            emit(f"friction_{phi:g}deg", status=str(e), wall_s=time.perf_counter() - t0)


def _deposition(name, radii, box, seed=1, max_time=0.4, note=""):
    c, r = loose_cloud(radii, (0, 0, 0), box, seed=seed)
    s = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.2)
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    walls = s.add_box((0, 0, 0), box, material=m)
    s.add_spheres(c, r, material=m)
    s.set_auto_timestep(safety=0.5, period=100)
    s.track_energy = True
    t0 = time.perf_counter()
    try:
        while s.time < max_time:
            s.run(1000)
        v = float(np.linalg.norm(s.velocities, axis=1).max())
        ov = prep.overlap_report(s, walls)
        emit(name, status="ok", grains=len(r), steps=s.step_count, dt_s=s.dt,
             max_speed_m_s=v, max_overlap_ratio=max(ov["pair"], ov["wall"]),
             balance_error=energy_error(s), wall_s=time.perf_counter() - t0,
             particle_steps_per_s=len(r) * s.step_count / (time.perf_counter() - t0), note=note)
    except dem.BlowUpError as e:
        emit(name, status=str(e), wall_s=time.perf_counter() - t0)


def psd_span():
    rng = np.random.default_rng(2)
    r = 0.01 * 20.0 ** (-rng.random(4000))  # log-uniform, 0.5 to 10 mm (1:20)
    _deposition("psd_span_1_20", r, (0.12, 0.12, 0.3), note="log-uniform radii 0.5-10 mm")


def tiny_grains():
    r = np.full(6000, 0.25e-3)  # d = 0.5 mm
    _deposition("grains_0.5mm", r, (0.01, 0.01, 0.03), max_time=0.08,
                note="d = 0.5 mm, a 1 x 1 x 3 cm column of the 10 cm box")


def stiffness_ratio():
    sys.path.insert(0, str(ROOT / "cases"))
    import pullout_000 as case  # noqa: E402
    from cpp_dem.protocols import pullout

    for ratio in (4e3, 1e5):
        p = replace(case.Params(**case.SMOKE), grid_young=1e6 * ratio)
        t0 = time.perf_counter()
        try:
            sample = case.build(p)
            pullout.prepare(sample, stress=p.pressure, porosity=p.porosity,
                            node_density_scale="auto")
            sc = sample.scene
            sc.track_energy = True
            sc.reset_energy()
            rec = pullout.pull(sample, velocity=p.velocity, distance=0.005, record_every=100)
            emit(f"grid_stiffness_ratio_{ratio:g}", status="ok",
                 node_density_scale=sample.node_density_scale, dt_s=sc.dt,
                 pull_force_at_5mm_N=float(rec["pull_force"][-1]),
                 balance_error=energy_error(sc), steps=sc.step_count,
                 wall_s=time.perf_counter() - t0, note="000 smoke pull-out, 5 mm")
        except dem.BlowUpError as e:
            emit(f"grid_stiffness_ratio_{ratio:g}", status=str(e),
                 wall_s=time.perf_counter() - t0)


SCENARIOS = {"dt": dt_factors, "confinement": confinement, "friction": friction,
             "psd": psd_span, "tiny": tiny_grains, "stiffness": stiffness_ratio}


def main(argv=None) -> int:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", nargs="*", choices=sorted(SCENARIOS), default=None)
    ap.add_argument("--threads", type=int, default=0)
    a = ap.parse_args(argv)
    if a.threads:
        dem.set_num_threads(a.threads)
    for name in a.only or SCENARIOS:
        SCENARIOS[name]()
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
