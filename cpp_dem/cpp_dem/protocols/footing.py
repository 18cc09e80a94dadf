"""A direct DEM of a plane-strain strip footing: a box of spheres, a rigid smooth footing
pushed into it next to a symmetry plane, a surcharge held on the rest of the surface.

It is the direct reference of a hierarchical FEM x DEM of the same body, whose quadrature
points are periodic cells of the same grains (``DemElement.periodic``): both start from the
same state, the isotropic stress q (the surcharge) everywhere, without gravity.

Geometry (SI units, z up, stresses and pressures compression positive, settlements downward
positive):

- x from 0 (the symmetry plane: a smooth fixed wall) to ``length`` (a smooth fixed wall);
- y from 0 to ``thickness``: two smooth fixed walls (plane strain), or, with
  ``periodic_y``, a periodic cell along y (``Scene.set_periodic_cell(h, (False, True,
  False))``): no wall out of the plane, the grains meet their own images there, and y is
  held during the load (plane strain without the walls' loose layers);
- z from 0 (a smooth fixed bottom wall) to ``depth`` (the top);
- on the top, the footing over 0 <= x <= ``footing_b`` (the half width b) and the surcharge
  ``surcharge_pa`` over b < x <= ``length``.

The engine's walls are infinite planes; ``Scene.set_wall_opening`` makes each top wall a
half plane: a grain whose centre lies in the opening passes the wall, and a grain beyond the
plane meets only the opening's edge, the line x = b across the box. So the surcharge is the
old top wall opened over x < b (driven by a ``ServoWall``), and the footing's base a new wall
at the same height opened over x > b (moved by its imposed velocity); its edge is the
footing's corner. Once the footing is below the surcharge, the grains beside it would reach
over that corner into the footing (a half plane has no side face): the footing's side is a
third wall, the plane x = b facing +x, opened below z_f + r_max (z_f the base, r_max the
largest grain radius) and moved with the base. Its opening's edge, r_max above the corner,
and the corner leave a slot narrower than every grain's diameter: no grain passes between
them, and a grain under the base is too far below that edge to touch the side.

:func:`prepare_footing_box` builds and prepares the box (:class:`FootingBoxState`),
:func:`load_strip_footing` splits the top and pushes the footing to a list of settlements.
"""

from __future__ import annotations

import csv
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cpp_dem import _core
from cpp_dem import measure
from cpp_dem._core import Material, ParameterError
from cpp_dem.build.packing import loose_cloud
from cpp_dem.progress import Progress
from cpp_dem.protocols import prep
from cpp_dem.scene import Scene

#: Solid fraction of the loose cloud the grains start from, -: random sequential addition
#: jams above about 0.3 (``cpp_dem.build.packing.loose_cloud``); the periodic cells of
#: ``DemElement.periodic`` start from the same 0.25 (``periodic.cube_cloud``).
CLOUD_SOLID_FRACTION = 0.25
#: Porosity the box is taken to reach, -: the number of grains is the box volume times
#: (1 - this) over the mean grain volume at ``radius_mean``, so that the grains, grown from
#: the cloud, end near ``radius_mean``. (Frictionless growth of radii uniform in r (1 +- 0.2)
#: packs the inside of the box to about 0.34, and its smooth walls loosen the layers next to
#: them: boxes 5 grains thick ended at 0.41-0.43 and their grains at 0.97-0.98 radius_mean.)
PACKED_POROSITY = 0.37
#: Speed cap of the surcharge's servo over the footing's speed, -.
SURCHARGE_SPEED = 10.0
#: Name of the load-settlement file written in ``out`` by :func:`load_strip_footing`.
CSV_NAME = "footing_dem.csv"
#: Columns of each load level (the CSV header and the keys of the returned dict).
COLUMNS = ("settlement_m", "footing_pressure_pa", "surcharge_pa", "unbalanced", "steps",
           "relaxed", "wall_s")


