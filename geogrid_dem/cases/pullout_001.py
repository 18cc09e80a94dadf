#!/usr/bin/env python3
"""Geogrid pull-out of the thesis (001 chapter 5, Tables 5.1-5.4, App. A): a 10 cm cube, a
square grid (10 x 10 nodes, 1 cm openings, cylinders of radius 1 mm) or a triangular grid
(equilateral, 1.43 cm sides, radius 0.5 mm) at mid-height, equal grains (r = 1, 1.5 or
2.5 mm; Table 5.1: E = 5 MPa, nu = 0.3, rho = 2650 kg/m^3, phi = 20 deg), confinement 75 / 150
/ 300 kPa on the top wall, pulled at 0.06 m/s.

Stages (App. A): grains on a regular hexagonal lattice (gap r/2) outside the geogrid's
layer; grid held; radius growth to 10 kPa; top wall servo-controlled to the confining
stress, stabilised; pull towards -x. App. A blocks every grid node and gives it the pull
velocity (the grid moves as a rigid body; its E = 5 MPa cylinders could not carry the pull):
that is the default here (--pull all); --pull front clamps only the front row of nodes and
lets the grid deform. Recorded pull-out force: the sum of the reactions of all pulled nodes
(pull_force, the whole soil resistance); beside it 001's own measure (force_001), the sum of
|x force| over the bodies App. A's pull loop names, ids 91-100: by position the back row of
nodes (largest x, the trailing edge) without its node at the smallest y, and one
GridConnection on which Yade puts no force (see force_bodies_001); and the front row's sum
(front_force).

--grains clumps:NAME fills the box with rigid clumps (docs/clumps.md) instead of the lattice
of spheres: as many clumps as the lattice has spheres, the grain radius as their
equivalent-volume radius, random seeded orientations in a loose cloud clear of the grid's
layer; the radius growth then packs them.

With --study the parameter table of 001 (Table 5.2) is run, each cell for every seed of
--seeds, and summarised like Tables 5.3 (mean pull-out force) and 5.4 (coefficient of
variation), beside the thesis's values: per cell the mean and standard deviation over the
seeds of the thesis's measure and of the whole resistance (study.csv, study.md, study.png; one
row per run in rows/). The App. A lattice is deterministic: with sphere grains the seed acts
only through --jitter (each lattice site moved at random within the lattice gap).
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np


from cpp_dem.io.figures import save_figure
from geogrid_dem.cases import THESIS, describe
from cpp_dem import apply_threads
from geogrid_dem.options import (case_parser, check_cap, check_seeds, distinct,
                                 given_options, parse_checked, refuse_unused, warn_below)
from geogrid_dem.rundir import end_run, run_main, run_status, write_atomic
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
    """Parameters of the thesis's pull-out (SI)."""

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
    record_every: int = 50          #: steps between records (001 records every step)
    snapshots: int = 3
    seed: int = 1
    jitter: float = 0.0             #: lattice sites moved by up to jitter x gap/2 (seeded), -,
                                    #: in [0, 1]; 0 = App. A's exact lattice (no seed effect)
    threads: int = 0
    grains: str = "spheres"         #: spheres, or clumps:NAME (cases/grains_option.py); the
                                    #: radius is then the clumps' equivalent-volume radius
    front_slot: float = 0.0         #: the front wall's slot during the pull: its half-height
                                    #: is front_slot x (rc + r) (rc + r: a grain touching a
                                    #: bar; 1 lets a grain pass beside a bar), -; 0 = closed,
                                    #: as App. A's box (pullout.open_front_slot)


SMOKE = dict(radius=2.5e-3, box=0.05, distance=0.004, snapshots=1)


def grid_spec(p: Params) -> tuple[float, int]:
    """Cylinder radius (m) and nodes per side of the square grid scaled to the box."""
    rc = 1e-3 if p.grid == "square" else 0.5e-3
    return rc, max(3, int(round(10 * p.box / 0.1)))


def grains(p: Params) -> tuple[np.ndarray, np.ndarray]:
    """Centres and radii (m): the App. A lattice (gap r/2) with the grid's layer left empty.

    With ``p.jitter`` > 0 every site is moved by a random vector (seed ``p.seed``) of length at
    most jitter x gap/2, uniform in that ball, then held inside the box and out of the grid's
    layer (a clip that never lengthens the move): no two grains touch (their centres stay at
    least 2 r apart), none touches a wall or the grid. jitter 0 is App. A's exact lattice."""
    gap = p.radius / 2
    c, r = hex_packing(np.zeros(3), np.full(3, p.box), p.radius, gap=gap)
    zg = 0.5 * p.box
    clear = r + 1.5 * grid_spec(p)[0]
    keep = np.abs(c[:, 2] - zg) > clear
    c, r, clear = c[keep], r[keep], clear[keep]
    if p.jitter > 0:
        rng = np.random.default_rng(p.seed)
        u = rng.normal(size=c.shape)
        u /= np.linalg.norm(u, axis=1)[:, None]
        step = p.jitter * 0.5 * gap * rng.random(len(c)) ** (1.0 / 3.0)
        moved = np.clip(c + u * step[:, None], r[:, None], p.box - r[:, None])
        above = c[:, 2] > zg
        moved[above, 2] = np.maximum(moved[above, 2], zg + clear[above])
        moved[~above, 2] = np.minimum(moved[~above, 2], zg - clear[~above])
        c = moved
    return c, r


#: 001 App. A, pull loop: ``F = abs(O.forces.f(91)[0]) + abs(O.forces.f(100)[0]) +
#: abs(O.forces.f(99)[0]) + ... + abs(O.forces.f(92)[0])``: the Yade body ids whose |x force|
#: it sums at every step (square grid; 001 gives no such list for the triangular grid).
FORCE_IDS_001 = (91, 100, 99, 98, 97, 96, 95, 94, 93, 92)


