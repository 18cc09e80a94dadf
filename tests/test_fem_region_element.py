"""The hierarchical mode on the reinforced-soil body (issue 18): a DEM element as the
material of a FemModel element region (the soil body), called at every Newton iterate
(FemModel.set_region_element, femcoupling.materials.dem_elements.DemRegionMaterial)."""

from __future__ import annotations

import numpy as np
import pytest

from femcoupling.materials.continuum import mandel_to_tensor, tensor_to_mandel
from test_fem_handover import _footing, two_region_model
from test_fem_region_tangent import C_TRUE


class LinearStandIn:
    """A linear element with stiffness C_TRUE behind the region-element interface
    (``femcoupling.fem.quadrature.QuadratureMaterial`` of strain measure "tensor"): its
    stress is the committed one plus C_TRUE times the increment."""

    strain_measure = "tensor"
    plastic = np.zeros(1)

    def __init__(self):
        self.commits = 0
        self.stress_n = np.zeros((3, 3))
        self._trial = self.stress_n

    def trial(self, de):
        self._trial = self.stress_n + mandel_to_tensor(C_TRUE @ tensor_to_mandel(de, 6))
        return self._trial, C_TRUE

    def commit(self):
        self.commits += 1
        self.stress_n = self._trial

    def state(self):
        return self.stress_n.copy()

    def set_state(self, data):
        self.stress_n = self._trial = np.array(data, float)


def test_a_linear_region_element_is_the_same_as_its_material():
    """The region's points take the element's answer for the region's mean strain plus its
    tangent times their deviation from it: for a linear element that is exactly the material
    with its stiffness (the displacements agree to Newton's tolerance), and Newton converges
    as it does with the material (the formulation's Jacobian is consistent)."""
    from femcoupling.materials.continuum import AnisotropicElastic

    a = two_region_model(("a",))
    a.set_region_material("a", AnisotropicElastic(C_TRUE))
    ra = a.load_footing(pressure_pa=100e3, steps=2)
    b = two_region_model(("a",))
    el = LinearStandIn()
    b.set_region_element("a", el)
    rb = b.load_footing(pressure_pa=100e3, steps=2)
    assert [r.newton_iterations for r in rb] == [r.newton_iterations for r in ra]
    assert el.commits == 2
    u = np.abs(a.u.x.array).max()
    assert np.abs(a.u.x.array - b.u.x.array).max() < 1e-7 * u
    np.testing.assert_allclose(b.region_stress("a"), a.region_stress("a"), rtol=0,
                               atol=1e-7 * np.abs(a.region_stress("a")).max())


def test_region_element_needs_the_interface():
    from femcoupling import FemInputError

    m = two_region_model(("a",))
    with pytest.raises(FemInputError, match="needs a trial"):
        m.set_region_element("a", object())
    with pytest.raises(FemInputError, match="region='b'"):
        m.set_region_element("b", LinearStandIn())