@dataclass
class StripFootingBox:
    """Parameters of the footing box (SI units).

    The grains: radii uniform in ``radius_mean`` (1 +- ``radius_spread``) (they start as a
    loose cloud of smaller radii and grow back to about these), a linear contact law of
    ``young`` and ``poisson`` (k_s / k_n), ``friction_deg``, ``density``. The preparation
    grows them at ``prep_friction_deg`` (0: frictionless, a dense packing, as the periodic
    cells of the FEM x DEM are grown), then at ``friction_deg``, and servos the six smooth
    walls to ``surcharge_pa`` until every wall is within ``tol`` (relative) of it and the
    unbalanced force is below ``unbalanced``. With ``periodic_y`` the box has no y walls:
    it is periodic along y, and the cell's sigma_yy is servoed to ``surcharge_pa`` with the
    four walls (:func:`prepare_footing_box`)."""

    footing_b: float                  #: footing half width b, m (0 <= x <= b)
    length: float                     #: box length from the symmetry plane, m (x)
    depth: float                      #: box depth, m (z)
    thickness: float                  #: box thickness, m (y, plane strain)
    surcharge_pa: float               #: surcharge q and the initial isotropic stress, Pa
    radius_mean: float = 0.003        #: mean grain radius, m
    radius_spread: float = 0.2        #: radii uniform in r_mean (1 +- spread), -
    young: float = 50e6               #: grain Young's modulus (linear law), Pa
    poisson: float = 0.23             #: k_s / k_n of the linear law, -
    friction_deg: float = 38.66       #: grain friction angle, deg
    density: float = 2640.0           #: grain density, kg/m^3
    prep_friction_deg: float = 0.0    #: friction of the first growth, deg (0: dense)
    damping: float = 0.7              #: Cundall local damping, -
    seed: int = 1                     #: seed of the radii and of the cloud
    tol: float = 0.005                #: relative tolerance of the wall stresses, -
    unbalanced: float = 1e-4          #: unbalanced force of an equilibrium, -
    periodic_y: bool = False          #: periodic along y instead of the two y walls

    @property
    def largest_diameter(self) -> float:
        """The largest grain diameter 2 r_mean (1 + spread), m."""
        return 2.0 * self.radius_mean * (1.0 + self.radius_spread)

    def check(self) -> None:
        """Refuses a bad value (ValueError: cpp_dem.ParameterError), naming the field, the
        value and what is allowed."""

        def bad(name: str, allowed: str) -> None:
            raise ParameterError(f"{name}={getattr(self, name)!r}: must be {allowed}")

        def number(v) -> bool:
            return (isinstance(v, (int, float, np.integer, np.floating))
                    and not isinstance(v, bool) and math.isfinite(v))

        for name in ("footing_b", "length", "depth", "thickness", "surcharge_pa",
                     "radius_mean", "young", "density", "tol", "unbalanced"):
            v = getattr(self, name)
            if not (number(v) and v > 0):
                unit = {"surcharge_pa": "Pa, compression positive", "young": "Pa",
                        "density": "kg/m^3", "tol": "-", "unbalanced": "-"}.get(name, "m")
                bad(name, f"a finite number > 0 ({unit})")
        for name, lo, hi, unit in (("radius_spread", 0.0, 1.0, "-"),
                                   ("friction_deg", 0.0, 90.0, "deg"),
                                   ("damping", 0.0, 1.0, "-")):
            v = getattr(self, name)
            if not (number(v) and lo <= v < hi):
                bad(name, f"in [{lo:g}, {hi:g}) ({unit})")
        if not (number(self.poisson) and 0 < self.poisson <= 0.5):
            bad("poisson", "in (0, 0.5] (k_s / k_n of the linear law, -)")
        if not (number(self.prep_friction_deg)
                and 0 <= self.prep_friction_deg <= self.friction_deg):
            bad("prep_friction_deg", f"in [0, friction_deg] = [0, {self.friction_deg:g}] deg")
        if not (self.tol < 0.1):
            bad("tol", "< 0.1 (relative, -)")
        if not (self.unbalanced < 1):
            bad("unbalanced", "< 1 (-)")
        if not (isinstance(self.seed, (int, np.integer)) and not isinstance(self.seed, bool)
                and self.seed >= 0):
            bad("seed", "an integer >= 0")
        if not isinstance(self.periodic_y, (bool, np.bool_)):
            bad("periodic_y", "True or False")
        d = self.largest_diameter
        if not self.footing_b < self.length:
            bad("footing_b", f"< length ({self.length:g} m)")
        if not self.footing_b >= 2 * d:
            bad("footing_b", f">= 2 largest grain diameters ({2 * d:g} m)")
        if not self.length - self.footing_b >= 2 * d:
            bad("length", f">= footing_b + 2 largest grain diameters "
                          f"({self.footing_b + 2 * d:g} m): the surcharge strip")
        if not self.depth >= 2 * d:
            bad("depth", f">= 2 largest grain diameters ({2 * d:g} m)")
        if not self.thickness >= 4 * d:
            bad("thickness", f">= 4 largest grain diameters ({4 * d:g} m)")

    @property
    def cloud_radius_mean(self) -> float:
        """The grains' mean radius in the loose cloud they grow from, m: ``radius_mean``
        shrunk to the cloud's solid fraction (CLOUD_SOLID_FRACTION against 1 -
        PACKED_POROSITY). A periodic cell grown from a cloud of these radii
        (``DemElement.periodic(radius_mean=)`` starts from the same solid fraction) ends
        with grains of about ``radius_mean``, as the box does."""
        shrink = (CLOUD_SOLID_FRACTION / (1.0 - PACKED_POROSITY)) ** (1.0 / 3.0)
        return self.radius_mean * shrink

    @property
    def grain_count(self) -> int:
        """The number of grains: the box volume times (1 - PACKED_POROSITY) over the mean
        grain volume at ``radius_mean`` (-)."""
        v = self.length * self.thickness * self.depth
        # mean of r^3 for r uniform in r_mean (1 +- s): r_mean^3 (1 + s^2)
        vg = 4.0 / 3.0 * math.pi * self.radius_mean**3 * (1.0 + self.radius_spread**2)
        return max(2, int(round((1.0 - PACKED_POROSITY) * v / vg)))

    def material(self) -> Material:
        """The grains' material (the linear law at ``friction_deg``)."""
        return Material(model="linear", density=self.density, young=self.young,
                        poisson=self.poisson, friction_angle_deg=self.friction_deg)


