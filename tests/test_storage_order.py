"""The spatial storage order (Scene.spatial_sort): the scene stores its spheres in Morton order
at the first broad-phase build, and everything seen from Python stays in id order.

Sorted and unsorted runs sum the contact forces in other orders, so they agree to round-off,
not bit for bit. A settling frictional packing amplifies round-off (sliding or not is decided
at a threshold, and the final state depends on the path: 1e-8 m apart after 5000 steps of a
lattice of 5 mm spheres); a frictionless confined lattice has one equilibrium, and there the
two runs agree to 1e-17 m (measured), tested at 1e-12 of the radius.
"""
import numpy as np
import pytest

import cpp_dem as dem

RHO, E, G = 2600.0, 1e7, 9.81
BOX = 0.1


def scattered_scene(sort: bool, seed: int = 3):
    """64 spheres on a jittered lattice, ids in random order, in a box under gravity."""
    rng = np.random.default_rng(seed)
    s = dem.Scene(gravity=(0, 0, -G), local_damping=0.2)
    s.spatial_sort = sort
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_box((0, 0, 0), (BOX, BOX, 2 * BOX), material=m)
    g = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    c = 0.015 + 0.022 * g + rng.uniform(-0.001, 0.001, g.shape)
    order = rng.permutation(len(c))
    s.add_spheres(c[order], rng.uniform(0.008, 0.0105, len(c)), material=m)
    s.set_auto_timestep(safety=0.5, period=50)
    return s, m


def canonical_contacts(s):
    """Sphere-sphere contacts as {(smaller id, larger id): force on the larger id}."""
    c = s.contacts()
    out = {}
    for (a, b), f in zip(c["ids"], c["force"]):
        if b < 0:
            out[(int(a), int(b))] = f
        elif a < b:
            out[(int(a), int(b))] = f
        else:
            out[(int(b), int(a))] = -f
    return out


def lattice_scene(sort: bool, friction_deg: float, seed: int = 3, n: int = 5, r: float = 0.005):
    """n^3 spheres on a slightly overlapping cubic lattice (ids in random order) in a box that
    confines it, under gravity."""
    rng = np.random.default_rng(seed)
    s = dem.Scene(gravity=(0, 0, -G), local_damping=0.2)
    s.spatial_sort = sort
    m = s.add_material(dem.linear_material(density=RHO, young=E, poisson=0.3,
                                           friction_angle_deg=friction_deg))
    a = 2 * r * 0.999
    s.add_box((0, 0, 0), (n * a + 2e-4 * r, n * a + 2e-4 * r, 2 * n * a), material=m)
    g = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    c = (g + 0.5) * a + rng.uniform(-1e-4 * r, 1e-4 * r, g.shape)
    s.add_spheres(c[rng.permutation(len(c))], np.full(len(c), r), material=m)
    s.set_auto_timestep(safety=0.5, period=50)
    return s


def test_sorted_and_unsorted_runs_agree_to_round_off():
    r = 0.005
    a = lattice_scene(True, 0.0)
    b = lattice_scene(False, 0.0)
    assert a.identity_order and b.identity_order  # nothing stored differently before a run
    r0 = a.radii.copy()
    a.run(3000)
    b.run(3000)
    assert not a.identity_order, "the scattered ids should have been sorted"
    assert b.identity_order
    np.testing.assert_array_equal(a.radii, r0)  # per-id arrays come back in id order
    assert a.unbalanced_force() < 1e-6  # settled: one equilibrium
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-12 * r)
    fmax = np.abs(a.forces).max() + a.masses.max() * G
    np.testing.assert_allclose(a.wall_forces, b.wall_forces, rtol=1e-9)
    ca, cb = canonical_contacts(a), canonical_contacts(b)
    assert ca.keys() == cb.keys() and len(ca) > 300
    for k in ca:
        np.testing.assert_allclose(ca[k], cb[k], rtol=0, atol=1e-9 * fmax)


def test_forces_and_contacts_are_reported_by_id():
    """In a sorted frictional deposition, every sphere's force is its weight plus the forces
    of the contacts that name it (ids from contacts() against forces by id)."""
    a, _ = scattered_scene(sort=True)
    a.run(6000)
    assert not a.identity_order
    c = a.contacts()
    f = np.zeros((a.num_bodies, 3))
    for (i, j), fc in zip(c["ids"], c["force"]):
        if j >= 0:
            f[j] += fc
            f[i] -= fc
        else:
            f[i] += fc
    f[:, 2] -= a.masses * G
    assert len(c["ids"]) > 80
    assert any(i > j >= 0 for i, j in c["ids"])  # pairs whose slots run against their ids
    np.testing.assert_allclose(a.forces, f, rtol=0, atol=1e-9 * np.abs(a.forces).max())