def test_a_dem_region_element_strains_as_its_region_and_carries_its_stress(tmp_path):
    """A dense periodic element of 150 grains as region a's material under a 20 kPa footing
    (elastic soil around it): it strains as the region does (it is given the region's mean
    strain; measured 7e-4 relative), the region's mean stress increment is the element's
    (to round-off); Newton's residual stalls at the element's resolution (measured 5.0e-6
    and 5.1e-6 of the force scale after 8 and 10 iterations, against newton_rtol 1e-8, within
    the noise measured at the scale of Newton's corrections), and the step is taken there,
    stopped_at_scatter, and said; the same run again is bitwise the same (a rejected
    iterate leaves no trace)."""
    from femcoupling.materials.dem_elements import DemRegionMaterial, PeriodicRegionElement

    def run(records=None):
        m = two_region_model(("a",))
        s0, e0 = m.region_stress("a"), m.region_strain("a")
        mat = DemRegionMaterial.prepared("a", s0, PeriodicRegionElement(
            n=150, seed=3, tol=0.02, unbalanced=1e-2), records=records)
        start = mat.element.stress()
        m.set_region_element("a", mat)
        steps = m.load_footing(pressure_pa=20e3, steps=2)
        return m, mat, s0, e0, start, steps

    m, mat, s0, e0, start, steps = run(tmp_path / "el.h5")
    idx = ([0, 2, 0], [0, 2, 2])  # xx, zz, xz: the plane-strain components
    fem = m.region_strain("a") - e0
    dem = mat.strain_since_start()
    assert np.abs(dem[idx] - fem[idx]).max() < 0.01 * np.abs(fem[idx]).max()
    ds_fem = m.region_stress("a") - s0
    ds_dem = mat.element.stress() - start
    assert np.abs(ds_fem[idx] - ds_dem[idx]).max() < 1e-9 * np.abs(ds_fem).max()
    assert np.abs(ds_fem).max() > 1e3  # (the footing did load the region: Pa)
    assert all(r.converged_on in ("tolerance", "noise") for r in steps)
    assert all(r.newton_iterations <= 15 for r in steps)
    # a step taken within the elements' noise: its residual within 2 x that noise (both on
    # the body's scale here) and the ceiling (on the region's)
    for r in steps:
        if r.converged_on == "noise":
            assert r.status == "stopped_at_scatter" and r.residual <= m.noise_ceiling
            assert r.noise_residual > 0
    assert sum(r.converged_on == "noise" for r in steps) == len(m.warnings)
    m2, *_ = run()
    assert np.array_equal(m.u.x.array, m2.u.x.array)
    import h5py

    with h5py.File(tmp_path / "el.h5") as f:  # a row per committed step, flushed
        assert f["step"][:].tolist() == [1, 2]
        assert np.array_equal(f["stress_pa"][-1], mat.element.stress())
        assert np.all(np.linalg.eigvalsh(f["tangent_mandel_pa"][:]) > 0)


def test_region_elements_on_dask_workers_give_the_same_run_bitwise():
    """Two regions' elements (100 grains each) on a 2-worker Dask pool
    (PoolRegionMaterials, evaluated at once at every iterate) give bitwise the run that the
    same elements in this process give, one after the other; save_state/restore_state carry
    the workers' elements (the restored run repeats bitwise)."""
    from femcoupling.materials.dem_elements import (DemRegionMaterial, PeriodicRegionElement,
                                                    PoolRegionMaterials)

    runner = PeriodicRegionElement(n=100, seed=5, tol=0.02, unbalanced=1e-2)

    def body():
        m = two_region_model()
        return m, {r: m.region_stress(r) for r in ("a", "b")}

    m1, s1 = body()
    for r, s in s1.items():
        m1.set_region_element(r, DemRegionMaterial.prepared(r, s, runner))
    m1.load_footing(pressure_pa=20e3, steps=1)
    m2, s2 = body()
    group = PoolRegionMaterials.build(s2, runner, workers=2)
    try:
        assert len(group.pool.workers()) == 2
        for r, mat in group.materials.items():
            m2.set_region_element(r, mat)
        start = m2.save_state()  # (the elements' states with it)
        m2.load_footing(pressure_pa=20e3, steps=1)
        first = m2.u.x.array.copy()
        m2.restore_state(start)
        m2.load_footing(pressure_pa=20e3, steps=1)
        assert np.array_equal(m2.u.x.array, first)  # restored elements: the same run
    finally:
        group.close()
    assert group.calls > 0
    assert np.array_equal(m1.u.x.array, m2.u.x.array)
    assert [r.newton_iterations for r in m1.history] == \
        [r.newton_iterations for r in m2.history]


def _cells_model(fine_m: float):
    """The test body's region a alone, meshed at ``fine_m`` there (P1: one quadrature point
    per cell)."""
    from femcoupling.fem.geometry import ElementRegion, ReinforcedSoilBody
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import LinearElastic

    body = ReinforcedSoilBody(width_m=4.0, height_m=3.0, footing_half_width_m=0.5,
                              regions=(ElementRegion("a", (0.25, 2.7), 0.2),),
                              mesh_size_m=0.6, fine_size_m=fine_m)
    m = FemModel(body, soil=LinearElastic(50e6, 0.3), unit_weight_n_m3=18e3, degree=1)
    m.set_geostatic()
    return m


