"""Targets that are never met, and geometry outside the box: each ends in an error or a
warning naming the target (or body), what was reached (or where it is), and why."""

import math
import types
import warnings

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem.measure import inertial
from cpp_dem.protocols import periodic
from cpp_dem.protocols import prep
from cpp_dem.protocols import pullout
from cpp_dem.build import psd
from cpp_dem.build.clumps import ClumpTemplate
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import build_box_sample


def _mat(scene, young=1e7):
    return scene.add_material(dem.linear_material(density=2650, young=young, poisson=0.3,
                                                  friction_angle_deg=30))


def _box_with_sphere(r=0.005):
    s = dem.Scene(local_damping=0.3)
    m = _mat(s)
    walls = s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    s.add_spheres([[0.05, 0.05, r]], [r], material=m)
    s.set_auto_timestep(safety=0.5)
    return s, m, walls


# ---- a ServoWall that never reaches its target --------------------------------------------


def test_a_servo_wall_that_never_reaches_its_target_is_reported_once_and_one_that_does_not():
    s, _, walls = _box_with_sphere()
    # The top wall is 9 cm above the sphere and may move 1e-6 m/s: it cannot arrive.
    servo = dem.ServoWall(wall=walls[5], target_stress=1e4, box_walls=walls, max_speed=1e-6)
    s.add_controller(servo)
    with pytest.warns(dem.ControllerLimitWarning) as rec:
        s.run(300)
    msg = str(rec[0].message)
    assert "wall 5" in msg and "has not reached its target 10000 Pa" in msg
    # (its own class, a ControllerLimitWarning: a loop that judges its targets filters it)
    assert type(rec[0].message) is dem.ServoTargetWarning
    assert "the stress is 0 Pa" in msg and "speed cap 1e-06 m/s for all 300 calls" in msg
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.ControllerLimitWarning)
        s.run(300)  # once per target
    servo.target_stress = 2e4  # a new target is watched again
    s.strict_controllers = True
    with pytest.raises(RuntimeError, match=r"has not reached its target 20000 Pa"):
        s.run(300)
    # A servo that reaches its target within the run is not reported.
    s = dem.Scene(local_damping=0.3)
    m = _mat(s, young=1e6)
    r = 0.005
    walls = s.add_box((0, 0, 0), (0.02, 0.02, 2 * r + 1e-4), material=m)
    s.add_spheres([[0.01, 0.01, r]], [r], material=m)
    servo = _core.ServoWall(wall=walls[5], target_stress=1e3, area=1e-4, gain=0.5,
                            max_speed=0.01)
    s.add_controller(servo)
    s.set_auto_timestep(safety=0.5, period=10)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.ControllerLimitWarning)
        s.run(10_000)  # converged within ~3000 steps (tests/test_servo.py)
    assert abs(servo.measured_stress / 1e3 - 1) < 0.05


# ---- two controllers on one wall, one controller twice --------------------------------------


def test_two_controllers_on_one_wall_are_refused():
    s, _, walls = _box_with_sphere()
    s.add_controller(dem.TriaxialController(walls=walls, max_speed=1e-3))
    with pytest.raises(dem.ParameterError,
                       match=r"wall 5 is moved by controller 0 \(TriaxialController\) already"):
        s.add_controller(dem.ServoWall(wall=walls[5], target_stress=1e4, box_walls=walls,
                                       max_speed=1e-3))
    assert s.num_controllers() == 1
    # A disabled one may share the wall (a preparation's controller, put aside) ...
    s.controller(0).enabled = False
    servo = dem.ServoWall(wall=walls[5], target_stress=1e4, box_walls=walls, max_speed=1e-3)
    s.add_controller(servo)
    with pytest.raises(dem.ParameterError, match=r"is controller 1 of the scene already"):
        s.add_controller(servo)
    # ... but not once it is enabled again: refused before the run, naming both.
    s.controller(0).enabled = True
    with pytest.raises(dem.ParameterError,
                       match=r"controllers 0 \(TriaxialController\) and 1 \(ServoWall\) are "
                             r"both enabled and both move wall 5"):
        s.run(1)
    assert s.step_count == 0
    # Controllers that move no wall, and walls of their own, are fine.
    s.controller(0).enabled = False
    s.add_controller(dem.ServoWall(wall=walls[4], target_stress=1e4, box_walls=walls,
                                   max_speed=1e-3))
    s.add_controller(dem.RadiusGrowth(walls=walls, target_stress=1e4))
    assert s.num_controllers() == 4


