"""Triangle-mesh walls (Scene.add_mesh_wall, cpp_dem/src/passes/mesh_wall.cpp): a sphere
sliding on an inclined mesh moves as on the analytic plane (trajectory and force to rounding)
and crosses the shared edge of two triangles without a jump; a sphere on a vertex where eight
triangles meet is pushed once, not eight times; one in a concave corner feels both faces, as
two plane walls; the force and the moment on the mesh; a moving mesh; a file read by the
project's mesh reader; a checkpoint; bad input refused by name."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.build.clump_mesh import write_stl
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint

R = 0.005  # m
L = 0.2  # m, half the side of the square meshes
SHIFT = np.array([0.01, -0.02, 0.03])  # m


def _material(sc, friction_deg=20.0, damping_normal=0.7):
    # Viscous normal damping (rotation invariant, unlike local damping) keeps the sphere on
    # the surface instead of bouncing. Without it (0) a mesh contact takes the linear law's
    # short kernel, with it the general law.
    return sc.add_material(dem.linear_material(density=2000, young=1e7, poisson=0.3,
                                               friction_angle_deg=friction_deg,
                                               damping_normal=damping_normal))



def _tilt(a_deg: float, b_deg: float) -> np.ndarray:
    a, b = np.radians([a_deg, b_deg])
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    return rz @ rx


SQUARE = np.array([[-L, -L, 0], [L, -L, 0], [L, L, 0], [-L, L, 0]], float)
SQUARE_TRIS = [[0, 1, 2], [0, 2, 3]]  # the diagonal x = y is their shared edge


def test_a_sphere_slides_on_an_inclined_mesh_as_on_the_plane_and_across_its_edge():
    # The plane z = 0 with gravity tilted 35 degrees from its normal; the mesh is the same
    # square turned anyhow, gravity turned with it. The sphere slides from x > y to x < y,
    # across the triangles' shared edge: its contact keeps its history (the shear spring at
    # the Coulomb limit), so the path stays the plane's to rounding.
    q = _tilt(20, 35)
    th = np.radians(35)
    g = 9.81 * np.array([0.6 * np.sin(th), 0.8 * np.sin(th), -np.cos(th)])
    x0 = np.array([-0.05, -0.06, R - 1e-5])
    plane = dem.Scene(gravity=tuple(g))
    m = _material(plane)
    plane.add_wall(axis=2, position=0.0, sense=1, material=m)
    plane.add_spheres([x0], [R], material=m)
    mesh = dem.Scene(gravity=tuple(q @ g))
    m = _material(mesh)
    k = mesh.add_mesh_wall((q @ SQUARE.T).T + SHIFT, SQUARE_TRIS, material=m)
    mesh.add_spheres([q @ x0 + SHIFT], [R], material=m)
    plane.dt = mesh.dt = 0.2 * plane.critical_dt()
    crossed, f_err, f_max = False, 0.0, 0.0
    for _ in range(50):
        plane.run(500)
        mesh.run(500)
        xp = np.asarray(plane.positions)[0]
        xm = q.T @ (np.asarray(mesh.positions)[0] - SHIFT)
        assert np.abs(xp - xm).max() <= 1e-9 * R
        fp = np.asarray(plane.wall_forces)[0]
        fm = q.T @ np.asarray(mesh.mesh_wall(k)["force"])
        f_err, f_max = max(f_err, np.abs(fp - fm).max()), max(f_max, np.abs(fp).max())
        crossed = crossed or xp[0] < xp[1]
    assert crossed and f_max > 0
    assert f_err <= 1e-6 * f_max
    assert mesh.mesh_dropped_contacts == 0


def _fan(n: int = 8):
    """n triangles around the vertex at the origin, in the plane z = 0."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = np.vstack([[0, 0, 0], np.column_stack([L * np.cos(a), L * np.sin(a), np.zeros(n)])])
    t = [[0, 1 + i, 1 + (i + 1) % n] for i in range(n)]
    return v, t