def yade_square_bodies(nodes_x: int, nodes_y: int) -> list[tuple[str, tuple[int, int]]]:
    """The bodies of 001's square grid in the order App. A creates them, so that entry k is
    Yade body id k (nothing is added before the grid). First the nodes, ``for i in
    range(nbL): for j in range(nbl)`` with i along x (the length, the pull direction) and j
    along y: ``("node", (i, j))`` is id i * nodes_y + j. Then the GridConnections, ``for a in
    range(n): for b in range(a + 1, n): if |p_a - p_b| <= 1.01 L/nbL`` (equal spacing in x
    and y): ``("connection", (a, b))`` with a, b node ids, in that order. For 10 x 10 nodes
    they are ids 100-279, and the six walls follow, 280-285, 285 the top wall whose force
    App. A servoes: the count checks the order."""
    nodes_x, nodes_y = int(nodes_x), int(nodes_y)
    if nodes_x < 2 or nodes_y < 2:
        raise ValueError(f"nodes_x={nodes_x}, nodes_y={nodes_y}: a grid needs >= 2 x 2 nodes")
    out: list[tuple[str, tuple[int, int]]] = [("node", (i, j)) for i in range(nodes_x)
                                              for j in range(nodes_y)]
    for a in range(nodes_x * nodes_y):
        i, j = divmod(a, nodes_y)
        # the nodes after a within one spacing, in increasing id: (i, j + 1), then (i + 1, j)
        if j + 1 < nodes_y:
            out.append(("connection", (a, a + 1)))
        if i + 1 < nodes_x:
            out.append(("connection", (a, a + nodes_y)))
    return out


def force_ids_001(nodes_x: int, nodes_y: int) -> tuple[int, ...]:
    """001's ids for a square grid of nodes_x x nodes_y nodes: the nodes_y ids that end at
    nodes_x * nodes_y (for 10 x 10 exactly App. A's 91-100): the back row of nodes without
    its first (y = min) node, and the first GridConnection."""
    n = int(nodes_x) * int(nodes_y)
    return tuple(range(n - int(nodes_y) + 1, n + 1))


@dataclass(frozen=True)
class Force001:
    """Which bodies of our scene 001's pull-out force sums (see force_bodies_001).

    nodes : our body ids of the nodes whose |x force| is summed.
    yade_ids : 001's Yade body ids (square grid), ascending; () for the triangular
        grid, for which 001 names none.
    zero_ids : the Yade ids among them that are GridConnections, with their nodes (our body
        ids): Yade puts no force on a GridConnection body (Law2_ScGridCoGeom_FrictPhys_
        CundallStrack applies the contact force to the sphere and to the connection's two
        nodes; only a periodic scene adds it to the connection), so they add 0.
    rule : the selection in words, by position.
    """

    nodes: np.ndarray
    yade_ids: tuple
    zero_ids: tuple
    rule: str


def force_bodies_001(grid_kind: str, node_ids, positions, *, tol: float = 1e-6) -> Force001:
    """The bodies 001's pull loop sums, mapped onto our grid by position.

    grid_kind : "square" or "triangular"; node_ids : our body ids of the grid nodes;
    positions : their positions (n, 3), m, as built (x the pull direction, towards -x).
    Square grid: the nodes are put in App. A's creation order by position (i the rank of x,
    j the rank of y; the ranks must form a full nodes_x x nodes_y lattice) and 001's ids
    (force_ids_001: for 10 x 10 nodes 91-100) are looked up in yade_square_bodies. Triangular
    grid (001 names no ids; the analogous choice): the last node of every row along x (the
    trailing edge) without the row at the smallest y, as the square grid's back row without
    its node at the smallest y. ``tol`` (m) groups equal coordinates."""
    ids = np.asarray(node_ids, dtype=np.int64)
    pos = np.asarray(positions, dtype=float)
    if pos.shape != (len(ids), 3) or len(ids) < 4:
        raise ValueError(f"positions: shape {pos.shape}, expected ({len(ids)}, 3) for the "
                         f"{len(ids)} node ids (at least 4)")

    def levels(v):  # distinct coordinate values, tolerant to round-off
        u = np.unique(np.round(v / tol).astype(np.int64))
        return u, np.searchsorted(u, np.round(v / tol).astype(np.int64))

    xs, i_of = levels(pos[:, 0])
    ys, j_of = levels(pos[:, 1])
    if grid_kind == "square":
        nx, ny = len(xs), len(ys)
        if nx * ny != len(ids) or len(set(zip(i_of.tolist(), j_of.tolist()))) != len(ids):
            raise ValueError(f"grid_kind='square': the {len(ids)} nodes do not form a full "
                             f"lattice ({nx} x values x {ny} y values)")
        ours = np.empty(nx * ny, dtype=np.int64)
        ours[i_of * ny + j_of] = ids  # Yade id i * ny + j -> our body id
        bodies = yade_square_bodies(nx, ny)
        yids = force_ids_001(nx, ny)
        nodes, zero = [], []
        for k in yids:
            kind, (a, b) = bodies[k]
            if kind == "node":
                nodes.append(int(ours[k]))
            else:
                zero.append((k, int(ours[a]), int(ours[b])))
        rule = (f"the back row of nodes (x = max, the trailing edge) without its node at "
                f"y = min: {len(nodes)} of {ny} nodes; and GridConnection "
                f"{', '.join(str(z[0]) for z in zero)} (between the first two nodes of the "
                f"front row, x = min, at the smallest y), on which Yade puts no force")
        return Force001(np.array(nodes, dtype=np.int64), tuple(yids), tuple(zero), rule)
    if grid_kind == "triangular":
        rows = {}
        for n, (j, x) in enumerate(zip(j_of.tolist(), pos[:, 0])):
            if j not in rows or x > pos[rows[j], 0]:
                rows[j] = n
        last = [rows[j] for j in sorted(rows)][1:]  # without the row at y = min
        rule = (f"the last node (x = max) of every row along x but the row at y = min: "
                f"{len(last)} of {len(rows)} rows (001 names no ids for this grid)")
        return Force001(ids[last], (), (), rule)
    raise ValueError(f"grid_kind={grid_kind!r}: must be 'square' or 'triangular'")


def grains_out(sample: pullout.PulloutSample) -> float:
    """How many grains have left the box through the front slot: grain centres beyond the
    front wall's plane (x below it)."""
    x0 = float(np.asarray(sample.scene.wall_positions)[sample.walls[pullout.X_MINUS]])
    return float(np.count_nonzero(np.asarray(sample.scene.positions)[sample.grain_ids, 0] < x0))


def force_001(scene, nodes) -> float:
    """001's pull-out force, N: the sum over ``nodes`` (body ids) of |x force| at the last
    step, as App. A sums |O.forces.f(id)[0]| (a node's resultant: the soil's contact forces
    passed to it and the grid's links; the links carry nothing in the rigid pull)."""
    return float(np.abs(np.asarray(scene.forces)[np.asarray(nodes, dtype=np.int64), 0]).sum())


