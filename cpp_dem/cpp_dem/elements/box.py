"""The servo-walled DEM element of 002's prestressed reinforced-soil element: a cube of
grains around a square geogrid, grown to a mean stress, then servo-controlled walls driven to
given normal stresses (from an FEM analysis or given), reinforced (RE) or with prestressed
longitudinal members (PRS). Used by ``cases/prs_element.py`` and ``femcoupling``'s two-way
coupling. SI units; stresses compression positive.

The functions take a parameter object with the fields of :class:`ElementParams` (the case's
``Params`` has them all).
"""

from __future__ import annotations

import functools
import hashlib
import math
import time
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from cpp_dem import _core, fixedorder
from cpp_dem.build import geogrid
from cpp_dem.measure import inertial
from cpp_dem import measure
from cpp_dem.protocols import prep, quasi_static
from cpp_dem._core import BeamParams
from cpp_dem.io import (CsvRecorder, H5Recorder, PvdWriter, write_vtk_box, write_vtk_contacts,
                        write_vtk_spheres)
from cpp_dem.build.packing import loose_cloud, placed_count
from cpp_dem.elements import boundaries
from cpp_dem.scene import (ControllerLimitWarning, ServoTargetWarning, apply_threads,
                           linear_material)
from cpp_dem.protocols.triaxial import build_box_sample


def _log(msg: str) -> None:
    print(f"[element] {msg}", flush=True)


@dataclass
class ElementParams:
    """The element's parameters (SI). Defaults: the 002 element of cases/prs_element.py."""

    n: int = 2000                    #: number of grains, -
    edge: float = 0.1                #: element edge length, m (002)
    seed: int = 1                    #: RNG seed, -
    radius_spread: float = 0.2       #: radii uniform in r_mean (1 +- spread), -
    young: float = 50e6              #: grain Young's modulus (linear law), Pa
    poisson: float = 0.23            #: k_s / k_n, -
    friction_deg: float = 38.66      #: grain friction, deg
    prep_friction_deg: float = 20.0  #: friction during radius growth, deg
    density: float = 2640.0          #: grain density, kg/m^3
    damping: float = 0.7             #: Cundall local damping, -
    grid_nodes: int = 10             #: nodes per side of the square grid, -
    grid_width: float = 0.095        #: grid width, m
    grid_radius: float = 1e-3        #: member (cylinder) radius, m
    grid_young: float = 1e9          #: member Young's modulus, Pa
    grid_density: float = 1030.0     #: geogrid density, kg/m^3
    prestress: float = 2000.0        #: PRS prestress T_p, N/m of grid width
    tol: float = 0.005               #: servo convergence, relative, -
    unbalanced: float = 0.02         #: servo convergence, unbalanced force, -
    hold_steps: int = 2000           #: steps the walls then hold the targets
    max_steps: int = 400_000         #: per servo stage
    record_every: int = 200          #: steps between records
    threads: int = 1                 #: OpenMP threads (0: OpenMP's default, every core; see run_element)
    # --- 002's element: clumps, Hertz–Mindlin, the woven grid of bonded spheres ---
    grains: str = "spheres"          #: 'spheres', or 'clumps:NAME' (cpp_dem.build.clumps templates)
    grain_law: str = "linear"        #: 'linear' (young, poisson), or 'hertz' (002 Table 1)
    shear_modulus: float = 3e10      #: Hertz–Mindlin G, Pa (002 Table 1)
    hertz_poisson: float = 0.2       #: Hertz–Mindlin nu, - (002 Table 1)
    geogrid: str = "square"          #: 'square' (cylinders), 'woven-detailed', 'woven-standard'
    apertures: int = 3               #: woven grids: apertures per side, -
    growth_max_strain: float = 1e-4  #: radius growth per step at most, -; woven elements
                                     #: grow at 10 x this until the grains touch, then at this
    servo_integral: bool = False     #: servo stages: integral correction of the set points
                                     #: near the targets (servo_stage); 002's clump element
    density_scaling: float = 0.0     #: target dt / unscaled dt of the growth and servo stages
                                     #: with density scaling (cpp_dem.protocols.quasi_static),
                                     #: -; 0: off
    # --- 002's boundaries, gravity and damping stages (the defaults keep the older element) ---
    gravity: float = 0.0             #: gravity along -z, m/s^2 (002: 9.81)
    fixed_walls: str = ""            #: walls that stay put, e.g. 'x-,y-,z-' (elements.boundaries);
                                     #: '' : all six servo about the centre
    fill_viscous: float = 0.0        #: viscous contact damping of the grains (normal and shear,
                                     #: ratio of critical) during the preparation (002: 0.97)
    fill_local_damping: float = -1.0  #: local damping during the preparation, -; < 0: damping
    re_grips: bool = False           #: RE: the grid's longitudinal ends held by the grips that
                                     #: hold PRS's (the same end conditions for both)
    plateau_records: int = 0         #: servo stages end, not converged, when on target with
                                     #: the unbalanced force at a floor for this many records
                                     #: (servo_stage); 0: they run to max_steps
    grid_held: str = "growth"        #: woven grids: the grid held in place for the whole
                                     #: 'growth', or only its 'fast' phase (free while the
                                     #: grains grow to the stress)
    grid_ends: str = "grips"         #: woven grids: PRS's prestress held by 'grips' (tensioned,
                                     #: then locked in place), or by 'tension': the ends pulled
                                     #: by T_p throughout (EndTension), RE's by 0 (free)
    grid_convention: str = "contact"  #: woven grids: 002's k_n, k_s as 'series' (PFC 4 ball
                                     #: properties, combined in series) or 'contact' stiffnesses
    # --- the loading at a bounded rate, and rest shown by motion (loading_stage, rest_hold) ---
    ramp: bool = False               #: stages after the first load along a ramp of the set
                                     #: points at a bounded inertial number (loading_stage),
                                     #: then hold until at rest (rest_hold); False: servo_stage
    load_inertial: float = 3e-4      #: the ramp caps the box's strain rate at this inertial
                                     #: number (the check is QUASI_STATIC_STRICT, 1e-3), -
    rest_inertial: float = 1e-4      #: at rest: the hold's strain rate at most this inertial
                                     #: number, -
    rest_unbalanced: float = 0.01    #: at rest: the unbalanced-force ratio at most this, -
    rest_max_holds: int = 12         #: holds of hold_steps before an element that does not come
                                     #: to rest is reported at_strength (still moving) or
                                     #: not_at_rest (still, a force or servo check failed), -
    kinematics: str = "stress"       #: the loading's walls: 'stress' (every axis servoed to its
                                     #: target), 'plane-strain' (y held, x and z servoed), or
                                     #: 'fem-strain' (y held, x following the FEM region's
                                     #: strain, z servoed): see KINEMATICS


def grid_spacing(p: ElementParams) -> float:
    """Node spacing of the square grid, m."""
    return p.grid_width / (p.grid_nodes - 1)


def grid_axial_stiffness(p: ElementParams) -> float:
    """J = E pi R^2 / spacing, N/m: the DEM grid's tensile stiffness per metre width."""
    return p.grid_young * math.pi * p.grid_radius**2 / grid_spacing(p)


def grid_stiffness_per_metre(p: ElementParams) -> float:
    """The element's geogrid tensile stiffness per metre of width, N/m: the square grid's
    E pi R^2 / spacing, or a woven grid's bonds in series (cpp_dem.build.woven)."""
    if p.geogrid.startswith("woven-"):
        from cpp_dem.build.woven import series_stiffness_per_metre

        return series_stiffness_per_metre(p.geogrid.split("-", 1)[1],
                                          convention=p.grid_convention)
    return grid_axial_stiffness(p)


def make_element(p: ElementParams, mean_stress: float, prestressed: bool,
                 log: Callable[[str], None] = _log):
    """The element: spheres in the cube, the square geogrid, radius growth to ``mean_stress``
    (Pa); for PRS the longitudinal members tensioned to p.prestress (N/m) and locked
    (cpp_dem.protocols.prestress). Returns (sample, grid, prestress or None)."""
    rng_r = np.random.default_rng(p.seed)
    vol = p.edge**3
    r_mean = (0.6 * vol / (p.n * 4.0 / 3.0 * math.pi)) ** (1.0 / 3.0)
    radii = r_mean * (1.0 + p.radius_spread * (2.0 * rng_r.random(p.n) - 1.0))
    shrink = (0.25 / 0.6) ** (1.0 / 3.0)
    c, r = loose_cloud(radii * shrink, (0, 0, 0), (p.edge,) * 3, seed=p.seed)
    z_grid = 0.5 * p.edge
    half = 0.5 * p.grid_width
    mid = 0.5 * p.edge
    over = (np.all(np.abs(c[:, :2] - mid) < half + r[:, None], axis=1)
            & (np.abs(c[:, 2] - z_grid) < r + p.grid_radius))
    c, r = c[~over], r[~over]
    counts = placed_count(p.n, len(r), "cleared from the grid's layer", log=log)
    sample = build_box_sample(c, r, (0, 0, 0), (p.edge,) * 3, young=p.young,
                              poisson=p.poisson, friction_deg=p.prep_friction_deg,
                              density=p.density, local_damping=p.damping)
    sample.counts = counts
    sc = sample.scene
    gmat = sc.add_material(linear_material(density=p.grid_density, young=p.young,
                                               poisson=p.poisson, friction_angle_deg=26.57))
    beam = BeamParams(young=p.grid_young, poisson=0.3, radius=p.grid_radius,
                          normal_cohesion=1e12, shear_cohesion=1e12)
    grid = geogrid.square_grid(sc, origin=(mid - half, mid - half, z_grid), length=p.grid_width,
                               width=p.grid_width, nodes_x=p.grid_nodes, nodes_y=p.grid_nodes,
                               params=beam, material=gmat, density=p.grid_density)
    sc.max_overlap_ratio = 0.95
    sc.block_dofs(grid.nodes, "all")
    _start_scaling(sc, p, log)
    t0 = time.perf_counter()
    grow = prep.grow_to_stress(sc, sample.walls, mean_stress, tol=0.05, unbalanced=0.05,
                               max_strain=1e-4 * _rate_factor(sc, p), max_steps=p.max_steps)
    if sc.density_scaling:  # (the target again, for the grown grains)
        quasi_static.disable(sc)
        _start_scaling(sc, p, log)
    log(f"element: {len(r)} grains (r_mean {r_mean * 1e3:.2f} mm), geogrid {p.grid_nodes}x"
        f"{p.grid_nodes} nodes, J = {grid_axial_stiffness(p) / 1e3:.0f} kN/m; grown to "
        f"{grow.mean_stress / 1e3:.2f} kPa in {grow.steps} steps, porosity {grow.porosity:.3f}"
        f" ({time.perf_counter() - t0:.1f} s)")
    prep.set_friction(sc, np.flatnonzero(measure.sphere_mask(sc)), sc.material(sample.material),
                      p.friction_deg)
    sc.block_dofs(grid.nodes, "")
    ps = None
    if prestressed and p.prestress > 0:
        # The library's prestress: tension the longitudinal members to T_p x spacing, lock
        # (ends held); the force along them is then found, not imposed by end forces.
        from cpp_dem.protocols.prestress import Prestress

        ps = Prestress(sc, grid, tension_per_m=p.prestress)
        row = ps.tension(p.max_steps)
        log(f"PRS: {len(ps.lines)} lines of longitudinal members tensioned to {ps.target_n:.1f}"
            f" N each (T_p = {p.prestress / 1e3:g} kN/m) and locked at step {row['step']}")
    return sample, grid, ps
    return sample, grid


GEOGRIDS = ("square", "woven-detailed", "woven-standard")
#: How the walls follow the loading stage (ElementParams.kinematics): per axis x, y, z
#: 'stress' (servoed to the target) or 'strain' (the walls move to a strain path; a held axis
#: follows the path 0).
KINEMATICS = {"stress": ("stress", "stress", "stress"),
              "plane-strain": ("stress", "strain", "stress"),
              "fem-strain": ("strain", "strain", "stress")}
