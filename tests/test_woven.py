"""The woven biaxial geogrid of bonded spheres (issue 16): structure, labels, presets, and a
tensile test against its bonds in series."""

import math

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem.build import woven


def _grid(preset="detailed", ax=2, ay=1, **kw):
    s = cd.Scene()
    m = s.add_material(woven.woven_material(preset))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=ax, apertures_y=ay, material=m,
                            preset=preset, **kw)
    return s, g, m


def test_structure_of_the_detailed_grid():
    s, g, _ = _grid()
    ns = 3
    # Junctions: one sphere per crossing of a longitudinal and a transverse string.
    assert np.sum(g.sphere_kind == "junction") == (ns * 3) * (ns * 2)
    # Members: 2 x 2 longitudinal (2 rows, 2 cells each), 3 transverse (3 columns, 1 cell).
    assert sorted(g.member_cell[g.members("longitudinal")].tolist()) == [[0, 0], [0, 1], [1, 0],
                                                                          [1, 1]]
    assert sorted(g.member_cell[g.members("transverse")].tolist()) == [[0, 0], [1, 0], [2, 0]]
    assert set(g.member_side[g.members("longitudinal")]) == {"A"}
    # Each member's mid-section cuts one bond per string.
    assert all(len(sec) == ns for sec in g.member_section_bonds)
    # Along a member the spheres touch; inside a junction the strings' crossings are 4.5 mm
    # apart, two bonds of 2.25 mm: a 0.25 mm reference gap.
    st = s.bond_state()
    inside = g.bond_member >= 0
    np.testing.assert_allclose(st["reference_gap"][inside], 0, atol=1e-15)
    np.testing.assert_allclose(st["reference_gap"][~inside], 0.25e-3, rtol=1e-9)
    # The contact bonds' springs: 002's ball values in series (the default convention).
    b = woven.preset_bond("detailed")
    assert (b.kn, b.ks) == pytest.approx((2.0e6, 4.25e5), rel=1e-12)
    # Every bond has the preset's parameters: R_bar = 0.29 r.
    np.testing.assert_allclose(st["pb_radius"], 0.29e-3, rtol=1e-12)
    assert all(st["contact_bond"]) and all(st["parallel_bond"])
    # Mass from the preset's density.
    assert s.masses[0] == pytest.approx(1030 * 4 / 3 * math.pi * 1e-3 ** 3, rel=1e-12)


def test_strings_of_a_member_are_free_between_junctions():
    """No bond joins two strings of one member outside the junctions."""
    s, g, _ = _grid()
    ab = np.asarray(s.bond_spheres)
    strand = g.sphere_strand
    for a, b in ab[g.bond_member >= 0]:
        sa, sb = strand[a], strand[b]
        assert sa == -1 or sb == -1 or sa == sb


def test_detailed_geometry_leaves_the_gap_the_docstring_states():
    """The detailed preset: 1 mm spheres, strings 4.5 mm apart, so a 2.5 mm clear gap between
    adjacent strings (room for member spheres of radius < 1.25 mm), and the 27 mm pitch
    (16 mm aperture + 11 mm member width) the element's box was sized for."""
    p = woven.PRESETS["detailed"]
    assert p["strand_spacing"] - 2 * p["sphere_radius"] == pytest.approx(2.5e-3, rel=1e-12)
    s, g, _ = _grid()
    assert g.pitch == pytest.approx((27e-3, 27e-3), rel=1e-12)
    assert g.member_width == pytest.approx(11e-3, rel=1e-12)
    # As built: the strings of every member stand 4.5 mm apart, centre to centre.
    pos = np.asarray(s.positions)
    ab = np.asarray(s.bond_spheres) - int(g.spheres[0])
    for m in range(g.n_members):
        ids = np.unique(ab[g.member_bonds[m]])
        ids = ids[g.sphere_kind[ids] != "junction"]
        cross = 1 if g.member_direction[m] == "longitudinal" else 0
        lines = np.unique(np.round(pos[ids, cross] / 1e-9)) * 1e-9
        np.testing.assert_allclose(np.diff(lines), 4.5e-3, rtol=1e-6)


def test_contact_stiffness_conventions():
    """'series': 002's values are PFC 4 ball properties, combined k1 k2 / (k1 + k2);
    'contact': they are the contacts' own."""
    assert woven.contact_stiffness("detailed", convention="series") == pytest.approx((2e6, 4.25e5))
    assert woven.contact_stiffness("detailed", 3.9e6, 9e5, "series") == pytest.approx(
        (3.9e6 * 4e6 / 7.9e6, 9e5 * 8.5e5 / 1.75e6), rel=1e-12)
    assert woven.contact_stiffness("detailed", 3.9e6, 9e5, "contact") == (3.9e6, 9e5)
    assert woven.contact_stiffness("standard", convention="contact") == (1.3e7, 6e4)
    with pytest.raises(cd.ParameterError, match="convention"):
        woven.contact_stiffness("detailed", convention="balls")


