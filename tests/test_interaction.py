"""The interaction measures of cpp_dem.measure.grid_soil on hand-placed grains (issue 16)."""

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem.measure import grid_soil as interaction
from cpp_dem.build import woven


def _grid_and_grain():
    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m)
    grain = s.add_material(cd.linear_material(density=2600, young=1e7, poisson=0.3,
                                              friction_angle_deg=30))
    return s, g, grain


def test_straight_grid_has_no_waviness():
    s, g, _ = _grid_and_grain()
    w = interaction.member_waviness(s, g)
    assert np.all(w["out_of_plane_m"] < 1e-15) and np.all(w["sideways_m"] < 1e-15)


def test_waviness_is_the_rms_deviation_from_the_string_chord():
    s, g, _ = _grid_and_grain()
    m = int(g.members("longitudinal")[0])
    strings = interaction._strings_of_member(g, s, m)
    pos = s.positions
    mid = strings[0][len(strings[0]) // 2]
    pos[mid, 2] += 1e-4  # one sphere of one string lifted by 0.1 mm
    s.positions = pos
    n = sum(len(x) for x in strings)
    w = interaction.member_waviness(s, g)
    assert w["out_of_plane_m"][m] == pytest.approx(1e-4 / np.sqrt(n), rel=1e-9)


def test_a_grain_resting_on_two_strings_touches_both_but_has_not_entered():
    """A 2 mm grain resting on two strings 4.5 mm apart (1 um overlap): two grid contacts,
    counted per metre of longitudinal member, but not a single-string entry; pushed 1 mm
    deeper (the strings spread to make room) it has entered."""
    s, g, grain = _grid_and_grain()
    m = int(g.members("longitudinal")[0])
    strings = interaction._strings_of_member(g, s, m)
    a, b = strings[0][5], strings[1][5]
    pa, pb = s.positions[a], s.positions[b]
    h = np.sqrt((2e-3 + 1e-3) ** 2 - (0.5 * np.linalg.norm(pb - pa)) ** 2) - 1e-6
    s.add_spheres([0.5 * (pa + pb) + [0, 0, h]], [2e-3], material=grain)
    s.dt = 1e-8
    s.run(1)
    r = interaction.grains_between_strings(s, g)
    assert r["grains_entered"] == 0 and r["spheres_entered"] == 0
    c2 = interaction.grid_contacts_per_metre(s, g)
    assert c2["contacts"] == 2 and c2["grains_touching"] == 1
    assert c2["longitudinal_per_m"] == pytest.approx(2 / interaction.member_lengths(g)["longitudinal"])
    pos = s.positions
    pos[strings[0][1:-1], 1] -= 0.7e-3
    pos[strings[1][1:-1], 1] += 0.7e-3
    pos[-1, 2] -= 1e-3
    s.positions = pos
    r = interaction.grains_between_strings(s, g)
    assert r["longitudinal_grains"] == 1 and r["longitudinal_spheres"] == 1


def test_a_grain_in_the_aperture_is_counted():
    s, g, grain = _grid_and_grain()
    centre = np.asarray(g.reference_positions).mean(axis=0)
    s.add_spheres([centre + [0, 0, 0.5e-3]], [2e-3], material=grain)  # crosses the plane
    s.add_spheres([centre + [0, 0, 5e-3]], [2e-3], material=grain)    # above it
    r = interaction.grains_in_apertures(s, g)
    assert r["grains_in_apertures"] == 1 and r["per_aperture"] == [[1]]


def test_force_profile_of_a_prestressed_grid_is_uniform():
    from cpp_dem.protocols.prestress import Prestress

    s = cd.Scene(local_damping=0.7)
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=3, apertures_y=1, material=m)
    s.dt = 0.5 * s.critical_dt()
    p = Prestress(s, g, tension_n=20.0)
    p.tension(100000)
    s.run(5000)
    f = interaction.member_force_profiles(s, g)
    assert f["longitudinal_cov_mean"] < 0.01
    assert f["longitudinal_force_mean_n"] == pytest.approx(20.0, rel=0.01)
