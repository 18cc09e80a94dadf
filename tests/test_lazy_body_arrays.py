"""Per-body arrays allocated on first use (issue 63 item 3). The energy accumulators: a scene
that never tracks energy carries none of their 48 bytes a body or clump; one that does has
them for every body and clump, those added while it tracks and before it started alike. The
external forces and torques: none of their 48 bytes until one is set; then every body has
its entry and the loads act as before."""

from __future__ import annotations

import numpy as np

import cpp_dem as dem
from cpp_dem.build.clumps import ClumpTemplate
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint

ENERGY_FIELDS = ("bodies.ke", "bodies.damp_dissip", "bodies.ext_work",
                 "bodies.pos_at_energy_reset")


def _pile(n: int = 30, seed: int = 3) -> tuple[dem.Scene, int]:
    """Spheres dropped into a box of six walls under gravity, with local damping."""
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0.012, 0.088, (n, 3))
    pos[:, 2] = 0.012 + 0.011 * np.arange(n)  # (one above the other: none overlap)
    s.add_spheres(pos, np.full(n, 0.005), material=m)
    for axis in range(3):
        s.add_wall(axis=axis, position=0.0, sense=1, material=m)
        s.add_wall(axis=axis, position=0.1 if axis < 2 else 0.4, sense=-1, material=m)
    s.gravity = (0, 0, -9.81)
    s.local_damping = 0.2
    s.dt = 2e-6
    return s, m


def test_a_scene_that_never_tracks_energy_holds_no_accumulators():
    s, _ = _pile()
    s.run(200)
    f = s.memory_by_field()
    assert all(f[k] == 0 for k in ENERGY_FIELDS), {k: f[k] for k in ENERGY_FIELDS}
    assert f["bodies.pos"] >= 24 * s.num_bodies  # (the other arrays are there)


def test_tracking_allocates_them_for_every_body_before_and_after_it_starts():
    s, m = _pile()
    s.run(100)
    s.track_energy = True
    f = s.memory_by_field()
    assert all(f[k] >= s.num_bodies * (24 if "pos" in k else 8) for k in ENERGY_FIELDS)
    # a body added while tracking takes part in the balance from where it was added
    s.add_spheres(np.array([[0.05, 0.05, 0.38]]), np.array([0.005]), material=m)
    s.run(3000)
    e = s.energies()
    assert e["kinetic"] > 0 and e["gravity_potential"] < 0 and e["local_damping"] > 0
    assert e["balance_error_relative"] < 1e-2, e
    # (memory_by_field counts capacities; every body has its entry)
    assert s.memory_by_field()["bodies.ke"] >= 8 * s.num_bodies


def test_the_balance_and_the_motion_do_not_depend_on_when_they_were_allocated():
    """Tracking from the start and tracking after a first run without it: the same motion
    bitwise (the accumulators never feed back), and the balance closes in both."""
    a, _ = _pile()
    a.track_energy = True
    a.run(4000)
    b, _ = _pile()
    b.run(1)
    b.track_energy = True
    b.run(3999)
    assert np.array_equal(a.positions, b.positions)
    for s in (a, b):
        assert s.energies()["balance_error_relative"] < 1e-2


def _restarted(path, setup, steps: int = 1500):
    """A pile set up by ``setup(scene)``, run, saved to ``path`` and run on; and the same pile
    set up again, loaded from ``path`` and run on as far: (the first, the second)."""
    s, _ = _pile()
    setup(s)
    s.run(steps)
    save_checkpoint(path, s)
    s.run(steps)
    t, _ = _pile()
    setup(t)
    load_checkpoint(path, t)
    t.run(steps)
    return s, t


def test_checkpoints_with_and_without_them_load_and_go_on_bitwise(tmp_path):
    for track in (False, True):
        s, t = _restarted(tmp_path / f"track{int(track)}.h5",
                          lambda sc: setattr(sc, "track_energy", track))
        assert np.array_equal(s.positions, t.positions)
        if track:
            assert t.energies() == s.energies()
        else:
            assert t.memory_by_field()["bodies.ke"] == 0


def test_clump_kinetic_energies_are_zero_until_tracked():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    t = ClumpTemplate.from_spheres([[0.0, 0, 0], [0.006, 0, 0]], [0.005, 0.005])
    s.add_clumps(t, np.zeros((1, 3)), material=m)
    s.set_clump_state(0, np.array([0.003, 0, 0]), np.array([1.0, 0, 0, 0]),
                      np.array([0.1, 0, 0]), np.zeros(3))
    s.dt = 1e-6
    s.run(2)
    assert np.array_equal(s.clump_kinetic_energies, np.zeros(1))
    s.track_energy = True
    s.run(2)
    assert s.clump_kinetic_energies[0] > 0


def test_external_loads_are_allocated_when_first_set_and_act_as_before():
    s, m = _pile()
    s.run(10)
    f = s.memory_by_field()
    assert f["bodies.ext_force"] == 0 and f["bodies.ext_torque"] == 0
    n = s.num_bodies
    assert np.array_equal(s.external_forces, np.zeros((n, 3)))
    # a load on every body as one array: the same motion as gravity raised by its weight
    a, _ = _pile()
    loads = np.zeros((n, 3))
    loads[:, 2] = -a.masses * 9.81
    a.external_forces = loads
    assert a.memory_by_field()["bodies.ext_force"] >= 24 * n
    assert a.memory_by_field()["bodies.ext_torque"] == 0  # (the torques stay unallocated)
    b, _ = _pile()
    b.gravity = (0, 0, -2 * 9.81)
    a.run(2000)
    b.run(2000)
    assert np.allclose(a.positions, b.positions, rtol=0, atol=1e-12)
    assert np.array_equal(a.external_forces, loads)
    # a body added afterwards gets its (zero) entry
    a.add_spheres(np.array([[0.05, 0.05, 0.38]]), np.array([0.005]), material=m)
    assert a.external_forces.shape == (n + 1, 3) and not a.external_forces[-1].any()
    a.run(10)


def test_checkpoints_with_and_without_external_loads_go_on_bitwise(tmp_path):
    def load(sc):
        f = np.zeros((sc.num_bodies, 3))
        f[:, 0] = 1e-4
        sc.external_forces = f

    for loaded in (False, True):
        s, t = _restarted(tmp_path / f"loads{int(loaded)}.h5",
                          load if loaded else (lambda sc: None), steps=1000)
        assert np.array_equal(s.positions, t.positions)
        assert np.array_equal(s.external_forces, t.external_forces)
        assert (t.memory_by_field()["bodies.ext_force"] > 0) == loaded


def test_a_clump_s_external_load_is_allocated_when_set():
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    t = ClumpTemplate.from_spheres([[0.0, 0, 0], [0.006, 0, 0]], [0.005, 0.005])
    s.add_clumps(t, np.array([[0.0, 0, 0], [0.1, 0, 0]]), material=m)
    s.dt = 1e-6
    assert s.memory_by_field()["clumps.ext_force"] == 0
    s.set_clump_external(1, np.array([0.0, 0, 1e-3]), np.zeros(3))
    s.run(100)
    v = s.clump_velocities
    assert v[0, 2] == 0 and v[1, 2] > 0  # (the load moves its clump alone)