def stats_001(rec: dict) -> dict:
    """001's averages of its force over the pull: the mean (N) and the coefficient of
    variation (standard deviation over the mean, -) of ``force_001`` over every record with a
    displacement above 0 (the records of the whole pull, as for our mean_force_N); 001 takes
    them over its records of every step of its 9.5 cm pull."""
    d = np.asarray(rec["displacement"], float)
    f = np.asarray(rec["force_001"], float)
    sel = d > 0
    if not np.any(sel):
        return {"mean_force_001_N": float("nan"), "cov_001": float("nan"),
                "records_001": 0}
    m = float(f[sel].mean())
    return {"mean_force_001_N": m,
            "cov_001": float(f[sel].std() / m) if m > 0 else float("nan"),
            "records_001": int(np.count_nonzero(sel))}


def window_stats(rec: dict, d_max: float) -> dict:
    """Mean (N) and CoV (-) of the whole resistance (``pull_force``) and of the thesis's
    measure (``force_001``) over the records with a displacement in (0, d_max] m: the
    statistics of a pull window that runs of different lengths share."""
    d = np.asarray(rec["displacement"], float)
    sel = (d > 0) & (d <= d_max * (1 + 1e-12))
    out = {"records": int(np.count_nonzero(sel))}
    for key, m_name, c_name in (("pull_force", "mean_force_N", "cov_force"),
                                ("force_001", "mean_force_001_N", "cov_001")):
        f = np.asarray(rec[key], float)[sel]
        m = float(f.mean()) if len(f) else float("nan")
        out[m_name] = m
        out[c_name] = float(f.std() / m) if len(f) and m > 0 else float("nan")
    return out


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
        # 001 §5.2: equilateral triangles of 1.43 cm, a grid of 10 cm x 8.7 cm. Seven sides
        # (10.01 cm) do not fit in the 10 cm box; the grid keeps the side and takes the
        # whole triangles that fit with the nodes inside the box (6 sides, 8.58 cm), centred.
        side = 0.0143
        h = side * math.sqrt(3) / 2
        nx = max(2, int(math.floor((p.box - 2 * rc) / side)))
        ny = max(2, int(math.floor(0.87 * p.box / h + 0.01)))
        return geogrid.triangular_grid(sc, origin=(0.5 * (p.box - nx * side),
                                                   0.5 * (p.box - ny * h), zg),
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
    sel = force_bodies_001(p.grid, sample.grid.nodes, sample.grid.reference_positions)
    log(f"the thesis's pull-out force (force_001): sum of |x force| on {sel.rule}"
        + (f"; App. A's ids {', '.join(map(str, sel.yade_ids))}" if sel.yade_ids else ""))
    snaps = np.linspace(0, p.distance, p.snapshots + 1)[1:] if p.snapshots else []
    slot_half_m = p.front_slot * (grid_spec(p)[0] + p.radius)

    def before_pull(s: pullout.PulloutSample) -> None:
        if slot_half_m > 0:  # opened after the preparation: the same sample as a closed box
            pullout.open_front_slot(s, slot_half_m)
            log(f"front wall: a slot {2 * slot_half_m * 1e3:.3g} mm high about the grid "
                f"plane ({p.front_slot:g} x (bar radius + grain radius) each side)")

    meta = {**asdict(p), "case": "001", "study": THESIS,
            "force_001_nodes": sel.nodes.tolist(), "force_001_yade_ids": list(sel.yade_ids),
            "force_001_zero_connections": [list(z) for z in sel.zero_ids],
            "force_001_rule": sel.rule, "front_slot_half_height_m": slot_half_m}
    summary = run_case(
        sample, out, tag="pullout-001", meta=meta,
        prep_kwargs={"porosity": None, "growth_stress": p.growth_stress,
                     "max_expansion_strain": 1e-4},
        velocity=p.velocity, distance=p.distance, record_every=p.record_every,
        snapshot_displacements=snaps, grain_density=p.density, stress=p.pressure,
        title=f"{THESIS}: pull-out, {p.grid} grid, {grain_label(sample)}, "
              f"r = {p.radius * 1e3:g} mm, {p.pressure / 1e3:g} kPa", log=log,
        extra_series={"force_001": (lambda s: force_001(s.scene, sel.nodes), "N",
                                    "the thesis's measure: back-row nodes, sum |x force|"),
                      **({"grains_out": (grains_out, "-", "grains out through the slot")}
                         if slot_half_m > 0 else {})},
        extra_summary=lambda rec: {**stats_001(rec), **(
            {"grains_out_end": float(rec["grains_out"][-1])} if "grains_out" in rec else {})},
        before_pull=before_pull)
    log(f"the thesis's measure (force_001): mean {summary['mean_force_001_N']:.3f} N, CoV "
        f"{summary['cov_001']:.3f}; whole resistance (pull_force): mean "
        f"{summary['mean_force_N']:.2f} N, CoV {summary['cov_force']:.3f}")
    return summary


#: A thesis value "lies within our seed scatter" when it is at most this many standard
#: deviations (over the seeds of the cell, ddof 1) from our mean over the seeds, -.
WITHIN_SD = 2.0

#: What identifies a study cell (the seeds of a cell are its runs).
MATERIAL_KEY = ("grid_young_Pa", "grains", "jitter", "front_slot")
CELL_KEY = ("grid", "radius_m", "pressure_Pa", *MATERIAL_KEY)


def material_of(c: dict) -> tuple:
    """A row's or cell's material and set-up (MATERIAL_KEY): what, beside the grid, the grain
    radius and the pressure, tells its cells apart. A row written before the front slot
    existed ran with the wall closed (front_slot 0)."""
    return tuple(c.get(k, 0.0) if k == "front_slot" else c[k] for k in MATERIAL_KEY)


def material_label(eg: float, gr: str, jit: float, slot: float) -> str:
    """The words for a material_of tuple (study.md, study.png)."""
    return (f"grid E {eg:g} Pa" + ("" if gr == "spheres" else f", {gr}")
            + (f", jitter {jit:g}" if jit else "")
            + (f", front slot {slot:g}" if slot else ""))


def thesis_value(table: dict, grid: str, radius: float, pressure: float):
    """The value of T53 or T54 for (grid, radius m, pressure Pa), or None."""
    for (g, r, P), v in table.items():
        if g == grid and math.isclose(r, radius, rel_tol=1e-9) and \
                math.isclose(P, pressure, rel_tol=1e-9):
            return v
    return None


def run_name(q: Params) -> str:
    """The sub-folder of one study run: grid, radius, pressure; the grid's Young's modulus
    where it differs from the grains' (Table 5.1: the same), the grains where not spheres,
    the jitter and the front slot where not 0; the seed."""
    name = f"{q.grid}_r{q.radius * 1e3:g}mm_P{q.pressure / 1e3:g}kPa"
    if q.grid_young != q.young:
        name += f"_Eg{q.grid_young:g}"
    if q.grains != "spheres":
        name += "_" + "".join(ch if ch.isalnum() or ch in "._-" else "-" for ch in q.grains)
    if q.jitter > 0:
        name += f"_j{q.jitter:g}"
    if q.front_slot > 0:
        name += f"_slot{q.front_slot:g}"
    return f"{name}_s{q.seed}"


def run_row(q: Params, sub: Path, status: str, wall_time: float) -> dict:
    """One run of the study as a row (SI): its cell, seed, how far it pulled, our mean force
    and CoV (the whole resistance, pullout.summarize), those of the thesis's measure
    (stats_001), the front row's mean, the wall time (s) and the status ("ok" or why it
    stopped)."""
    rec = pullout.read_record(sub / "pullout.csv")
    if not rec or len(rec.get("pull_force", ())) < 3:
        rec = None  # stopped before the pull
    nan = float("nan")
    # (the whole resistance only: a grid of triangles records no transverse members)
    st = pullout.summarize({k: rec[k] for k in ("displacement", "pull_force")}) \
        if rec is not None else {"mean_force_N": nan, "cov_force": nan}
    s1 = stats_001(rec) if rec is not None else {"mean_force_001_N": nan, "cov_001": nan}
    return {"run": sub.name, "grid": q.grid, "radius_m": q.radius, "pressure_Pa": q.pressure,
            "grid_young_Pa": q.grid_young, "grains": q.grains, "jitter": q.jitter,
            "front_slot": q.front_slot, "seed": q.seed, "num_grains": int(len(grains(q)[1])),
            "pulled_m": float(rec["displacement"][-1]) if rec is not None else 0.0,
            "mean_force_N": st["mean_force_N"], "cov_force": st["cov_force"],
            "mean_force_001_N": s1["mean_force_001_N"], "cov_001": s1["cov_001"],
            "mean_front_force_N": float(np.mean(rec["front_force"][1:])) if rec is not None
            else nan,
            "grains_out_end": float(rec["grains_out"][-1]) if rec is not None
            and "grains_out" in rec else 0.0,
            "wall_time_s": float(wall_time), "status": status}


def row_run_dir(out: Path, row: dict) -> Path:
    """The folder of a study row's run in the study folder ``out`` (rows written before they
    named it: rebuilt by run_name with the default grain modulus)."""
    if "run" in row:
        return out / row["run"]
    q = replace(Params(), grid=row["grid"], radius=row["radius_m"],
                pressure=row["pressure_Pa"], grid_young=row["grid_young_Pa"],
                grains=row["grains"], jitter=row["jitter"],
                front_slot=row.get("front_slot", 0.0), seed=row["seed"])
    return out / run_name(q)


def study(p: Params, out: Path, grids, radii, pressures, radii_given: bool,
          seeds=(1,), overwrite: bool = False, window_m: float | None = None) -> None:
    """Runs the cells grid x radius x pressure, each once per seed, into sub-folders of
    ``out`` (run_name); each run leaves its row in out/rows/<run>.json, and study.csv,
    study.md and study.png are rebuilt from every row there after each run. A run whose row
    is there already is skipped (``overwrite``: run again), so a study can be filled in
    several sittings and by several processes at once (each its own cells)."""
    out.mkdir(parents=True, exist_ok=True)
    rows_dir = out / "rows"
    rows_dir.mkdir(exist_ok=True)
    for g in grids:
        # 001 ran the triangular grid with r = 2.5 mm only (Table 5.3, last column).
        for r in (radii if g == "square" or radii_given else [2.5e-3]):
            for P in pressures:
                for seed in seeds:
                    q = replace(p, grid=g, radius=r, pressure=P, seed=seed)
                    sub = out / run_name(q)
                    row_file = rows_dir / f"{sub.name}.json"
                    if row_file.is_file() and not overwrite and not json.loads(
                            row_file.read_text())["status"].startswith("interrupted"):
                        print(f"[pullout-001] {sub.name}: in the study already "
                              f"({row_file}); --overwrite runs it again", flush=True)
                        continue
                    if (run_status(sub) or {}).get("status") == "complete":
                        # run before, its row lost (e.g. a stop between the two): no new run
                        wall = json.loads((sub / "summary.json").read_text())[
                            "wall_time_total_s"]
                        write_atomic(row_file, json.dumps(run_row(q, sub, "ok", wall),
                                                           indent=1) + "\n")
                        continue
                    t0 = time.perf_counter()
                    try:
                        run(q, sub)
                        status = "ok"
                    except dem.BlowUpError as e:  # keep the table going; say where it stopped
                        status = str(e).split(";")[0]
                        print(f"[pullout-001] {sub.name} STOPPED: {e}", flush=True)
                        end_run(sub, "failed", f"BlowUpError: {e}")
                    except KeyboardInterrupt:
                        # what it pulled stays in the study, marked; a new study runs it again
                        row = run_row(q, sub, "interrupted (Ctrl-C)", time.perf_counter() - t0)
                        write_atomic(row_file, json.dumps(row, indent=1) + "\n")
                        write_study(read_rows(out), out, window_m)
                        raise
                    row = run_row(q, sub, status, time.perf_counter() - t0)
                    write_atomic(row_file, json.dumps(row, indent=1) + "\n")
                    write_study(read_rows(out), out, window_m)
    rows = read_rows(out)
    if rows:
        write_study(rows, out, window_m)


def read_rows(out: Path) -> list[dict]:
    """The rows of every study run in ``out`` (out/rows/*.json)."""
    return [json.loads(f.read_text()) for f in sorted((out / "rows").glob("*.json"))]


def _mean_sd(values) -> tuple[float, float]:
    """Mean and standard deviation (ddof 1; nan for fewer than 2 values) of ``values``."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], float)
    if len(v) == 0:
        return float("nan"), float("nan")
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else float("nan")


def _within(ref, mean: float, sd: float):
    """Whether ``ref`` lies within mean +- WITHIN_SD sd; None without a reference or a
    scatter (fewer than 2 completed seeds)."""
    if ref is None or not (math.isfinite(mean) and math.isfinite(sd)):
        return None
    return bool(abs(ref - mean) <= WITHIN_SD * sd)


def study_cells(rows: list[dict]) -> list[dict]:
    """One row per cell (CELL_KEY): the thesis's values (T5.3, T5.4) and, over the seeds whose
    run completed the pull ("ok"), the mean and standard deviation of the thesis's measure
    (mean force and CoV), of the whole resistance and of the front row's mean; whether the thesis's
    values lie within mean +- WITHIN_SD sd; the mean wall time per run (s); and the runs that
    stopped, with how far they pulled. A cell none of whose runs completed gives the same
    statistics over its stopped runs, each over what it pulled (basis "partial"; no
    "within")."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["grid"], r["radius_m"], r["pressure_Pa"], *material_of(r)),
                          []).append(r)
    cells = []
    for key, rs in groups.items():
        rs = sorted(rs, key=lambda r: r["seed"])
        ok = [r for r in rs if r["status"] == "ok"]
        basis = "completed"
        if not ok:  # no run completed: the stopped ones, each over what it pulled
            ok = [r for r in rs if r["pulled_m"] > 0 and math.isfinite(r["mean_force_N"])]
            basis = "partial"
        c = dict(zip(CELL_KEY, key))
        t53 = thesis_value(T53, c["grid"], c["radius_m"], c["pressure_Pa"])
        t54 = thesis_value(T54, c["grid"], c["radius_m"], c["pressure_Pa"])
        m1, s1 = _mean_sd(r["mean_force_001_N"] for r in ok)
        c1, sc1 = _mean_sd(r["cov_001"] for r in ok)
        m, s = _mean_sd(r["mean_force_N"] for r in ok)
        cv, scv = _mean_sd(r["cov_force"] for r in ok)
        mf, _ = _mean_sd(r["mean_front_force_N"] for r in ok)
        stopped = [f"seed {r['seed']} at {1e3 * r['pulled_m']:.1f} mm: {r['status']}"
                   for r in rs if r["status"] != "ok"]
        c.update({"seeds": " ".join(str(r["seed"]) for r in rs), "runs": len(rs),
                  "completed": len(ok) if basis == "completed" else 0,
                  "basis": basis if ok else "none",
                  "pulled_mm": " ".join(f"{1e3 * r['pulled_m']:.1f}" for r in rs),
                  "num_grains": rs[0]["num_grains"],
                  "thesis_mean_force_N": t53, "thesis_cov": t54,
                  "mean_force_001_N": m1, "sd_mean_force_001_N": s1,
                  "cov_001": c1, "sd_cov_001": sc1,
                  "mean_force_N": m, "sd_mean_force_N": s, "cov_force": cv, "sd_cov_force": scv,
                  "mean_front_force_N": mf,
                  "thesis_force_within": _within(t53, m1, s1) if basis == "completed" else None,
                  "thesis_cov_within": _within(t54, c1, sc1) if basis == "completed" else None,
                  "wall_time_per_run_s": float(np.mean([r["wall_time_s"] for r in rs])),
                  "status": "ok" if not stopped else "; ".join(stopped)})
        cells.append(c)
    return sorted(cells, key=lambda c: (c["grid"] != "square", -c["radius_m"], c["pressure_Pa"],
                                        *material_of(c)))