# ---- a tensile target on a periodic cell ------------------------------------------------------


def test_a_tensile_normal_stress_target_on_a_periodic_cell_is_refused():
    c = dem.CellController(gain=0.3, max_rate=1.0)
    with pytest.raises(dem.ParameterError,
                       match=r"stress \(1, 1\)=-5000 Pa: a tensile normal stress; a periodic "
                             r"cell of cohesionless grains cannot hold tension"):
        c.set_stress(1, 1, -5e3)
    c.set_stress(0, 1, -5e3)  # a shear stress may have either sign
    c.set_stress(2, 2, 0.0)
    centers, radii, edge = periodic.cube_cloud(20, 0.001, 0.2, 1, 0.25)
    s = periodic.periodic_scene(centers, radii, periodic.cube_cell(edge),
                                material=dem.linear_material(density=2650, young=1e8,
                                                             poisson=0.3,
                                                             friction_angle_deg=30))
    with pytest.raises(dem.ParameterError, match=r"stress \(0, 0\)=-1000 Pa: a tensile"):
        periodic.drive_cell(s, stress=(-1e3, 1e3, 1e3), max_steps=10)
    assert s.step_count == 0


# ---- a triaxial from a packing of one sphere --------------------------------------------------


def test_a_triaxial_from_a_packing_of_one_sphere_is_refused(tmp_path):
    from geogrid_dem.cases import triaxial as case

    f = tmp_path / "one.csv"
    dem.write_packing_csv(f, np.array([[0.05, 0.05, 0.05]]), np.array([0.01]))
    p = case.Params(packing=str(f))
    with pytest.raises(SystemExit, match=r"one.csv: 1 sphere; a triaxial sample needs at "
                                         r"least 10 grains"):
        case.make_sample(p, lambda msg: None)


# ---- inertial numbers of quasi-static stages --------------------------------------------------


def test_inertial_number_definition_and_limit():
    # I = gamma_dot d / sqrt(p / rho): 1 1/s, 1 mm, 2650 Pa, 2650 kg/m^3 -> 1e-3.
    assert inertial.inertial_number(1.0, 1e-3, 2650.0, 2650.0) == pytest.approx(1e-3)
    assert inertial.QUASI_STATIC_LIMIT == 1e-2
    with pytest.raises(dem.ParameterError, match=r"pressure=0.0: must be > 0 \(Pa\)"):
        inertial.inertial_number(1.0, 1e-3, 0.0, 2650.0)


def _fake_pullout(velocity_ok=True):
    s, m, _ = _box_with_sphere(r=0.012)
    return types.SimpleNamespace(scene=s, grain_material=m, top_servo=None,
                                 top_stress=lambda: 25e3)


def test_a_pull_out_above_the_quasi_static_inertial_number_warns():
    sample = _fake_pullout()
    rho, sigma = 2650.0, 25e3
    fast = 6.4 * math.sqrt(sigma / rho)  # I = 6.4, the audit's pull
    with pytest.warns(dem.InertialNumberWarning,
                      match=r"pull-out: inertial number I = 6.4 at pull velocity 19.66 m/s, "
                            r"mean grain diameter 0.024 m, pressure 2.5e\+04 Pa"):
        pullout._check_pull_rate(sample, fast)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.InertialNumberWarning)
        pullout._check_pull_rate(sample, 3.2e-3 * math.sqrt(sigma / rho))  # 'balanced' preset