@dataclass
class FootingBoxState:
    """A prepared footing box. ``walls``: the six box walls (x-, x+, y-, y+, z-, z+, the
    ``Scene.add_box`` order), or with ``periodic_y`` the four (x-, x+, z-, z+);
    ``wall_stresses``: the normal stresses at the end of the preparation, Pa, compression
    positive, one per wall of ``walls`` (x-, x+, y, y, z-, z+ with ``periodic_y``: the cell's
    sigma_yy twice). ``walls[-1]`` is the top. After :func:`load_strip_footing`,
    ``footing_wall`` is the footing base's wall id, ``footing_side`` its side's and ``servo``
    the surcharge's ServoWall (``walls[-1]`` is then the surcharge)."""

    scene: Scene
    walls: list
    grains: int                       #: number of grains, -
    porosity: float                   #: of the box at the end of the preparation, -
    wall_stresses: np.ndarray         #: (6,), Pa
    unbalanced: float                 #: at the end of the preparation, -
    grain_ids: np.ndarray             #: body ids of the grains
    grain_material: int               #: material index at friction_deg
    wall_material: int                #: material index of the smooth walls
    top: float                        #: the top wall's position at the end, m
    thickness: float = 0.0            #: the box's extent along y at the end, m
    steps: int = 0                    #: steps of the preparation
    wall_s: float = 0.0               #: wall-clock seconds of the preparation
    stages: list = field(default_factory=list)  #: (name, prep.StageResult)
    footing_wall: int | None = None   #: the footing base's wall id, once loaded
    footing_side: int | None = None   #: the footing side's wall id, once loaded
    servo: object = None              #: the surcharge's ServoWall, once loaded


def _say(log, msg: str) -> None:
    if log is not None:
        log(msg)