@pytest.mark.parametrize("preset", ["detailed", "standard"])
@pytest.mark.parametrize("convention", ["series", "contact"])
def test_tensile_test_is_the_bonds_in_series(preset, convention):
    """A sample gripped at its end junctions and pulled 0.1 %: each longitudinal string is a
    chain of n bonds of stiffness k_n + k_bar_n A, k_n the grid-grid contact's (half the
    Table's for 'series'); the reaction is rows x strings x k / n x the grip displacement
    (to 1e-6), and every member carries its row's share."""
    p = woven.PRESETS[preset]
    r = woven.tensile_test(preset, apertures_x=3, apertures_y=1, convention=convention)
    ns, rad, sp = p["strands"], p["sphere_radius"], p["strand_spacing"]
    width = (ns - 1) * sp + 2 * rad
    pitch = p["aperture"] + width
    span = pitch - (ns - 1) * sp
    n_bonds = 3 * max(1, round(span / (2 * rad))) + 2 * (ns - 1) * max(1, round(sp / (2 * rad)))
    kn = p["kn"] / 2 if convention == "series" else p["kn"]
    k_bond = kn + p["pb_kn"] * math.pi * (p["pb_radius_factor"] * rad) ** 2
    length = 3 * pitch - width + 2 * rad
    expected = 2 * ns * k_bond / n_bonds * r["strain"] * length
    assert r["force_n"] == pytest.approx(expected, rel=1e-6)
    np.testing.assert_allclose(r["member_forces_n"], r["force_n"] / 2, rtol=1e-6)
    # The endless grid's value differs from the sample's by its grips only (about 1 %).
    assert r["stiffness_per_metre"] == pytest.approx(r["series_per_metre"], rel=0.02)


@pytest.mark.parametrize("preset", ["detailed", "standard"])
def test_series_convention_scales_the_analytic_stiffness_by_the_series_factor(preset):
    """Only the contact bond's k_n changes with the convention (halved for equal balls in
    series); the parallel bond's k_bar_n A is a bond property and stays."""
    p = woven.PRESETS[preset]
    pb = p["pb_kn"] * math.pi * (p["pb_radius_factor"] * p["sphere_radius"]) ** 2
    ratio = (woven.series_stiffness_per_metre(preset, convention="series")
             / woven.series_stiffness_per_metre(preset, convention="contact"))
    assert ratio == pytest.approx((p["kn"] / 2 + pb) / (p["kn"] + pb), rel=1e-12)
    assert woven.series_stiffness_per_metre(preset) == woven.series_stiffness_per_metre(
        preset, convention="series")


def test_grid_laws_for_002():
    s, g, m = _grid()
    grain = s.add_material(cd.hertz_mindlin_material(density=2640, shear_modulus=3e10,
                                                     poisson=0.2, friction_coefficient=0.8))
    woven.set_grid_laws(s, m, grain)  # 'series': 002's values are PFC 4 ball properties
    laws = {(d["a"], d["b"]): d for d in s.pair_laws}
    assert laws[(m, m)]["kn"] == pytest.approx(2e6) and laws[(m, m)]["friction"] == 0.5
    gg = laws[(min(m, grain), max(m, grain))]
    assert (gg["model"], gg["friction"]) == ("linear", 0.5)
    assert (gg["kn"], gg["ks"]) == pytest.approx((3.9e6 * 4e6 / 7.9e6, 9e5 * 8.5e5 / 1.75e6))
    woven.set_grid_laws(s, m, grain, convention="contact")  # the values as contacts' own
    laws = {(d["a"], d["b"]): d for d in s.pair_laws}
    assert laws[(m, m)]["kn"] == 4e6
    gg = laws[(min(m, grain), max(m, grain))]
    assert (gg["model"], gg["kn"], gg["ks"], gg["friction"]) == ("linear", 3.9e6, 9e5, 0.5)


@pytest.mark.parametrize("kw, field", [
    (dict(preset="fancy"), "preset"),
    (dict(strand_spacing=1.5e-3), "strand_spacing"),
    (dict(sphere_radius=-1.0), "sphere_radius"),
    (dict(strands=0), "strands"),
    (dict(ax=0), "apertures_x"),
])
def test_bad_input_names_the_field(kw, field):
    with pytest.raises(cd.ParameterError, match=field):
        _grid(**kw)


