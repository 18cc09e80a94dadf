"""The drained triaxial test of a cylindrical specimen in a flexible membrane, as in the
laboratory (issue 65; the cubical one is :mod:`cpp_dem.protocols.triaxial`).

:func:`prepare` makes the specimen in a rigid mould: a loose cloud inside a cylindrical wall
between a still base and a lid, compacted by servos on the mould's radius and the lid to the
cell pressure; then the mould is opened and a membrane
(:func:`cpp_dem.build.membrane.cylindrical_membrane`) holds the specimen under the cell
pressure alone, its end rings sealed to the platens, the lid servoed to the cell pressure on
the specimen's cross-section until the specimen is at rest. :func:`shear` then moves the lid
down at a constant axial strain rate, the cell pressure held on the membrane.

Recorded per row (compression positive): the axial strain eps_a = (H0 - H) / H0, the
volumetric strain eps_v = (V0 - V) / V0 from the volume inside the membrane (its triangles'
volume less their area times R_c: ``Membrane.inner_volume_m3``), the axial stress on the
current cross-section A = V / H (the laboratory's area correction), the deviator
q = sigma_a - sigma_r with sigma_r the cell pressure, and the membrane's correction: the
grains' measured radial stress in the middle third less the cell pressure, what the
membrane's own tension adds to the confinement (the laboratory subtracts an estimate of it
from q; here it is measured).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cpp_dem import _core
from cpp_dem.measure import inertial
from cpp_dem.protocols.quasi_static import effective_density
from cpp_dem.protocols.prep import overlap_limit
from cpp_dem.build.membrane import Membrane, cylindrical_membrane, lattice_sides
from cpp_dem.build.packing import loose_cylinder
import warnings

from cpp_dem.scene import ControllerLimitWarning, Scene


@dataclass
class CylinderSpecimen:
    """A specimen made by :func:`prepare`."""

    scene: Scene
    membrane: Membrane
    base: int  #: the base's wall id (still)
    lid: int  #: the lid's wall id
    material: int
    pressure_pa: float  #: the cell pressure, Pa
    height0_m: float  #: the height between the platens at the end of the preparation, m
    volume0_m3: float  #: the specimen's volume then, m^3
    lid_servo: object = None
    #: what the preparation reached: steps, the mould's and the lid's stresses, the radial
    #: stress the grains put on the membrane (Pa), whether the targets were reached
    prepared: dict = field(default_factory=dict)


#: the largest ``membrane_side`` of :func:`prepare`: a triangle as wide as the smallest grain,
#: the membrane's limit (:func:`cpp_dem.build.membrane.cylindrical_membrane`)
MEMBRANE_SIDE_MAX = 2.0
#: the smallest: below it the links (R_c a quarter of the smallest radius) would overlap
MEMBRANE_SIDE_MIN = 0.75


def membrane_side_problem(side: float) -> str | None:
    """What is wrong with a ``membrane_side`` (-), after its name in a refusal; None when it
    is allowed (the protocol's and the triaxial case's check)."""
    if math.isfinite(side) and MEMBRANE_SIDE_MIN <= side <= MEMBRANE_SIDE_MAX:
        return None
    return (f"must be in [{MEMBRANE_SIDE_MIN:g}, {MEMBRANE_SIDE_MAX:g}] (the membrane's "
            f"triangles in smallest grain radii: below {MEMBRANE_SIDE_MIN:g} its links would "
            f"overlap, above {MEMBRANE_SIDE_MAX:g} they are wider than the grain)")


def _auto_segments(radius_m: float, height_m: float, side_m: float, r_min: float) -> int:
    """The fewest segments whose chord is at most ``side_m`` (m), and whose triangles are no
    wider than the smallest grain (``2 r_min``, m: the membrane's limit) on any side."""
    n = max(12, int(math.ceil(2.0 * math.pi * radius_m / side_m)))
    while max(lattice_sides(radius_m, height_m, n)[:2]) > 2.0 * r_min:
        n += 1
    return n


def prepare(radii, *, radius_m: float, height_m: float, pressure_pa: float,
            material: _core.Material, seed: int = 1, platen_friction_deg: float = 0.0,
            membrane_young_pa: float = 1e6,
            membrane_thickness_m: float = 3e-4, mass_scale: float = 20.0,
            membrane_side: float = 1.0, dt_safety: float | None = None,
            damping: float = 0.3, tol: float = 0.01,
            max_steps: int = 200_000,
            check_every: int = 1000, inclusion=None, log=None) -> CylinderSpecimen:
    """The specimen of ``radii`` (m) in a mould of ``radius_m`` and ``height_m`` (m),
    compacted to ``pressure_pa`` (Pa) and then held by a membrane of
    ``membrane_young_pa`` (Pa) and ``membrane_thickness_m`` (m) (R_c a quarter of the smallest
    grain radius; its triangles' side around a ring ``membrane_side`` times that radius, -:
    1, the default, is finer than the grains, as a rubber membrane is; up to
    :data:`MEMBRANE_SIDE_MAX`, as wide as the smallest grain, the membrane's limit; a coarser
    membrane is cheaper, docs/studies/membrane_resolution.md measures what it changes). The
    time step: without ``dt_safety``, 0.3 of the grains' p-wave estimate, set in the mould
    before they touch and kept (at most 0.3 of the critical step once the membrane is on);
    with ``dt_safety`` in (0, 1], that fraction of the critical step of the grains and the
    membrane as they touch, renewed every 100 steps (as the cubical test's), which lets the
    step grow as the contacts form (docs/studies/membrane_resolution.md measures it). The
    hold ends with the lid within ``tol`` and the grains' radial stress steady; it differs
    from the cell pressure by the membrane's correction
    (``prepared["membrane_correction_pa"]``). The grains and the membrane take ``material``;
    the mould and the platens the same with ``platen_friction_deg`` (deg; frictionless by
    default, as the cubical test's walls: lubricated ends). Each stage runs until its
    stresses are within ``tol`` of the cell pressure at two checks in a row (``check_every``
    steps apart), at most ``max_steps``; a stage that does not get there is said in
    ``prepared["reached"]`` (False) and by ``log``, not hidden. The scene's blow-up limit on
    overlaps is the cubical test's for soft grains under confinement
    (:func:`cpp_dem.protocols.prep.overlap_limit` of the cell pressure and the material's
    Young's modulus, 0.5 to 0.95 of the radius).

    ``inclusion(scene, centres, radii)``, if given, is called once the mould and the platens
    are in the scene and before the grains: it adds what the specimen holds besides its
    grains (a geogrid disc: :func:`cpp_dem.build.geogrid.disc_grid`) and returns a mask of the
    grains (of the loose cloud's ``centres`` and ``radii``, m) to keep, False for those it
    displaces. The time step is set after it, so it counts the inclusion's members."""
    say = log or (lambda msg: None)
    p = float(pressure_pa)
    if not (math.isfinite(p) and p > 0):
        raise _core.ParameterError(f"pressure_pa={pressure_pa!r}: must be > 0 (Pa)")
    safety = None if dt_safety is None else float(dt_safety)
    if safety is not None and not (math.isfinite(safety) and 0 < safety <= 1):
        raise _core.ParameterError(f"dt_safety={dt_safety!r}: must be in (0, 1] (a fraction "
                                   "of the critical time step), or None (the protocol's)")
    side = float(membrane_side)
    problem = membrane_side_problem(side)
    if problem:
        raise _core.ParameterError(f"membrane_side={membrane_side!r}: {problem}")
    radii = np.asarray(radii, dtype=float)
    pts, radii = loose_cylinder(radii, radius_m, height_m, seed=seed)
    sc = Scene(local_damping=damping)
    # soft grains overlap by design under the cell pressure (4 p / E of the radius on the mean
    # contact, several times that on the strongest chains): the blow-up limit of the cubical
    # test's preparation (prep.overlap_limit); at the scene's default 0.5 the smoke's seed 3
    # (E 4.5 MPa, 75 kPa, a slab cleared at mid-height) stopped in the mould with two grains
    # on one chain pressed, slowly, to half a radius
    sc.max_overlap_ratio = overlap_limit(p, float(material.young))
    m = sc.add_material(material)
    smooth = sc.add_material(material.replace(friction_angle_deg=platen_friction_deg))
    mould = sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=radius_m,
                                 inside=True, material=smooth, lo=0.0, hi=height_m)
    base = sc.add_wall(axis=2, position=0.0, sense=1, material=smooth)
    lid = sc.add_wall(axis=2, position=height_m, sense=-1, material=smooth)
    if inclusion is not None:
        keep = np.asarray(inclusion(sc, pts, radii), dtype=bool)
        if keep.shape != radii.shape:
            raise _core.ParameterError(f"inclusion: returned a mask of shape {keep.shape}; "
                                       f"it must be one bool per grain, {radii.shape}")
        if not keep.any():
            raise _core.ParameterError("inclusion: displaced every grain")
        pts, radii = pts[keep], radii[keep]
    sc.add_spheres(pts, radii, material=m)
    sc.dt = 0.3 * sc.critical_dt()
    speed = 0.1 * height_m / (1e4 * sc.dt)  # m/s: the servos' cap, a tenth of the height in 1e4 steps
    if safety is not None:  # (the servos' caps in m/s stay those of the protocol's step)
        sc.set_auto_timestep(safety=safety, period=100)
    cs = _core.CylinderServo(cylinder=mould, target_pressure=p, max_speed=speed)
    mould_servo = _core.ServoWall(wall=lid, target_stress=p, area=math.pi * radius_m**2,
                                  max_speed=speed)
    sc.add_controller(cs)
    sc.add_controller(mould_servo)

    def settle(ok, what: str, between=None) -> tuple[int, bool]:
        steps, held = 0, 0
        while steps < max_steps:
            sc.run(check_every)
            steps += check_every
            if between is not None:
                between()
            held = held + 1 if ok() else 0
            if held == 2:
                return steps, True
        say(f"{what}: not within {tol:.0%} of {p:g} Pa after {steps} steps")
        return steps, False

    def mould_radius_now() -> float:
        return sc.cylinder_wall(mould)["radius"]

    def mould_ok() -> bool:
        # (the lid's stress on the mould's area as made: the membrane's stage below puts it
        # on the specimen's own cross-section)
        return (abs(sc.cylinder_wall(mould)["pressure_pa"] / p - 1) < tol
                and abs(mould_servo.measured_stress / p - 1) < tol)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ControllerLimitWarning)  # (compacting at the cap)
        n1, ok1 = settle(mould_ok, "compaction in the mould")
    rs = mould_radius_now()
    say(f"compacted in the mould: radius {rs:.5g} m after {n1} steps")
    cs.enabled = mould_servo.enabled = False
    sc.set_cylinder_radius(mould, 3.0 * radius_m)  # (opened wide: the membrane holds alone)
    z0, z1 = sc.wall_positions
    rc = 0.25 * float(radii.min())
    mb = cylindrical_membrane(sc, centre=[0, 0, z0], radius_m=rs + rc, height_m=z1 - z0,
                              young_pa=membrane_young_pa, thickness_m=membrane_thickness_m,
                              node_radius_m=rc, material=m,
                              segments=_auto_segments(rs + rc, z1 - z0,
                                                      side * float(radii.min()),
                                                      float(radii.min())),
                              mass_scale=mass_scale)
    area = math.pi * rs**2
    lid_servo = _core.ServoWall(wall=lid, target_stress=p, area=area, max_speed=speed)
    sc.add_controller(lid_servo)
    sc.add_controller(mb.pressure(p))
    for c in mb.clamps(base, lid):
        sc.add_controller(c)
    sc.dt = (min(sc.dt, 0.3 * sc.critical_dt()) if safety is None
             else safety * sc.critical_dt())

    last = [math.nan]

    def held_ok() -> bool:
        # The lid at the cell pressure on the specimen's cross-section, and the grains'
        # radial stress steady (within tol x p since the last check): it differs from the
        # cell pressure by the membrane's correction, which is measured, not a target.
        a = math.pi * mb.specimen_radius_m(sc) ** 2
        radial, before = mb.radial_stress_pa(sc), last[0]
        last[0] = radial
        return (abs(sc.wall_forces[lid][2] / a / p - 1) < tol
                and abs(radial - before) < tol * p)

    with warnings.catch_warnings():
        # (the swap from the mould to the membrane unloads the specimen for a moment)
        warnings.simplefilter("ignore", ControllerLimitWarning)
        n2, _ = settle(lambda: True, "the membrane's first hold")
    # The lid's servo on the specimen's own cross-section, now that the membrane lies on it.
    lid_servo.enabled = False
    r_lid = mb.specimen_radius_m(sc)
    lid_servo = _core.ServoWall(wall=lid, target_stress=p, area=math.pi * r_lid ** 2,
                                max_speed=speed)
    sc.add_controller(lid_servo)

    def on_section() -> None:
        # The servo's force target follows the specimen's cross-section as the membrane
        # moves (its area is fixed when it is made): p on the current section.
        lid_servo.target_stress = p * (mb.specimen_radius_m(sc) / r_lid) ** 2

    with warnings.catch_warnings():
        # (the new servo starts from the first hold's stress, at its cap for a while; the
        # hold's own check says whether it got there)
        warnings.simplefilter("ignore", ControllerLimitWarning)
        n3, ok3 = settle(held_ok, "the hold in the membrane", between=on_section)
    z0, z1 = sc.wall_positions
    radial = mb.radial_stress_pa(sc)
    prepared = {"steps": n1 + n2 + n3, "mould_radius_m": rs,
                "radial_stress_pa": radial, "membrane_correction_pa": radial - p,
                "axial_stress_pa": sc.wall_forces[lid][2] / (math.pi *
                                                             mb.specimen_radius_m(sc) ** 2),
                "grains_outside": int(len(mb.grains_outside(sc))), "reached": ok1 and ok3}
    return CylinderSpecimen(scene=sc, membrane=mb, base=base, lid=lid, material=m,
                            pressure_pa=p, height0_m=z1 - z0,
                            volume0_m3=mb.inner_volume_m3(sc), lid_servo=lid_servo,
                            prepared=prepared)


