#!/usr/bin/env python3
"""05 - Hierarchical FEM x DEM under MPI: the mesh split over ranks, the DEM elements on Dask.

A plane-strain biaxial test of a 0.04 m x 0.08 m sample (P1 triangles, smooth platens, the
right side at a 100 kPa confining pressure, the top pushed down) with a periodic DEM element
at every triangle's quadrature point, each its own packing (seed 1 + k). The same script runs
on one rank or on several: each rank assembles and solves its part of the mesh, and rank 0
holds the Dask client of the element pool (femcoupling.fem.mpi_points). Element k is the same
place, and the same packing, on any number of ranks.

Run:   .venv/bin/python examples/05_hierarchical_mpi.py [--smoke] [--out DIR]
       .venv/bin/mpiexec -n 2 .venv/bin/python examples/05_hierarchical_mpi.py [--smoke]
Needs: dolfinx and mpi4py (`make setup` installs both, and MPICH's mpiexec in .venv/bin).
Writes (in --out): biaxial.csv (per load step: axial strain, the mean stresses, Pa,
compression positive; Newton iterations, status), elements.csv (each element's place, m, and
final stress, Pa, tension positive), biaxial.png, and the model's records: elements.h5,
fem.xdmf (ParaView), steps.csv, report.md.
"""

import argparse
from pathlib import Path

#: Files this script writes in --out (tests/test_examples.py checks them).
OUTPUTS = ["biaxial.csv", "elements.csv", "biaxial.png", "report.md", "elements.h5", "fem.xdmf",
           "steps.csv"]
#: The test that runs this script (on 1 and 2 ranks, under mpiexec), not tests/test_examples.py.
RUN_BY = "tests/test_hierarchical_mpi.py"

ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
ap.add_argument("--smoke", action="store_true", help="8 elements of 60 grains, 1 load step")
ap.add_argument("--out", type=Path, default=Path("results/examples/05_hierarchical_mpi"))
args = ap.parse_args()

from cpp_dem.elements.pool import ElementPool, PeriodicFactory  # noqa: E402
from femcoupling.fem.mpi_points import on_root, world  # noqa: E402
from geogrid_dem.studies.biaxial import fem_dem_biaxial  # noqa: E402


def main(out: Path, smoke: bool) -> None:
    comm = world()
    root = comm.rank == 0
    nx, ny, grains, steps = (2, 2, 60, 1) if smoke else (4, 8, 150, 6)
    factory = PeriodicFactory(n=grains, stress=100e3, seed=1)
    # the pool, and its Dask client, on rank 0 only (None on the others)
    pool = on_root(comm, lambda: ElementPool.build(2 * nx * ny, factory, workers=2))
    try:
        res = fem_dem_biaxial(pool, lx=0.04, ly=0.08, nx=nx, ny=ny, pressure=100e3,
                              strain=0.001 if smoke else 0.01, steps=steps,
                              log=print if root else None, comm=comm, out=out,
                              overwrite=True)
    finally:
        if pool is not None:
            pool.close()
    m = res["model"]
    xy = m.point_coordinates  # (every rank takes part: the points are gathered)
    if not root:
        return
    with open(out / "biaxial.csv", "w") as fh:
        fh.write("axial_strain,sigma_axial_pa,sigma_lateral_pa,iterations,status\n")
        for k, r in enumerate(res["steps"]):
            row = [float(res[c][k]) for c in ("axial_strain", "sigma_axial", "sigma_lateral")]
            fh.write(",".join(map(repr, row)) + f",{r.newton_iterations},{r.status}\n")
    sig = m.history[-1].element_stresses
    with open(out / "elements.csv", "w") as fh:
        fh.write("element,x_m,y_m,sigma_xx_pa,sigma_yy_pa,sigma_xy_pa\n")
        for k in range(m.n_points):
            fh.write(f"{k}," + ",".join(map(repr, [*map(float, xy[k]), *map(float, sig[k])]))
                     + "\n")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(100 * res["axial_strain"], res["sigma_axial"] / 1e3, "o-", label="axial")
    ax.plot(100 * res["axial_strain"], res["sigma_lateral"] / 1e3, "s-", label="lateral")
    ax.set(xlabel="axial strain, %", ylabel="mean element stress, kPa",
           title=f"{m.n_points} DEM elements on {comm.size} MPI rank(s)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "biaxial.png", dpi=120)
    print(f"{m.n_points} elements, {comm.size} rank(s): status {m.status}, peak axial "
          f"{res['peak_sigma_axial'] / 1e3:.1f} kPa; wrote {out}")


if __name__ == "__main__":  # (Dask spawns its workers: the guard is needed)
    from geogrid_dem.warnings_display import shown_once

    with shown_once():  # (one line per kind of warning, then how many more: as the cases)
        main(args.out, args.smoke)
