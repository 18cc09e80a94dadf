"""Controllers that hit their limits (issue 20, item 3): a stress-controlled wall that drifts
from its target at its speed cap says so after the run (ControllerLimitWarning naming axis or
wall, target, reached stress and cap; an error on request), and a TriaxialController's cap
follows an axis switched to strain-rate control."""

import warnings

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem.protocols import prep
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import build_box_sample


def isotropic_sample(stress=20e3):
    c, r = loose_cloud(np.full(150, 0.003), (0, 0, 0), (0.05, 0.05, 0.05), seed=2)
    sample = build_box_sample(c, r * 1.2, (0, 0, 0), (0.05, 0.05, 0.05), young=5e7, poisson=0.3,
                              friction_deg=30, density=2650, local_damping=0.3)
    st = prep.compact_isotropic(sample.scene, sample.walls, stress, controller=sample.controller,
                                tol=0.02, unbalanced=0.02)
    return sample, st


def test_the_cap_follows_an_axis_switched_to_strain_rate():
    sample, _ = isotropic_sample()
    ctl = sample.controller
    ctl.max_speed = 1e-4  # m/s, a preparation's cap
    assert ctl.effective_max_speed == pytest.approx(1e-4)
    ctl.set_strain_rate(2, 0.5)  # 1/s, axial loading
    l0 = max(ctl.reference_lengths)
    assert ctl.effective_max_speed == pytest.approx(0.5 * l0, rel=1e-12)
    ctl.set_stress(2, 20e3)  # back to stress control: the preparation's cap again
    assert ctl.effective_max_speed == pytest.approx(1e-4)


def test_a_new_users_triaxial_keeps_its_cell_pressure_and_says_nothing():
    """The issue's case: compact_isotropic, then one's own axial loading with the lateral
    walls' preparation cap. With the cap following the loading, sigma_3 holds."""
    sample, _ = isotropic_sample(20e3)
    sc, walls, ctl = sample.scene, sample.walls, sample.controller
    ctl.set_strain_rate(2, 0.05)  # 1/s
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.ControllerLimitWarning)
        for _ in range(10):
            sc.run(300)
    from cpp_dem import measure

    lateral = measure.axis_stresses(sc, walls)[:2]
    np.testing.assert_allclose(lateral, 20e3, rtol=0.1)


def test_a_wall_drifting_at_its_cap_warns_and_can_be_an_error():
    sample, _ = isotropic_sample(20e3)
    sc, walls, ctl = sample.scene, sample.walls, sample.controller
    ctl.enabled = False
    for w in walls:
        sc.set_wall_velocity(w, (0, 0, 0))
    top = _core.ServoWall(wall=walls[5], target_stress=20e3, area=0.0, gain=0.5,
                          max_speed=1e-5, box_walls=list(walls))
    sc.add_controller(top)
    sc.set_wall_velocity(walls[4], (0, 0, 0.05))  # the floor rises faster than the cap
    with pytest.warns(dem.ControllerLimitWarning,
                      match=r"wall 5\): at its speed cap 1e-05 m/s for \d+ calls while the "
                            r"stress drifted from the target 20000 Pa to \d"):
        sc.run(400)
    sc.strict_controllers = True
    with pytest.raises(RuntimeError, match="at its speed cap"):
        sc.run(400)


def test_approaching_the_target_at_the_cap_is_not_reported():
    c, r = loose_cloud(np.full(150, 0.003), (0, 0, 0), (0.05, 0.05, 0.05), seed=2)
    sample = build_box_sample(c, r * 1.2, (0, 0, 0), (0.05, 0.05, 0.05), young=5e7, poisson=0.3,
                              friction_deg=30, density=2650, local_damping=0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", dem.ControllerLimitWarning)
        prep.compact_isotropic(sample.scene, sample.walls, 20e3, controller=sample.controller,
                               tol=0.02, unbalanced=0.02)