GRAIN_LAWS = ("linear", "hertz")
#: How the grid's longitudinal ends are held (ElementParams.grid_ends): 'lock' (PRS
#: tensioned by the grips, then released: the soil locks what it holds; RE untouched),
#: 'grips' (tensioned and held by the grips; RE by the same grips with p.re_grips),
#: 'tension' (PRS pulled by T_p throughout, RE free).
GRID_ENDS = ("lock", "grips", "tension")


def check_element_params(p: ElementParams) -> None:
    """Raises ParameterError naming the first bad choice of grains, law or geogrid."""
    from cpp_dem._core import ParameterError

    if p.geogrid not in GEOGRIDS:
        raise ParameterError(f"geogrid={p.geogrid!r}: must be one of {', '.join(GEOGRIDS)}")
    if p.grain_law not in GRAIN_LAWS:
        raise ParameterError(f"grain_law={p.grain_law!r}: must be one of {', '.join(GRAIN_LAWS)}")
    if p.grains != "spheres":
        from cpp_dem.build.clump_mesh import templates_from_spec

        templates_from_spec(p.grains)  # names the bad value
    if not (isinstance(p.apertures, int) and p.apertures >= 1):
        raise ParameterError(f"apertures={p.apertures!r}: must be an integer >= 1")
    if not (math.isfinite(p.density_scaling) and (p.density_scaling == 0 or p.density_scaling >= 1)):
        raise ParameterError(f"density_scaling={p.density_scaling!r}: must be 0 (off) or >= 1 "
                             "(the target time step over the unscaled one, -)")
    if not (isinstance(p.plateau_records, int) and p.plateau_records >= 0):
        raise ParameterError(f"plateau_records={p.plateau_records!r}: must be an integer >= 0")
    if not (math.isfinite(p.gravity) and p.gravity >= 0):
        raise ParameterError(f"gravity={p.gravity!r}: must be >= 0 (m/s^2, along -z)")
    boundaries.parse_fixed_walls(p.fixed_walls)
    if not (math.isfinite(p.fill_viscous) and 0 <= p.fill_viscous <= 1):
        raise ParameterError(f"fill_viscous={p.fill_viscous!r}: must be in [0, 1] (ratio of "
                             "critical damping)")
    if not (math.isfinite(p.fill_local_damping) and p.fill_local_damping < 1):
        raise ParameterError(f"fill_local_damping={p.fill_local_damping!r}: must be in [0, 1) "
                             "(local damping), or < 0 for the loading's damping")
    if p.grid_held not in ("growth", "fast"):
        raise ParameterError(f"grid_held={p.grid_held!r}: must be 'growth' or 'fast'")
    if p.kinematics not in KINEMATICS:
        raise ParameterError(f"kinematics={p.kinematics!r}: must be one of "
                             f"{', '.join(KINEMATICS)}")
    if p.kinematics != "stress" and p.fixed_walls:
        raise ParameterError(f"kinematics={p.kinematics!r} with fixed_walls="
                             f"{p.fixed_walls!r}: held axes need the box's own controller; "
                             "use kinematics='stress' with fixed walls")
    for name in ("load_inertial", "rest_inertial", "rest_unbalanced"):
        v = getattr(p, name)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v < 1):
            raise ParameterError(f"{name}={v!r}: must be in (0, 1) (-)")
    if not (isinstance(p.rest_max_holds, int) and p.rest_max_holds >= 1):
        raise ParameterError(f"rest_max_holds={p.rest_max_holds!r}: must be an integer >= 1")
    if p.grid_ends not in GRID_ENDS:
        raise ParameterError(f"grid_ends={p.grid_ends!r}: must be one of {', '.join(GRID_ENDS)}")
    from cpp_dem.build.woven import CONVENTIONS

    if p.grid_convention not in CONVENTIONS:
        raise ParameterError(f"grid_convention={p.grid_convention!r}: must be one of "
                             f"{', '.join(CONVENTIONS)}")


def _rate_factor(sc, p: ElementParams) -> float:
    """How much farther the element's per-step limits (growth strain, wall speed) reach per
    step with density scaling on: p.density_scaling, the dt over the unscaled reference, so
    that the loading keeps its physical rate (1/s, m/s) and takes that many times fewer
    steps; 1 without scaling."""
    return p.density_scaling if sc.density_scaling else 1.0


def _start_scaling(sc, p: ElementParams, log: Callable[[str], None]) -> None:
    """Density scaling on for the element's quasi-static stages (p.density_scaling > 0)."""
    if p.density_scaling > 0:
        ref = quasi_static.reference_dt(sc)
        # (Every 10 steps: the grains' Hertz contacts form soft, and the linear wall and
        # grid contacts are far softer than a grain's mass allows at this dt.)
        target = quasi_static.enable(sc, p.density_scaling, period=10)
        log(f"density scaling: dt {target:.3g} s, {p.density_scaling:g} x the unscaled "
            f"{ref:.3g} s (each body's inertia raised where its contacts need it)")


def grain_material(p: ElementParams, friction_deg: float):
    """The grains' material: 002 Table 1's Hertz–Mindlin (G, nu, density) or the linear law."""
    from cpp_dem.scene import hertz_mindlin_material

    if p.grain_law == "hertz":
        return hertz_mindlin_material(density=p.density, shear_modulus=p.shear_modulus,
                                      poisson=p.hertz_poisson,
                                      friction_coefficient=math.tan(math.radians(friction_deg)))
    return linear_material(density=p.density, young=p.young, poisson=p.poisson,
                           friction_angle_deg=friction_deg)


def make_woven_element(p: ElementParams, mean_stress: float, prestressed: bool,
                       log: Callable[[str], None] = _log):
    """002's element: :func:`prepare_woven_element`, then :func:`load_variant` (RE or PRS).
    Returns (sample, grid, prestress or None)."""
    sample, grid = prepare_woven_element(p, mean_stress, log=log)
    return sample, grid, load_variant(sample, grid, p, prestressed, log=log)


def _grain_damping(sc, sample, p: ElementParams, friction_deg: float, viscous: float) -> None:
    """The grains' pair laws with viscous contact damping ``viscous`` (normal and shear, ratio
    of critical): grain–grain (Coulomb friction ``friction_deg``), and the grain–wall and
    grain–grid laws set before, each kept as it is but for its damping."""
    mu = math.tan(math.radians(friction_deg))
    if viscous == 0 and p.fill_viscous == 0:
        sc.set_pair_law(sample.material, sample.material, friction=mu)
        return
    sc.set_pair_law(sample.material, sample.material, friction=mu, damping_normal=viscous,
                    damping_shear=viscous)
    for law in sc.pair_laws:
        a, b = int(law["a"]), int(law["b"])
        if sample.material not in (a, b) or a == b:
            continue
        keep = {k: law[k] for k in ("model", "kn", "ks", "friction") if law[k] is not None}
        sc.set_pair_law(a, b, **keep, damping_normal=viscous, damping_shear=viscous)


