"""The reinforced soil body (``femcoupling.fem.model.FemModel`` (the soil body)) under MPI, run by
tests/test_soil_body_mpi.py as ``mpiexec -n N python tests/mpi_soil_body.py OUT [LU]`` (LU: the
package on one rank, femcoupling.fem.quadrature.SERIAL_LU; PETSc's own by default).

A Drucker-Prager soil (max_newton=60; a Newton that makes no progress over four iterations
halves its next correction, femcoupling.fem.quadrature.CYCLE_WINDOW, so no step is cut and every rank
count and LU takes the same steps) with its self-weight, a prestressed geogrid layer and two element
regions (b across the layer):
geostatic stress, prestress (2 steps), a footing pressure of 100 kPa (4 steps), then a
settlement of 10 mm (4 steps). Rank 0 writes OUT/result.json: each step's settlement (m),
pressure (Pa), Newton iterations, status and residual (Pa), and at the end the plastic points,
the region's stress (Pa), the layer's force (N/m) and the stress at a point (Pa); after the
prestress, region b's cells and band cells by their keys (``cell_stresses``, ``band_cells``,
``band_cell_states``); and whether every rank returned the same values
(``same_on_every_rank``)."""

import json
import sys


def main(out: str, lu: str | None = None) -> None:
    from femcoupling.fem.geometry import ElementRegion, GeogridLayer, ReinforcedSoilBody
    from femcoupling.fem.mpi_points import world
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import DruckerPrager, GeogridLayerMaterial

    if lu is not None:  # (the LU on one rank: SERIAL_LU, PETSc's own by default)
        import femcoupling.fem.quadrature as quadrature

        quadrature.SERIAL_LU = lu
    comm = world()
    body = ReinforcedSoilBody(
        width_m=3.0, height_m=2.0, footing_half_width_m=0.5,
        layers=(GeogridLayer(z_m=1.7, x_min_m=0.0, x_max_m=2.0, thickness_m=0.02),),
        regions=(ElementRegion("el", (0.3, 1.5), 0.2), ElementRegion("b", (0.3, 1.7), 0.2)),
        mesh_size_m=0.4, fine_size_m=0.05, fine_radius_m=0.3)
    m = FemModel(body, soil=DruckerPrager(young_pa=30e6, poisson=0.3, cohesion_pa=2e3,
                                           friction_deg=35.0),
                  layers=[GeogridLayerMaterial(500e3, prestress_n_per_m=10e3)],
                  unit_weight_n_m3=18e3, max_newton=60, comm=comm)
    m.set_geostatic()
    steps = m.apply_prestress(steps=2)
    # the cells of region b and of the layer's band in it, by the serial model's keys
    cells = {"cell_stresses": {k: v.tolist() for k, v in m.cell_stresses("b").items()},
             "band_cells": m.band_cells("b"), "band_cell_states": m.band_cell_states("b", 0.05)}
    steps += m.load_footing(pressure_pa=100e3, steps=4)
    steps += m.load_footing(settlement_m=0.01, steps=4)
    res = {"ranks": comm.size,
           "settlement_m": [r.footing_settlement_m for r in steps],
           "pressure_pa": [r.footing_pressure_pa for r in steps],
           "newton": [r.newton_iterations for r in steps],
           "status": [r.status for r in steps],
           "residual_pa": [r.residual_pa for r in steps],
           "plastic_points": m.plastic_points(),
           "region_stress_pa": m.region_stress("el").tolist(),
           "layer_force_n_per_m": m.layer_force_n_per_m(0),
           "point_stress_pa": m.point_stress([[0.0, 1.0]])[0].tolist(), **cells}
    every = comm.gather(res, root=0)
    if comm.rank == 0:
        res["same_on_every_rank"] = all(r == res for r in every)
        with open(f"{out}/result.json", "w") as fh:
            json.dump(res, fh)
        print(f"on {comm.size} rank(s): {len(steps)} steps, settlement "
              f"{res['settlement_m'][-1]:.6g} m")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None)