def test_a_triaxial_loading_above_the_quasi_static_inertial_number_warns():
    r = psd.radii_uniform(0.005, 0.0015, 40, seed=1)
    c, r = loose_cloud(r * 0.75, (0, 0, 0), (0.05, 0.05, 0.05), seed=1)
    sample = build_box_sample(c, r, (0, 0, 0), (0.05, 0.05, 0.05), young=1e7, poisson=0.3,
                              friction_deg=30, density=2650, local_damping=0.3)
    d = float(np.mean(2 * r))
    rate = 0.5 * math.sqrt(75e3 / 2650) / d  # I = 0.5
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.InertialNumberWarning)
        with pytest.raises(dem.InertialNumberWarning,
                           match=r"triaxial deviatoric stage: inertial number I = 0.5 "):
            from cpp_dem.protocols.triaxial import deviatoric_stage

            deviatoric_stage(sample, 75e3, rate, 0.01)


def test_a_dem_element_strain_increment_above_the_quasi_static_inertial_number_warns_once():
    centers, radii, edge = periodic.cube_cloud(40, 0.001, 0.2, 2, 0.3)
    f = 0.5 ** (1 / 3)  # the cell shrunk to a solid fraction of 0.6: the grains overlap
    s = periodic.periodic_scene(centers * f, radii, periodic.cube_cell(edge * f),
                                material=dem.linear_material(density=2650, young=1e8,
                                                             poisson=0.3,
                                                             friction_angle_deg=30))
    s.run(1)
    el = dem.DemElement(s)
    p = abs(float(np.trace(np.asarray(s.cell_stress())))) / 3
    assert p > 0
    fast = 0.5 * math.sqrt(p / 2650) / float(np.mean(2 * np.asarray(s.radii)))  # I = 0.5
    with pytest.warns(dem.InertialNumberWarning,
                      match=r"DemElement \(periodic\) strain increment .*: inertial number "
                            r"I = 0.5 "):
        el._check_rate(fast)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.InertialNumberWarning)
        el._check_rate(fast)  # once per element


# ---- a porosity target -----------------------------------------------------------------------


def _refd_sample(seed=4):
    r = psd.radii_uniform(0.005, 0.0015, 250, seed=seed)
    c, r = loose_cloud(r * 0.75, (0, 0, 0), (0.07, 0.07, 0.07), seed=seed)
    return build_box_sample(c, r, (0, 0, 0), (0.07, 0.07, 0.07), young=1e7, poisson=0.3,
                            friction_deg=30, density=2650, local_damping=0.3)


def test_a_porosity_no_packing_reaches_is_refused_up_front():
    s = _refd_sample()
    for bad in (0.95, 0.0, float("nan")):
        with pytest.raises(dem.ParameterError, match=rf"porosity={bad}: must be in \(0, 0.6\]"):
            prep.refd(s.scene, s.walls, s.material, stress=2e4, porosity=bad,
                      accept_denser=True)
    assert s.scene.step_count == 0
    e = dem.Scene()
    m = _mat(e)
    walls = e.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    e.add_spheres([[0.05, 0.05, 0.05], [0.02, 0.02, 0.02]], [0.01, 0.01], material=m)
    with pytest.raises(dem.ParameterError, match=r"porosity=0.25: below 0.2595, the densest "
                                                 r"packing of equal spheres"):
        prep.refd(e, walls, m, stress=2e4, porosity=0.25)


def test_a_porosity_target_the_sample_is_already_denser_than_warns():
    s = _refd_sample()
    with pytest.warns(dem.TargetNotMetWarning,
                      match=r"porosity=0.55: not met; the expansion to 20000 Pa already packed "
                            r"the sample to porosity 0\.4"):
        res = prep.refd(s.scene, s.walls, s.material, stress=2e4, porosity=0.55,
                        accept_denser=True, max_steps_per_stage=60_000)
    assert res.porosity < 0.55 - prep.POROSITY_MISS


# ---- geometry outside the box -----------------------------------------------------------------