def prepare_woven_element(p: ElementParams, mean_stress: float,
                          log: Callable[[str], None] = _log, *, build_only: bool = False):
    """002's element prepared: grains (clumps or spheres; Hertz–Mindlin or linear) in the
    cube around a woven geogrid of bonded spheres at mid-height (cpp_dem.build.woven,
    'detailed' or 'standard'), with 002's contact laws, grown to ``mean_stress`` (Pa; the grid
    held) under p.gravity with the preparation's damping (p.fill_viscous,
    p.fill_local_damping), then the loading's damping (p.damping, no viscous) and friction.
    Fixed walls (p.fixed_walls): ``sample.controller`` is a
    :class:`cpp_dem.elements.boundaries.WallServos` and ``sample.fixed`` names them.
    Returns (sample, grid).

    ``build_only``: the element's skeleton, for a checkpoint of it to be loaded into
    (cpp_dem.checkpoint.load_checkpoint; ``geogrid-dem continue``): the same bodies, materials,
    laws, walls and controllers, in the same order (the box's servo, the fast growth's
    RadiusGrowth and the slow growth's, both disabled), but no step is run: the grains keep
    their initial size and place until the checkpoint's state replaces them."""
    from cpp_dem.build import woven

    check_element_params(p)
    preset = p.geogrid.split("-", 1)[1]
    rng = np.random.default_rng(p.seed)
    vol = p.edge**3
    d_mean = (0.6 * vol / (p.n * math.pi / 6.0)) ** (1.0 / 3.0)
    diam = d_mean * (1.0 + p.radius_spread * (2.0 * rng.random(p.n) - 1.0))
    z_grid = mid = 0.5 * p.edge
    r_grid = woven.PRESETS[preset]["sphere_radius"]
    clumps = None
    if p.grains != "spheres":
        from cpp_dem.build.clump_mesh import templates_from_spec
        from cpp_dem.build.clumps import ClumpCloud, bounding_volume_factor, clump_cloud

        templates = templates_from_spec(p.grains)
        shrink = (0.25 / (0.6 * bounding_volume_factor(templates))) ** (1.0 / 3.0)
        cl = clump_cloud(templates, diam * shrink, (0, 0, 0), (p.edge,) * 3, seed=p.seed)
        rb = cl.scales * np.array([templates[t].bounding_radius for t in cl.template])
        keep = np.abs(cl.positions[:, 2] - z_grid) > rb + 1.5 * r_grid
        clumps = (ClumpCloud(cl.template[keep], cl.positions[keep], cl.orientations[keep],
                             cl.scales[keep]), templates)
        c, r = cl.positions[keep], rb[keep]
    else:
        shrink = (0.25 / 0.6) ** (1.0 / 3.0)
        c, r = loose_cloud(0.5 * diam * shrink, (0, 0, 0), (p.edge,) * 3, seed=p.seed)
        keep = np.abs(c[:, 2] - z_grid) > r + 1.5 * r_grid
        c, r = c[keep], r[keep]
    counts = placed_count(p.n, len(r), "cleared from the grid's layer",
                          log=(lambda m: None) if build_only else log,
                          what="grains" if clumps is None else "clumps")
    sample = build_box_sample(c, r, (0, 0, 0), (p.edge,) * 3, young=p.young, poisson=p.poisson,
                              friction_deg=p.prep_friction_deg, density=p.density,
                              local_damping=p.damping, clumps=clumps,
                              grain_material=grain_material(p, p.prep_friction_deg))
    sample.counts = counts
    sc = sample.scene
    grain_bodies = np.arange(sc.num_bodies)
    gmat = sc.add_material(woven.woven_material(preset))
    pr = woven.PRESETS[preset]
    pitch = pr["aperture"] + (pr["strands"] - 1) * pr["strand_spacing"] + 2 * r_grid
    o = mid - 0.5 * p.apertures * pitch
    width = pitch - pr["aperture"]
    if o - 0.5 * width < 0.03 * p.edge:  # room for the walls to move in
        from cpp_dem._core import ParameterError

        raise ParameterError(f"apertures={p.apertures}: the {preset} grid ({p.apertures} x "
                             f"{pitch * 1e3:.1f} mm) does not fit in the {p.edge:g} m element "
                             "with 3 % of its edge to spare on each side")
    # The grid reaches towards the faces: where its end ribs leave room (beyond the walls'
    # 3 %) for whole spheres, its strings go on past them as tails (cpp_dem.build.woven), so
    # that the ends pulled (the layer's tension, the prestress's grips) are near the faces and
    # not at a rib inside the soil. (The standard grid's 23 mm pitch leaves its end ribs
    # 14 mm inside the walls: pulled there, they pressed the soil outside them into the
    # walls, and the element never came to rest. The detailed grid's leave 4 mm: no tail.)
    tails = int(math.floor((o - 0.5 * width - 0.03 * p.edge) / (2 * r_grid) + 1e-9))
    grid = woven.woven_geogrid(sc, origin=(o, o, z_grid), apertures_x=p.apertures,
                               apertures_y=p.apertures, material=gmat, preset=preset,
                               convention=p.grid_convention, tails=tails)
    # 002's laws: grid-grain and grid-grid linear (Table 1, Table 2; p.grid_convention); walls
    # frictionless, and for Hertz–Mindlin grains linear with 002's grain k_n, k_s as the
    # contact's (002 gives no wall stiffness).
    woven.set_grid_laws(sc, gmat, sample.material, preset=preset, convention=p.grid_convention)
    wall_mat = sample.wall_material
    if p.grain_law == "hertz":
        sc.set_pair_law(sample.material, wall_mat, model="linear", kn=3.9e6, ks=9.0e5,
                        friction=0.0)
    sc.set_pair_law(gmat, wall_mat, model="linear", kn=pr["kn"], ks=pr["ks"], friction=0.0)
    sc.max_overlap_ratio = 0.95
    sample.fixed = boundaries.parse_fixed_walls(p.fixed_walls)
    if sample.fixed:
        # (The box's TriaxialController stays, disabled: it moves both walls of an axis.)
        sample.controller = boundaries.WallServos(sc, sample.walls, sample.fixed,
                                       max_speed=prep.default_max_speed(sc, sample.walls))
    if p.gravity > 0:
        sc.gravity = (0.0, 0.0, -p.gravity)
        if not sample.fixed:
            # Each wall on its own stress lets the box translate under gravity: the bottom
            # wall carries the weight too and backs off while the top one pushes; at the speed
            # cap the ramp's z stress then stayed 4 % under its set point for 150 000 steps
            # (tests/test_element_rest.py on one CPU). Both z walls move on the axis's mean.
            sample.controller.symmetric = True
    # The preparation's damping (002: a filling with viscous damping 0.97 and no local
    # damping); the loading's (p.damping) after it.
    if p.fill_local_damping >= 0:
        sc.local_damping = p.fill_local_damping
    if p.fill_viscous > 0:
        _grain_damping(sc, sample, p, p.prep_friction_deg, p.fill_viscous)
    sc.block_dofs(grid.spheres, "all")
    _start_scaling(sc, p, log)
    t0 = time.perf_counter()
    # Radius growth in two phases. A growth servo on the wall stress stops too early in a
    # loose cloud of clumps: grains that the growth itself presses into the walls show the
    # target stress while the inside is not yet in contact (measured: 20 kPa at a
    # coordination number of 0.4). So the grains first grow fast, with no stress feedback,
    # until contacts form throughout (coordination number 1). The wall stress is only a
    # ceiling there: above the target the growth pauses until the grains it pressed into the
    # walls have moved into the loose inside, and goes on (ending the phase on such a spike
    # left coordination numbers of 0.02-0.07, and the packing sprang apart). The phase also
    # ends when the growth stays paused for 20 checks (10 000 unscaled steps): the packing is
    # jammed, in contact throughout. Then the grains grow slowly to the target stress, which must hold at three
    # checks in a row with the grains in contact (two grain-grain contacts per grain: in a
    # small element the walls and the grid take many of the contacts) and the unbalanced
    # force below 0.3. The servo stages then bring the packing to rest (p.unbalanced) at the
    # exact targets; a clump packing creeps, and growing it to rest as well was measured
    # 10 x slower (150 000 steps, not at rest).
    from cpp_dem._core import RadiusGrowth

    rate = _rate_factor(sc, p)
    fast = RadiusGrowth(walls=list(sample.walls), bodies=[int(b) for b in grain_bodies],
                        target_stress=1e12, gain=0.5, max_strain=10 * p.growth_max_strain * rate)
    sc.add_controller(fast)
    if build_only:
        # The slow growth's controller as prep.grow_to_stress adds it (same kind, walls,
        # bodies and settings), disabled as it leaves it; the loading's damping and friction.
        fast.enabled = False
        prep.add_growth(sc, sample.walls, mean_stress, max_strain=p.growth_max_strain * rate,
                        bodies=grain_bodies).enabled = False
        _grain_damping(sc, sample, p, p.friction_deg, 0.0)
        sc.local_damping = p.damping
        sc.block_dofs(grid.spheres, "")
        return sample, grid
    start = sc.step_count
    last = [time.perf_counter()]
    history = sample.growth_history

    def note(phase: str) -> dict:
        row = {"phase": phase, "step": sc.step_count, "time_s": sc.time,
               "coordination": measure.coordination_number(sc),
               "porosity": measure.porosity(sc, sample.walls),
               "wall_stress_pa": float(measure.wall_stresses(sc, sample.walls).mean()),
               "unbalanced_force": float(sc.unbalanced_force()), "dt_s": sc.dt}
        history.append(row)
        return row

    def progress(phase: str) -> None:
        if time.perf_counter() - last[0] > 10:
            last[0] = time.perf_counter()
            log(f"  growth ({phase}): step {sc.step_count - start}, walls "
                f"{np.round(measure.axis_stresses(sc, sample.walls) / 1e3, 2).tolist()} kPa "
                f"(target {mean_stress / 1e3:.2f}), coordination "
                f"{measure.coordination_number(sc):.2f}, unbalanced {sc.unbalanced_force():.3g},"
                f" {quasi_static.describe(quasi_static.report(sc))};"
                f" at most {p.max_steps - (sc.step_count - start)} steps left in this phase")

    paused = 0
    row = note("fast")
    # (Checked every 500 steps' worth of growth: 500 steps unscaled, 500 / S with density
    # scaling, whose steps grow the grains S times more.)
    every = max(10, int(round(500 / rate)))
    while row["coordination"] < 1.0 and sc.step_count - start < p.max_steps:
        # The ceiling: pause above the target, go on below it. Paused for 20 checks in a row
        # (10 000 unscaled steps), the grains pressed into the walls have not found room
        # inside: the packing is jammed.
        fast.enabled = row["wall_stress_pa"] < mean_stress
        paused = paused + 1 if not fast.enabled else 0
        if paused >= 20:
            break
        sc.run(every)
        row = note("fast")
        progress("fast")
    fast.enabled = False
    fast_steps = sc.step_count - start
    fast_end = ("coordination 1" if row["coordination"] >= 1.0 else
                "jammed at the ceiling" if paused >= 20 else "step limit")
    if fast_end == "step limit":
        log(f"WARNING: the fast growth reached its {p.max_steps} steps at coordination "
            f"{row['coordination']:.2f} (not 1): the grains are not in contact throughout; the "
            "slow growth goes on from there")
    if p.grid_held == "fast":
        # The grid free for the slow growth: held to the end, it propped the packing (the
        # walls' forces then summed to 290 N in x at smoke size, carried by the held grid)
        # and the packing fell away from the walls as soon as it was let go.
        sc.block_dofs(grid.spheres, "")
    start = sc.step_count

    calls = [0]

    def slow(_s) -> None:  # (called every 200 steps; the history every 2000)
        calls[0] += 1
        if calls[0] % 10 == 0:
            note("slow")
        progress("to the stress")

    grow = prep.grow_to_stress(sc, sample.walls, mean_stress, tol=0.05,
                               unbalanced=max(0.3, p.unbalanced),
                               max_strain=p.growth_max_strain * rate, max_steps=p.max_steps,
                               bodies=grain_bodies, checks=3, min_coordination=2.0,
                               callback=slow)
    note("slow")
    if not grow.converged:
        log(f"WARNING: the growth did not reach {mean_stress / 1e3:.2f} kPa at rest within "
            f"{p.max_steps} steps (axis stresses {np.round(grow.axis_stresses / 1e3, 2).tolist()}"
            f" kPa, unbalanced force {grow.unbalanced_force:.3g}); the servo stages go on from "
            "there")
    # The grains are now at their size: density scaling's target again from the unscaled
    # step of the grown packing (it grew about 1.4 x in radius since the target was set).
    if sc.density_scaling:
        quasi_static.disable(sc)
        _start_scaling(sc, p, log)
    n_grains = measure.grain_of_body(sc)[1]
    log(f"element: {n_grains} grains ({p.grains}, {p.grain_law}; {len(grain_bodies)} spheres), "
        f"woven {preset} grid {p.apertures}x{p.apertures} apertures ({len(grid.spheres)} "
        f"spheres, {len(grid.bonds)} bonds, J = "
        f"{grid_stiffness_per_metre(p) / 1e3:.0f} kN/m, {p.grid_convention} stiffnesses); grown to "
        f"{grow.mean_stress / 1e3:.2f} kPa in {fast_steps} (fast, to {fast_end}) + "
        f"{grow.steps} steps, "
        f"porosity {measure.porosity(sc, sample.walls):.3f}"
        f" ({time.perf_counter() - t0:.1f} s)")
    _grain_damping(sc, sample, p, p.friction_deg, 0.0)
    sc.local_damping = p.damping
    sc.block_dofs(grid.spheres, "")
    return sample, grid


class Grips:
    """RE's grips: the grid's longitudinal end junctions held in all six DOFs where the
    prepared packing left them, as PRS's grips hold its ends once the prestress is locked
    (cpp_dem.protocols.prestress.GridEnds: the same bodies)."""

    def __init__(self, scene, grid):
        from cpp_dem.protocols.prestress import GridEnds

        ends = GridEnds(scene, grid)
        self.held = np.concatenate([ends.low, ends.high])
        scene.block_dofs(self.held, "all")
        v = np.asarray(scene.velocities).copy()
        v[self.held] = 0.0
        scene.velocities = v


def load_variant(sample, grid, p: ElementParams, prestressed: bool,
                 log: Callable[[str], None] = _log, *, build_only: bool = False):
    """The variant on the prepared element: PRS tensions the grid's longitudinal members to
    p.prestress (N/m) and locks them (cpp_dem.protocols.prestress), its end junctions then held
    (p.grid_ends 'grips') or released so that the grains hold the prestress ('lock'); RE with
    p.re_grips holds the same end junctions untensioned (:class:`Grips`), else leaves the grid
    free. Returns the Prestress (its line forces recorded as the run goes), or None.

    ``build_only``: the variant's objects on a restored element (``geogrid-dem continue``;
    call it after loading the state, whose positions find the grid's ends): PRS's Prestress
    with its grips as ``p.grid_ends`` leaves them (locked for 'grips', released for 'lock'),
    not tensioned (no step). It adds no controller; the grips' held DOFs and velocities it
    sets are the scene's, which the checkpoint loaded after it restores."""
    from cpp_dem.protocols.prestress import Prestress

    sc = sample.scene
    if p.grid_ends == "tension":
        return None  # (run_element pulls the ends: EndTension at T_p for PRS, 0 for RE)
    if prestressed and p.prestress > 0 and build_only:
        ps = Prestress(sc, grid, tension_per_m=p.prestress)
        ps.locked = True
        if p.grid_ends == "lock":
            ps.unlock()
        return ps
    if prestressed and p.prestress > 0:
        ps = Prestress(sc, grid, tension_per_m=p.prestress)
        t0 = time.perf_counter()
        # 'lock' (002's concept: the grid tensioned, the fill over it, its ends released):
        # the whole grid stretched at once in the fill, so that every member carries T_p
        # (grips pulling the ends of a grid already interlocked with the grains tensioned the
        # end members above T_p and the inner ones below; released, the difference pushed
        # the soil outside the end ribs into the walls, and the standard grid's element never
        # came to rest). 'grips': the ends pulled by the grips and held.
        row = ps.tension_uniform(p.max_steps) if p.grid_ends == "lock" else \
            ps.tension(p.max_steps)
        log(f"PRS: longitudinal members tensioned to {ps.target_n:.1f} N each (T_p = "
            f"{p.prestress / 1e3:g} kN/m"
            + ("; the whole grid stretched uniformly" if p.grid_ends == "lock" else "")
            + f") and locked at step {row['step']}: line forces "
            f"{np.round(row['line_forces_n'], 2).tolist()} N ({time.perf_counter() - t0:.1f} s)")
        if p.grid_ends == "lock":
            # 002's concept: the grid tensioned in the fill, then its ends released; the
            # grains hold what they can (the first stage's rest hold lets the grid settle).
            ps.unlock()
            log("PRS: the grips released: the grains (and an FEM layer's tension at the "
                "ends, where one is handed over) hold the prestress")
        return ps
    if p.re_grips:
        g = Grips(sc, grid)
        log(f"RE: the grid's longitudinal end junctions held by the grips ({len(g.held)} "
            "spheres), untensioned")
    return None


