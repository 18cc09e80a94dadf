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


def make_hertz():
    """Hertz–Mindlin spheres falling into a box, half of them with contact dashpots (the
    pair pass's two Hertz kernels), and a linear wall law."""
    s = dem.Scene(gravity=(0, 0, -9.81))
    plain = s.add_material(dem.hertz_mindlin_material(density=2650, shear_modulus=2.9e7,
                                                      poisson=0.25, friction_coefficient=0.8))
    damped = s.add_material(dem.hertz_mindlin_material(density=2650, shear_modulus=2.9e7,
                                                       poisson=0.25, friction_coefficient=0.8))
    s.set_pair_law(damped, damped, damping_normal=0.97, damping_shear=0.97)
    s.set_pair_law(plain, damped, damping_normal=0.5, damping_shear=0.5)
    s.add_box((0, 0, 0), (0.03, 0.03, 0.06), material=plain)
    c, r = loose_cloud(np.full(120, 0.003), (0, 0, 0), (0.03, 0.03, 0.06), seed=5)
    s.add_spheres(c, r, material=plain)
    s.velocities = np.random.default_rng(5).normal(0, 0.5, (120, 3))
    for b in range(0, 120, 2):
        s.set_body_material(b, damped)
    s.dt = 0.2 * s.critical_dt()
    return s


def test_a_hertz_restart_is_bitwise_and_its_checkpoint_the_same_bytes_again(tmp_path):
    """The Hertz kernels (with and without dashpots) are found again from each contact's law
    when a checkpoint loads: the restart is bitwise, and the loaded scene saves the same
    bytes (a contact's bytes do not depend on its kernel)."""
    n = 1500
    a = make_hertz()
    a.run(n)
    assert a.num_active_contacts > 10
    blob = bytes(_core._checkpoint_save(a))
    save_checkpoint(tmp_path / "ck.h5", a)
    a.run(n)
    b = make_hertz()
    load_checkpoint(tmp_path / "ck.h5", b)
    assert bytes(_core._checkpoint_save(b)) == blob
    b.run(n)
    for x, y in zip((a.positions, a.velocities, a.angular_velocities, a.forces,
                     a.contacts()["force"]),
                    (b.positions, b.velocities, b.angular_velocities, b.forces,
                     b.contacts()["force"])):
        assert np.array_equal(x, y)
