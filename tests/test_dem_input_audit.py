"""Inputs of the DEM core's Python face that would otherwise be handled wrongly in silence:
boundaries moved past the grains (teleported walls, walls and cells moving more than a grain
in one step), checkpoints of other materials or pair laws, ids truncated or wrapped, non-finite
velocities and forces, and a mesh of large triangles binned without bound (docs/core.md,
docs/reliability.md)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import BlowUpError, ParameterError

R = 0.005  # m


def scene(young=5e7, box=True):
    sc = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
    m = sc.add_material(dem.linear_material(density=2650, young=young, poisson=0.3,
                                            friction_angle_deg=20))
    if box:
        sc.add_box([0, 0, 0], [0.1, 0.1, 0.1], material=m)
    g = [0.03, 0.05]
    sc.add_spheres([[x, y, z] for x in g for y in g for z in g], np.full(8, R), material=m)
    sc.dt = 0.3 * sc.critical_dt()
    return sc


def test_a_wall_moved_behind_the_grains_after_a_run_is_refused():
    sc = scene()
    sc.run(10)
    sc.set_wall_position(5, 0.02)  # the lid below every grain
    with pytest.raises(ParameterError, match=r"body 0 \(sphere\) .* behind wall 5"):
        sc.run(10)
    sc.set_wall_position(5, 0.1)  # back: it runs
    sc.run(10)


def test_a_cylinder_shrunk_inside_the_grains_after_a_run_is_refused():
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                            friction_angle_deg=20))
    sc.add_spheres([[0.01, 0, 0], [-0.01, 0, 0]], [R, R], material=m)
    c = sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=0.05, inside=True,
                             material=m)
    sc.dt = 0.3 * sc.critical_dt()
    sc.run(5)
    sc.set_cylinder_radius(c, 0.002)
    with pytest.raises(ParameterError, match="outside cylindrical wall 0"):
        sc.run(5)


def test_a_wall_moving_more_than_a_grain_radius_a_step_is_refused():
    sc = scene()
    sc.set_wall_velocity(5, [0, 0, -3000.0])  # the lid down through the grains
    with pytest.raises(BlowUpError, match=r"wall 5 \(-z\) would move .* towards the bodies in "
                                          r"one step .*tunnelling"):
        sc.run(1)
    assert sc.wall_positions[5] == 0.1  # refused before it moved
    away = scene()
    away.set_wall_velocity(5, [0, 0, 3000.0])  # away from them: nothing to pass
    away.run(2)
    slow = scene()
    slow.set_wall_velocity(5, [0, 0, -0.9 * R / slow.dt])  # just below the bound
    slow.run(1)


def test_a_cylinder_or_mesh_moving_too_far_in_a_step_is_refused():
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                            friction_angle_deg=20))
    sc.add_spheres([[0.01, 0, 0]], [R], material=m)
    c = sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=0.05, inside=True,
                             material=m)
    sc.dt = 0.3 * sc.critical_dt()
    sc.set_cylinder_radial_velocity(c, -2 * R / sc.dt)
    with pytest.raises(BlowUpError, match="cylindrical wall 0 would move"):
        sc.run(1)
    sc.set_cylinder_radial_velocity(c, 2 * R / sc.dt)  # widening: away from the grain
    sc.run(1)
    mesh = dem.Scene()
    m = mesh.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                              friction_angle_deg=20))
    mesh.add_mesh_wall([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], [[0, 1, 2], [0, 2, 3]],
                       material=m)
    mesh.add_spheres([[0, 0, 0.02]], [R], material=m)
    mesh.dt = 0.3 * mesh.critical_dt()
    mesh.set_mesh_velocity(0, [0, 0, 1.5 * R / mesh.dt])
    with pytest.raises(BlowUpError, match="mesh wall 0 would move"):
        mesh.run(1)


def test_a_periodic_cell_strained_too_far_in_a_step_is_refused():
    for rate in (2.0, -3.0, 0.6):  # |L| dt: singular, a reflection, a contact passed
        sc = scene(box=False)
        sc.set_periodic_cell(np.eye(3) * 0.04)
        sc.velocity_gradient = np.diag([0, 0, rate / sc.dt])
        with pytest.raises(BlowUpError, match=r"the periodic cell's velocity_gradient strains "
                                              r"it by \|L\| dt = "):
            sc.run(1)
        assert np.isfinite(sc.positions).all() and np.linalg.det(sc.cell_matrix) > 0
    sc = scene(box=False)
    sc.set_periodic_cell(np.eye(3) * 0.04)
    sc.velocity_gradient = np.diag([0, 0, -0.2 / sc.dt])  # 2 r_max |L| dt = 0.4 R: allowed
    sc.run(1)


def test_a_checkpoint_of_other_materials_or_pair_laws_is_refused(tmp_path):
    a = scene()
    a.run(20)
    path = tmp_path / "a.h5"
    dem.save_checkpoint(path, a)
    with pytest.raises(ParameterError, match=r"material 0's young is 50000000 .* in the saved "
                                             r"scene, 1000000000 in this one"):
        dem.load_checkpoint(path, scene(young=1e9))
    other = scene()
    other.set_pair_law(0, 0, kn=1e3)
    with pytest.raises(ParameterError, match=r"the pair laws are none in the saved scene, "
                                             r"\(0, 0: kn 1000\) in this one"):
        dem.load_checkpoint(path, other)
    two = scene()
    two.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                         friction_angle_deg=20))
    with pytest.raises(ParameterError, match="the saved scene has 1 materials, this scene has 2"):
        dem.load_checkpoint(path, two)
    same = scene()
    dem.load_checkpoint(path, same)  # the scene it came from
    assert same.step_count == 20
    replaced = scene(young=1e9)
    dem.load_checkpoint(path, replaced, replace=True)
    assert replaced.material(0).young == 5e7


def test_a_triangle_index_beyond_32_bits_is_refused_not_wrapped():
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                            friction_angle_deg=20))
    for big in (2**32 + 2, 2**40):
        with pytest.raises(ParameterError, match=f"triangles\\[0\\]: vertex {big} is not one "
                                                 "of the 4 vertices"):
            sc.add_mesh_wall([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                             np.array([[0, 1, big], [0, 2, 3]]), material=m)


_PLANE = textwrap.dedent("""
    import resource, sys
    lim = 1200 * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
    import numpy as np, cpp_dem as dem
    L = float(sys.argv[1]); cells = int(sys.argv[2])
    sc = dem.Scene(gravity=(0, 0, -9.81))
    m = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                            friction_angle_deg=20))
    s = np.linspace(-L, L, cells + 1)
    v = np.array([[x, y, 0.0] for y in s for x in s])
    t = []
    for j in range(cells):
        for i in range(cells):
            a = j * (cells + 1) + i
            t += [[a, a + 1, a + cells + 2], [a, a + cells + 2, a + cells + 1]]
    sc.add_mesh_wall(v, t, material=m)
    sc.add_spheres([[0.0101, 0.0203, 0.0049], [-0.02, 0.013, 0.0052]], [0.005, 0.0055],
                   material=m)
    sc.dt = 0.3 * sc.critical_dt()
    zs = []
    for k in range(40):
        sc.run(5)
        zs.append(np.asarray(sc.positions)[:, 2].tolist())
    print(repr(zs))
