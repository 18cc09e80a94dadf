#!/usr/bin/env python3
"""The pull-out paper's set-up ("Geogrid pull-out modelling using DEM", 000) in cpp_dem and in
Yade from the same state: how each code's member forces give the paper's "transverse members
carry about 14 % of the longitudinal members' axial stress" (issue 36).

1. **Our preparation.** The case's builders (``geogrid_dem.cases.pullout_000.build``: Table 1
   grains and geogrid, 80 mm apertures, 10 mm flat ribs of PFacets, the box) and its
   preparation (``pullout.prepare``: REFD to the porosity, geogrid freed, gravity, top wall
   servo to the confining stress, node density scale ``auto``).
2. **The hand-over.** The prepared state goes to both codes as a fresh scene: sphere centres,
   radii, masses; grid node positions, masses and inertias (scaled, as the case pulls them) and
   the external force that keeps their weight the true one; the links (GridConnections) and
   PFacets in the same order, each link unloaded at its present length (rest length = current
   length in both codes); the six walls where the servo left them; zero velocities; no contact
   history (equal overlaps, zero shear springs). Same dt (fixed), local damping, gravity,
   Verlet distance, contact parameters (linear law, E R harmonic mean, k_s/k_n = nu, friction
   min of the pair; beam k_n = E pi R^2/L, k_s = 12 E I/L^3, k_r = E I/L, k_tw = G J/L).
3. **The pull.** Both codes pull the clamped front rib at ``--velocity`` towards -x for
   ``--steps`` steps, the top wall servo-controlled to the confining stress by the same rule
   (cpp_dem's ``ServoWall``: v = gain (sigma_t - sigma) A / (k dt), capped; in Yade a
   ``PyRunner`` every step before the forces). Yade: GridNode / GridConnection / PFacet
   (``yade.gridpfacet``), ``Ip2_CohFrictMat_CohFrictMat_CohFrictPhys`` +
   ``Law2_ScGeom6D_CohFrictPhys_CohesionMoment`` (unbreakable) for the links, sphere-PFacet
   contacts by ``Ig2_Sphere_PFacet_ScGridCoGeom`` + ``Law2_ScGridCoGeom_FrictPhys_CundallStrack``.

``--yade-kinematics matched`` (default) makes Yade integrate our laws: shear of sphere-sphere
contacts and of the links from the velocities at the contact point / the link's middle
(``avoidGranularRatcheting=False``), incremental bending and twisting. ``yade`` leaves Yade's
defaults, as a Yade user (000) would have had them: ``avoidGranularRatcheting=True``, which for
a GridConnection scales the shear increment by 2 R_c / L, and total-form moments. ``both`` runs
Yade twice.

Checks of the hand-over: after one step, the force on every sphere that touches the geogrid
in neither code (its sphere-sphere and sphere-wall contacts), ours against Yade's; the link
stiffnesses Yade uses against ours; the geogrid alone (no grains, ``--grid-check-steps``)
pulled under its weight in both codes. ``--edge-probe`` runs only a one-PFacet test of each
code's grain-rib contact on the face, beside and above an edge, beside a corner (Yade 2023.02a
makes no contact on an outer edge: its sphere-PFacet contact needs the sphere centre to
project inside a triangle, except near a node; cpp_dem's PFacet has rounded edges).

Member forces, read at every record from both codes for the members A (longitudinal) and C
(transverse) of apertures 1 and 2 as the case groups them (``PulloutSample.aperture_members``):
per link the axial force (Yade: the GridNode-GridNode interaction's ``phys.normalForce`` along
its normal, tension positive) and the shear force (``phys.shearForce``). Definitions of "the
member's force" (N; a stress is any of them over an area common to A and C, which leaves the
ratio unchanged):

- ``section_sum``: sum over the links cut by the rib's mid-section of F_axial |n . axis| (the
  case's ``force_*`` today);
- ``section_abs_sum``: the same with |F_axial|;
- ``section_edge_abs``: mean |F_axial| of the two links along the rib at its mid-section (one
  GridConnection of the member, as one would read it in Yade);
- ``along_mean_abs``: mean |F_axial| over every link of the member that runs along it;
- ``link_mean_abs``: mean |F_axial| over every link of the member (edges, rungs, diagonals);
- ``link_max_abs``: the largest |F_axial| over the member's links;
- ``link_total_mean``: mean over the member's links of |F_axial n + F_shear| (the whole
  interaction force).

For each: |C| / |A| = mean over the records of |C1| and |C2| over that of |A1| and |A2| (as
``pullout.summarize``), per aperture C1/A1, C2/A2, and over WINDOWS equal windows of the pull.
Agreement of the codes: relative differences of the pull force and of every member force over
the run (of the mean magnitudes, and the mean absolute difference over the records).

    .venv/bin/python bench/pullout_000_vs_yade.py                      # 3000 spheres, 20 mm
    .venv/bin/python bench/pullout_000_vs_yade.py --distance 0.1 --every 400 \\
        --out results/bench_runs/pullout_000_vs_yade.json             # the case's 100 mm
    .venv/bin/python bench/pullout_000_vs_yade.py --smoke --yade-kinematics both   # 1 min
    .venv/bin/python bench/pullout_000_vs_yade.py --edge-probe                       # 10 s

Results and wall times: bench/results/pullout_000_vs_yade.md.

The last line printed is one JSON object with the key numbers.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

import cpp_dem as dem  # noqa: E402
from cpp_dem import apply_threads  # noqa: E402
from cpp_dem._core import ServoWall  # noqa: E402
from cpp_dem.build import geogrid  # noqa: E402
from cpp_dem.protocols import pullout  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

MEMBERS = ("A1", "C1", "A2", "C2")
DEFINITIONS = ("section_sum", "section_abs_sum", "section_edge_abs", "along_mean_abs",
               "link_mean_abs", "link_max_abs", "link_total_mean")
WINDOWS = 5  #: the pull split into this many equal displacement windows for the ratios


def log(msg: str) -> None:
    print(f"[po000-yade] {msg}", flush=True)


# ---- 1. our preparation ---------------------------------------------------------------------


def prepare_state(p, *, log=log) -> dict:
    """Builds the pull-out paper's sample with the case's builders (``p``: a
    ``pullout_000.Params``), prepares it as the case does and returns the state both codes
    start from (SI; see :func:`state_from_sample`)."""
    from geogrid_dem.cases import pullout_000 as case

    sample = case.build(p)
    t0 = time.perf_counter()
    res = pullout.prepare(sample, stress=p.pressure, porosity=p.porosity,
                          node_density_scale=p.node_density_scale, log=log)
    log(f"prepared in {time.perf_counter() - t0:.1f} s: porosity {res.porosity:.4f}, top "
        f"stress {res.top_stress / 1e3:.2f} kPa, node density scale "
        f"{sample.node_density_scale:.3g}, dt {sample.scene.dt:.4g} s")
    st = state_from_sample(sample, p)
    st["prep"] = {"porosity": res.porosity, "top_stress_Pa": res.top_stress,
                  "converged": bool(res.converged), "seconds": time.perf_counter() - t0}
    return st


def state_from_sample(sample: pullout.PulloutSample, p) -> dict:
    """The state of a pull-out sample as plain arrays (SI) for both codes: spheres, grid nodes
    (local indices 0..m-1), links and PFacets (local node and link indices, in scene order),
    box corners, laws, dt, the clamp, the top servo, the members A1, C1, A2, C2."""
    sc = sample.scene
    grains = np.flatnonzero(np.asarray(sc.body_kinds) == 0)
    nodes = np.asarray(sample.grid.nodes)
    if not (np.array_equal(grains, np.arange(len(grains)))
            and np.array_equal(nodes, len(grains) + np.arange(len(nodes)))):
        raise SystemExit("error: expected the spheres first, then the grid nodes")
    local = {int(b): k for k, b in enumerate(nodes)}
    pos, m, j = np.asarray(sc.positions), np.asarray(sc.masses), np.asarray(sc.inertias)
    ln = np.asarray(sc.grid_link_nodes)
    links = np.array([[local[int(a)], local[int(b)]] for a, b in ln], dtype=int)
    link_of = {frozenset(map(int, ab)): k for k, ab in enumerate(links)}
    pf = np.array([[local[int(n)] for n in t] for t in np.asarray(sc.pfacet_nodes)], dtype=int)
    pf_links = np.array([[link_of[frozenset((int(a), int(b)))]
                          for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))] for t in pf])
    lo, hi = sample.box_lo_hi()
    members = {}
    for name, idx in sample.aperture_members().items():
        members[name] = {"index": int(idx),
                         "links": [int(x) for x in sample.grid.member_links[idx]],
                         "section": [int(x) for x in sample.grid.member_section_links[idx]],
                         "axis": [float(x) for x in sample.grid.member_axis[idx]],
                         "area_m2": float(sample.grid.area[idx])}
    servo = sample.top_servo
    rc = float(np.asarray(sc.grid_link_radii)[0])
    return {
        "sphere_pos": pos[grains], "sphere_rad": np.asarray(sc.radii)[grains],
        "sphere_mass": m[grains], "sphere_inertia": j[grains],
        "node_pos": pos[nodes], "node_mass": m[nodes], "node_inertia": j[nodes],
        "node_ext_force": np.asarray(sc.external_forces)[nodes], "rc": rc,
        "links": links, "pfacets": pf, "pfacet_links": pf_links,
        "box_lo": lo, "box_hi": hi, "walls": list(sample.walls),
        "grain": {"young": p.young, "poisson": p.poisson, "density": p.unit_weight /
                  geogrid.G_STANDARD, "friction_deg": p.phi},
        "grid": {"young": p.grid_young, "poisson": p.grid_poisson, "friction_deg": p.grid_phi,
                 "density": p.grid_unit_weight / geogrid.G_STANDARD},
        "dt": float(sc.dt), "damping": float(sc.local_damping),
        "gravity": [float(g) for g in sc.gravity],
        "verlet": 0.2 * float(np.mean(np.asarray(sc.radii)[grains])),
        "clamp": [local[int(b)] for b in sample.clamp_nodes],
        "servo": {"target_Pa": float(servo.target_stress), "area_m2": float(servo.area)
                  if servo.area > 0 else float((hi[0] - lo[0]) * (hi[1] - lo[1])),
                  "gain": float(servo.gain), "max_speed": float(servo.max_speed),
                  "period": int(servo.period)},
        "members": members, "max_overlap_ratio": float(sc.max_overlap_ratio),
        "node_density_scale": float(sample.node_density_scale),
    }


# ---- 2. our twin scene ----------------------------------------------------------------------


def twin_scene(st: dict):
    """cpp_dem's fresh scene from the state: the same spheres, walls, grid (every link unloaded
    at its present length), masses, external forces, fixed dt. Returns (scene, walls,
    node_ids)."""
    g, gr = st["grain"], st["grid"]
    sc = dem.Scene(local_damping=st["damping"])
    gmat = sc.add_material(dem.linear_material(density=g["density"], young=g["young"],
                                               poisson=g["poisson"],
                                               friction_angle_deg=g["friction_deg"]))
    wmat = sc.add_material(dem.linear_material(density=g["density"], young=g["young"],
                                               poisson=g["poisson"], friction_angle_deg=0.0))
    walls = sc.add_box(st["box_lo"], st["box_hi"], material=wmat)
    if len(st["sphere_rad"]):
        sc.add_spheres(st["sphere_pos"], st["sphere_rad"], material=gmat)
    for b, (mb, jb) in enumerate(zip(st["sphere_mass"], st["sphere_inertia"])):
        sc.set_mass_inertia(b, float(mb), float(jb))
    grid_mat = sc.add_material(dem.linear_material(
        density=gr["density"], young=gr["young"], poisson=gr["poisson"],
        friction_angle_deg=gr["friction_deg"]))
    beam = dem.BeamParams(young=gr["young"], poisson=gr["poisson"], radius=st["rc"],
                          normal_cohesion=0.0, shear_cohesion=0.0)
    first = sc._add_grid_nodes(np.asarray(st["node_pos"], float), st["rc"],
                               np.asarray(st["node_mass"], float),
                               np.asarray(st["node_inertia"], float), grid_mat)
    nid = first + np.arange(len(st["node_pos"]))
    lid = [sc.add_grid_link(int(nid[a]), int(nid[b]), beam, grid_mat) for a, b in st["links"]]
    for t, ls in zip(st["pfacets"], st["pfacet_links"]):
        sc.add_pfacet(int(nid[t[0]]), int(nid[t[1]]), int(nid[t[2]]), int(lid[ls[0]]),
                      int(lid[ls[1]]), int(lid[ls[2]]), grid_mat)
    sc.gravity = st["gravity"]
    ext = np.zeros((sc.num_bodies, 3))
    ext[nid] = st["node_ext_force"]
    sc.external_forces = ext
    sc.set_auto_timestep(period=0)
    sc.dt = st["dt"]
    sc.verlet_margin = st["verlet"]
    sc.max_overlap_ratio = st["max_overlap_ratio"]
    return sc, walls, nid


# ---- 3. the pull in both codes --------------------------------------------------------------


def tracked_links(st: dict) -> list[int]:
    """The links of the members A1, C1, A2, C2 (sorted, unique)."""
    return sorted({lk for m in st["members"].values() for lk in m["links"]})


def run_ours(st: dict, *, velocity: float, steps: int, every: int, log=log) -> dict:
    """The pull in cpp_dem from the state; records at step 1 and every ``every`` steps."""
    sc, walls, nid = twin_scene(st)
    top = walls[5]
    sv = st["servo"]
    servo = ServoWall(wall=top, target_stress=sv["target_Pa"], area=sv["area_m2"],
                      gain=sv["gain"], max_speed=sv["max_speed"])
    servo.period = sv["period"]
    sc.add_controller(servo)
    clamp = nid[st["clamp"]]
    sc.block_dofs(clamp, "all")
    v = np.zeros((sc.num_bodies, 3))
    v[clamp] = (-velocity, 0.0, 0.0)
    sc.velocities = v
    sc.angular_velocities = np.zeros((sc.num_bodies, 3))
    track = np.array(tracked_links(st), dtype=int)
    lnodes = np.asarray(sc.grid_link_nodes)[track]
    x0 = np.asarray(sc.positions)[nid].copy()
    rows, first = [], {}

    ns = len(st["sphere_rad"])
    weight = np.asarray(sc.masses)[:ns, None] * np.asarray(st["gravity"])[None, :]

    def record():
        pos, f = np.asarray(sc.positions), np.asarray(sc.forces)
        d = pos[lnodes[:, 1]] - pos[lnodes[:, 0]]
        gc = sc.grid_contacts()
        if not rows:  # the hand-over check: every sphere's contact force after one step
            first.update({"sphere_force": (f[:ns] - weight).tolist(),
                          "grid_spheres": sorted({int(x) for x in gc["sphere"]}),
                          "grid_contact_kinds": np.bincount(np.asarray(gc["kind"], int),
                                                            minlength=3).tolist()})
        rows.append({"step": int(sc.step_count), "grid_contacts": int(len(gc["sphere"])),
                     "pull_force": float(f[clamp, 0].sum()),
                     "top_force": float(np.asarray(sc.wall_forces)[top][2]),
                     "top_z": float(np.asarray(sc.wall_positions)[top]),
                     "displacement": float(np.mean(x0[st["clamp"], 0] - pos[clamp, 0])),
                     "grid_mean_dx": float(np.mean(pos[nid, 0] - x0[:, 0])),
                     "axial": np.asarray(sc.grid_link_axial_forces)[track].tolist(),
                     "shear": np.asarray(sc.grid_link_shear_forces)[track].tolist(),
                     "direction": (d / np.linalg.norm(d, axis=1)[:, None]).tolist()})

    t0 = time.perf_counter()
    # The front nodes may lie a fraction of a millimetre behind the front wall after the
    # preparation (the geogrid leaves the box there; walls never touch it). Scene.run refuses
    # geogrid nodes behind a wall at step 0 (only then), so the first step is the core's.
    sc._run(1)
    record()
    while sc.step_count < steps:
        sc.run(min(every - sc.step_count % every, steps - sc.step_count))
        record()
    secs = time.perf_counter() - t0
    log(f"cpp_dem: {steps} steps in {secs:.1f} s ({1e3 * secs / steps:.2f} ms/step)")
    return {"rows": rows, "seconds": secs, "tracked": track.tolist(), "first": first}


YADE_SCRIPT = r'''
# Yade side of bench/pullout_000_vs_yade.py (yade -n -j1 -x THIS CONFIG.json): the state the
# bench hands over, rebuilt with yade.gridpfacet, pulled as in cpp_dem; prints YADE_RESULT.
import json, math, sys, time
from yade import utils
from yade.wrapper import *
import yade.gridpfacet as gp

cfg = json.load(open(sys.argv[-1]))
matched = cfg["kinematics"] == "matched"
g, gr = cfg["grain"], cfg["grid"]
O.materials.append(FrictMat(young=g["young"], poisson=g["poisson"], density=g["density"],
                            frictionAngle=math.radians(g["friction_deg"]), label="grains"))
O.materials.append(FrictMat(young=g["young"], poisson=g["poisson"], density=g["density"],
                            frictionAngle=0.0, label="walls"))
O.materials.append(FrictMat(young=gr["young"], poisson=gr["poisson"], density=gr["density"],
                            frictionAngle=math.radians(gr["friction_deg"]), label="gridext"))
# The links: unbreakable (cohesions far above any force), moments on.
O.materials.append(CohFrictMat(young=gr["young"], poisson=gr["poisson"], density=gr["density"],
                               frictionAngle=math.radians(gr["friction_deg"]),
                               normalCohesion=1e100, shearCohesion=1e100,
                               momentRotationLaw=True, label="gridnode"))
# masks: grains 0b011, walls 0b010, PFacets 0b101 (the collider skips PFacet-PFacet pairs,
# and walls never touch the geogrid, as in cpp_dem with grid_wall_contacts False)
O.engines = [
    PyRunner(iterPeriod=1, command="servo()", label="servo_runner"),
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb(), Bo1_PFacet_Aabb(),
                           Bo1_GridConnection_Aabb()], verletDist=cfg["verlet"],
                          avoidSelfInteractionMask=4),
    InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom(avoidGranularRatcheting=not matched), Ig2_Box_Sphere_ScGeom(),
         Ig2_GridNode_GridNode_GridNodeGeom6D(avoidGranularRatcheting=not matched),
         Ig2_Sphere_PFacet_ScGridCoGeom(), Ig2_Sphere_GridConnection_ScGridCoGeom()],
        [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys(setCohesionNow=True,
                                                  setCohesionOnNewContacts=False),
         Ip2_FrictMat_FrictMat_FrictPhys()],
        [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(useIncrementalForm=matched),
         Law2_ScGeom_FrictPhys_CundallStrack(), Law2_ScGridCoGeom_FrictPhys_CundallStrack()]),
    NewtonIntegrator(damping=cfg["damping"], gravity=tuple(cfg["gravity"])),
]
O.dt = cfg["dt"]
sph = []
for (x, y, z), r, m, j in zip(cfg["sphere_pos"], cfg["sphere_rad"], cfg["sphere_mass"],
                              cfg["sphere_inertia"]):
    b = utils.sphere((x, y, z), r, material="grains")
    b.mask = 3
    sph.append(O.bodies.append(b))
    b.state.mass = m
    b.state.inertia = (j, j, j)
walls = utils.aabbWalls([tuple(cfg["box_lo"]), tuple(cfg["box_hi"])], thickness=0,
                        material="walls")
wall_ids = O.bodies.append(walls)  # x-, x+, y-, y+, z-, z+
for w in wall_ids:
    O.bodies[w].mask = 2
top = wall_ids[5]
nodes = [O.bodies.append(gp.gridNode(tuple(x), cfg["rc"], material="gridnode", fixed=False))
         for x in cfg["node_pos"]]
for a, b in cfg["links"]:
    O.bodies.append(gp.gridConnection(nodes[a], nodes[b], cfg["rc"], material="gridext",
                                      mask=5))
for t in cfg["pfacets"]:
    O.bodies.append(gp.pfacet(nodes[t[0]], nodes[t[1]], nodes[t[2]], material="gridext",
                              mask=5))
for k, n in enumerate(nodes):  # the scaled node masses, and the force that keeps the weight
    st = O.bodies[n].state
    st.mass = cfg["node_mass"][k]
    j = cfg["node_inertia"][k]
    st.inertia = (j, j, j)
    O.forces.setPermF(n, tuple(cfg["node_ext_force"][k]))
links = [O.interactions[nodes[a], nodes[b]] for a, b in cfg["links"]]
stiff = [[i.phys.kn, i.phys.ks, i.phys.kr, i.phys.ktw] for i in links]
clamp = [nodes[k] for k in cfg["clamp"]]
for n in clamp:
    st = O.bodies[n].state
    st.blockedDOFs = "xyzXYZ"
    st.vel = (-cfg["velocity"], 0, 0)
    st.angVel = (0, 0, 0)
sv = cfg["servo"]


def servo():
    """cpp_dem's ServoWall rule on the top wall (forces of the last step)."""
    sigma = O.forces.f(top)[2] / sv["area_m2"]
    k = sum(i.phys.kn for i in O.interactions.withBody(top) if i.isReal)
    err = sv["target_Pa"] - sigma
    vmax = sv["max_speed"]
    v = sv["gain"] * err * sv["area_m2"] / (k * O.dt * sv["period"]) if k > 0 else (
        vmax if err > 0 else 0.0)
    O.bodies[top].state.vel = (0, 0, -max(-vmax, min(vmax, v)))


