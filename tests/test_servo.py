"""Servo walls and the triaxial controller: analytic equilibrium F = sigma A on one elastic
sphere for soft and stiff grains without retuning, a cap that caps, per-axis modes."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem import measure
from cpp_dem.protocols import prep


def one_sphere(young, gap=1e-4):
    s = dem.Scene(local_damping=0.3)
    m = s.add_material(dem.linear_material(density=2600, young=young, poisson=0.3,
                                           friction_angle_deg=30))
    r = 0.005
    walls = s.add_box((0, 0, 0), (0.02, 0.02, 2 * r + gap), material=m)
    s.add_spheres([[0.01, 0.01, r]], [r], material=m)
    return s, walls, r


@pytest.mark.parametrize("young", [1e6, 1e9])
def test_servo_holds_single_sphere_at_sigma_a(young):
    s, walls, r = one_sphere(young)
    area = 1e-4
    sigma = 1e-3 * young  # overlap ~ 1e-3 x area / r ... a fixed strain level
    servo = _core.ServoWall(wall=walls[5], target_stress=sigma, area=area, gain=0.5,
                            max_speed=0.01)
    s.add_controller(servo)
    s.set_auto_timestep(safety=0.5, period=10)
    for _ in range(100):  # converged in ~3000 steps (1 MPa) and ~4000 steps (1 GPa)
        s.run(500)
        f = s.wall_forces[walls[5]][2]  # the sphere pushes the top wall up (+z)
        if abs(f / (sigma * area) - 1) < 1e-6:
            break
    assert s.step_count <= 10_000
    assert abs(f / (sigma * area) - 1) < 1e-6
    # Analytic overlaps: each wall contact carries F with k = E r (000 eq 4, wall side).
    k = young * r
    assert abs(s.wall_positions[walls[5]] - (2 * r - 2 * sigma * area / k)) < 1e-9 * r
    assert abs(servo.stiffness / k - 1) < 1e-12


def test_velocity_cap_really_caps():
    s, walls, r = one_sphere(1e7, gap=0.005)
    cap = 0.02
    servo = _core.ServoWall(wall=walls[5], target_stress=1e6, area=1e-4, gain=1.0,
                            max_speed=cap)
    s.add_controller(servo)
    s.dt = 1e-6
    speeds = []
    for _ in range(400):
        s.run(5)
        speeds.append(abs(s.wall_velocities[walls[5]][2]))
    assert max(speeds) <= cap and max(speeds) == pytest.approx(cap)
    # The law itself: a huge error with a small stiffness still gives at most the cap.
    assert _core.servo_speed(1e9, 0.0, 1.0, 1e-6, 1e-8, 1, 1.0, cap) == cap
    assert _core.servo_speed(0.0, 1e9, 1.0, 1e-6, 1e-8, 1, 1.0, cap) == -cap


def test_bad_targets_are_refused():
    s, walls, _ = one_sphere(1e7)
    with pytest.raises(dem.ParameterError, match=r"target_stress=-1000.*compressive positive"):
        _core.ServoWall(wall=walls[5], target_stress=-1e3, area=1e-4, max_speed=0.1)
    with pytest.raises(dem.ParameterError, match="max_speed=0"):
        _core.ServoWall(wall=walls[5], target_stress=1e3, area=1e-4, max_speed=0.0)
    t = _core.TriaxialController(walls=walls, max_speed=0.1)
    with pytest.raises(dem.ParameterError, match=r"stress=-5.*compressive positive"):
        t.set_stress(0, -5.0)
    with pytest.raises(dem.ParameterError, match="axis=3"):
        t.set_strain_rate(3, 0.1)
    with pytest.raises(dem.ParameterError, match="6 walls"):
        _core.TriaxialController(walls=walls[:4], max_speed=0.1)


def lattice_box(young, n=4, r=0.005):
    s = dem.Scene(local_damping=0.3)
    m = s.add_material(dem.linear_material(density=2600, young=young, poisson=0.3,
                                           friction_angle_deg=20))
    L = 2 * r * n
    walls = s.add_box((0, 0, 0), (L, L, L), material=m)
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(0)
    s.add_spheres(r + 2 * r * g, r * (0.97 + 0.02 * rng.random(len(g))), material=m)
    s.set_auto_timestep(safety=0.5, period=50)
    return s, walls


@pytest.mark.parametrize("young", [1e6, 1e9])
def test_triaxial_controller_stress_and_strain_rate(young):
    s, walls = lattice_box(young)
    sigma = 2e-3 * young
    # Same settings for both moduli: the cap is a fraction of a radius per step.
    t = _core.TriaxialController(walls=walls, gain=0.5,
                                 max_speed=prep.default_max_speed(s, walls))
    s.add_controller(t)
    for a in range(3):
        t.set_stress(a, sigma)
    for _ in range(100):
        s.run(200)
        ax = measure.axis_stresses(s, walls)
        if np.all(np.abs(ax / sigma - 1) < 1e-3) and s.unbalanced_force() < 0.01:
            break
    assert np.all(np.abs(ax / sigma - 1) < 1e-3), ax
    # Strain-rate control of z: strain grows at the rate (engineering, from L0).
    t.reset_strain(s)
    t.set_strain_rate(2, 0.5)
    assert t.mode(2) == "strain_rate" and t.mode(0) == "stress"
    t0 = s.time
    s.run(500)
    eps = t.strains(s)
    assert eps[2] == pytest.approx(0.5 * (s.time - t0), rel=1e-9)
