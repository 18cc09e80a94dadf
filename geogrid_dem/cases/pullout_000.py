#!/usr/bin/env python3
"""Geogrid pull-out of the pull-out paper (000 §2.3, §3, Table 1): a 1.0 x 0.5 x 0.5 m box, a
flat-ribbed biaxial geogrid (80 mm apertures, 10 mm ribs, 2 mm thick, E = 4 GPa) at
mid-height, 3000 / 6000 / 9000 spheres (E = 1 MPa, nu = 0.5, unit weight 25.5 kN/m^3,
phi = 30 deg, initial radius 12 +- 6 mm) grown by REFD around the held geogrid to the
confining stress.

Stages: grains in two loose layers, geogrid held; REFD with frictionless walls (expansion at
phi = 30 deg, friction lowered until the target porosity, friction restored); geogrid freed,
gravity on, top wall servo-controlled to the confining stress, stabilised; the clamp (the
front transverse rib) pulled towards -x at constant velocity while the top wall holds the
stress. The paper states neither the confining stress nor the pull rate nor the porosity:
the defaults here (25 kPa, 0.01 m/s, 0.35) are ours, see docs/pullout.md.

The geogrid is 4000 times stiffer than the grains: with true masses its critical time step
is about 1e-7 s. Its node masses are scaled (--node-density-scale, default auto: the grid's
step becomes a quarter of the grains') while its weight stays true; docs/pullout.md gives
the effect on the results.

--grains clumps:NAME fills the box with rigid clumps (docs/clumps.md) instead of spheres: the
same radii as equivalent-volume radii, random seeded orientations; NAME as in the triaxial
case (a shipped grain or a template CSV x,y,z,r in m). --spheres then counts clumps.

Outputs in --out (per run): pullout.h5 (series + snapshots with member forces), pullout.csv,
pullout_force.png (000 Fig. 5), pullout_members.png (Figs 7-8), vtk/ (spheres, contacts,
geogrid with member forces, box; PVD series over the snapshots), packing_prepared.csv (the
grains' spheres after the preparation; with clumps also clumps_prepared.csv), summary.json.
With several --spheres values: one sub-directory per count and comparison.png +
comparison.csv. Interrupted (Ctrl-C, SIGTERM), a run leaves summary.json marked
"interrupted" with the stages it finished and the pull so far, and the figures of that pull;
with several counts, the counts that finished and their comparison (docs/output.md).
"""

from __future__ import annotations

import csv
import math
import sys
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np


from cpp_dem.io.figures import save_figure
from geogrid_dem.cases import PULLOUT_PAPER, describe
from cpp_dem import apply_threads
from geogrid_dem.options import (case_parser, check_cap, distinct, given_options,
                                 parse_checked, refuse_unused, warn_below)
from geogrid_dem.rundir import on_interrupt, run_main
import cpp_dem as dem  # noqa: E402
from cpp_dem import presets  # noqa: E402
from cpp_dem.build import geogrid
from cpp_dem.protocols import prep
from cpp_dem.protocols import pullout
from geogrid_dem.cases.grains_option import HELP as GRAINS_HELP, check_grains  # noqa: E402
from geogrid_dem.cases.pullout_common import (clump_layers, grain_label, make_logger,  # noqa: E402
                                          run_case)