track = cfg["tracked"]
x0 = [O.bodies[n].state.pos[0] for n in nodes]
rows = []


grid_bodies = set(O.bodies[b].id for b in range(len(O.bodies))
                  if type(O.bodies[b].shape).__name__ in ("PFacet", "GridConnection"))
first = {}


def grid_contacts():
    n, spheres = 0, set()
    for i in O.interactions:
        if i.isReal and (i.id1 in grid_bodies or i.id2 in grid_bodies):
            g = i.geom
            if getattr(g, "isDuplicate", 0) and g.trueInt != i.id2:
                continue  # a duplicate the law skips
            n += 1
            spheres.add(i.id1 if i.id2 in grid_bodies else i.id2)
    return n, spheres


def record():
    ax, sh, dr = [], [], []
    n_gc, gsph = grid_contacts()
    if not rows:
        first["sphere_force"] = [list(O.forces.f(b)) for b in sph]
        first["grid_spheres"] = sorted(gsph)
    for lk in track:
        a, b = nodes[cfg["links"][lk][0]], nodes[cfg["links"][lk][1]]
        i = O.interactions[a, b]
        s = 1.0 if i.id1 == a else -1.0  # cpp_dem's a -> b against Yade's id1 -> id2
        n = i.geom.normal
        ax.append(-i.phys.normalForce.dot(n))  # tension positive
        sh.append([s * c for c in i.phys.shearForce])  # on node b
        dr.append([s * c for c in n])
    rows.append({"step": O.iter, "grid_contacts": n_gc,
                 "pull_force": sum(O.forces.f(n)[0] for n in clamp),
                 "top_force": O.forces.f(top)[2], "top_z": O.bodies[top].state.pos[2],
                 "displacement": sum(x0[k] - O.bodies[nodes[k]].state.pos[0]
                                     for k in cfg["clamp"]) / len(clamp),
                 "grid_mean_dx": sum(O.bodies[n].state.pos[0] - x0[k]
                                     for k, n in enumerate(nodes)) / len(nodes),
                 "axial": ax, "shear": sh, "direction": dr})


