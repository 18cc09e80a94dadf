"""Sample preparation in a box of six walls: isotropic compaction by servo walls, radius
expansion under stress control (001 §4.3.1), and REFD (radius expansion – friction decrease,
000 §2.3). Stresses Pa (compressive positive); ``walls`` in the order of ``Scene.add_box``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cpp_dem import _core
from cpp_dem import measure
from cpp_dem._core import Material, ParameterError
from cpp_dem.build.packing import loose_cloud
from cpp_dem.progress import Progress
from cpp_dem.scene import Scene, TargetNotMetWarning


def default_max_speed(scene, walls, fraction: float = 1e-4) -> float:
    """A velocity cap for servo walls, m/s: each wall may move ``fraction`` of the mean
    radius per step (quasi-static: far below the grains' elastic wave speed)."""
    r = float(np.mean(np.asarray(scene.radii)[measure.sphere_mask(scene)]))
    return fraction * r / scene.dt


def overlap_limit(stress: float, young: float) -> float:
    """A blow-up limit on the overlap (fraction of the radius) for soft grains under
    confinement: with k_n = E R a contact carrying sigma (2R)^2 overlaps by 4 sigma / E of
    the radius, and the most loaded contacts carry several times the mean, so soft grains
    (E of a few MPa) at tens of kPa overlap by design. Returns 60 sigma / E, at least 0.5 and
    at most 0.95 (stress and young in Pa)."""
    return min(0.95, max(0.5, 60.0 * stress / young))


def _check_target(stress: float, field_name: str = "stress") -> None:
    if not (math.isfinite(stress) and stress > 0):
        raise ParameterError(f"{field_name}={stress}: must be > 0 (Pa, compressive positive; "
                             "a confining stress pushes the walls onto the sample)")


def _stable(scene, walls, targets, tol: float, unb: float) -> tuple[bool, np.ndarray, float]:
    ax = measure.axis_stresses(scene, walls)
    u = float(scene.unbalanced_force())
    ok = bool(np.all(np.abs(ax - targets) <= tol * np.abs(targets))) and u < unb
    return ok, ax, u


@dataclass
class StageResult:
    """What a preparation stage achieved."""

    converged: bool
    steps: int
    axis_stresses: np.ndarray          #: Pa
    mean_stress: float                 #: Pa
    unbalanced_force: float            #: -
    porosity: float                    #: -
    extra: dict = field(default_factory=dict)


def set_friction(scene, bodies, material: Material, friction_angle_deg: float) -> int:
    """Gives ``bodies`` a copy of ``material`` with another friction angle (deg); returns the
    new material index. Contacts remix their parameters at the next step (the stored shear
    forces are capped by the new Coulomb limit)."""
    m = material.replace(friction_angle_deg=friction_angle_deg)
    idx = scene.add_material(m)
    for b in np.asarray(bodies, dtype=int):
        scene.set_body_material(int(b), idx)
    return idx


def compact_isotropic(scene, walls, stress: float, *, controller=None, tol: float = 0.01,
                      unbalanced: float = 0.01, check_every: int = 200,
                      max_steps: int = 200_000, gain: float = 0.5,
                      max_speed: float | None = None, callback=None) -> StageResult:
    """Servo walls to an isotropic ``stress`` (Pa) until every axis stress is within ``tol``
    (relative) of it and the unbalanced force is below ``unbalanced``. Uses (or adds) a
    TriaxialController; returns a StageResult (``extra['controller']`` the controller)."""
    _check_target(stress)
    return drive_to_stresses(scene, walls, (stress, stress, stress), controller=controller,
                             tol=tol, unbalanced=unbalanced, check_every=check_every,
                             max_steps=max_steps, gain=gain, max_speed=max_speed,
                             callback=callback)


def drive_to_stresses(scene, walls, stresses, *, controller=None, tol: float = 0.01,
                      unbalanced: float = 0.01, check_every: int = 200,
                      max_steps: int = 200_000, gain: float = 0.5,
                      max_speed: float | None = None, callback=None) -> StageResult:
    """Servo the six walls of the box to the axis stresses ``stresses`` = (sigma_x, sigma_y,
    sigma_z), Pa, compressive positive (an anisotropic state, e.g. K0 or the stresses an FEM
    analysis hands over), until every axis stress is within ``tol`` (relative) of its target
    and the unbalanced force is below ``unbalanced``. Uses (or adds) a TriaxialController;
    returns a StageResult (``extra['controller']`` the controller; ``converged`` False when
    ``max_steps`` ran out first)."""
    t = np.asarray(stresses, dtype=float)
    if t.shape != (3,):
        raise ParameterError(f"stresses={stresses!r}: must be 3 values (sigma_x, sigma_y, "
                             "sigma_z), Pa")
    for a in range(3):
        _check_target(float(t[a]), f"stresses[{a}]")
    if controller is None:
        controller = _core.TriaxialController(
            walls=list(walls), gain=gain,
            max_speed=max_speed if max_speed is not None else default_max_speed(scene, walls))
        scene.add_controller(controller)
    for a in range(3):
        controller.set_stress(a, float(t[a]))
    controller.enabled = True
    start = scene.step_count
    ok, ax, u = False, None, float("nan")
    bar = Progress("servo stage")
    while scene.step_count - start < max_steps:
        scene.run(check_every)
        ok, ax, u = _stable(scene, walls, t, tol, unbalanced)
        if callback is not None:
            callback(scene)
        if ok:
            break
        bar.update(None, f"step {scene.step_count - start} of at most {max_steps}, stresses "
                         f"{', '.join(f'{x / 1e3:.4g}' for x in ax)} kPa (targets "
                         f"{', '.join(f'{x / 1e3:.4g}' for x in t)}), unbalanced {u:.3g}")
    return StageResult(ok, scene.step_count - start, ax, float(ax.mean()), u,
                       measure.porosity(scene, walls), {"controller": controller})


def solve_to_equilibrium(scene, *, unbalanced: float = 0.01, check_every: int = 200,
                         max_steps: int = 200_000, callback=None) -> tuple[bool, int, float]:
    """Runs ``scene`` until its unbalanced force (Yade's definition, -) is below
    ``unbalanced``, checking every ``check_every`` steps; returns (converged, steps run,
    unbalanced force). Without contacts the unbalanced force is undefined and the scene is
    not in equilibrium (it runs on until ``max_steps``)."""
    if not (math.isfinite(unbalanced) and unbalanced > 0):
        raise ParameterError(f"unbalanced={unbalanced}: must be > 0 (-)")
    if check_every < 1 or max_steps < 1:
        raise ParameterError(f"check_every={check_every}, max_steps={max_steps}: must be >= 1")
    start = scene.step_count
    u = float("nan")
    while scene.step_count - start < max_steps:
        scene.run(min(check_every, max_steps - (scene.step_count - start)))
        u = float(scene.unbalanced_force())
        if callback is not None:
            callback(scene)
        if u < unbalanced:
            return True, scene.step_count - start, u
    return False, scene.step_count - start, u


def add_growth(scene, walls, stress: float, *, gain: float = 0.5, max_strain: float = 1e-3,
               period: int = 1, bodies=(), grown_only: bool = False):
    """The RadiusGrowth controller that :func:`grow_to_stress` runs, added to ``scene`` and
    returned (a checkpoint's skeleton adds the same one: cpp_dem.elements.box
    ``prepare_woven_element(build_only=True)``)."""
    g = _core.RadiusGrowth(walls=list(walls), bodies=[int(b) for b in bodies],
                           target_stress=stress, gain=gain, max_strain=max_strain,
                           grown_only=grown_only)
    g.period = period
    scene.add_controller(g)
    return g


def grow_to_stress(scene, walls, stress: float, *, tol: float = 0.01, unbalanced: float = 0.01,
                   gain: float = 0.5, max_strain: float = 1e-3, period: int = 1,
                   check_every: int = 200, max_steps: int = 200_000, bodies=(),
                   callback=None, axes_tol: float | None = None, checks: int = 1,
                   min_coordination: float = 0.0, grown_only: bool = False) -> StageResult:
    """Radius expansion with fixed walls until the mean wall stress is within ``tol`` of
    ``stress`` (Pa) and the unbalanced force is below ``unbalanced`` (001 §4.3.1). The
    RadiusGrowth controller is removed from duty (disabled) at the end.

    grown_only: the growth counts only the contacts that touch the growing ``bodies``, and no
    bonds (RadiusGrowth.grown_only); in a periodic cell the stress reached is then those
    grains' mean normal stress (RadiusGrowth.measured_stress), not the cell's: a sheet of
    bonded spheres among them does not offset the target (docs/periodic.md).

    axes_tol: every axis stress must also be within this (relative) of ``stress``; checks:
    the criteria must hold at that many checks in a row (a loose sample hit hard by the
    growth can pass one check in passing); min_coordination: the grains' coordination number
    (measure.coordination_number, -) must also reach this (a loose cloud whose grains bounce
    off the walls can show the target stress without carrying it)."""
    _check_target(stress)
    for w in walls:
        scene.set_wall_velocity(int(w), (0.0, 0.0, 0.0))
    g = add_growth(scene, walls, stress, gain=gain, max_strain=max_strain, period=period,
                   bodies=bodies, grown_only=grown_only)
    start = scene.step_count
    ok, u, mean, passed = False, float("nan"), float("nan"), 0
    while scene.step_count - start < max_steps:
        scene.run(check_every)
        mean = float(g.measured_stress if grown_only and not walls
                     else measure.wall_stresses(scene, walls).mean())
        u = float(scene.unbalanced_force())
        if callback is not None:
            callback(scene)
        ax = measure.axis_stresses(scene, walls) if axes_tol is not None else np.array([mean])
        if (abs(mean - stress) <= tol * stress and u < unbalanced
                and np.all(np.abs(ax - stress) <= (axes_tol or tol) * stress)
                and (min_coordination <= 0
                     or measure.coordination_number(scene) >= min_coordination)):
            passed += 1
            if passed >= checks:
                ok = True
                break
        else:
            passed = 0
    g.enabled = False
    return StageResult(ok, scene.step_count - start, measure.axis_stresses(scene, walls), mean,
                       u, measure.porosity(scene, walls),
                       {"growth_factor": g.total_factor, "controller": g})


@dataclass
class RefdResult:
    """Outcome of REFD: achieved stress (Pa), porosity (-), the friction angle (deg) at which
    the target porosity was reached, and the stages."""

    stress: float
    porosity: float
    friction_deg_reached: float
    steps: int
    stages: list


#: The loosest porosity target REFD takes, -. No cohesionless packing under stress is that
#: loose: random loose packing of frictional spheres has a porosity of about 0.45 (Onoda &
#: Liniger 1990), and the loosest stable packings of angular or elongated grains of moderate
#: aspect ratio stay below 0.6.
POROSITY_MAX = 0.6
#: The densest packing of equal spheres (Kepler; Hales 2005): porosity 1 - pi / (3 sqrt 2), -.
POROSITY_EQUAL_SPHERES_MIN = 1.0 - math.pi / (3.0 * math.sqrt(2.0))
#: A porosity reached this far (absolute, -) below a target taken as a maximum is reported.
POROSITY_MISS = 0.02


def check_porosity_target(porosity: float, radii=None) -> None:
    """Refuses a porosity target (-) that no packing reaches: outside (0, POROSITY_MAX], or,
    for grains of one size (``radii``, m), below the densest packing of equal spheres. (A
    polydisperse sample packs denser; REFD then says what it reached when it cannot.)"""
    if not (isinstance(porosity, (int, float)) and math.isfinite(porosity)
            and 0 < porosity <= POROSITY_MAX):
        raise ParameterError(
            f"porosity={porosity}: must be in (0, {POROSITY_MAX}] (-); no cohesionless "
            f"packing under stress is looser than about {POROSITY_MAX} (random loose packing "
            "of frictional spheres: about 0.45)")
    if radii is not None and len(radii):
        r = np.asarray(radii, dtype=float)
        if r.max() - r.min() <= 1e-9 * r.max() and porosity < POROSITY_EQUAL_SPHERES_MIN:
            raise ParameterError(
                f"porosity={porosity}: below {POROSITY_EQUAL_SPHERES_MIN:.4f}, the densest "
                f"packing of equal spheres (these {len(r)} grains have one radius, "
                f"{r[0]:g} m); no packing of them reaches it")


def refd(scene, walls, material_id: int, *, stress: float, porosity: float,
         friction_steps_deg=(20.0, 10.0, 5.0, 2.0, 0.0), tol: float = 0.01,
         unbalanced: float = 0.01, max_steps_per_stage: int = 100_000, gain: float = 0.5,
         max_strain: float = 1e-3, check_every: int = 200, accept_denser: bool = False,
         log=None) -> RefdResult:
    """REFD (000 §2.3): (1) expand the radii to ``stress`` (Pa) at the material's friction;
    (2) lower the grains' friction step by step (``friction_steps_deg``) and keep expanding
    at that stress until the porosity is at or below ``porosity`` (-); (3) restore the
    friction and re-balance at the stress. Walls stay fixed (frictionless walls are the
    caller's material choice, as 000). Raises ParameterError when the sample is already
    denser than the target after stage 1, or when the target is not reached at the lowest
    friction (the message gives the porosity reached). With ``accept_denser`` a sample already
    at or below the target after stage 1 is accepted as it is (the target is a maximum)."""
    _check_target(stress)
    spheres = np.flatnonzero(measure.sphere_mask(scene))  # grains only, not geogrid nodes
    check_porosity_target(porosity, np.asarray(scene.radii)[spheres])
    mat = scene.material(material_id)
    stages = []
    r1 = grow_to_stress(scene, walls, stress, tol=tol, unbalanced=unbalanced, gain=gain,
                        max_strain=max_strain, check_every=check_every,
                        max_steps=max_steps_per_stage)
    stages.append(("expand", mat.friction_angle_deg, r1))
    if log:
        log(f"REFD expand: stress {r1.mean_stress:.4g} Pa, porosity {r1.porosity:.4f}")
    if r1.porosity <= porosity and accept_denser:
        if log:
            log(f"REFD: porosity {r1.porosity:.4f} after expansion is already at or below "
                f"the target {porosity}; no friction decrease needed")
        if r1.porosity < porosity - POROSITY_MISS:
            import warnings

            warnings.warn(TargetNotMetWarning(
                f"porosity={porosity}: not met; the expansion to {stress:g} Pa already packed "
                f"the sample to porosity {r1.porosity:.4f}, denser than the target, and REFD "
                "only densifies (accept_denser takes the target as a maximum); ask for a "
                f"porosity of at most {r1.porosity + POROSITY_MISS:.3f}, or grow the sample "
                "at a higher friction for a looser one"), stacklevel=2)
        return RefdResult(r1.mean_stress, r1.porosity, mat.friction_angle_deg, r1.steps, stages)
    if r1.porosity <= porosity:
        raise ParameterError(f"porosity={porosity}: the sample is already denser (porosity "
                             f"{r1.porosity:.4f} at {stress} Pa after expansion); REFD only "
                             "densifies; ask for a porosity above that")
    reached = None
    last = r1
    for phi in friction_steps_deg:
        if phi >= mat.friction_angle_deg:
            continue
        set_friction(scene, spheres, mat, phi)
        last = grow_to_stress(scene, walls, stress, tol=tol, unbalanced=unbalanced, gain=gain,
                              max_strain=max_strain, check_every=check_every,
                              max_steps=max_steps_per_stage)
        stages.append(("friction", phi, last))
        if log:
            log(f"REFD friction {phi} deg: porosity {last.porosity:.4f}")
        if last.porosity <= porosity:
            reached = phi
            break
    if reached is None:
        raise ParameterError(f"porosity={porosity}: not reachable; REFD reached "
                             f"{last.porosity:.4f} at {stress} Pa with friction down to "
                             f"{min(friction_steps_deg)} deg (this PSD packs no denser here); "
                             "ask for a porosity of at least that")
    # Restore the friction: the grains take back their original material.
    for b in spheres:
        scene.set_body_material(int(b), material_id)
    r3 = grow_to_stress(scene, walls, stress, tol=tol, unbalanced=unbalanced, gain=gain,
                        max_strain=max_strain, check_every=check_every,
                        max_steps=max_steps_per_stage)
    stages.append(("restore", mat.friction_angle_deg, r3))
    steps = sum(s[2].steps for s in stages)
    return RefdResult(r3.mean_stress, r3.porosity, reached, steps, stages)


def _pair_overlaps(c: np.ndarray, r: np.ndarray):
    """All overlapping sphere pairs (i < j): (pairs, overlap / smaller radius, centre
    distance, sum of radii, smaller radius)."""
    empty = (np.zeros((0, 2), int),) + (np.zeros(0),) * 4
    if len(r) < 2:
        return empty
    h = 2.0 * float(r.max())
    cell = np.floor((c - c.min(0)) / h).astype(np.int64)
    cells: dict = {}
    for k, key in enumerate(map(tuple, cell)):
        cells.setdefault(key, []).append(k)
    cells = {k: np.asarray(v) for k, v in cells.items()}
    pairs = []
    offs = [(a, b, d) for a in (-1, 0, 1) for b in (-1, 0, 1) for d in (-1, 0, 1)]
    for key, idx in cells.items():
        for o in offs:
            nb = cells.get((key[0] + o[0], key[1] + o[1], key[2] + o[2]))
            if nb is None:
                continue
            d = np.linalg.norm(c[idx][:, None, :] - c[nb][None, :, :], axis=2)
            ii, jj = np.nonzero(d < r[idx][:, None] + r[nb][None, :])
            a, b = idx[ii], nb[jj]
            keep = a < b
            if np.any(keep):
                pairs.append(np.column_stack([a[keep], b[keep]]))
    if not pairs:
        return empty
    p = np.vstack(pairs)
    dist = np.linalg.norm(c[p[:, 1]] - c[p[:, 0]], axis=1)
    rs = r[p[:, 0]] + r[p[:, 1]]
    rmin = np.minimum(r[p[:, 0]], r[p[:, 1]])
    return p, (rs - dist) / rmin, dist, rs, rmin


@dataclass
class _Overlaps:
    """Spheres of a scene (ids, centres, radii), their overlapping pairs (_pair_overlaps) and
    the centre distance to each wall (inside positive), in one pass."""

    ids: np.ndarray
    c: np.ndarray
    r: np.ndarray
    pairs: tuple
    wall_gaps: list  #: (wall id, gap per sphere, m)

    @classmethod
    def of(cls, scene, walls) -> "_Overlaps":
        ids = np.flatnonzero(measure.sphere_mask(scene))
        c = np.asarray(scene.positions)[ids]
        r = np.asarray(scene.radii)[ids]
        wp = np.asarray(scene.wall_positions)
        ax, se = np.asarray(scene.wall_axes), np.asarray(scene.wall_senses)
        gaps = [(int(w), se[w] * (c[:, ax[w]] - wp[w])) for w in walls]
        return cls(ids, c, r, _pair_overlaps(c, r), gaps)

    def report(self) -> dict:
        out = {"pair": 0.0, "pair_bodies": None, "wall": 0.0, "wall_body": None}
        p, ratio = self.pairs[0], self.pairs[1]
        if len(p):
            k = int(np.argmax(ratio))
            out["pair"] = float(ratio[k])
            out["pair_bodies"] = (int(self.ids[p[k, 0]]), int(self.ids[p[k, 1]]))
        for w, gap in self.wall_gaps:
            ratio = (self.r - gap) / self.r
            k = int(np.argmax(ratio))
            if ratio[k] > out["wall"]:
                out["wall"], out["wall_body"] = float(ratio[k]), (int(self.ids[k]), w)
        return out


def overlap_report(scene, walls=()) -> dict:
    """The largest overlaps in a scene's current configuration, as fractions of the (smaller)
    radius: ``pair`` (sphere-sphere, with the pair), ``wall`` (sphere-wall, with the body and
    wall). Spheres only (grid nodes are skipped). Computed in NumPy from the positions."""
    return _Overlaps.of(scene, walls).report()


def relax_overlaps(scene, walls=(), *, target_ratio: float = 0.01, steps: int = 4000,
                   chunks: int = 40, damping: float = 0.8, log=None) -> dict:
    """Controlled relaxation of initial overlaps (e.g. of a packing read from a file).

    If the largest sphere-sphere or sphere-wall overlap exceeds ``target_ratio`` of the radius,
    every sphere radius is multiplied by the one factor s < 1 that brings the largest overlap
    down to ``target_ratio``; then the radii grow back to their original values in ``chunks``
    equal increments over ``steps`` steps with Cundall local damping ``damping`` (the overlap
    added per increment is (1 - s) / chunks of the radius, resolved before the next one), and
    velocities are zeroed at the end. The radii, masses and damping are restored exactly. Walls
    (ids in ``walls``) stay where they are. Returns the overlaps before and after, and s.
    """
    if not (0 <= target_ratio < 0.5):
        raise ParameterError(f"target_ratio={target_ratio}: must be in [0, 0.5)")
    if steps < chunks or chunks < 1:
        raise ParameterError(f"steps={steps}, chunks={chunks}: need 1 <= chunks <= steps")
    if not (0 <= damping < 1):
        raise ParameterError(f"damping={damping}: must be in [0, 1)")
    ov = _Overlaps.of(scene, walls)
    before = ov.report()
    worst = max(before["pair"], before["wall"])
    if worst <= target_ratio:
        return {"before": before, "after": before, "shrink": 1.0, "steps": 0}
    ids, r = ov.ids, ov.r
    r0_all = np.asarray(scene.radii).copy()
    s = 1.0
    t = target_ratio
    if len(ov.pairs[0]):
        _, _, dist, rs, rmin = ov.pairs
        # ((ri + rj) s - d) / (rmin s) <= t  <=>  s <= d / (ri + rj - t rmin)
        s = min(s, float(np.min(dist / (rs - t * rmin))))
    for w, gap in ov.wall_gaps:
        if np.any(gap <= 0):
            k = int(ids[np.argmin(gap)])
            raise ParameterError(f"body {k}: its centre is outside wall {w}; relax_overlaps "
                                 "cannot push it back in")
        s = min(s, float(np.min(gap / (r * (1 - t)))))
    s *= 1 - 1e-9
    if log:
        log(f"relax_overlaps: largest overlap {worst:.3g} of the radius; radii x {s:.4f}, "
            f"grown back over {steps} steps")
    damp0 = scene.local_damping
    scene.local_damping = damping
    try:
        for k in range(chunks + 1):
            f = s + (1.0 - s) * k / chunks
            rr = r0_all.copy()
            rr[ids] = r * f if k < chunks else r
            scene.radii = rr
            if k < chunks:
                scene.run(steps // chunks)
        scene.run(steps // chunks)
    finally:
        scene.local_damping = damp0
        scene.radii = r0_all
    v = np.asarray(scene.velocities)
    v[ids] = 0.0
    scene.velocities = v
    w = np.asarray(scene.angular_velocities)
    w[ids] = 0.0
    scene.angular_velocities = w
    after = overlap_report(scene, walls)
    return {"before": before, "after": after, "shrink": s, "steps": steps + steps // chunks}


def gravity_deposition(radii, lo, hi, *, material, seed: int = 0, gravity: float = 9.81,
                       local_damping: float = 0.3, max_time: float = 2.0,
                       settled_speed: float = 1e-3, check_every: int = 500,
                       dt_safety: float = 0.3) -> tuple[np.ndarray, np.ndarray, dict]:
    """Deposits the spheres into the box [lo, hi] (m) under gravity (-z): a loose cloud
    (``cpp_dem.build.packing.loose_cloud``) in the box settles until max |v| < ``settled_speed`` (m/s) or
    ``max_time`` (s). ``material`` is a cpp_dem.Material. Returns (centres, radii, info) with
    info: time (s), steps, settled (bool), max_speed (m/s)."""
    c, r = loose_cloud(radii, lo, hi, seed=seed)
    s = Scene(gravity=(0.0, 0.0, -gravity), local_damping=local_damping)
    m = s.add_material(material)
    s.add_box(lo, hi, material=m)
    s.add_spheres(c, r, material=m)
    s.set_auto_timestep(safety=dt_safety, period=100)
    vmax = float("inf")
    while s.time < max_time:
        s.run(check_every)
        vmax = float(np.sqrt((s.velocities**2).sum(1).max()))
        if vmax < settled_speed and s.time > 0.05:
            break
    info = {"time": s.time, "steps": s.step_count, "settled": vmax < settled_speed,
            "max_speed": vmax}
    return s.positions, s.radii, info
