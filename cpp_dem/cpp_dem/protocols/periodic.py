"""Periodic cells: packings, preparation and mixed stress/strain control (docs/periodic.md).

A periodic scene (``Scene.set_periodic_cell``) repeats its cell H [0,1)^3 in space; the cell
deforms under the velocity gradient L (``Scene.velocity_gradient``, 1/s, tension positive)
and every grain carries the mean field L x. ``CellController`` drives each component of L
either at an imposed rate or so that a cell stress component reaches a target (Yade's
PeriTriaxController, PFC's periodic servo).

Stresses here are compression positive (as ``measure``); strains and L tension positive (the
continuum convention), since they are the cell's kinematics. SI units.
"""

from __future__ import annotations

import math

import numpy as np

from cpp_dem import fixedorder, measure
from cpp_dem.protocols import prep
from cpp_dem._core import CellController, ParameterError
from cpp_dem.build.packing import loose_cloud
from cpp_dem.scene import Scene


def cube_cell(edge: float) -> np.ndarray:
    """The cell matrix (columns: cell vectors, m) of a cube of edge ``edge`` (m)."""
    if not (math.isfinite(edge) and edge > 0):
        raise ParameterError(f"edge={edge}: must be > 0 (m)")
    return np.eye(3) * float(edge)


def periodic_cloud(radii, edge: float, *, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A loose random cloud of spheres (radii, m) in the cube cell [0, edge)^3 (m), without
    overlaps, also across the periodic faces (random sequential addition, seeded)."""
    cube_cell(edge)
    return loose_cloud(radii, (0.0, 0.0, 0.0), (edge, edge, edge), seed=seed)


def cube_cloud(n: int, radius_mean: float, radius_spread: float, seed: int,
               solid_fraction: float) -> tuple[np.ndarray, np.ndarray, float]:
    """n radii uniform in radius_mean (1 +- radius_spread) (m, seeded) placed as a loose cloud
    (``packing.loose_cloud``, no overlaps with each other or the faces) in the cube [0, edge)^3
    that they fill at ``solid_fraction`` (-). Returns (centres, radii, edge): the start of a
    periodic cube and of a box of six walls alike."""
    if n < 2:
        raise ParameterError(f"n={n}: need at least 2 spheres")
    if not (0 < radius_spread < 1):
        raise ParameterError(f"radius_spread={radius_spread}: must be in (0, 1)")
    if not (0 < solid_fraction <= 0.3):
        raise ParameterError(f"solid_fraction={solid_fraction}: must be in (0, 0.3] (random "
                             "sequential addition jams above it)")
    rng = np.random.default_rng(seed)
    radii = radius_mean * (1.0 + radius_spread * (2.0 * rng.random(n) - 1.0))
    # (libm's pow, not NumPy's r**3: an array's power rounds otherwise on a CPU without
    # AVX-512, and the cell's edge decides where every sphere goes)
    edge = math.pow(float(np.sum(4.0 / 3.0 * np.pi * fixedorder.powers(radii, 3)))
                    / solid_fraction, 1.0 / 3.0)
    centers, radii = periodic_cloud(radii, edge, seed=seed)
    return centers, radii, edge


def periodic_scene(centers, radii, cell, *, material, damping: float = 0.7,
                   periodic=(True, True, True), dt_safety: float = 0.5,
                   dt_period: int = 500) -> Scene:
    """A Scene with the spheres (centres (n, 3) m, radii (n,) m) in the periodic ``cell``
    (3 x 3, columns the cell vectors, m) along the ``periodic`` axes, Cundall local damping
    ``damping`` (-) and the automatic time step (safety ``dt_safety``, updated every
    ``dt_period`` steps). ``material`` is a Material."""
    s = Scene(local_damping=damping)
    m = s.add_material(material)
    s.add_spheres(centers, radii, material=m)
    s.set_periodic_cell(np.asarray(cell, dtype=float), tuple(bool(p) for p in periodic))
    s.set_auto_timestep(dt_safety, dt_period)
    return s


def cell_controller(scene, *, gain: float = 0.3, max_rate: float | None = None) -> CellController:
    """The scene's CellController (the last one added), or a new one added to it. The default
    rate cap lets the cell strain 1e-4 of a grain radius relative to the cell size per step
    (quasi-static), as ``prep.default_max_speed`` does for walls."""
    for i in range(scene.num_controllers() - 1, -1, -1):
        c = scene.controller(i)
        if isinstance(c, CellController):
            return c
    if max_rate is None:
        max_rate = default_max_rate(scene)
    c = CellController(gain=gain, max_rate=max_rate)
    scene.add_controller(c)
    return c


def default_max_rate(scene, fraction: float = 1e-4) -> float:
    """A rate cap for the cell servo, 1/s: the cell's smallest thickness changes by at most
    ``fraction`` of the mean radius per step."""
    r = float(np.mean(np.asarray(scene.radii)))
    thick = float(np.min(measure.box_size(scene, ())))
    return fraction * r / thick / scene.dt


def deformation_gradient(scene) -> np.ndarray:
    """F = H H_ref^-1 (-): the cell's deformation since it was set."""
    # (in a fixed order: NumPy's 3 x 3 product and inverse are BLAS's and LAPACK's, which
    # round as the CPU's kernel does; an element's strain is read from this)
    return fixedorder.matmul3(scene.cell_matrix, fixedorder.inv3(scene.cell_reference))


def small_strain(scene) -> np.ndarray:
    """The symmetric part of F - I (-, tension positive): the small-strain tensor of the cell
    since it was set."""
    f = deformation_gradient(scene) - np.eye(3)
    return 0.5 * (f + f.T)


def drive_cell(scene, *, stress=None, rate=None, tol: float = 0.01, unbalanced: float = 0.01,
               check_every: int = 200, max_steps: int = 200_000, gain: float = 0.3,
               max_rate: float | None = None, steps: int | None = None,
               callback=None, allow_tension: bool | None = None) -> prep.StageResult:
    """Mixed control of the cell. ``stress`` maps components (r, c) to targets (Pa,
    compression positive), or is a 3-vector of normal stresses (sigma_x, sigma_y, sigma_z);
    ``rate`` maps components to imposed rates of L (1/s, tension positive). Components named
    in neither are held (rate 0). ``allow_tension``: sets CellController.allow_tension
    (tensile normal targets, for a cell whose bonds hold them; None leaves it as it is).

    Without ``steps``: runs until every stress target is within ``tol`` (relative to the
    largest target) and the
    unbalanced force is below ``unbalanced`` (or ``max_steps``). With ``steps``: runs exactly
    that many steps (a loading stage). Returns a StageResult (``extra['controller']``,
    ``extra['stress']`` the full cell stress, Pa)."""
    targets: dict = {}
    if stress is not None:
        if isinstance(stress, dict):
            targets = {tuple(int(i) for i in k): float(v) for k, v in stress.items()}
        else:
            t = np.asarray(stress, dtype=float)
            if t.shape != (3,):
                raise ParameterError(f"stress={stress!r}: a dict {{(r, c): Pa}} or 3 normal "
                                     "stresses (Pa)")
            targets = {(a, a): float(t[a]) for a in range(3)}
    rates = {tuple(int(i) for i in k): float(v) for k, v in (rate or {}).items()}
    both = set(targets) & set(rates)
    if both:
        raise ParameterError(f"components {sorted(both)}: given both a stress and a rate")
    c = cell_controller(scene, gain=gain, max_rate=max_rate)
    if max_rate is not None:
        c.max_rate = max_rate
    if allow_tension is not None:
        c.allow_tension = bool(allow_tension)
    for r in range(3):
        for q in range(3):
            if (r, q) in targets:
                c.set_stress(r, q, targets[(r, q)])
            else:
                c.set_rate(r, q, rates.get((r, q), 0.0))
    c.enabled = True
    start = scene.step_count
    ok = False
    u = float("nan")
    while scene.step_count - start < (steps if steps is not None else max_steps):
        left = (steps if steps is not None else max_steps) - (scene.step_count - start)
        scene.run(min(check_every, left))
        u = float(scene.unbalanced_force())
        if callback is not None:
            callback(scene)
        if steps is None:
            sig = np.asarray(scene.cell_stress())
            sym = 0.5 * (sig + sig.T)
            # (relative to the largest target: a zero shear target is met within tol of the
            # normal stresses, not of 1 Pa)
            scale = max([abs(v) for v in targets.values()] + [1.0])
            ok = all(abs(sym[k] - v) <= tol * scale for k, v in targets.items())
            ok = ok and u < unbalanced
            if ok:
                break
    if steps is not None:
        ok = True
    sig = np.asarray(scene.cell_stress())
    ax = np.diag(sig).copy()
    return prep.StageResult(ok, scene.step_count - start, ax, float(ax.mean()), u,
                            measure.porosity(scene, ()), {"controller": c, "stress": sig})


def prepare_periodic(n: int, *, material, stress: float, radius_mean: float,
                     radius_spread: float = 0.2, seed: int = 1, solid_fraction: float = 0.25,
                     porosity: float | None = None, prep_friction_deg: float | None = None,
                     damping: float = 0.7, tol: float = 0.01, unbalanced: float = 0.01,
                     max_steps: int = 200_000, growth_gain: float = 0.5,
                     growth_max_strain: float = 1e-3, log=None) -> Scene:
    """A periodic cube of ``n`` spheres (radii uniform in radius_mean (1 +- radius_spread), m)
    prepared to an isotropic ``stress`` (Pa): a loose cloud at ``solid_fraction``, radius
    growth to the stress in the fixed cell (at ``prep_friction_deg`` if given, then the
    material's friction), and an isotropic cell servo to equilibrium. With ``porosity`` (-)
    REFD (000 §2.3) densifies it to that porosity instead. ``growth_gain`` and
    ``growth_max_strain`` are RadiusGrowth's (fast growth overshoots and leaves a denser
    packing: docs/periodic.md). The preparation's controllers are removed at the end; the
    scene is at rest at the stress."""
    centers, radii, edge = cube_cloud(n, radius_mean, radius_spread, seed, solid_fraction)
    scene = periodic_scene(centers, radii, cube_cell(edge), material=material, damping=damping)
    settle_grains(scene, stress=stress, porosity=porosity,
                  prep_friction_deg=prep_friction_deg, tol=tol, unbalanced=unbalanced,
                  max_steps=max_steps, growth_gain=growth_gain,
                  growth_max_strain=growth_max_strain, log=log)
    return scene


def settle_grains(scene, *, stress: float, porosity: float | None = None,
                  prep_friction_deg: float | None = None, tol: float = 0.01,
                  unbalanced: float = 0.01, max_steps: int = 200_000, log=None,
                  **grow) -> None:
    """The stages of ``prepare_periodic`` after the cloud: ``grow_grains`` (``grow``: its
    grains, grain_material, growth_gain, growth_max_strain), then the isotropic cell servo
    to ``stress`` (Pa) in equilibrium, and the controllers are removed."""
    grow_grains(scene, stress=stress, porosity=porosity, prep_friction_deg=prep_friction_deg,
                tol=tol, unbalanced=unbalanced, max_steps=max_steps, log=log, **grow)
    res = drive_cell(scene, stress=(stress, stress, stress), tol=tol, unbalanced=unbalanced,
                     max_steps=max_steps)
    if log:
        log(f"isotropic servo: {res.mean_stress:.4g} Pa, porosity {res.porosity:.4f}, "
            f"unbalanced {res.unbalanced_force:.3g}, converged {res.converged}")
    if not res.converged:
        raise RuntimeError(f"prepare_periodic: the cell did not settle at {stress} Pa in "
                           f"{max_steps} steps (reached {res.axis_stresses} Pa, unbalanced "
                           f"{res.unbalanced_force:.3g}); raise max_steps or loosen tol")
    scene.clear_controllers()
    scene.velocity_gradient = np.zeros((3, 3))


def grow_grains(scene, *, stress: float, grains=None, grain_material: int = 0,
                porosity: float | None = None, prep_friction_deg: float | None = None,
                tol: float = 0.01, unbalanced: float = 0.01, max_steps: int = 200_000,
                growth_gain: float = 0.5, growth_max_strain: float = 1e-3,
                log=None) -> None:
    """The grains grow in the fixed cell to ``stress`` (Pa): at ``prep_friction_deg`` first if
    given, then at their material's friction; REFD (000 §2.3) to ``porosity`` instead.

    ``grains``: the ids of the growing spheres, all of material ``grain_material`` (default:
    every body, numbered from 0). Given, the growth counts only their contacts and no bonds
    (RadiusGrowth.grown_only), so the stress it reaches is theirs, not the cell's."""
    n = scene.num_bodies if grains is None else len(grains)
    ids = np.arange(n) if grains is None else np.asarray(grains, dtype=int)
    only = {} if grains is None else {"bodies": ids, "grown_only": True}
    if porosity is not None:
        if grains is not None:
            raise ParameterError("porosity: REFD to a porosity needs a cell of grains alone "
                                 "(grains=None)")
        prep.refd(scene, (), 0, stress=stress, porosity=porosity, tol=tol,
                  unbalanced=unbalanced, max_steps_per_stage=max_steps, gain=growth_gain,
                  max_strain=growth_max_strain, log=log)
        return
    if prep_friction_deg is not None:
        m = int(grain_material)
        prep.set_friction(scene, ids, scene.material(m), prep_friction_deg)
        r = prep.grow_to_stress(scene, (), stress, tol=tol, unbalanced=unbalanced,
                                max_steps=max_steps, gain=growth_gain,
                                max_strain=growth_max_strain, **only)
        if log:
            log(f"growth at {prep_friction_deg} deg: {r.mean_stress:.4g} Pa, porosity "
                f"{r.porosity:.4f}")
        for b in ids:
            scene.set_body_material(int(b), m)
    r = prep.grow_to_stress(scene, (), stress, tol=tol, unbalanced=unbalanced,
                            max_steps=max_steps, gain=growth_gain,
                            max_strain=growth_max_strain, **only)
    if log:
        log(f"growth: {r.mean_stress:.4g} Pa, porosity {r.porosity:.4f}")


def plane_strain_biaxial(scene, *, pressure: float, strain: float,
                         strain_per_step: float = 5e-7, points: int = 100,
                         progress=None) -> dict:
    """A drained plane-strain biaxial test of a periodic cell, the direct-DEM reference of
    ``femcoupling.coupling.hierarchical``'s biaxial: the cell's z is shortened at a constant rate
    (``strain_per_step`` per step, -) to the axial ``strain`` (-, compression positive); x is
    servo-controlled to ``pressure`` (Pa, compression positive) with the x–z shear stress at
    zero; y (out of plane) and the other shears are held. The FEM's (x, y) is the cell's
    (x, z), as in ``femcoupling.coupling.hierarchical.dem_increment``.

    Returns arrays sampled ``points`` times (compression positive): ``axial_strain``,
    ``volumetric_strain`` (-tr of the small strain since the start), ``sigma_x``,
    ``sigma_z`` (Pa), and the peak: ``peak_sigma_z`` (Pa), ``peak_axial_strain`` and
    ``peak_volumetric_strain``. ``progress(fraction)`` is called at every sample."""
    if not (pressure > 0 and math.isfinite(pressure)):
        raise ParameterError(f"pressure={pressure}: must be > 0 (Pa)")
    if not (0 < strain < 0.5):
        raise ParameterError(f"strain={strain}: the axial strain must be in (0, 0.5) (-)")
    if not (0 < strain_per_step <= 1e-4):
        raise ParameterError(f"strain_per_step={strain_per_step}: must be in (0, 1e-4] (-); "
                             "quasi-static loading needs a small one")
    if int(points) < 2:
        raise ParameterError(f"points={points}: must be >= 2")
    dt = float(scene.dt)
    steps = int(math.ceil(strain / strain_per_step))
    every = max(1, steps // int(points))
    e0 = small_strain(scene)
    rows = []

    def sample(sc) -> None:
        st = np.asarray(sc.cell_stress())
        e = small_strain(sc) - e0
        rows.append((-e[2, 2], -float(np.trace(e)), st[0, 0], st[2, 2]))
        if progress is not None:
            progress(len(rows) * every / steps)

    r = drive_cell(scene, stress={(0, 0): float(pressure), (0, 2): 0.0},
                   rate={(2, 2): -strain_per_step / dt}, steps=steps, check_every=every,
                   callback=sample)
    r.extra["controller"].enabled = False
    scene.velocity_gradient = np.zeros((3, 3))
    a = np.array(rows)
    k = int(np.argmax(a[:, 3]))
    return {"axial_strain": a[:, 0], "volumetric_strain": a[:, 1], "sigma_x": a[:, 2],
            "sigma_z": a[:, 3], "peak_sigma_z": float(a[k, 3]),
            "peak_axial_strain": float(a[k, 0]), "peak_volumetric_strain": float(a[k, 1])}


def bond_branches(scene) -> np.ndarray:
    """Each bond's branch a -> b, to b's nearest image (bonds are shorter than half the
    cell), m, shape (n_bonds, 3)."""
    ab = np.asarray(scene.bond_spheres, dtype=int).reshape(-1, 2)
    x = np.asarray(scene.positions)
    h = np.asarray(scene.cell_matrix)
    d = x[ab[:, 1]] - x[ab[:, 0]]
    return d - fixedorder.rows_matmul(np.round(fixedorder.rows_matmul(d, fixedorder.inv3(h).T)),
                                      h.T)


def bond_stress(scene) -> np.ndarray:
    """The bonds' part of the cell stress (Love–Weber: the sum over the bonds of force x
    branch, over the cell volume), Pa, compression positive, 3 x 3. The cell stress less it
    is the grains'."""
    f = np.asarray(scene.bond_state()["force"]).reshape(-1, 3)
    h = np.asarray(scene.cell_matrix)
    return np.einsum("ki,kj->ij", f, bond_branches(scene)) / float(np.linalg.det(h))


def cell_height(scene) -> float:
    """The cell's height, m: its volume over its x–y face (the spacing of the sheets)."""
    h = np.asarray(scene.cell_matrix)
    return float(np.linalg.det(h)) / float(np.linalg.norm(np.cross(h[:, 0], h[:, 1])))


__all__ = ["cube_cell", "periodic_cloud", "cube_cloud", "periodic_scene", "cell_controller",
           "default_max_rate", "deformation_gradient", "small_strain", "drive_cell",
           "prepare_periodic", "settle_grains", "grow_grains", "plane_strain_biaxial",
           "bond_branches", "bond_stress", "cell_height", "CellController"]