SERIES = {"stage": (None, "-"), "step": (None, "-"), "time": (None, "s"),
          "sigma_x": (None, "Pa"), "sigma_y": (None, "Pa"), "sigma_z": (None, "Pa"),
          "target_x": (None, "Pa"), "target_y": (None, "Pa"), "target_z": (None, "Pa"),
          "lx": (None, "m"), "ly": (None, "m"), "lz": (None, "m"),
          "unbalanced_force": (None, "-"), "grid_force_longitudinal_mean": (None, "N"),
          "grid_force_transverse_mean": (None, "N"),
          "prestress_line_force_mean": (None, "N"), "grid_end_force": (None, "N")}


def at_floor(unbalanced: list, records: int, improvement: float = 0.05) -> bool:
    """Whether a stage's unbalanced force (one value per record, inf where the walls were off
    target) has reached a floor: the last ``records`` values all on target, and their least
    no lower than (1 - improvement) x the least of the at least ``records`` values before
    them."""
    if records <= 0 or len(unbalanced) <= 2 * records:
        return False
    recent = unbalanced[-records:]
    return (all(math.isfinite(u) for u in recent)
            and min(recent) >= (1.0 - improvement) * min(unbalanced[:-records]))


def held_stresses(sample) -> np.ndarray:
    """Per axis, the stress the element holds, Pa: the mean of the axis's stress-controlled
    walls (both, unless one is fixed: cpp_dem.elements.boundaries)."""
    return boundaries.axis_stresses(sample.scene, sample.walls, getattr(sample, "fixed", ()))


def _recorder(sample, grid, stage: int, rec, prestress=None, ends=None):
    """A function ``record(targets)`` that writes one row of the element's series (SERIES)
    through ``rec`` (the stresses held, the targets, the box, the member forces) and returns
    the stresses held per axis, Pa."""
    sc, walls = sample.scene, sample.walls
    longi = grid.member_direction == geogrid.LONGITUDINAL

    def record(t) -> np.ndarray:
        ax = held_stresses(sample)
        size = measure.box_size(sc, walls)
        f = grid.member_axial_forces(sc)
        locked = (float(prestress.record()["line_forces_n"].mean()) if prestress is not None
                  else float("nan"))
        rec(prestress_line_force_mean=locked, stage=stage, step=sc.step_count, time=sc.time,
            grid_end_force=ends.line_force_n if ends is not None else float("nan"),
            sigma_x=ax[0], sigma_y=ax[1], sigma_z=ax[2], target_x=t[0], target_y=t[1],
            target_z=t[2], lx=size[0], ly=size[1], lz=size[2],
            unbalanced_force=sc.unbalanced_force(),
            grid_force_longitudinal_mean=float(f[longi].mean()),
            grid_force_transverse_mean=float(f[~longi].mean()))
        return ax

    return record


def _judges_its_targets(stage_fn):
    """An element stage that runs its servos in short runs and judges its own targets (its
    tolerance, its hold, its rest): a servo that ends one of those runs short of its set point
    is how the stage proceeds (the set points move with the integral action at every
    record), so ServoTargetWarning is not raised there; the stage reports whether it
    converged and came to rest. A wall drifting at its cap is still warned of."""
    @functools.wraps(stage_fn)
    def run(*args, **kwargs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ServoTargetWarning)
            return stage_fn(*args, **kwargs)
    return run


@_judges_its_targets
def servo_stage(sample, grid, targets, stage: int, p: ElementParams, rec,
                log: Callable[[str], None] = _log, prestress=None, ends=None,
                grid_tension: float | None = None, integral: bool | None = None,
                bias=None, check_end: bool = True) -> dict:
    """Servo walls to ``targets`` (3,) Pa compression positive: converge within p.tol and
    p.unbalanced, then hold p.hold_steps steps; returns the max relative error while held
    (and, with density scaling, ``sample_inertial_number_max``: the sample's largest inertial
    number over the stage's records, logged when above QUASI_STATIC_LIMIT; the state the
    stage ends in is checked, InertialNumberWarning). With a ``prestress`` (cpp_dem.protocols.prestress.Prestress) its line forces are recorded too (its
    history, and the series' prestress_line_force_mean). With ``ends``
    (cpp_dem.protocols.prestress.EndTension) the grid's longitudinal ends are pulled by
    ``grid_tension`` (N/m) during the stage (series grid_end_force: the force per line, N).
    ``integral`` (default p.servo_integral): the set points take an integral correction near
    the targets (see below); off, they keep ``bias`` (Pa per axis, default 0) added to the
    targets: the tangent probes keep the held state's correction fixed, as their creep
    subtraction assumes.
    ``check_end`` False: the caller holds the element to rest after the stage
    (:func:`rest_hold`) and checks the state there; the stage's peak is still logged and
    returned."""
    if integral is None:
        integral = p.servo_integral
    sc, walls, ctl = sample.scene, sample.walls, sample.controller
    t = np.asarray(targets, float)
    bias = np.zeros(3) if bias is None else np.asarray(bias, float).copy()
    if ends is not None:
        ends.set(grid_tension)
    for a in range(3):
        ctl.set_stress(a, float(t[a] + bias[a]))
    ctl.max_speed = prep.default_max_speed(sc, walls, fraction=4e-4 * _rate_factor(sc, p))
    ctl.enabled = True
    record = _recorder(sample, grid, stage, rec, prestress, ends)

    fixed = getattr(sample, "fixed", ())

    # (The weight on the bottom, N: the solid volume does not change in a stage.)
    weight_n = (boundaries.weight(sc, p.gravity, sc.material(sample.material).density)
                if fixed else 0.0)

    balance = boundaries.BalanceWindow()

    def imbalance_ratio() -> float:
        # With fixed walls: each must carry its opposite servo wall's stress (and the bottom
        # the weight too) within boundaries.BALANCE_TOL of the target, in the mean over the
        # last BALANCE_RECORDS records (a single record's fluctuates by several %): <= 1
        # balanced. 0 without fixed walls.
        if not fixed:
            return 0.0
        size = measure.box_size(sc, walls)
        return balance.add(boundaries.imbalance(
            sc, walls, fixed, t, weight_n / float(size[0] * size[1]), signed=True))

    start, last = sc.step_count, time.perf_counter()
    wall0 = last
    size0, t0 = measure.box_size(sc, walls), sc.time
    ok = False
    window: list = []  # the unbalanced force per record while on target (inf off it)
    stall = None
    # The sample's inertial number (quasi_static.report: with density scaling) at every record:
    # its largest over the stage is reported, and logged when above the limit. (It was
    # sampled on the progress log's 5-second timer, so whether a stage warned depended on the
    # machine's speed.) The state the stage ends in is checked below (a warning).
    i_sample_max, i_sample_step = 0.0, 0
    # Integral action on the set points: the walls' servo is proportional (it moves a wall by
    # gain x error x area / wall-contact stiffness per step), so a packing that creeps under
    # the load holds it a steady error below the target (at full size 1.1 % at 20/20/40 kPa,
    # 12 % at the FEM's 2.3/2.3/5.4 kPa, against the 0.5 % tolerance). Within 20 % of a
    # target each record moves its set point by a quarter of the remaining error, at most
    # 25 % of the target; the set points stay for the hold.
    while sc.step_count - start < p.max_steps:
        sc.run(p.record_every)
        ax = record(t)
        if sc.density_scaling:
            i_now = float(sc.density_scaling_stats()["inertial_number"])
            if i_now > i_sample_max:
                i_sample_max, i_sample_step = i_now, sc.step_count - start
        err = np.abs(ax - t) / t
        near = err < 0.2
        if integral and near.any():
            bias = np.where(near, np.clip(bias + 0.25 * (t - ax), -0.25 * t, 0.25 * t), bias)
            for a in range(3):
                ctl.set_stress(a, float(t[a] + bias[a]))
        unb = sc.unbalanced_force()
        on_target = bool(np.all(err <= p.tol))
        r_unb, r_bal = unb / p.unbalanced, imbalance_ratio()
        if time.perf_counter() - last > 5:
            last = time.perf_counter()
            log(f"  stage {stage}: step {sc.step_count - start}, walls "
                f"{np.round(ax / 1e3, 2).tolist()} kPa (targets {np.round(t / 1e3, 2).tolist()}),"
                f" unbalanced {unb:.3g}, "
                + (f"fixed walls' imbalance {r_bal * boundaries.BALANCE_TOL:.3g}, "
                   if fixed and math.isfinite(r_bal) else "")
                + f"{quasi_static.describe(quasi_static.report(sc))}")
        if on_target and r_unb < 1 and r_bal <= 1:
            ok = True
            break
        # A stall (p.plateau_records > 0): on target for the last plateau_records records,
        # and the criterion that fails (the unbalanced force, or with fixed walls their
        # imbalance, each over its tolerance) no lower than 0.95 x its least before them. The
        # stage ends, not converged, and says which criterion stalled.
        window.append(max(r_unb, r_bal) if on_target else math.inf)
        if p.plateau_records and at_floor(window, p.plateau_records):
            ratio = min(window[-p.plateau_records:])
            what, tol = (("unbalanced force", p.unbalanced) if r_unb >= r_bal else
                         ("fixed walls' imbalance", boundaries.BALANCE_TOL))
            stall = {"criterion": what, "value": ratio * tol, "tolerance": tol}
            log(f"  stage {stage}: the walls on target, but the {what} has stayed at "
                f"{ratio * tol:.3g} (> {tol:g}) for {p.plateau_records} records "
                f"({p.plateau_records * p.record_every} steps): ends NOT converged")
            break
    steps = sc.step_count - start
    # (The density under scaling: the mass-weighted mean factor raises the inertia.)
    _check_stage_rate(sc, walls, size0, t0, t, stage, quasi_static.effective_density(
        sc, sc.material(sample.material).density))
    if i_sample_max > quasi_static.QUASI_STATIC_LIMIT:
        log(f"  stage {stage}: with density scaling the sample's inertial number peaked at "
            f"{i_sample_max:.3g} (step {i_sample_step}), above "
            f"{quasi_static.QUASI_STATIC_LIMIT:g}, while the walls servoed to the targets; "
            f"{quasi_static.describe(quasi_static.report(sc))} at the stage's end")
    if check_end:
        quasi_static.check(sc, f"element servo stage {stage}", stacklevel=2)
    hold_err = 0.0
    held = 0
    size_end = measure.box_size(sc, walls)
    while held < p.hold_steps:
        sc.run(p.record_every)
        held += p.record_every
        hold_err = max(hold_err, float(np.max(np.abs(record(t) - t) / t)))
    ax = held_stresses(sample)
    size_held = measure.box_size(sc, walls)
    return {"converged": ok, "steps": steps, "hold_max_rel_error": hold_err,
            # The box's strain (per axis, extension +) over the stage up to its end, and
            # over the hold after it: a packing at rest holds its size; a creeping one not.
            "strain_stage": ((size_end - size0) / size0).tolist(),
            "strain_hold": ((size_held - size_end) / size0).tolist(),
            "stall": stall, "unbalanced_final": float(sc.unbalanced_force()),
            "density_scaling": quasi_static.report(sc),
            "sample_inertial_number_max": i_sample_max,
            "wall_time_s": time.perf_counter() - wall0,
            "wall_stresses_pa": ax, "box_size_m": measure.box_size(sc, walls)}