@dataclass
class Params:
    """Parameters of the pull-out paper's pull-out (SI)."""

    spheres: int = 3000                 #: number of grains (spheres, or clumps), -
    box: tuple = (1.0, 0.5, 0.5)        #: box x (pull), y, z, m (Table 1)
    radius_mean: float = 0.012          #: initial mean radius, m (Table 1)
    radius_dispersion: float = 0.006    #: initial radius spread +-, m (Table 1)
    young: float = 1e6                  #: grain E, Pa (Table 1)
    poisson: float = 0.5                #: grain nu (k_s / k_n), - (Table 1)
    unit_weight: float = 2.55e4         #: grain unit weight, N/m^3 (Table 1)
    phi: float = 30.0                   #: grain contact friction angle, deg (Table 1)
    grid_young: float = 4e9             #: geogrid E, Pa (Table 1)
    grid_poisson: float = 0.3           #: geogrid nu, - (Table 1)
    grid_thickness: float = 2e-3        #: geogrid thickness 2 R_c, m (Table 1)
    grid_unit_weight: float = 981.0     #: geogrid unit weight, N/m^3 (Table 1)
    grid_phi: float = 20.0              #: geogrid contact friction angle, deg (Table 1)
    aperture_area: float = 6.4e-3       #: clear aperture area, m^2 (Table 1)
    rib_width: float = 0.01             #: rib width, m (ours; 000 Fig. 3 shows flat ribs)
    pressure: float = 25e3              #: confining stress, Pa (ours; 000 does not give it)
    porosity: float = 0.35              #: REFD target porosity, - (ours; "minimum porosity")
    velocity: float = 0.01              #: pull velocity, m/s (ours)
    distance: float = 0.1               #: pull distance, m (ours)
    damping: float = 0.2                #: Cundall local damping, - (Yade's default)
    dt_safety: float = 0.5              #: dt = safety x critical dt, -
    node_density_scale: str = "auto"    #: grid node mass factor, or 'auto'
    record_every: int = 50              #: steps between records
    snapshots: int = 4                  #: VTK/HDF5 snapshots over the pull
    seed: int = 1
    threads: int = 0
    preset: str = ""                    #: speed-accuracy preset for the pull ('' = none)
    grains: str = "spheres"             #: spheres, or clumps:NAME (a shipped grain gravel_a ..
                                        #: gravel_d, 'gravel' for the four mixed, or a
                                        #: template CSV x,y,z,r in m); the radii are then
                                        #: the clumps' equivalent-volume radii


SMOKE = dict(spheres=375, box=(0.5, 0.25, 0.25), distance=0.01, snapshots=2)

def build(p: Params) -> pullout.PulloutSample:
    lo = np.zeros(3)
    hi = np.asarray(p.box, float)
    rng = np.random.default_rng(p.seed)
    radii = rng.uniform(p.radius_mean - p.radius_dispersion,
                        p.radius_mean + p.radius_dispersion, p.spheres)
    zg = 0.5 * hi[2]
    rc = 0.5 * p.grid_thickness
    clumps = None
    if p.grains != "spheres":
        c, r, clumps = clump_layers(p.grains, radii, lo, hi, grid_z=zg, clearance=1.5 * rc,
                                    seed=p.seed)
    else:
        c, r = pullout.layered_cloud(radii, lo, hi, grid_z=zg, clearance=1.5 * rc,
                                     seed=p.seed)
    pitch = math.sqrt(p.aperture_area) + p.rib_width
    nx = int(math.floor((hi[0] - p.rib_width) / pitch + 1e-9))
    ny = int(math.floor((hi[1] - p.rib_width) / pitch + 1e-9))
    if nx < 3 or ny < 1:
        raise SystemExit(f"error: box {p.box} m holds {nx} x {ny} apertures of pitch "
                         f"{pitch} m; need at least 3 along x")
    y0 = 0.5 * (hi[1] - (ny * pitch + p.rib_width)) + 0.5 * p.rib_width
    grain = dem.linear_material(density=p.unit_weight / geogrid.G_STANDARD, young=p.young,
                                poisson=p.poisson, friction_angle_deg=p.phi)

    def grid_builder(sc):
        gm = sc.add_material(dem.linear_material(
            density=p.grid_unit_weight / geogrid.G_STANDARD, young=p.grid_young,
            poisson=p.grid_poisson, friction_angle_deg=p.grid_phi))
        beam = dem.BeamParams(young=p.grid_young, poisson=p.grid_poisson, radius=rc,
                              normal_cohesion=0.0, shear_cohesion=0.0)  # 000: no breakage
        return geogrid.biaxial_geogrid(sc, origin=(0.5 * p.rib_width, y0, zg), apertures_x=nx,
                                       apertures_y=ny, aperture_area=p.aperture_area,
                                       rib_width=p.rib_width, params=beam, material=gm,
                                       unit_weight=p.grid_unit_weight)

    # E = 1 MPa grains at tens of kPa overlap by design (prep.overlap_limit).
    return pullout.build_sample(c, r, lo, hi, grain=grain, grid_builder=grid_builder,
                                grid_z=zg, clamp_depth=p.rib_width, clamp="front",
                                local_damping=p.damping, dt_safety=p.dt_safety,
                                max_overlap_ratio=prep.overlap_limit(p.pressure, p.young),
                                clumps=clumps)


