"""A 3D hierarchical triaxial step under MPI, run by tests/test_hierarchical_mpi.py as
``mpiexec -n N python tests/mpi_hierarchical3d.py OUT``: one hexahedron of 6 tetrahedra, each
with a periodic element of 40 grains (its own packing), two load steps. Rank 0 saves the
points (m) and the element stresses (Pa) in OUT/points.npy and OUT/stresses.npy and prints
the status."""

import sys

import numpy as np


def main(out: str) -> None:
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from femcoupling.fem.bodies import Box
    from femcoupling.fem.model import FemModel
    from femcoupling.fem.mpi_points import on_root, world

    comm = world()
    pool = on_root(comm, lambda: ElementPool.build(6, PeriodicFactory(n=40, seed=3),
                                                   workers=1))
    try:
        body = Box(lx=0.02, ly=0.02, lz=0.02, nx=1, ny=1, nz=1, confining_pa=100e3)
        m = FemModel(body, elements=pool, comm=comm, out=out, overwrite=True)
        m.step(top_displacement=-1e-5)  # (two steps: the records appended under MPI)
        r = m.step(top_displacement=-2e-5)
        xyz = m.point_coordinates  # (collective)
    finally:
        if pool is not None:
            pool.close()
    if comm.rank == 0:
        np.save(f"{out}/points.npy", xyz)
        np.save(f"{out}/stresses.npy", r.element_stresses)
        print(f"status {m.status} on {comm.size} rank(s)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
