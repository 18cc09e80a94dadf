"""DemElement (docs/periodic.md): exact strain increments, stress, save/restore/continue,
the wall-bounded kind's limits, the p–e curve against a wall-bounded sample, and the two
tangents against each other in the elastic range."""

from __future__ import annotations

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import DemElement
from cpp_dem import measure
from cpp_dem.elements.periodic import VOIGT, voigt_strain


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
    # (The compressibility: the periodic cube's is repeatable, the box core's is noise at this
    # size — +0.011 and -0.043 — so it is compared in bench/periodic_pe.py at 2000.) The
    # periodic cube's de over seeds 1-12: -0.0268 to -0.0311 (sd 4.8 % of the mean); two seeds
    # differ by at most 14.6 % of their mean over the 66 pairs (above the earlier bound 10 % at
    # 13 of them; 2.9 % for seeds 1 and 2 here). Asserted: 25 %, about 3.7 sd of a difference.
    assert np.ptp(de["periodic"]) < 0.25 * abs(np.mean(de["periodic"])), de


def test_voigt_strain_components():
    for k, (a, b) in enumerate(VOIGT):
        e = voigt_strain(k, 0.1)
        assert e[a, b] == pytest.approx(0.1 if a == b else 0.05)
        assert np.allclose(e, e.T)


def test_stress_scatter_is_the_bootstrap_of_the_contact_sum(element_blob):
    """The bootstrap standard deviation of a sum of m contact terms is sqrt(m) times their
    standard deviation (the closed form); seeded, so repeatable; and it leaves the element
    as it was."""
    from cpp_dem.measure import network_tangent as tangent

    el = DemElement.from_bytes(element_blob)
    d = el.network_data()
    f = d["fn"][:, None] * d["normal"] + d["fs"]
    terms = -np.einsum("ci,cj->cij", f, d["branch"]) / d["volume"]
    terms = 0.5 * (terms + terms.transpose(0, 2, 1))
    closed = np.sqrt(len(terms)) * terms.std(axis=0)
    got = el.stress_scatter(n_boot=2000, seed=3)
    # (2000 resamplings: the std of a std estimate is about 1/sqrt(2 * 2000) = 1.6 %)
    assert np.allclose(got, closed, rtol=0.06)
    assert np.array_equal(el.stress_scatter(), el.stress_scatter())
    # the contacts' sum is the element's stress
    s = tangent.stress_from_contacts(branch=d["branch"], normal=d["normal"], fn=d["fn"],
                                     fs=d["fs"], volume=d["volume"])
    assert np.allclose(0.5 * (s + s.T), el.stress(), rtol=0, atol=1e-9 * 1e5)
    # it only reads: the element goes on as one that was never asked
    de = np.diag([1e-4, 0.0, -1e-4])
    other = DemElement.from_bytes(element_blob)
    assert np.array_equal(el.apply_strain(de), other.apply_strain(de))
    with pytest.raises(dem.ParameterError, match="n_boot"):
        el.stress_scatter(n_boot=1)


def test_dense_preparation_holds_an_isochoric_shear():
    """Grown at zero friction (prep_friction_deg=0) the packing is dense and dilatant: under
    an isochoric shear its mean stress rises. Grown at its own friction (30 deg) the same
    grains make a loose packing whose mean stress falls (seed 2: it loses every contact by
    2e-3; docs/coupling_hierarchical.md). How far is chaotic: over seeds 1-12 after the two
    increments, dense 100.8 to 104.9 kPa, loose 18 to 98 kPa (below 50 kPa at seeds 2 and 4
    only; the earlier bound p_loose < 50 kPa held at seed 2 by chance). Asserted: the signs."""
    de = np.diag([1e-3, 0.0, -1e-3])
    p = {}
    for pf in (0.0, None):
        el = DemElement.periodic(150, stress=100e3, seed=2, prep_friction_deg=pf)
        el.apply_stress(-100e3 * np.eye(3))
        for _ in range(2):
            s = el.apply_strain(de, unbalanced=1e-4, max_relax_steps=50_000)
        p[pf] = -np.trace(s) / 3
    assert p[0.0] > 100e3 and p[None] < 100e3


def test_a_rotated_load_gives_the_same_invariants():
    """Invariance (issue 18): element B is element A turned rigidly by R (an increment
    F = R, exact in the cell's map); B's stress is then R sigma_A R^T, and the load R dE R^T
    on B gives A's answer to dE, turned: the same invariants. The two frames round
    differently and the relaxation amplifies it, a chaotic difference; its scatter over seeds
    1-30 of this element (seed 3 is the test's): the rigid turn alone at most 2.6e-5 of the
    stress (asserted 1e-4); after the loads the invariants at most 3.75e-3 apart (median
    1.9e-4; above 1e-3 at 3 of 30 seeds; asserted 1e-2) and the turned tensor at most 1.86e-3
    of the stress (median 8.7e-5; asserted 5e-3). (The earlier bound 1e-3 was ten times one
    seed's 8e-5.)"""
    from scipy.spatial.transform import Rotation

    def invariants(s):
        d = s - np.trace(s) / 3 * np.eye(3)
        return np.array([np.trace(s) / 3, np.sqrt(1.5 * np.sum(d * d))])

    el = DemElement.periodic(100, stress=100e3, seed=3, prep_friction_deg=0.0)
    el.apply_stress(-100e3 * np.eye(3))
    blob = el.to_bytes()
    a, b = DemElement.from_bytes(blob), DemElement.from_bytes(blob)
    R = Rotation.from_euler("zyx", [30, 20, 10], degrees=True).as_matrix()
    s0 = a.stress()
    sb = b.apply_strain(R - np.eye(3), steps=2000, unbalanced=1e-5)
    assert np.abs(sb - R @ s0 @ R.T).max() <= 1e-4 * np.abs(s0).max()
    de = np.diag([1e-3, 0.0, -1e-3])
    de[0, 2] = 5e-4  # a shear and a rotation too
    for _ in range(3):
        sa = a.apply_strain(de, unbalanced=1e-5, max_relax_steps=100_000)
        sb = b.apply_strain(R @ de @ R.T, unbalanced=1e-5, max_relax_steps=100_000)
    assert np.allclose(invariants(sb), invariants(sa), rtol=1e-2, atol=0)
    assert np.abs(sb - R @ sa @ R.T).max() <= 5e-3 * np.abs(sa).max()
    assert invariants(sa)[1] > 0.5 * 100e3  # (the load did something)


def test_a_sheared_apart_element_keeps_a_stable_step():
    # A loose element (10 kPa, grown at its 30 deg) loses its contacts under shear; with one or
    # two contacts left its critical step estimate doubled, the next increment took that dt,
    # and contacts forming again stopped it with BlowUpError (dt 7.80e-6 s against a critical
    # 7.66e-6 s). The element's dt never exceeds its prepared one (dt_max), saved with it.
    el = DemElement.periodic(200, stress=10e3, seed=2)
    de = np.array([[1e-4, 0, 2e-5], [0, 0, 0], [2e-5, 0, -3e-4]])
    dts = []
    for k in (3, 6, 9):
        el.apply_strain(k * de)  # (raised BlowUpError in the third before)
        dts.append(el.scene.dt)
    assert max(dts) <= el.dt_max
    assert DemElement.from_bytes(el.to_bytes()).dt_max == el.dt_max
