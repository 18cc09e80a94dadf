"""The reinforced-soil body in 3D with DEM elements (issue 38; docs/coupling_dem_elements.md,
"The reinforced-soil body in 3D with elements"): a footing on a body of tetrahedra with a
prestressed geogrid layer, and a DEM element at every cell of a cube under the footing, across
the layer.

The same code path as in plane strain (FemModel.set_cell_elements), with every strain
component: verified first with linear stand-ins, which must be exactly the material of their
stiffness, then run with dense periodic elements on Dask."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from test_fem_region_element import LinearStandIn
from test_fem_region_tangent import C_TRUE

pytest.importorskip("dolfinx_solver")


def _body_3d(fine_m: float):
    from femcoupling.fem.geometry import ElementRegion, GeogridLayer, ReinforcedSoilBody
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import DruckerPrager, GeogridLayerMaterial

    body = ReinforcedSoilBody(
        width_m=1.5, height_m=1.0, footing_half_width_m=0.25, dim=3, length_m=0.3,
        layers=(GeogridLayer(z_m=0.9, x_min_m=0.0, x_max_m=1.0, thickness_m=0.02),),
        regions=(ElementRegion("zone", (0.1, 0.15, 0.85), 0.2),),
        mesh_size_m=0.3, fine_size_m=fine_m)
    m = FemModel(body, soil=DruckerPrager(young_pa=20e6, poisson=0.3, cohesion_pa=2e3,
                                           friction_deg=35.0),
                  layers=[GeogridLayerMaterial(500e3, prestress_n_per_m=2e3)],
                  unit_weight_n_m3=18e3, degree=1)
    m.set_geostatic()
    m.apply_prestress(steps=1)
    m.load_footing_to_pressure(10e3, steps=1)
    return m


def test_3d_cell_elements_of_a_linear_stand_in_are_the_material():
    """An element per cell of the zone, each a linear stand-in of stiffness C_TRUE (6 x 6,
    transversely isotropic): the body is the one whose zone has that material, to Newton's
    tolerance, in the same Newton iterations. A wrong component order, weight or sign of
    the 3D strains (yy, yz, xy included) would break it."""
    from femcoupling.materials.continuum import AnisotropicElastic

    a = _body_3d(0.1)
    a.set_region_material("zone", AnisotropicElastic(C_TRUE))
    ra = a.load_footing(pressure_pa=40e3, steps=2)
    b = _body_3d(0.1)
    keys = list(b.cell_stresses("zone"))
    members = {k: LinearStandIn() for k in keys}
    assert b.set_cell_elements("zone", SimpleNamespace(materials=members)) == keys
    rb = b.load_footing(pressure_pa=40e3, steps=2)
    assert len(keys) > 50 and all(el.commits == 2 for el in members.values())
    assert [r.newton_iterations for r in rb] == [r.newton_iterations for r in ra]
    u = np.abs(a.u.x.array).max()
    assert np.abs(a.u.x.array - b.u.x.array).max() < 1e-7 * u
    # 3D: the cells strain out of the x-z plane too
    e = b.region_strain("zone")
    assert abs(e[1, 1]) > 0.05 * np.abs(e).max()  # (measured 0.17)


def test_3d_cell_elements_on_dask_workers(tmp_path):
    """A dense periodic element (60 grains of the footing case's material, distinct seeds)
    at every cell of the zone, on a 2-worker pool, the footing from 10 to 20 kPa in one step. The
    step is accepted (converged, or stopped within the elements' scatter: said); every
    element strains as its cell (their volume mean is the zone's strain increment, all six
    components, to round-off); the cells strain differently (measured zz -2.5e-4 to
    -8.8e-4 over the 36 cells); some strain along y; the zone's stress increment is
    the elements' volume mean; the records hold a row per element."""
    import h5py

    from femcoupling.materials.dem_elements import PeriodicRegionElement, PoolRegionMaterials
    from geogrid_dem.studies.footing_multiscale import FootingParams, grain_options

    m = _body_3d(0.2)
    stresses = m.cell_stresses("zone")
    group = PoolRegionMaterials.build(
        stresses, PeriodicRegionElement(n=60, seed=3, tol=0.02, unbalanced=1e-2,
                                        options=grain_options(FootingParams())),
        workers=2, distinct_seeds=True, records=tmp_path / "cells.h5")
    try:
        m.set_cell_elements("zone", group)
        s0, e0 = m.region_stress("zone"), m.region_strain("zone")
        start = np.array(group.stresses())
        steps = m.load_footing(pressure_pa=20e3, steps=1)
    finally:
        group.close()
    assert len(stresses) > 20
    assert all(r.converged_on in ("tolerance", "noise") for r in steps)
    assert sum(r.converged_on == "noise" for r in steps) == len(m.warnings)
    with h5py.File(tmp_path / "cells.h5") as f:
        assert list(f.attrs["names"]) == list(stresses)
        assert f["step"][:].tolist() == [len(steps)] * len(stresses)
        strain, stress = f["strain"][:], f["stress_pa"][:]
    cells = [int(k.rsplit("/", 1)[1]) for k in stresses]
    w = m.cell_volume[cells] / m.cell_volume[cells].sum()
    fem = m.region_strain("zone") - e0
    mean_el = np.einsum("k,kij->ij", w, strain)
    assert np.abs(mean_el - fem).max() < 1e-6 * np.abs(fem).max()
    zz = strain[:, 2, 2]
    assert zz.max() - zz.min() > 0.2 * abs(zz.mean())  # not one strain for all
    # out of the x-z plane: the y faces are rollers, the cells inside strain along y too
    # (measured: 0.068 of the largest zz)
    assert np.abs(strain[:, 1, 1]).max() > 0.02 * np.abs(zz).max()
    ds_el = np.einsum("k,kij->ij", w, stress - start)
    ds_fem = m.region_stress("zone") - s0
    assert np.abs(ds_fem - ds_el).max() < 1e-6 * np.abs(ds_fem).max()
    assert ds_fem[2, 2] < 0  # the footing's load compresses the zone vertically
