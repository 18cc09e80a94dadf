"""Issue 59 item 5: the measures of cpp_dem.measure.grid_soil added for 002's effects that were
not measured yet, and the end transverse members left out. Each measure separates a hand-built
scene where its effect is present from one where it is absent:

- the end transverse members (bowed by the pull at the end junctions) change no transverse
  measure; the same bow of an interior member does;
- interfriction |F_t| / (mu F_n): 0 for a grain resting on the grid, 1 for one dragged along it;
- gaps between the grid and the grains: 0 for grains resting on it, the lift for lifted ones;
- member strain: a homogeneous stretch of the grid, exactly;
- the contact-normal rose's two inclined main directions (cpp_dem.measure.grid_figures): none
  significant in an isotropic sample, two imposed families found at their angles.

The grid is the detailed preset's (1 mm spheres, 3 strings 4.5 mm apart, 27 mm pitch)."""

import math

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem.build import woven
from cpp_dem.measure import grid_figures as gf
from cpp_dem.measure import grid_soil as gs

R_STRING = 1e-3


def _scene(ax=2, ay=1, laws=False):
    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=ax, apertures_y=ay, material=m)
    grain = s.add_material(cd.linear_material(density=2600, young=1e7, poisson=0.3,
                                              friction_angle_deg=30))
    if laws:
        woven.set_grid_laws(s, m, grain)  # 002's grain–grid law: mu = 0.5
    s.dt = 1e-9
    return s, g, grain


def _transverse(g):
    """(the two end transverse members, the interior ones) of a grid."""
    ends = np.flatnonzero(gs.end_members(g))
    return ends, gs.measured_members(g, "transverse")


def _bow(s, g, m, amplitude, axis):
    """Bows member m: its strings' spheres between the end crossings moved along ``axis``
    (0 x, 1 y, 2 z) by amplitude x sin(pi t), t from 0 to 1 along the member (as built)."""
    ref = np.asarray(g.reference_positions)
    ax = int(np.argmax(np.abs(g.member_axis[m])))
    p = s.positions
    for st in gs._strings_of_member(g, s, m):
        t = (ref[st, ax] - ref[st[0], ax]) / (ref[st[-1], ax] - ref[st[0], ax])
        p[st[1:-1], axis] += amplitude * np.sin(math.pi * t[1:-1])
    s.positions = p


def _same(a, b):
    return (math.isnan(a) and math.isnan(b)) or a == b


# --- the end transverse members are left out ----------------------------------------------------

def test_the_end_transverse_members_are_the_two_on_the_grid_ends():
    s, g, _ = _scene(ax=3, ay=2)
    ends, interior = _transverse(g)
    col = g.member_cell[:, 0]
    assert set(col[ends]) == {0, 3} and len(ends) == 4  # two columns x two rows
    assert set(col[interior]) == {1, 2}
    assert np.all(g.member_direction[ends] == "transverse")
    assert len(gs.measured_members(g, "longitudinal")) == len(g.members("longitudinal"))
    # A periodic sheet has no ends.
    sp = cd.Scene()
    mp = sp.add_material(woven.woven_material("detailed"))
    px, py = woven.preset_pitch("detailed")
    sp.set_periodic_cell(np.diag([2 * px, py, 0.1]), [True, True, False])
    gp = woven.woven_geogrid(sp, origin=(1e-3, 1e-3, 0.05), apertures_x=2, apertures_y=1,
                             material=mp, periodic=True)
    assert not gs.end_members(gp).any()
    assert len(gs.measured_members(gp, "transverse")) == len(gp.members("transverse"))


_TRANSVERSE_KEYS = ("transverse_sideways_displacement_rms_m",
                    "transverse_sideways_displacement_max_m",
                    "transverse_out_of_plane_mean_m", "transverse_sideways_chord_mean_m",
                    "transverse_tension_std_along_n", "transverse_tension_range_along_n",
                    "transverse_tension_std_across_n", "transverse_force_mean_n",
                    "transverse_mean_axial_strain")


