"""Measurements against analytic values: Love–Weber of a confined sphere, coordination."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem import measure


def test_love_weber_single_confined_sphere_equals_wall_stress():
    s = dem.Scene(local_damping=0.3)
    m = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    r = 0.005
    walls = s.add_box((0, 0, 0), (0.012, 0.014, 2 * r), material=m)
    s.add_spheres([[0.006, 0.007, r]], [r], material=m)
    servo = _core.ServoWall(wall=walls[5], target_stress=5e4, gain=0.5, max_speed=0.01,
                            box_walls=walls)
    s.add_controller(servo)
    s.set_auto_timestep(0.5, 10)
    s.run(3000)
    ws = measure.wall_stresses(s, walls)
    lw = measure.love_weber_stress(s, measure.box_volume(s, walls))
    assert ws[5] == pytest.approx(5e4, rel=1e-6) and ws[4] == pytest.approx(5e4, rel=1e-6)
    assert lw[2, 2] == pytest.approx(ws[5], rel=1e-9)
    assert np.allclose(lw[:2, :], 0) and np.allclose(lw[:, :2], 0)
    # The area the servo used is the current box face.
    assert servo.area == pytest.approx(0.012 * 0.014)


def test_coordination_of_a_cubic_lattice_and_rattlers():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    r = 0.005
    g = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    # Slight overlap so that neighbours touch; one extra sphere far away (a rattler).
    c = np.vstack([r + 1.99 * r * g, [[0.2, 0.2, 0.2]]])
    s.add_spheres(c, np.full(len(c), r), material=m)
    s.run(1)
    # 3x3x3 cubic lattice: 54 bonds; 28 spheres.
    assert measure.coordination_number(s) == pytest.approx(2 * 54 / 28)
    # Mechanical: the rattler goes, then corner spheres (3 contacts) stay: 54 bonds / 27.
    assert measure.coordination_number(s, mechanical=True) == pytest.approx(2 * 54 / 27)


# ---- packing measures (cpp_dem.measure, from the deposition case) --------------------------

def test_slab_solid_volume_is_exact_for_cut_spheres():
    from cpp_dem.measure import slab_solid_volume

    r = np.array([0.01, 0.02])
    z = np.array([0.0, 1.0])
    # The slab [-0.01, 0.0] holds the lower half of sphere 0 and nothing of sphere 1.
    assert slab_solid_volume(z, r, -0.01, 0.0) == pytest.approx(2 / 3 * np.pi * 0.01**3,
                                                                 rel=1e-12)
    # A slab holding both whole.
    whole = 4 / 3 * np.pi * (0.01**3 + 0.02**3)
    assert slab_solid_volume(z, r, -1.0, 2.0) == pytest.approx(whole, rel=1e-12)
    # A cap of height h = r / 2 of sphere 1: pi h^2 (3 r - h) / 3.
    h = 0.01
    assert slab_solid_volume(z, r, 1.02 - h, 5.0) == pytest.approx(
        np.pi * h**2 * (3 * 0.02 - h) / 3, rel=1e-9)


def test_interior_porosity_and_surface_height_of_a_cubic_lattice():
    from cpp_dem.measure import interior_porosity, surface_height

    d = 0.01  # lattice spacing = diameter: simple cubic, porosity 1 - pi/6
    g = np.stack(np.meshgrid(*[np.arange(10)] * 3, indexing="ij"), -1).reshape(-1, 3)
    pos = (g + 0.5) * d
    radii = np.full(len(pos), d / 2)
    box = (0.1, 0.1, 0.1)
    phi = interior_porosity(pos, radii, box, inset=2 * d, z_top=0.08)
    assert phi == pytest.approx(1 - np.pi / 6, abs=1e-12)
    assert surface_height(pos, radii, box) == pytest.approx(0.1, rel=1e-12)
    assert np.isnan(interior_porosity(pos, radii, box, inset=0.03, z_top=0.05))
