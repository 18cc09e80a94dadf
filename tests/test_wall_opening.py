"""A wall with an opening (Scene.set_wall_opening): a body whose centre lies in the opening
passes the wall without contact; every other body meets the plane as before. The pull-out
box's front slot uses it. The opening is kept by a checkpoint, and bad input is refused by
name."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint

R = 0.005  # m
E = 1e7  # Pa


def _floor_scene(opening: tuple | None):
    """Two spheres falling onto the floor z = 0: one at x = 0, one at x = 4 R."""
    sc = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.5)
    m = sc.add_material(dem.linear_material(density=2000, young=E, poisson=0.3,
                                            friction_angle_deg=30))
    w = sc.add_wall(axis=2, position=0.0, sense=1, material=m)
    if opening is not None:
        sc.set_wall_opening(w, axis=opening[0], lo=opening[1], hi=opening[2])
    sc.add_spheres([[0, 0, 1.2 * R], [4 * R, 0, 1.2 * R]], [R, R], material=m)
    sc.dt = 0.2 * sc.critical_dt()
    return sc, w


def test_a_centre_in_the_opening_passes_the_wall_and_one_outside_rests_on_it():
    sc, w = _floor_scene((0, -R, R))  # open for |x| < R: the first sphere only
    sc.run(int(0.3 / sc.dt))  # (damped: the first sphere falls ~8 R, the second settles)
    z = np.asarray(sc.positions)[:, 2]
    assert z[0] < -R  # through the plane, untouched by it
    assert z[1] == pytest.approx(R, abs=0.05 * R)  # resting on it
    # The wall carries the resting sphere's weight only.
    weight = 2000 * 4 / 3 * np.pi * R**3 * 9.81
    assert float(np.asarray(sc.wall_forces)[w][2]) == pytest.approx(-weight, rel=0.02)


def test_a_closed_wall_holds_both_and_closing_an_opening_restores_it():
    for opening in (None, (1, 10.0, 11.0)):  # closed; open only far away in y
        sc, _ = _floor_scene(opening)
        sc.run(int(0.05 / sc.dt))
        z = np.asarray(sc.positions)[:, 2]
        assert np.all(z > 0.9 * R), opening
    sc, w = _floor_scene((0, -R, R))
    assert sc.wall_opening(w) == (0, -R, R)
    sc.set_wall_opening(w, axis=-1)
    assert sc.wall_opening(w)[0] == -1
    sc.run(int(0.05 / sc.dt))
    assert np.all(np.asarray(sc.positions)[:, 2] > 0.9 * R)


def test_the_opening_goes_by_the_centre_not_the_sphere():
    # Open for x in (R/2, 3 R): the sphere at x = 0 overlaps the band but its centre is
    # outside, so it is held; the one at 4 R is outside too.
    sc, _ = _floor_scene((0, 0.5 * R, 3 * R))
    sc.run(int(0.05 / sc.dt))
    assert np.all(np.asarray(sc.positions)[:, 2] > 0.9 * R)


def test_a_checkpoint_keeps_the_opening_and_the_restart_is_exact(tmp_path):
    a, w = _floor_scene((0, -R, R))
    b, _ = _floor_scene((0, -R, R))
    n = int(0.01 / a.dt)
    a.run(n)
    save_checkpoint(tmp_path / "ck.h5", a)
    c, _ = _floor_scene(None)  # rebuilt without the opening: the checkpoint brings it
    load_checkpoint(tmp_path / "ck.h5", c)
    assert c.wall_opening(w) == (0, -R, R)
    a.run(n)
    c.run(n)
    b.run(2 * n)
    assert np.array_equal(np.asarray(a.positions), np.asarray(c.positions))
    assert np.array_equal(np.asarray(b.positions), np.asarray(c.positions))


@pytest.mark.parametrize("kw, match", [
    (dict(axis=2, lo=0.0, hi=1.0), r"axis=2 \(opening of wall 0\).*not the wall's own axis 2"),
    (dict(axis=3, lo=0.0, hi=1.0), r"axis=3"),
    (dict(axis=0, lo=1.0, hi=1.0), r"hi=1.*above lo=1"),
    (dict(axis=0, lo=float("nan"), hi=1.0), r"lo=nan"),
])
def test_bad_openings_are_refused_by_name(kw, match):
    sc, w = _floor_scene(None)
    with pytest.raises(_core.ParameterError, match=match):
        sc.set_wall_opening(w, **kw)
    with pytest.raises(_core.ParameterError, match="wall"):
        sc.set_wall_opening(7, axis=0, lo=0.0, hi=1.0)


def test_a_centre_beyond_the_plane_is_outside_an_opened_wall_only():
    """A grain that left through the opening and moved sideways, its centre half a radius
    beyond the plane outside the opening, is outside the box: an opened wall leaves it alone.
    A closed wall refuses a body there before the run."""
    for opening in ((0, 10 * R, 11 * R), None):
        sc = dem.Scene()
        m = sc.add_material(dem.linear_material(density=2000, young=E, poisson=0.3,
                                                friction_angle_deg=30))
        sc.add_spheres([[0, 0, -0.5 * R]], [R], material=m)  # (before the wall: it is
        w = sc.add_wall(axis=2, position=0.0, sense=1, material=m)  # behind it)
        if opening is not None:
            sc.set_wall_opening(w, axis=opening[0], lo=opening[1], hi=opening[2])
        sc.dt = 0.2 * sc.critical_dt()
        if opening is None:
            with pytest.raises(dem.ParameterError, match="body 0 .* behind wall 0"):
                sc.run(10)
            continue
        sc.run(100)
        assert np.array_equal(np.asarray(sc.positions)[0], [0, 0, -0.5 * R])
        assert np.all(np.asarray(sc.wall_forces)[w] == 0)


def test_an_edge_of_the_opening_pushes_like_the_plane_along_its_own_normal():
    """A sphere in the opening, its centre on the wall's plane half a radius from the edge
    x = R: the edge (a line across the wall) pushes it with the plane's law and overlap
    (R/2), along the edge's normal -x; a closed wall at the same overlap pushes along +z."""
    forces = []
    for opening in ((0, -R, R), None):
        sc = dem.Scene()
        m = sc.add_material(dem.linear_material(density=2000, young=E, poisson=0.3,
                                                friction_angle_deg=30))
        x = [0.5 * R, 0, 0] if opening else [0, 0, 0.5 * R]
        sc.add_spheres([x], [R], material=m)
        w = sc.add_wall(axis=2, position=0.0, sense=1, material=m)
        if opening:
            sc.set_wall_opening(w, axis=opening[0], lo=opening[1], hi=opening[2])
        sc.dt = 0.01 * sc.critical_dt()
        sc.run(1)
        forces.append(np.asarray(sc.wall_forces)[w].copy())
    edge, plane = forces
    assert plane[2] < 0 and np.allclose(plane[:2], 0)  # the sphere pushes the floor down
    assert edge[0] > 0 and edge[1] == 0 and abs(edge[2]) < 1e-9 * edge[0]
    assert edge[0] == pytest.approx(-plane[2], rel=1e-12)


def test_a_sphere_that_leaves_the_opening_sideways_meets_its_edge_not_the_plane():
    """A sphere half through the opening is pushed towards the opening's middle by the edge
    it drifts against, without the plane's one-sided jump (an overlap of R at once)."""
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2000, young=E, poisson=0.3,
                                            friction_angle_deg=30))
    sc.add_spheres([[0, 0, 0]], [R], material=m)
    w = sc.add_wall(axis=2, position=0.0, sense=1, material=m)
    sc.set_wall_opening(w, axis=0, lo=-1.5 * R, hi=1.5 * R)
    sc.velocities = [[0.5, 0, 0]]  # m/s, towards the edge at x = 1.5 R
    sc.dt = 0.05 * sc.critical_dt()
    xs = []
    for _ in range(400):
        sc.run(5)
        xs.append(float(np.asarray(sc.positions)[0, 0]))
    assert max(xs) < 1.5 * R  # held by the edge: the centre never leaves the opening
    assert xs[-1] < max(xs)  # and sent back
