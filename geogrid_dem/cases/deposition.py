#!/usr/bin/env python3
"""Gravity deposition of polydisperse spheres into a box — the main demo of ``cpp_dem``.

A loose, jittered lattice of spheres (radii uniform in [r_min, r_max], seeded RNG) starts in
the upper part of a box and settles on its floor under gravity with the linear Cundall–Strack
law (000 eqs 1–6; grain modulus E = 1 MPa as 000's grains), Coulomb friction, rolling
resistance (so that grains on the free surface stop rolling) and Cundall local damping. The
time step comes from ``scene.set_auto_timestep``; the run stops once the packing is at rest
(or at ``--duration``). Energy bookkeeping is on and its balance error is reported.

Outputs in ``--out DIR`` (default a new folder ``results/deposition/run_NNN`` per run):

- ``deposition.h5``  time series (``/series/*``) and snapshots (``/snapshots/NNNNNN``), run
  parameters as root attributes (``cpp_dem.io.H5Recorder``; layout in docs/output.md);
- ``deposition.csv`` the same time series as CSV (``cpp_dem.io.CsvRecorder``);
- ``vtk/spheres_NNNN.vtp``, ``vtk/contacts_NNNN.vtp`` per snapshot, ``vtk/box.vtp``, and the
  ParaView time series ``deposition.pvd`` (spheres), ``contacts.pvd`` (force network) and
  ``box.pvd`` (the walls, which do not move here: one entry);
- ``energies.png``   energy terms and balance error over time;
- ``packing.csv``    the settled packing, columns x,y,z,r (m) (``cpp_dem.write_packing_csv``);
- ``summary.json``   the numbers printed at the end.

Run ``python cases/deposition.py`` (about 3000 spheres) or ``--smoke`` (a few hundred, a few
seconds). SI units throughout.
"""

from __future__ import annotations

import json
import math
import platform
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from cpp_dem.io.figures import save_figure
from geogrid_dem.provenance import git_revision
from geogrid_dem.cases import describe
from cpp_dem import apply_threads
from geogrid_dem.options import case_parser, check_cap, parse_checked
from geogrid_dem.rundir import begin_run, run_main
import cpp_dem as dem
from cpp_dem.measure import interior_porosity, slab_solid_volume, surface_height
from cpp_dem.io import (CsvRecorder, H5Recorder, PvdWriter, read_h5_series,
                            standard_series, write_vtk_box, write_vtk_contacts,
                            write_vtk_spheres)



@dataclass
class Params:
    """Parameters of the deposition (SI)."""

    n: int = 3000                    #: number of spheres, -
    seed: int = 1                    #: RNG seed, -
    r_min: float = 0.002             #: smallest radius, m
    r_max: float = 0.003             #: largest radius, m
    box: tuple = (0.1, 0.1, 0.3)     #: box size x, y, z, m (the box spans [0, box])
    gap: float = 0.2                 #: lattice spacing = 2 r_max (1 + gap), -
    density: float = 2600.0          #: grain density, kg/m^3
    young: float = 1e6               #: Young's modulus of the linear law, Pa (000's grains)
    poisson: float = 0.3             #: k_s / k_n of the linear law (000 eq 5), -
    friction_angle_deg: float = 30.0  #: contact friction angle, deg
    rolling_stiffness: float = 1.0   #: rolling stiffness coefficient beta_r, - (0: off)
    rolling_friction: float = 0.1    #: rolling friction coefficient eta_r, - (0: off)
    damping_normal: float = 0.0      #: viscous damping ratio (normal), -
    local_damping: float = 0.3       #: Cundall local damping coefficient, -
    gravity: float = 9.81            #: gravitational acceleration, m/s^2
    dt_safety: float = 0.2           #: dt = dt_safety x critical_dt(), -
    dt_period: int = 100             #: steps between time-step updates, -
    duration: float = 1.5            #: maximum simulated time, s
    record_interval: float = 0.005   #: time between series records, s
    snapshot_interval: float = 0.05  #: time between snapshots (HDF5 + VTK), s
    settled_speed: float = 0.005     #: stop once max |v| is below this, m/s ...
    settled_unbalanced: float = 0.01  #: ... and the unbalanced force below this, -
    settled_hold: float = 0.05       #: ... over this long (consecutive records), s
    threads: int = 0                 #: OpenMP threads (0: automatic, cpp_dem.apply_threads), -