def test_clump_rests_on_a_woven_grid():
    """A clump set down on a held woven grid, over the hollow between four spheres of a
    junction, comes to rest on them: the pair contacts between its member and the grid's
    spheres carry its weight (within 1 %), with 002's grid-grain law (linear, Table 1's
    k_n = 3.9e6 N/m in series with the grid's 4e6). (A clump set down on the side of a
    string slides off it into the gap between the strings: single-string interaction.)"""
    from cpp_dem.build.clumps import ClumpTemplate

    s = cd.Scene(gravity=(0, 0, -9.81), local_damping=0.5)
    gm = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=gm)
    s.block_dofs(g.spheres, "all")
    grain = s.add_material(cd.linear_material(density=2640, young=1e8, poisson=0.25,
                                              friction_angle_deg=38.66))
    woven.set_grid_laws(s, gm, grain)
    t = ClumpTemplate.from_spheres([[0.0, 0, 0]], [0.004])
    # Over the hollow at (2.25, 2.25) mm inside the first junction, between its spheres at
    # (2.25, 0), (0, 2.25), (4.5, 2.25), (2.25, 4.5) mm (the strings 4.5 mm apart, each
    # with a sphere midway between its crossings); touching height sqrt(5^2 - 2.25^2) mm.
    z0 = np.sqrt(5e-3**2 - 2.25e-3**2) + 1e-4
    s.add_clumps(t, [[2.25e-3, 2.25e-3, z0]], [[1.0, 0, 0, 0]], material=grain)
    s.set_auto_timestep(safety=0.5, period=100)
    s.run(30000)
    members = set(s.clump_members(0))
    c = s.contacts()
    ids = np.asarray(c["ids"])
    on_grid = np.array([(a in members) != (b in members) and b >= 0 for a, b in ids])
    assert on_grid.sum() == 4
    np.testing.assert_allclose(np.asarray(c["kn"])[on_grid],  # 002's grid-grain law
                               woven.contact_stiffness("detailed", 3.9e6, 9e5)[0])
    # The force on the clump's member: +force when the member is body 2.
    f = np.asarray(c["force"])[on_grid]
    member_is_2 = np.array([b in members for a, b in ids[on_grid]])
    fz = np.where(member_is_2, f[:, 2], -f[:, 2]).sum()
    weight = s.clump_masses[0] * 9.81
    assert abs(fz / weight - 1) < 0.01
    assert np.linalg.norm(s.clump_velocities[0]) < 1e-4


def test_tails_continue_every_string_past_its_end_junctions():
    """tails=(2, 1): each longitudinal string goes on by 2 touching spheres past both end
    junctions, each transverse one by 1; the tail bonds belong to no member and touch."""
    s0, g0, _ = _grid("standard", ax=3, ay=1)
    s, g, _ = _grid("standard", ax=3, ay=1, tails=(2, 1))
    r = woven.PRESETS["standard"]["sphere_radius"]
    n_long, n_trans = 2, 4  # strings (one strand per member)
    assert len(g.spheres) == len(g0.spheres) + 2 * (2 * n_long + 1 * n_trans)
    assert len(g.bonds) == len(g0.bonds) + 2 * (2 * n_long + 1 * n_trans)
    assert g.tails == (2, 1) and g0.tails == (0, 0)
    # The members are the same; the tails' bonds are in none of them.
    assert g.n_members == g0.n_members
    assert [len(b) for b in g.member_bonds] == [len(b) for b in g0.member_bonds]
    assert np.sum(g.bond_member < 0) == np.sum(g0.bond_member < 0) + 2 * (2 * 2 + 1 * 4)
    pos = np.asarray(s.positions)[g.spheres]
    x0 = np.asarray(s0.positions)[g0.spheres]
    assert pos[:, 0].min() == pytest.approx(x0[:, 0].min() - 2 * 2 * r, abs=1e-15)
    assert pos[:, 0].max() == pytest.approx(x0[:, 0].max() + 2 * 2 * r, abs=1e-15)
    assert pos[:, 1].min() == pytest.approx(x0[:, 1].min() - 2 * r, abs=1e-15)
    st = s.bond_state()
    np.testing.assert_allclose(st["reference_gap"][g.bond_member < 0], 0, atol=1e-15)
    # Tail spheres are of their string's kind.
    assert set(g.sphere_kind) == set(g0.sphere_kind)


@pytest.mark.parametrize("kw, field", [(dict(tails=-1), "tails"), (dict(tails=1.5), "tails"),
                                       (dict(tails=(1, 2, 3)), "tails")])
def test_bad_tails_name_the_field(kw, field):
    with pytest.raises((cd.ParameterError, ValueError), match=field):
        _grid("standard", **kw)


def test_a_grid_with_tails_is_pulled_at_their_tips():
    """EndTension on a grid with tails grips the tips (one sphere per string end), and the
    lines carry T x pitch through the tails to the members."""
    from cpp_dem.protocols.prestress import EndTension, GridEnds

    s = cd.Scene(local_damping=0.7)
    m = s.add_material(woven.woven_material("standard"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=3, apertures_y=2, material=m,
                            preset="standard", tails=3)
    s.dt = 0.5 * s.critical_dt()
    ends = GridEnds(s, g)
    x = np.asarray(s.positions)[:, 0]
    assert len(ends.low) == len(ends.high) == 3  # one tip per longitudinal string
    assert x[ends.low].max() == pytest.approx(x[g.spheres].min())
    e = EndTension(s, g)
    e.set(1000.0)
    s.run(40000)
    assert e.line_forces().mean() == pytest.approx(1000.0 * g.pitch[1], rel=1e-3)
