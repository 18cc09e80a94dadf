# Yade side of bench/clump_vs_yade.py (run as: yade -n -j1 -x bench/yade_clumps.py CONFIG).
# The same clumps (member spheres at the same world positions, appended with
# O.bodies.appendClumped: members that do not overlap, so Yade's sums of member masses and
# inertias are exact, as cpp_dem's), the same linear law (FrictMat, CundallStrack), walls as
# zero-thickness boxes (aabbWalls), Cundall local damping, Fincham's rotation leapfrog, the
# same dt and the same wall motion; writes the wall forces and the clumps' centres.
import json
import sys

from yade import utils
from yade.wrapper import *  # noqa: F401,F403

cfg = json.load(open(sys.argv[-1]))
O.materials.append(FrictMat(young=cfg["young"], poisson=cfg["poisson"], density=cfg["density"],
                            frictionAngle=cfg["friction_rad"], label="grains"))
O.materials.append(FrictMat(young=cfg["young"], poisson=cfg["poisson"], density=0,
                            frictionAngle=0, label="walls"))
walls = utils.aabbWalls([tuple(cfg["box_lo"]), tuple(cfg["box_hi"])], thickness=0, material="walls")
wall_ids = O.bodies.append(walls)  # x-, x+, y-, y+, z-, z+ (as cpp_dem's add_box)
clump_ids = []
for members in cfg["clumps"]:
    cid, _ = O.bodies.appendClumped([utils.sphere(tuple(m[:3]), m[3], material="grains")
                                     for m in members])
    clump_ids.append(cid)
newton = NewtonIntegrator(damping=cfg["damping"], gravity=tuple(cfg["gravity"]),
                          exactAsphericalRot=True)
if hasattr(newton, "rotAlgorithm"):
    newton.rotAlgorithm = "Fincham1992"
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb()], verletDist=cfg["verlet"]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Box_Sphere_ScGeom()],
                    [Ip2_FrictMat_FrictMat_FrictPhys()],
                    [Law2_ScGeom_FrictPhys_CundallStrack()]),
    newton,
]
O.dt = cfg["dt"]
top = wall_ids[5]
out = {"mass": [O.bodies[c].state.mass for c in clump_ids],
       "inertia": [sorted(list(O.bodies[c].state.inertia)) for c in clump_ids], "rows": []}
for stage in cfg["stages"]:
    if stage.get("top_position") is not None:
        O.bodies[top].state.pos = (O.bodies[top].state.pos[0], O.bodies[top].state.pos[1],
                                   stage["top_position"])
    O.bodies[top].state.vel = (0, 0, stage["top_velocity"])
    for k in range(stage["records"]):
        O.run(stage["every"], True)
        out["rows"].append({"step": O.iter,
                            "top_force": O.forces.f(top)[2],
                            "bottom_force": O.forces.f(wall_ids[4])[2],
                            "top_position": O.bodies[top].state.pos[2],
                            "centres": [list(O.bodies[c].state.pos) for c in clump_ids],
                            "spins": [list(O.bodies[c].state.angVel) for c in clump_ids]})
if cfg.get("dump_contacts_at"):
    # Debugging aid: the contacts (member ids as cpp_dem numbers them: walls after members).
    O.run(cfg["dump_contacts_at"] - O.iter, True)
    num = {}
    for k, c in enumerate(clump_ids):
        for j, m in enumerate(sorted(O.bodies[c].shape.members.keys())):
            num[m] = 3 * k + j
    out["contacts"] = [[num.get(i.id1, -1 - wall_ids.index(i.id1) if i.id1 in wall_ids else -99),
                        num.get(i.id2, -1 - wall_ids.index(i.id2) if i.id2 in wall_ids else -99),
                        list(i.phys.normalForce), list(i.phys.shearForce)]
                       for i in O.interactions if i.isReal]
print("YADE_RESULT " + json.dumps(out), flush=True)
