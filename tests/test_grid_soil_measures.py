"""002's grid-soil measures (cpp_dem.measure.grid_soil) can fail: each one, on a small
hand-built scene, separates a scene where its effect is present from one where it is
absent. The grid is the detailed preset's (1 mm spheres, strings 4.5 mm apart); grains are
hand-placed spheres; the grid is deformed by setting its spheres' positions (the bonds'
forces follow the positions: one step of 1e-9 s)."""

import math

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem.build import woven
from cpp_dem.measure import grid_soil as gs

R_STRING = 1e-3
HALF = 2.25e-3  # half the detailed preset's string spacing, m


def _scene(ax=1, ay=1):
    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=ax, apertures_y=ay, material=m)
    grain = s.add_material(cd.linear_material(density=2600, young=1e7, poisson=0.3,
                                              friction_angle_deg=30))
    s.dt = 1e-9
    return s, g, grain


def _move(s, ids, delta):
    p = s.positions
    p[ids] += delta
    s.positions = p


def _member(g, direction, k=0):
    """The k-th member of ``direction`` that the measures take (transverse: an interior one;
    the grid's two end transverse members are left out)."""
    return int(gs.measured_members(g, direction)[k])


def _strings(s, g, m):
    return gs._strings_of_member(g, s, m)


def _settle(s):
    s.run(1)


# --- tension variation along the members, N ---------------------------------------------

def _stretched(shape):
    s, g, _ = _scene(ax=2, ay=1)
    p = s.positions
    x = p[g.spheres, 0]
    p[g.spheres, 0] = x + (1e-3 * x if shape == "uniform" else 0.05 * x**2)
    s.positions = p
    _settle(s)
    return s, g


def test_tension_variation_absent_for_a_uniform_tension():
    s, g = _stretched("uniform")
    t = gs.tension_variation(s, g, locked_n=10.0)
    mean = gs.member_force_profiles(s, g)["longitudinal_force_mean_n"]
    assert mean > 10  # 3 strings x 2.74e6 N/m x 2 um = 16.4 N
    assert t["longitudinal_std_along_n"] < 1e-6 * mean
    assert t["longitudinal_range_along_n"] < 1e-6 * mean
    assert t["longitudinal_std_across_n"] < 1e-6 * mean
    assert t["longitudinal_mean_above_locked_n"] == pytest.approx(mean - 10.0, rel=1e-9)


def test_tension_variation_present_for_a_tension_varying_along_the_member():
    s, g = _stretched("quadratic")  # bond strain 0.1 x: grows along x
    t = gs.tension_variation(s, g)
    f = gs.member_force_profiles(s, g)
    mean = f["longitudinal_force_mean_n"]
    # Along one member from x = 5.5 to 21.5 mm the force grows by 2 x 0.05 x 16 mm x k x 2 mm
    assert t["longitudinal_std_along_n"] > 0.1 * mean
    assert t["longitudinal_range_along_n"] > 3 * t["longitudinal_std_along_n"]
    # The members of the second cell (further along x) carry more: variation across them.
    assert t["longitudinal_std_across_n"] > 0.1 * mean
    # The locked-in value per member is subtracted member by member.
    per = np.array([p.mean() for p in f["profiles_n"]])
    t2 = gs.tension_variation(s, g, locked_n=per)
    assert abs(t2["longitudinal_mean_above_locked_n"]) < 1e-9 * mean


# --- single-string interaction ----------------------------------------------------------

def _gap_point(s, g, k=5):
    m = _member(g, "longitudinal")
    st = _strings(s, g, m)
    return m, st, 0.5 * (s.positions[st[0][k]] + s.positions[st[1][k]])


@pytest.mark.parametrize("radius", [1.3e-3, 2.0e-3, 4.0e-3])
def test_a_grain_resting_on_two_strings_has_not_entered(radius):
    """A sphere touching two adjacent strings (no overlap; 1.3 mm is just too big for the
    2.5 mm gap, 2 mm the full-size median, 4 mm a large member sphere) does not count."""
    s, g, grain = _scene()
    _, _, c = _gap_point(s, g)
    h = math.sqrt((radius + R_STRING) ** 2 - HALF ** 2)
    s.add_spheres([c + [0, 0, h]], [radius], material=grain)
    s.add_spheres([c + [0, 0, -h]], [radius], material=grain)  # and one resting from below
    r = gs.single_string_entries(s, g)
    assert r["grains_entered"] == 0 and r["spheres_entered"] == 0
    assert r["longitudinal_depth_max_m"] == 0


