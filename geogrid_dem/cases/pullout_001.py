#!/usr/bin/env python3
"""Geogrid pull-out of 001 (chapter 5, Tables 5.1-5.4, App. A): a 10 cm cube, a square grid
(10 x 10 nodes, 1 cm openings, cylinders of radius 1 mm) or a triangular grid (equilateral,
1.43 cm sides, radius 0.5 mm) at mid-height, equal grains (r = 1, 1.5 or 2.5 mm; Table 5.1:
E = 5 MPa, nu = 0.3, rho = 2650 kg/m^3, phi = 20 deg), confinement 75 / 150 / 300 kPa on the
top wall, pulled at 0.06 m/s.

Stages (App. A): grains on a regular hexagonal lattice (gap r/2) outside the geogrid's
layer; grid held; radius growth to 10 kPa; top wall servo-controlled to the confining
stress, stabilised; pull towards -x. App. A blocks every grid node and gives it the pull
velocity (the grid moves as a rigid body; its E = 5 MPa cylinders could not carry the pull):
that is the default here (--pull all); --pull front clamps only the front row of nodes and
lets the grid deform. Recorded pull-out force: the sum of the reactions of all pulled nodes;
001 sums the 10 front nodes only (recorded too, as front_force).

--grains clumps:NAME fills the box with rigid clumps (docs/clumps.md) instead of the lattice
of spheres: as many clumps as the lattice has spheres, the grain radius as their
equivalent-volume radius, random seeded orientations in a loose cloud clear of the grid's
layer; the radius growth then packs them.

With --study the parameter table of 001 (Table 5.2) is run and summarised like Tables 5.3
(mean pull-out force) and 5.4 (coefficient of variation), beside 001's values: study.csv,
study.md, study.png.
"""

from __future__ import annotations

import csv
import math
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np


from cpp_dem.io.figures import save_figure
from geogrid_dem.cases import THESIS, describe
from cpp_dem import apply_threads
from geogrid_dem.options import case_parser, parse_checked
from geogrid_dem.rundir import run_main
import cpp_dem as dem  # noqa: E402
from cpp_dem.build import geogrid  # noqa: E402
from cpp_dem.protocols import prep
from cpp_dem.protocols import pullout
from cpp_dem.build.packing import hex_packing  # noqa: E402
from geogrid_dem.cases.grains_option import HELP as GRAINS_HELP, check_grains  # noqa: E402
from geogrid_dem.cases.pullout_common import (clump_layers, grain_label, make_logger,  # noqa: E402
                                          run_case)


#: 001 Table 5.3 (mean pull-out force, N) and 5.4 (coefficient of variation), by
#: (grid, radius m, pressure Pa). Table 5.4 gives no triangular values.
T53 = {("square", 2.5e-3, 75e3): 26.29, ("square", 1.5e-3, 75e3): 20.11,
       ("square", 1.0e-3, 75e3): 41.32, ("triangular", 2.5e-3, 75e3): 20.11,
       ("square", 2.5e-3, 150e3): 36.66, ("square", 1.5e-3, 150e3): 28.05,
       ("square", 1.0e-3, 150e3): 42.41, ("triangular", 2.5e-3, 150e3): 28.05,
       ("square", 2.5e-3, 300e3): 43.56, ("square", 1.5e-3, 300e3): 31.20,
       ("square", 1.0e-3, 300e3): 44.51, ("triangular", 2.5e-3, 300e3): 39.23}
T54 = {("square", 2.5e-3, 75e3): 0.543, ("square", 1.5e-3, 75e3): 0.445,
       ("square", 1.0e-3, 75e3): 0.242, ("square", 2.5e-3, 150e3): 0.434,
       ("square", 1.5e-3, 150e3): 0.381, ("square", 1.0e-3, 150e3): 0.234,
       ("square", 2.5e-3, 300e3): 0.413, ("square", 1.5e-3, 300e3): 0.406,
       ("square", 1.0e-3, 300e3): 0.230}


