"""The reinforced-soil RVE (issue 38): an endless woven sheet in a periodic cell
(cpp_dem.elements.reinforced). Alone, it gives its tensile stiffness per metre (the series
value of its bonds, woven.series_stiffness_per_metre); a prestress is locked into it. With
grains around it (reinforced_element) it is a DemElement: without the sheet it is the soil
element bitwise, a prestress stays locked in, a rigid rotation rotates its stress, and it
saves and restores bitwise."""

import numpy as np
import pytest

from cpp_dem import DemElement, ParameterError
from cpp_dem.build import woven
from cpp_dem.elements import reinforced


@pytest.mark.parametrize("preset", ["detailed", "standard"])
def test_the_sheet_alone_gives_its_series_stiffness_per_metre(preset):
    s, g, _, _, lz = reinforced.sheet_cell(preset=preset, apertures=(2, 1))
    lx0 = float(np.asarray(s.cell_matrix)[0, 0])
    assert lx0 == pytest.approx(2 * woven.preset_pitch(preset)[0])
    s.run(10)
    assert np.abs(np.asarray(s.bond_state()["force"])).max() < 1e-9  # closed, unloaded
    reinforced.stretch_x(s, 1e-4, 2000)
    eps = float(np.asarray(s.cell_matrix)[0, 0]) / lx0 - 1
    tx, ty = reinforced.sheet_tension_per_metre(s, lz)
    j = woven.series_stiffness_per_metre(preset)
    assert tx / eps == pytest.approx(j, rel=1e-4)
    # the cell stress is the sheet's alone: -sigma_xx x height is the same tension
    assert -float(np.asarray(s.cell_stress())[0, 0]) * lz == pytest.approx(tx, rel=1e-9)
    # and each longitudinal member carries its pitch's share
    f = g.member_axial_forces(s)[g.members(woven.LONGITUDINAL)]
    assert np.allclose(f, tx * woven.preset_pitch(preset)[1], rtol=1e-4)
    assert abs(ty) < 1e-6 * tx


def test_a_prestress_is_locked_into_the_sheet():
    s, g, _, _, lz = reinforced.sheet_cell(preset="detailed", prestress=2000.0)
    tx, _ = reinforced.sheet_tension_per_metre(s, lz)
    assert tx == pytest.approx(2000.0, rel=1e-3)
    s.run(20000)  # it stays: the cell holds the sheet stretched
    assert reinforced.sheet_tension_per_metre(s, lz)[0] == pytest.approx(tx, rel=1e-6)


@pytest.mark.parametrize("kw, msg", [
    (dict(apertures=(0, 1)), "apertures=(0, 1)"),
    (dict(prestress=-1.0), "prestress=-1.0: must be >= 0"),
    (dict(height=0.0), "height=0.0: must be > 0"),
])
def test_bad_sheet_cells_are_named(kw, msg):
    with pytest.raises(ParameterError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        reinforced.sheet_cell(**kw)


def test_a_sheet_needs_its_periodic_cell():
    import cpp_dem as cd

    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    with pytest.raises(ParameterError, match="no periodic cell"):
        woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m,
                            periodic=True)
    s.set_periodic_cell(np.diag([0.03, 0.027, 0.03]))
    with pytest.raises(ParameterError, match="the sheet needs"):
        woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m,
                            periodic=True)


# ---- the reinforced RVE: the sheet and grains around it -------------------------------------

P = 50e3      # Pa, the grains' isotropic stress
T_P = 2000.0  # N/m, the prestress (PRS)


@pytest.fixture(scope="module")
def prs():
    """150 grains around a detailed sheet prestressed to 2 kN/m, at 50 kPa (about 6 s)."""
    return reinforced.reinforced_element(150, stress=P, prestress=T_P, seed=1)


def test_the_soil_alone_is_the_soil_element():
    # Without a sheet the reinforced RVE's stages (the growth counting the grains' own
    # contacts, the servo on the whole cell) are the soil element's, summed alike: bitwise.
    kw = dict(stress=100e3, seed=3, tol=0.005, unbalanced=1e-4)
    soil = DemElement.periodic(60, **kw)
    alone = reinforced.reinforced_element(60, preset=None, **kw)
    assert alone.to_bytes() == soil.to_bytes()
    de = np.zeros((3, 3))
    de[0, 0], de[0, 2] = -2e-4, 1e-4
    assert np.array_equal(alone.apply_strain(de), soil.apply_strain(de))