def run(p: Params, out: Path) -> dict:
    apply_threads(p.threads)
    log = make_logger(f"pullout-000 n={p.spheres}"
                      + ("" if p.grains == "spheres" else f" {p.grains}"))
    sample = build(p)
    nds = p.node_density_scale if p.node_density_scale == "auto" else float(
        p.node_density_scale)
    snaps = np.linspace(0, p.distance, p.snapshots + 1)[1:] if p.snapshots else []
    before_pull = None
    if p.preset:
        ps = presets.preset(p.preset)
        p = replace(p, velocity=ps.velocity(density=p.unit_weight / geogrid.G_STANDARD,
                                            stress=p.pressure))
        log(f"preset {p.preset!r} for the pull: dt safety {ps.dt_safety}, node density scale "
            f"{ps.node_density_scale}, damping {ps.local_damping}, I = {ps.inertial_number} "
            f"-> {p.velocity:.4g} m/s")

        def before_pull(sample):
            pullout.apply_preset(sample, p.preset)
    return run_case(sample, out, tag="pullout-000",
                    meta={**asdict(p), "case": "000", "study": PULLOUT_PAPER},
                    prep_kwargs={"porosity": p.porosity, "node_density_scale": nds},
                    velocity=p.velocity, distance=p.distance, record_every=p.record_every,
                    snapshot_displacements=snaps,
                    grain_density=p.unit_weight / geogrid.G_STANDARD, stress=p.pressure,
                    title=f"{PULLOUT_PAPER}: {grain_label(sample)}, "
                          f"{p.pressure / 1e3:g} kPa, {p.velocity:.4g} m/s", log=log,
                    before_pull=before_pull)