@dataclass
class Params:
    """Parameters of the 001 pull-out (SI)."""

    grid: str = "square"            #: square or triangular (001 §5.1)
    radius: float = 1.5e-3          #: grain radius, m (Table 5.2)
    pressure: float = 75e3          #: confining stress on the top wall, Pa (Table 5.2)
    box: float = 0.1                #: cube side, m
    young: float = 5e6              #: E, Pa (Table 5.1)
    poisson: float = 0.3            #: nu, - (Table 5.1)
    density: float = 2650.0         #: kg/m^3 (Table 5.1)
    phi: float = 20.0               #: contact friction angle, deg (Table 5.1)
    grid_young: float = 5e6         #: E of the grid material, Pa (Table 5.1: as the grains);
                                    #: with the rigid pull it sets only the contact stiffness
    growth_stress: float = 10e3     #: radius growth target, Pa (App. A: 10 kN/m^2)
    velocity: float = 0.06          #: pull velocity, m/s (001 §5.1)
    distance: float = 0.095         #: pull distance, m (001: total pull-out, 9.5 cm)
    pull: str = "all"               #: all (App. A: rigid grid) or front (clamped front row)
    damping: float = 0.3            #: Cundall local damping (App. A)
    dt_safety: float = 0.5          #: dt = safety x critical dt (App. A uses 0.7)
    record_every: int = 50
    snapshots: int = 3
    seed: int = 1
    threads: int = 0
    grains: str = "spheres"         #: spheres, or clumps:NAME (cases/grains_option.py); the
                                    #: radius is then the clumps' equivalent-volume radius


SMOKE = dict(radius=2.5e-3, box=0.05, distance=0.004, snapshots=1)


def grid_spec(p: Params) -> tuple[float, int]:
    """Cylinder radius (m) and nodes per side of the square grid scaled to the box."""
    rc = 1e-3 if p.grid == "square" else 0.5e-3
    return rc, max(3, int(round(10 * p.box / 0.1)))


def grains(p: Params) -> tuple[np.ndarray, np.ndarray]:
    """Centres and radii (m): the App. A lattice (gap r/2) with the grid's layer left empty."""
    c, r = hex_packing(np.zeros(3), np.full(3, p.box), p.radius, gap=p.radius / 2)
    keep = np.abs(c[:, 2] - 0.5 * p.box) > r + 1.5 * grid_spec(p)[0]
    return c[keep], r[keep]


def build(p: Params) -> pullout.PulloutSample:
    lo, hi = np.zeros(3), np.full(3, p.box)
    zg = 0.5 * p.box
    rc, n_nodes = grid_spec(p)
    c, r = grains(p)
    clumps = None
    if p.grains != "spheres":
        c, r, clumps = clump_layers(p.grains, r, lo, hi, grid_z=zg, clearance=1.5 * rc,
                                    seed=p.seed)
    grain = dem.linear_material(density=p.density, young=p.young, poisson=p.poisson,
                                friction_angle_deg=p.phi)

    def grid_builder(sc):
        gm = sc.add_material(dem.linear_material(density=p.density, young=p.grid_young,
                                                 poisson=p.poisson, friction_angle_deg=p.phi))
        beam = dem.BeamParams(young=p.grid_young, poisson=p.poisson, radius=rc,
                              normal_cohesion=1e7, shear_cohesion=1e7)  # App. A
        if p.grid == "square":
            sp = p.box / 10.0
            return geogrid.square_grid(sc, origin=(0.5 * sp, 0.5 * sp, zg),
                                       length=(n_nodes - 1) * sp, width=(n_nodes - 1) * sp,
                                       nodes_x=n_nodes, nodes_y=n_nodes, params=beam,
                                       material=gm, density=p.density)
        side = 0.0143
        h = side * math.sqrt(3) / 2
        nx = max(2, int(math.floor(p.box / side + 0.01)))
        ny = max(2, int(math.floor(0.87 * p.box / h + 0.01)))
        return geogrid.triangular_grid(sc, origin=(0.0, 0.5 * (p.box - ny * h), zg),
                                       length=nx * side, width=ny * h, side=side, params=beam,
                                       material=gm, density=p.density)

    return pullout.build_sample(c, r, lo, hi, grain=grain, grid_builder=grid_builder,
                                grid_z=zg, clamp=p.pull, local_damping=p.damping,
                                dt_safety=p.dt_safety,
                                max_overlap_ratio=prep.overlap_limit(p.pressure, p.young),
                                clumps=clumps)