def test_a_sphere_on_a_vertex_of_eight_triangles_is_pushed_once():
    # At rest on the vertex (and then just off it, on an edge, and inside a face) the mesh
    # holds the sphere's weight at the plane's overlap: the triangles that share the vertex
    # or the edge give one contact, not one each.
    v, t = _fan()
    for x in ([0, 0, R], [0.3 * R, 0, R], [0.2 * R, 0.1 * R, R]):
        z = {}
        for kind in ("mesh", "plane"):
            sc = dem.Scene(gravity=(0, 0, -9.81))
            m = _material(sc)
            if kind == "mesh":
                k = sc.add_mesh_wall(v, t, material=m)
            else:
                sc.add_wall(axis=2, position=0.0, sense=1, material=m)
            sc.add_spheres([x], [R], material=m)
            sc.dt = 0.2 * sc.critical_dt()
            sc.run(20000)
            z[kind] = np.asarray(sc.positions)[0, 2]
            if kind == "mesh":
                weight = float(np.asarray(sc.masses)[0]) * 9.81
                assert sc.mesh_wall(k)["force"][2] == pytest.approx(-weight, rel=1e-6), x
        assert z["mesh"] == pytest.approx(z["plane"], abs=1e-12 * R), x
        assert R - z["plane"] > 1e-5 * R  # (a real overlap: eight contacts would shrink it)


def test_a_sphere_in_a_concave_corner_feels_both_faces_as_two_plane_walls():
    # An L-shaped mesh: the floor z = 0 (x >= 0) and the wall x = 0 (z >= 0); gravity presses
    # the sphere into the corner. Two plane walls give the reference.
    v = np.array([[0, -L, 0], [L, -L, 0], [L, L, 0], [0, L, 0], [0, -L, L], [0, L, L]], float)
    t = [[0, 1, 2], [0, 2, 3], [0, 3, 5], [0, 5, 4]]
    g = (-6.0, 0.0, -7.0)
    x0 = [R, 0.01, R]
    walls = dem.Scene(gravity=g)
    m = _material(walls)
    walls.add_wall(axis=0, position=0.0, sense=1, material=m)
    walls.add_wall(axis=2, position=0.0, sense=1, material=m)
    walls.add_spheres([x0], [R], material=m)
    mesh = dem.Scene(gravity=g)
    m = _material(mesh)
    k = mesh.add_mesh_wall(v, t, material=m)
    mesh.add_spheres([x0], [R], material=m)
    walls.dt = mesh.dt = 0.2 * walls.critical_dt()
    walls.run(20000)
    mesh.run(20000)
    assert np.abs(np.asarray(walls.positions) - np.asarray(mesh.positions)).max() <= 1e-9 * R
    fw = np.asarray(walls.wall_forces).sum(axis=0)
    assert np.abs(fw - np.asarray(mesh.mesh_wall(k)["force"])).max() <= 1e-9 * np.abs(fw).max()
    weight = float(np.asarray(mesh.masses)[0]) * np.asarray(g)
    assert np.asarray(mesh.mesh_wall(k)["force"])[[0, 2]] == pytest.approx(weight[[0, 2]],
                                                                           rel=1e-6)


def test_the_force_and_moment_on_a_mesh_and_a_moving_mesh(tmp_path):
    # A sphere at rest off the mesh's centre: the moment about it is the lever times the
    # weight. A mesh moving sideways under the sphere rolls it along.
    sc = dem.Scene(gravity=(0, 0, -9.81))
    m = _material(sc)
    k = sc.add_mesh_wall(SQUARE, SQUARE_TRIS, material=m)
    assert np.allclose(sc.mesh_wall(k)["ref"], 0)
    sc.add_spheres([[0.05, -0.03, R]], [R], material=m)
    sc.dt = 0.2 * sc.critical_dt()
    sc.run(20000)
    w = sc.mesh_wall(k)
    weight = float(np.asarray(sc.masses)[0]) * 9.81
    f = np.array([0, 0, -weight])
    x = np.asarray(sc.positions)[0]
    lever = np.array([x[0], x[1], 0.0])  # the contact point, from ref
    assert np.asarray(w["moment"]) == pytest.approx(np.cross(lever, f), rel=1e-6, abs=1e-12)
    sc.set_mesh_velocity(k, [0.05, 0, 0])
    sc.run(20000)
    w = sc.mesh_wall(k)
    moved = 0.05 * 20000 * sc.dt
    assert np.asarray(w["vertices"])[0, 0] == pytest.approx(-L + moved, rel=1e-9)
    assert np.asarray(w["ref"])[0] == pytest.approx(moved, rel=1e-9)
    # Rolling without slipping on the moving plate, the sphere's centre takes 2/7 of its
    # speed (friction's impulse J: v = J / m, w = J R / I, v + w R = V, I = 2/5 m R^2).
    assert (np.asarray(sc.positions)[0, 0] - x[0]) / moved == pytest.approx(2 / 7, rel=0.01)
    assert w["work"] > 0  # the mesh did work on the sphere


