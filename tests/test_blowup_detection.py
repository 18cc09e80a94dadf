"""Blow-up detection of non-finite values (issue 2): a NaN or inf force, torque, velocity or
angular velocity stops the run with a BlowUpError naming the step, the body (by id) and the
quantity, in the integration's fast path (blocks of bodies, one finite test per block) and in
its energy-bookkeeping path, for free and for blocked bodies."""

from __future__ import annotations

import numpy as np
import pytest

import cpp_dem as dem

RHO, E = 2600.0, 1e7  # kg/m^3, Pa


def lattice_scene(n_side: int = 6, energy: bool = False) -> dem.Scene:
    """n_side^3 spheres (r = 4 mm) on a 10 mm lattice, not touching, no gravity: nothing
    happens unless a test injects a bad value. Ids are random in space, so the scene's
    storage order (spatial sort) differs from the id order."""
    rng = np.random.default_rng(7)
    s = dem.Scene(gravity=(0, 0, 0))
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30))
    g = np.stack(np.meshgrid(*[np.arange(n_side)] * 3, indexing="ij"), -1).reshape(-1, 3)
    centres = 0.01 * g[rng.permutation(len(g))]
    s.add_spheres(centres, np.full(len(centres), 0.004), material=m)
    s.track_energy = energy
    s.dt = 1e-5
    s.run(1)  # the first build sorts the storage order
    return s


@pytest.mark.parametrize("energy", [False, True])
def test_non_finite_external_force_names_step_body_and_force(energy):
    s = lattice_scene(energy=energy)
    f = np.zeros((s.num_bodies, 3))
    f[37, 1] = np.nan
    with pytest.raises(dem.ParameterError, match="external_forces: body 37 has"):
        s.external_forces = f  # the setter refuses it; a law or controller could make one:
    s._inject_unchecked("external_forces", 37, 1, np.nan)
    step = s.step_count
    with pytest.raises(dem.BlowUpError, match=rf"blow-up at step {step}: body 37 has a "
                                              r"non-finite force"):
        s.run(10)
    # The bad body did not move; every other body's state stays finite.
    assert np.isfinite(s.positions).all() and np.isfinite(s.velocities).all()


@pytest.mark.parametrize("energy", [False, True])
def test_inf_force_on_a_blocked_dof_is_still_caught(energy):
    # The blocked DOF ignores the force (zero acceleration), so the velocities stay finite:
    # only the force test can see it.
    s = lattice_scene(energy=energy)
    s.block_dofs(101, "x")
    s._inject_unchecked("external_forces", 101, 0, np.inf)
    with pytest.raises(dem.BlowUpError, match=r"body 101 has a non-finite force"):
        s.run(10)


@pytest.mark.parametrize("field, body, axis, value, quantity", [
    ("external_torques", 5, 2, -np.inf, "torque"),
    ("velocities", 150, 0, np.inf, "velocity"),
    ("angular_velocities", 80, 1, np.nan, "angular velocity"),
])
def test_non_finite_torque_velocity_and_spin_are_named(field, body, axis, value, quantity):
    s = lattice_scene()
    a = getattr(s, field)
    a[body, axis] = value
    with pytest.raises(dem.ParameterError, match=f"{field}: body {body} has"):
        setattr(s, field, a)  # the setter refuses it; a law or controller could make one:
    s._inject_unchecked(field, body, axis, value)
    with pytest.raises(dem.BlowUpError, match=rf"body {body} has a non-finite {quantity} "):
        s.run(10)


def test_two_bad_bodies_in_different_blocks_one_is_named():
    # 216 bodies: four blocks of the integration pass, and two threads.
    s = lattice_scene()
    for b in (3, 200):
        s._inject_unchecked("external_forces", b, 2, np.nan)
    with pytest.raises(dem.BlowUpError) as ei:
        s.run(10)
    assert any(f"body {b} has a non-finite force" in str(ei.value) for b in (3, 200))


def test_large_finite_forces_are_no_blow_up():
    # Forces of 1e300 N on x-blocked bodies: the block's sum overflows to inf, the exact test
    # per body then finds every force finite, and the run goes on (nothing moves).
    s = lattice_scene()
    for b in range(s.num_bodies):
        s.block_dofs(b, "x")
    x0 = s.positions
    f = np.zeros((s.num_bodies, 3))
    f[:, 0] = 1e300
    s.external_forces = f
    s.run(2)
    assert np.array_equal(s.positions, x0)