def test_a_prestress_stays_locked_in_with_grains_around_the_sheet(prs):
    lz = reinforced.cell_height(prs.scene)
    band = 0.005 * P  # the preparation's tolerance
    # the sheet at T_P along x and unloaded along y, to the tolerance times the height
    tx, ty = reinforced.sheet_tension_per_metre(prs.scene)
    assert abs(tx - T_P) <= band * lz and abs(ty) <= band * lz
    # the grains at P on average, sigma_zz at P; the cell's sigma_xx is the grains' less
    # T_P / height (the grains' own split between x and y is theirs: measured 46.6 and
    # 52.7 kPa)
    s = -prs.stress()  # compression positive
    grains = s - reinforced.bond_stress(prs.scene)
    assert np.trace(grains) / 3 == pytest.approx(P, abs=2 * band)
    assert s[2, 2] == pytest.approx(P, abs=band)
    assert s[0, 0] == pytest.approx(grains[0, 0] - T_P / lz, abs=band)
    assert abs(grains[0, 0] - grains[1, 1]) < 0.3 * P
    # and it stays: held at this strain, the sheet keeps its tension
    el = prs.clone()
    el.scene.run(20000)
    assert reinforced.sheet_tension_per_metre(el.scene)[0] == pytest.approx(tx, rel=0.01)


def test_an_unreinforced_sheet_ends_unloaded_with_large_grains():
    # 80 grains (6.1 mm across against the 16 mm apertures) press the sheet's strands apart;
    # a servo of the whole cell to an isotropic stress left this sheet at -195 N/m, in
    # compression. Following the sheet instead, it ends unloaded (its strands still bent:
    # 0.48 J along x, docs/periodic.md).
    el = reinforced.reinforced_element(80, stress=P, seed=1)
    lz = reinforced.cell_height(el.scene)
    tx, ty = reinforced.sheet_tension_per_metre(el.scene)
    assert abs(tx) <= 0.005 * P * lz and abs(ty) <= 0.005 * P * lz


def test_the_reinforced_element_restores_bitwise(prs):
    blob = prs.to_bytes()
    a, b = DemElement.from_bytes(blob), DemElement.from_bytes(blob)
    assert b.to_bytes() == blob
    assert b.controller.allow_tension  # (its sheet holds tensile targets)
    de = np.zeros((3, 3))
    de[0, 0], de[1, 2] = 3e-4, -1e-4
    sa = a.apply_strain(de)
    assert np.array_equal(b.apply_strain(de), sa)
    assert a.to_bytes() == b.to_bytes()
    # the increment stretched the sheet along x: it is in the element's stress
    assert reinforced.sheet_tension_per_metre(a.scene)[0] > reinforced.sheet_tension_per_metre(
        prs.scene)[0]


def test_the_quasi_static_check_takes_the_grains_pressure_not_the_sheets_tension(prs):
    """A too fast increment of a reinforced cell is reported with the grains' own mean
    stress (the fixture's P), not the cell's, which the prestressed sheet's tension along x
    takes down by T_P / (3 h)."""
    import re
    import warnings

    from cpp_dem.measure.inertial import InertialNumberWarning
    from cpp_dem.protocols.periodic import cell_height

    cell_p = float(np.trace(prs.scene.cell_stress())) / 3.0  # (Pa, compression positive)
    assert cell_p < 0.8 * P  # (the measure below can fail: the cell's pressure is not P)
    fast = DemElement.from_bytes(prs.to_bytes())
    de = np.zeros((3, 3))
    de[2, 2] = -1e-3
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always", InertialNumberWarning)
        fast.apply_strain(de, steps=10, max_relax_steps=0)
    said = [str(w.message) for w in got if issubclass(w.category, InertialNumberWarning)]
    assert len(said) == 1, said
    pressure = float(re.search(r"pressure ([0-9.e+-]+) Pa", said[0]).group(1))
    assert abs(pressure - P) < 0.05 * P, (pressure, cell_p)
    assert abs(cell_p - (P - T_P / (3.0 * cell_height(prs.scene)))) < 0.05 * P


