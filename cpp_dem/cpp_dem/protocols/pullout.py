"""Geogrid pull-out test in a box (000 §2.3 and §3; 001 §5 and App. A).

The scene: a box of six frictionless walls, grains in two layers below and above a geogrid
laid fully stretched in the plane z = ``grid_z``; the box walls never touch the geogrid
(``scene.grid_wall_contacts`` stays False), so the geogrid leaves the box through the front
wall (x = lo) as it is pulled, as through the slot of a pull-out box.

Stages (000 §2.3):

1. :func:`prepare` - the geogrid is held fixed while the grains expand to the confining stress
   (REFD: radius expansion, then friction decrease until a target porosity, then friction
   restored; or radius expansion alone); then the geogrid is freed, gravity switched on and
   the top wall servo-controlled to the confining stress until the sample is stable.
2. :func:`pull` - the clamped nodes (the front edge of the geogrid, or every node for 001's
   rigid pull) move at a constant velocity towards -x (displacement control) while the top
   wall holds the confining stress. Recorded: the pull-out force (sum of the clamp reactions),
   the front displacement, the axial forces of the members A (longitudinal) and C (transverse)
   of apertures 1 and 2 (000 Figs 6-8), the top-wall stress, the grid's kinetic energy.

Conventions: x is the pull direction (the geogrid moves towards -x), z is vertical; forces in
N, stresses in Pa (compressive positive for walls, tension positive for geogrid members),
displacements in m. The pull-out force is positive when the soil resists the pull.

Apertures: along the middle row of cells (j = n_cells_y // 2), "aperture k" is the k-th cell,
counted from the front, none of whose A and C members has a link with both ends clamped (a
member held rigidly by the clamp carries no information). With a clamp on the front edge of
a square grid that is cell (1, j); with the front transverse rib of a biaxial grid in the clamp
it is cell (1, j) too. :attr:`PulloutSample.apertures` gives the cells used.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from cpp_dem import _core
from cpp_dem.measure import inertial
from cpp_dem import measure
from cpp_dem.protocols import prep
from cpp_dem._core import Material, ParameterError
from cpp_dem.progress import Progress
from cpp_dem.build.geogrid import Geogrid
from cpp_dem.build.packing import loose_cloud
from cpp_dem.scene import ControllerLimitWarning, Scene

#: Box wall order of Scene.add_box.
X_MINUS, X_PLUS, Y_MINUS, Y_PLUS, Z_MINUS, Z_PLUS = range(6)


@dataclass
class PulloutSample:
    """A pull-out scene: the scene, its six walls, the geogrid and the clamp.

    Attributes
    ----------
    scene, walls : the scene and its wall ids (x-, x+, y-, y+, z-, z+).
    grid : the geogrid (members labelled, see cpp_dem.build.geogrid).
    grain_material : material index of the grains.
    grid_z : height of the geogrid plane, m.
    clamp_nodes : body ids of the nodes the clamp holds and pulls.
    front_nodes : body ids of the nodes of the front edge (x = min). (001's App. A sums the
        back row instead: geogrid_dem.cases.pullout_001, force_001.)
    node_density_scale : the factor on the grid node masses (1 = true masses).
    true_node_masses : the unscaled node masses, kg (their weight is what gravity applies).
    apertures : (2, 2) cells (i, j) of apertures 1 and 2 (see the module docstring).
    top_servo : the ServoWall on the top wall (set by :func:`prepare`).
    """

    scene: Scene
    walls: list
    grid: Geogrid
    grain_material: int
    grid_z: float
    clamp_nodes: np.ndarray
    front_nodes: np.ndarray
    node_density_scale: float
    true_node_masses: np.ndarray
    apertures: np.ndarray
    top_servo: object = None
    info: dict = field(default_factory=dict)

    @property
    def grain_ids(self) -> np.ndarray:
        return np.flatnonzero(measure.sphere_mask(self.scene))

    def box_lo_hi(self) -> tuple[np.ndarray, np.ndarray]:
        """Current box corners (m) from the wall positions."""
        wp = np.asarray(self.scene.wall_positions)
        lo = np.array([wp[self.walls[2 * a]] for a in range(3)])
        hi = np.array([wp[self.walls[2 * a + 1]] for a in range(3)])
        return lo, hi

    def top_stress(self) -> float:
        """Normal stress on the top wall, Pa (compressive positive)."""
        return float(measure.wall_stresses(self.scene, self.walls)[Z_PLUS])

    def aperture_members(self) -> dict[str, int]:
        """Member indices 'A1', 'C1', 'A2', 'C2' (000 Fig. 6); -1 where the grid has no such
        member (e.g. a single chain)."""
        out = {}
        for k, (i, j) in enumerate(self.apertures, start=1):
            cm = self.grid.cell_members(int(i), int(j))
            out[f"A{k}"] = cm.get("A", -1)
            out[f"C{k}"] = cm.get("C", -1)
        return out


def layered_cloud(radii, lo, hi, *, grid_z: float, clearance: float, seed: int = 0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """A loose cloud of spheres (radii in m) in two layers of the box [lo, hi] (m): below
    ``grid_z - clearance`` and above ``grid_z + clearance`` (m), so that no sphere touches the
    geogrid plane. Radii are dealt to the layers alternately from the largest down, so both
    layers get the same size distribution and volumes in proportion to the layers' heights."""
    lo, hi = _layer_box(lo, hi, grid_z, clearance)
    r = np.sort(np.asarray(radii, float).reshape(-1))[::-1]
    to_low = _deal_layers(r, lo, hi, grid_z, clearance)
    c1, r1 = loose_cloud(r[to_low], lo, [hi[0], hi[1], grid_z - clearance], seed=seed)
    c2, r2 = loose_cloud(r[~to_low], [lo[0], lo[1], grid_z + clearance], hi, seed=seed + 1)
    return np.vstack([c1, c2]), np.concatenate([r1, r2])