def test_a_mesh_file_and_a_checkpoint(tmp_path):
    path = tmp_path / "fan.stl"
    v, t = _fan()
    write_stl(path, np.asarray(v, float) * 1e3, np.asarray(t))  # in mm
    sc = dem.Scene(gravity=(0, 0, -9.81))
    m = _material(sc)
    k = sc.add_mesh_wall(path=path, scale=1e-3, material=m)
    assert sc.mesh_wall(k)["num_triangles"] == 8
    assert len(sc.mesh_wall(k)["vertices"]) == 9  # the STL's repeated corners merged
    sc.add_spheres([[0.2 * R, 0.1 * R, R]], [R], material=m)
    sc.dt = 0.2 * sc.critical_dt()
    sc.set_mesh_velocity(k, [0.01, 0, 0])
    sc.run(3000)
    save_checkpoint(tmp_path / "c.h5", sc)
    sc.run(500)
    ref = np.asarray(sc.positions).copy(), sc.mesh_wall(k)
    other = dem.Scene(gravity=(0, 0, -9.81))
    m = _material(other)
    other.add_mesh_wall(path=path, scale=1e-3, material=m)
    other.add_spheres([[0.2 * R, 0.1 * R, R]], [R], material=m)
    load_checkpoint(tmp_path / "c.h5", other)
    other.run(500)
    assert np.array_equal(np.asarray(other.positions), ref[0])
    for key in ("vertices", "force", "moment", "ref"):
        assert np.array_equal(other.mesh_wall(k)[key], ref[1][key]), key
    assert other.mesh_wall(k)["work"] == ref[1]["work"]
    bare = dem.Scene(gravity=(0, 0, -9.81))
    m = _material(bare)
    bare.add_spheres([[0.2 * R, 0.1 * R, R]], [R], material=m)
    with pytest.raises(dem.ParameterError, match="1 mesh walls, this scene has 0"):
        load_checkpoint(tmp_path / "c.h5", bare)


def test_energy_is_balanced_with_a_moving_mesh():
    sc = dem.Scene(gravity=(0, 0, -9.81))
    m = _material(sc)
    k = sc.add_mesh_wall(*_fan(), material=m)
    sc.add_spheres([[0.02, 0.01, R], [-0.03, 0.02, R]], [R, R], material=m)
    sc.dt = 0.2 * sc.critical_dt()
    sc.track_energy = True
    sc.set_mesh_velocity(k, [0.02, 0.01, 0.0])
    sc.run(20000)
    e = sc.energies()
    assert abs(e["wall_work"]) > 100 * abs(e["balance_error"])
    assert e["balance_error_relative"] < 1e-3