def test_per_body_settings_follow_the_id_after_sorting():
    s, m = scattered_scene(sort=True)
    s.run(10)  # the first build sorts
    assert not s.identity_order
    target = 17
    x0 = s.positions[target].copy()
    s.block_dofs(target, "xyz")
    s.velocities = np.zeros((s.num_bodies, 3))
    heavy = s.add_material(dem.linear_material(density=3 * RHO, young=E, poisson=0.3,
                                               friction_angle_deg=30))
    m_before = s.masses.copy()
    s.set_body_material(5, heavy)
    ext = np.zeros((s.num_bodies, 3))
    ext[9] = [0, 0, 1e-3]
    s.external_forces = ext
    s.run(500)
    np.testing.assert_array_equal(s.positions[target], x0)  # blocked by id
    assert s.masses[5] == pytest.approx(3 * m_before[5], rel=1e-12)
    np.testing.assert_array_equal(np.delete(s.masses, 5), np.delete(m_before, 5))
    np.testing.assert_array_equal(s.external_forces[9], [0, 0, 1e-3])
    assert s.material_ids[5] == heavy
    assert s._blocked[target] == 7 and sum(s._blocked) == 7


def test_radius_growth_of_listed_ids_after_sorting():
    s, _ = scattered_scene(sort=True)
    s.gravity = (0, 0, 0)
    s.run(10)
    assert not s.identity_order
    r0 = s.radii.copy()
    grow = [3, 40, 41]
    g = dem.RadiusGrowth(walls=list(range(6)), bodies=grow, target_stress=1e3, gain=0.5,
                         max_strain=1e-3)
    s.add_controller(g)
    s.run(1)
    ratio = s.radii / r0
    assert np.all(ratio[grow] > 1)
    np.testing.assert_array_equal(np.delete(ratio, grow), 1.0)


@pytest.mark.parametrize("max_step_ratio, pattern", [
    # The overlap check (the tunnelling check allows the 1.3 R per step here).
    (2.0, r"bodies (11 and \d+|\d+ and 11) overlap"),
    # The tunnelling check (default: at most 1 R per step), which stops it first.
    (1.0, r"step 1: body 11 moved .* \(tunnelling\)"),
])
def test_blow_up_names_ids_not_slots(max_step_ratio, pattern):
    """Sphere 11 is shot across the box at 200 m/s (1.3 radii per step); the sorted and the
    unsorted scene stop at the same step with the same message, naming sphere 11 by its id."""
    msgs = []
    for sort in (True, False):
        s, _ = scattered_scene(sort=sort)
        s.gravity = (0, 0, 0)
        s.max_step_ratio = max_step_ratio
        s.run(1)
        assert s.identity_order != sort
        x = s.positions
        d = x[50] - x[11]
        v = np.zeros((s.num_bodies, 3))
        v[11] = d / np.linalg.norm(d) * 200.0
        s.velocities = v
        with pytest.raises(dem.BlowUpError, match=pattern) as e:
            s.run(2000)
        msgs.append(str(e.value))
    assert msgs[0] == msgs[1]


def test_sorting_off_keeps_storage_in_id_order_and_threads_agree():
    s, _ = scattered_scene(sort=False)
    s.run(50)
    assert s.identity_order
    # Sorted runs on 1 and 2 threads are bitwise equal.
    out = []
    before = dem.get_num_threads()
    try:
        for t in (1, 2):
            dem.set_num_threads(t)
            a, _ = scattered_scene(sort=True)
            a.run(1000)
            out.append((a.positions, a.forces))
    finally:
        dem.set_num_threads(before)
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_checkpoint_keeps_the_storage_order(tmp_path):
    a, _ = scattered_scene(sort=True)
    a.run(300)
    dem.save_checkpoint(tmp_path / "a.ckpt", a)
    b, _ = scattered_scene(sort=True)
    dem.load_checkpoint(tmp_path / "a.ckpt", b)
    assert not b.identity_order
    np.testing.assert_array_equal(a.positions, b.positions)
    a.run(300)
    b.run(300)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.forces, b.forces)
