# Yade side of bench/periodic_vs_yade.py (run as: yade -n -j1 -x bench/yade_periodic.py CONFIG).
# The same spheres in the same periodic cell, fresh contacts, the same linear law (FrictMat,
# FrictPhys, CundallStrack: k_n = 2 E1 R1 E2 R2 / (E1 R1 + E2 R2), k_s = poisson k_n), the
# same dt and Cundall local damping (Yade damps the fluctuation velocity in a periodic scene,
# as cpp_dem does), the same constant velocity gradient (Cell.velGrad; the default
# homoDeform, the second-order velocity update of the mean field, is cpp_dem's fluctuation
# scheme to first order). Writes the cell stress (Love-Weber over the cell, computed here from
# the interactions: compression positive, as cpp_dem's Scene.cell_stress), the contact count
# and the cell matrix every `every` steps.
import json
import sys

from yade import utils
from yade.wrapper import *  # noqa: F401,F403

cfg = json.load(open(sys.argv[-1]))
O.periodic = True
h = cfg["hsize"]
O.cell.hSize = Matrix3(h[0][0], h[0][1], h[0][2], h[1][0], h[1][1], h[1][2],
                       h[2][0], h[2][1], h[2][2])
O.materials.append(FrictMat(young=cfg["young"], poisson=cfg["poisson"], density=cfg["density"],
                            frictionAngle=cfg["friction_rad"], label="grains"))
for c, r in zip(cfg["centres"], cfg["radii"]):
    O.bodies.append(utils.sphere(tuple(c), r, material="grains"))
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb()], verletDist=cfg["verlet"]),
    InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_FrictMat_FrictMat_FrictPhys()],
                    [Law2_ScGeom_FrictPhys_CundallStrack()]),
    NewtonIntegrator(damping=cfg["damping"], gravity=(0, 0, 0)),
]
O.dt = cfg["dt"]
L = cfg["velgrad"]
O.cell.velGrad = Matrix3(L[0][0], L[0][1], L[0][2], L[1][0], L[1][1], L[1][2],
                         L[2][0], L[2][1], L[2][2])


def cell_stress():
    hs = O.cell.hSize
    s = [[0.0] * 3 for _ in range(3)]
    n = 0
    for i in O.interactions:
        if not i.isReal:
            continue
        f = i.phys.normalForce + i.phys.shearForce  # on id2
        b1, b2 = O.bodies[i.id1], O.bodies[i.id2]
        l = b2.state.pos + hs * Vector3(*[float(x) for x in i.cellDist]) - b1.state.pos
        for a in range(3):
            for b in range(3):
                s[a][b] += f[a] * l[b]
        n += 1
    v = hs.determinant()
    return [[x / v for x in row] for row in s], n


rows = []
st, n = cell_stress()
rows.append({"step": O.iter, "stress": st, "contacts": n,
             "hsize": [[O.cell.hSize[a, b] for b in range(3)] for a in range(3)]})
# The first step alone: the forces of the shared initial state.
O.run(1, True)
st, n = cell_stress()
rows.append({"step": O.iter, "stress": st, "contacts": n,
             "hsize": [[O.cell.hSize[a, b] for b in range(3)] for a in range(3)]})
import time  # noqa: E402

t0 = time.time()
while O.iter < cfg["steps"]:
    O.run(min(cfg["every"], cfg["steps"] - O.iter), True)
    st, n = cell_stress()
    rows.append({"step": O.iter, "stress": st, "contacts": n,
                 "hsize": [[O.cell.hSize[a, b] for b in range(3)] for a in range(3)]})
out = {"rows": rows, "seconds": time.time() - t0, "homoDeform": O.cell.homoDeform}
print("YADE_RESULT " + json.dumps(out))