def _steps(cs: list[dict], k: str, sdk: str) -> list[str]:
    """Each step of ``k`` from one entry of ``cs`` to the next: "falls" or "rises" when it
    exceeds WITHIN_SD combined standard deviations (``sdk``), else "stays within the
    scatter"; "not known (one seed)" without a scatter."""
    steps = []
    for a, b in zip(cs, cs[1:]):
        d = b[k] - a[k]
        lim = WITHIN_SD * math.hypot(a[sdk], b[sdk])
        steps.append("not known (one seed)" if not math.isfinite(lim) else
                     "falls" if d < -lim else "rises" if d > lim else
                     "stays within the scatter")
    return steps


def window_trend(rows: list[dict], out: Path, window_m: float | None = None) -> list[dict]:
    """The CoV against the grain size over a pull window every run shares: for every grid,
    pressure and material with runs at two or more radii, the window is the shortest pull of
    those runs (stopped ones included; at most ``window_m``, m), and each radius gets the mean
    ± sd over its seeds of window_stats of its runs, read back from their records. So runs
    that stopped at different distances are compared over the same pull. One dict per
    (group, radius), with the window (m) and the steps from the radius before."""
    groups: dict = {}
    for r in rows:
        if r["pulled_m"] > 0:
            groups.setdefault((r["grid"], r["pressure_Pa"], *material_of(r)), []).append(r)
    result = []
    for (g, P, *mat), rs in sorted(groups.items()):
        radii = sorted({r["radius_m"] for r in rs}, reverse=True)
        if len(radii) < 2:
            continue
        d_max = min(r["pulled_m"] for r in rs)
        if window_m is not None:
            d_max = min(d_max, window_m)
        cs = []
        for rad in radii:
            stats = []
            for r in (r for r in rs if math.isclose(r["radius_m"], rad)):
                rec = pullout.read_record(row_run_dir(out, r) / "pullout.csv")
                if rec is not None and len(rec.get("pull_force", ())) >= 3:
                    stats.append(window_stats(rec, d_max))
            if not stats:
                continue
            c = {"grid": g, "pressure_Pa": P, **dict(zip(MATERIAL_KEY, mat)),
                 "radius_m": rad, "window_m": d_max, "runs": len(stats)}
            for k in ("mean_force_N", "cov_force", "mean_force_001_N", "cov_001"):
                c[k], c["sd_" + k] = _mean_sd(st[k] for st in stats)
            c["thesis_cov"] = thesis_value(T54, g, rad, P)
            cs.append(c)
        for k, sdk in (("cov_001", "sd_cov_001"), ("cov_force", "sd_cov_force")):
            for c, step in zip(cs, ["—", *_steps(cs, k, sdk)]):
                c[f"{k}_step"] = step
        result += cs
    return result