def _layer_box(lo, hi, grid_z: float, clearance: float) -> tuple[np.ndarray, np.ndarray]:
    """The box as arrays, checked to hold the geogrid plane with its clearance (m)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    if not (lo[2] < grid_z - clearance and grid_z + clearance < hi[2]):
        raise ParameterError(f"grid_z={grid_z}: the geogrid plane with clearance {clearance} m "
                             f"must lie inside the box z range ({lo[2]}, {hi[2]})")
    return lo, hi


def _deal_layers(r, lo, hi, grid_z: float, clearance: float) -> np.ndarray:
    """Which of the sizes r (sorted, largest first) go below the geogrid: dealt so that both
    layers get volumes in proportion to their heights (deterministic)."""
    h_lo = grid_z - clearance - lo[2]
    h_hi = hi[2] - grid_z - clearance
    share = h_lo / (h_lo + h_hi)
    to_low = np.zeros(len(r), bool)
    acc_lo = acc_hi = 0.0
    for k, rk in enumerate(r):  # volume-balanced deal, deterministic
        v = rk**3
        if acc_lo * (1 - share) <= acc_hi * share:
            to_low[k] = True
            acc_lo += v
        else:
            acc_hi += v
    return to_low


def layered_clump_cloud(templates, diameters, lo, hi, *, grid_z: float, clearance: float,
                        seed: int = 0):
    """:func:`layered_cloud` for clumps: equivalent-volume diameters (m) dealt to the two
    layers the same way, each layer a :func:`cpp_dem.build.clumps.clump_cloud` (bounding spheres
    clear of the geogrid plane by ``clearance``). Returns one ClumpCloud."""
    from cpp_dem.build.clumps import ClumpCloud, clump_cloud

    lo, hi = _layer_box(lo, hi, grid_z, clearance)
    d = np.sort(np.asarray(diameters, float).reshape(-1))[::-1]
    to_low = _deal_layers(0.5 * d, lo, hi, grid_z, clearance)
    a = clump_cloud(templates, d[to_low], lo, [hi[0], hi[1], grid_z - clearance], seed=seed)
    b = clump_cloud(templates, d[~to_low], [lo[0], lo[1], grid_z + clearance], hi, seed=seed + 1)
    return ClumpCloud(np.concatenate([a.template, b.template]),
                      np.vstack([a.positions, b.positions]),
                      np.vstack([a.orientations, b.orientations]),
                      np.concatenate([a.scales, b.scales]))


def build_sample(centers, radii, lo, hi, *, grain: Material, grid_builder: Callable,
                 grid_z: float, clamp_depth: float = 0.0, clamp: str = "front",
                 local_damping: float = 0.2, dt_safety: float = 0.5,
                 max_overlap_ratio: float = 0.5, clumps=None) -> PulloutSample:
    """The pull-out scene: grains of material ``grain`` at ``centers``/``radii`` (m) in the box
    [lo, hi] (m) of frictionless walls, and the geogrid made by ``grid_builder(scene)`` (which
    adds it and returns a :class:`Geogrid`, laid in the plane z = ``grid_z``, m).

    clamp: ``"front"`` holds the nodes within ``clamp_depth`` (m) of the grid's front edge
    (x = min), as a clamp gripping the front rib (000); ``"all"`` holds every node: the grid is
    pulled as a rigid body (001 App. A blocks all nodes and gives them the pull velocity).

    clumps: (ClumpCloud, templates) to add clumps instead of the spheres (their members take
    the grain's equivalent radius for their contact stiffness; see Scene.add_clumps).
    """
    if clamp not in ("front", "all"):
        raise ParameterError(f"clamp={clamp!r}: must be 'front' or 'all'")
    if not (math.isfinite(clamp_depth) and clamp_depth >= 0):
        raise ParameterError(f"clamp_depth={clamp_depth}: must be >= 0 (m)")
    sc = Scene(local_damping=local_damping)
    gmat = sc.add_material(grain)
    wall_mat = sc.add_material(grain.replace(  # (the grains' elastic law, frictionless)
        friction_angle_deg=0.0, damping_normal=0.0, damping_shear=0.0, rolling_stiffness=0.0,
        rolling_friction=0.0))
    walls = sc.add_box(lo, hi, material=wall_mat)
    if clumps is not None:
        cloud, templates = clumps
        cloud.add_to(sc, templates, material=gmat, stiffness="grain")
    else:
        sc.add_spheres(centers, radii, material=gmat)
    grid = grid_builder(sc)
    if not isinstance(grid, Geogrid):
        raise ParameterError("grid_builder: must add a geogrid to the scene and return it")
    sc.max_overlap_ratio = max_overlap_ratio
    sc.set_auto_timestep(safety=dt_safety, period=100)
    pos = sc.positions[grid.nodes]
    if np.max(np.abs(pos[:, 2] - grid_z)) > 1e-9:
        raise ParameterError(f"grid_z={grid_z}: the geogrid nodes are not in that plane")
    x0 = pos[:, 0].min()
    front = grid.nodes[pos[:, 0] <= x0 + 1e-9]
    held = grid.nodes if clamp == "all" else grid.nodes[pos[:, 0] <= x0 + clamp_depth + 1e-9]
    masses = np.asarray(sc.masses)[grid.nodes]
    sample = PulloutSample(sc, walls, grid, gmat, float(grid_z), held, front, 1.0, masses,
                           np.zeros((2, 2), int), info={"clamp": clamp,
                                                        "clamp_depth_m": clamp_depth})
    sample.apertures = _apertures(grid, set(held.tolist()), sc)
    return sample


def _apertures(grid: Geogrid, held: set, sc) -> np.ndarray:
    nodes = np.asarray(sc.grid_link_nodes)
    ni, nj = grid.n_cells
    if ni < 1 or nj < 1:
        return np.zeros((2, 2), int)  # no apertures (a chain): members are reported as -1
    j = nj // 2
    found = []
    for i in range(ni):
        cm = grid.cell_members(i, j)
        if "A" not in cm or "C" not in cm:
            continue
        rigid = False
        for side in ("A", "C"):
            for lk in grid.member_section_links[cm[side]]:
                a, b = nodes[lk]
                if int(a) in held and int(b) in held:
                    rigid = True
        if not rigid:
            found.append((i, j))
        if len(found) == 2:
            return np.array(found)
    # Too few free cells (e.g. the whole grid pulled rigidly): use the first two cells.
    return np.array([(0, j), (min(1, ni - 1), j)])


def set_node_density_scale(sample: PulloutSample, scale: float) -> None:
    """Scales the grid node masses and inertias by ``scale`` (>= 1 raises the critical time
    step by sqrt(scale)) while their weight stays the true one: gravity acts on the scaled
    mass and an opposite external force removes the excess, so only the inertia changes."""
    if not (math.isfinite(scale) and scale > 0):
        raise ParameterError(f"node_density_scale={scale}: must be > 0")
    sc = sample.scene
    f = scale / sample.node_density_scale
    m, j = np.asarray(sc.masses), np.asarray(sc.inertias)
    for b in sample.grid.nodes:
        sc.set_mass_inertia(int(b), float(m[b] * f), float(j[b] * f))
    sample.node_density_scale = float(scale)
    _apply_true_weight(sample)


def _apply_true_weight(sample: PulloutSample) -> None:
    sc = sample.scene
    g = np.asarray(sc.gravity, float)
    ext = np.asarray(sc.external_forces)
    m_scaled = sample.true_node_masses * sample.node_density_scale
    ext[sample.grid.nodes] = (sample.true_node_masses - m_scaled)[:, None] * g[None, :]
    sc.external_forces = ext


def auto_node_density_scale(sample: PulloutSample, *, target_ratio: float = 0.25,
                            max_scale: float = 1e6) -> float:
    """The node density scale that brings the grid's critical time step up to
    ``target_ratio`` times the grains' own (at most ``max_scale``; at least 1). Measured on
    the current scene with the grid free and the grains as they are."""
    sc = sample.scene
    if not (0 < target_ratio <= 1):
        raise ParameterError(f"target_ratio={target_ratio}: must be in (0, 1]")
    mask = np.asarray(sc._blocked).copy()
    cmask = np.asarray(sc._clump_blocked).copy() if sc.num_clumps else []
    free = sample.grain_ids
    if sc.num_clumps:
        free = free[np.asarray(sc.clump_ids)[free] < 0]
        sc.block_clump_dofs(np.arange(sc.num_clumps), "all")
    sc.block_dofs(free, "all")
    sc.block_dofs(sample.grid.nodes, "")
    dt_grid = sc.critical_dt()
    for b in free:
        sc._set_blocked(int(b), int(mask[b]))
    for c, m in enumerate(cmask):
        sc._set_clump_blocked(c, int(m))
    sc.block_dofs(sample.grid.nodes, "all")
    dt_grains = sc.critical_dt()
    for b in sample.grid.nodes:
        sc._set_blocked(int(b), int(mask[b]))
    if not (math.isfinite(dt_grid) and math.isfinite(dt_grains)):
        return 1.0
    s = (target_ratio * dt_grains / dt_grid) ** 2 * sample.node_density_scale
    return float(min(max_scale, max(1.0, s)))


@dataclass
class PrepResult:
    """What :func:`prepare` achieved (SI)."""

    porosity: float
    top_stress: float
    unbalanced_force: float
    steps: int
    converged: bool
    refd: object = None
    stages: list = field(default_factory=list)


def prepare(sample: PulloutSample, *, stress: float, porosity: float | None = None,
            growth_stress: float | None = None, gravity: float = 9.81, node_density_scale: float | str = 1.0,
            stable_unbalanced: float = 0.02, stable_tol: float = 0.02,
            max_expansion_strain: float = 2e-4, max_steps_per_stage: int = 200_000,
            check_every: int = 200, log: Callable[[str], None] | None = None) -> PrepResult:
    """000 §2.3: geogrid held fixed; REFD (to ``porosity``) or radius expansion alone
    (``porosity=None``) to the confining ``stress`` (Pa; or to ``growth_stress`` first, as
    001 App. A grows to 10 kPa before the top servo applies the stress) with frictionless
    walls; friction
    restored; geogrid freed (unless the clamp holds all of it); gravity (m/s^2, along -z);
    the top wall servo-controlled to ``stress``; run until the unbalanced force is below
    ``stable_unbalanced`` and the top stress within ``stable_tol`` (relative) of ``stress``.
    ``porosity`` is a maximum: a sample denser than it after the expansion is kept as it is.
    ``node_density_scale`` is a number or ``"auto"`` (:func:`auto_node_density_scale`)."""
    prep._check_target(stress)
    say = log or (lambda s: None)
    sc, walls, grid = sample.scene, sample.walls, sample.grid
    sc.block_dofs(grid.nodes, "all")
    v = np.asarray(sc.velocities)
    v[grid.nodes] = 0.0
    sc.velocities = v
    start = sc.step_count
    res = PrepResult(float("nan"), float("nan"), float("nan"), 0, False)

    def progress(s) -> None:
        if s.step_count % 5000 == 0:
            st = measure.wall_stresses(s, walls)
            say(f"  step {s.step_count}: mean wall stress {st.mean() / 1e3:.2f} kPa, "
                f"porosity {measure.porosity(s, walls):.4f}, unbalanced "
                f"{s.unbalanced_force():.3g}")

    s_grow = stress if growth_stress is None else growth_stress
    prep._check_target(s_grow, "growth_stress")
    if porosity is not None:
        r = prep.refd(sc, walls, sample.grain_material, stress=s_grow, porosity=porosity,
                      tol=0.02, unbalanced=0.05, max_strain=max_expansion_strain,
                      max_steps_per_stage=max_steps_per_stage, check_every=check_every,
                      accept_denser=True, log=say)
        res.refd = r
        say(f"REFD: porosity {r.porosity:.4f} reached at friction {r.friction_deg_reached} deg,"
            f" stress {r.stress / 1e3:.2f} kPa, {r.steps} steps")
    else:
        g = prep.grow_to_stress(sc, walls, s_grow, tol=0.02, unbalanced=0.05,
                                max_strain=max_expansion_strain, max_steps=max_steps_per_stage,
                                check_every=check_every, callback=progress)
        res.stages.append(("expand", g))
        say(f"expansion: {g.steps} steps, growth factor {g.extra['growth_factor']:.4f}, "
            f"mean stress {g.mean_stress / 1e3:.2f} kPa, porosity {g.porosity:.4f}"
            + ("" if g.converged else " (NOT converged)"))
    # Free the geogrid (the clamp takes it at the start of the pull), weight and servo.
    if sample.info["clamp"] != "all":
        sc.block_dofs(grid.nodes, "")
    sc.gravity = (0.0, 0.0, -float(gravity))  # first: the true-weight force depends on it
    if node_density_scale == "auto":
        node_density_scale = auto_node_density_scale(sample)
    set_node_density_scale(sample, float(node_density_scale))
    lo, hi = sample.box_lo_hi()
    area = float((hi[0] - lo[0]) * (hi[1] - lo[1]))
    servo = _core.ServoWall(wall=walls[Z_PLUS], target_stress=stress, area=area, gain=0.5,
                            max_speed=prep.default_max_speed(sc, walls))
    sc.add_controller(servo)
    sample.top_servo = servo
    # The freed (stiff) grid may need a smaller step at once, not at the next automatic update.
    sc.dt = sc.timestep_safety * sc.critical_dt()
    say(f"geogrid {'freed' if sample.info['clamp'] != 'all' else 'held (rigid pull)'}, "
        f"node density scale {sample.node_density_scale:.3g}, gravity {gravity} m/s^2, top "
        f"wall servo at {stress / 1e3:.3g} kPa; dt {sc.dt:.3g} s")
    k0 = sc.step_count
    # The sample settles under gravity while the top servo follows: drift at the servo's cap
    # on the way is expected here, and this stage runs until the stress holds within
    # stable_tol, so it is not reported (ControllerLimitWarning watches the pull).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ControllerLimitWarning)
        while sc.step_count - k0 < max_steps_per_stage:
            sc.run(check_every)
            u = float(sc.unbalanced_force())
            top = sample.top_stress()
            progress(sc)
            if u < stable_unbalanced and abs(top - stress) <= stable_tol * stress:
                res.converged = True
                break
    servo.clear_limit_report()
    res.top_stress = sample.top_stress()
    res.unbalanced_force = float(sc.unbalanced_force())
    res.porosity = measure.porosity(sc, walls)
    res.steps = sc.step_count - start
    say(f"stabilised: top stress {res.top_stress / 1e3:.3f} kPa, unbalanced "
        f"{res.unbalanced_force:.3g}, porosity {res.porosity:.4f}, dt {sc.dt:.3g} s"
        + ("" if res.converged else " (NOT converged: limits reached)"))
    return res


def open_front_slot(sample: PulloutSample, half_height: float) -> None:
    """Opens a slot in the front wall (x-, where the grid leaves the box): z within
    ``half_height`` (m) of the grid plane z = grid_z (``Scene.set_wall_opening``), as a
    pull-out box's slot. A grain whose centre is in the slot meets only the slot's edges
    (lines across the wall), so a grain a transverse bar pushes head-on leaves the box
    instead of being squeezed against the wall; grains that leave stay in the scene, beyond
    the wall. The slot must be wider than every grain (half_height above the largest grain
    radius): a grain that fits in no slot touches both its edges."""
    if not (math.isfinite(half_height) and half_height > 0):
        raise ParameterError(f"half_height={half_height}: must be > 0 (m)")
    r_max = float(np.max(np.asarray(sample.scene.radii)[sample.grain_ids])) \
        if len(sample.grain_ids) else 0.0
    if half_height <= r_max:
        raise ParameterError(f"half_height={half_height}: must exceed the largest grain "
                             f"radius {r_max:g} m (a narrower slot lets no grain through)")
    lo, hi = sample.box_lo_hi()
    if sample.grid_z - half_height <= lo[2] or sample.grid_z + half_height >= hi[2]:
        raise ParameterError(f"half_height={half_height}: the slot must lie inside the box, "
                             f"z in ({lo[2]:g}, {hi[2]:g}) m, around the grid plane "
                             f"z = {sample.grid_z:g} m")
    sample.scene.set_wall_opening(sample.walls[X_MINUS], axis=2,
                                  lo=sample.grid_z - half_height,
                                  hi=sample.grid_z + half_height)


def inertial_number(velocity: float, density: float, stress: float) -> float:
    """Inertial number of the pull, I = gamma_dot d sqrt(rho / sigma) with the shear rate
    gamma_dot = v / d of a shear zone one grain thick on the geogrid: I = v sqrt(rho / sigma)
    (v m/s, rho kg/m^3, sigma Pa). Below about 1e-3 the flow is quasi-static."""
    return float(velocity * math.sqrt(density / stress))


def _check_pull_rate(sample: PulloutSample, velocity: float) -> None:
    """Warns (cpp_dem.InertialNumberWarning) when the pull is not quasi-static: the shear
    zone on the geogrid is one mean grain diameter d thick, so its rate is v / d and
    I = (v / d) d / sqrt(sigma / rho) (cpp_dem.measure.inertial), sigma the top wall's target (or its
    stress now without a servo)."""
    sc = sample.scene
    stress = (float(sample.top_servo.target_stress) if sample.top_servo is not None
              else sample.top_stress())
    d = measure.grain_diameters(sc)
    if not (stress > 0 and len(d)):
        return  # unconfined, or no grains: no inertial number
    d_mean = float(np.mean(d))
    # (With density scaling the grains are heavier to the pull: the scaled density.)
    from cpp_dem.protocols.quasi_static import effective_density

    rho = effective_density(sc, float(sc.material(sample.grain_material).density))
    value = inertial.inertial_number(velocity / d_mean, d_mean, stress, rho)
    inertial.check_quasi_static(value, "pull-out", rate=velocity, rate_name="pull velocity",
                                rate_unit="m/s", diameter=d_mean, pressure=stress,
                                density=rho, stacklevel=3)


def pull_record(sample: PulloutSample, x_ref: float, members: dict) -> dict:
    """One row of the pull-out record (SI)."""
    sc = sample.scene
    f = np.asarray(sc.forces)
    pos = np.asarray(sc.positions)
    vel = np.asarray(sc.velocities)
    m = np.asarray(sc.masses)[sample.grid.nodes]
    mf = sample.grid.member_axial_forces(sc)
    row = {"time": float(sc.time), "step": int(sc.step_count),
           "displacement": float(x_ref - pos[sample.clamp_nodes, 0].mean()),
           "pull_force": float(f[sample.clamp_nodes, 0].sum()),
           "front_force": float(f[sample.front_nodes, 0].sum()),
           "top_stress": sample.top_stress(),
           "top_wall_z": float(np.asarray(sc.wall_positions)[sample.walls[Z_PLUS]]),
           "unbalanced_force": float(sc.unbalanced_force()),
           "grid_kinetic_energy": float(0.5 * np.sum(m * (vel[sample.grid.nodes] ** 2).sum(1))),
           "max_member_force": float(mf.max()) if len(mf) else 0.0}
    for k, idx in members.items():
        row[f"force_{k}"] = float(mf[idx]) if idx >= 0 else float("nan")
        row[f"stress_{k}"] = float(mf[idx] / sample.grid.area[idx]) if idx >= 0 \
            else float("nan")
    return row


PULL_UNITS = {"time": "s", "step": "-", "displacement": "m", "pull_force": "N",
              "front_force": "N", "top_stress": "Pa", "top_wall_z": "m",
              "unbalanced_force": "-", "grid_kinetic_energy": "J", "max_member_force": "N",
              **{f"force_{k}": "N" for k in ("A1", "C1", "A2", "C2")},
              **{f"stress_{k}": "Pa" for k in ("A1", "C1", "A2", "C2")}}


def pull(sample: PulloutSample, *, velocity: float, distance: float, record_every: int = 50,
         on_record: Callable[[dict], None] | None = None,
         snapshot_displacements: Sequence[float] = (),
         on_snapshot: Callable[[float], None] | None = None,
         max_steps: int = 50_000_000) -> dict:
    """Pulls the clamped nodes at ``velocity`` (m/s, > 0, towards -x) until the front has
    moved ``distance`` (m); records a row (:func:`pull_record`) every ``record_every`` steps
    and calls ``on_snapshot(displacement)`` when the displacement first passes each value of
    ``snapshot_displacements`` (m). Returns the record as arrays."""
    if not (math.isfinite(velocity) and velocity > 0):
        raise ParameterError(f"velocity={velocity}: must be > 0 (m/s; the pull is towards -x)")
    if not (math.isfinite(distance) and distance > 0):
        raise ParameterError(f"distance={distance}: must be > 0 (m)")
    if record_every < 1:
        raise ParameterError(f"record_every={record_every}: must be >= 1")
    sc = sample.scene
    servo = sample.top_servo
    _check_pull_rate(sample, velocity)
    if servo is not None and servo.max_speed < velocity:
        # The soil above the geogrid settles or dilates at a rate of the order of the pull
        # velocity; the preparation's quasi-static cap (prep.default_max_speed) can be far
        # below it for a fast pull (001: 0.06 m/s against 7 mm/s), and the top stress then
        # drifts from its target while the wall runs at the cap. During the pull the top
        # wall may move as fast as the geogrid.
        servo.max_speed = velocity
    sc.block_dofs(sample.clamp_nodes, "all")
    v = np.asarray(sc.velocities)
    v[sample.clamp_nodes] = (-velocity, 0.0, 0.0)
    sc.velocities = v
    w = np.asarray(sc.angular_velocities)
    w[sample.clamp_nodes] = 0.0
    sc.angular_velocities = w
    x_ref = float(np.asarray(sc.positions)[sample.clamp_nodes, 0].mean())
    members = sample.aperture_members()
    snaps = sorted(float(s) for s in snapshot_displacements)
    rows: list[dict] = []

    def take() -> dict:
        r = pull_record(sample, x_ref, members)
        rows.append(r)
        if on_record is not None:
            on_record(r)
        while snaps and r["displacement"] >= snaps[0] - 1e-12:
            d = snaps.pop(0)
            if on_snapshot is not None:
                on_snapshot(d)
        return r

    take()
    k0 = sc.step_count
    bar = Progress("pull-out")
    while rows[-1]["displacement"] < distance and sc.step_count - k0 < max_steps:
        sc.run(record_every)
        r = take()
        bar.update(r["displacement"] / distance,
                   f"{r['displacement'] * 1e3:.3g} of {distance * 1e3:.3g} mm, "
                   f"pull force {r['pull_force']:.4g} N")
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def first_peak(displacement, force, *, drop: float = 0.1, window: int = 5) -> tuple[float, float]:
    """The initial peak of a pull-out curve: the running maximum of the force (smoothed by a
    centred moving average of ``window`` records) at the first point where the smoothed force
    has fallen ``drop`` (relative) below it; the global maximum if it never falls (see
    :func:`peak_found`). Returns (displacement m, force N)."""
    d, f, _ = _first_peak(displacement, force, drop, window)
    return d, f


def peak_found(displacement, force, *, drop: float = 0.1, window: int = 5) -> bool:
    """Whether the smoothed force fell ``drop`` below its running maximum within the record,
    i.e. whether :func:`first_peak` is a peak and not just the largest force so far."""
    return _first_peak(displacement, force, drop, window)[2]


def _first_peak(displacement, force, drop: float, window: int) -> tuple[float, float, bool]:
    f = np.asarray(force, float)
    d = np.asarray(displacement, float)
    if len(f) == 0:
        raise ParameterError("force: empty record")
    w = max(1, min(int(window), len(f)))
    # Centred moving average over the records inside the window (near the ends fewer: a
    # zero-padded average would sag there and fake a drop at the end of a rising curve).
    fs = (np.convolve(f, np.ones(w), mode="same")
          / np.convolve(np.ones_like(f), np.ones(w), mode="same"))
    k_max = 0
    for k in range(len(fs)):
        if fs[k] > fs[k_max]:
            k_max = k
        elif fs[k_max] > 0 and fs[k] < (1 - drop) * fs[k_max]:
            return float(d[k_max]), float(fs[k_max]), True
    k = int(np.argmax(fs))
    return float(d[k]), float(fs[k]), False


def summarize(rec: dict, *, mobilised_from: float = 0.0) -> dict:
    """Statistics of a pull-out record (SI): initial peak (:func:`first_peak`; with
    ``initial_peak_found`` False the force has not dropped yet and it is the largest so far),
    maximum, mean and coefficient of variation of the pull-out force over the displacements beyond
    ``mobilised_from`` (m; 0 = the whole pull, as 001's averages), and of the member forces
    of apertures 1 and 2: mean and maximum of A and C (signed), the ratio of the mean magnitudes
    |C| / |A| (000: about 14 %), and the largest |C| over its mean (000: secondary peaks up to
    4x the mean)."""
    d = rec["displacement"]
    f = rec["pull_force"]
    sel = d > mobilised_from
    if not np.any(sel):
        sel = np.ones_like(d, bool)
    dp, fp, found = _first_peak(d, f, 0.1, 5)
    out = {"initial_peak_force_N": fp, "initial_peak_displacement_m": dp,
           "initial_peak_found": found,
           "max_force_N": float(f.max()), "mean_force_N": float(f[sel].mean()),
           "cov_force": float(f[sel].std() / f[sel].mean()) if f[sel].mean() != 0
           else float("nan"),
           "final_displacement_m": float(d[-1])}
    for k in ("A1", "A2", "C1", "C2"):
        key = f"force_{k}"
        if key in rec:
            out[f"mean_{key}_N"] = float(rec[key][sel].mean())
            out[f"max_{key}_N"] = float(rec[key][sel].max())
    if all(k in rec for k in ("force_A1", "force_A2", "force_C1", "force_C2")):
        # (a grid without transverse members, e.g. of triangles, records none: no ratio)
        # Magnitudes: a transverse rib may carry compression as well as tension.
        a = np.abs(np.concatenate([rec["force_A1"][sel], rec["force_A2"][sel]]))
        c = np.abs(np.concatenate([rec["force_C1"][sel], rec["force_C2"][sel]]))
        out["transverse_over_longitudinal"] = float(np.mean(c) / np.mean(a)) if np.mean(a) \
            else float("nan")
        ratios = [float(np.max(np.abs(rec[f"force_C{k}"][sel])) /
                        np.mean(np.abs(rec[f"force_C{k}"][sel])))
                  for k in (1, 2) if np.mean(np.abs(rec[f"force_C{k}"][sel])) > 0]
        out["transverse_peak_over_mean"] = max(ratios) if ratios else float("nan")
    return out


def read_record(path) -> dict | None:
    """A pull-out record from its CSV (as written by the cases, flushed row by row, so a run
    that stopped early leaves the rows up to the stop); None if the file does not exist."""
    from cpp_dem.io import read_csv_series

    try:
        return read_csv_series(path)
    except FileNotFoundError:
        return None


def apply_preset(sample: PulloutSample, preset) -> None:
    """Applies a speed-accuracy preset (a cpp_dem.presets.Preset or its name) to the pull
    stage of a prepared sample: time-step safety, geogrid node density scale and local
    damping; dt is reset at once. (The loading velocity is the preset's inertial number:
    Preset.velocity.)"""
    from cpp_dem.presets import preset as by_name

    ps = by_name(preset) if isinstance(preset, str) else preset
    sc = sample.scene
    set_node_density_scale(sample, auto_node_density_scale(sample)
                           if ps.node_density_scale == "auto" else float(ps.node_density_scale))
    sc.set_auto_timestep(safety=ps.dt_safety, period=100)
    sc.local_damping = ps.local_damping
    sc.dt = ps.dt_safety * sc.critical_dt()
