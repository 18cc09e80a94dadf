"""The periodic cell (docs/periodic.md): contacts across images, the mean field, frame
indifference, mixed cell control, bitwise restart and thread independence, the supported
combinations and their errors."""

from __future__ import annotations

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.protocols import periodic
from cpp_dem._core import CellController

E, NU, RHO = 1e8, 0.3, 2650.0


def _mat(phi=30.0):
    return dem.linear_material(density=RHO, young=E, poisson=NU, friction_angle_deg=phi)


@pytest.fixture(scope="module")
def packed():
    """A 300-sphere periodic cube at rest at 100 kPa (blob, for fresh copies)."""
    s = periodic.prepare_periodic(300, material=_mat(), stress=100e3, radius_mean=1e-3,
                                  tol=0.005, unbalanced=1e-4)
    return bytes(dem._core._checkpoint_save(s))


def _copy(blob, controllers=()):
    s = dem.Scene()
    for c in controllers:
        s.add_controller(c)
    dem._core._checkpoint_load(s, blob)
    return s


def test_contact_through_the_periodic_face():
    # Two spheres at opposite faces of a 10 mm cube touch only through the face: the contact
    # force is k_n delta (linear law, k_n = E R for equal spheres) along the wrapped branch.
    r, edge, overlap = 1e-3, 10e-3, 1e-5
    s = dem.Scene(dt=1e-7)
    m = s.add_material(_mat())
    x0 = np.array([0.5e-3, 5e-3, 5e-3])
    x1 = np.array([edge - (2 * r - overlap) + 0.5e-3, 5e-3, 5e-3])
    s.add_spheres([x0, x1], [r, r], material=m)
    s.set_periodic_cell(periodic.cube_cell(edge))
    s.run(1)
    c = s.contacts()
    assert len(c["ids"]) == 1
    # (after one step: the spheres moved apart by ~1e-9 m)
    assert np.allclose(c["branch"][0], [-(2 * r - overlap), 0, 0], rtol=0, atol=1e-8)
    f = c["force"][0]  # on the second body (id 1), pushed towards -x... seen from id 0's side
    assert abs(np.linalg.norm(f) - E * r * overlap) < 1e-9 * E * r * overlap
    # The stress of that single contact: sigma_xx = f l / V (compression positive).
    st = s.cell_stress()
    assert st[0, 0] == pytest.approx(E * r * overlap * (2 * r - overlap) / edge**3, rel=1e-5)


def test_translation_by_a_cell_vector_changes_nothing():
    # A compressed cell, and a copy with every grain moved by whole cell vectors (each by
    # another one): the next steps give the same stress and the same positions modulo the
    # cell (to rounding: the shifted copy is wrapped back at its next build).
    rng = np.random.default_rng(4)
    edge = 5e-3
    c, r = periodic.periodic_cloud(rng.uniform(0.4e-3, 0.6e-3, 55), edge, seed=2)
    a = periodic.periodic_scene(c, r, periodic.cube_cell(edge), material=_mat(), damping=0.3)
    a.dt = 1e-6
    a.velocity_gradient = np.diag([-170.0, -170.0, -170.0])
    a.run(1100)
    b = _copy(bytes(dem._core._checkpoint_save(a)))
    h = np.asarray(a.cell_matrix)
    k = rng.integers(-2, 3, size=(len(r), 3))
    b.positions = np.asarray(a.positions) + k @ h.T
    a.run(20)
    b.run(20)
    assert a.num_active_contacts > 20
    assert np.allclose(a.cell_stress(), b.cell_stress(), rtol=1e-9, atol=1e-9 * 1e6)
    d = np.linalg.solve(h, (np.asarray(b.positions) - np.asarray(a.positions)).T)
    assert np.allclose(d, np.round(d), atol=1e-9)


def test_free_grains_follow_the_mean_field_exactly():
    # Without contacts every grain keeps its reduced coordinates H^-1 x: the cell and the
    # grains take the same map each step (any L: stretch, shear, spin).
    s = dem.Scene(dt=1e-5)
    m = s.add_material(_mat())
    x = np.array([[1e-3, 2e-3, 3e-3], [7e-3, 5e-3, 1e-3], [4e-3, 8e-3, 6e-3]])
    s.add_spheres(x, [0.2e-3] * 3, material=m)
    s.set_periodic_cell(periodic.cube_cell(10e-3))
    L = np.array([[0.3, 2.0, -1.0], [-2.5, -0.1, 0.4], [1.5, 0.2, 0.5]])
    s.velocity_gradient = L
    s.run(2000)
    h = np.asarray(s.cell_matrix)
    xs = np.asarray(s.positions) + np.asarray(s.images) @ h.T
    sref = np.linalg.solve(np.asarray(s.cell_reference), x.T).T
    assert np.allclose(np.linalg.solve(h, xs.T).T, sref, rtol=0, atol=1e-12)
    # and H itself is Cayley's map applied 2000 times
    a = np.linalg.solve(np.eye(3) - 0.5e-5 * L, np.eye(3) + 0.5e-5 * L)
    assert np.allclose(h, np.linalg.matrix_power(a, 2000) @ periodic.cube_cell(10e-3),
                       rtol=1e-12, atol=1e-16)
    assert np.allclose(np.asarray(s.velocities), 0.0)  # fluctuations stay zero