""")


def _plane(half_width_m: float, cells: int) -> list:
    p = subprocess.run([sys.executable, "-c", _PLANE, str(half_width_m), str(cells)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    return eval(p.stdout)  # (our own repr of floats)


def test_a_mesh_of_huge_triangles_is_binned_in_bounded_memory_and_touches_as_a_fine_one():
    # Two triangles 200 km wide under grains of 5 mm: their boxes would span 1e15 cells of
    # the grains' grid; binned coarsely, the run fits in 1.2 GB of address space and gives
    # the grains the bits of a plane of small triangles (each within the fine grid's bound).
    huge = _plane(1e5, 1)
    fine = _plane(0.04, 4)
    assert huge == fine
    assert huge[0] != huge[-1]  # (the grains moved: they touched the plane)


def test_ids_are_refused_not_truncated_or_wrapped():
    sc = scene()
    for bad, msg in (([0.7], r"bodies=\[0.7\]: must be body ids"),
                     ([True], r"bodies=\[True\]: must be body ids"),
                     ([8], r"body 8 does not exist \(the scene has 8: 0 to 7\)"),
                     (-1, r"body -1 does not exist")):
        with pytest.raises(ParameterError, match=msg):
            sc.block_dofs(bad, "x")
    with pytest.raises(ParameterError, match=r"body -1 does not exist"):
        sc.blocked_dofs(-1)
    sc.block_dofs([0, 1], "x")
    sc.block_dofs(np.array([2]), "y")
    sc.block_dofs(3, "z")
    sc.block_dofs([], "z")
    assert [sc.blocked_dofs(k) for k in range(5)] == ["x", "x", "y", "z", ""]


@pytest.mark.parametrize("field", ["velocities", "angular_velocities", "external_forces",
                                   "external_torques"])
def test_non_finite_velocities_and_loads_are_refused(field):
    sc = scene()
    v = np.zeros((8, 3))
    v[2, 1] = np.nan
    with pytest.raises(ParameterError, match=f"{field}: body 2 has .*nan.*must be finite"):
        setattr(sc, field, v)
    assert np.isfinite(np.asarray(getattr(sc, field))).all()


def test_a_pair_law_friction_no_grain_has_warns():
    sc = scene()
    with pytest.warns(dem.PhysicalRangeWarning, match=r"set_pair_law\(0, 0\): friction=1e\+06"):
        sc.set_pair_law(0, 0, friction=1e6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sc.set_pair_law(0, 0, friction=0.5)


def test_grains_kilometres_apart_run():
    # (the broad phase's cell count overflowed 64 bits: "cannot create std::vector larger
    # than max_size()")
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                            friction_angle_deg=20))
    sc.add_spheres([[0, 0, 0], [3e4, 3e4, 3e4]], [R, R], material=m)
    sc.dt = 0.3 * sc.critical_dt()
    sc.run(3)
    assert sc.step_count == 3


def test_shapes_and_types_are_refused_by_name():
    sc = scene()
    cases = [
        (lambda: sc.add_spheres(np.zeros((1, 1, 3)), [R], material=0),
         r"centers: shape \(1, 1, 3\); must be \(n, 3\)"),
        (lambda: sc.add_spheres([[0.05, 0.05, 0.05]], [R], material=2**31),
         r"material=2147483648: no such material"),
        (lambda: sc.run(10, every=0.5), r"every=0.5: must be a whole number of steps"),
        (lambda: sc.run(10, every="3"), r"every='3': must be a whole number of steps"),
        (lambda: sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=1.0, inside=2,
                                      material=0), r"inside=2: must be True"),
    ]
    for call, msg in cases:
        with pytest.raises(ParameterError, match=msg):
            call()
    from cpp_dem.build.clumps import ClumpTemplate

    t = ClumpTemplate.from_spheres([[0, 0, 0], [0.004, 0, 0]], [0.003, 0.003], name="pair")
    with pytest.raises(ParameterError, match=r"scale: 2 factors for 1 clumps"):
        sc.add_clumps(t, [[0.05, 0.05, 0.08]], material=0, scale=[1, 2])
    sc.run(4, every=2.0)  # a whole float is a whole number
    assert sc.step_count == 4