def test_a_sphere_moved_outside_through_the_positions_setter_is_refused_at_run():
    s, _, _ = _box_with_sphere()
    x = np.asarray(s.positions)
    x[0] = (0.05, 0.05, 0.15)
    s.positions = x
    with pytest.raises(dem.ParameterError, match=r"body 0 \(sphere\) at \[0.05, 0.05, 0.15\] "
                                                 r"m: behind wall 5 \(z <= 0.1 m is inside\)"):
        s.run(1)
    assert s.step_count == 0
    x[0] = (0.05, 0.05, 0.05)
    s.positions = x
    s.run(1)  # inside again


def test_spheres_added_before_the_walls_are_checked_at_the_first_run():
    s = dem.Scene()
    m = _mat(s)
    s.add_spheres([[0.05, 0.05, 0.05], [-0.02, 0.05, 0.05]], [0.005, 0.005], material=m)
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    s.set_auto_timestep(safety=0.5)
    with pytest.raises(dem.ParameterError, match=r"body 1 \(sphere\) at \[-0.02, 0.05, 0.05\] "
                                                 r"m: behind wall 0 \(x >= 0 m is inside\)"):
        s.run(1)


def test_a_clump_outside_the_box_is_refused_at_run():
    s = dem.Scene()
    m = _mat(s)
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    t = ClumpTemplate.from_spheres([[0, 0, 0], [0.01, 0, 0]], [0.006, 0.006])
    s.add_clumps(t, [[0.05, 0.05, 0.05], [0.05, 0.3, 0.05]], material=m)
    s.set_auto_timestep(safety=0.5)
    with pytest.raises(dem.ParameterError, match=r"\(member of clump 1\) at .*behind wall 3 "
                                                 r"\(y <= 0.1 m is inside\)"):
        s.run(1)


def test_a_geogrid_through_a_wall_is_refused_at_run():
    s = dem.Scene()
    m = _mat(s)
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    beam = dem.BeamParams(young=1e9, poisson=0.3, radius=0.001)
    dem.geogrid.square_grid(s, origin=(0.02, 0.02, 0.05), length=0.12, width=0.06,
                            nodes_x=4, nodes_y=3, params=beam, material=m, density=1000.0)
    s.set_auto_timestep(safety=0.5)
    with pytest.raises(dem.ParameterError, match=r"\(geogrid node\) at \[0.14, 0.02, 0.05\] "
                                                 r"m: behind wall 1"):
        s.run(1)


def test_a_second_box_is_refused():
    s, m, _ = _box_with_sphere()
    with pytest.raises(dem.ParameterError, match=r"the scene has walls already \(wall 0, x- at "
                                                 r"0 m\); a box is added once"):
        s.add_box((0, 0, 0), (0.2, 0.2, 0.2), material=m)
    assert s.num_walls == 6


# ---- bonds ------------------------------------------------------------------------------------


def test_a_bond_across_a_wide_gap_is_refused():
    s = dem.Scene()
    m = _mat(s)
    ids = s.add_spheres([[0, 0, 0], [0.025, 0, 0], [0.05, 0, 0], [1.0, 0, 0]],
                        [0.01, 0.01, 0.01, 0.01], material=m)
    p = dem.BondParams(kn=1e5)
    s.add_bond(int(ids[0]), int(ids[1]), p)  # gap 5 mm: half the radius
    with pytest.raises(dem.ParameterError, match=r"bond 2-3: surface gap 0.93 m; must be <= "
                                                 r"0.01 m \(the smaller radius\)"):
        s.add_bond(int(ids[2]), int(ids[3]), p)
    assert s.num_bonds == 1


def test_a_parallel_bond_radius_factor_above_one_is_refused():
    assert dem.BondParams(kn=1e5, pb_kn=1e9, pb_radius_factor=1.0).pb_radius_factor == 1.0
    with pytest.raises(dem.ParameterError, match=r"pb_radius_factor=1.5: must be in \(0, 1\]"):
        dem.BondParams(kn=1e5, pb_kn=1e9, pb_radius_factor=1.5)