class _Rate:
    """The inertial number of the box's deformation over a window: the largest axis strain
    rate |d(L) / L0| / dt (1/s) times the grains' mean diameter over sqrt(p / rho), with p the
    mean of the stresses held (Pa, at least 1 Pa) and rho the grains' density as the loading
    sees it (density scaling included), -."""

    def __init__(self, sample):
        sc = sample.scene
        self.sample = sample
        self.d = float(np.mean(measure.grain_diameters(sc)))
        self.rho = quasi_static.effective_density(sc, sc.material(sample.material).density)
        self.mark()

    def mark(self) -> None:
        sc = self.sample.scene
        self.size, self.time = measure.box_size(sc, self.sample.walls), sc.time

    def strain_rate(self, size0) -> float:
        """The largest axis strain rate since the last mark, 1/s (strains on ``size0``)."""
        sc = self.sample.scene
        dt = sc.time - self.time
        if not dt > 0:
            return 0.0
        return float(np.max(np.abs(measure.box_size(sc, self.sample.walls) - self.size)
                            / size0)) / dt

    def inertial(self, rate: float, pressure: float) -> float:
        return inertial.inertial_number(rate, self.d, max(abs(pressure), 1.0), self.rho)

    def rate_cap(self, inertial_number: float, pressure: float) -> float:
        """The strain rate at ``inertial_number`` under ``pressure`` (Pa), 1/s."""
        return inertial_number * math.sqrt(max(abs(pressure), 1.0) / self.rho) / self.d


def strain_ratios(element, fem, zero: float = 1e-12) -> list:
    """The element's strain over its FEM region's, per component (-): 1.0 where both are
    within ``zero`` of 0 (a held axis of a plane-strain region), None where only the FEM's
    is."""
    out = []
    for e, f in zip(np.asarray(element, float), np.asarray(fem, float)):
        if abs(f) > zero:
            out.append(float(e / f))
        else:
            out.append(1.0 if abs(e) <= zero else None)
    return out


def mobilised_friction_deg(stresses) -> float:
    """The friction angle the walls mobilise, deg: asin((s1 - s3) / (s1 + s3)) of the largest
    and least normal stresses held (Pa, compression positive; NaN without compression)."""
    s = np.asarray(stresses, float)
    hi, lo = float(s.max()), float(s.min())
    if not (hi + lo > 0 and lo >= 0):
        return float("nan")
    return math.degrees(math.asin(min(1.0, (hi - lo) / (hi + lo))))