@pytest.mark.parametrize("axis", [0, 2], ids=["in_plane", "out_of_plane"])
def test_a_bowed_end_transverse_member_changes_no_transverse_measure(axis):
    """002's element: the end transverse members bow 1.2–1.3 mm in plane under the pull. Here
    both end members are bowed by 1.25 mm (in plane, along x; or out of plane), and every
    transverse value of the history row (sideways displacement, waviness, tension along and
    across, force, strain, contacts, string gaps, entries) stays what it is for the straight
    grid; the per-member arrays still show the bow. The same bow of the interior member
    changes the transverse measures."""
    s0, g0, _ = _scene()
    s0.run(1)
    straight = gs.history_row(s0, g0, z_grid=0.0)
    s, g, _ = _scene()
    ends, interior = _transverse(g)
    for m in ends:
        _bow(s, g, m, 1.25e-3, axis)
    s.run(1)
    bowed_ends = gs.history_row(s, g, z_grid=0.0)
    for k, v in straight.items():
        if k.startswith("transverse_"):
            assert _same(bowed_ends[k], v), (k, bowed_ends[k], v)
    # The bow is there, member by member.
    sd = gs.member_sideways_displacement(s, g)["per_member_rms_m"]
    wav = gs.member_waviness(s, g)
    strain = gs.member_strain(s, g)["per_member"]
    assert np.all(strain[ends] > 1e-4)
    if axis == 0:
        assert np.all(sd[ends] > 5e-4)
    else:
        assert np.all(wav["out_of_plane_m"][ends] > 5e-4)
    # The interior member bowed the same way: the transverse measures see it.
    s2, g2, _ = _scene()
    _bow(s2, g2, int(interior[0]), 1.25e-3, axis)
    s2.run(1)
    bowed = gs.history_row(s2, g2, z_grid=0.0)
    changed = {k for k in _TRANSVERSE_KEYS if not _same(bowed[k], straight[k])}
    expected = {"transverse_tension_std_along_n", "transverse_tension_range_along_n",
                "transverse_force_mean_n", "transverse_mean_axial_strain"}
    expected |= ({"transverse_sideways_displacement_rms_m",
                  "transverse_sideways_displacement_max_m",
                  "transverse_sideways_chord_mean_m"} if axis == 0
                 else {"transverse_out_of_plane_mean_m"})
    assert expected <= changed, expected - changed
    if axis == 0:
        assert bowed["transverse_sideways_displacement_max_m"] == pytest.approx(1.25e-3,
                                                                               rel=0.02)
    else:
        assert bowed["transverse_out_of_plane_mean_m"] > 4e-4
    assert bowed["transverse_tension_std_along_n"] > 1.0
    assert bowed["transverse_mean_axial_strain"] > 1e-4


def test_contacts_and_entries_on_an_end_transverse_member_are_not_counted():
    """A grain resting on a string of an end transverse member is a grain–grid contact, but
    not a transverse contact per metre; on the interior member it is one. A sphere pushed
    between the strings of an end member is not an entry; between those of the interior one
    it is."""
    def grain_on(member, gap):
        s, g, grain = _scene()
        st = gs._strings_of_member(g, s, member)
        top = s.positions[st[0][5]]
        s.add_spheres([top + [0, 0, R_STRING + 2e-3 + gap]], [2e-3], material=grain)
        c = 0.5 * (s.positions[st[0][5]] + s.positions[st[1][5]])
        s.add_spheres([c + [0, 0, 0.2e-3]], [1e-3], material=grain)  # in the gap
        s.run(1)
        return s, g

    ends, interior = _transverse(_scene()[1])
    s, g = grain_on(int(ends[0]), -1e-6)
    c = gs.grid_contacts_per_metre(s, g)
    e = gs.single_string_entries(s, g)
    assert c["contacts"] >= 1 and c["transverse_per_m"] == 0
    assert e["transverse_grains"] == 0 and e["transverse_spheres"] == 0
    assert gs.interfriction(s, g)["transverse_contacts"] == 0
    s, g = grain_on(int(interior[0]), -1e-6)
    c = gs.grid_contacts_per_metre(s, g)
    e = gs.single_string_entries(s, g)
    length = gs.member_lengths(g)["transverse"]
    assert length == pytest.approx(g.pitch[1] - g.member_width)  # one interior member
    assert gs.member_lengths(g, interior=False)["transverse"] == pytest.approx(3 * length)
    n = gs.interfriction(s, g)["transverse_contacts"]
    assert n >= 1 and c["transverse_per_m"] == pytest.approx(n / length)
    assert e["transverse_grains"] == 1


