"""Tunnelling (issue 20, item 1): a body that moves more than ``max_step_ratio`` of its radius
in one step stops the run with BlowUpError naming the step, the body and its speed, before
any recorder can write the state (item 2: no inf in results)."""

import numpy as np
import pytest

import cpp_dem as dem

R = 0.005  # grain radius, m


def grains_in_box(gravity=(0.0, 0.0, -9.81)):
    """64 grains on a lattice in a 0.1 m box, automatic time step."""
    s = dem.Scene(gravity=gravity)
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    g = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    s.add_spheres(0.02 + 0.02 * g, np.full(len(g), R), material=m)
    s.set_auto_timestep(safety=0.8, period=100)
    return s


def launch(s, body, v):
    vel = s.velocities
    vel[body] = v
    s.velocities = vel


@pytest.mark.parametrize("speed", [1e4, 1e3])
def test_fast_grain_into_the_floor_is_stopped(speed):
    s = grains_in_box()
    launch(s, 5, (0.0, 0.0, -speed))
    with pytest.raises(dem.BlowUpError, match=r"step 0: body 5 moved .* \(speed (1e\+04|1000) m/s"):
        s.run(2000)
    # It was stopped within the step that would have tunnelled: still near the box.
    assert s.positions[5, 2] > -1.0


def test_huge_gravity_is_stopped():
    s = grains_in_box(gravity=(0.0, 0.0, -1e30))
    with pytest.raises(dem.BlowUpError, match="tunnelling"):
        s.run(100)


def test_overflowing_velocity_stops_before_anything_is_recorded():
    s = grains_in_box()
    launch(s, 3, (1e307, 0.0, 0.0))
    with pytest.raises(dem.BlowUpError, match=r"body 3 moved"):
        s.run(10)


def test_a_grain_just_below_the_limit_runs_and_one_just_above_stops():
    # One grain alone in the middle of the box: nothing to touch within a few steps.
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    s.add_spheres([[0.05, 0.05, 0.05]], [R], material=m)
    s.dt = 1e-4
    assert s.max_step_ratio == 1.0  # the default
    launch(s, 0, (0.9 * R / 1e-4, 0.0, 0.0))  # 0.9 R per step: allowed
    s.run(1)
    launch(s, 0, (-1.1 * R / 1e-4, 0.0, 0.0))
    with pytest.raises(dem.BlowUpError, match="body 0 moved .* max_step_ratio=1 "):
        s.run(1)
    s.max_step_ratio = 0.5
    launch(s, 0, (0.6 * R / 1e-4, 0.0, 0.0))
    with pytest.raises(dem.BlowUpError, match="max_step_ratio=0.5 "):
        s.run(1)


def test_a_settling_packing_is_not_flagged():
    s = grains_in_box()
    s.run(3000)  # falls and settles under gravity
    assert np.all(np.isfinite(s.positions))
    assert s.positions[:, 2].min() > 0


@pytest.mark.parametrize("bad", [0.0, -1.0, 3.0, float("nan")])
def test_max_step_ratio_is_validated(bad):
    s = grains_in_box()
    with pytest.raises(dem.ParameterError, match="max_step_ratio"):
        s.max_step_ratio = bad


def test_a_geogrid_node_may_move_its_radius_plus_the_smallest_grain_radius():
    # A node is a member of radius R_c; what it must not cross is a grain of radius r, along
    # which the deep-overlap band is r + 2 R_c long: the limit is (R_c + r_min) per step.
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_box((0, 0, 0), (0.2, 0.2, 0.2), material=m)
    s.add_spheres([[0.15, 0.15, 0.15]], [R], material=m)
    rc = 0.001
    node = [s._add_grid_nodes(np.array([[0.05, 0.05, 0.05]]), rc, np.array([1e-3]),
                              np.array([1e-9]), m)]
    s.dt = 1e-4
    launch(s, int(node[0]), (0.9 * (rc + R) / 1e-4, 0.0, 0.0))  # 5.4 mm per step: allowed
    s.run(1)
    launch(s, int(node[0]), (-1.1 * (rc + R) / 1e-4, 0.0, 0.0))
    with pytest.raises(dem.BlowUpError, match="its radius plus the smallest grain's 0.006 m"):
        s.run(1)
