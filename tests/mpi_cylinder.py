"""The cylindrical triaxial specimen under MPI, run by tests/test_hierarchical_cylinder.py
as ``mpiexec -n N python tests/mpi_cylinder.py OUT [quarter|full [SIZE]]``: linear elastic
elements (the section given, the quarter by default; tetrahedra SIZE m across, 0.025 by
default; exact, so the
ranks' runs can be compared to rounding), one triaxial step. Rank 0 writes OUT/result.json:
the points (m), the element stresses and the specimen's volume-mean stress (Voigt, Pa), the
increments (-)."""

import json
import sys


def main(out: str, section: str = "quarter", size: str = "0.025") -> None:
    from cpp_dem.elements.linear import LinearElement, LinearFactory
    from cpp_dem.elements.pool import ElementPool
    from femcoupling.fem.bodies import Cylinder, cylinder_cells
    from femcoupling.fem.model import FemModel
    from femcoupling.fem.mpi_points import on_root, world

    comm = world()
    n = cylinder_cells(0.025, 0.1, float(size), section)
    pool = on_root(comm, lambda: ElementPool.build(n, LinearFactory(), workers=1,
                                                   element_type=LinearElement))
    try:
        body = Cylinder(radius_m=0.025, height_m=0.1, size_m=float(size), confining_pa=100e3,
                        section=section)
        m = FemModel(body, elements=pool, newton_rtol=1e-10, comm=comm)
        r = m.step(top_displacement=-1e-4)
        xyz, mean = m.point_coordinates, m.volume_mean_stress()  # (collective)
    finally:
        if pool is not None:
            pool.close()
    if comm.rank == 0:
        with open(f"{out}/result.json", "w") as fh:
            json.dump({"points": xyz.tolist(), "stresses": r.element_stresses.tolist(),
                       "increments": r.increments.tolist(), "volume_mean": mean.tolist()},
                      fh)
        print(f"on {comm.size} rank(s): status {r.status}")


if __name__ == "__main__":
    main(*sys.argv[1:4])