# --- interfriction: |F_t| / (mu F_n) at grain–grid contacts ---------------------------------------

def _dragged(direction, steps, speed=1.0):
    """A 2 mm grain resting on a string sphere (1 um overlap) of a member of ``direction``
    (transverse: the interior one), the grid and the grain held; then dragged along the
    member at ``speed`` (m/s) for ``steps`` steps of 0.1 us."""
    s, g, grain = _scene(laws=True)
    m = int(gs.measured_members(g, direction)[0])
    top = s.positions[gs._strings_of_member(g, s, m)[0][5]]
    gid = int(s.add_spheres([top + [0, 0, R_STRING + 2e-3 - 1e-6]], [2e-3],
                            material=grain)[0])
    s.block_dofs([int(i) for i in g.spheres], "all")
    s.block_dofs(gid, "all")
    s.dt = 1e-7
    s.run(1)
    if steps:
        v = s.velocities
        v[gid] = speed * np.asarray(g.member_axis[m])
        s.velocities = v
        s.run(steps)
    return s, g


@pytest.mark.parametrize("direction", ["longitudinal", "transverse"])
def test_interfriction_of_a_resting_grain_is_zero(direction):
    s, g = _dragged(direction, 0)
    c = s.contacts()
    assert len(c["ids"]) == 1 and c["tan_phi"][0] == pytest.approx(0.5)  # the pair law's mu
    f = gs.interfriction(s, g)
    other = "transverse" if direction == "longitudinal" else "longitudinal"
    assert f["contacts"] == 1 and f[f"{direction}_contacts"] == 1
    assert f[f"{direction}_mean_ratio"] < 1e-9 and f["mean_ratio"] < 1e-9
    assert f[f"{direction}_sliding_fraction"] == 0 and f["sliding_fraction"] == 0
    assert f[f"{other}_contacts"] == 0 and math.isnan(f[f"{other}_mean_ratio"])


@pytest.mark.parametrize("direction", ["longitudinal", "transverse"])
def test_interfriction_of_a_dragged_grain_is_one(direction):
    """Dragged 4 um along the member (40 steps at 1 m/s): the tangential spring (k_s = 4.4e5
    N/m) needs 2.3 um to reach mu F_n = 0.99 N, so the contact slides: ratio 1."""
    s, g = _dragged(direction, 40)
    f = gs.interfriction(s, g)
    assert f[f"{direction}_contacts"] == 1
    assert f[f"{direction}_mean_ratio"] == pytest.approx(1.0, abs=1e-6)
    assert f[f"{direction}_sliding_fraction"] == 1.0
    row = gs.history_row(s, g, z_grid=0.0)
    assert row[f"{direction}_interfriction_sliding_fraction"] == 1.0
    assert row["interfriction_mean_ratio"] == pytest.approx(1.0, abs=1e-6)


def test_interfriction_of_a_grain_dragged_a_little_is_ks_u_over_mu_fn():
    """Dragged 1 um (10 steps): below the limit the ratio is k_s u_t / (mu F_n), about 0.44,
    and the contact does not slide."""
    s, g = _dragged("longitudinal", 10)
    c = s.contacts()
    expect = c["ks"][0] * 1e-6 / (c["tan_phi"][0] * c["normal_force"][0])
    f = gs.interfriction(s, g)
    assert 0.3 < expect < 0.6
    assert f["longitudinal_mean_ratio"] == pytest.approx(expect, rel=1e-3)
    assert f["longitudinal_sliding_fraction"] == 0


# --- gaps between the reinforcement and the grains ----------------------------------------------

R_GRAIN = 1.5e-3


def _layers(lift_above=0.0, lift_below=0.0):
    """A grain sphere (1.5 mm) right above and one right below every grid sphere, touching it,
    then the upper layer lifted by ``lift_above`` and the lower one lowered by
    ``lift_below`` (m). The grains above neighbouring grid spheres overlap each other: the
    scene is only measured, never stepped."""
    s, g, grain = _scene()
    p = np.asarray(s.positions)[g.spheres]
    h = R_STRING + R_GRAIN
    s.add_spheres(p + [0, 0, h + lift_above], [R_GRAIN] * len(p), material=grain)
    s.add_spheres(p - [0, 0, h + lift_below], [R_GRAIN] * len(p), material=grain)
    return s, g


