#!/usr/bin/env python3
"""p–e curves: a periodic cube against the core of a box of six walls (issue 17).

For each seed, N spheres (the same PSD and linear law) are prepared to 50 kPa both ways
(``DemElement.periodic``: growth in the cell and the isotropic cell servo; ``DemElement.box``:
growth in the box and servo walls; the same slow growth for both), then taken isotropically
to 100, 200 and 400 kPa. The
void ratio of the periodic cube is the cell's; the box's is measured in its core (inset 4
mean radii from every wall: the wall layers are looser). Prints a table of e per stress,
kind and seed, and the mean difference against the seeds' scatter.

    .venv/bin/python bench/periodic_pe.py 2000            # growth (0.1, 1e-4)
    .venv/bin/python bench/periodic_pe.py 2000 0.5 1e-3   # the default growth
"""
import sys, time

import numpy as np

import cpp_dem as dem  # noqa: F401
from cpp_dem.elements.periodic import DemElement
from cpp_dem import measure
from cpp_dem.protocols import prep
from cpp_dem.protocols import periodic
n = int(sys.argv[1]) if len(sys.argv) > 1 else 400
# RadiusGrowth (gain, max strain per call), the same for both: slow, since a box feels the
# stress only at its walls and fast growth overshoots (core e 0.695 at (0.5, 1e-3), 0.725 at
# (0.5, 1e-4), 0.760 at (0.1, 1e-4) for N = 2000, seed 1; the cell 0.767).
GROWTH = (0.1, 1e-4) if len(sys.argv) < 3 else (float(sys.argv[2]), float(sys.argv[3]))
P = [50e3, 100e3, 200e3, 400e3]
out = {}
for seed in (1, 2, 3):
    for kind in ("periodic", "box"):
        t=time.time()
        el = (DemElement.periodic if kind == "periodic" else DemElement.box)(
            n, stress=P[0], seed=seed, growth=GROWTH)
        es = []
        for p in P:
            el.apply_stress(-p*np.eye(3), components=((0,0),(1,1),(2,2)), unbalanced=1e-3)
            s = el.scene
            if kind == "periodic":
                por = measure.porosity(s, ())
            else:
                wp = np.asarray(s.wall_positions)
                lo, hi = wp[[0,2,4]], wp[[1,3,5]]
                ins = 4*np.mean(s.radii)
                x = np.asarray(s.positions); r = np.asarray(s.radii)
                m = np.all((x >= lo+ins) & (x < hi-ins), axis=1)
                por = 1 - np.sum(4/3*np.pi*r[m]**3)/np.prod(hi-lo-2*ins)
                por_all = measure.porosity(s, el.walls)
            es.append(por/(1-por))
        out[(seed, kind)] = es
        print(seed, kind, np.round(es, 4), f"{time.time()-t:.1f}s", flush=True)

for k, p in enumerate(P):
    per = [out[(sd, "periodic")][k] for sd in (1, 2, 3)]
    box = [out[(sd, "box")][k] for sd in (1, 2, 3)]
    print(f"p {p / 1e3:.0f} kPa: periodic e {np.mean(per):.4f} +- {np.std(per):.4f}, box core "
          f"e {np.mean(box):.4f} +- {np.std(box):.4f}, difference {np.mean(per) - np.mean(box):+.4f}")
