"""Exact restart: 2n steps == n steps + save + load (into a rebuilt scene) + n steps, bitwise,
with servo walls, radius growth and energy tracking on."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem.protocols import prep
from cpp_dem.build import psd
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import build_box_sample


def make():
    r = psd.radii_uniform(0.005, 0.001, 150, seed=3)
    c, r = loose_cloud(r * 0.8, (0, 0, 0), (0.06, 0.06, 0.06), seed=3)
    smp = build_box_sample(c, r, (0, 0, 0), (0.06, 0.06, 0.06), young=1e7, poisson=0.3,
                           friction_deg=30, density=2650, local_damping=0.2)
    g = _core.RadiusGrowth(walls=smp.walls, target_stress=3e4, max_strain=5e-4)
    smp.scene.add_controller(g)
    smp.scene.track_energy = True
    for a in range(3):
        smp.controller.set_stress(a, 3e4)
    smp.controller.enabled = True
    return smp


def state(s):
    e = s.energies()
    return (s.positions, s.velocities, s.angular_velocities, s.forces, s.radii,
            s.wall_positions, s.wall_velocities, s.wall_forces,
            np.array([s.dt, s.time, s.step_count]), np.array(list(e.values())),
            s.contacts()["force"])


def test_restart_is_bitwise(tmp_path):
    n = 400
    a = make()
    a.scene.run(n)
    save_checkpoint(tmp_path / "ck.h5", a.scene)
    a.scene.run(n)
    b = make()  # rebuilt by the same script, then restored
    b.scene.run(7)  # whatever it did before is replaced
    load_checkpoint(tmp_path / "ck.h5", b.scene)
    b.scene.run(n)
    for x, y in zip(state(a.scene), state(b.scene)):
        assert np.array_equal(x, y)
    assert b.scene.step_count == 2 * n


def test_controller_mismatch_is_refused(tmp_path):
    a = make()
    a.scene.run(10)
    save_checkpoint(tmp_path / "ck.h5", a.scene)
    s = dem.Scene()
    with pytest.raises(dem.ParameterError, match="saved scene had 2 controllers"):
        load_checkpoint(tmp_path / "ck.h5", s)


def test_checkpoint_keeps_the_blow_up_settings(tmp_path):
    # max_step_ratio (tunnelling) and dt_check_period travel with the state: a restart must
    # not fall back silently to the defaults.
    a = make()
    a.scene.max_step_ratio = 0.5
    a.scene.dt_check_period = 7
    a.scene.run(10)
    save_checkpoint(tmp_path / "ck.h5", a.scene)
    b = make()
    load_checkpoint(tmp_path / "ck.h5", b.scene)
    assert b.scene.max_step_ratio == 0.5
    assert b.scene.dt_check_period == 7