def loading_stage(sample, grid, targets, stage: int, p: ElementParams, rec, *,
                  log: Callable[[str], None] = _log, prestress=None, ends=None,
                  tension=None, strain_path=None) -> dict:
    """The element loaded from the stresses it holds to ``targets`` (3,) Pa compression
    positive at a bounded rate, then held until it is at rest (:func:`rest_hold`).

    The stress-controlled axes (p.kinematics, KINEMATICS) follow set points that ramp from the
    stresses held to the targets, s(l) = s0 + l (s1 - s0); the strain-controlled axes follow
    l x ``strain_path`` (3,, compression positive, on the stage's start size; 0 where not
    given: a held axis). The ramp's l advances by dl a record while every stress axis is
    within 2 % of its set point; dl (from 1/100, at most 1/20) halves after a record whose
    box moved faster than p.load_inertial and grows by 1/4 while it stays under half that, so
    the box's inertial number, measured over each record, stays near p.load_inertial
    (reported: ``inertial_number_max``, against QUASI_STATIC_STRICT = 1e-3). With ``ends`` the
    grid's end tension ramps along, ``tension`` = (from, to) N/m. After the ramp the set
    points take servo_stage's integral correction until the stress axes are within p.tol
    (p.max_steps at most), then :func:`rest_hold`."""
    sc, walls, ctl = sample.scene, sample.walls, sample.controller
    modes = KINEMATICS[p.kinematics]
    stress_axes = [a for a in range(3) if modes[a] == "stress"]
    strain_axes = [a for a in range(3) if modes[a] == "strain"]
    s1 = np.asarray(targets, float)
    s0 = held_stresses(sample)
    path = np.zeros(3) if strain_path is None else np.asarray(strain_path, float)
    t_from, t_to = (None, None) if tension is None else (float(tension[0]), float(tension[1]))
    record = _recorder(sample, grid, stage, rec, prestress, ends)
    rate = _Rate(sample)
    size0, start, wall0 = measure.box_size(sc, walls), sc.step_count, time.perf_counter()
    dt_rec = p.record_every * sc.dt
    ctl.enabled = True
    lam, dlam, bias, at_cap = 0.0, 0.01, np.zeros(3), 0
    i_max, last, windows, ok = 0.0, time.perf_counter(), 0, False

    def set_points(lam: float) -> np.ndarray:
        sp = s0 + lam * (s1 - s0)
        return np.where([m == "stress" for m in modes], sp, s1)

    while sc.step_count - start < p.max_steps:
        sp = set_points(lam)
        pressure = float(np.mean(np.abs(held_stresses(sample))))
        cap = rate.rate_cap(p.load_inertial, pressure)
        # Each wall servoes on its own stress, so under gravity the bottom one (carrying the
        # weight too) backs off while the top one pushes: at a common speed cap the box would
        # only translate. The cap is 4 x the rate's; the ramp's pace bounds the rate (below),
        # and the strain axes are driven towards their path at most at half the rate.
        ctl.max_speed = 4.0 * cap * 0.5 * float(np.min(measure.box_size(sc, walls)))
        for a in stress_axes:
            ctl.set_stress(a, float(sp[a] + bias[a]))
        eps = (size0 - measure.box_size(sc, walls)) / size0
        for a in strain_axes:
            ctl.set_strain_rate(a, float(np.clip((lam * path[a] - eps[a]) / dt_rec,
                                                 -0.5 * cap, 0.5 * cap)))
        if ends is not None and tension is not None:
            ends.set(t_from + lam * (t_to - t_from))
        rate.mark()
        with warnings.catch_warnings(record=True) as caught:
            # (a wall at this stage's low cap while its stress trails the set point is how
            # the ramp waits: counted and said once, below, not warned per record)
            warnings.simplefilter("always", ControllerLimitWarning)
            sc.run(p.record_every)
        # (a servo short of its moving set point at a record's end is the ramp's wait too,
        # not a wall at its cap: not counted)
        at_cap += sum(isinstance(w.message, ControllerLimitWarning)
                      and not isinstance(w.message, ServoTargetWarning) for w in caught)
        for w in caught:
            if not isinstance(w.message, ControllerLimitWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        ax = record(sp)
        windows += 1
        i_now = rate.inertial(rate.strain_rate(size0), pressure)
        i_max = max(i_max, i_now)
        near = all(abs(ax[a] - sp[a]) <= 0.02 * max(abs(s0[a]), abs(s1[a])) for a in stress_axes)
        if lam < 1.0:
            # The ramp's pace: halved when a record's inertial number passed the bound,
            # raised (to 1/20 a record at most) while well under it.
            if i_now > p.load_inertial:
                dlam *= 0.5
            elif i_now < 0.5 * p.load_inertial:
                dlam = min(0.05, 1.25 * dlam)
            if near:
                lam = min(1.0, lam + dlam)
        else:
            err = np.array([abs(ax[a] - s1[a]) / abs(s1[a]) for a in stress_axes])
            if p.servo_integral:
                for a in stress_axes:
                    if abs(ax[a] - s1[a]) < 0.2 * abs(s1[a]):
                        bias[a] = float(np.clip(bias[a] + 0.25 * (s1[a] - ax[a]),
                                                -0.25 * abs(s1[a]), 0.25 * abs(s1[a])))
            strain_err = max((abs(eps[a] - path[a]) for a in strain_axes), default=0.0)
            if np.all(err <= p.tol) and strain_err <= max(1e-6, 0.02 * np.max(np.abs(path))):
                ok = True
                break
        if time.perf_counter() - last > 5:
            last = time.perf_counter()
            log(f"  stage {stage}: ramp {100 * lam:.0f} %, step {sc.step_count - start}, walls "
                f"{np.round(ax / 1e3, 2).tolist()} kPa (set points "
                f"{np.round(sp / 1e3, 2).tolist()}), inertial number {i_now:.2g}")
    for a in strain_axes:
        ctl.set_strain_rate(a, 0.0)  # (held where the path ends)
    steps = sc.step_count - start
    size_end = measure.box_size(sc, walls)
    if at_cap:
        log(f"  stage {stage}: a wall trailed its set point at the ramp's speed cap in "
            f"{at_cap} of {windows} records (the ramp waited for it)")
    if not ok:
        log(f"  stage {stage}: the walls did not reach the targets within {p.max_steps} steps "
            f"(walls {np.round(held_stresses(sample) / 1e3, 2).tolist()} kPa)")
    rest = rest_hold(sample, s1, p, lambda: record(s1), stress_axes, bias, rate, log=log,
                     stage=stage)
    ax = held_stresses(sample)
    size_held = measure.box_size(sc, walls)
    return {"converged": ok, "steps": steps, "hold_max_rel_error": rest["hold_max_rel_error"],
            "strain_stage": ((size_end - size0) / size0).tolist(),
            "strain_hold": ((size_held - size_end) / size0).tolist(),
            "stall": None, "unbalanced_final": float(sc.unbalanced_force()),
            "density_scaling": quasi_static.report(sc),
            "wall_time_s": time.perf_counter() - wall0, "wall_stresses_pa": ax,
            "box_size_m": size_held, "box_size_start_m": size0,
            "inertial_number_max": i_max, "ramp_records": windows,
            "records_at_speed_cap": at_cap, "rest": rest,
            "strain_axes": list(strain_axes), "strain_path_given": strain_path is not None}


def _strain_path_note(st: dict) -> str:
    """The stage log's note on its strain-controlled axes (their stresses are the element's
    answer, not servoed to the targets): on the FEM region's strain path, or held where the
    stage has none; empty without such axes."""
    axes = st.get("strain_axes") or []
    if not axes:
        return ""
    names = ", ".join("xyz"[a] for a in axes)
    how = "on the FEM region's strain path" if st.get("strain_path_given") else "held"
    strain = ", ".join(f"{100 * st['strain_stage'][a]:.3g}" for a in axes)
    return (f" ({names} strain-controlled, {how}: strain {strain} % (extension +); their "
            "stresses are the element's own, not servoed to the targets)")


@_judges_its_targets
def rest_hold(sample, targets, p: ElementParams, record, stress_axes, bias, rate: "_Rate", *,
              log: Callable[[str], None] = _log, stage: int = 0) -> dict:
    """Holds the element (the stress axes at ``targets`` + ``bias``, the strain axes where
    they are) in holds of p.hold_steps until it is at rest: over one whole hold the box's
    strain rate gives an inertial number at most p.rest_inertial, the unbalanced-force ratio
    at its end is at most p.rest_unbalanced, and the stress axes held their targets within
    p.tol in the mean over the hold (one record's wall stress scatters by about 1 % at a few
    kPa; ``hold_max_rel_error`` reports the largest). After p.rest_max_holds holds without that
    the element is ``at_strength`` when it still moves (its last hold's inertial number above
    p.rest_inertial: it flows or creeps under its targets), else ``not_at_rest`` (still, but
    its unbalanced force or its walls' error failed: ``failed`` says which); the friction angle
    its walls mobilise is given either way.
    Returns {"status", "inertial_number_max" (over the holds), "inertial_number_end" (the
    last hold's), "unbalanced_end", "hold_steps" (all holds), "holds", "hold_max_rel_error",
    "mobilised_friction_deg", "failed" (the checks the last hold failed)}."""
    sc, ctl = sample.scene, sample.controller
    t = np.asarray(targets, float)
    for a in stress_axes:
        ctl.set_stress(a, float(t[a] + bias[a]))
    size0 = measure.box_size(sc, sample.walls)
    n_rec = max(1, int(math.ceil(p.hold_steps / p.record_every)))
    inertials, status, failed, err_all = [], "at_strength", [], 0.0
    steps0 = sc.step_count
    for _k in range(p.rest_max_holds):
        rate.mark()
        off = np.zeros((n_rec, len(stress_axes)))  # (signed, relative to the target)
        for k in range(n_rec):
            sc.run(p.record_every)
            ax = record()
            off[k] = [(ax[a] - t[a]) / abs(t[a]) for a in stress_axes]
        err_all = max(err_all, float(np.max(np.abs(off), initial=0.0)))
        err = float(np.max(np.abs(off.mean(axis=0)), initial=0.0))
        if p.servo_integral and err > 0.5 * p.tol:
            # (the proportional servo holds a creeping packing a steady error off: the next
            # hold's set points take half the mean error back, at most 25 % of the target)
            bias = np.array(bias, float)
            for i, a in enumerate(stress_axes):
                bias[a] = float(np.clip(bias[a] - 0.5 * off[:, i].mean() * abs(t[a]),
                                        -0.25 * abs(t[a]), 0.25 * abs(t[a])))
                ctl.set_stress(a, float(t[a] + bias[a]))
        pressure = float(np.mean(np.abs(ax)))
        i_hold = rate.inertial(rate.strain_rate(size0), pressure)
        inertials.append(i_hold)
        unb = float(sc.unbalanced_force())
        failed = ([f"inertial number {i_hold:.3g} > {p.rest_inertial:g}"]
                  if i_hold > p.rest_inertial else []) + (
                 [f"unbalanced force {unb:.3g} > {p.rest_unbalanced:g}"]
                 if unb > p.rest_unbalanced else []) + (
                 [f"walls {100 * err:.2f} % off their targets in the mean > {100 * p.tol:g} %"]
                 if err > p.tol else [])
        if not failed:
            status = "at_rest"
            break
    if status != "at_rest" and inertials[-1] <= p.rest_inertial:
        # (still: not flowing, so not at its strength; what failed is a force or the servo)
        status = "not_at_rest"
    ax = held_stresses(sample)
    out = {"status": status, "inertial_number_max": float(max(inertials)),
           "inertial_number_end": float(inertials[-1]), "unbalanced_end": unb,
           "hold_steps": int(sc.step_count - steps0), "holds": len(inertials),
           "hold_max_rel_error": err_all, "mobilised_friction_deg": mobilised_friction_deg(ax),
           "failed": failed,
           # (the grains' own: their contacts' relative speeds, where the box's rate above
           # is the walls'; warned above QUASI_STATIC_LIMIT with density scaling)
           "sample_inertial_number_end": float(
               sc.density_scaling_stats()["inertial_number"])}
    quasi_static.check(sc, f"element stage {stage} at the end of its rest hold", stacklevel=2)
    log(f"  stage {stage}: {status} after {len(inertials)} hold(s) of {n_rec * p.record_every} "
        f"steps (inertial number {inertials[-1]:.2g}, unbalanced {unb:.3g}"
        + (f"; not at rest: {'; '.join(failed)}; the walls mobilise "
           f"{out['mobilised_friction_deg']:.1f} deg" if failed else "") + ")")
    return out


def save_final_state(path: Path, sample, p: ElementParams, targets, *, prestressed: bool,
                     label: str, ends=None, prestress=None) -> None:
    """The element's final state, to be continued (``geogrid-dem continue``): the scene's
    checkpoint (cpp_dem.checkpoint.save_checkpoint) with, as its extra JSON, the element's
    parameters, its label and variant, the targets (Pa), the controller's set points and axis
    modes, and the grid's end conditions (the end tension, N/m; the prestress grips locked or
    not)."""
    from cpp_dem.checkpoint import save_checkpoint

    ctl = sample.controller
    save_checkpoint(path, sample.scene, extra={
        "kind": "prs_element_002 element", "label": label, "prestressed": bool(prestressed),
        "params": _params_json(p), "targets_pa": [float(x) for x in targets],
        "set_points": [float(ctl.goal(a)) for a in range(3)],
        "modes": [ctl.mode(a) for a in range(3)],
        "grid_end_tension_n_per_m": None if ends is None else float(ends.tension_per_m),
        "prestress_locked": bool(prestress is not None and prestress.locked)})


#: The ``kind`` of a prepared packing's file (:func:`save_prepared`).
PREPARED_KIND = "woven element, prepared"


def _params_json(p: ElementParams) -> dict:
    """The element's parameters as JSON keeps them (a state file's ``params``)."""
    import json
    from dataclasses import asdict

    return json.loads(json.dumps(asdict(p), default=lambda o: np.asarray(o).tolist()))


def save_prepared(path: Path, sample, p: ElementParams, grow_stress: float,
                  label: str) -> None:
    """The grown packing of :func:`prepare_woven_element` (before its variant is loaded) to
    ``path``, to be restored by :func:`restore_prepared` instead of grown again (a resumed
    run's packings): the scene's checkpoint with, as its extra JSON, the element's
    parameters, the grow stress (Pa), the label and the growth's history."""
    from cpp_dem.checkpoint import save_checkpoint

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_checkpoint(path, sample.scene, extra={
        "kind": PREPARED_KIND, "label": label, "params": _params_json(p),
        "grow_stress_pa": float(grow_stress),
        "growth_history": [{k: _plain(v) for k, v in r.items()} for r in sample.growth_history]})


def _plain(v):
    """A growth-history value as JSON keeps it: a str, an int, or a float."""
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return int(v)
    return float(v)


def restore_prepared(prepared: dict, p: ElementParams, grow_stress: float,
                     log: Callable[[str], None] = _log) -> bool:
    """Fills ``prepared`` (run_element's) from its ``file`` when that holds the packing these
    parameters and this grow stress (Pa) grow: the element's skeleton
    (``prepare_woven_element(build_only=True)``) with the file's state, bitwise the grown one;
    True then. False, and ``prepared`` unchanged, when there is no file; a file of other
    parameters or grow stress is set aside (renamed ``*.stale``, said in the log) and the
    packing is grown again."""
    from cpp_dem.checkpoint import checkpoint_extra, load_checkpoint

    path = Path(prepared["file"])
    if not path.is_file():
        return False
    extra = checkpoint_extra(path)
    why = ("not a prepared packing" if extra.get("kind") != PREPARED_KIND else
           "other element parameters" if extra.get("params") != _params_json(p) else
           f"grown to {extra.get('grow_stress_pa')!r} Pa, not {float(grow_stress)!r}"
           if extra.get("grow_stress_pa") != float(grow_stress) else None)
    if why is not None:
        stale = path.with_name(path.name + ".stale")
        path.replace(stale)
        log(f"{path}: {why}: set aside as {stale.name}; the packing is grown again")
        return False
    sample, grid = prepare_woven_element(p, float(grow_stress), log=lambda _m: None,
                                         build_only=True)
    load_checkpoint(path, sample.scene)
    sample.growth_history[:] = [dict(r) for r in extra["growth_history"]]
    blob = bytes(_core._checkpoint_save(sample.scene))
    prepared["state"] = (sample, grid, blob)
    prepared["sha256"] = hashlib.sha256(blob).hexdigest()
    prepared["label"] = extra["label"]
    prepared["wall_time_s"] = 0.0
    log(f"{extra['label']}: the grown packing restored from {path} (step "
        f"{sample.scene.step_count}): no growth")
    return True


GROWTH_COLUMNS = ("phase", "step", "time_s", "coordination", "porosity", "wall_stress_pa",
                  "unbalanced_force", "dt_s")


def write_growth_history(out: Path, label: str, history: list) -> None:
    """The preparation's history (TriaxialSample.growth_history rows) as <label>_growth.csv
    and a figure <label>_growth.png: coordination number, porosity and mean wall stress
    against the step, the fast phase shaded."""
    import csv as _csv

    with open(out / f"{label}_growth.csv", "w", newline="") as fh:
        w = _csv.DictWriter(fh, fieldnames=GROWTH_COLUMNS)
        w.writeheader()
        for row in history:
            w.writerow({k: row[k] for k in GROWTH_COLUMNS})
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    step = np.array([r["step"] for r in history], float)
    fast = np.array([r["phase"] == "fast" for r in history])
    fig, axes = plt.subplots(3, 1, figsize=(6.0, 6.5), sharex=True, constrained_layout=True)
    for ax, key, scale, name in ((axes[0], "coordination", 1.0, "coordination number, -"),
                                 (axes[1], "porosity", 1.0, "porosity, -"),
                                 (axes[2], "wall_stress_pa", 1e-3, "mean wall stress, kPa")):
        ax.plot(step, [r[key] * scale for r in history], "k.-", ms=3, lw=0.8)
        if fast.any():
            ax.axvspan(step[0], step[fast][-1], color="0.9", zorder=0)
        ax.set_ylabel(name)
    axes[0].set_title(f"{label}: preparation (grey: fast growth, then growth to the stress)",
                      fontsize=9)
    axes[2].set_xlabel("step")
    fig.savefig(out / f"{label}_growth.png", dpi=120)
    plt.close(fig)


def _check_stage_rate(sc, walls, size0, t0: float, targets, stage: int,
                      rho: float) -> None:
    """Warns (cpp_dem.InertialNumberWarning) when a servo stage deformed the element faster
    than quasi-statically: the rate is the largest mean strain rate of the box's axes over the
    stage (|dL / L0| / dt, 1/s), the pressure the mean target, d the grains' mean diameter,
    rho (kg/m^3) their density."""
    dt = sc.time - t0
    d = measure.grain_diameters(sc)
    pressure = float(np.mean(targets))
    if not (dt > 0 and pressure > 0 and len(d)):
        return
    rate = float(np.max(np.abs(measure.box_size(sc, walls) - size0) / size0)) / dt
    d_mean = float(np.mean(d))
    inertial.check_quasi_static(inertial.inertial_number(rate, d_mean, pressure, rho),
                                f"element servo stage {stage}", rate=rate, diameter=d_mean,
                                pressure=pressure, density=rho, stacklevel=3)


def probe_tangent(sample, grid, p: ElementParams, target, *, rel: float, signs=None,
                  ends=None, grid_tension: float | None = None,
                  log: Callable[[str], None] = _log) -> dict:
    """The wall-bounded element's tangent at its current state, held at ``target`` (3,) Pa
    compression positive, by three stress probes (issue 18: the element's tangent in place of
    the isotropic secant in region mode). From a checkpoint of the state, probe ``a`` servoes
    the walls to the target with axis ``a`` changed by ``signs[a] * rel`` times the target's
    mean (``signs``: +1 or -1 per axis, the handed-over increment's direction; default +1) and
    measures the box's strain. The three probes give the compliance S (strain per stress, the
    stress changes being the targets', which the walls hold within ``p.tol``); the normal
    block is C = S^-1 made symmetric. The walls cannot shear the element, so the shear moduli
    are those of each plane's normal block as if it were isotropic in that plane, G_ij =
    (C_ii + C_jj - 2 C_ij) / 4 (exact for an isotropic C). The state is restored after (a
    PRS grid's grips stay as they are; the probes are not recorded).

    Returns plain numbers: ``tangent_voigt_pa`` (6 x 6, Voigt, order xx yy zz yz xz xy),
    ``normal_pa`` (3 x 3), ``probe_pa`` (the three stress changes), ``probe_strains`` (3 x 3,
    column a: probe a's strain, compression positive), ``converged`` per probe, ``steps``.
    """
    if not (0 < rel <= 0.5):
        raise _core.ParameterError(f"rel={rel!r}: the probe's size relative to the mean "
                                   "stress must be in (0, 0.5]")
    sc, walls = sample.scene, sample.walls
    t0 = np.asarray(target, float)
    signs = np.ones(3) if signs is None else np.where(np.asarray(signs, float) < 0, -1.0, 1.0)
    blob = bytes(_core._checkpoint_save(sc))
    size0 = measure.box_size(sc, walls)
    step0 = sc.step_count
    # The held state's set-point correction (servo_stage's integral action), kept fixed.
    held = np.array([sample.controller.goal(a) for a in range(3)]) - t0
    # A probe past the element's strength flows on: it stops after 10 holds (its strain then
    # is the flow's over that time, a soft answer, said), not after the stage's max_steps.
    pp = replace(p, max_steps=min(p.max_steps, 10 * max(p.hold_steps, p.record_every)))
    d = rel * float(t0.mean())
    strains, ok, used = np.zeros((3, 3)), [], []
    try:
        for a in range(3):
            _core._checkpoint_load(sc, blob)
            t = t0.copy()
            t[a] += signs[a] * d
            st = servo_stage(sample, grid, t, -1 - a, pp, lambda **row: None, log=log,
                             ends=ends, grid_tension=grid_tension, integral=False, bias=held)
            strains[:, a] = (size0 - st["box_size_m"]) / size0
            ok.append(bool(st["converged"]))
            used.append(sc.step_count - step0)
        # The drift: held at the target itself as long as the longest probe, the element
        # still creeps (near its strength, most of a probe's strain); subtracted at each
        # probe's step count.
        _core._checkpoint_load(sc, blob)
        drift = [(0, np.zeros(3))]

        def rec(**row) -> None:
            size = np.array([row["lx"], row["ly"], row["lz"]])
            drift.append((row["step"] - step0, (size0 - size) / size0))

        servo_stage(sample, grid, t0, -4, replace(pp, hold_steps=max(used)), rec, log=log,
                    ends=ends, grid_tension=grid_tension, integral=False, bias=held)
    finally:
        _core._checkpoint_load(sc, blob)
    ds_steps = np.array([k for k, _ in drift], float)
    ds_strain = np.array([e for _, e in drift])
    creep = np.array([[np.interp(n, ds_steps, ds_strain[:, i]) for n in used]
                      for i in range(3)])
    raw = strains.copy()
    strains = strains - creep
    dsig = signs * d
    compliance = strains / dsig[None, :]  # column a: strain per Pa of probe a
    with np.errstate(all="ignore"):
        try:
            c = fixedorder.inv3(compliance)  # (not LAPACK's: the same bits on every CPU)
        except ValueError:
            c = np.full((3, 3), np.nan)
    c = 0.5 * (c + c.T)
    voigt = np.zeros((6, 6))
    voigt[:3, :3] = c
    for k, (i, j) in zip((3, 4, 5), ((1, 2), (0, 2), (0, 1))):
        voigt[k, k] = 0.25 * (c[i, i] + c[j, j] - 2.0 * c[i, j])
    if not all(ok):
        axes = ", ".join("xyz"[a] for a in range(3) if not ok[a])
        log(f"  tangent probes: the {axes} probe(s) did not settle within {pp.max_steps} "
            "steps (a probe past the element's strength flows): the tangent there is the "
            "flow's over that time")
    return {"tangent_voigt_pa": voigt.tolist(), "normal_pa": c.tolist(),
            "probe_pa": dsig.tolist(), "probe_strains": strains.tolist(),
            "probe_strains_raw": raw.tolist(), "converged": ok,
            "steps": int(sum(used) + max(used))}


def run_element(p: ElementParams, targets: list, *, prestressed: bool, label: str, out: Path,
                log: Callable[[str], None] = _log, cache: dict | None = None,
                grid_tension: list | None = None, probe: float = 0.0,
                prepared: dict | None = None, grow_stress: float | None = None,
                prep_label: str | None = None, draw_figures: bool = True,
                fem_strain_increment=None) -> dict:
    """The DEM element driven through ``targets`` (rows of 3, Pa, compression positive).

    Prepared at the first row's mean stress, then servoed to each row in turn. Returns the
    element summary (plain numbers); writes <label>.h5/.csv and the VTK files.

    ``grid_tension`` (one value per row, N/m of width, tension positive; issue 18): the
    tension an FEM layer carries across the element's faces, handed over. The grid's
    longitudinal (x) ends are then force-controlled (cpp_dem.protocols.prestress.EndTension) at that
    tension during each row's stage, a PRS grid's grips let go first: the walls then carry
    the soil's stress alone, as the FEM region's soil cells do, and the grid is counted once.
    None (the default): the ends are free (RE) or held by the locked grips (PRS).

    ``cache`` (a dict the caller keeps; the two-way loop's): the element prepared and servoed
    to the first row is kept there (its objects and its checkpoint bytes), keyed by that row
    and ``prestressed``; a later call with the same first row restores it and runs only the
    remaining rows (bitwise the run it would have made; its records then start at the second
    row). Same ``p`` for every call with one cache.

    ``prepared`` (a dict the caller keeps; woven grids): RE and PRS on one grown packing. The
    first call prepares the element (:func:`prepare_woven_element`, to ``grow_stress``, Pa,
    default the first row's mean) and keeps it there with its checkpoint bytes; a later call
    restores that state and only loads its own variant (:func:`load_variant`), bitwise the
    run it would have made from its own preparation. ``prep_label``: the name of the
    preparation's files (``<prep_label>_growth.csv/.png``; default ``label``).

    ``draw_figures``: woven grids draw this element's figures alone (cpp_dem.measure.grid_figures;
    a caller that draws several elements on shared scales from ``<label>_figure.npz`` says
    False).

    ``p.ramp``: every row after the first is a :func:`loading_stage` (a ramp at a bounded
    inertial number, then held until at rest), and the first row's stage is held until at
    rest too (:func:`rest_hold`), so the loading starts from rest. ``fem_strain_increment``
    (3,, compression positive): the FEM region's strain over the last row's loading; the
    strain-controlled axes of p.kinematics follow it, and the summary gives
    ``strain_ratio_to_fem`` (the element's ``loading_strain`` over it, per axis; 1 where
    both are 0). The summary's ``rest`` is the last stage's (status at_rest, at_strength or
    not_at_rest: rest_hold,
    with ``rest_initial`` the first's), and ``interaction_start`` the measures at the start
    of the loading (woven grids).

    ``probe`` (> 0, relative): after the last row, the element's tangent there by three
    stress probes of that size relative to the mean stress (:func:`probe_tangent`), each in
    the direction of the last increment on its axis: the summary's ``tangent_voigt_pa`` and
    ``tangent_probes``. 0 (the default): none."""
    t_start = time.perf_counter()
    targets = [np.asarray(t, float) for t in targets]
    # One thread by default (ElementParams.threads): on a shared 2-core machine OpenMP with 2
    # threads was measured ~1000x slower than 1 thread for this small scene (oversubscription).
    apply_threads(p.threads)
    (out / "vtk").mkdir(parents=True, exist_ok=True)
    woven_grid = p.geogrid != "square"
    check_element_params(p)
    if grid_tension is not None:
        grid_tension = [float(x) for x in grid_tension]
        if len(grid_tension) != len(targets) or not all(map(math.isfinite, grid_tension)):
            raise _core.ParameterError(f"grid_tension={grid_tension!r}: must be one finite "
                                       f"value (N/m) per target row ({len(targets)})")
    key = (bool(prestressed), tuple(float(x) for x in targets[0]),
           None if grid_tension is None else grid_tension[0])
    hit = cache.get(key) if cache is not None and len(targets) > 1 else None
    ends = None
    if hit is not None:
        sample, grid, ps, ends, blob, first_stage = hit
        _core._checkpoint_load(sample.scene, blob)
        log(f"{label}: the element at the first targets restored from the cache "
            f"(step {sample.scene.step_count}): no preparation")
    elif woven_grid and prepared is not None:
        grow_pa = float(targets[0].mean()) if grow_stress is None else float(grow_stress)
        if "state" not in prepared and prepared.get("file") is not None:
            restore_prepared(prepared, p, grow_pa, log=log)
        if "state" in prepared:
            sample, grid, blob = prepared["state"]
            _core._checkpoint_load(sample.scene, blob)
            log(f"{label}: the prepared packing of {prepared['label']} restored (step "
                f"{sample.scene.step_count})")
        else:
            sample, grid = prepare_woven_element(p, grow_pa, log=log)
            blob = bytes(_core._checkpoint_save(sample.scene))
            prepared["state"] = (sample, grid, blob)
            prepared["sha256"] = hashlib.sha256(blob).hexdigest()
            prepared["label"] = prep_label or label
            prepared["wall_time_s"] = time.perf_counter() - t_start
            if prepared.get("file") is not None:
                save_prepared(prepared["file"], sample, p, grow_pa, prepared["label"])
        ps = load_variant(sample, grid, p, prestressed, log=log)
    elif woven_grid:
        sample, grid, ps = make_woven_element(
            p, float(targets[0].mean()) if grow_stress is None else float(grow_stress),
            prestressed, log=log)
    else:
        sample, grid, ps = make_element(p, float(targets[0].mean()), prestressed, log=log)
    sc, walls = sample.scene, sample.walls
    t_prepared = time.perf_counter()
    if woven_grid and p.grid_ends == "tension" and grid_tension is None:
        # PRS's prestress as a force at the grid's ends throughout, RE's ends free: the same
        # end conditions, and no grip holds the grid in place.
        grid_tension = [p.prestress if prestressed else 0.0] * len(targets)
        ends_by_prestress = True
    else:
        ends_by_prestress = False
    if hit is None and sample.growth_history and not (prepared and prepared.get("written")):
        write_growth_history(out, prep_label or label, sample.growth_history)
        if prepared is not None:
            prepared["written"] = True
    if grid_tension is not None and ends is None:
        from cpp_dem.protocols.prestress import EndTension

        if ps is not None:
            ps.unlock()
        ends = EndTension(sc, grid)
        log(f"{label}: the grid's longitudinal ends pulled by T_p = {grid_tension[0] / 1e3:g} "
            f"kN/m throughout (x {ends.ends.spacing * 1e3:.2f} mm line spacing)"
            if ends_by_prestress else
            f"{label}: the FEM layer's tension handed over: the grid's longitudinal ends "
            f"pulled by {np.round(np.array(grid_tension) / 1e3, 4).tolist()} kN/m (x "
            f"{ends.ends.spacing * 1e3:.2f} mm line spacing)"
            + ("; the prestress grips let go" if ps is not None else ""))
    meta = {"case": "prs_element", "label": label, "prestressed": prestressed,
            "units": "SI; stresses compression positive"}
    # The locked-in prestress is a series of PRS runs only; the end force, of handed-over
    # grid tensions only.
    absent = ({"prestress_line_force_mean"} if ps is None else set()) | (
        {"grid_end_force"} if ends is None else set())
    series = {k: v for k, v in SERIES.items() if k not in absent}
    h5 = H5Recorder(out / f"{label}.h5", series=series, metadata=meta, overwrite=True,
                    snapshot_fields=("positions", "radii"))
    csv = CsvRecorder(out / f"{label}.csv", series=series, overwrite=True)

    # 002's measures over the loading, every 10th record and the first of each stage (woven
    # grids): <label>_measures.csv,
    # appended and flushed row by row.
    measures = {"n": 0, "fh": None, "writer": None}
    locked_n = (float(np.mean(ps.history[0]["line_forces_n"])) if ps is not None else
                grid_tension[-1] * ends.ends.spacing if ends is not None else 0.0)
    ref_measures = sc.positions.copy()

    def measure_row(row: dict) -> None:
        import csv as _csv
        from cpp_dem.measure import grid_soil

        zg = float(np.mean(np.asarray(sc.positions)[grid.spheres, 2]))
        m = {"stage": row["stage"], "step": row["step"], "time_s": row["time"],
             "sigma_z_pa": row["sigma_z"], "lz_m": row["lz"],
             **grid_soil.history_row(sc, grid, z_grid=zg, locked_n=locked_n,
                                     reference_positions=ref_measures)}
        if measures["fh"] is None:
            measures["fh"] = open(out / f"{label}_measures.csv", "w", newline="")
            measures["writer"] = _csv.DictWriter(measures["fh"], fieldnames=list(m))
            measures["writer"].writeheader()
        measures["writer"].writerow(m)
        measures["fh"].flush()

    def rec(**row) -> None:
        if woven_grid and row.get("stage", -1) >= 0:
            # (every 10th record, and the first of each stage)
            if measures["n"] % 10 == 0 or row["stage"] != measures.get("stage"):
                measure_row(row)
                measures["n"] = 0
                measures["stage"] = row["stage"]
            measures["n"] += 1
        row = {k: v for k, v in row.items() if k in series}
        h5.record(**row)
        csv.record(**row)

    # The series vtk/<label>_spheres.pvd and <label>_box.pvd: the state this call starts from
    # (the prepared element, or the one restored from the cache), then the end.
    vtk_pvds = {k: PvdWriter(out / "vtk" / f"{label}_{k}.pvd", overwrite=True)
                for k in ("spheres", "box")}
    lo0 = np.array([sc.wall_positions[walls[2 * a]] for a in range(3)])
    vtk_pvds["spheres"].add(sc.time, write_vtk_spheres(
        out / "vtk" / f"{label}_spheres_prepared.vtp", sc).name)
    vtk_pvds["box"].add(sc.time, write_vtk_box(
        out / "vtk" / f"{label}_box_prepared.vtp", lo0, lo0 + measure.box_size(sc, walls),
        time=sc.time).name)
    stages = [] if hit is None else [first_stage]
    try:
        ref_pos = None
        for k, t in enumerate(targets):
            if k < len(stages):
                continue  # (restored from the cache)
            if k == len(targets) - 1:
                ref_pos = sc.positions.copy()
                size_before = measure.box_size(sc, walls)
                stress_before = held_stresses(sample)
                # (the longitudinal lines' mean force where the loading starts, N: PRS's
                # prestress as held)
                lines = ps if ps is not None else ends
                prestress_at_loading = (float(lines.line_forces().mean()) if lines is not None
                                        else None)
                if woven_grid:
                    # 002's measures where the loading starts: the summary's change over it
                    from cpp_dem.measure import grid_soil

                    interaction_start = grid_soil.summary(
                        sc, grid, z_grid=float(np.mean(np.asarray(sc.positions)[grid.spheres, 2])),
                        locked_n=locked_n)
            if p.ramp and k > 0:
                st = loading_stage(
                    sample, grid, t, k, p, rec, log=log, prestress=ps, ends=ends,
                    tension=None if ends is None else (grid_tension[k - 1], grid_tension[k]),
                    strain_path=(fem_strain_increment if k == len(targets) - 1 else None))
            else:
                st = servo_stage(sample, grid, t, k, p, rec, log=log, prestress=ps, ends=ends,
                                 grid_tension=None if ends is None else grid_tension[k],
                                 check_end=not p.ramp)
                if p.ramp:
                    # (the loading starts from rest: held at the first targets until then)
                    st["rest"] = rest_hold(
                        sample, t, p, functools.partial(_recorder(
                            sample, grid, k, rec, ps, ends), t),
                        range(3), np.array([sample.controller.goal(a) for a in range(3)]) - t,
                        _Rate(sample), log=log, stage=k)
            stages.append(st)
            if k == 0 and cache is not None and len(targets) > 1:
                cache[key] = (sample, grid, ps, ends, bytes(_core._checkpoint_save(sc)), st)
            log(f"{label} stage {k}: walls {np.round(st['wall_stresses_pa'] / 1e3, 3).tolist()} "
                f"kPa for targets {np.round(t / 1e3, 3).tolist()} kPa"
                + _strain_path_note(st) + f" in {st['steps']} steps "
                f"({'converged' if st['converged'] else 'NOT converged'}); held within "
                f"{100 * st['hold_max_rel_error']:.2f} % over {p.hold_steps} steps")
        h5.snapshot(sc)
        if woven_grid:
            save_final_state(out / f"{label}_final.h5", sample, p, targets[-1],
                             prestressed=prestressed, label=label, ends=ends, prestress=ps)
    finally:
        h5.close()
        csv.close()
        if measures["fh"] is not None:
            measures["fh"].close()
    size_after = measure.box_size(sc, walls)
    # Displacement above vs below the geogrid over the last stage (002 §6), m, from the
    # element centre's frame (the walls move symmetrically about it).
    mask = measure.sphere_mask(sc)
    disp = sc.positions - ref_pos
    z0 = ref_pos[:, 2]
    zg = 0.5 * (sc.wall_positions[walls[4]] + sc.wall_positions[walls[5]])
    above = mask & (z0 > zg)
    below = mask & (z0 < zg)
    f = grid.member_axial_forces(sc)
    longi = grid.member_direction == geogrid.LONGITUDINAL
    vtk_pvds["spheres"].add(sc.time, write_vtk_spheres(
        out / "vtk" / f"{label}_spheres.vtp", sc).name)
    write_vtk_contacts(out / "vtk" / f"{label}_contacts.vtp", sc)
    extra = {}
    if woven_grid:
        from cpp_dem.measure import grid_soil as interaction

        from cpp_dem.measure import grid_figures

        interaction.write_vtk_woven(out / "vtk" / f"{label}_geogrid.vtp", sc, grid)
        # The figures' data: the case draws RE against PRS on shared scales from these.
        fig_data = grid_figures.figure_data(sc, grid, reference_positions=ref_pos)
        grid_figures.save_figure_data(out / f"{label}_figure.npz", fig_data)
        if draw_figures:
            grid_figures.draw_all({label: fig_data}, out, label)
        zg_now = float(np.mean(np.asarray(sc.positions)[grid.spheres, 2]))
        extra["interaction"] = interaction.summary(sc, grid, z_grid=zg_now,
                                                   reference_positions=ref_pos,
                                                   locked_n=locked_n)
        extra["locked_in_n"] = locked_n
        # (PRS: the members' mean line force where the loading starts, N: with the ends
        # released, what the grains hold of the prestress)
        extra["prestress_at_loading_n"] = prestress_at_loading
        if ps is not None:
            extra["prestress_target_n"] = ps.target_n
            extra["prestress_locked_final_n"] = ps.line_forces().tolist()
    else:
        geogrid.write_vtk_geogrid(out / "vtk" / f"{label}_geogrid.vtp", sc, grid)
    lo = np.array([sc.wall_positions[walls[2 * a]] for a in range(3)])
    vtk_pvds["box"].add(sc.time, write_vtk_box(out / "vtk" / f"{label}_box.vtp", lo,
                                               lo + size_after, time=sc.time).name)
    strain_inc = (size_before - size_after) / size_before
    if "rest" in stages[-1]:
        # Rest shown by motion (rest_hold): the last stage's, and the strain from the start of
        # the loading to the end of its rest hold (compression positive).
        r = stages[-1]["rest"]
        extra["rest"] = {k: r[k] for k in ("status", "inertial_number_max",
                                           "inertial_number_end", "hold_steps",
                                           "unbalanced_end", "mobilised_friction_deg",
                                           "failed", "sample_inertial_number_end")}
        extra["rest"]["loading_inertial_number_max"] = stages[-1].get("inertial_number_max")
        if "rest" in stages[0] and len(stages) > 1:
            # (the first stage's hold, before the loading: 'not_at_rest' where it did not
            # come to rest within its holds; the element is judged after the loading)
            extra["rest_initial"] = {k: stages[0]["rest"][k] for k in (
                "status", "inertial_number_end", "unbalanced_end", "hold_steps", "failed")}
            if extra["rest_initial"]["status"] != "at_rest":
                extra["rest_initial"]["status"] = "not_at_rest"
        extra["loading_strain"] = strain_inc.tolist()
        if woven_grid:
            extra["interaction_start"] = interaction_start
    if fem_strain_increment is not None:
        extra["fem_strain_increment"] = [float(x) for x in fem_strain_increment]
        extra["strain_ratio_to_fem"] = strain_ratios(strain_inc, fem_strain_increment)
    # Load–settlement: the vertical strain of the last stage (compression positive) for its
    # vertical stress increment.
    d_sigma_z = float(targets[-1][2] - stress_before[2])
    extra["vertical_strain_last_stage"] = float(strain_inc[2])
    extra["vertical_stress_increment_pa"] = d_sigma_z
    extra["vertical_compliance_per_pa"] = (float(strain_inc[2] / d_sigma_z)
                                           if abs(d_sigma_z) > 0.01 * abs(targets[-1][2])
                                           else None)
    if probe > 0:
        tp = time.perf_counter()
        pr = probe_tangent(sample, grid, p, targets[-1], rel=probe,
                           signs=targets[-1] - targets[0] if len(targets) > 1 else None,
                           ends=ends, log=log,
                           grid_tension=None if ends is None else grid_tension[-1])
        pr["wall_time_s"] = time.perf_counter() - tp
        extra["tangent_voigt_pa"] = pr.pop("tangent_voigt_pa")
        extra["tangent_probes"] = pr
        log(f"{label}: tangent by three {100 * probe:g} % stress probes, normal block "
            f"{np.round(np.array(pr['normal_pa']) / 1e6, 3).tolist()} MPa "
            f"({pr['steps']} steps, {pr['wall_time_s']:.1f} s)")
    return {
        "label": label, "prestressed": prestressed,
        "num_grains": int(measure.grain_of_body(sc)[1]),
        # the grains (or clumps) asked and placed: those a grid's layer would cut are cleared
        **getattr(sample, "counts", {}),
        "num_spheres": int(sc.num_bodies),
        "preparation_wall_time_s": t_prepared - t_start,
        "stage_wall_time_s": [s.get("wall_time_s") for s in stages],
        "density_scaling": quasi_static.report(sc),
        "targets_pa": [t.tolist() for t in targets],
        "wall_stresses_pa": [s["wall_stresses_pa"].tolist() for s in stages],
        "converged": [bool(s["converged"]) for s in stages],
        "unbalanced_final": [s.get("unbalanced_final") for s in stages],
        "stall": [s.get("stall") for s in stages],
        "strain_stage": [s.get("strain_stage") for s in stages],
        "strain_hold": [s.get("strain_hold") for s in stages],
        "hold_steps": p.hold_steps,
        "servo_steps": [int(s["steps"]) for s in stages],
        "hold_max_rel_error": max(s["hold_max_rel_error"] for s in stages),
        "stress_initial_pa": stress_before.tolist(),
        "stress_final_pa": stages[-1]["wall_stresses_pa"].tolist(),
        "strain_increment": strain_inc.tolist(),
        # the walls' stresses' own scatter (the bootstrap of the contacts' Love–Weber
        # terms), Pa: the noise floor of the two-way loop
        "stress_scatter_pa": np.diag(measure.stress_scatter(
            sc, measure.box_volume(sc, walls))).tolist(),
        "porosity_final": measure.porosity(sc, walls),
        # grain–grain contacts per grain (a clump one grain; each member–member contact
        # counted, as Yade and PFC do), -
        "coordination_final": measure.coordination_number(sc),
        "disp_above_grid_mean_m": float(np.linalg.norm(disp[above], axis=1).mean()),
        "disp_below_grid_mean_m": float(np.linalg.norm(disp[below], axis=1).mean()),
        "disp_z_above_grid_mean_m": float(disp[above, 2].mean()),
        "disp_z_below_grid_mean_m": float(disp[below, 2].mean()),
        "grid_force_longitudinal_mean_n": float(f[longi].mean()),
        "grid_force_longitudinal_max_n": float(f[longi].max()),
        "grid_force_transverse_mean_n": float(f[~longi].mean()),
        "grid_force_longitudinal_cv": float(f[longi].std() / max(abs(f[longi].mean()), 1e-12)),
        # the FEM layer's tension handed over per row (N/m) and the force per line (N)
        "grid_tension_n_per_m": grid_tension,
        "grid_end_force_n": None if ends is None else ends.line_force_n,
        "grid_force_end_members_mean_n": (None if ends is None
                                          else float(ends.end_member_forces().mean())),
        "wall_time_s": time.perf_counter() - t_start,
        # the prepared packing's state (its checkpoint's SHA-256), shared by RE and PRS
        "prepared_sha256": prepared.get("sha256") if prepared else None,
        # how the element was held and damped, as run (docs/prs_element_002.md)
        "conditions": {"fixed_walls": list(getattr(sample, "fixed", ())),
                       "gravity_m_per_s2": float(-np.asarray(sc.gravity)[2]),
                       "local_damping_loading": float(sc.local_damping),
                       "fill_viscous": p.fill_viscous,
                       "fill_local_damping": (p.fill_local_damping if p.fill_local_damping >= 0
                                              else p.damping),
                       "grid_held": p.grid_held, "grid_ends": p.grid_ends,
                       "grid_convention": p.grid_convention},
        "geogrid": p.geogrid, "grains": p.grains, "grain_law": p.grain_law,
        **extra,
    }
