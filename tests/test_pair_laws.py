"""Laws per pair of materials (issue 16): 002's Hertz–Mindlin grains with mu = 0.8, a linear
grain–geogrid contact with its own k_n, k_s and mu = 0.5."""

import math

import numpy as np
import pytest

import cpp_dem as cd


def _scene():
    s = cd.Scene()
    grain = s.add_material(cd.hertz_mindlin_material(density=2640, shear_modulus=3e10 / 100,
                                                     poisson=0.2, friction_coefficient=0.8))
    grid = s.add_material(cd.linear_material(density=1030, young=1e8, poisson=0.25,
                                             friction_angle_deg=math.degrees(math.atan(0.5))))
    return s, grain, grid


def _touching(s, ma, mb, overlap=1e-6, r=1e-3):
    a = s.add_spheres([[0, 0, 0]], [r], material=ma)
    b = s.add_spheres([[2 * r - overlap, 0, 0]], [r], material=mb)
    s.dt = 1e-8
    s.run(1)
    c = s.contacts()
    ids = c["ids"]
    k = int(np.flatnonzero((ids[:, 0] == min(a[0], b[0])) & (ids[:, 1] == max(a[0], b[0])))[0])
    return c, k


def test_pair_law_sets_stiffness_and_friction():
    s, grain, grid = _scene()
    s.set_pair_law(grain, grid, model="linear", kn=3.9e6, ks=9e5, friction=0.5)
    c, k = _touching(s, grain, grid)
    assert c["kn"][k] == 3.9e6 and c["ks"][k] == 9e5
    assert c["tan_phi"][k] == 0.5
    # The force is the linear law's with these stiffnesses.
    assert np.linalg.norm(c["force"][k]) == pytest.approx(3.9e6 * 1e-6, rel=1e-9)


def test_other_pairs_keep_the_mixing_rules():
    s, grain, grid = _scene()
    s.set_pair_law(grain, grid, model="linear", kn=3.9e6, ks=9e5, friction=0.5)
    c, k = _touching(s, grain, grain)
    ref = cd.mix_materials(s.material(grain), s.material(grain), 1e-3, 1e-3,
                           s.masses[0], s.masses[1])
    # Hertz: the tangent stiffness 1.5 K overlap^0.5 with the mixed K.
    assert c["kn"][k] == pytest.approx(1.5 * ref.kn * math.sqrt(c["overlap"][k]), rel=1e-12)
    assert c["tan_phi"][k] == pytest.approx(0.8)


def test_pair_law_reaches_existing_contacts_and_walls():
    s, grain, grid = _scene()
    c, k = _touching(s, grid, grid)
    kn_mixed = c["kn"][k]
    s.set_pair_law(grid, grid, kn=2 * kn_mixed)
    s.run(1)
    assert s.contacts()["kn"][k] == 2 * kn_mixed
    assert s.pair_laws[0]["kn"] == 2 * kn_mixed
    # A wall of the geogrid's material against a grain.
    w = s.add_wall(axis=2, position=-0.01, sense=1, material=grid)
    s.set_pair_law(grain, grid, model="linear", kn=1e6, ks=2e5, friction=0.5)
    g = s.add_spheres([[0.1, 0, -0.01 + 1e-3 - 1e-7]], [1e-3], material=grain)
    s.run(1)
    assert s.wall_forces[w][2] == pytest.approx(-1e6 * 1e-7, rel=1e-6)
    assert g[0] >= 0


def test_pair_laws_are_listed_and_replaced():
    s, grain, grid = _scene()
    s.set_pair_law(grid, grain, friction=0.5)
    s.set_pair_law(grain, grid, friction=0.6)
    assert s.pair_laws == [dict(a=grain, b=grid, model=None, kn=None, ks=None, friction=0.6,
                                damping_normal=None, damping_shear=None)]


@pytest.mark.parametrize("kw, field", [(dict(kn=-1.0), "kn"), (dict(friction=-0.5), "friction"),
                                       (dict(damping_normal=1.5), "damping_normal"),
                                       (dict(model="bogus"), "model")])
def test_bad_pair_laws_name_the_field(kw, field):
    s, grain, grid = _scene()
    with pytest.raises(cd.ParameterError, match=field):
        s.set_pair_law(grain, grid, **kw)


def test_linear_stiffness_on_a_hertz_pair_is_refused():
    s, grain, grid = _scene()
    with pytest.raises(cd.ParameterError, match="hertz_mindlin"):
        s.set_pair_law(grain, grain, kn=1e6)
    with pytest.raises(cd.ParameterError, match="material"):
        s.set_pair_law(grain, 9, friction=0.5)


def test_time_step_floor_takes_the_pair_law_stiffness():
    """A grain with no contact yet is given at least one contact of its material's stiffest
    pair law in the critical time step: a soft grain (E R = 4e5 N/m) above 002's grid
    (grid-grain k_n = 3.9e6 N/m) gets a step that stays stable when it lands. (Measured
    before: 3 x too large a step, and the grain bounced off the grid at 4 m/s.)"""
    from cpp_dem.build import woven

    s = cd.Scene()
    gm = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=gm)
    s.block_dofs(g.spheres, "all")
    soft = s.add_material(cd.linear_material(density=2640, young=1e8, poisson=0.25,
                                             friction_angle_deg=30))
    s.add_spheres([[0.0, 0.0, 0.01]], [0.004], material=soft)
    m = s.masses[-1]
    assert s.critical_dt() == pytest.approx(math.sqrt(2 * m / (1e8 * 0.004)), rel=1e-12)
    woven.set_grid_laws(s, gm, soft, convention="contact")  # Table 1's 3.9e6 as the contact's
    assert s.critical_dt() == pytest.approx(math.sqrt(2 * m / 3.9e6), rel=1e-12)