@pytest.mark.parametrize("kw, msg", [
    ({"vertices": [[0, 0, 0], [1, 0, 0]], "triangles": [[0, 1, 1]]}, "vertices: 2 given"),
    ({"vertices": SQUARE, "triangles": [[0, 1, 7]]},
     r"triangles\[0\]: vertex 7 is not one of the 4 vertices"),
    ({"vertices": SQUARE, "triangles": [[0, 1, 1]]}, r"triangles\[0\]: degenerate"),
    ({"vertices": [[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], "triangles": [[0, 1, 2]]},
     "vertices"),
    ({"vertices": SQUARE, "triangles": [[0, 1]]}, r"triangles: shape \(1, 2\)"),
    ({"path": "/nonexistent.stl"}, "no such file"),
    ({}, "give vertices"),
])
def test_bad_meshes_are_refused_by_name(kw, msg):
    sc = dem.Scene()
    m = _material(sc)
    with pytest.raises(dem.ParameterError, match=msg):
        sc.add_mesh_wall(material=m, **kw)
    with pytest.raises(dem.ParameterError, match="mesh=2: no such mesh wall"):
        sc.mesh_wall(2)


def test_a_mesh_that_must_be_closed_is_refused_open_or_crossing_and_holds_grains_closed():
    """add_mesh_wall(closed=True): a container or a solid must bound a volume. A box with one
    triangle missing (a hole), the box given as six sheets that do not share their edges,
    and two boxes crossing each other in one mesh are refused by name; the closed box is
    taken and holds the grains dropped in it; closed=False (the default) takes the open
    mesh as before."""
    from cpp_dem.build.clump_mesh import box_mesh

    v, t = box_mesh(0.04)
    sc = dem.Scene(gravity=(0, 0, -9.81))
    m = _material(sc)
    with pytest.raises(dem.ParameterError, match=r"add_mesh_wall\(closed=True\): triangles: "
                       r"edge \(\d+, \d+\) belongs to 1 triangle\(s\), an open boundary"):
        sc.add_mesh_wall(v, t[1:], material=m, closed=True)
    sheets = np.concatenate([v[tri] for tri in np.asarray(t)])  # (each corner its own vertex)
    with pytest.raises(dem.ParameterError, match="open boundary"):
        sc.add_mesh_wall(sheets, np.arange(3 * len(t)).reshape(-1, 3), material=m, closed=True)
    v2, t2 = box_mesh(0.04, centre=(0.02, 0.01, 0.005))
    with pytest.raises(dem.ParameterError, match=r"triangles \d+ .* and \d+ .* cross"):
        sc.add_mesh_wall(np.vstack([v, v2]), np.vstack([t, np.asarray(t2) + len(v)]),
                         material=m, closed=True)
    with pytest.raises(dem.ParameterError, match="closed=1: must be True or False"):
        sc.add_mesh_wall(v, t, material=m, closed=1)
    assert sc.num_mesh_walls == 0  # (nothing refused was added)
    sc.add_mesh_wall(v, t, material=m, closed=True)
    g = (np.arange(3) - 1) * 2.2 * R
    sc.add_spheres([[a, b, 0.0] for a in g for b in g], np.full(9, R), material=m)
    sc.dt = 0.2 * sc.critical_dt()
    sc.run(4000)
    x = np.asarray(sc.positions)
    assert np.all(np.abs(x) < 0.02 - 0.9 * R)  # inside the box,
    assert x[:, 2].max() < -0.02 + 1.2 * R  # on its floor
    other = dem.Scene()
    other.add_mesh_wall(v, t[1:], material=_material(other))  # open: taken as it is
    assert other.num_mesh_walls == 1


def _fine_square(n: int, half: float):
    """The square [-half, half]^2 at z = 0 cut into n x n cells of two triangles each."""
    s = np.linspace(-half, half, n + 1)
    v = np.array([[x, y, 0.0] for y in s for x in s])
    t = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            t += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    return v, t


# The mesh pass's two forms of the linear law: the general one (a dashpot), the short kernel.
@pytest.mark.parametrize("damping_normal", [0.7, 0.0], ids=["general_law", "short_kernel"])
def test_a_sphere_rolls_over_a_fine_mesh_as_over_the_plane(damping_normal):
    # Triangles a fifth of the sphere's radius: dozens within its reach at every step, many
    # edges crossed. The path stays the plane's (one contact at a time, its history carried).
    v, t = _fine_square(60, 6 * R)
    g = (2.0, 1.5, -9.81)
    out = {}
    for kind in ("mesh", "plane"):
        sc = dem.Scene(gravity=g)
        m = _material(sc, damping_normal=damping_normal)
        if kind == "mesh":
            k = sc.add_mesh_wall(v, t, material=m)
        else:
            sc.add_wall(axis=2, position=0.0, sense=1, material=m)
        sc.add_spheres([[-4 * R, -4 * R, R - 1e-6]], [R], material=m)
        sc.dt = 0.2 * sc.critical_dt()
        sc.run(12000)
        out[kind] = np.asarray(sc.positions)[0]
        if kind == "mesh":
            assert sc.mesh_dropped_contacts == 0
    assert np.linalg.norm(out["plane"][:2] - [-4 * R, -4 * R]) > 3 * R  # it travelled
    assert np.abs(out["mesh"] - out["plane"]).max() <= 1e-9 * R


def test_a_mesh_plate_servoed_to_a_stress_holds_it():
    # A two-triangle plate above grains in a box, servoed down to 10 kPa (MeshServo), as a
    # loading plate: it holds the stress within 2 %, and the box carries its push.
    from cpp_dem.build.packing import loose_cloud

    c, r = loose_cloud(np.full(120, 0.002), (0, 0, 0), (0.03, 0.03, 0.02), seed=2)
    sc = dem.Scene(local_damping=0.3)
    # (No viscous damping here: a force that follows the plate's speed makes a servo at its
    # cap chatter.)
    m = sc.add_material(dem.linear_material(density=2000, young=1e7, poisson=0.3,
                                            friction_angle_deg=20))
    walls = sc.add_box((0, 0, 0), (0.03, 0.03, 0.03), material=m)
    sc.add_spheres(c, r, material=m)
    lid = np.array([[0, 0, 0.022], [0.03, 0, 0.022], [0.03, 0.03, 0.022], [0, 0.03, 0.022]])
    k = sc.add_mesh_wall(lid, [[0, 1, 2], [0, 2, 3]], material=m)
    sc.dt = 0.3 * sc.critical_dt()
    servo = dem.MeshServo(mesh=k, direction=(0, 0, -1), target_stress=10e3, area=0.03**2,
                          max_speed=0.2)
    sc.add_controller(servo)
    with pytest.raises(dem.ParameterError, match="mesh wall 0 is moved by controller 0"):
        sc.add_controller(dem.MeshServo(mesh=k, direction=(0, 0, -1), target_stress=1.0,
                                        area=1.0, max_speed=0.1))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", dem.ControllerLimitWarning)  # (closing in at the cap)
        held = 0
        for _ in range(60):
            sc.run(1000)
            ok = abs(servo.measured_stress / 10e3 - 1) < 0.02
            held = held + 1 if ok else 0
            if held == 3:
                break
    assert held == 3, servo.measured_stress
    f = np.asarray(sc.mesh_wall(k)["force"])
    assert f[2] / 0.03**2 == pytest.approx(servo.measured_stress, rel=0.05)  # (pushed up)
    # At rest (no gravity) the box's walls (the floor, and the sides by friction) carry the
    # plate's push.
    box_z = np.asarray(sc.wall_forces)[walls][:, 2].sum()
    assert -box_z == pytest.approx(f[2], rel=0.02)
    with pytest.raises(dem.ParameterError, match="direction=.*non-zero"):
        dem.MeshServo(mesh=k, direction=(0, 0, 0), target_stress=1.0, area=1.0, max_speed=0.1)


def test_the_mesh_pass_is_the_same_on_one_and_two_threads():
    # 400 grains on a fine mesh floor (its contacts are split between the threads above 128).
    v, t = _fine_square(40, 0.05)
    g = np.arange(20) * 2.05 * R - 0.039
    x = np.array([[a, b, R - 1e-6] for a in g for b in g])
    states = []
    threads = dem.get_num_threads()
    try:
        for n in (1, 2):
            dem.set_num_threads(n)
            sc = dem.Scene(gravity=(1.0, 0.5, -9.81))
            m = _material(sc)
            sc.add_mesh_wall(v, t, material=m)
            sc.add_spheres(x, np.full(len(x), R), material=m)
            sc.dt = 0.2 * sc.critical_dt()
            sc.run(500)
            states.append((np.asarray(sc.positions).copy(), np.asarray(sc.mesh_wall(0)["force"])))
    finally:
        dem.set_num_threads(threads)
    assert np.array_equal(states[0][0], states[1][0])
    assert np.array_equal(states[0][1], states[1][1]) and states[0][1][2] < 0  # (pushed down)


def test_a_checkpoint_loaded_over_another_mesh_takes_the_loaded_faces(tmp_path):
    """A face's contact comes from its triangle's normal (computed when the mesh is added, not
    saved): loaded into a scene whose mesh has the same triangles elsewhere (tilted 30
    degrees), a checkpoint's mesh pushes along its own faces' normals, the run going on as the
    saved one to the bit; loaded over the same mesh, the same too (its normals kept)."""
    tilted = SQUARE @ _tilt(30, 0).T

    def scene(vertices):
        sc = dem.Scene(gravity=(0.5, 0.2, -9.81))
        m = _material(sc)
        sc.add_mesh_wall(vertices, SQUARE_TRIS, material=m)
        sc.add_spheres([[0.3 * R, 0.1 * R, 0.99 * R]], [R], material=m)
        sc.dt = 0.2 * sc.critical_dt()
        return sc

    sc = scene(SQUARE)
    sc.set_mesh_velocity(0, [0.003, 0.001, 0.0])
    sc.run(2000)
    path = tmp_path / "c.h5"
    save_checkpoint(path, sc)
    sc.run(1000)
    want = np.asarray(sc.positions).copy(), np.asarray(sc.mesh_wall(0)["force"])
    assert want[1][2] < 0  # (the sphere rests on the face: it pushes the mesh down)
    for vertices in (SQUARE, tilted):
        other = scene(vertices)
        other.set_mesh_velocity(0, [0.003, 0.001, 0.0])
        load_checkpoint(path, other)
        other.run(1000)
        assert np.array_equal(np.asarray(other.positions), want[0])
        assert np.array_equal(np.asarray(other.mesh_wall(0)["force"]), want[1])