def window_lines(wt: list[dict]) -> list[str]:
    """study.md's lines on window_trend's result, one per group."""
    groups: dict = {}
    for c in wt:
        groups.setdefault((c["grid"], c["pressure_Pa"], *material_of(c)), []).append(c)
    lines = []
    for (g, P, *mat), cs in groups.items():
        if len(cs) < 2:
            continue
        parts = []
        for name, k in (("the thesis's measure", "cov_001"), ("whole resistance", "cov_force")):
            vals = ", ".join(f"{c[k]:.3f} ± {c['sd_' + k]:.3f} (r = {c['radius_m'] * 1e3:g} mm, "
                             f"{c['runs']} runs)" for c in cs)
            parts.append(f"{name} {vals}: {', then '.join(c[k + '_step'] for c in cs[1:])}")
        thesis = [c["thesis_cov"] for c in cs]
        ref = ("; the thesis (its whole pull): " + ", ".join(f"{v:.3f}" for v in thesis)
               if all(v is not None for v in thesis) else "")
        lines.append(f"- {g}, {P / 1e3:g} kPa, {material_label(*mat)}"
                     + f", over the first {cs[0]['window_m'] * 1e3:.1f} mm: CoV of "
                     + "; ".join(parts) + ref + ".")
    return lines


def cov_trend(cells: list[dict]) -> list[str]:
    """Lines on the CoV against the grain size (001, Table 5.4: it falls with smaller grains):
    for every grid, pressure and material with completed cells at two or more radii, the CoV
    of the thesis's measure and of the whole resistance from the largest to the smallest
    grains, and whether each step falls or rises by more than WITHIN_SD combined standard deviations
    (sqrt(sd1^2 + sd2^2)) or stays within the scatter."""
    out = []
    groups: dict = {}
    for c in cells:
        if c["completed"]:
            groups.setdefault((c["grid"], c["pressure_Pa"], *material_of(c)), []).append(c)
    for (g, P, *mat), cs in sorted(groups.items()):
        if len(cs) < 2:
            continue
        cs = sorted(cs, key=lambda c: -c["radius_m"])
        parts = []
        for name, k, sdk in (("the thesis's measure", "cov_001", "sd_cov_001"),
                             ("whole resistance", "cov_force", "sd_cov_force")):
            vals = ", ".join(f"{c[k]:.3f} ± {c[sdk]:.3f} (r = {c['radius_m'] * 1e3:g} mm)"
                             for c in cs)
            parts.append(f"{name} {vals}: {', then '.join(_steps(cs, k, sdk))}")
        thesis = [thesis_value(T54, g, c["radius_m"], P) for c in cs]
        ref = ("; the thesis: " + ", ".join(f"{v:.3f}" for v in thesis)
               if all(v is not None for v in thesis) else "")
        out.append(f"- {g}, {P / 1e3:g} kPa, {material_label(*mat)}: CoV of {'; '.join(parts)}"
                   + ref + ".")
    return out