def test_a_sphere_in_the_gap_has_entered():
    """A 1 mm member sphere (fits the 2.5 mm gap) with its centre in the strings' plane,
    between two strings: entered, 2 mm below their top."""
    s, g, grain = _scene()
    _, _, c = _gap_point(s, g)
    s.add_spheres([c + [0, 0, 0.2e-3]], [1e-3], material=grain)
    r = gs.single_string_entries(s, g)
    assert gs.resting_depth(1e-3, R_STRING, HALF) == 0  # it cannot rest on both
    assert r["longitudinal_grains"] == 1 and r["longitudinal_spheres"] == 1
    assert r["transverse_grains"] == 0
    assert r["longitudinal_depth_max_m"] == pytest.approx(R_STRING + 1e-3 - 0.2e-3, rel=1e-9)


def test_a_large_sphere_that_spread_the_strings_has_entered():
    """A 2 mm sphere 0.8 mm above the strings' plane: it reaches there only with the strings
    spread apart (here by 0.65 mm each); resting on the as-built strings it would sit at
    1.98 mm. Entered."""
    s, g, grain = _scene()
    m, st, c = _gap_point(s, g)
    _move(s, st[0][1:-1], [0, -0.65e-3, 0])
    _move(s, st[1][1:-1], [0, 0.65e-3, 0])
    s.add_spheres([c + [0, 0, 0.8e-3]], [2e-3], material=grain)
    r = gs.single_string_entries(s, g)
    assert r["longitudinal_grains"] == 1
    assert r["longitudinal_depth_max_m"] == pytest.approx(R_STRING + 2e-3 - 0.8e-3, rel=1e-9)
    # The same sphere at the same height over a junction is not in a member's clear span.
    s2, g2, grain2 = _scene()
    j = np.asarray(g2.reference_positions)[0]
    s2.add_spheres([j + [HALF, HALF, 0.8e-3]], [2e-3], material=grain2)
    assert gs.single_string_entries(s2, g2)["spheres_entered"] == 0


# --- string gaps -----------------------------------------------------------------------

def test_string_gaps_as_built():
    s, g, _ = _scene(ax=2)  # two apertures long: one interior transverse member
    r = gs.string_gaps(s, g)
    for d in ("longitudinal", "transverse"):
        assert r[f"{d}_built_mean_m"] == pytest.approx(2.5e-3, rel=1e-9)
        assert r[f"{d}_now_min_m"] == pytest.approx(2.5e-3, rel=1e-9)
        assert r[f"{d}_now_max_m"] == pytest.approx(2.5e-3, rel=1e-9)
        assert abs(r[f"{d}_spread_max_m"]) < 1e-12


def test_string_gaps_spread():
    s, g, _ = _scene(ax=2)
    m, st, _ = _gap_point(s, g)
    _move(s, st[0][1:-1], [0, -0.65e-3, 0])
    _move(s, st[1][1:-1], [0, 0.65e-3, 0])
    r = gs.string_gaps(s, g)
    assert r["longitudinal_now_max_m"] == pytest.approx(2.5e-3 + 1.3e-3, rel=1e-9)
    assert r["longitudinal_now_min_m"] == pytest.approx(2.5e-3 - 0.65e-3, rel=1e-9)
    assert r["longitudinal_spread_max_m"] == pytest.approx(1.3e-3, rel=1e-9)
    assert abs(r["transverse_spread_max_m"]) < 1e-12