def prepare_footing_box(p: StripFootingBox, log=None, *, max_steps: int = 400_000,
                        check_every: int = 200) -> FootingBoxState:
    """Builds the box [0, length] x [0, thickness] x [0, depth] (m) of six smooth fixed walls
    around ``p.grain_count`` grains, and brings it to the isotropic stress
    ``p.surcharge_pa`` (Pa): a loose cloud (``loose_cloud``, solid fraction
    CLOUD_SOLID_FRACTION, the radii shrunk to fit), radius growth in the fixed box at
    ``p.prep_friction_deg`` and then at ``p.friction_deg`` (``prep.grow_to_stress``, as
    ``periodic.grow_grains`` does in a cell), then servo walls (``prep.compact_isotropic``)
    until every wall is within ``p.tol`` of the stress and the unbalanced force is below
    ``p.unbalanced``. ``max_steps``: the step budget of each stage. The controllers are
    removed at the end and the walls stopped.

    With ``p.periodic_y`` the box is a cell periodic along y with the four walls x-, x+, z-,
    z+ (``FootingBoxState.walls``). The growth aims at the box's own mean stress
    (``box_stresses``: the walls' forces over their faces, and sigma_yy from the contacts'
    forces and branch vectors over the box's volume, to which the smooth walls add nothing);
    then a servo brings the four walls and sigma_yy to the stress. The cell's y extent is
    then held.

    Raises RuntimeError when the box does not settle in the budget (with what it reached).
    ``log(msg)`` gets a line per stage."""
    p.check()
    if not (isinstance(max_steps, int) and max_steps >= 1):
        raise ParameterError(f"max_steps={max_steps!r}: must be an integer >= 1")
    t0 = time.perf_counter()
    q = float(p.surcharge_pa)
    n = p.grain_count
    rng = np.random.default_rng(p.seed)
    radii = p.radius_mean * (1.0 + p.radius_spread * (2.0 * rng.random(n) - 1.0))
    hi = (p.length, p.thickness, p.depth)
    centers, r0 = loose_cloud(radii * (p.cloud_radius_mean / p.radius_mean), (0.0, 0.0, 0.0), hi,
                              seed=p.seed)
    scene = Scene(local_damping=p.damping)
    mat = p.material()
    gm = scene.add_material(mat)
    wm = scene.add_material(Material(model="linear", density=p.density, young=p.young,
                                     poisson=p.poisson, friction_angle_deg=0.0))
    if p.periodic_y:
        scene.set_periodic_cell(np.diag(hi), (False, True, False))
        walls = [int(scene.add_wall(axis=a, position=x, sense=sense, material=wm))
                 for a, x, sense in ((0, 0.0, 1), (0, hi[0], -1), (2, 0.0, 1),
                                     (2, hi[2], -1))]
    else:
        walls = scene.add_box((0.0, 0.0, 0.0), hi, material=wm)
    grains = scene.add_spheres(centers, r0, material=gm)
    scene.set_auto_timestep(0.5, 500)
    _say(log, f"footing box {p.length:g} x {p.thickness:g} x {p.depth:g} m: {n} grains, "
              f"cloud at solid fraction {CLOUD_SOLID_FRACTION}, growing to {q:g} Pa")
    k0 = scene.step_count
    stages = []
    # Growth at the preparation friction (frictionless: dense), then at the grains' own.
    frictions = ([p.prep_friction_deg] if p.prep_friction_deg < p.friction_deg else [])
    frictions.append(p.friction_deg)
    for phi in frictions:
        if phi != p.friction_deg:
            prep.set_friction(scene, grains, mat, phi)
        else:
            for b in grains:
                scene.set_body_material(int(b), gm)
        bar, k1 = Progress(f"footing box growth at {phi:g} deg"), scene.step_count

        def tick(sc, bar=bar, k1=k1) -> None:  # (reads the scene only)
            bar.update(None, f"step {sc.step_count - k1} of at most {max_steps}, mean wall "
                             f"stress {float(np.mean(box_stresses(sc, walls))):.4g} "
                             f"Pa (target {q:g}), unbalanced {float(sc.unbalanced_force()):.3g}")

        if p.periodic_y:
            g = _grow_periodic_y(scene, walls, q, p, max_steps, check_every, tick)
        else:
            g = prep.grow_to_stress(scene, walls, q, tol=p.tol, unbalanced=p.unbalanced,
                                    max_steps=max_steps, check_every=check_every,
                                    callback=tick)
        stages.append((f"growth at {phi:g} deg", g))
        _say(log, f"growth at {phi:g} deg: {g.steps} steps, mean wall stress "
                  f"{g.mean_stress:.5g} Pa, porosity {g.porosity:.4f}, unbalanced "
                  f"{g.unbalanced_force:.3g}" + ("" if g.converged else " (not converged)"))
    # Servo walls to the stress on every axis.
    ok, r, ctl = False, None, None
    if p.periodic_y:
        r = _servo_periodic_y(scene, walls, q, p, max_steps, check_every)
        ok = r.converged
        stages.append(("isotropic servo", r))
    for _ in range(0 if p.periodic_y else 3):
        # (equal axis stresses can hide unequal opposite walls: re-check)
        r = prep.compact_isotropic(scene, walls, q, controller=ctl, tol=p.tol,
                                   unbalanced=p.unbalanced, max_steps=max_steps,
                                   check_every=check_every)
        ctl = r.extra["controller"]
        st = measure.wall_stresses(scene, walls)
        ok = r.converged and bool(np.all(np.abs(st - q) <= p.tol * q))
        stages.append(("isotropic servo", r))
        if ok or not r.converged:
            break
    st = box_stresses(scene, walls)
    u = float(scene.unbalanced_force())
    _say(log, f"isotropic servo: {r.steps} steps, wall stresses "
              f"{', '.join(f'{s:.5g}' for s in st)} Pa, unbalanced {u:.3g}")
    if not ok:
        raise RuntimeError(
            f"prepare_footing_box: the box did not settle at {q:g} Pa within tol={p.tol} and "
            f"unbalanced={p.unbalanced} in {max_steps} steps per stage (wall stresses "
            f"{', '.join(f'{s:.5g}' for s in st)} Pa, unbalanced {u:.3g}); raise max_steps "
            "or loosen tol / unbalanced")
    scene.clear_controllers()
    for w in walls:
        scene.set_wall_velocity(int(w), (0.0, 0.0, 0.0))
    if p.periodic_y:
        scene.velocity_gradient = np.zeros((3, 3))  # (y held from here: plane strain)
    porosity = (_box_porosity if p.periodic_y else measure.porosity)(scene, walls)
    state = FootingBoxState(
        scene=scene, walls=list(walls), grains=n, porosity=porosity,
        wall_stresses=st, unbalanced=u, grain_ids=np.asarray(grains), grain_material=gm,
        wall_material=wm, top=float(scene.wall_positions[walls[-1]]),
        thickness=float(box_extents(scene, walls)[1]), steps=scene.step_count - k0,
        wall_s=time.perf_counter() - t0, stages=stages)
    _say(log, f"prepared: porosity {state.porosity:.4f}, mean radius "
              f"{float(np.mean(scene.radii)):.4g} m, {state.steps} steps, "
              f"{state.wall_s:.1f} s")
    return state