def run(p: Params, out: Path) -> dict:
    apply_threads(p.threads)
    tag = f"pullout-001 {p.grid} r={p.radius * 1e3:g}mm P={p.pressure / 1e3:g}kPa" + (
        "" if p.grains == "spheres" else f" {p.grains}")
    log = make_logger(tag)
    sample = build(p)
    snaps = np.linspace(0, p.distance, p.snapshots + 1)[1:] if p.snapshots else []
    return run_case(sample, out, tag="pullout-001", meta={**asdict(p), "case": "001",
                                                         "study": THESIS},
                    prep_kwargs={"porosity": None, "growth_stress": p.growth_stress,
                                 "max_expansion_strain": 1e-4},
                    velocity=p.velocity, distance=p.distance, record_every=p.record_every,
                    snapshot_displacements=snaps, grain_density=p.density,
                    stress=p.pressure,
                    title=f"{THESIS}: pull-out, {p.grid} grid, {grain_label(sample)}, "
                          f"r = {p.radius * 1e3:g} mm, {p.pressure / 1e3:g} kPa", log=log)


def study(p: Params, out: Path, grids, radii, pressures, radii_given: bool) -> None:
    out.mkdir(parents=True, exist_ok=True)
    rows = read_study(out)  # earlier runs of the study in this directory stay in the table
    for g in grids:
        # 001 ran the triangular grid with r = 2.5 mm only (Table 5.3, last column).
        for r in (radii if g == "square" or radii_given else [2.5e-3]):
            for P in pressures:
                q = replace(p, grid=g, radius=r, pressure=P)
                sub = out / f"{g}_r{r * 1e3:g}mm_P{P / 1e3:g}kPa"
                t0 = time.perf_counter()
                try:
                    run(q, sub)
                    status = "ok"
                except dem.BlowUpError as e:  # keep the table going; say where it stopped
                    status = str(e).split(";")[0]
                    print(f"[pullout-001] {sub.name} STOPPED: {e}", flush=True)
                key = (g, r, P)
                rows = [x for x in rows if (x["grid"], x["radius_m"], x["pressure_Pa"]) != key]
                rec = pullout.read_record(sub / "pullout.csv")
                if not rec or len(rec.get("pull_force", ())) < 3:
                    rec = None  # stopped before the pull
                st = pullout.summarize(rec) if rec is not None else {
                    "mean_force_N": float("nan"), "cov_force": float("nan"),
                    "initial_peak_force_N": float("nan")}
                rows.append({"grid": g, "radius_m": r, "pressure_Pa": P,
                             "grains": len(grains(q)[1]),
                             "mean_force_N": st["mean_force_N"], "cov_force": st["cov_force"],
                             "mean_front_force_N": float(np.mean(rec["front_force"][1:]))
                             if rec is not None else float("nan"),
                             "initial_peak_force_N": st["initial_peak_force_N"],
                             "pulled_m": float(rec["displacement"][-1]) if rec is not None
                             else 0.0,
                             "mean_force_001_N": T53.get(key), "cov_001": T54.get(key),
                             "wall_time_s": time.perf_counter() - t0, "status": status})
                write_study(rows, out)