def test_string_gaps_of_a_single_string_grid_are_nan():
    s = cd.Scene()
    m = s.add_material(woven.woven_material("standard"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m,
                            preset="standard")
    assert math.isnan(gs.string_gaps(s, g)["longitudinal_now_mean_m"])
    assert gs.single_string_entries(s, g)["spheres_entered"] == 0


# --- interlocking: sideways displacement --------------------------------------------------

def test_no_sideways_displacement_for_rigid_motions():
    """A rigid shift of the whole grid, and a member's strings slid along its axis, give no
    sideways displacement (the ends' motion is subtracted, and only the component across
    the member counts)."""
    s, g, _ = _scene(ax=2, ay=2)
    _move(s, g.spheres, [1e-3, 2e-3, 0.5e-3])
    m = _member(g, "longitudinal")
    for st in _strings(s, g, m):
        _move(s, st[1:-1], [0.3e-3, 0, 0])
    r = gs.member_sideways_displacement(s, g)
    assert r["longitudinal_rms_m"] < 1e-12 and r["transverse_rms_m"] < 1e-12


def test_sideways_displacement_of_a_pushed_member():
    s, g, _ = _scene(ax=2, ay=2)
    _move(s, g.spheres, [1e-3, 2e-3, 0.5e-3])
    m = _member(g, "longitudinal")
    ref = np.asarray(g.reference_positions)
    for st in _strings(s, g, m):
        x = ref[st[1:-1], 0]
        t = (x - ref[st[0], 0]) / (ref[st[-1], 0] - ref[st[0], 0])
        p = s.positions
        p[st[1:-1], 1] += 0.5e-3 * np.sin(math.pi * t)  # bowed sideways, 0.5 mm at mid-span
        s.positions = p
    r = gs.member_sideways_displacement(s, g)
    assert r["per_member_rms_m"][m] > 0.3e-3
    assert r["longitudinal_max_m"] == pytest.approx(0.5e-3, rel=0.05)
    assert r["longitudinal_rms_m"] > 1e-4 and r["transverse_rms_m"] < 1e-12


# --- interlocking: grains in the apertures ---------------------------------------------------

def test_grains_in_apertures_present_and_absent():
    s, g, grain = _scene()
    centre = np.asarray(g.reference_positions).mean(axis=0)
    s.add_spheres([centre + [0, 0, 5e-3]], [2e-3], material=grain)  # above the plane
    assert gs.grains_in_apertures(s, g)["grains_in_apertures"] == 0
    s.add_spheres([centre + [0, 0, 0.5e-3]], [2e-3], material=grain)  # crosses it
    assert gs.grains_in_apertures(s, g)["grains_in_apertures"] == 1


# --- alignment: waviness and contacts, per direction -----------------------------------------

@pytest.mark.parametrize("direction", ["longitudinal", "transverse"])
def test_waviness_of_a_wavy_member_against_a_straight_one(direction):
    s, g, _ = _scene(ax=2, ay=2)
    _move(s, g.spheres, [1e-3, 0, 0.5e-3])  # a rigid shift: still straight
    w0 = gs.member_waviness(s, g)
    assert all(w0[f"out_of_plane_{d}_mean_m"] < 1e-15 for d in ("longitudinal", "transverse"))
    m = _member(g, direction)
    ax = 0 if direction == "longitudinal" else 1
    ref = np.asarray(g.reference_positions)
    for st in _strings(s, g, m):
        t = (ref[st, ax] - ref[st[0], ax]) / (ref[st[-1], ax] - ref[st[0], ax])
        p = s.positions
        p[st, 2] += 0.4e-3 * np.sin(math.pi * t)  # wrapped over a grain
        s.positions = p
    w = gs.member_waviness(s, g)
    other = "transverse" if direction == "longitudinal" else "longitudinal"
    assert w[f"out_of_plane_{direction}_mean_m"] > 0.2e-3 / len(gs.measured_members(g, direction))
    assert w[f"out_of_plane_{other}_mean_m"] < 1e-15


@pytest.mark.parametrize("direction", ["longitudinal", "transverse"])
def test_contacts_per_metre_by_direction(direction):
    def grain_on_string(gap):
        s, g, grain = _scene(ax=2)  # an interior transverse member
        m = _member(g, direction)
        top = s.positions[_strings(s, g, m)[0][5]]
        s.add_spheres([top + [0, 0, R_STRING + 2e-3 + gap]], [2e-3], material=grain)
        _settle(s)
        return s, g

    # Absent: a grain 1 mm clear of the string.
    s, g = grain_on_string(1e-3)
    c0 = gs.grid_contacts_per_metre(s, g)
    assert c0["contacts"] == 0 and c0["longitudinal_per_m"] == c0["transverse_per_m"] == 0
    # Present: a grain resting on that string (a 1 um overlap).
    s, g = grain_on_string(-1e-6)
    _settle(s)
    c = gs.grid_contacts_per_metre(s, g)
    other = "transverse" if direction == "longitudinal" else "longitudinal"
    assert c["grains_touching"] == 1 and c["contacts"] == 1
    assert c[f"{direction}_per_m"] == pytest.approx(1 / gs.member_lengths(g)[direction])
    assert c[f"{other}_per_m"] == 0


# --- displacement above and below the grid ---------------------------------------------------

def _layered():
    s, g, grain = _scene()
    c = np.asarray(g.reference_positions).mean(axis=0)
    above = s.add_spheres([c + [x, 0, 10e-3] for x in (-5e-3, 0, 5e-3)], [2e-3] * 3,
                          material=grain)
    below = s.add_spheres([c + [x, 0, -10e-3] for x in (-5e-3, 0, 5e-3)], [2e-3] * 3,
                          material=grain)
    return s, np.asarray(above), np.asarray(below), s.positions.copy()


def test_displacement_equal_above_and_below():
    s, above, below, ref = _layered()
    _move(s, np.concatenate([above, below]), [0, 0, -0.5e-3])
    d = gs.displacement_above_below(s, ref, 0.0)
    assert d["above_mean_m"] == pytest.approx(d["below_mean_m"], rel=1e-9)
    assert d["above_z_mean_m"] == pytest.approx(-0.5e-3, rel=1e-9)


def test_displacement_larger_above_the_grid():
    s, above, below, ref = _layered()
    _move(s, above, [0, 0, -1e-3])
    _move(s, below, [0, 0, -0.2e-3])
    d = gs.displacement_above_below(s, ref, 0.0)
    assert d["above_mean_m"] == pytest.approx(1e-3, rel=1e-9)
    assert d["below_mean_m"] == pytest.approx(0.2e-3, rel=1e-9)


# --- summary and the history row -----------------------------------------------------------

def test_summary_and_history_row_are_plain_numbers():
    s, g, grain = _scene(ax=2)
    _, _, c = _gap_point(s, g)
    s.add_spheres([c + [0, 0, 0.2e-3]], [1e-3], material=grain)  # entered
    ref = s.positions.copy()
    _settle(s)
    out = gs.summary(s, g, z_grid=0.0, reference_positions=ref, locked_n=5.0)
    assert set(out) == {"contacts", "between_strings", "apertures", "waviness", "force",
                        "displacement", "tension_variation", "string_gaps",
                        "sideways_displacement", "interfriction", "gaps", "member_strain"}
    assert out["between_strings"]["longitudinal_grains"] == 1
    for part in out.values():
        assert all(isinstance(v, (int, float)) and not isinstance(v, bool)
                   for v in part.values() if not isinstance(v, list))
    row = gs.history_row(s, g, z_grid=0.0, locked_n=5.0, reference_positions=ref)
    assert all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in row.values())
    assert all(k.endswith(("_n", "_m", "_per_m", "_grains", "_spheres", "contacts",
                           "_grid", "_apertures", "_ratio", "_fraction", "_strain"))
               for k in row)
    assert row["longitudinal_entered_grains"] == 1
    assert row["longitudinal_string_gap_mean_m"] == pytest.approx(2.5e-3, rel=1e-6)
    assert row["transverse_string_gap_mean_m"] == pytest.approx(2.5e-3, rel=1e-6)
    assert row["longitudinal_tension_mean_above_locked_n"] == pytest.approx(
        row["longitudinal_force_mean_n"] - 5.0)
    assert "disp_above_mean_m" in row
    for k in ("interfriction_contacts", "interfriction_mean_ratio",
              "interfriction_sliding_fraction", "gap_above_mean_m", "gap_below_mean_m",
              "unsupported_above_fraction", "unsupported_below_fraction"):
        assert k in row
        for d in ("longitudinal", "transverse"):
            assert f"{d}_{k}" in row
    assert row["longitudinal_mean_axial_strain"] == pytest.approx(0.0, abs=1e-12)
    assert row["transverse_mean_axial_strain"] == pytest.approx(0.0, abs=1e-12)


def test_a_grid_one_aperture_long_has_no_transverse_values():
    """One aperture along x: both transverse members are end members, so every transverse
    value is NaN (entries: 0), and nothing warns."""
    import warnings

    s, g, grain = _scene()
    _settle(s)
    assert len(gs.measured_members(g, "transverse")) == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        row = gs.history_row(s, g, z_grid=0.0)
    for k in ("transverse_contacts_per_m", "transverse_out_of_plane_mean_m",
              "transverse_sideways_displacement_rms_m", "transverse_string_gap_mean_m",
              "transverse_force_mean_n", "transverse_tension_std_along_n",
              "transverse_mean_axial_strain", "transverse_gap_above_mean_m"):
        assert math.isnan(row[k]), k
    assert row["transverse_entered_grains"] == 0
    assert row["longitudinal_force_mean_n"] == pytest.approx(0.0, abs=1e-9)