def compare(runs: dict, out: Path) -> None:
    """000 Fig. 5 with one curve per sphere count, and the table of the report."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpp_dem.io import read_csv_series

    fig, ax = plt.subplots(figsize=(7, 4.2))
    rows = []
    for n, (sub, s) in runs.items():
        rec = read_csv_series(sub / "pullout.csv")
        ax.plot(1e3 * rec["displacement"], rec["pull_force"],
                label=f"{n} {'spheres' if s.get('num_clumps', 0) == 0 else 'clumps'}")
        rows.append({"spheres": n, **{k: s[k] for k in (
            "initial_peak_force_N", "initial_peak_displacement_m", "max_force_N",
            "mean_force_N", "cov_force", "transverse_over_longitudinal",
            "transverse_peak_over_mean", "porosity_prepared", "wall_time_total_s")}})
    ax.set_xlabel("front displacement (mm)")
    ax.set_ylabel("pull-out force (N)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    save_figure(fig, out / "comparison.png")
    plt.close(fig)
    with open(out / "comparison.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    for r in rows:
        print("[pullout-000] " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else
                                           f"{k}={v}" for k, v in r.items()), flush=True)


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    d = Params()
    ap = case_parser(
        "pullout-000", describe("pullout-000", "Geogrid pull-out with the paper's Table 1 "
                                "parameters. x is the pull direction (the clamp moves towards "
                                "-x); SI units."),
        smoke=f"{SMOKE['spheres']} spheres in a half-size box (0.5 x 0.25 x 0.25 m), pull "
              f"{SMOKE['distance'] * 1e3:g} mm", seed=d.seed,
        preset="for the pull (dt safety, node density scale, damping, rate as an inertial "
               "number; overrides --velocity)",
        out_help="; with several --spheres, one sub-folder n<N> each")
    ap.add_argument("--spheres", type=str, default=None,
                    help=f"number of grains (spheres, or clumps with --grains clumps:...), or "
                         f"a comma list (e.g. 3000,6000,9000) to run each and compare "
                         f"(default {d.spheres})")
    ap.add_argument("--grains", type=str, default=d.grains, help=GRAINS_HELP)
    ap.add_argument("--pressure", type=float, default=d.pressure,
                    help="confining stress on the top wall, Pa, > 0")
    ap.add_argument("--porosity", type=float, default=d.porosity,
                    help="REFD target porosity, (0, 1)")
    ap.add_argument("--velocity", type=float, default=d.velocity, help="pull velocity, m/s")
    ap.add_argument("--distance", type=float, default=None,
                    help=f"pull distance, m (default {d.distance})")
    ap.add_argument("--damping", type=float, default=d.damping, help="local damping, [0, 1)")
    ap.add_argument("--dt-safety", type=float, default=d.dt_safety,
                    help="time step as a fraction of the critical one, (0, 1]")
    ap.add_argument("--node-density-scale", type=str, default=d.node_density_scale,
                    help="geogrid node mass factor (>= 1), or 'auto'")
    ap.add_argument("--snapshots", type=int, default=None,
                    help=f"VTK/HDF5 snapshots over the pull (default {d.snapshots})")
    return ap


def parse_args(argv=None) -> tuple[Params, list[int], Path]:
    ap = build_parser()
    a = parse_checked(ap, argv)
    given = given_options(ap, argv)
    p = Params(**SMOKE) if a.smoke else Params()
    counts = [p.spheres]
    if a.spheres is not None:
        try:
            counts = [int(x) for x in a.spheres.split(",")]
        except ValueError:
            ap.error(f"--spheres={a.spheres!r}: expected an integer or a comma list")
        if any(n < 50 for n in counts):
            ap.error(f"--spheres={a.spheres}: each count must be >= 50")
        # (each count runs into its folder n<N>: one listed twice would run over itself)
        distinct(ap, "--spheres", a.spheres, counts)
        check_cap(ap, a, "--spheres", a.spheres, max(counts), "grains",
                  "grains in the largest run")
        check_cap(ap, a, "--spheres", a.spheres, len(counts), "elements or runs", "runs")
    if a.preset:
        refuse_unused(ap, a, given, "velocity", f"with --preset {a.preset} (the preset sets "
                      "the pull velocity from its inertial number)")
    checks = [("--pressure", a.pressure, a.pressure > 0, "> 0 (Pa)"),
              ("--porosity", a.porosity, 0 < a.porosity < 1, "in (0, 1)"),
              ("--velocity", a.velocity, a.velocity > 0, "> 0 (m/s)"),
              ("--damping", a.damping, 0 <= a.damping < 1, "in [0, 1)"),
              ("--dt-safety", a.dt_safety, 0 < a.dt_safety <= 1, "in (0, 1]")]
    for name, v, ok, allowed in checks:
        if not (math.isfinite(v) and ok):
            ap.error(f"{name}={v}: must be {allowed}")
    if a.node_density_scale != "auto":
        try:
            s = float(a.node_density_scale)
        except ValueError:
            s = float("nan")
        if not (math.isfinite(s) and s > 0):
            ap.error(f"--node-density-scale={a.node_density_scale!r}: must be a number > 0 "
                     "or 'auto'")
    check_grains(ap, a.grains)
    p = replace(p, pressure=a.pressure, porosity=a.porosity, velocity=a.velocity,
                damping=a.damping, dt_safety=a.dt_safety,
                node_density_scale=a.node_density_scale, seed=a.seed, threads=a.threads,
                preset=a.preset, grains=a.grains)
    if a.distance is not None:
        if not (math.isfinite(a.distance) and a.distance > 0):
            ap.error(f"--distance={a.distance}: must be > 0 (m)")
        if a.distance >= p.box[0]:
            ap.error(f"--distance={a.distance}: must be < the box length {p.box[0]} m (the "
                     "geogrid would be pulled out of the box); at --velocity "
                     f"{p.velocity:g} m/s that is {a.distance / p.velocity:.3g} s of pull")
        p = replace(p, distance=a.distance)
    if a.snapshots is not None:
        if a.snapshots < 0:
            ap.error(f"--snapshots={a.snapshots}: must be >= 0")
        # (each snapshot writes the grains and the grid, HDF5 and VTK: 3000 of a smoke run
        # are 4000 files and 420 MB)
        check_cap(ap, a, "--snapshots", a.snapshots, a.snapshots, "snapshots",
                  "snapshots over the pull")
        p = replace(p, snapshots=a.snapshots)
    warn_below("--pressure", a.pressure, 1e3, "Pa",
               f"kPa given as Pa? {a.pressure:g} kPa is --pressure {a.pressure * 1e3:g}")
    return p, counts, a.out


def main(argv=None) -> int:
    p, counts, out = parse_args(argv)

    def work(out: Path) -> None:
        if len(counts) == 1:
            run(replace(p, spheres=counts[0]), out)
            return
        runs = {}
        # interrupted: the counts that finished, and their comparison
        on_interrupt(out, summary=lambda: {"finished": [f"n{n}" for n in runs],
                                           "spheres": counts},
                     figures=lambda: compare(runs, out) if runs else None)
        for n in counts:
            sub = out / f"n{n}"
            runs[n] = (sub, run(replace(p, spheres=n), sub))
        compare(runs, out)

    return run_main("pullout_000", out, work)


if __name__ == "__main__":
    sys.exit(main())