def row(spec: CylinderSpecimen) -> dict:
    """The specimen's state now (module doc): axial and volumetric strain (-), the axial
    stress on the current cross-section at the lid (the load cell) and at the base (in a
    quasi-static test they agree: a lid ahead of its base is a test loaded too fast), the
    deviator and the membrane's correction (Pa),
    the cross-section (m^2), the grains outside the membrane (count), the grains' unbalanced
    force (their mean over their mean contact force, -)."""
    sc, mb = spec.scene, spec.membrane
    z0, z1 = sc.wall_positions
    h = z1 - z0
    v = mb.inner_volume_m3(sc)
    a = v / h
    sigma_a = float(sc.wall_forces[spec.lid][2]) / a
    sigma_base = -float(sc.wall_forces[spec.base][2]) / a
    radial = mb.radial_stress_pa(sc)
    return {"step": int(sc.step_count), "axial_strain": (spec.height0_m - h) / spec.height0_m,
            "volumetric_strain": (spec.volume0_m3 - v) / spec.volume0_m3,
            "axial_stress_pa": sigma_a, "base_stress_pa": sigma_base,
            "deviatoric_stress_pa": sigma_a - spec.pressure_pa,
            "radial_stress_pa": radial,
            "membrane_correction_pa": radial - spec.pressure_pa, "area_m2": a,
            "grains_outside": int(len(mb.grains_outside(sc))),
            "unbalanced_force": float(sc.unbalanced_force())}