def sheet_stiffness_x(el) -> float:
    """The bonds' part of the element's stiffness along x, Pa: a central difference of
    1e-5 on clones."""
    out = []
    for h in (1e-5, -1e-5):
        c = el.clone()
        de = np.zeros((3, 3))
        de[0, 0] = h
        c.apply_strain(de)
        out.append(-reinforced.bond_stress(c.scene)[0, 0])
    return (out[0] - out[1]) / 2e-5


def test_the_sheet_adds_its_stiffness_per_metre_over_the_height_along_x(prs):
    # The bonds' part of the cell's stiffness along x, times the height, is the sheet's
    # tensile stiffness per metre: at most its straight strings' affine value (1.004 J),
    # less where the grains have bent them (PRS 0.96-0.99 J, RE 0.73-0.94 J:
    # bench/reinforced_rve.py).
    j = woven.series_stiffness_per_metre("detailed")
    assert 0.85 * j < sheet_stiffness_x(prs) * reinforced.cell_height(prs.scene) < 1.005 * j


def test_a_rigidly_rotated_reinforced_cell_gives_the_rotated_stress(prs):
    # A quarter turn about z (x -> y, y -> -x) as one increment I + dE = R, at 157 rad/s: the
    # sheet, its bonds through the faces and the grains turn with the cell. Tolerance: the
    # soil element's (2e-3 of |sigma|, docs/periodic.md); measured 4e-5 here.
    el = prs.clone()
    el.scene.run(20000)  # (at rest first: a loose packing creeps, 0.2 % of its stress)
    s0 = el.stress()
    tx, ty = reinforced.sheet_tension_per_metre(el.scene)
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    s1 = el.apply_strain(rot - np.eye(3), steps=20000, unbalanced=1e-4)
    assert np.allclose(s1, rot @ s0 @ rot.T, atol=2e-3 * np.linalg.norm(s0))
    # the sheet's tension that was along x is now along y, and the other way round
    assert reinforced.sheet_tension_per_metre(el.scene) == pytest.approx((ty, tx),
                                                                          abs=1e-3 * tx)
    assert abs(ty) < 10.0 and tx > 0.99 * T_P


def test_the_network_tangent_takes_the_sheet_as_the_finite_differences_do(prs):
    # The sheet's bonds are in the network (springs in tension too, their rotational springs):
    # the plane's block (xx, zz, xz) against central differences of relaxed clones at
    # h = 1e-6, within 3 % of its largest entry (measured 2.1 %, in the xz shear; 0.8 % in
    # xx). As a band (h / t = 2.7), the sheet's rows count h / t times: the band's tangent
    # less the cell's is the finite differences' within 3 % of that rise in xx (measured
    # 1 %): 7.7 MPa, which a network without the sheet (or with it counted once) misses.
    el = prs.clone()
    el.apply_strain(np.zeros((3, 3)), unbalanced=1e-5, max_relax_steps=400_000)
    plane = np.ix_((0, 2, 4), (0, 2, 4))
    fd_kw = dict(h=1e-6, components=(0, 2, 4), unbalanced=1e-5, max_relax_steps=100_000)
    out = {}
    for t in (None, 0.02):
        el.set_band_thickness(t)
        net, info = el.network_tangent()
        assert info["residual"] < 1e-8
        out[t] = net[plane], el.fd_tangent(**fd_kw)[plane]
    net, fd = out[None]
    assert np.abs(net - fd).max() < 0.03 * np.abs(fd).max(), (net / 1e6, fd / 1e6)
    rise_net, rise_fd = out[0.02][0] - net, out[0.02][1] - fd
    assert rise_fd[0, 0] > 0.15 * fd[0, 0]
    assert np.abs(rise_net - rise_fd).max() < 0.03 * rise_fd[0, 0], (rise_net, rise_fd)