t0 = time.time()
O.run(1, True)
record()
while O.iter < cfg["steps"]:
    O.run(min(cfg["every"] - O.iter % cfg["every"], cfg["steps"] - O.iter), True)
    record()
print("YADE_RESULT " + json.dumps({"rows": rows, "seconds": time.time() - t0,
                                   "link_stiffness": stiff, "first": first}), flush=True)
'''


# ---- the edge probe: does a code see a grain on a flat rib's rounded edge? --------------------

#: One PFacet (nodes at (0,0,0), (0.04,0,0), (0,0.04,0) m, R_c = 1 mm) and a grain of 12 mm
#: radius (the paper's materials) at four places, each overlapping the PFacet's Minkowski body
#: (the triangle dilated by R_c) by about 0.5 mm: on the face, beside an edge in the plane,
#: above the plane just beyond an edge, and beside a corner.
PROBE_NODES = [(0.0, 0.0, 0.0), (0.04, 0.0, 0.0), (0.0, 0.04, 0.0)]
PROBE_RC, PROBE_R = 1e-3, 0.012
PROBES = {"face": (0.01, 0.01, 0.0125), "edge_in_plane": (0.02, -0.0125, 0.0),
          "edge_above": (0.02, -0.002, 0.0123), "corner": (-0.0088, -0.0088, 0.0)}

PROBE_SCRIPT = r'''
import json, math, sys
from yade import utils
from yade.wrapper import *
import yade.gridpfacet as gp
cfg = json.load(open(sys.argv[-1]))
O.materials.append(FrictMat(young=1e6, poisson=0.5, density=2600, frictionAngle=0.5,
                            label="grains"))