def test_an_element_per_cell_of_a_linear_stand_in_is_the_material():
    """set_cell_elements: every cell of region a its own element (here a linear stand-in per
    cell): exactly the material with that stiffness, Newton converging as with it."""
    from types import SimpleNamespace

    from femcoupling import FemInputError
    from femcoupling.materials.continuum import AnisotropicElastic

    a = _cells_model(0.1)
    a.set_region_material("a", AnisotropicElastic(C_TRUE))
    ra = a.load_footing(pressure_pa=100e3, steps=2)
    b = _cells_model(0.1)
    keys = list(b.cell_stresses("a"))
    members = {k: LinearStandIn() for k in keys}
    assert b.set_cell_elements("a", SimpleNamespace(materials=members)) == keys
    rb = b.load_footing(pressure_pa=100e3, steps=2)
    assert len(keys) > 5 and all(el.commits == 2 for el in members.values())
    assert [r.newton_iterations for r in rb] == [r.newton_iterations for r in ra]
    u = np.abs(a.u.x.array).max()
    assert np.abs(a.u.x.array - b.u.x.array).max() < 1e-7 * u
    with pytest.raises(FemInputError, match="needs an element .* for every cell of region"):
        _cells_model(0.1).set_cell_elements("a", SimpleNamespace(materials={}))


def test_an_element_per_cell_on_dask_workers(tmp_path):
    """A dense periodic element (100 grains, distinct seeds) for every cell of region a, all
    on a 2-worker pool, under a 20 kPa footing: every element strains as its cell (their
    volume mean is the region's strain increment, measured to round-off), the cells strain
    differently under the footing (the field inside the region is resolved: measured zz
    -3.1e-4 to -5.7e-4 over 14 cells), the region's stress increment is the elements' volume
    mean, the step converges (at a stall, said), and the records hold a row per element."""
    import h5py

    from femcoupling.materials.dem_elements import PeriodicRegionElement, PoolRegionMaterials

    m = _cells_model(0.15)
    stresses = m.cell_stresses("a")
    group = PoolRegionMaterials.build(
        stresses, PeriodicRegionElement(n=100, seed=3, tol=0.02, unbalanced=1e-2), workers=2,
        distinct_seeds=True, records=tmp_path / "cells.h5")
    try:
        m.set_cell_elements("a", group)
        s0, e0 = m.region_stress("a"), m.region_strain("a")
        start = np.array(group.stresses())  # (within the servo's tol of the cells' stresses)
        steps = m.load_footing(pressure_pa=20e3, steps=1)
    finally:
        group.close()
    assert all(r.converged_on in ("tolerance", "noise") for r in steps)
    assert sum(r.converged_on == "noise" for r in steps) == len(m.warnings)
    with h5py.File(tmp_path / "cells.h5") as f:
        assert list(f.attrs["names"]) == list(stresses)
        assert f["step"][:].tolist() == [1] * len(stresses)
        strain, stress = f["strain"][:], f["stress_pa"][:]
    cells = [int(k.rsplit("/", 1)[1]) for k in stresses]
    w = m.cell_volume[cells] / m.cell_volume[cells].sum()
    idx = ([0, 2, 0], [0, 2, 2])  # xx, zz, xz: the plane-strain components
    fem = m.region_strain("a") - e0
    mean_el = np.einsum("k,kij->ij", w, strain)
    assert np.abs(mean_el[idx] - fem[idx]).max() < 1e-6 * np.abs(fem[idx]).max()
    zz = strain[:, 2, 2]
    assert zz.max() - zz.min() > 0.2 * abs(zz.mean())  # not one strain for all
    ds_el = np.einsum("k,kij->ij", w, stress - start)
    ds_fem = m.region_stress("a") - s0
    assert np.abs(ds_fem[idx] - ds_el[idx]).max() < 1e-6 * np.abs(ds_fem).max()