def test_no_gap_under_grains_resting_on_the_grid():
    s, g = _layers()
    r = gs.grid_grain_gaps(s, g)
    for pre in ("", "longitudinal_", "transverse_"):
        assert abs(r[f"{pre}above_mean_m"]) < 1e-12 and abs(r[f"{pre}below_mean_m"]) < 1e-12
        assert r[f"{pre}unsupported_above_fraction"] == 0
        assert r[f"{pre}unsupported_below_fraction"] == 0
    assert len(r["above_m"]) == len(g.spheres)


def test_gaps_of_lifted_grains_are_the_lift():
    """The upper layer lifted by 0.7 mm: every grid sphere's gap above is 0.7 mm (the grain
    right above it is the nearest), below still 0; lifted by 2.5 mm (more than the grid
    sphere's 2 mm diameter): every grid sphere is unsupported from above."""
    s, g = _layers(lift_above=0.7e-3)
    r = gs.grid_grain_gaps(s, g)
    assert np.max(np.abs(r["above_m"] - 0.7e-3)) < 1e-9
    for pre in ("", "longitudinal_", "transverse_"):
        assert r[f"{pre}above_mean_m"] == pytest.approx(0.7e-3, abs=1e-9)
        assert abs(r[f"{pre}below_mean_m"]) < 1e-12
        assert r[f"{pre}unsupported_above_fraction"] == 0
    s, g = _layers(lift_above=2.5e-3, lift_below=0.3e-3)
    r = gs.grid_grain_gaps(s, g)
    assert r["above_mean_m"] == pytest.approx(2.5e-3, abs=1e-9)
    assert r["below_mean_m"] == pytest.approx(0.3e-3, abs=1e-9)
    assert r["unsupported_above_fraction"] == 1 and r["unsupported_below_fraction"] == 0
    row = gs.history_row(s, g, z_grid=0.0)
    assert row["gap_above_mean_m"] == pytest.approx(2.5e-3, abs=1e-9)
    assert row["longitudinal_unsupported_above_fraction"] == 1
    assert row["transverse_gap_below_mean_m"] == pytest.approx(0.3e-3, abs=1e-9)


def test_gaps_without_grains_on_a_side():
    """No grain below: every grid sphere is unsupported from below, the mean gap below is
    NaN (none to measure)."""
    s, g, grain = _scene()
    p = np.asarray(s.positions)[g.spheres]
    s.add_spheres(p + [0, 0, R_STRING + R_GRAIN + 1e-4], [R_GRAIN] * len(p), material=grain)
    r = gs.grid_grain_gaps(s, g)
    assert r["above_mean_m"] == pytest.approx(1e-4, abs=1e-9)
    assert math.isnan(r["below_mean_m"]) and r["unsupported_below_fraction"] == 1
    assert np.all(np.isinf(r["below_m"]))


def test_gaps_are_the_nearest_grain_sphere_of_a_sparse_layer():
    """A few grains far apart (more than the 16 nearest centres searched first): the gap of
    every grid sphere is its exact clear distance to the nearest grain above, by brute force."""
    s, g, grain = _scene()
    rng = np.random.default_rng(3)
    lo = np.asarray(g.reference_positions).min(axis=0)
    hi = np.asarray(g.reference_positions).max(axis=0)
    n = 60
    c = rng.uniform(lo - 5e-3, hi + 5e-3, (n, 3))
    c[:, 2] = rng.uniform(-8e-3, 8e-3, n)
    r = rng.uniform(1e-3, 3e-3, n)
    s.add_spheres(c, r, material=grain)
    out = gs.grid_grain_gaps(s, g)
    p = np.asarray(s.positions)[g.spheres]
    d = np.linalg.norm(p[:, None, :] - c[None, :, :], axis=2) - r[None, :] - R_STRING
    above = np.where(c[None, :, 2] > p[:, None, 2], d, np.inf).min(axis=1)
    below = np.where(c[None, :, 2] < p[:, None, 2], d, np.inf).min(axis=1)
    np.testing.assert_allclose(out["above_m"], np.maximum(above, 0), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["below_m"], np.maximum(below, 0), rtol=0, atol=1e-15)


