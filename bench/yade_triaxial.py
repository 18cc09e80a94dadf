# Yade side of bench/triaxial_bench.py (run as: yade -n -jT -x bench/yade_triaxial.py CONFIG).
# Same packing (CSV x,y,z,r), same linear law, frictionless walls as Yade's aabbWalls, the
# TriaxialStressController of 001 App. B: isotropic stage to the cell pressure, then axial (z)
# compression at a constant strain rate with x and y held; the deviatoric steps are timed.
import json
import sys
import time

from yade import utils
from yade.wrapper import *  # noqa: F401,F403  (Yade's engines live in this namespace)

cfg = json.load(open(sys.argv[-1]))
O.materials.append(FrictMat(young=cfg["young"], poisson=cfg["poisson"], density=cfg["density"],
                            frictionAngle=cfg["friction_rad"], label="grains"))
O.materials.append(FrictMat(young=cfg["young"], poisson=cfg["poisson"], density=0,
                            frictionAngle=0, label="walls"))
lo, hi = cfg["box_lo"], cfg["box_hi"]
walls = utils.aabbWalls([tuple(lo), tuple(hi)], thickness=0, material="walls")
O.bodies.append(walls)
with open(cfg["packing"]) as fh:
    fh.readline()
    for line in fh:
        x, y, z, r = (float(v) for v in line.split(","))
        O.bodies.append(utils.sphere((x, y, z), r, material="grains"))
n = len(O.bodies) - 6
triax = TriaxialStressController(thickness=0, stressMask=7, internalCompaction=False,
                                 max_vel=cfg["max_vel"])
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Box_Aabb()], verletDist=cfg["verlet"]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Box_Sphere_ScGeom()],
                    [Ip2_FrictMat_FrictMat_FrictPhys()],
                    [Law2_ScGeom_FrictPhys_CundallStrack()]),
    triax,
    NewtonIntegrator(damping=cfg["damping"], gravity=(0, 0, 0)),
]
O.dt = cfg["dt"]
p = cfg["pressure"]
triax.goal1 = triax.goal2 = triax.goal3 = -p
iso_steps = 0
while iso_steps < cfg["max_iso_steps"]:
    O.run(500, True)
    iso_steps += 500
    if (utils.unbalancedForce() < 0.01 and abs(-p - triax.meanStress) / p < 0.01):
        break
# Deviatoric: x and y stress-controlled (mask 1 + 2), z at the strain rate (compression < 0).
triax.stressMask = 3
triax.goal1 = triax.goal2 = -p
triax.goal3 = -cfg["strain_rate"]
O.run(cfg["warmup"], True)
t0 = time.perf_counter()
O.run(cfg["steps"], True)
el = time.perf_counter() - t0
out = {"yade_n": n, "yade_steps": cfg["steps"], "yade_wall_s": el,
       "yade_particle_steps_per_s": n * cfg["steps"] / el, "yade_iso_steps": iso_steps,
       "yade_sigma": [-triax.stress(triax.wall_left_id)[0],
                      -triax.stress(triax.wall_bottom_id)[1],
                      -triax.stress(triax.wall_back_id)[2]],
       "yade_contacts": sum(1 for i in O.interactions if i.isReal)}
print("YADE_RESULT " + json.dumps(out), flush=True)