def test_a_band_member_on_the_pool_answers_as_its_element_alone():
    """PoolRegionMaterials.build(band=): a reinforced RVE of a band cell beside a soil
    element on one Dask worker. Its trial is the element run alone (bitwise), its stress in
    the band's scale, its tangent its network's with the sheet's bonds; with
    ``band_tangent="fd-forward"`` the forward differences of the components asked (the others
    filled by symmetry). The soil element's tangent is its network's."""
    from cpp_dem.elements.periodic import DemElement
    from femcoupling.materials.dem_elements import (PeriodicRegionElement, PoolRegionMaterials,
                                                    ReinforcedBandElement, network_stiffness)

    runner = PeriodicRegionElement(n=40, seed=3, tol=0.02, unbalanced=1e-2)
    band = ReinforcedBandElement(n=50, seed=11, band_thickness_m=0.02)
    s0 = -12e3 * np.eye(3)
    group = PoolRegionMaterials.build({"zone/0": s0}, runner, workers=1,
                                      band=(band, {"zone-geogrid/1": (12e3, 400.0)}),
                                      fd_components=(0, 2, 4))
    try:
        assert group.names == ["zone/0", "zone-geogrid/1"]
        de = np.zeros((3, 3))
        de[0, 0], de[2, 2], de[0, 2] = 5e-5, -1e-4, 2e-5
        got = group.trial_many({"zone/0": de, "zone-geogrid/1": de})
        alone = band.element(12e3, 400.0, seed=11)
        assert alone.band_thickness == 0.02
        before = alone.stress()
        from cpp_dem.elements.reinforced import sheet_tension_per_metre

        sheet = sheet_tension_per_metre(alone.scene)[0]  # (N/m, as prepared)
        after = alone.apply_strain(de)
        total, tangent = got["zone-geogrid/1"]
        assert np.array_equal(total, after)
        member = group.materials["zone-geogrid/1"]
        assert np.array_equal(member.stress_n, before)  # (its increment: total - stress_n)
        net = alone.network_tangent()[0]
        assert np.array_equal(group._filled(net), net)  # (a whole tangent stays)
        assert np.array_equal(tangent, network_stiffness(None, 1e-3, voigt=net))
        fd = alone.fd_tangent(components=(0, 2, 4), central=False)
        assert np.isnan(fd[:, 1]).all() and not np.isnan(fd[:, [0, 2, 4]]).any()
        whole = group._filled(fd)
        assert not np.isnan(whole).any()
        assert np.array_equal(whole[:, [0, 2, 4]], fd[:, [0, 2, 4]])
        assert whole[0, 1] == fd[1, 0] and whole[3, 3] == np.mean(np.diag(fd)[[0, 2, 4]])
        group.band_tangent = "fd-forward"  # (the same trial again, from the step's start)
        both = group.trial_many({"zone/0": de, "zone-geogrid/1": de})
        again = both["zone-geogrid/1"]
        assert np.array_equal(both["zone/0"][1], got["zone/0"][1])  # (the soil's: network)
        assert np.array_equal(again[0], total)
        assert np.array_equal(again[1], network_stiffness(None, 1e-3, voigt=whole))
        group.band_tangent = "network"
        with pytest.raises(ValueError, match="band_tangent='fd': 'network', "):
            PoolRegionMaterials(group.pool, group.names, band_tangent="fd")
        soil = DemElement.from_bytes(group.pool.states()[0])
        soil.apply_strain(de)
        assert np.array_equal(got["zone/0"][1], network_stiffness(soil, 1e-3))
        # the footing's record of the band's sheets: the band members' committed states
        from geogrid_dem.studies.footing_multiscale import band_sheet_tensions

        assert band_sheet_tensions(group, 1) == [sheet]
    finally:
        group.close()