# --- member strain ------------------------------------------------------------------------------

def test_member_strain_of_a_homogeneous_stretch():
    """The grid stretched by 1e-3 along x and 2.5e-3 along y: every longitudinal member's
    strain is 1e-3, every interior transverse member's 2.5e-3, within 1e-9."""
    s, g, _ = _scene(ax=3, ay=2)
    ref = np.asarray(g.reference_positions)
    o = ref.min(axis=0)
    p = s.positions
    p[g.spheres] = o + (ref - o) * [1 + 1e-3, 1 + 2.5e-3, 1]
    s.positions = p
    r = gs.member_strain(s, g)
    for k in ("mean", "min", "max"):
        assert r[f"longitudinal_{k}"] == pytest.approx(1e-3, abs=1e-9)
        assert r[f"transverse_{k}"] == pytest.approx(2.5e-3, abs=1e-9)
    assert np.all(np.abs(r["per_member"][g.member_direction == "transverse"] - 2.5e-3) < 1e-9)
    row = gs.history_row(s, g, z_grid=0.0)
    assert row["longitudinal_mean_axial_strain"] == pytest.approx(1e-3, abs=1e-9)
    assert row["transverse_mean_axial_strain"] == pytest.approx(2.5e-3, abs=1e-9)


def test_member_strain_as_built_and_after_a_rigid_motion_is_zero():
    s, g, _ = _scene()
    p = s.positions
    c, a = np.cos(0.3), np.sin(0.3)
    rot = np.array([[c, -a, 0], [a, c, 0], [0, 0, 1]])
    p[g.spheres] = p[g.spheres] @ rot.T + [1e-2, -2e-3, 5e-3]
    s.positions = p
    r = gs.member_strain(s, g)
    assert np.max(np.abs(r["per_member"])) < 1e-12


# --- the contact-normal rose's two inclined main directions ---------------------------------------

def _isotropic(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1)[:, None]


def _families(rng, angles_deg, n, spread_deg=4.0, plane=(0, 1)):
    a = np.deg2rad(rng.choice(angles_deg, n) + rng.normal(0, spread_deg, n))
    v = np.zeros((n, 3))
    v[:, plane[0]], v[:, plane[1]] = np.cos(a), np.sin(a)
    v += rng.normal(0, 0.1, (n, 3))  # out of the plane too
    v *= rng.choice([-1, 1], n)[:, None]
    return v / np.linalg.norm(v, axis=1)[:, None]


@pytest.mark.parametrize("n", [200, 20000])
def test_an_isotropic_sample_has_no_significant_inclined_pair(n):
    """Normals uniform on the sphere (fixed seed), weighted by forces uniform in [0.5, 2]:
    in every plane the rose's anisotropy of order 2 (the fabric tensor's deviator) and 4 stay
    below sqrt(7.6 / n_eff), the level an isotropic fabric exceeds with probability 1e-3
    (p_isotropic >= 1e-3), so no main direction is significant and there is no inclined
    pair."""
    rng = np.random.default_rng(59)
    u = _isotropic(rng, n)
    w = rng.uniform(0.5, 2.0, n)
    for plane in gf.PLANES:
        r = gf.main_directions(u, w, plane)
        level = math.sqrt(-math.log(gf.ISOTROPY_ALPHA / 2) / r["n_eff"])
        assert r["anisotropy_2"] < level and r["anisotropy_4"] < level, (plane, r)
        assert r["p_isotropic"] >= gf.ISOTROPY_ALPHA
        assert not r["significant"] and not r["inclined_pair"]
        f = gf.fabric_tensor(u, w, plane)
        dev = np.linalg.eigvalsh(f)
        assert dev[1] - dev[0] == pytest.approx(r["anisotropy_2"], abs=1e-12)
        if n >= 20000:
            assert r["directions_deg"] == []