def box_extents(scene, walls) -> np.ndarray:
    """The box's extents along x, y and z, m (3,): from its walls' positions, and along y
    from the periodic cell when ``walls`` are the four of a box periodic along y."""
    pos = np.asarray(scene.wall_positions, float)[list(walls)]
    if len(walls) == 4:
        return np.array([pos[1] - pos[0], float(np.asarray(scene.cell_matrix)[1, 1]),
                         pos[3] - pos[2]])
    return pos[1::2] - pos[0::2]


def box_stresses(scene, walls) -> np.ndarray:
    """The normal stress on each wall of the box, Pa, compression positive (6,): the force of
    the grains over the face's area (``wall_pressure``), in the order x-, x+, y-, y+, z-, z+.
    With the four walls of a box periodic along y, y's two entries are the cell's sigma_yy:
    the contacts' forces times their branch vectors over the box's volume (its smooth walls
    push along x and z only, so they add nothing to it)."""
    if len(walls) != 4:
        return np.asarray(measure.wall_stresses(scene, walls))
    size = box_extents(scene, walls)
    h = np.asarray(scene.cell_matrix)
    syy = float(np.asarray(scene.cell_stress())[1, 1]) * abs(np.linalg.det(h)) / np.prod(size)
    x0, x1, z0, z1 = (wall_pressure(scene, w, a) for w, a in zip(walls, _faces(size)))
    return np.array([x0, x1, syy, syy, z0, z1])


def _faces(size) -> list[float]:
    """The areas of the four walls x-, x+, z-, z+ of a box periodic along y, m^2."""
    return [size[1] * size[2]] * 2 + [size[0] * size[1]] * 2


def _box_porosity(scene, walls) -> float:
    """Porosity of a box periodic along y (its four walls), -: ``measure.porosity``'s, over
    the box's volume (the walls' positions and the cell's y extent)."""
    return 1.0 - measure.solid_volume(scene) / float(np.prod(box_extents(scene, walls)))


def _axes(st: np.ndarray) -> np.ndarray:
    """The box's axis stresses (3,), Pa, from ``box_stresses``' six."""
    return np.array([st[:2].mean(), st[2], st[4:].mean()])


def _grow_periodic_y(scene, walls, q: float, p: StripFootingBox, max_steps: int,
                     check_every: int, callback) -> prep.StageResult:
    """Radius growth of a box periodic along y (its four walls fixed) until the box's mean
    stress (``box_stresses``) is within ``p.tol`` of q (Pa) and the unbalanced force below
    ``p.unbalanced``, as ``prep.grow_to_stress`` grows a walled box to its walls' mean. The
    growth controller reads the cell's stress, its grain contacts alone over the cell's
    volume; between checks its target is scaled by that reading over the box's mean stress
    (the walls' contacts add 4-6 % at these sizes), so that it aims at the box's stress.
    Aiming at its own reading instead, the growth held the box 3.5 % above q (and at the
    bench's size took 199 400 steps against 128 000; both end denser inside than the walled
    box, docs/studies/footing_direct_dem.md)."""
    g = _core.RadiusGrowth(walls=[], target_stress=q, gain=0.5, max_strain=1e-3)
    scene.add_controller(g)
    start = scene.step_count
    ok, u, mean = False, float("nan"), float("nan")
    while scene.step_count - start < max_steps:
        scene.run(check_every)
        mean = float(box_stresses(scene, walls).mean())
        own = float(np.trace(np.asarray(scene.cell_stress()))) / 3.0
        if mean > 0 and own > 0:
            g.target_stress = q * own / mean
        u = float(scene.unbalanced_force())
        callback(scene)
        if abs(mean - q) <= p.tol * q and u < p.unbalanced:
            ok = True
            break
    g.enabled = False
    return prep.StageResult(ok, scene.step_count - start, _axes(box_stresses(scene, walls)),
                            mean, u, _box_porosity(scene, walls),
                            {"growth_factor": g.total_factor, "controller": g})


