"""The drained triaxial test in a box of six frictionless walls (001 chapter 6, App. B).

Axis z is axial. Stage 1 (isotropic): servo walls bring all three axis stresses to the cell
pressure (within ``tol``, unbalanced force below ``unbalanced``). Stage 2 (deviatoric): the z
walls move inwards at a constant axial strain rate (engineering, from the box height at the
start of the stage) while the x and y walls hold the cell pressure. Recorded: axial strain
eps_a = (H0 - H) / H0, volumetric strain eps_v = (V0 - V) / V0 (compression positive), the
deviator q = sigma_z - (sigma_x + sigma_y) / 2 (Pa), mean stress p, the three axis stresses,
porosity, unbalanced force.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cpp_dem import _core
from cpp_dem.measure import inertial
from cpp_dem import measure
from cpp_dem.protocols import prep
from cpp_dem.progress import Progress
from cpp_dem.scene import Scene


@dataclass
class TriaxialSample:
    """A scene with its six walls, the grain material index and the box controller."""

    scene: Scene
    walls: list
    material: int
    controller: object
    wall_material: int = -1
    #: Rows of the preparation's history (phase, step, time_s, coordination, porosity,
    #: wall_stress_pa, unbalanced_force, dt_s), for those preparations that keep one.
    growth_history: list = field(default_factory=list)


def build_box_sample(centers, radii, lo, hi, *, young: float, poisson: float,
                     friction_deg: float, density: float, local_damping: float,
                     dt_safety: float = 0.5, gain: float = 0.5, clumps=None,
                     grain_material=None) -> TriaxialSample:
    """A scene with the spheres in the box [lo, hi] (m): grains of the linear law (E Pa, nu
    -, phi deg, rho kg/m^3), frictionless walls, Cundall local damping, automatic time step,
    and a TriaxialController on the walls (all axes at zero stress until set).

    clumps: (ClumpCloud, templates) to add clumps instead of the spheres (``centers`` and
    ``radii`` are then ignored; see cpp_dem.build.clumps.clump_cloud).
    grain_material: a Material for the grains instead of the linear one (e.g. 002's
    Hertz–Mindlin); the walls keep the linear law of young and poisson."""
    s = Scene(local_damping=local_damping)
    mat = s.add_material(grain_material if grain_material is not None else
                         _core.Material(model="linear", density=density, young=young,
                                        poisson=poisson, friction_angle_deg=friction_deg))
    wall_mat = s.add_material(_core.Material(model="linear", density=density, young=young,
                                             poisson=poisson, friction_angle_deg=0.0))
    walls = s.add_box(lo, hi, material=wall_mat)
    if clumps is not None:
        cloud, templates = clumps
        # Members as stiff as the grain's equivalent sphere (E R_eq): the calibrated E of a
        # sphere sample keeps its meaning, and small corner members do not sink into walls.
        cloud.add_to(s, templates, material=mat, stiffness="grain")
    else:
        s.add_spheres(centers, radii, material=mat)
    s.set_auto_timestep(safety=dt_safety, period=100)
    ctl = _core.TriaxialController(walls=walls, gain=gain,
                                   max_speed=prep.default_max_speed(s, walls))
    for a in range(3):
        ctl.set_stress(a, 0.0)
    ctl.enabled = False
    s.add_controller(ctl)
    return TriaxialSample(s, walls, mat, ctl, wall_mat)


def isotropic_stage(sample: TriaxialSample, pressure: float, *, tol: float = 0.01,
                    unbalanced: float = 0.01, check_every: int = 200,
                    max_steps: int = 300_000, callback=None) -> prep.StageResult:
    """Servo walls to the isotropic cell ``pressure`` (Pa)."""
    sample.controller.max_speed = prep.default_max_speed(sample.scene, sample.walls)
    return prep.compact_isotropic(sample.scene, sample.walls, pressure,
                                  controller=sample.controller, tol=tol, unbalanced=unbalanced,
                                  check_every=check_every, max_steps=max_steps,
                                  callback=callback)


def apply_preset(sample: TriaxialSample, preset, *, pressure: float, density: float) -> float:
    """Applies a speed-accuracy preset (a cpp_dem.presets.Preset or its name) to the loading
    of a prepared sample: time-step safety (dt reset at once) and local damping. Returns the
    preset's axial strain rate, 1/s, for the mean grain diameter, ``density`` (kg/m^3) and the
    cell ``pressure`` (Pa)."""
    from cpp_dem.presets import preset as by_name

    ps = by_name(preset) if isinstance(preset, str) else preset
    sc = sample.scene
    sc.set_auto_timestep(safety=ps.dt_safety, period=100)
    sc.local_damping = ps.local_damping
    sc.dt = ps.dt_safety * sc.critical_dt()
    d_mean = 2.0 * float(np.mean(np.asarray(sc.radii)[measure.sphere_mask(sc)]))
    return ps.strain_rate(grain_diameter=d_mean, density=density, stress=pressure)


def deviatoric_stage(sample: TriaxialSample, pressure: float, strain_rate: float,
                     stop_strain: float, *, record_every: int = 100, on_record=None,
                     max_steps: int = 10_000_000) -> dict:
    """Axial (z) compression at ``strain_rate`` (1/s, > 0) with x and y held at ``pressure``
    (Pa), until the axial strain reaches ``stop_strain`` (-). Calls ``on_record(row)`` every
    ``record_every`` steps with a dict of the recorded values; returns the arrays."""
    if not (np.isfinite(strain_rate) and strain_rate > 0):
        raise _core.ParameterError(f"strain_rate={strain_rate}: must be > 0 (1/s, axial "
                                   "compression)")
    if not (0 < stop_strain < 0.5):
        raise _core.ParameterError(f"stop_strain={stop_strain}: must be in (0, 0.5)")
    sc, walls, ctl = sample.scene, sample.walls, sample.controller
    d = measure.grain_diameters(sc)
    if pressure > 0 and len(d):
        d_mean = float(np.mean(d))
        from cpp_dem.protocols.quasi_static import effective_density

        rho = effective_density(sc, float(sc.material(sample.material).density))
        inertial.check_quasi_static(
            inertial.inertial_number(strain_rate, d_mean, pressure, rho),
            "triaxial deviatoric stage", rate=strain_rate, diameter=d_mean,
            pressure=pressure, density=rho, stacklevel=2)
    ctl.reset_strain(sc)
    l0 = np.asarray(ctl.reference_lengths)
    v0 = float(np.prod(l0))
    ctl.set_stress(0, pressure)
    ctl.set_stress(1, pressure)
    ctl.set_strain_rate(2, strain_rate)
    # The lateral walls must be able to follow: cap at 4 x the axial wall speed, or above.
    ctl.max_speed = max(ctl.max_speed, 4.0 * 0.5 * strain_rate * l0[2])
    ctl.enabled = True
    t0 = sc.time
    rows = []

    def row() -> dict:
        size = measure.box_size(sc, walls)
        ax = measure.axis_stresses(sc, walls)
        r = {"time": sc.time - t0, "step": sc.step_count,
             "axial_strain": float((l0[2] - size[2]) / l0[2]),
             "volumetric_strain": float((v0 - np.prod(size)) / v0),
             "deviatoric_stress": float(ax[2] - 0.5 * (ax[0] + ax[1])),
             "mean_stress": float(ax.mean()),
             "sigma_x": float(ax[0]), "sigma_y": float(ax[1]), "sigma_z": float(ax[2]),
             "porosity": measure.porosity(sc, walls),
             "unbalanced_force": float(sc.unbalanced_force())}
        rows.append(r)
        if on_record is not None:
            on_record(r)
        return r

    row()
    steps = 0
    bar = Progress("triaxial deviatoric stage")
    while rows[-1]["axial_strain"] < stop_strain and steps < max_steps:
        sc.run(record_every)
        steps += record_every
        r = row()
        bar.update(r["axial_strain"] / stop_strain,
                   f"axial strain {100 * r['axial_strain']:.3g} of {100 * stop_strain:.3g} %, "
                   f"q {r['deviatoric_stress'] / 1e3:.4g} kPa")
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}