def write_study(rows: list, out: Path, window_m: float | None = None) -> None:
    """study.csv (one row per cell, study_cells), study.md (the table and the CoV trend with
    the grain size, over the whole pull and over the window every run shares: window_trend,
    also as study_window.csv) and study.png (Tables 5.3 and 5.4 against ours) in ``out``."""
    cells = study_cells(rows)
    if not cells:
        return
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(cells[0]))
    w.writeheader()
    w.writerows(cells)
    write_atomic(out / "study.csv", buf.getvalue())

    def f(v, fmt):
        return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) \
            else format(v, fmt)

    def pm(m, sd, fmt):
        return f(m, fmt) + ("" if not math.isfinite(sd) else " ± " + format(sd, fmt))

    def yes(v):
        return "—" if v is None else ("yes" if v else "no")

    def short(status: str) -> str:  # "seed 2 at 51.6 mm: blow-up ... by 0.9001 of ..."
        out = []
        for part in status.split("; seed "):
            head, _, why = part.partition(": ")
            m = re.search(r"overlaps (the geogrid|wall \d+) .*?by ([0-9.]+)", why)
            what = (f"a grain {float(m.group(2)):.2f} R into "
                    + ("a bar" if m.group(1) == "the geogrid" else m.group(1))) if m else why[:60]
            out.append(f"{'' if head.startswith('seed') else 'seed '}{head}: {what}")
        return "; ".join(out)

    lines = ["# The thesis's pull-out study (001, Tables 5.2-5.4): report", "",
             f'Source: the thesis, "{THESIS}" (docs/studies.md).', "",
             f"Per cell: mean ± standard deviation over the seeds whose run completed the "
             f"pull; \"within\": the thesis's value lies within our mean ± {WITHIN_SD:g} sd.",
             "",
             "| grid | r (mm) | P (kPa) | grid E (Pa) | seeds (completed) | thesis T5.3 (N) | "
             "thesis's measure (N) | whole grid (N) | T5.3 within | thesis T5.4 | "
             "CoV, thesis's measure | CoV, whole grid | T5.4 within | front row (N) | "
             "wall time per run (s) | status |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for c in cells:
        slot = f", front slot {c['front_slot']:g}" if c["front_slot"] else ""
        lines.append(
            f"| {c['grid']}{'' if c['grains'] == 'spheres' else ' ' + c['grains']}{slot} | "
            f"{c['radius_m'] * 1e3:g} | {c['pressure_Pa'] / 1e3:g} | {c['grid_young_Pa']:g} | "
            f"{c['seeds']} ({c['completed']}) | {f(c['thesis_mean_force_N'], '.2f')} | "
            f"{pm(c['mean_force_001_N'], c['sd_mean_force_001_N'], '.2f')} | "
            f"{pm(c['mean_force_N'], c['sd_mean_force_N'], '.1f')} | "
            f"{yes(c['thesis_force_within'])} | {f(c['thesis_cov'], '.3f')} | "
            f"{pm(c['cov_001'], c['sd_cov_001'], '.3f')} | "
            f"{pm(c['cov_force'], c['sd_cov_force'], '.3f')} | {yes(c['thesis_cov_within'])} | "
            f"{f(c['mean_front_force_N'], '.2f')} | {c['wall_time_per_run_s']:.0f} | "
            f"{'ok' if c['status'] == 'ok' else short(c['status'])}"
            f"{' (statistics over the stopped runs)' if c['basis'] == 'partial' else ''} |")
    trend = cov_trend(cells)
    if trend:
        lines += ["", "CoV against the grain size over the whole pull, completed cells (a step "
                  f"\"falls\" or \"rises\" when it exceeds {WITHIN_SD:g} combined sd):", "",
                  *trend]
    wt = window_trend(rows, out, window_m)
    if wt:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(wt[0]))
        w.writeheader()
        w.writerows(wt)
        write_atomic(out / "study_window.csv", buf.getvalue())
        wl = window_lines(wt)
        if wl:
            lines += ["", "CoV against the grain size over the pull every run of the "
                      "compared radii reached, stopped runs included (study_window.csv; the "
                      "same steps rule):", "", *wl]
    write_atomic(out / "study.md", "\n".join(lines) + "\n")
    plot_study(cells, out / "study.png")