def _servo_periodic_y(scene, walls, q: float, p: StripFootingBox, max_steps: int,
                      check_every: int) -> prep.StageResult:
    """Servo of a box periodic along y to the isotropic stress q (Pa): a ServoWall on each of
    the four walls and the cell's sigma_yy by a CellController. Their own readings take a
    fixed area (the walls') and the cell's volume (its x and z extents as built); between
    checks each target is scaled so that the box's own stresses (``box_stresses``: the
    walls' forces over the current faces, sigma_yy over the box's volume) reach q. Ends when
    every stress is within ``p.tol`` of q and the unbalanced force below ``p.unbalanced``."""
    size = box_extents(scene, walls)
    vmax = prep.default_max_speed(scene, walls)
    area0 = _faces(size)
    servos = [_core.ServoWall(wall=int(w), target_stress=q, area=a, gain=0.5, max_speed=vmax)
              for w, a in zip(walls, area0)]
    for s in servos:
        scene.add_controller(s)
    cell = _core.CellController(gain=0.3, max_rate=vmax / float(size[1]))
    cell.set_stress(1, 1, q)
    scene.add_controller(cell)
    start = scene.step_count
    ok, u, st = False, float("nan"), box_stresses(scene, walls)
    while scene.step_count - start < max_steps:
        size = box_extents(scene, walls)
        for s, a0, a in zip(servos, area0, _faces(size)):  # F / a0 = q a / a0 <=> F / a = q
            s.target_stress = q * a / a0
        h = np.asarray(scene.cell_matrix)
        cell.set_stress(1, 1, q * float(np.prod(size)) / abs(np.linalg.det(h)))
        scene.run(check_every)
        st, u = box_stresses(scene, walls), float(scene.unbalanced_force())
        if np.all(np.abs(st - q) <= p.tol * q) and u < p.unbalanced:
            ok = True
            break
    axes = _axes(st)
    return prep.StageResult(ok, scene.step_count - start, axes, float(axes.mean()), u,
                            _box_porosity(scene, walls), {"controller": cell})


def wall_pressure(scene, wall: int, area: float) -> float:
    """The mean normal stress the grains exert on ``wall`` over ``area`` (m^2), Pa,
    compression positive: ``Scene.wall_forces`` is the force of the spheres on the wall (N),
    which pushes a wall facing +axis (sense +1) towards -axis and one facing -axis towards
    +axis, so the compression is -sense F_axis / area."""
    w = int(wall)
    f = np.asarray(scene.wall_forces)[w]
    return float(-int(scene.wall_senses[w]) * f[int(scene.wall_axes[w])] / area)