@pytest.mark.parametrize("kw, msg", [
    (dict(n=1), "n=1: the number of grains, a whole number >= 2"),
    (dict(stress=-5.0), "stress=-5.0: must be > 0"),
    (dict(radius_spread=1.5), "radius_spread=1.5: must be in (0, 1)"),
    (dict(radius_mean=0.0), "radius_mean=0.0: must be > 0"),
    (dict(preset=None, prestress=100.0), "prestress=100.0: there is no sheet"),
    (dict(preset="coarse"), "preset='coarse': must be one of 'detailed', 'standard'"),
    (dict(prestress=-1.0), "prestress=-1.0: must be >= 0"),
    (dict(prep_friction_deg=-3.0), "prep_friction_deg=-3.0: must be in "),
])
def test_bad_reinforced_elements_are_named(kw, msg):
    with pytest.raises(ParameterError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        reinforced.reinforced_element(**kw)


# ---- the preparation's controllers with a sheet in the cell ---------------------------------


def test_the_cell_servo_counts_the_sheet_along_its_plane_only():
    # The sheet alone: the servo's stress is the cell's, bonds included (it reaches a tensile
    # target that only the bonds can carry), and its affine stiffness holds the sheet along
    # x (its series stiffness per metre over the height, bounded below by it: the affine sum
    # of springs in series) and nothing along z (its bonds' l_z is zero).
    from cpp_dem.protocols import periodic

    s, _, _, _, lz = reinforced.sheet_cell(preset="detailed")
    j = woven.series_stiffness_per_metre("detailed")
    target = -500.0 / lz  # Pa, compression positive: 500 N/m of tension
    with pytest.raises(ParameterError, match="or set allow_tension"):
        periodic.drive_cell(s, stress={(0, 0): target}, max_steps=10)
    r = periodic.drive_cell(s, stress={(0, 0): target}, allow_tension=True, steps=20_000)
    assert reinforced.sheet_tension_per_metre(s, lz)[0] == pytest.approx(500.0, rel=2e-3)
    c = np.asarray(r.extra["controller"].stiffness)
    assert c[0, 0] * lz >= j * (1 - 1e-9)
    assert c[0, 0] * lz == pytest.approx(j, rel=0.05)
    assert c[2, 2] == 0.0 and c[0, 2] == 0.0


def test_growth_around_a_sheet_reaches_the_grains_stress_with_grown_only(prs):
    # In the prepared cell the bonds carry T / height along x; the growth stage counted the
    # grains alone, so the grains (not the cell) reached the target. A RadiusGrowth that
    # counts them saves its flag in a checkpoint (seven values; six without it: the older
    # format) and restores it.
    from cpp_dem import _core
    from cpp_dem.scene import Scene

    sc = prs.clone().scene
    ids = list(range(sc.num_bodies - 150, sc.num_bodies))
    g = _core.RadiusGrowth(walls=[], bodies=ids, target_stress=P, grown_only=True)
    sc.add_controller(g)
    sc.run(1)
    grains = -prs.stress() - reinforced.bond_stress(prs.scene)
    assert g.measured_stress == pytest.approx(np.trace(grains) / 3, rel=0.01)
    cell = float(np.trace(-prs.stress())) / 3
    assert abs(cell - g.measured_stress) > 0.1 * P  # (what counting the bonds would see)
    blob = _core._checkpoint_save(sc)
    back = Scene()
    back.add_controller(_core.CellController())  # (the element's, first)
    h = _core.RadiusGrowth(walls=[], bodies=ids, target_stress=P)
    back.add_controller(h)
    _core._checkpoint_load(back, blob)
    assert h.grown_only


def test_the_documented_example_runs(prs):
    # docs/periodic.md, "A reinforced-soil RVE": its code block, run as shown; it builds
    # the same element as the fixture (same arguments): bitwise.
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "periodic.md").read_text()
    section = text[text.index("### A reinforced-soil RVE"):]
    code = section[section.index("```python") + len("```python"):]
    code = code[:code.index("```")]
    ns: dict = {}
    exec(compile(code, "docs/periodic.md", "exec"), ns)
    assert ns["back"].to_bytes() == ns["el"].to_bytes()
    assert ns["tx"] == pytest.approx(reinforced.sheet_tension_per_metre(prs.scene)[0],
                                     rel=1e-12)
    assert ns["sigma"][0, 0] > prs.stress()[0, 0]  # stretched along the sheet


@pytest.mark.filterwarnings("ignore::cpp_dem.ControllerLimitWarning")  # (2000 steps: at the cap)
def test_a_cell_that_does_not_settle_says_what_it_missed():
    with pytest.raises(RuntimeError, match=r"reinforced_element: the cell did not settle in "
                                           r"2000 steps: the sheet at .* N/m \(targets 500, 0\), "
                                           r"the grains at .* Pa and sigma_zz at"):
        reinforced.reinforced_element(60, stress=P, prestress=500.0, max_steps=2000)