O.materials.append(FrictMat(young=4e9, poisson=0.3, density=100, frictionAngle=0.35,
                            label="gridext"))
O.materials.append(CohFrictMat(young=4e9, poisson=0.3, density=100, frictionAngle=0.35,
                               normalCohesion=1e100, shearCohesion=1e100,
                               momentRotationLaw=True, label="gridnode"))
O.engines = [ForceResetter(),
             InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_PFacet_Aabb(),
                                    Bo1_GridConnection_Aabb()]),
             InteractionLoop([Ig2_GridNode_GridNode_GridNodeGeom6D(),
                              Ig2_Sphere_PFacet_ScGridCoGeom(),
                              Ig2_Sphere_GridConnection_ScGridCoGeom()],
                             [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys(
                                 setCohesionNow=True, setCohesionOnNewContacts=False),
                              Ip2_FrictMat_FrictMat_FrictPhys()],
                             [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(),
                              Law2_ScGridCoGeom_FrictPhys_CundallStrack()]),
             NewtonIntegrator(damping=0.0, gravity=(0, 0, 0))]
O.dt = 1e-6
n = [O.bodies.append(gp.gridNode(tuple(x), cfg["rc"], material="gridnode", fixed=True))
     for x in cfg["nodes"]]
for a, b in ((0, 1), (1, 2), (0, 2)):
    O.bodies.append(gp.gridConnection(n[a], n[b], cfg["rc"], material="gridext", mask=5))