def plot_study(cells: list[dict], png: Path) -> None:
    """Tables 5.3 and 5.4 against ours: the mean force (log scale) and the CoV against the
    confining stress, one row of panels per grid material (and grains, jitter), one colour per
    grid and radius: the thesis's measure and the whole resistance (mean ± sd over the seeds)
    and the thesis's values. A cell none of whose runs completed is drawn faded (statistics
    over what its runs pulled)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mats = sorted({material_of(c) for c in cells})
    kinds = sorted({(c["grid"], c["radius_m"]) for c in cells},
                   key=lambda k: (k[0] != "square", -k[1]))
    colour = {k: f"C{n}" for n, k in enumerate(kinds)}
    fig, axes = plt.subplots(len(mats), 2, figsize=(12, 4.2 * len(mats)), squeeze=False)
    for row, mat_key in zip(axes, mats):
        for n, kind in enumerate(kinds):
            sel = sorted((c for c in cells if (c["grid"], c["radius_m"]) == kind
                          and material_of(c) == mat_key),
                         key=lambda c: c["pressure_Pa"])
            if not sel:
                continue
            col = colour[kind]
            lab = f"{kind[0]}, r = {kind[1] * 1e3:g} mm"
            dx = 3.0 * (n - 0.5 * (len(kinds) - 1))  # kPa: keep the error bars apart
            for a, (k, sdk), (k1, sdk1), kt in (
                    (row[0], ("mean_force_N", "sd_mean_force_N"),
                     ("mean_force_001_N", "sd_mean_force_001_N"), "thesis_mean_force_N"),
                    (row[1], ("cov_force", "sd_cov_force"), ("cov_001", "sd_cov_001"),
                     "thesis_cov")):
                for key, sdkey, fmt, mfc, what in ((k, sdk, "o", None, "whole grid"),
                                                   (k1, sdk1, "s", "none",
                                                    "the thesis's measure")):
                    done = [c for c in sel if c["basis"] == "completed"]
                    part = [c for c in sel if c["basis"] == "partial"]
                    for group, alpha, ls, tag in ((done, 1.0, "-" if fmt == "o" else "--", ""),
                                                  (part, 0.35, "none", " (stopped runs)")):
                        if not group:
                            continue
                        P = np.array([c["pressure_Pa"] / 1e3 for c in group]) + dx
                        a.errorbar(P, [c[key] for c in group],
                                   yerr=np.nan_to_num([c[sdkey] for c in group]), fmt=fmt,
                                   ls=ls, color=col, mfc=mfc, alpha=alpha, capsize=3,
                                   label=f"{lab}: {what}{tag}")
                ref = [(c["pressure_Pa"] / 1e3, c[kt]) for c in sel if c[kt] is not None]
                if ref:
                    a.plot(*zip(*ref), "x:", color=col, ms=9, mew=2, label=f"{lab}: thesis")
        mat = material_label(*mat_key) + (" (Table 5.1)" if mat_key[0] == 5e6 else " (stiff bars)")
        row[0].set_yscale("log")
        row[0].set_ylabel("mean pull-out force (N)")
        row[0].set_title(f"Table 5.3 and ours; {mat}", fontsize=9)
        row[1].set_ylabel("coefficient of variation (-)")
        row[1].set_title(f"Table 5.4 and ours; {mat}", fontsize=9)
        for a in row:
            a.set_xlabel("confining stress (kPa)")
            a.grid(alpha=0.3)
        row[1].legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.suptitle("Mean ± standard deviation over the seeds; faded: no run completed the pull "
                 "(over what the runs pulled)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, png)
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


def _seeds(text: str, ap, a=None) -> list[int]:
    """The seeds of --seeds: 'A-B' (A to B) or a comma list of whole numbers; more than the
    cap of seeds is refused without --allow-large (``a``: the parsed namespace) before the
    list is made."""
    try:
        if "-" in text.strip().lstrip("-"):
            lo, hi = (int(x) for x in text.split("-", 1))
            check_cap(ap, a, "--seeds", repr(text), hi - lo + 1, "seeds")
            seeds = list(range(lo, hi + 1))
        else:
            seeds = [int(x) for x in text.split(",")]
    except ValueError:
        ap.error(f"--seeds={text!r}: expected A-B (e.g. 1-3) or a comma list of whole numbers")
    check_cap(ap, a, "--seeds", repr(text), len(seeds), "seeds")
    if not seeds:
        ap.error(f"--seeds={text!r}: A-B needs A <= B")
    check_seeds(ap, "--seeds", repr(text), seeds)
    if len(set(seeds)) != len(seeds):
        ap.error(f"--seeds={text!r}: a seed is given twice")
    return seeds


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
    ap.add_argument("--seeds", type=str, default=None,
                    help="seeds of every study cell: A-B (from A to B) or a comma list; each "
                         "seed is one run, the table gives mean and standard deviation over "
                         "them (default: --seed); needs --study, and with sphere grains "
                         "--jitter > 0 (the lattice is otherwise the same for every seed)")
    ap.add_argument("--jitter", type=float, default=d.jitter,
                    help="random move of each lattice site (sphere grains), as a fraction of "
                         "half the lattice gap r/2, in [0, 1]; the seed draws it; 0 is App. A's "
                         "exact lattice, on which the seed has no effect")
    ap.add_argument("--record-every", type=int, default=d.record_every,
                    help="steps between two records of the pull (the thesis's script records "
                         "every step: 1)")
    ap.add_argument("--cov-window", type=float, default=None,
                    help="with --study: the longest pull, m, over which the CoV against the "
                         "grain size is compared (default: the shortest pull of the compared "
                         "runs)")
    ap.add_argument("--front-slot", type=float, default=d.front_slot,
                    help="a slot in the front wall during the pull, as a real pull-out box "
                         "has: its half-height is FRONT_SLOT x (bar radius + grain radius) "
                         "about the grid plane (1: a grain a bar pushes head-on leaves the "
                         "box); grains in it meet only its edges; in [0, 2], above grain "
                         "radius / (bar radius + grain radius); 0, the default, is the "
                         "thesis's closed box")
    ap.add_argument("--grains", type=str, default=d.grains, help=GRAINS_HELP)
    return ap


def parse_args(argv=None):
    ap = build_parser()
    a = parse_checked(ap, argv)
    given = given_options(ap, argv)
    check_grains(ap, a.grains)
    p = Params(**SMOKE) if a.smoke else Params()
    # (an empty list is refused by _floats, not replaced by the default)
    radii = _floats("--radius", a.radius, ap) if a.radius is not None else [p.radius]
    pressures = _floats("--pressure", a.pressure, ap) if a.pressure is not None else \
        [p.pressure]
    distinct(ap, "--radius", a.radius, radii)
    distinct(ap, "--pressure", a.pressure, pressures)
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
    distinct(ap, "--grids", a.grids, grids)
    if not (math.isfinite(a.velocity) and a.velocity > 0):
        ap.error(f"--velocity={a.velocity}: must be > 0 (m/s)")
    if not (0 <= a.damping < 1):
        ap.error(f"--damping={a.damping}: must be in [0, 1)")
    if not (math.isfinite(a.grid_young) and a.grid_young > 0):
        ap.error(f"--grid-young={a.grid_young}: must be > 0 (Pa)")
    if not (math.isfinite(a.jitter) and 0 <= a.jitter <= 1):
        ap.error(f"--jitter={a.jitter}: must be in [0, 1] (a fraction of half the lattice "
                 "gap; above 1 two grains could start in contact)")
    if not (math.isfinite(a.front_slot) and 0 <= a.front_slot <= 2):
        ap.error(f"--front-slot={a.front_slot}: must be in [0, 2], a fraction of the bar "
                 "radius + the grain radius (0: the wall closed)")
    if a.record_every < 1:
        ap.error(f"--record-every={a.record_every}: must be a whole number of steps >= 1")
    if a.seeds is not None and not a.study:
        ap.error(f"--seeds={a.seeds}: needs --study (a single run takes --seed)")
    seeds = _seeds(a.seeds, ap, a) if a.seeds is not None else [a.seed]
    # options that would have no effect given the others (docs/cli.md)
    if a.seeds is not None:
        refuse_unused(ap, a, given, "seed", f"with --seeds {a.seeds} (each run takes its seed "
                      "from --seeds)")
    if a.study:
        refuse_unused(ap, a, given, "grid", "with --study (the study runs the grids of "
                      "--grids)", "give --grids")
    else:
        refuse_unused(ap, a, given, "grids", "without --study (a single run takes --grid)",
                      "add --study")
    if a.grains != "spheres":
        refuse_unused(ap, a, given, "jitter", f"with --grains {a.grains} (it moves the "
                      "spheres' lattice sites; clumps are placed at random)")
    for r in radii:
        # App. A's lattice (gap r/2): about sqrt(2) (box / 2.5 r)^3 sites in the box
        check_cap(ap, a, "--radius", r, math.sqrt(2.0) * (p.box / (2.5 * r)) ** 3, "grains",
                  estimate=True)
    if a.study:
        runs = sum(len(radii if g == "square" or a.radius is not None else [2.5e-3])
                   for g in grids) * len(pressures) * len(seeds)
        check_cap(ap, a, "--grids/--radius/--pressure/--seeds",
                  f"{a.grids}/{a.radius}/{a.pressure}/{a.seeds}", runs, "elements or runs",
                  "runs of the study")
    if len(seeds) > 1 and a.grains == "spheres" and a.jitter == 0:
        ap.error(f"--seeds={a.seeds}: with sphere grains and --jitter 0 (App. A's exact "
                 "lattice) every seed gives the same run; give --jitter > 0 (e.g. 0.1)")
    if a.seeds is None and a.grains == "spheres" and a.jitter == 0 \
            and a.seed != ap.get_default("seed"):
        ap.error(f"--seed={a.seed}: has no effect with sphere grains and --jitter 0 (App. A's "
                 "exact lattice: no draw takes the seed; every seed gives the same run); give "
                 "--jitter > 0 (e.g. 0.1) or clump grains, or leave --seed out")
    for P in pressures:
        warn_below("--pressure", P, 1e3, "Pa", f"kPa given as Pa? {P:g} kPa is {P * 1e3:g}")
    p = replace(p, grid=a.grid, radius=radii[0], pressure=pressures[0], velocity=a.velocity,
                grid_young=a.grid_young,
                pull=a.pull, damping=a.damping, seed=seeds[0], threads=a.threads,
                grains=a.grains, jitter=a.jitter, record_every=a.record_every,
                front_slot=a.front_slot)
    if a.distance is not None:
        if not (math.isfinite(a.distance) and a.distance > 0):
            ap.error(f"--distance={a.distance}: must be > 0 (m)")
        if a.distance >= p.box:
            ap.error(f"--distance={a.distance}: must be < the box side {p.box} m (the grid "
                     f"would leave the box); at --velocity {a.velocity:g} m/s that is "
                     f"{a.distance / a.velocity:.3g} s of pull")
        p = replace(p, distance=a.distance)
    if a.cov_window is not None:
        if not a.study:
            ap.error(f"--cov-window={a.cov_window}: needs --study")
        if not (math.isfinite(a.cov_window) and a.cov_window > 0):
            ap.error(f"--cov-window={a.cov_window}: must be > 0 (m)")
    return (p, a.out, a.study, grids, radii, pressures, bool(a.radius), seeds, a.overwrite,
            a.cov_window)


def main(argv=None) -> int:
    (p, out, is_study, grids, radii, pressures, radii_given, seeds, overwrite,
     window) = parse_args(argv)
    if is_study:
        return run_main("pullout_001", out,
                        lambda o: study(p, o, grids, radii, pressures, radii_given, seeds,
                                        overwrite, window),
                        own_folder=False)
    return run_main("pullout_001", out, lambda o: run(p, o))


if __name__ == "__main__":
    sys.exit(main())