def test_the_reinforced_element_is_bitwise_on_one_and_two_threads(prs):
    import cpp_dem

    de = np.zeros((3, 3))
    de[0, 0], de[1, 2] = 1e-4, 5e-5
    out = []
    before = cpp_dem.get_num_threads()
    try:
        for threads in (1, 2):
            cpp_dem.set_num_threads(threads)
            el = prs.clone()
            el.apply_strain(de)
            out.append(el.to_bytes())
    finally:
        cpp_dem.set_num_threads(before)
    assert out[0] == out[1]


# ---- the RVE as a continuum's geogrid band (DemElement.set_band_thickness) -------------------


def test_a_band_counts_the_sheet_once_per_band_thickness(prs):
    # The cell holds one sheet per height h; as a band of thickness t the same force per
    # metre is spread over t: the grains' stress as it is, the bonds' times h / t.
    el = prs.clone()
    h = reinforced.cell_height(el.scene)
    cell, bonds = el.stress(), -reinforced.bond_stress(el.scene)  # tension positive
    t = 0.02
    el.set_band_thickness(t)
    band = el.stress()
    bonds_sym = 0.5 * (bonds + bonds.T)  # (the element's stress is symmetrised)
    assert np.allclose(band, cell + (h / t - 1) * bonds_sym, rtol=0, atol=1e-9 * P)
    # the band's force per metre along x less its grains' is the sheet's tension
    tx = reinforced.sheet_tension_per_metre(el.scene)[0]
    assert t * (band[0, 0] - (cell - bonds)[0, 0]) == pytest.approx(tx, rel=1e-12)
    assert tx == pytest.approx(T_P, abs=0.005 * P * h)
    # a band as thick as the cell is the cell
    el.set_band_thickness(h)
    assert np.allclose(el.stress(), cell, rtol=0, atol=1e-9 * P)
    el.set_band_thickness(None)
    assert np.array_equal(el.stress(), cell)


def test_a_band_element_restores_with_its_thickness_and_answers_in_its_scale(prs):
    el = prs.clone()
    el.set_band_thickness(0.02)
    back = DemElement.from_bytes(el.to_bytes())
    assert back.band_thickness == 0.02 and np.array_equal(back.stress(), el.stress())
    # a stretch along x: the band's stress rise is the grains' plus the sheet's h / t times
    de = np.zeros((3, 3))
    de[0, 0] = 1e-4
    cell = prs.clone()
    d_cell = cell.apply_strain(de) - prs.stress()
    d_band = back.apply_strain(de) - el.stress()
    h = reinforced.cell_height(cell.scene)
    d_bonds = -reinforced.bond_stress(cell.scene) + reinforced.bond_stress(prs.scene)
    assert d_band[0, 0] == pytest.approx(d_cell[0, 0] + (h / 0.02 - 1) * d_bonds[0, 0],
                                         rel=1e-6)
    assert d_band[0, 0] > d_cell[0, 0]  # (h = 27 mm against t = 20 mm: more sheet)
    # the soil element's bytes carry no band thickness (unchanged format)
    assert b"band_thickness" not in DemElement.periodic(40, stress=P, seed=2).to_bytes()


def test_bad_band_thicknesses_are_named(prs):
    el = prs.clone()
    for bad in (0.0, -0.02, float("nan"), "x"):
        with pytest.raises(ParameterError, match="must be > 0"):
            el.set_band_thickness(bad)
    soil = DemElement.periodic(40, stress=P, seed=2)
    with pytest.raises(ParameterError, match="needs a periodic element with bonds"):
        soil.set_band_thickness(0.02)
    el.set_band_thickness(0.02)
    with pytest.raises(ParameterError, match="apply_stress: this element stands for a band"):
        el.apply_stress(-P * np.eye(3))


def test_given_radii_get_a_cell_tall_enough_for_their_clouds():
    # 3 mm grains, 80 of them: the default height (the pitch, 27 mm) would fill 0.5 of the
    # room and the loose clouds jam; the cell is made taller (a quarter filled)
    from cpp_dem.elements.reinforced import woven

    el = reinforced.reinforced_element(80, stress=20e3, radius_mean=0.003, seed=3)
    px, py = woven.preset_pitch("detailed")
    assert reinforced.cell_height(el.scene) > 1.5 * px
    tx, ty = reinforced.sheet_tension_per_metre(el.scene)
    h = reinforced.cell_height(el.scene)
    assert abs(tx) <= 0.005 * 20e3 * h and abs(ty) <= 0.005 * 20e3 * h