def inertial_number(spec: CylinderSpecimen, strain_rate: float) -> float:
    """The loading's inertial number I = rate x d_mean / sqrt(p / rho), - (the grains' mean
    diameter, the cell pressure, the grains' density): quasi-static below about 1e-3, as
    the cubical test's (:func:`cpp_dem.measure.inertial.check_quasi_static`)."""
    d_mean, rho = _grains(spec)
    return inertial.inertial_number(strain_rate, d_mean, spec.pressure_pa, rho)


def _grains(spec: CylinderSpecimen) -> tuple[float, float]:
    """The grains' mean diameter (m) and density (kg/m^3, with density scaling's factor)."""
    sc = spec.scene
    grains = np.asarray(sc.body_kinds) == 0
    return (2.0 * float(np.mean(np.asarray(sc.radii)[grains])),
            effective_density(sc, float(sc.material(spec.material).density)))


def shear(spec: CylinderSpecimen, *, strain_rate: float, stop_strain: float,
          record_every: int = 500, on_row=None) -> list[dict]:
    """Moves the lid down at ``strain_rate`` (1/s, of the height at the start) to
    ``stop_strain`` (-), the cell pressure held on the membrane; returns a :func:`row` every
    ``record_every`` steps (``on_row`` is called with each)."""
    for name, v in (("strain_rate", strain_rate), ("stop_strain", stop_strain)):
        if not (math.isfinite(v) and v > 0):
            raise _core.ParameterError(f"{name}={v!r}: must be > 0")
    sc = spec.scene
    d_mean, rho = _grains(spec)
    inertial.check_quasi_static(inertial.inertial_number(strain_rate, d_mean, spec.pressure_pa,
                                                         rho),
                                "cylindrical triaxial shearing", rate=strain_rate,
                                diameter=d_mean, pressure=spec.pressure_pa, density=rho,
                                stacklevel=2)
    if spec.lid_servo is not None:
        spec.lid_servo.enabled = False
    sc.set_wall_velocity(spec.lid, [0.0, 0.0, -strain_rate * spec.height0_m])
    rows = [row(spec)]
    while rows[-1]["axial_strain"] < stop_strain:
        sc.run(record_every)
        rows.append(row(spec))
        if on_row is not None:
            on_row(rows[-1])
    sc.set_wall_velocity(spec.lid, [0.0, 0.0, 0.0])
    return rows