def test_rigid_rotation_leaves_the_invariants(packed):
    # A quarter turn about an oblique axis (L = W, skew): the stress tensor turns with the
    # cell, sigma' = R sigma R^T; its invariants stay within 1e-3 and no contact is lost.
    s = _copy(packed)
    s.velocity_gradient = np.zeros((3, 3))
    s.run(1)
    st0 = np.asarray(s.cell_stress())
    h0 = np.asarray(s.cell_matrix)
    n0 = s.num_active_contacts
    axis = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    w = 100.0  # rad/s
    W = w * np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s.velocity_gradient = W
    s.run(int(round(np.pi / 2 / w / s.dt)))
    s.velocity_gradient = np.zeros((3, 3))
    s.run(1)
    st = np.asarray(s.cell_stress())
    e0 = np.linalg.eigvalsh(0.5 * (st0 + st0.T))
    e1 = np.linalg.eigvalsh(0.5 * (st + st.T))
    assert np.abs(e1 - e0).max() < 1e-3 * e0.max()
    rot = np.asarray(s.cell_matrix) @ np.linalg.inv(h0)
    assert np.allclose(rot.T @ rot, np.eye(3), atol=1e-12)  # a rotation (Cayley: exact)
    assert np.abs(st - rot @ st0 @ rot.T).max() < 2e-3 * e0.max()
    assert abs(s.num_active_contacts - n0) <= 0.01 * n0


def test_mixed_control_holds_lateral_stress_while_compressing(packed):
    c = CellController(gain=0.3, max_rate=20.0)
    s = _copy(packed)
    f0 = periodic.deformation_gradient(s)
    s.add_controller(c)
    for a in range(2):
        c.set_stress(a, a, 100e3)
    c.set_rate(2, 2, -5.0)  # 1/s, compression along z
    n, t0 = 4000, s.time
    s.run(n)
    st = np.asarray(s.cell_stress())
    assert abs(st[0, 0] / 100e3 - 1) < 0.02 and abs(st[1, 1] / 100e3 - 1) < 0.02
    assert st[2, 2] > 1.3 * 100e3  # the axial stress rose
    f = periodic.deformation_gradient(s) @ np.linalg.inv(f0)
    assert f[2, 2] == pytest.approx(np.exp(-5.0 * (s.time - t0)), rel=1e-9)
    assert f[0, 0] > 1 and f[1, 1] > 1  # the sides extend to hold their stress
    assert c.limit_report() == []


def test_cell_servo_reaches_a_shear_stress_target(packed):
    c = CellController(gain=0.3, max_rate=20.0)
    s = _copy(packed)
    s.add_controller(c)
    for a in range(3):
        c.set_stress(a, a, 100e3)
    c.set_stress(0, 2, 20e3)  # sigma_xz through L_xz (simple shear)
    s.run(6000)
    st = np.asarray(s.cell_stress())
    assert 0.5 * (st[0, 2] + st[2, 0]) == pytest.approx(20e3, rel=0.03)
    assert np.diag(st) == pytest.approx([100e3] * 3, rel=0.03)


def test_restart_is_bitwise(packed):
    def run(blob, split):
        s = _copy(blob)
        s.velocity_gradient = np.array([[0, 0, 30.0], [0, 0, 0], [0, 0, -10.0]])
        if split:
            s.run(700)
            s2 = _copy(bytes(dem._core._checkpoint_save(s)))
            s2.run(800)
            return s2
        s.run(1500)
        return s

    a, b = run(packed, False), run(packed, True)
    assert np.array_equal(np.asarray(a.positions), np.asarray(b.positions))
    assert np.array_equal(np.asarray(a.cell_stress()), np.asarray(b.cell_stress()))
    assert np.array_equal(np.asarray(a.cell_matrix), np.asarray(b.cell_matrix))