SMOKE = dict(n=400, box=(0.06, 0.06, 0.12), duration=1.0, snapshot_interval=0.05)


# ---------------------------------------------------------------------------------------------
# Building
# ---------------------------------------------------------------------------------------------


def initial_cloud(p: Params) -> tuple[np.ndarray, np.ndarray]:
    """A loose, non-overlapping cloud in the upper part of the box: a cubic lattice of spacing
    2 r_max (1 + gap), filled layer by layer from the top, each centre jittered at random
    within its cell. Returns centres (n, 3) and radii (n,), m."""
    rng = np.random.default_rng(p.seed)
    lx, ly, lz = p.box
    spacing = 2.0 * p.r_max * (1.0 + p.gap)
    # Each sphere stays inside its lattice cell (a cube of side `spacing`), and the cells
    # stay inside the box: no sphere touches another sphere or a wall at the start.
    clear = 0.5 * spacing
    nx = int((lx - 2 * clear) // spacing) + 1
    ny = int((ly - 2 * clear) // spacing) + 1
    per_layer = nx * ny
    layers = math.ceil(p.n / per_layer)
    z_top = lz - clear
    z_bottom = z_top - (layers - 1) * spacing
    if nx < 1 or ny < 1 or z_bottom < 0.5 * lz:
        raise SystemExit(f"error: n={p.n} spheres need {layers} lattice layers of {per_layer} "
                         f"(spacing {spacing * 1e3:.1f} mm), reaching down to z="
                         f"{z_bottom:.3f} m: that is not the upper part of a box of height "
                         f"{lz} m. Use fewer spheres or a taller/wider box.")
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    xy = np.column_stack([ix.ravel(), iy.ravel()]) * spacing + clear
    # Centre the lattice horizontally.
    xy += 0.5 * (np.array([lx, ly]) - (xy.max(0) + xy.min(0)))
    centers = np.concatenate([
        np.column_stack([xy, np.full(per_layer, z_top - k * spacing)]) for k in range(layers)
    ])[: p.n]
    radii = rng.uniform(p.r_min, p.r_max, p.n)
    # Jitter each centre so that the sphere stays inside its cell (no overlaps by
    # construction): |jitter| <= spacing/2 - r_max per axis.
    amp = 0.5 * spacing - p.r_max
    centers = centers + rng.uniform(-amp, amp, centers.shape)
    r = radii[:, None]
    assert np.all(centers - r > 0) and np.all(centers + r < np.asarray(p.box)), "cloud vs box"
    return centers, radii


def build_scene(p: Params) -> tuple[dem.Scene, list[int]]:
    """The scene: box walls, spheres, material, time step and energy tracking."""
    scene = dem.Scene(gravity=(0.0, 0.0, -p.gravity), local_damping=p.local_damping)
    mat = scene.add_material(dem.Material(
        model="linear", density=p.density, young=p.young, poisson=p.poisson,
        friction_angle_deg=p.friction_angle_deg, damping_normal=p.damping_normal,
        damping_shear=0.0, rolling_stiffness=p.rolling_stiffness,
        rolling_friction=p.rolling_friction))
    walls = scene.add_box((0.0, 0.0, 0.0), p.box, material=mat)
    centers, radii = initial_cloud(p)
    scene.add_spheres(centers, radii, material=mat)
    scene.set_auto_timestep(safety=p.dt_safety, period=p.dt_period)
    scene.track_energy = True
    return scene, walls


def _json_safe(x):
    """NaN/inf -> None (strict JSON), NumPy scalars -> Python numbers, recursively."""
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    return x


# ---------------------------------------------------------------------------------------------
# Plot
# ---------------------------------------------------------------------------------------------


def plot_energies(h5_path: Path, png_path: Path) -> None:
    """energies.png from the recorded series: the energy terms (J) and, on a log scale,
    the kinetic energy and |balance error|."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = read_h5_series(h5_path)
    t = s["time"]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7.5), sharex=True,
                                   gridspec_kw=dict(height_ratios=[3, 2]))
    ax1.plot(t, s["kinetic"], color="C0", label="kinetic")
    ax1.plot(t, s["elastic"], color="C1", label="elastic (contact springs)")
    ax1.plot(t, s["gravity_potential"], color="C2", label="gravity potential change")
    ax1.plot(t, s["friction"], color="C4", label="friction dissipation")
    if np.any(s["viscous"] != 0):
        ax1.plot(t, s["viscous"], color="C5", label="viscous dissipation")
    ax1.plot(t, s["local_damping"], color="C6", label="local damping dissipation")
    dissip = s["friction"] + s["viscous"] + s["local_damping"]
    ax1.plot(t, dissip, "k--", lw=1, label="total dissipation")
    ax1.plot(t, s["balance_error"], color="C3", lw=2, label="balance error")
    ax1.axhline(0, color="0.6", lw=0.5)
    ax1.set_ylabel("energy (J)")
    ax1.legend(fontsize=8, ncol=2)
    ax1.set_title("Gravity deposition: energy bookkeeping (scene.energies())")

    def positive(y):  # log axes: leave out zeros (the initial state)
        y = np.asarray(y, dtype=float)
        return np.where(y > 0, y, np.nan)

    released = np.abs(s["gravity_potential"])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.abs(s["balance_error"]) / released
    ax2.semilogy(t, positive(s["kinetic"]), color="C0", label="kinetic (J)")
    ax2.semilogy(t, positive(np.abs(s["balance_error"])), color="C3",
                 label="|balance error| (J)")
    ax2.semilogy(t, positive(ratio), color="C3", ls=":",
                 label="|balance error| / |gravity potential change| (-)")
    top = np.nanmax([np.nanmax(positive(s["kinetic"])), np.nanmax(positive(ratio)), 1e-12])
    ax2.set_ylim(top * 1e-10, top * 10)
    ax2.set_xlabel("time (s)")
    ax2.set_ylabel("log scale")
    ax2.legend(fontsize=8)
    ax2.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, png_path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Run
# ---------------------------------------------------------------------------------------------


def clean_outputs(out: Path) -> None:
    """Removes the files a previous run of this case wrote in ``out`` (only those)."""
    for name in ("deposition.h5", "deposition.csv", "deposition.pvd", "contacts.pvd", "box.pvd",
                 "energies.png", "energies.pdf", "packing.csv", "summary.json"):
        (out / name).unlink(missing_ok=True)
    vtk = out / "vtk"
    if vtk.is_dir():
        for f in list(vtk.glob("spheres_*.vtp")) + list(vtk.glob("contacts_*.vtp")) + \
                [vtk / "box.vtp"]:
            f.unlink(missing_ok=True)


def run(p: Params, out: Path) -> dict:
    """Runs the deposition, writes the outputs in ``out``; returns the summary."""
    wall_t0 = time.perf_counter()
    apply_threads(p.threads)
    begin_run(out, "deposition")  # (a no-op when main() began the run)
    if (out / "deposition.h5").exists():
        print(f"[deposition] replacing the outputs of a previous run in {out}", flush=True)
    clean_outputs(out)
    (out / "vtk").mkdir(exist_ok=True)

    scene, walls = build_scene(p)
    n = scene.num_bodies
    print(f"[deposition] {n} spheres, radii {p.r_min * 1e3:.1f}-{p.r_max * 1e3:.1f} mm, box "
          f"{p.box[0]} x {p.box[1]} x {p.box[2]} m, {dem.threads_for(scene)} threads; "
          f"dt = {scene.dt:.3g} s (auto, safety {p.dt_safety}, p-wave {scene.pwave_dt():.3g} s)",
          flush=True)

    meta = {**asdict(p), "case": "deposition", "git_revision": git_revision(),
            "python": platform.python_version(), "num_threads": dem.get_num_threads(),
            "units": "SI (m, s, kg, N, J)"}
    series = standard_series(scene)
    h5 = H5Recorder(out / "deposition.h5", scene, series=series, metadata=meta,
                    snapshot_fields=("positions", "velocities", "angular_velocities", "radii",
                                     "forces"),
                    overwrite=True)
    csv = CsvRecorder(out / "deposition.csv", scene, series=series, overwrite=True)
    pvd_spheres = PvdWriter(out / "deposition.pvd", overwrite=True)
    pvd_contacts = PvdWriter(out / "contacts.pvd", overwrite=True)
    # The walls do not move in this case: box.pvd lists the one box file, at the start.
    f_box = write_vtk_box(out / "vtk" / "box.vtp", (0, 0, 0), p.box, time=scene.time)
    PvdWriter(out / "box.pvd", overwrite=True).add(scene.time, f_box.relative_to(out))

    last_snapshot_step = [-1]

    def snapshot() -> None:
        last_snapshot_step[0] = scene.step_count
        k = h5.num_snapshots
        h5.snapshot()
        f_s = out / "vtk" / f"spheres_{k:04d}.vtp"
        f_c = out / "vtk" / f"contacts_{k:04d}.vtp"
        write_vtk_spheres(f_s, scene)
        write_vtk_contacts(f_c, scene)
        pvd_spheres.add(scene.time, f_s.relative_to(out))
        pvd_contacts.add(scene.time, f_c.relative_to(out))

    def progress(tag: str = "") -> None:
        e = scene.energies()
        vmax = float(np.sqrt((scene.velocities**2).sum(1).max()))
        released = abs(e["gravity_potential"])
        rel = abs(e["balance_error"]) / released if released > 0 else 0.0
        print(f"[deposition] t={scene.time:7.4f} s  step {scene.step_count:7d}  "
              f"dt={scene.dt:.3g} s  contacts {scene.num_active_contacts:6d}  "
              f"max|v|={vmax:.3g} m/s  unbalanced={scene.unbalanced_force():.3g}  "
              f"KE={e['kinetic']:.3g} J  balance error={e['balance_error']:.3g} J "
              f"({100 * rel:.2g}% of |dE_grav|)  wall {time.perf_counter() - wall_t0:.1f} s"
              f"{tag}", flush=True)

    # Record the initial state (the energy reference is set during the first step).
    h5.record()
    csv.record()
    snapshot()
    next_snapshot = p.snapshot_interval
    settled = False
    calm_since = None  # time since which the packing has been at rest
    run_t0 = time.perf_counter()
    try:
        while scene.time < p.duration - 1e-12:
            # Run to the next record time in one C++ call (dt may change every dt_period).
            steps = max(1, int(round(min(p.record_interval, p.duration - scene.time)
                                     / scene.dt)))
            scene.run(steps)
            h5.record()
            csv.record()
            if scene.time >= next_snapshot - 1e-12:
                snapshot()
                progress()
                next_snapshot += p.snapshot_interval
            vmax = float(np.sqrt((scene.velocities**2).sum(1).max()))
            ub = scene.unbalanced_force()
            if vmax < p.settled_speed and ub < p.settled_unbalanced:
                calm_since = scene.time if calm_since is None else calm_since
                if scene.time - calm_since >= p.settled_hold - 1e-12:
                    settled = True
                    break
            else:
                calm_since = None
    finally:
        run_wall = time.perf_counter() - run_t0
        if last_snapshot_step[0] != scene.step_count:
            snapshot()  # the final state
        progress(" (settled)" if settled else " (end)")
        h5.close()
        csv.close()

    # ---- summary ---------------------------------------------------------------------------
    pos, radii = scene.positions, scene.radii
    dem.write_packing_csv(out / "packing.csv", pos, radii)
    e = scene.energies()
    released = abs(e["gravity_potential"])
    h_surf = surface_height(pos, radii, p.box)
    h_top = float((pos[:, 2] + radii).max())
    z0, z1 = 0.0, 0.5 * h_surf
    area = p.box[0] * p.box[1]
    porosity = 1.0 - slab_solid_volume(pos[:, 2], radii, z0, z1) / (area * (z1 - z0))
    porosity_core = interior_porosity(pos, radii, p.box, 2 * p.r_max, z1)
    vmax = float(np.sqrt((scene.velocities**2).sum(1).max()))
    floor_force = float(scene.wall_forces[walls[4]][2])
    weight = float(scene.masses.sum() * p.gravity)
    inside = bool(np.all((pos - radii[:, None] > -0.5 * radii[:, None])
                         & (pos + radii[:, None] < np.asarray(p.box) + 0.5 * radii[:, None])))
    summary = {
        "num_spheres": n,
        "settled": settled,
        "simulated_time_s": scene.time,
        "steps": scene.step_count,
        "dt_final_s": scene.dt,
        "surface_height_m": h_surf,
        "top_height_m": h_top,
        "porosity_bottom": porosity,
        "porosity_region_m": [z0, z1],
        "porosity_interior": porosity_core,
        "max_speed_m_per_s": vmax,
        "unbalanced_force": scene.unbalanced_force(),
        "floor_force_z_N": floor_force,
        "total_weight_N": weight,
        "all_inside_box": inside,
        "energy_J": {k: float(v) for k, v in e.items()},
        "gravity_energy_released_J": released,
        "balance_error_J": e["balance_error"],
        "balance_error_over_released": abs(e["balance_error"]) / released if released else 0.0,
        "balance_error_relative_core": e["balance_error_relative"],
        "wall_time_run_s": run_wall,
    }
    plot_energies(out / "deposition.h5", out / "energies.png")
    summary["wall_time_total_s"] = time.perf_counter() - wall_t0
    (out / "summary.json").write_text(json.dumps(_json_safe(summary), indent=2) + "\n")

    print()
    print(f"[deposition] summary ({out})")
    print(f"  {'settled' if settled else 'NOT settled'} after {scene.time:.3f} s simulated, "
          f"{scene.step_count} steps (final dt {scene.dt:.3g} s)")
    print(f"  settled height: free surface {h_surf * 1e3:.1f} mm (mean of 5x5 column tops), "
          f"highest sphere top {h_top * 1e3:.1f} mm")
    print(f"  porosity of the bottom region z in [{z0 * 1e3:.0f}, {z1 * 1e3:.1f}] mm "
          f"(full cross-section, wall effects included): {porosity:.3f}; away from the "
          f"walls (centres > {2 * p.r_max * 1e3:.0f} mm from floor and sides): "
          + (f"{porosity_core:.3f}" if math.isfinite(porosity_core) else "n/a (too thin)"))
    print(f"  max |v| = {vmax:.3g} m/s, unbalanced force = {scene.unbalanced_force():.3g}; the "
          f"floor carries {-floor_force:.4g} N of the {weight:.4g} N weight (the rest: "
          f"friction on the side walls)")
    print(f"  energy: released by gravity {released:.4g} J; dissipated by local damping "
          f"{e['local_damping']:.4g} J, friction {e['friction']:.4g} J, viscous "
          f"{e['viscous']:.4g} J; kinetic {e['kinetic']:.3g} J, elastic {e['elastic']:.3g} J")
    print(f"  energy balance error: {e['balance_error']:.3g} J = "
          f"{100 * summary['balance_error_over_released']:.2f}% of the released energy "
          f"(core's relative measure {e['balance_error_relative']:.2g})")
    print(f"  wall time: {run_wall:.1f} s in the run loop, "
          f"{summary['wall_time_total_s']:.1f} s in total ({dem.get_num_threads()} threads)")
    return summary


#: The most steps a deposition run may ask for (about 1e5 settle the default packing).
MAX_STEPS = 1e8


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    ap = case_parser("deposition", describe("deposition", __doc__.split("\n")[0]),
                     smoke=f"{SMOKE['n']} spheres in a {SMOKE['box'][0]} x {SMOKE['box'][1]} x "
                           f"{SMOKE['box'][2]} m box", seed=Params.seed)
    ap.add_argument("--n", type=int, default=None, help="number of spheres (default 3000, "
                    f"smoke {SMOKE['n']})")
    ap.add_argument("--duration", type=float, default=None,
                    help=f"maximum simulated time, s (default {Params.duration}, smoke "
                         f"{SMOKE['duration']}); the run stops earlier once settled")
    ap.add_argument("--local-damping", type=float, default=Params.local_damping,
                    help="Cundall local damping coefficient, -")
    ap.add_argument("--damping-normal", type=float, default=Params.damping_normal,
                    help="viscous normal damping ratio of the contacts, -")
    ap.add_argument("--dt-safety", type=float, default=Params.dt_safety,
                    help="dt = safety x scene.critical_dt(), -")
    ap.add_argument("--no-early-stop", action="store_true",
                    help="run the full duration even once settled")
    return ap


def parse_args(argv=None) -> tuple[Params, Path]:
    ap = build_parser()
    a = parse_checked(ap, argv)
    p = Params(**SMOKE) if a.smoke else Params()
    if a.n is not None:
        p.n = a.n
    if a.duration is not None:
        p.duration = a.duration
    p.seed, p.threads = a.seed, a.threads
    p.local_damping, p.damping_normal, p.dt_safety = a.local_damping, a.damping_normal, a.dt_safety
    if a.no_early_stop:
        p.settled_speed = -1.0
    if p.n < 1:
        ap.error(f"--n={p.n}: must be >= 1")
    check_cap(ap, a, "--n", p.n, p.n, "grains")
    for name, v, ok, allowed in (
            ("--local-damping", p.local_damping, 0 <= p.local_damping < 1, "in [0, 1)"),
            ("--damping-normal", p.damping_normal, 0 <= p.damping_normal <= 1,
             "in [0, 1] (a damping ratio)"),
            ("--dt-safety", p.dt_safety, 0 < p.dt_safety <= 1, "in (0, 1]")):
        if not (math.isfinite(v) and ok):
            ap.error(f"{name}={v}: must be {allowed}")
    if not (math.isfinite(p.duration) and p.duration > 0):
        ap.error(f"--duration={p.duration}: must be a finite number > 0 (s)")
    # steps at the p-wave step of the smallest grain (dt = dt_safety x r_min sqrt(rho / E),
    # as scene.pwave_dt()): a request beyond MAX_STEPS is refused with the estimate
    if 0 < p.dt_safety and p.young > 0:
        steps = p.duration / (p.dt_safety * p.r_min * math.sqrt(p.density / p.young))
        if steps > MAX_STEPS:
            ap.error(f"--duration={p.duration}: about {steps:.3g} steps of dt "
                     f"{p.duration / steps:.3g} s ({steps * p.n:.3g} particle-steps); more "
                     f"than the {MAX_STEPS:.0e} steps this case runs (the packing settles in "
                     "about 1 s; the run stops once settled)")
    return p, a.out


def main(argv=None) -> int:
    p, out = parse_args(argv)
    return run_main("deposition", out, lambda o: run(p, o))


if __name__ == "__main__":
    sys.exit(main())
