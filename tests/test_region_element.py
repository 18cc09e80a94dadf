"""The periodic region element (femcoupling.materials.dem_elements.PeriodicRegionElement; issue 18):
it takes the FEM region's full stress tensor, shear included; it is prepared once and kept (as
bytes) for the next two-way iterations; a stress beyond its strength is said, not silently missed.
And two_way does not warn about turned principal axes for an element that takes them."""

from __future__ import annotations

import numpy as np
import pytest

from femcoupling.coupling.handover import fem_to_dem
from femcoupling.materials.dem_elements import PeriodicRegionElement

# FEM tensors (tension positive, Pa): an initial K0-like state and a loaded one with shear
INITIAL = np.diag([-25e3, -25e3, -50e3])
FINAL = np.array([[-35e3, 0.0, -8e3], [0.0, -32e3, 0.0], [-8e3, 0.0, -70e3]])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("region")
    el = PeriodicRegionElement(n=100, cache_dir=str(d), tol=0.01)
    a = el("r", fem_to_dem(INITIAL), fem_to_dem(FINAL))
    b = el("r", fem_to_dem(INITIAL), fem_to_dem(FINAL))
    return a, b, d


def test_the_full_tensor_is_reached_shear_included(runs):
    a, _, _ = runs
    assert a.info["full_tensor"] and a.info["reached"]
    np.testing.assert_allclose(a.stress_final_pa, -np.diag(FINAL), rtol=0.02)
    np.testing.assert_allclose(a.stress_initial_pa, -np.diag(INITIAL), rtol=0.02)
    # the shear is imposed (the walls could not): within the servo's tolerance of 70 kPa
    assert a.info["shear_final_pa"][1] == pytest.approx(8e3, abs=0.011 * 70e3)
    assert abs(a.info["shear_final_pa"][0]) < 0.011 * 70e3
    assert a.strain_increment[2] > 0  # shortened along z, compression positive
    assert 0 < np.max(a.info["stress_scatter_pa"]) < 0.5 * 70e3


def test_the_prepared_element_is_kept_between_iterations(runs):
    a, b, d = runs
    assert (d / "r_initial.bin").is_file()
    assert not a.info["prepared_from_cache"] and b.info["prepared_from_cache"]
    # the same start, so the same answer, bitwise
    assert np.array_equal(a.stress_final_pa, b.stress_final_pa)
    assert np.array_equal(a.strain_increment, b.strain_increment)


def test_the_disk_copy_is_taken_only_by_a_runner_with_the_same_settings(runs, tmp_path):
    # A fresh runner (on an earlier run's folder) takes the kept element from cache_dir; one
    # of other grains, seed or material prepares its own (only the tensor was checked before,
    # so a rerun with other grains into the same folder took the old element).
    import shutil

    from cpp_dem.scene import linear_material

    _, _, d = runs
    same = PeriodicRegionElement(n=100, cache_dir=str(d), tol=0.01)
    el, kept = same.prepare("r", fem_to_dem(INITIAL))
    assert kept
    fresh, kept = PeriodicRegionElement(n=100, tol=0.01).prepare("r", fem_to_dem(INITIAL))
    assert not kept and np.array_equal(el.stress(), fresh.stress())
    soft = linear_material(density=2650.0, young=50e6, poisson=0.3, friction_angle_deg=30.0)
    for k, other in enumerate((dict(n=120), dict(seed=2), dict(options={"material": soft}))):
        copy = shutil.copytree(d, tmp_path / str(k))
        runner = PeriodicRegionElement(**{"n": 100, "tol": 0.01, **other}, cache_dir=str(copy))
        assert not runner.prepare("r", fem_to_dem(INITIAL))[1], other


def test_a_stress_beyond_its_strength_is_said(tmp_path):
    el = PeriodicRegionElement(n=100, cache_dir=str(tmp_path), tol=0.01, max_strain=0.01)
    far = np.array([[-10e3, 0.0, -30e3], [0.0, -20e3, 0.0], [-30e3, 0.0, -60e3]])
    r = el("r", fem_to_dem(INITIAL), fem_to_dem(far))
    assert not r.info["reached"]
    assert "cannot carry the FEM stress" in r.info["message"]
    assert np.abs(r.info["strain_increment_tensor"]).max() > 0.01


def test_two_way_takes_a_full_tensor_element_at_its_word():
    from femcoupling.coupling.twoway import check_region

    t = fem_to_dem(np.array([[-100e3, 0, -40e3], [0, -80e3, 0], [-40e3, 0, -150e3]]))
    assert t.rotation_deg > 15
    msgs, _ = check_region("r", t, full_tensor=True)
    assert msgs == []
    msgs, _ = check_region("r", t)
    assert len(msgs) == 1 and "turned" in msgs[0]


def test_the_element_returns_its_tangent_and_the_region_gets_a_full_stiffness(runs):
    """The network tangent at the final state, made to reproduce the increment exactly, is
    the region's stiffness (two_way's default), shear included."""
    from femcoupling.coupling.twoway import element_stiffness
    from femcoupling.materials.continuum import tensor_to_mandel

    a, _, _ = runs
    t = a.info["tangent_voigt_pa"]
    assert t.shape == (6, 6) and np.all(np.isfinite(t))
    _, _, c = element_stiffness(a)
    de = tensor_to_mandel(a.info["strain_increment_tensor"], 6)
    ds = tensor_to_mandel(a.info["stress_increment_tensor"], 6)
    assert np.abs(c @ de - ds).max() < 1e-12 * np.abs(ds).max()
    assert np.linalg.eigvalsh(c).min() > 0
    # the shear increment (xz) is carried by the full stiffness, as the element carried it
    assert (c @ de)[4] == pytest.approx(ds[4], rel=1e-12) and abs(ds[4]) > 1e3
