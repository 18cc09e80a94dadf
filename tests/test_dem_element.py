"""DemElement (docs/periodic.md): exact strain increments, stress, save/restore/continue,
the wall-bounded kind's limits, the p–e curve against a wall-bounded sample, and the two
tangents against each other in the elastic range."""

from __future__ import annotations

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import DemElement, measure
from cpp_dem.dem_element import VOIGT, voigt_strain


@pytest.fixture(scope="module")
def element_blob():
    return DemElement.periodic(300, stress=100e3, seed=1).to_bytes()


def test_strain_increment_is_exact_and_the_stress_balanced(element_blob):
    el = DemElement.from_bytes(element_blob)
    f0 = np.asarray(el.scene.cell_matrix)
    de = np.array([[1e-4, 0, 3e-4], [0, 0, 0], [-1e-4, 0, -2e-4]])  # shear + rotation
    s = el.apply_strain(de)
    f = np.asarray(el.scene.cell_matrix) @ np.linalg.inv(f0)
    assert np.allclose(f, np.eye(3) + de, rtol=0, atol=1e-12)
    assert el.last_report.relaxed
    assert el.stress_asymmetry() < 1e-3
    assert np.allclose(s, s.T)
    assert s[0, 2] < 0 or s[0, 2] > 0  # a shear stress developed (tension positive)
    assert np.trace(s) < 0  # still compressed


def test_save_restore_continue_is_bitwise(element_blob):
    de = np.zeros((3, 3))
    de[0, 1] = 2e-4
    a = DemElement.from_bytes(element_blob)
    a.apply_strain(de)
    a.apply_strain(de)
    b = DemElement.from_bytes(element_blob)
    b.apply_strain(de)
    c = DemElement.from_bytes(b.to_bytes())  # moved to "another process" mid-way
    c.apply_strain(de)
    assert np.array_equal(a.stress(), c.stress())
    assert np.array_equal(np.asarray(a.scene.positions), np.asarray(c.scene.positions))
    assert a.scene.step_count == c.scene.step_count


def test_rollback_restores_the_increment_start(element_blob):
    el = DemElement.from_bytes(element_blob)
    start = el.to_bytes()
    s0 = el.stress()
    el.apply_strain(np.diag([0.0, 0.0, -1e-3]))
    assert not np.allclose(el.stress(), s0)
    el = DemElement.from_bytes(start)  # a rejected Newton iteration
    assert np.array_equal(el.stress(), s0)


def test_stress_control_of_the_element(element_blob):
    el = DemElement.from_bytes(element_blob)
    target = -np.diag([80e3, 100e3, 150e3])
    s = el.apply_stress(target)
    assert np.allclose(np.diag(s), np.diag(target), rtol=0.006)
    assert abs(s[0, 1]) < 0.01 * 150e3 and abs(s[0, 2]) < 0.01 * 150e3


def test_bad_input_names_the_field(element_blob):
    el = DemElement.from_bytes(element_blob)
    with pytest.raises(dem.ParameterError, match="de"):
        el.apply_strain(np.zeros((2, 2)))
    with pytest.raises(dem.ParameterError, match="positive determinant"):
        el.apply_strain(-2 * np.eye(3))
    with pytest.raises(dem.ParameterError, match="not a saved DemElement"):
        DemElement.from_bytes(b"junk")
    with pytest.raises(dem.ParameterError, match="h="):
        el.fd_tangent(h=0)


def test_box_element_takes_normal_strains_only():
    el = DemElement.box(250, stress=100e3, seed=2)
    s0 = el.stress()
    s = el.apply_strain(np.diag([0, 0, -5e-4]))
    assert s[2, 2] < s0[2, 2]  # more compression along z (tension positive)
    de = np.zeros((3, 3))
    de[0, 2] = 1e-4
    with pytest.raises(dem.ParameterError, match="normal strains only"):
        el.apply_strain(de)
    with pytest.raises(dem.ParameterError, match="periodic element"):
        el.network_tangent()
    c = el.clone()
    assert np.array_equal(c.stress(), el.stress())


def test_p_e_curve_follows_the_wall_bounded_sample():
    # Isotropic compression 50 -> 200 kPa: the periodic cube's void ratio against the core of
    # a box of six walls (away from the wall layers), 2 seeds each, both grown slowly alike
    # (fast growth over-compacts the box, whose walls feel the stress late); the difference
    # of the means is within the seed scatter (docs/periodic.md has a larger run).
    def core_void_ratio(el):
        s = el.scene
        wp = np.asarray(s.wall_positions)
        lo, hi = wp[[0, 2, 4]], wp[[1, 3, 5]]
        inset = 4 * float(np.mean(s.radii))
        x, r = np.asarray(s.positions), np.asarray(s.radii)
        inside = np.all((x >= lo + inset) & (x < hi - inset), axis=1)
        n = 1 - np.sum(4 / 3 * np.pi * r[inside] ** 3) / np.prod(hi - lo - 2 * inset)
        return n / (1 - n)

    def void_ratio(el, kind):
        if kind == "periodic":
            por = measure.porosity(el.scene, ())
            return por / (1 - por)
        return core_void_ratio(el)

    e = {"periodic": [], "box": []}
    de = {"periodic": [], "box": []}  # compression 50 -> 200 kPa
    for seed in (1, 2):
        for kind in e:
            el = (DemElement.periodic if kind == "periodic" else DemElement.box)(
                500, stress=50e3, seed=seed, growth=(0.1, 1e-4))
            e50 = void_ratio(el, kind)
            el.apply_stress(-200e3 * np.eye(3), components=VOIGT[:3], unbalanced=1e-3)
            e[kind].append(void_ratio(el, kind))
            de[kind].append(e[kind][-1] - e50)
    scatter = max(np.ptp(e["box"]), np.ptp(e["periodic"]), 0.01)
    assert abs(np.mean(e["periodic"]) - np.mean(e["box"])) <= 2 * scatter, e
    # (The compressibility: the periodic cube's is repeatable to 3 %, the box core's is noise
    # at this size — +0.011 and -0.043 — so it is compared in bench/periodic_pe.py at 2000.)
    assert np.ptp(de["periodic"]) < 0.1 * abs(np.mean(de["periodic"])), de


def test_voigt_strain_components():
    for k, (a, b) in enumerate(VOIGT):
        e = voigt_strain(k, 0.1)
        assert e[a, b] == pytest.approx(0.1 if a == b else 0.05)
        assert np.allclose(e, e.T)