def check_settlements(settlements_m, depth: float) -> np.ndarray:
    """``settlements_m`` as an array (m): finite, > 0, increasing and below half the body's
    ``depth`` (m); ParameterError (a ValueError) naming the field otherwise."""
    try:
        s = np.asarray(settlements_m, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ParameterError(f"settlements_m={settlements_m!r}: must be a list of numbers "
                             "(m, downward positive)") from None
    if len(s) == 0:
        raise ParameterError("settlements_m=[]: give at least one settlement (m)")
    if not np.all(np.isfinite(s)) or s[0] <= 0:
        raise ParameterError(f"settlements_m={s.tolist()}: must be finite and > 0 (m, "
                             "downward positive, from the footing's start)")
    if np.any(np.diff(s) <= 0):
        k = int(np.flatnonzero(np.diff(s) <= 0)[0]) + 1
        raise ParameterError(f"settlements_m={s.tolist()}: must be increasing (m); "
                             f"settlements_m[{k}]={s[k]:g} follows {s[k - 1]:g}")
    if s[-1] >= 0.5 * depth:
        raise ParameterError(f"settlements_m={s.tolist()}: must stay below half the depth "
                             f"({0.5 * depth:g} m)")
    return s


def load_strip_footing(state: FootingBoxState, p: StripFootingBox, settlements_m, *,
                       log=None, out=None, speed_fraction: float = 1e-4,
                       relax_unbalanced: float | None = None,
                       surcharge_tol: float | None = None, relax_max_steps: int = 200_000,
                       check_every: int = 200) -> dict:
    """Splits the top of a prepared box into the footing and the surcharge and pushes the
    footing down to each settlement of ``settlements_m`` (m, increasing, from the footing's
    start) in turn.

    The top wall (z+) becomes the surcharge: opened over x in (-1, b) and driven by a
    ServoWall to ``p.surcharge_pa`` over the area (length - b) thickness (its speed capped at
    SURCHARGE_SPEED x the footing's: the surface beside the footing heaves, and by bursts
    once the soil under it gives way; a ControllerLimitWarning says when the servo could not
    follow). A new wall at the same height, opened over x in (b, length + 1), is the
    footing's base, and the plane x = b opened below the base + r_max its side (see the
    module doc). The side and bottom walls of the box stay fixed (the preparation's
    controllers are gone).

    The footing moves down at ``speed_fraction`` of the grains' mean radius per step (the
    scene's dt), is held at the settlement, and the grains relax until the **relaxation
    criterion** holds: the unbalanced force below ``relax_unbalanced`` (default
    ``p.unbalanced``) and the surcharge stress within ``surcharge_tol`` (relative; default
    ``2 p.tol``) of ``p.surcharge_pa``, checked every ``check_every`` steps, for at most
    ``relax_max_steps`` steps (beyond, the row says ``relaxed: False`` and a RuntimeWarning
    says so). The state before any move is relaxed alike and recorded first, as row 0
    (settlement 0: the footing pressure is then about q, within the scatter of the few
    grains under the footing).

    Each row: settlement_m (m), footing_pressure_pa (the vertical force of the grains on the
    footing, base and side, over b thickness, Pa, compression positive; the smooth side
    takes a vertical force at its opening's edge only: 0-2.5 % of the base's in the runs
    measured), surcharge_pa
    (the surcharge wall's measured stress, Pa), unbalanced (-), steps (of the level: move
    and relaxation), relaxed (bool), wall_s (wall-clock seconds of the level). ``out`` (a
    directory, made if missing): each row is appended to ``out/footing_dem.csv`` as it comes
    (header first, flushed); an existing file is not overwritten (FileExistsError, before
    anything is done). ``log(msg)`` gets a line per level with an ETA. Returns the columns as
    a dict of lists (keys COLUMNS).

    Raises ValueError (ParameterError) naming the field for bad input, and when the state's
    top is split already (a state is loaded once)."""
    p.check()
    s_targets = check_settlements(settlements_m, p.depth)
    if not (isinstance(speed_fraction, (int, float)) and math.isfinite(speed_fraction)
            and 0 < speed_fraction <= 1e-2):
        raise ParameterError(f"speed_fraction={speed_fraction!r}: must be in (0, 0.01] (of "
                             "the mean radius per step, -; quasi-static loading needs a "
                             "small one)")
    ru = p.unbalanced if relax_unbalanced is None else relax_unbalanced
    if not (isinstance(ru, (int, float)) and math.isfinite(ru) and 0 < ru < 1):
        raise ParameterError(f"relax_unbalanced={relax_unbalanced!r}: must be in (0, 1) (-)")
    st_tol = 2.0 * p.tol if surcharge_tol is None else surcharge_tol
    if not (isinstance(st_tol, (int, float)) and math.isfinite(st_tol) and 0 < st_tol < 0.5):
        raise ParameterError(f"surcharge_tol={surcharge_tol!r}: must be in (0, 0.5) (-)")
    for name, v in (("relax_max_steps", relax_max_steps), ("check_every", check_every)):
        if not (isinstance(v, int) and not isinstance(v, bool) and v >= 1):
            raise ParameterError(f"{name}={v!r}: must be an integer >= 1")
    path = None
    if out is not None:
        path = Path(out) / CSV_NAME
        if path.exists():
            raise FileExistsError(f"{path}: exists already; load_strip_footing does not "
                                  "overwrite a load-settlement file (give another out)")
    if state.footing_wall is not None:
        raise ParameterError("state: its top is split already (a footing was loaded on it); "
                             "prepare a new box")
    sc, walls = state.scene, state.walls
    q, b = float(p.surcharge_pa), float(p.footing_b)
    radii = np.asarray(sc.radii)[state.grain_ids]
    r_mean, r_max = float(np.mean(radii)), float(np.max(radii))
    per_step = speed_fraction * r_mean  # the footing's move per step at most, m
    top = float(sc.wall_positions[walls[-1]])
    sc.clear_controllers()
    for w in walls:
        sc.set_wall_velocity(int(w), (0.0, 0.0, 0.0))
    # The surcharge: the old top wall, open where the footing is, held at q by a servo.
    surcharge = int(walls[-1])
    sc.set_wall_opening(surcharge, axis=0, lo=-1.0, hi=b)
    # The faces' extent along y: the periodic cell's (held through the load), or as given
    # between walls (they moved by the preparation's servo strain only).
    thick = state.thickness if p.periodic_y else p.thickness
    area_s = (p.length - b) * thick
    servo = _core.ServoWall(wall=surcharge, target_stress=q, area=area_s, gain=0.5,
                            max_speed=SURCHARGE_SPEED * per_step / sc.dt)
    sc.add_controller(servo)
    # The footing: its base, a new top wall at the same height open over the surcharge, and
    # its side, the plane x = b open below the base + r_max.
    footing = int(sc.add_wall(axis=2, position=top, sense=-1, material=state.wall_material))
    sc.set_wall_opening(footing, axis=0, lo=b, hi=p.length + 1.0)
    side = int(sc.add_wall(axis=0, position=b, sense=+1, material=state.wall_material))

    def open_side() -> None:
        sc.set_wall_opening(side, axis=2, lo=-1.0,
                            hi=float(sc.wall_positions[footing]) + r_max)

    open_side()
    state.footing_wall, state.footing_side, state.servo = footing, side, servo
    area_f = b * thick

    def footing_pressure() -> float:
        f = np.asarray(sc.wall_forces)
        return float((f[footing][2] + f[side][2]) / area_f)  # (grains push the footing up)

    rows: dict = {k: [] for k in COLUMNS}
    fh = writer = None
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        fh = open(path, "x", newline="", encoding="utf-8")
        writer = csv.writer(fh)
        writer.writerow(COLUMNS)
        fh.flush()

    def relax() -> tuple[bool, int]:
        k0 = sc.step_count
        while sc.step_count - k0 < relax_max_steps:
            sc.run(min(check_every, relax_max_steps - (sc.step_count - k0)))
            u = float(sc.unbalanced_force())
            if u < ru and abs(wall_pressure(sc, surcharge, area_s) - q) <= st_tol * q:
                return True, sc.step_count - k0
        return False, sc.step_count - k0

    def move_to(z_target: float) -> int:
        k0 = sc.step_count
        while True:
            rem = float(sc.wall_positions[footing]) - z_target
            if rem <= 1e-3 * per_step:
                break
            n = int(min(check_every, math.ceil(rem / per_step)))
            v = (0.0, 0.0, -min(per_step, rem / n) / sc.dt)
            sc.set_wall_velocity(footing, v)
            sc.set_wall_velocity(side, v)  # (along the side's plane: it does not move it)
            sc.run(n)
            open_side()
        for w in (footing, side):
            sc.set_wall_velocity(w, (0.0, 0.0, 0.0))
        sc.set_wall_position(footing, z_target)
        open_side()
        return sc.step_count - k0

    t_all = time.perf_counter()
    levels = [0.0] + [float(s) for s in s_targets]
    try:
        for i, s in enumerate(levels):
            t0 = time.perf_counter()
            steps = move_to(top - s) if s > 0 else 0
            ok, n_relax = relax()
            row = {"settlement_m": s, "footing_pressure_pa": footing_pressure(),
                   "surcharge_pa": wall_pressure(sc, surcharge, area_s),
                   "unbalanced": float(sc.unbalanced_force()),
                   "steps": steps + n_relax, "relaxed": bool(ok),
                   "wall_s": time.perf_counter() - t0}
            for k in COLUMNS:
                rows[k].append(row[k])
            if writer is not None:
                writer.writerow([row[k] for k in COLUMNS])
                fh.flush()
            if not ok:
                warnings.warn(
                    f"load_strip_footing: settlement {s:g} m not relaxed in "
                    f"{relax_max_steps} steps (unbalanced {row['unbalanced']:.3g}, target "
                    f"{ru:g}; surcharge {row['surcharge_pa']:.5g} Pa, target {q:g} Pa within "
                    f"{st_tol:g}); the row says relaxed: False", RuntimeWarning,
                    stacklevel=2)
            el = time.perf_counter() - t_all
            eta = el / (i + 1) * (len(levels) - i - 1)
            _say(log, f"level {i}/{len(levels) - 1}: settlement {1e3 * s:.4g} mm, footing "
                      f"{row['footing_pressure_pa'] / 1e3:.5g} kPa, surcharge "
                      f"{row['surcharge_pa'] / 1e3:.5g} kPa, unbalanced "
                      f"{row['unbalanced']:.3g}, {row['steps']} steps"
                      + ("" if ok else " (NOT relaxed)")
                      + f", {row['wall_s']:.1f} s; ETA {eta:.0f} s")
    finally:
        if fh is not None:
            fh.close()
    return rows


__all__ = ["StripFootingBox", "FootingBoxState", "prepare_footing_box", "load_strip_footing",
           "wall_pressure", "box_extents", "box_stresses", "check_settlements",
           "CLOUD_SOLID_FRACTION", "PACKED_POROSITY", "CSV_NAME", "COLUMNS"]