O.bodies.append(gp.pfacet(n[0], n[1], n[2], material="gridext", mask=5))
out = {}
for name, c in cfg["probes"].items():
    s = O.bodies.append(utils.sphere(tuple(c), cfg["r"], material="grains"))
    O.bodies[s].state.blockedDOFs = "xyzXYZ"
    O.step()
    out[name] = {"contacts": sum(1 for i in O.interactions.withBody(s) if i.isReal),
                 "force_N": O.forces.f(s).norm()}
    O.bodies.erase(s)
print("PROBE_RESULT " + json.dumps(out), flush=True)
'''


def edge_probe(yade: str | None = "yade") -> dict:
    """Each code's contact with one PFacet for the grain at each of PROBES after one step:
    {probe: {"overlap_m", "expected_N" (k_n x overlap), "ours": {contacts, force_N},
    "yade": {...}}} (Yade's only when ``yade`` is given)."""
    x = np.asarray(PROBE_NODES)
    res = {}
    for name, c in PROBES.items():
        # the overlap with the dilated triangle (closest point of the triangle, plane z = 0)
        q = np.array([min(max(c[0], 0.0), 0.04), min(max(c[1], 0.0), 0.04), 0.0])
        if q[0] + q[1] > 0.04:
            t = min(max((c[0] - c[1] + 0.04) / 0.08, 0.0), 1.0)
            q = np.array([0.04 * t, 0.04 * (1 - t), 0.0])
        ov = PROBE_R + PROBE_RC - float(np.linalg.norm(np.asarray(c) - q))
        sc = dem.Scene()
        gm = sc.add_material(dem.linear_material(density=2600, young=1e6, poisson=0.5,
                                                 friction_angle_deg=30))
        pm = sc.add_material(dem.linear_material(density=100, young=4e9, poisson=0.3,
                                                 friction_angle_deg=20))
        sc.add_spheres([c], [PROBE_R], material=gm)
        first = sc._add_grid_nodes(x, PROBE_RC, np.full(3, 1e-3), np.full(3, 1e-9), pm)
        beam = dem.BeamParams(young=4e9, poisson=0.3, radius=PROBE_RC)
        lk = [sc.add_grid_link(first + a, first + b, beam, pm) for a, b in ((0, 1), (1, 2),
                                                                           (2, 0))]
        sc.add_pfacet(first, first + 1, first + 2, lk[0], lk[1], lk[2], pm)
        sc.block_dofs(range(sc.num_bodies), "all")
        sc.dt = 1e-6
        sc.run(1)
        kn = dem.mix_materials(sc.material(gm), sc.material(pm), PROBE_R, PROBE_RC, 1, 1).kn
        res[name] = {"overlap_m": ov, "expected_N": kn * ov,
                     "ours": {"contacts": int(len(sc.grid_contacts()["sphere"])),
                              "force_N": float(np.linalg.norm(np.asarray(sc.forces)[0]))}}
    if yade:
        cfg = {"nodes": PROBE_NODES, "rc": PROBE_RC, "r": PROBE_R, "probes": PROBES}
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "probe.py").write_text(PROBE_SCRIPT)
            (Path(tmp) / "cfg.json").write_text(json.dumps(cfg))
            pr = subprocess.run([yade, "-n", "-j1", "-x", str(Path(tmp) / "probe.py"),
                                 str(Path(tmp) / "cfg.json")], capture_output=True, text=True,
                                timeout=600)
        line = [x for x in pr.stdout.splitlines() if x.startswith("PROBE_RESULT ")]
        if not line:
            print(pr.stdout[-3000:], pr.stderr[-3000:], file=sys.stderr)
            raise SystemExit("error: the Yade edge probe gave no result")
        for name, v in json.loads(line[0][len("PROBE_RESULT "):]).items():
            res[name]["yade"] = v
    return res


def _jsonable(st: dict) -> dict:
    out = {}
    for k, v in st.items():
        out[k] = v.tolist() if isinstance(v, np.ndarray) else v
    return out


def run_yade(st: dict, *, velocity: float, steps: int, every: int, kinematics: str,
             yade: str = "yade", log=log) -> dict:
    """The same pull in Yade (a subprocess); ``kinematics`` 'matched' or 'yade' (see the
    module docstring). Returns the records, Yade's wall time of the steps (s) and its link
    stiffnesses."""
    cfg = {**_jsonable({k: v for k, v in st.items() if k != "prep"}), "velocity": velocity,
           "steps": steps, "every": every, "kinematics": kinematics,
           "tracked": tracked_links(st)}
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "yade_pullout_000.py"
        script.write_text(YADE_SCRIPT)
        path = Path(tmp) / "cfg.json"
        path.write_text(json.dumps(cfg))
        t0 = time.perf_counter()
        pr = subprocess.run([yade, "-n", "-j1", "-x", str(script), str(path)],
                            capture_output=True, text=True, timeout=6 * 3600)
        wall = time.perf_counter() - t0
    line = [x for x in pr.stdout.splitlines() if x.startswith("YADE_RESULT ")]
    if not line:
        print(pr.stdout[-4000:], pr.stderr[-4000:], file=sys.stderr)
        raise SystemExit("error: Yade gave no result")
    res = json.loads(line[0][len("YADE_RESULT "):])
    res["wall_seconds"] = wall
    log(f"yade ({kinematics}): {steps} steps in {res['seconds']:.1f} s "
        f"({1e3 * res['seconds'] / steps:.2f} ms/step; {wall:.1f} s with start-up)")
    return res


def grid_only_check(st: dict, *, velocity: float, steps: int, every: int, kinematics: str,
                    yade: str = "yade", log=log) -> dict:
    """The geogrid alone (no grains) pulled by its clamp under its weight in both codes: the
    links, node masses, weight, damping and clamp without any contact. Returns the largest
    difference of the tracked links' axial forces over the run relative to their largest
    |F| (N/N), and that of the grid's mean x displacement (m/m)."""
    bare = {**st, "sphere_pos": np.zeros((0, 3)), "sphere_rad": np.zeros(0),
            "sphere_mass": np.zeros(0), "sphere_inertia": np.zeros(0)}
    import warnings

    from cpp_dem.scene import ControllerLimitWarning

    with warnings.catch_warnings():  # no grains: the top servo runs at its cap, harmlessly
        warnings.simplefilter("ignore", ControllerLimitWarning)
        o = run_ours(bare, velocity=velocity, steps=steps, every=every, log=lambda s: None)
    y = run_yade(bare, velocity=velocity, steps=steps, every=every, kinematics=kinematics,
                 yade=yade, log=lambda s: None)
    fo = np.array([r["axial"] for r in o["rows"]])
    fy = np.array([r["axial"] for r in y["rows"]])
    xo = np.array([r["grid_mean_dx"] for r in o["rows"]])
    xy = np.array([r["grid_mean_dx"] for r in y["rows"]])
    out = {"steps": steps, "kinematics": kinematics,
           "link_axial_max_diff_over_max": float(np.abs(fo - fy).max() / np.abs(fy).max()),
           "largest_link_force_N": float(np.abs(fy).max()),
           "grid_mean_dx_max_diff_over_max": float(np.abs(xo - xy).max() / np.abs(xy).max())}
    log(f"grid alone, {steps} steps ({kinematics}): link axial forces differ by at most "
        f"{out['link_axial_max_diff_over_max']:.2e} of the largest "
        f"({out['largest_link_force_N']:.3g} N); grid mean dx by "
        f"{out['grid_mean_dx_max_diff_over_max']:.2e}")
    return out


# ---- 4. member forces by each definition ----------------------------------------------------


def member_series(run: dict, st: dict) -> dict:
    """{definition: {member: array over the records}} (N) from a run's link records."""
    track = run.get("tracked", tracked_links(st))
    pos = {lk: k for k, lk in enumerate(track)}
    ax = np.array([r["axial"] for r in run["rows"]])            # (records, links)
    sh = np.array([r["shear"] for r in run["rows"]])            # (records, links, 3)
    dr = np.array([r["direction"] for r in run["rows"]])        # (records, links, 3)
    total = np.linalg.norm(-ax[:, :, None] * dr + sh, axis=2)   # |force on node b|
    out = {d: {} for d in DEFINITIONS}
    for name, mem in st["members"].items():
        axis = np.asarray(mem["axis"], float)
        sec = [pos[lk] for lk in mem["section"]]
        alll = [pos[lk] for lk in mem["links"]]
        cos = np.abs(dr[:, sec, :] @ axis)                       # (records, section links)
        edge = list(np.argsort(-cos[0])[:2])  # the two links along the rib (not the diagonal)
        out["section_sum"][name] = np.sum(ax[:, sec] * cos, axis=1)
        out["section_abs_sum"][name] = np.sum(np.abs(ax[:, sec]) * cos, axis=1)
        out["section_edge_abs"][name] = np.mean(np.abs(ax[:, sec][:, edge]), axis=1)
        along = [k for k in alll if abs(dr[0, k] @ axis) > 0.9]
        out["along_mean_abs"][name] = np.mean(np.abs(ax[:, along]), axis=1)
        out["link_mean_abs"][name] = np.mean(np.abs(ax[:, alll]), axis=1)
        out["link_max_abs"][name] = np.max(np.abs(ax[:, alll]), axis=1)
        out["link_total_mean"][name] = np.mean(total[:, alll], axis=1)
    return out


def ratios(series: dict, displacement) -> dict:
    """|C|/|A| over the records after the first (the paper's "mean value"), all apertures
    (as pullout.summarize) and per aperture; and over WINDOWS equal windows of the pull
    displacement (m)."""
    out = {}
    disp = np.asarray(displacement, float)[1:]
    edges = np.linspace(0.0, disp.max(), WINDOWS + 1)
    for d, s in series.items():
        a = np.abs(np.concatenate([s["A1"][1:], s["A2"][1:]]))
        c = np.abs(np.concatenate([s["C1"][1:], s["C2"][1:]]))
        win = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            k = (disp > lo) & (disp <= hi)
            if not k.any():
                win.append({"from_m": float(lo), "to_m": float(hi), "C_over_A": float("nan"),
                            "mean_abs_A_N": float("nan"), "mean_abs_C_N": float("nan")})
                continue
            aw = np.abs(np.concatenate([s["A1"][1:][k], s["A2"][1:][k]])).mean()
            cw = np.abs(np.concatenate([s["C1"][1:][k], s["C2"][1:][k]])).mean()
            win.append({"from_m": float(lo), "to_m": float(hi), "C_over_A": float(cw / aw),
                        "mean_abs_A_N": float(aw), "mean_abs_C_N": float(cw)})
        out[d] = {"C_over_A": float(c.mean() / a.mean()), "windows": win,
                  "C1_over_A1": float(np.abs(s["C1"][1:]).mean() / np.abs(s["A1"][1:]).mean()),
                  "C2_over_A2": float(np.abs(s["C2"][1:]).mean() / np.abs(s["A2"][1:]).mean()),
                  **{f"mean_abs_{m}_N": float(np.abs(s[m][1:]).mean()) for m in MEMBERS}}
    return out


def rel_diff(a, b) -> dict:
    """Differences of series a (ours) and b (Yade) over the records after the first, relative
    to b: of the mean magnitudes (mean |a| / mean |b| - 1), the mean absolute difference over
    the mean |b|, and the correlation of the two series."""
    a, b = np.asarray(a, float)[1:], np.asarray(b, float)[1:]
    scale = float(np.mean(np.abs(b)))
    return {"of_mean": float(np.mean(np.abs(a)) / scale - 1) if scale else float("nan"),
            "mean_abs_diff_over_mean_abs": float(np.mean(np.abs(a - b)) / scale) if scale
            else float("nan"),
            "corr": float(np.corrcoef(a, b)[0, 1]) if len(a) > 2 and a.std() > 0
            and b.std() > 0 else float("nan")}


def handover_check(fo: dict, fy: dict) -> dict:
    """The state hand-over after one step: the contact force on every sphere that touches
    the geogrid in neither code (sphere-sphere and sphere-wall contacts only), ours against
    Yade's: the largest difference over the mean |F| (N/N), and how many spheres touch the
    geogrid in each code."""
    a, b = np.asarray(fo["sphere_force"]), np.asarray(fy["sphere_force"])
    touch = set(fo["grid_spheres"]) | set(fy["grid_spheres"])
    free = np.array([k for k in range(len(a)) if k not in touch], dtype=int)
    scale = float(np.mean(np.linalg.norm(b[free], axis=1)))
    return {"free_spheres": int(len(free)),
            "max_force_diff_over_mean": float(np.max(np.linalg.norm(a[free] - b[free], axis=1))
                                              / scale),
            "grid_spheres_ours": len(fo["grid_spheres"]),
            "grid_spheres_yade": len(fy["grid_spheres"]),
            "grid_contact_kinds_ours": fo.get("grid_contact_kinds")}


def agreement(ours: dict, yade: dict, so: dict, sy: dict) -> dict:
    po = [r["pull_force"] for r in ours["rows"]]
    py = [r["pull_force"] for r in yade["rows"]]
    out = {"pull_force": rel_diff(po, py),
           "top_force": rel_diff([r["top_force"] for r in ours["rows"]],
                                 [r["top_force"] for r in yade["rows"]]),
           "grid_mean_dx": rel_diff([r["grid_mean_dx"] for r in ours["rows"]],
                                    [r["grid_mean_dx"] for r in yade["rows"]]),
           "first_step": {k: [ours["rows"][0][k], yade["rows"][0][k]]
                          for k in ("pull_force", "top_force", "grid_contacts")},
           "handover": handover_check(ours["first"], yade["first"]),
           "grid_contacts_mean": [float(np.mean([r["grid_contacts"] for r in ours["rows"]])),
                                  float(np.mean([r["grid_contacts"] for r in yade["rows"]]))],
           "members": {d: {m: rel_diff(so[d][m], sy[d][m]) for m in MEMBERS}
                       for d in DEFINITIONS}}
    return out


# ---- main -----------------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--spheres", type=int, default=3000,
                    help="grains (the paper's smallest sample: 3000)")
    ap.add_argument("--steps", type=int, default=0,
                    help="pull steps in both codes (0: --distance / --velocity / dt)")
    ap.add_argument("--distance", type=float, default=0.02,
                    help="pull distance, m, when --steps is 0")
    ap.add_argument("--velocity", type=float, default=None,
                    help="pull velocity, m/s (default: the case's, 0.01)")
    ap.add_argument("--every", type=int, default=200, help="steps between records")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--smoke", action="store_true",
                    help="the case's smoke sample (375 spheres, half box), 2000 steps")
    ap.add_argument("--yade-kinematics", choices=("matched", "yade", "both"), default="matched",
                    help="Yade's shear kinematics and moment form: ours (matched), Yade's "
                         "defaults (yade), or one run of each")
    ap.add_argument("--grid-check-steps", type=int, default=2000,
                    help="steps of the geogrid-alone check (no grains) before the pull; 0: none")
    ap.add_argument("--no-yade", action="store_true", help="cpp_dem only")
    ap.add_argument("--edge-probe", action="store_true",
                    help="only the edge probe: one PFacet and a grain on its face, beside an "
                         "edge, above an edge, beside a corner; the contact each code sees")
    ap.add_argument("--yade", default="yade")
    ap.add_argument("--out", type=Path, default=None, help="JSON with every record")
    args = ap.parse_args(argv)
    if not args.no_yade and shutil.which(args.yade) is None:
        print(f"error: --yade={args.yade}: not found (apt-get install yade)", file=sys.stderr)
        return 2
    from geogrid_dem.cases import pullout_000 as case

    apply_threads(1)
    if args.edge_probe:
        probe = edge_probe(None if args.no_yade else args.yade)
        print("\n| grain position | overlap (mm) | k_n x overlap (N) | ours: contacts, force (N) "
              "| Yade: contacts, force (N) |\n|---|---|---|---|---|")
        for k, v in probe.items():
            y = v.get("yade", {"contacts": "-", "force_N": float("nan")})
            print(f"| {k} | {1e3 * v['overlap_m']:.3f} | {v['expected_N']:.2f} | "
                  f"{v['ours']['contacts']}, {v['ours']['force_N']:.2f} | {y['contacts']}, "
                  f"{y['force_N']:.2f} |")
        print(json.dumps({"bench": "pullout_000_vs_yade", "edge_probe": probe}, default=float))
        return 0
    t_all = time.perf_counter()
    p = case.Params(**case.SMOKE) if args.smoke else case.Params(spheres=args.spheres)
    p = replace(p, seed=args.seed)
    if args.smoke:
        args.steps = args.steps or 2000
    velocity = args.velocity if args.velocity is not None else p.velocity
    st = prepare_state(p)
    steps = args.steps or int(math.ceil(args.distance / velocity / st["dt"]))
    log(f"{len(st['sphere_rad'])} spheres, {len(st['node_pos'])} nodes, {len(st['links'])} "
        f"links, {len(st['pfacets'])} PFacets; pull {velocity} m/s for {steps} steps "
        f"({1e3 * steps * st['dt'] * velocity:.1f} mm), dt {st['dt']:.4g} s; members "
        + ", ".join(f"{k}: {len(v['links'])} links" for k, v in st["members"].items()))
    ours = run_ours(st, velocity=velocity, steps=steps, every=args.every)
    so = member_series(ours, st)
    result = {"spheres": len(st["sphere_rad"]), "steps": steps, "dt_s": st["dt"],
              "velocity_m_per_s": velocity, "pull_distance_m": steps * st["dt"] * velocity,
              "node_density_scale": st["node_density_scale"], "prep": st["prep"],
              "ours": {"seconds": ours["seconds"],
                       "ratios": ratios(so, [r["displacement"] for r in ours["rows"]]),
                       "mean_pull_force_N": float(np.mean([r["pull_force"]
                                                           for r in ours["rows"][1:]]))},
              "yade": {}}
    runs = {"ours": ours}
    kins = [] if args.no_yade else (["matched", "yade"] if args.yade_kinematics == "both"
                                    else [args.yade_kinematics])
    for kin in kins:
        grid_only = grid_only_check(st, velocity=velocity, steps=args.grid_check_steps,
                                    every=max(1, args.grid_check_steps // 10), kinematics=kin,
                                    yade=args.yade) if args.grid_check_steps else None
        y = run_yade(st, velocity=velocity, steps=steps, every=args.every, kinematics=kin,
                     yade=args.yade)
        sy = member_series(y, st)
        ks = np.asarray(y["link_stiffness"])
        sc, _, _ = twin_scene(st)
        k_ours = np.asarray(sc.grid_link_stiffness)
        result["yade"][kin] = {
            "seconds": y["seconds"], "wall_seconds": y["wall_seconds"],
            "ratios": ratios(sy, [r["displacement"] for r in y["rows"]]),
            "mean_pull_force_N": float(np.mean([r["pull_force"] for r in y["rows"][1:]])),
            "link_stiffness_rel_diff_max": float(np.max(np.abs(ks / k_ours - 1))),
            "agreement": agreement(ours, y, so, sy), "grid_only": grid_only}
        runs[f"yade_{kin}"] = y
    result["wall_time_s"] = time.perf_counter() - t_all
    report(result)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"result": result, "args": {k: str(v) for k, v in
                                                                   vars(args).items()},
                                        "members": st["members"],
                                        "tracked": tracked_links(st),
                                        "runs": {k: {"rows": v["rows"]}
                                                 for k, v in runs.items()}}, default=float))
        log(f"wrote {args.out}")
    print(json.dumps(summary_line(result), default=float))
    return 0


def report(res: dict) -> None:
    """Prints the table of ratios and the agreement."""
    cols = [("ours", res["ours"]["ratios"])] + [(f"Yade {k}", v["ratios"])
                                               for k, v in res["yade"].items()]
    print("\n| definition | " + " | ".join(f"{n}: C/A (C1/A1, C2/A2)" for n, _ in cols) + " |")
    print("|---|" + "---|" * len(cols))
    for d in DEFINITIONS:
        print(f"| {d} | " + " | ".join(
            f"{r[d]['C_over_A']:.3f} ({r[d]['C1_over_A1']:.3f}, {r[d]['C2_over_A2']:.3f})"
            for _, r in cols) + " |")
    print("\n| definition | member | " + " | ".join(f"{n} mean abs (N)" for n, _ in cols)
          + " | " + " | ".join(f"{k}: rel. diff of mean / mean abs diff"
                               for k in res["yade"]) + " |")
    print("|---|---|" + "---|" * (len(cols) + len(res["yade"])))
    for d in DEFINITIONS:
        for m in MEMBERS:
            print(f"| {d} | {m} | " + " | ".join(f"{r[d][f'mean_abs_{m}_N']:.2f}"
                                                 for _, r in cols) + " | " + " | ".join(
                f"{v['agreement']['members'][d][m]['of_mean']:+.3f} / "
                f"{v['agreement']['members'][d][m]['mean_abs_diff_over_mean_abs']:.3f}"
                for v in res["yade"].values()) + " |")
    print("\n| definition | window (mm) | " + " | ".join(f"{n}: C/A" for n, _ in cols) + " |")
    print("|---|---|" + "---|" * len(cols))
    for d in DEFINITIONS:
        for w in range(WINDOWS):
            ww = cols[0][1][d]["windows"][w]
            print(f"| {d} | {1e3 * ww['from_m']:.0f}-{1e3 * ww['to_m']:.0f} | " + " | ".join(
                f"{r[d]['windows'][w]['C_over_A']:.3f}" for _, r in cols) + " |")
    for k, v in res["yade"].items():
        a = v["agreement"]
        log(f"Yade {k}: pull force mean {v['mean_pull_force_N']:.1f} N vs ours "
            f"{res['ours']['mean_pull_force_N']:.1f} N (rel. diff of mean "
            f"{a['pull_force']['of_mean']:+.3f}, mean abs diff "
            f"{a['pull_force']['mean_abs_diff_over_mean_abs']:.3f}, corr "
            f"{a['pull_force']['corr']:.3f}); first step pull force ours/Yade "
            f"{a['first_step']['pull_force']}, top force {a['first_step']['top_force']}; "
            f"hand-over: {a['handover']}; grid contacts mean ours/Yade "
            f"{a['grid_contacts_mean']}; "
            f"link stiffness max rel diff {v['link_stiffness_rel_diff_max']:.1e}")


def summary_line(res: dict) -> dict:
    out = {"bench": "pullout_000_vs_yade", "spheres": res["spheres"], "steps": res["steps"],
           "pull_distance_m": res["pull_distance_m"], "wall_time_s": res["wall_time_s"],
           "ours_s": res["ours"]["seconds"],
           "ours_C_over_A": {d: res["ours"]["ratios"][d]["C_over_A"] for d in DEFINITIONS},
           "ours_mean_pull_force_N": res["ours"]["mean_pull_force_N"]}
    for k, v in res["yade"].items():
        out[f"yade_{k}_s"] = v["seconds"]
        out[f"yade_{k}_C_over_A"] = {d: v["ratios"][d]["C_over_A"] for d in DEFINITIONS}
        out[f"yade_{k}_mean_pull_force_N"] = v["mean_pull_force_N"]
        out[f"yade_{k}_pull_force_rel_diff_of_mean"] = v["agreement"]["pull_force"]["of_mean"]
        out[f"yade_{k}_member_rel_diff_of_mean"] = {
            d: {m: v["agreement"]["members"][d][m]["of_mean"] for m in MEMBERS}
            for d in ("section_sum", "section_edge_abs")}
        out[f"yade_{k}_grid_contacts_mean"] = v["agreement"]["grid_contacts_mean"]
        out[f"yade_{k}_handover_max_force_diff"] = \
            v["agreement"]["handover"]["max_force_diff_over_mean"]
        if v.get("grid_only"):
            out[f"yade_{k}_grid_only_link_diff"] = v["grid_only"]["link_axial_max_diff_over_max"]
    return out


if __name__ == "__main__":
    sys.exit(_cli.run(main))
