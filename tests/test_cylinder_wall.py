"""Cylindrical walls (Scene.add_cylinder_wall, cpp_dem/src/passes/cylinder_wall.cpp): a sphere
meets the lateral surface as it meets the tangent plane there (force and trajectory against a
plane wall's, to rounding), inside and outside, along a tilted axis; it crosses an open end's
rim with a continuous force; a CylinderServo holds a pressure on a packing that stays inside;
the energy balance counts the wall's work; a checkpoint keeps the walls and their contacts; bad
input is refused by name."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint

R = 0.005  # m, the sphere's radius
E = 1e7  # Pa
R0 = 10 * R  # m, the cylinder's radius
SHIFT = np.array([0.001, 0.002, 0.003])  # m, the cylinder's centre


def _material(sc):
    return sc.add_material(dem.linear_material(density=2000, young=E, poisson=0.3,
                                               friction_angle_deg=30))


def _tilt(a_deg: float = 30.0, b_deg: float = 50.0) -> np.ndarray:
    """A rotation: about x by a, then about z by b."""
    a, b = np.radians([a_deg, b_deg])
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    return rz @ rx


@pytest.mark.parametrize("inside", [True, False])
def test_a_sphere_meets_the_lateral_surface_as_its_tangent_plane(inside):
    # The sphere starts overlapping the surface where its outward radial direction is +x,
    # moving into it and along the axis: a plane wall at x = R0 (facing -x inside, +x
    # outside) in the cylinder's frame. Along the axis the surface is straight, so force,
    # spin and trajectory are the plane's, to rounding, for a cylinder tilted anyhow.
    q = _tilt()
    sense = -1 if inside else 1
    x0 = np.array([R0 + sense * 0.95 * R, 0.0, 0.0])
    v0 = np.array([-sense * 0.02, 0.0, 0.3])  # m/s: into the surface, and along the axis
    plane = dem.Scene()
    m = _material(plane)
    plane.add_wall(axis=0, position=R0, sense=sense, material=m)
    plane.add_spheres([x0], [R], material=m)
    plane.velocities = [v0]
    cyl = dem.Scene()
    m = _material(cyl)
    c = cyl.add_cylinder_wall(centre=SHIFT, axis=q @ [0, 0, 1], radius=R0, inside=inside,
                              material=m)
    cyl.add_spheres([q @ x0 + SHIFT], [R], material=m)
    cyl.velocities = [q @ v0]
    plane.dt = cyl.dt = 0.1 * plane.critical_dt()
    f_max, f_err, touched = 0.0, 0.0, 0
    for _ in range(120):
        plane.run(1)
        cyl.run(1)
        fp = np.asarray(plane.wall_forces)[0]
        fc = q.T @ np.asarray(cyl.cylinder_wall(c)["force"])
        f_max = max(f_max, np.abs(fp).max())
        f_err = max(f_err, np.abs(fp - fc).max())
        touched += fp[0] != 0
        # The normal force is the plane's normal component, compressive positive.
        assert cyl.cylinder_wall(c)["normal_force"] == pytest.approx(abs(fp[0]), rel=1e-9,
                                                                     abs=1e-12 * E * R**2)
    assert touched > 20 and f_max > 1.0  # it was a real contact (N), with friction
    assert f_err <= 1e-9 * f_max
    xp = np.asarray(plane.positions)[0]
    xc = q.T @ (np.asarray(cyl.positions)[0] - SHIFT)
    assert np.abs(xp - xc).max() <= 1e-9 * R
    wp = np.asarray(plane.angular_velocities)[0]
    wc = q.T @ np.asarray(cyl.angular_velocities)[0]
    assert abs(wp[1]) > 1.0  # rad/s: the friction spun it
    assert np.abs(wp - wc).max() <= 1e-9 * abs(wp[1])


def test_a_sphere_crossing_an_open_end_feels_a_continuous_force():
    # Held at a fixed overlap with the inside of a cylinder ending at z = 0, the sphere
    # slides along the axis past the end: the lateral contact becomes the rim's, the force
    # falls smoothly (no jump between steps larger than the change the step's travel
    # explains) and ends once the sphere is clear of the rim.
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2000, young=E, poisson=0.3,
                                            friction_angle_deg=0))
    c = sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=R0, inside=True,
                             material=m, lo=-1.0, hi=0.0)
    delta = 0.02 * R  # m, the overlap
    sc.add_spheres([[R0 - R + delta, 0.0, -0.5 * R]], [R], material=m)
    sc.block_dofs(0, "all")
    sc.velocities = [[0.0, 0.0, 0.05]]  # m/s, along the axis (held: it keeps this velocity)
    sc.dt = 2e-5  # s (a held sphere: no critical step)
    kn = None
    forces = []
    while np.asarray(sc.positions)[0, 2] < 0.5 * R:
        sc.run(1)
        f = np.asarray(sc.cylinder_wall(c)["force"])
        forces.append(np.linalg.norm(f))
        if kn is None:
            kn = forces[0] / delta  # N/m: the law's normal stiffness (frictionless)
    forces = np.array(forces)
    assert forces[0] == pytest.approx(kn * delta, rel=1e-12) and forces[0] > 0
    # The overlap beyond the end: delta_rim = R - sqrt(dz^2 + (R - delta)^2); it reaches zero
    # at dz = sqrt(2 R delta - delta^2): the force must end there, and be zero after.
    dz_end = np.sqrt(2 * R * delta - delta**2)
    travel = 0.05 * sc.dt  # m per step
    z0 = -0.5 * R
    z = z0 + travel * np.arange(1, len(forces) + 1)  # (the position after each step)
    expect = kn * np.clip(R - np.sqrt(np.clip(z, 0, None) ** 2 + (R - delta) ** 2), 0, None)
    # (forces[k] is computed at the position before step k's move)
    before = np.concatenate([[z0], z[:-1]])
    expect = kn * np.clip(R - np.sqrt(np.clip(before, 0, None) ** 2 + (R - delta) ** 2), 0,
                          None)
    assert np.abs(forces - expect).max() <= 1e-9 * forces[0]
    jumps = np.abs(np.diff(forces))
    assert jumps.max() <= 2 * kn * travel * (dz_end / (R - delta))  # the slope's bound
    assert np.all(forces[before > dz_end + travel] == 0)


def _column(seed: int = 1):
    """360 spheres on a square lattice inside a cylinder of radius 8.5 R between a floor
    and a lid, a CylinderServo and a ServoWall on the lid to the same pressure."""
    r = 0.002
    rng = np.random.default_rng(seed)
    g = np.arange(-4, 5) * 2.0 * r
    pts = np.array([[x, y, (k + 0.5) * 2.0 * r] for x in g for y in g for k in range(8)
                    if np.hypot(x, y) <= 7.5 * r])
    rad = r * rng.uniform(0.97, 1.0, len(pts))
    rc, h = 8.5 * r, 16 * r
    sc = dem.Scene(local_damping=0.3)
    m = sc.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                            friction_angle_deg=20))
    c = sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=rc, inside=True,
                             material=m, lo=0.0, hi=h)
    sc.add_wall(axis=2, position=0.0, sense=1, material=m)
    lid = sc.add_wall(axis=2, position=h, sense=-1, material=m)
    sc.add_spheres(pts, rad, material=m)
    sc.dt = 0.3 * sc.critical_dt()
    return sc, c, lid, rc


def test_a_cylinder_servo_holds_its_pressure_and_the_grains_stay_inside():
    P = 20e3  # Pa
    sc, c, lid, rc = _column()
    sc.track_energy = True
    cs = dem.CylinderServo(cylinder=c, target_pressure=P, max_speed=0.05)
    lw = dem.ServoWall(wall=lid, target_stress=P, area=np.pi * rc**2, max_speed=0.05)
    sc.add_controller(cs)
    sc.add_controller(lw)
    with pytest.warns(dem.ControllerLimitWarning, match="CylinderServo, cylindrical wall 0"):
        sc.run(2000)  # (compacting at the cap from nothing: said)
    held = 0
    for _ in range(30):
        sc.run(500)
        w = sc.cylinder_wall(c)
        ok = abs(w["pressure_pa"] / P - 1) < 0.02 and abs(lw.measured_stress / P - 1) < 0.02
        held = held + 1 if ok else 0
        if held == 3:
            break
    assert held == 3, (w["pressure_pa"], lw.measured_stress)
    # The servo measures the wall's pressure (at the start of the last step: one step off).
    assert w["pressure_pa"] == pytest.approx(
        w["normal_force"] / (2 * np.pi * w["radius"] * (w["hi"] - w["lo"])), rel=1e-12)
    assert cs.measured_pressure == pytest.approx(w["pressure_pa"], rel=1e-3)
    assert w["radius"] < rc  # it closed on the grains
    x = np.asarray(sc.positions)
    rho = np.hypot(x[:, 0], x[:, 1])
    assert np.all(rho < w["radius"])  # no centre outside
    assert np.max(rho + np.asarray(sc.radii) - w["radius"]) < 0.05 * 0.002  # overlaps small
    e = sc.energies()
    # The cylinder's work is in the balance: it is large against the balance's error.
    assert abs(e["wall_work"]) > 100 * abs(e["balance_error"])
    assert e["balance_error_relative"] < 2e-3


def test_a_checkpoint_keeps_the_cylinder_and_its_contacts(tmp_path):
    sc, c, lid, rc = _column()
    sc.set_cylinder_radial_velocity(c, -0.1)  # m/s: closing on the grains
    sc.run(2000)
    assert sc.cylinder_wall(c)["normal_force"] > 0  # (contacts with history to keep)
    path = tmp_path / "c.h5"
    save_checkpoint(path, sc)
    sc.run(300)
    ref = np.asarray(sc.positions).copy(), sc.cylinder_wall(c)
    other, c2, _, _ = _column()
    load_checkpoint(path, other)
    other.run(300)
    assert np.array_equal(np.asarray(other.positions), ref[0])
    for k in ("radius", "normal_force", "work", "radial_velocity"):
        assert other.cylinder_wall(c2)[k] == ref[1][k], k
    assert np.array_equal(other.cylinder_wall(c2)["force"], ref[1]["force"])
    # Into a scene without the cylinder: refused, by name.
    bare = dem.Scene(local_damping=0.3)
    m = bare.add_material(dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                              friction_angle_deg=20))
    bare.add_wall(axis=2, position=0.0, sense=1, material=m)
    bare.add_wall(axis=2, position=16 * 0.002, sense=-1, material=m)
    bare.add_spheres(np.asarray(sc.positions), np.asarray(sc.radii), material=m)
    with pytest.raises(dem.ParameterError, match="1 cylindrical walls, this scene has 0"):
        load_checkpoint(path, bare)


@pytest.mark.parametrize("kw, msg", [
    ({"radius": 0.0}, "radius=0: must be > 0 (m)"),
    ({"radius": float("nan")}, "radius=nan: must be > 0 (m)"),
    ({"axis": [0, 0, 0]}, "axis=(0, 0, 0): must be a finite non-zero vector"),
    ({"centre": [0, float("inf"), 0]}, "centre=(0, inf, 0): must be finite (m)"),
    ({"lo": 1.0, "hi": 0.5}, "hi=0.5: must be above lo=1 (m along the axis"),
    ({"material": 7}, "material"),
])
def test_bad_cylinders_are_refused_by_name(kw, msg):
    sc = dem.Scene()
    m = _material(sc)
    args = {"centre": [0, 0, 0], "axis": [0, 0, 1], "radius": R0, "inside": True,
            "material": m, **kw}
    with pytest.raises(dem.ParameterError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        sc.add_cylinder_wall(**args)


def test_what_a_cylinder_cannot_do_is_said():
    sc = dem.Scene()
    m = _material(sc)
    c = sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=R0, inside=True,
                             material=m)
    with pytest.raises(dem.ParameterError, match="cylinder=3: no such cylindrical wall"):
        sc.cylinder_wall(3)
    with pytest.raises(dem.ParameterError, match="periodic cell: the scene has cylindrical walls"):
        sc.set_periodic_cell(np.eye(3) * 0.2, periodic=(True, True, True))
    # A servo needs a finite lateral area.
    sc.add_spheres([[R0 - 0.99 * R, 0, 0]], [R], material=m)
    sc.dt = 0.1 * sc.critical_dt()
    sc.add_controller(dem.CylinderServo(cylinder=c, target_pressure=1e3, max_speed=0.01))
    with pytest.raises(dem.ParameterError, match="cylindrical wall 0 is infinite"):
        sc.run(1)
    # Two servos on one cylinder would set its rate in turn: refused, naming it.
    with pytest.raises(dem.ParameterError, match="cylindrical wall 0 is moved by controller 0"):
        sc.add_controller(dem.CylinderServo(cylinder=c, target_pressure=2e3, max_speed=0.01))
    with pytest.raises(dem.ParameterError, match="target_pressure"):
        dem.CylinderServo(cylinder=c, target_pressure=-1.0, max_speed=0.01)
    # A radius that shrinks to nothing is stopped, not run through.
    sc2 = dem.Scene()
    m2 = _material(sc2)
    c2 = sc2.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=1e-4, inside=False,
                               material=m2)
    sc2.add_spheres([[1.0, 1.0, 1.0]], [R], material=m2)
    sc2.dt = 1e-4
    sc2.set_cylinder_radial_velocity(c2, -1.0)
    with pytest.raises(dem.BlowUpError, match="cylindrical wall 0 at step [0-9]+: its radius fell to"):
        sc2.run(5)


def test_the_documented_example_runs_and_holds_its_pressure():
    # docs/core.md's example under "Cylindrical walls", run as shown.
    from conftest import run_list_item_example

    out = run_list_item_example("core.md", "**Cylindrical walls**")
    p, radius = (float(v) for v in out.split())
    assert p == pytest.approx(20e3, rel=0.05)
    assert radius < 0.017  # m: closed on the grains


def test_a_sphere_behind_a_cylinder_is_refused_and_the_series_record_it(tmp_path):
    from cpp_dem.io.series import standard_series

    sc = dem.Scene()
    m = _material(sc)
    sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=R0, inside=True, material=m,
                         lo=0.0, hi=0.1)
    with pytest.raises(dem.ParameterError, match="outside cylindrical wall 0, behind it"):
        sc.add_spheres([[0, 0, 0.05], [2 * R0, 0, 0.05]], [R, R], material=m)
    sc.add_spheres([[0, 0, 0.05], [2 * R0, 0, 0.2]], [R, R], material=m)  # beyond its end: kept
    sc.positions = [[0, 0, 0.05], [2 * R0, 0, 0.05]]  # moved behind it
    sc.dt = 0.1 * sc.critical_dt()
    with pytest.raises(dem.ParameterError, match="body 1 .* outside cylindrical wall 0"):
        sc.run(1)
    series = standard_series(sc)
    assert series["cylinder_radius_0"][0](sc) == R0
    assert series["cylinder_normal_force_0"][1] == "N"


def test_a_loose_cloud_fills_a_cylinder_without_overlaps():
    from cpp_dem.build.packing import loose_cylinder

    rng = np.random.default_rng(3)
    radii = rng.uniform(0.8, 1.2, 300) * 0.002
    c, r = loose_cylinder(radii, 0.02, 0.06, centre=(0.1, -0.2, 0.5), seed=4)
    c2, r2 = loose_cylinder(radii, 0.02, 0.06, centre=(0.1, -0.2, 0.5), seed=4)
    assert np.array_equal(c, c2) and np.array_equal(r, r2)  # seeded
    assert sorted(r) == sorted(radii)
    rho = np.hypot(c[:, 0] - 0.1, c[:, 1] + 0.2)
    assert np.all(rho + r <= 0.02 + 1e-15)
    assert np.all(c[:, 2] - r >= 0.5 - 1e-15) and np.all(c[:, 2] + r <= 0.56 + 1e-15)
    d = np.linalg.norm(c[:, None] - c[None], axis=2) - (r[:, None] + r[None])
    np.fill_diagonal(d, 1.0)
    assert d.min() >= 0
    # The spheres fit the scene's cylinder: none is behind it.
    sc = dem.Scene()
    m = _material(sc)
    sc.add_cylinder_wall(centre=[0.1, -0.2, 0.5], axis=[0, 0, 1], radius=0.02, inside=True,
                         material=m, lo=0.0, hi=0.06)
    sc.add_spheres(c, r, material=m)
    with pytest.raises(dem.ParameterError, match="radius=0.001: must be > the largest grain"):
        loose_cylinder(radii, 0.001, 0.06)
    with pytest.raises(dem.ParameterError, match=r"height=0.0: must be > 0 \(m\)"):
        loose_cylinder(radii, 0.02, 0.0)
    with pytest.raises(dem.ParameterError, match="loose_cylinder: could not place .* of the "
                                                 "cylinder"):
        loose_cylinder(radii, 0.01, 0.02, max_tries=50)