def read_study(out: Path) -> list:
    """Rows of an existing study.csv in ``out`` (numbers parsed; empty cells are None)."""
    f = out / "study.csv"
    if not f.is_file():
        return []
    rows = []
    with open(f, newline="") as fh:
        for r in csv.DictReader(fh):
            rows.append({k: (v if k in ("grid", "status") else
                             (None if v == "" else float(v))) for k, v in r.items()})
    return rows


def write_study(rows: list, out: Path) -> None:
    rows = sorted(rows, key=lambda r: (r["grid"] != "square", -r["radius_m"],
                                       r["pressure_Pa"]))
    with open(out / "study.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = ["| grid | r (mm) | P (kPa) | grains | pulled (mm) | mean F (N) | thesis T5.3 (N) | "
             "CoV | thesis T5.4 | mean F, front row only (N) | wall time (s) | status |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        def f(v, fmt):
            return "—" if v is None else format(v, fmt)
        lines.append(f"| {r['grid']} | {r['radius_m'] * 1e3:g} | {r['pressure_Pa'] / 1e3:g} | "
                     f"{r['grains']:.0f} | {1e3 * r['pulled_m']:.1f} | {r['mean_force_N']:.2f} | {f(r['mean_force_001_N'], '.2f')}"
                     f" | {r['cov_force']:.3f} | {f(r['cov_001'], '.3f')} | "
                     f"{r['mean_front_force_N']:.2f} | {r['wall_time_s']:.0f} | {r['status']} |")
    (out / "study.md").write_text("\n".join(lines) + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    keys = sorted({(r["grid"], r["radius_m"]) for r in rows})
    for g, rad in keys:
        sel = sorted((r for r in rows if r["grid"] == g and r["radius_m"] == rad),
                     key=lambda r: r["pressure_Pa"])
        P = [r["pressure_Pa"] / 1e3 for r in sel]
        lab = f"{g}, r = {rad * 1e3:g} mm"
        ln = ax[0].plot(P, [r["mean_force_N"] for r in sel], "o-", label=lab)[0]
        ref = [r["mean_force_001_N"] for r in sel]
        if all(v is not None for v in ref):
            ax[0].plot(P, ref, "x--", color=ln.get_color(), label=lab + " (thesis)")
        ax[1].plot(P, [r["cov_force"] for r in sel], "o-", color=ln.get_color(), label=lab)
        ref = [r["cov_001"] for r in sel]
        if all(v is not None for v in ref):
            ax[1].plot(P, ref, "x--", color=ln.get_color(), label=lab + " (thesis)")
    ax[0].set_ylabel("mean pull-out force (N)")
    ax[1].set_ylabel("coefficient of variation (-)")
    for a in ax:
        a.set_xlabel("confining stress (kPa)")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "study.png")
    plt.close(fig)


def _floats(name, s, ap, lo=0.0):
    try:
        v = [float(x) for x in s.split(",")]
    except ValueError:
        ap.error(f"{name}={s!r}: expected a number or a comma list")
    for x in v:
        if not (math.isfinite(x) and x > lo):
            ap.error(f"{name}={x}: must be > {lo}")
    return v


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    d = Params()
    ap = case_parser(
        "pullout-001", describe("pullout-001", "Geogrid pull-out of the thesis's chapter 5 "
                                "(its Appendix A script). x is the pull direction; SI units; "
                                "stresses compressive positive."),
        smoke="r = 2.5 mm in a 5 cm cube, pull 4 mm", seed=d.seed,
        out_help="; --study keeps its table in --out and each point in a sub-folder (a point "
                 "run before needs --overwrite)")
    ap.add_argument("--grid", choices=("square", "triangular"), default=d.grid,
                    help="geogrid shape")
    ap.add_argument("--radius", type=str, default=None,
                    help=f"grain radius, m (default {d.radius}); a comma list with --study")
    ap.add_argument("--pressure", type=str, default=None,
                    help=f"confining stress, Pa (default {d.pressure}); a list with --study")
    ap.add_argument("--velocity", type=float, default=d.velocity, help="pull velocity, m/s")
    ap.add_argument("--distance", type=float, default=None,
                    help=f"pull distance, m (default {d.distance})")
    ap.add_argument("--pull", choices=("all", "front"), default=d.pull,
                    help="pull every grid node (as the thesis's Appendix A) or only the front row")
    ap.add_argument("--damping", type=float, default=d.damping, help="local damping, [0, 1)")
    ap.add_argument("--grid-young", type=float, default=d.grid_young,
                    help="E of the grid material, Pa (the thesis's Table 5.1: 5e6, as the grains); with "
                         "the rigid pull it only sets the grain-grid contact stiffness")
    ap.add_argument("--study", action="store_true",
                    help="run the grid x radius x pressure table (Table 5.2) and summarise it "
                         "like Tables 5.3-5.4; --grids, --radius and --pressure select")
    ap.add_argument("--grids", type=str, default="square,triangular",
                    help="grids of the study (comma list)")
    ap.add_argument("--grains", type=str, default=d.grains, help=GRAINS_HELP)
    return ap


def parse_args(argv=None):
    ap = build_parser()
    a = parse_checked(ap, argv)
    check_grains(ap, a.grains)
    p = Params(**SMOKE) if a.smoke else Params()
    radii = _floats("--radius", a.radius, ap) if a.radius else [p.radius]
    pressures = _floats("--pressure", a.pressure, ap) if a.pressure else [p.pressure]
    if not a.study and (len(radii) > 1 or len(pressures) > 1):
        ap.error("--radius/--pressure: lists need --study")
    if a.study and not a.radius:
        radii = [2.5e-3, 1.5e-3, 1.0e-3]
    if a.study and not a.pressure:
        pressures = [75e3, 150e3, 300e3]
    for r in radii:
        if r > p.box / 8:
            ap.error(f"--radius={r}: must be <= box/8 = {p.box / 8} m")
    grids = [g.strip() for g in a.grids.split(",")]
    for g in grids:
        if g not in ("square", "triangular"):
            ap.error(f"--grids: {g!r} is not square or triangular")
    if not (math.isfinite(a.velocity) and a.velocity > 0):
        ap.error(f"--velocity={a.velocity}: must be > 0 (m/s)")
    if not (0 <= a.damping < 1):
        ap.error(f"--damping={a.damping}: must be in [0, 1)")
    if not (math.isfinite(a.grid_young) and a.grid_young > 0):
        ap.error(f"--grid-young={a.grid_young}: must be > 0 (Pa)")
    p = replace(p, grid=a.grid, radius=radii[0], pressure=pressures[0], velocity=a.velocity,
                grid_young=a.grid_young,
                pull=a.pull, damping=a.damping, seed=a.seed, threads=a.threads,
                grains=a.grains)
    if a.distance is not None:
        if not (math.isfinite(a.distance) and a.distance > 0):
            ap.error(f"--distance={a.distance}: must be > 0 (m)")
        if a.distance >= p.box:
            ap.error(f"--distance={a.distance}: must be < the box side {p.box} m (the grid "
                     f"would leave the box); at --velocity {a.velocity:g} m/s that is "
                     f"{a.distance / a.velocity:.3g} s of pull")
        p = replace(p, distance=a.distance)
    return p, a.out, a.study, grids, radii, pressures, bool(a.radius)


def main(argv=None) -> int:
    p, out, is_study, grids, radii, pressures, radii_given = parse_args(argv)
    if is_study:
        return run_main("pullout_001", out,
                        lambda o: study(p, o, grids, radii, pressures, radii_given),
                        own_folder=False)
    return run_main("pullout_001", out, lambda o: run(p, o))


if __name__ == "__main__":
    sys.exit(main())