def test_results_do_not_depend_on_the_thread_count(packed):
    out = []
    before = dem.get_num_threads()
    for t in (1, 2):
        dem.set_num_threads(t)
        try:
            s = _copy(packed)
            s.velocity_gradient = np.array([[0, 0, 30.0], [0, 0, 0], [0, 0, -10.0]])
            s.run(1000)
            out.append((np.asarray(s.positions), np.asarray(s.cell_stress())))
        finally:
            dem.set_num_threads(before)
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_energy_balance_under_shear(packed):
    s = _copy(packed)
    s.track_energy = True
    s.reset_energy()
    s.velocity_gradient = np.array([[0, 0, 20.0], [0, 0, 0], [0, 0, 0]])  # simple shear
    s.run(3000)
    e = s.energies()
    assert e["cell_work"] > 0  # the mean field works on the sample
    assert e["friction"] > 0
    assert e["balance_error_relative"] < 2e-3


def test_walls_across_a_cell_periodic_in_x_and_y():
    # A layer on a floor, periodic in x and y (as the sides of a pull-out box could be): at
    # rest, the floor carries the whole weight (no side walls take any of it).
    edge = 8e-3
    c, r = periodic.periodic_cloud(np.full(100, 0.5e-3), edge, seed=1)
    g = 1000.0  # m/s^2 (scaled, so the grains settle in a short run)
    s = dem.Scene(gravity=(0, 0, -g), local_damping=0.7)
    m = s.add_material(_mat())
    s.add_wall(axis=2, position=0.0, sense=1, material=m)
    s.add_wall(axis=2, position=edge, sense=-1, material=m)
    s.add_spheres(c, r, material=m)
    s.set_periodic_cell(periodic.cube_cell(edge), (True, True, False))
    s.set_auto_timestep(0.5, 100)
    s.run(30000)
    f = np.asarray(s.wall_forces)
    weight = float(np.sum(np.asarray(s.masses))) * g
    # (a layer two grains thick still has a few rattlers moving: within 3 %)
    assert -f[0, 2] == pytest.approx(weight, rel=0.03)
    x = np.asarray(s.positions)
    assert x[:, :2].min() >= -1e-12 and x[:, :2].max() < edge  # wrapped in x and y
    with pytest.raises(dem.ParameterError, match="row and column z"):
        s.velocity_gradient = np.diag([0.0, 0.0, -1.0])


def test_unsupported_combinations_say_so():
    s = dem.Scene()
    m = s.add_material(_mat())
    s.add_wall(axis=0, position=0.0, sense=1, material=m)
    with pytest.raises(dem.ParameterError, match="walls may only be normal"):
        s.set_periodic_cell(np.eye(3) * 0.01)
    s = dem.Scene()
    m = s.add_material(_mat())
    s.set_periodic_cell(np.eye(3) * 0.01)
    with pytest.raises(dem.ParameterError, match="walls may only be normal"):
        s.add_wall(axis=1, position=0.0, sense=1, material=m)
    with pytest.raises(dem.ParameterError, match="clumps in a periodic cell"):
        s._add_clump(np.zeros((1, 3)), np.array([1e-3]), m, 1e-5, np.full(3, 1e-12),
                     np.zeros(3), np.array([1.0, 0, 0, 0]), 0.0)
    with pytest.raises(dem.ParameterError, match="det > 0"):
        s.set_periodic_cell(np.diag([0.01, 0.01, -0.01]))
    with pytest.raises(dem.ParameterError, match="at least one axis"):
        s.set_periodic_cell(np.eye(3) * 0.01, (False, False, False))
    with pytest.raises(dem.ParameterError, match="no periodic cell"):
        dem.Scene().velocity_gradient = np.zeros((3, 3))
    # a cell thinner than 2 interaction ranges
    s = dem.Scene(dt=1e-6)
    m = s.add_material(_mat())
    s.add_spheres([[1e-3, 1e-3, 1e-3]], [1e-3], material=m)
    s.set_periodic_cell(np.eye(3) * 4.2e-3)
    with pytest.raises(dem.ParameterError, match="less than 2 interaction ranges"):
        s.run(1)


def test_refd_in_a_cell():
    # REFD (000 §2.3) in a periodic cell: expansion at the grains' friction, then friction
    # steps until the porosity is reached, friction restored, the isotropic servo at rest.
    from cpp_dem import measure

    s = periodic.prepare_periodic(200, material=_mat(), stress=100e3, radius_mean=1e-3,
                                  porosity=0.415, seed=3)
    assert measure.porosity(s, ()) <= 0.415
    assert np.diag(s.cell_stress()) == pytest.approx([100e3] * 3, rel=0.01)
    assert all(m == 0 for m in np.asarray(s.material_ids))  # friction restored
    assert s.num_controllers() == 0