def test_chance_peaks_of_a_small_isotropic_sample_are_not_significant():
    """60 isotropic normals (seed 34): the smoothed rose has two chance peaks at -48.5 and
    61.5 deg in plan, which principal_directions and is_inclined_pair take for 002's inclined
    pair (11 % of such samples of 30 normals, 2.4 % of 60, do); main_directions does not:
    p_isotropic = 0.27. Over 500 isotropic samples of 200 normals, the share called
    significant is about alpha (1e-3)."""
    rng = np.random.default_rng(34)
    u = _isotropic(rng, 60)
    w = rng.uniform(0.5, 2.0, 60)
    dirs = gf.principal_directions(u, w, "xy")
    assert gf.is_inclined_pair(dirs)
    r = gf.main_directions(u, w, "xy")
    assert r["directions_deg"] == dirs
    assert r["p_isotropic"] > 0.1 and not r["significant"] and not r["inclined_pair"]
    hits = 0
    for seed in range(500):
        rng = np.random.default_rng(1000 + seed)
        hits += gf.main_directions(_isotropic(rng, 200), rng.uniform(0.5, 2.0, 200),
                                   "xy")["significant"]
    assert hits <= 3


@pytest.mark.parametrize("angles,plane", [((40.0, -40.0), "xy"), ((35.0, 125.0), "xz"),
                                          ((45.0, -45.0), "yz")])
def test_two_imposed_inclined_families_are_found_at_their_angles(angles, plane):
    """Two families of normals (4 deg spread) at the given angles, 40 % of 2000 normals, the
    rest isotropic: both found within 3 deg, significant (p far below 1e-3), an inclined
    pair. The +-45 deg pair leaves the fabric tensor isotropic: the order-4 anisotropy
    finds it."""
    rng = np.random.default_rng(7)
    ij = gf.PLANES[plane]
    fam = _families(rng, list(angles), 800, plane=ij)
    n = np.concatenate([fam, _isotropic(rng, 1200)])
    w = rng.uniform(0.5, 2.0, len(n))
    r = gf.main_directions(n, w, plane)
    want = sorted(a - 180.0 if a > 90.0 else a for a in angles)
    assert len(r["directions_deg"]) == 2
    assert r["directions_deg"] == [pytest.approx(a, abs=3) for a in want]
    assert r["significant"] and r["p_isotropic"] < 1e-6 and r["inclined_pair"]
    assert all(d >= 1.5 for d in r["peak_density"])
    if abs(abs(angles[0] - angles[1]) - 90) < 1e-9 and abs(angles[0]) == 45:
        assert r["anisotropy_2"] < 0.05 < r["anisotropy_4"]


def test_axis_aligned_families_are_significant_but_not_an_inclined_pair():
    rng = np.random.default_rng(8)
    n = np.concatenate([_families(rng, [0.0, 90.0], 800), _isotropic(rng, 1200)])
    r = gf.main_directions(n, np.ones(len(n)), "xy")
    assert r["significant"] and not r["inclined_pair"]
    assert r["directions_deg"] == [pytest.approx(0, abs=3), pytest.approx(90, abs=3)]


def test_gaps_and_strain_of_a_periodic_sheet_use_the_images():
    """A periodic sheet (its strings close through the cell's faces): as built, every member's
    strain is 0; a grain 0.4 mm above the first junction sphere, placed one cell away along
    x, is found through its image."""
    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    px, py = woven.preset_pitch("detailed")
    s.set_periodic_cell(np.diag([2 * px, py, 0.1]), [True, True, False])
    g = woven.woven_geogrid(s, origin=(1e-3, 1e-3, 0.05), apertures_x=2, apertures_y=1,
                            material=m, periodic=True)
    assert np.max(np.abs(gs.member_strain(s, g)["per_member"])) < 1e-12
    grain = s.add_material(cd.linear_material(density=2600, young=1e7, poisson=0.3,
                                              friction_angle_deg=30))
    p0 = np.asarray(s.positions)[g.spheres[0]]
    s.add_spheres([p0 + [2 * px, 0, R_STRING + R_GRAIN + 0.4e-3]], [R_GRAIN], material=grain)
    assert gs.grid_grain_gaps(s, g)["above_m"][0] == pytest.approx(0.4e-3, abs=1e-12)
