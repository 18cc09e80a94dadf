"""Prestress of geogrid members (issue 16): tension to T_p, lock, hold within 1 %."""

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem.build import geogrid
from cpp_dem.build import woven
from cpp_dem.protocols.prestress import Prestress, PrestressError


def _woven():
    s = cd.Scene(local_damping=0.7)
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=3, apertures_y=1, material=m)
    s.dt = 0.5 * s.critical_dt()
    return s, g


def _cylinders(kind="square"):
    s = cd.Scene(local_damping=0.7)
    m = s.add_material(cd.linear_material(density=1000, young=1e8, poisson=0.3,
                                          friction_angle_deg=30))
    bp = cd.BeamParams(young=4e9, poisson=0.3, radius=1e-3)
    if kind == "square":
        g = geogrid.square_grid(s, origin=(0, 0, 0), length=0.1, width=0.05, nodes_x=6,
                                nodes_y=3, params=bp, material=m, density=1000)
    else:
        g = geogrid.biaxial_geogrid(s, origin=(0, 0, 0), apertures_x=2, apertures_y=1,
                                    aperture_area=4e-4, rib_width=4e-3, params=bp, material=m,
                                    density=1000)
    s.dt = 0.5 * s.critical_dt()
    return s, g


@pytest.mark.parametrize("make, kw, spread", [
    (_woven, dict(tension_per_m=1000.0), 0.01),  # 1 kN/m x 27 mm pitch = 27 N per member
    (_cylinders, dict(tension_n=20.0), 0.01),
    # A PFacet rib's mid-section force also counts its diagonal link (docs/pullout.md), so
    # its members read 2 % apart while the line's mean is on target.
    (lambda: _cylinders("pfacet"), dict(tension_n=20.0), 0.03),
    (_woven, dict(tension_n=10.0, direction="transverse"), 0.01),
])
def test_prestress_is_reached_locked_and_held(make, kw, spread):
    s, g = make()
    p = Prestress(s, g, **kw)
    row = p.tension(100000)
    assert p.locked and row["deviation"] <= 0.01
    # Locked: the ends are held, the run goes on, the force stays within 1 %.
    s.run(20000)
    held = p.check_locked(0.01)
    assert held["deviation"] <= 0.01
    # Uniform along the members of a line (no grains): every member at the line's force.
    f = p.member_forces()
    assert np.max(np.abs(f / p.target_n - 1)) <= spread
    assert len(p.history) == 2


def test_per_metre_is_per_member_times_the_spacing():
    s, g = _woven()
    p = Prestress(s, g, tension_per_m=1000.0)
    assert p.target_n == pytest.approx(1000.0 * g.pitch[1], rel=1e-12)


def test_unreachable_prestress_says_so():
    s, g = _woven()
    p = Prestress(s, g, tension_n=27.0, max_speed=1e-6)
    with pytest.raises(PrestressError, match="not reached"):
        p.tension(500)


def test_drift_after_locking_says_so():
    s, g = _woven()
    p = Prestress(s, g, tension_n=27.0)
    p.tension(100000)
    # Move a held end by hand: the locked-in force is lost, and the check says so.
    pos = s.positions
    pos[p.pulled, 0] -= 2e-5
    s.positions = pos
    s.run(5000)
    with pytest.raises(PrestressError, match="drifted"):
        p.check_locked()


@pytest.mark.parametrize("kw, field", [
    (dict(), "tension_n"),
    (dict(tension_n=1.0, tension_per_m=1.0), "tension_n"),
    (dict(tension_n=-1.0), "tension"),
    (dict(tension_n=1.0, direction="diagonal"), "direction"),
    (dict(tension_n=1.0, tolerance=0.0), "tolerance"),
])
def test_bad_input_names_the_field(kw, field):
    s, g = _woven()
    with pytest.raises(cd.ParameterError, match=field):
        Prestress(s, g, **kw)


def test_end_tension_pulls_each_line_by_t_times_spacing():
    """EndTension (issue 18's hand-over of an FEM layer's tension): a free square grid pulled
    at its ends by T = 1 kN/m. Every longitudinal member then carries T x spacing = 25 N and
    stretches by F L / (E A); the transverse members carry nothing. Measured: 1.1e-7 and
    5e-14 relative; asserted 1e-5."""
    from cpp_dem.protocols.prestress import EndTension

    s, g = _cylinders()
    e = EndTension(s, g)
    e.set(1000.0)
    assert e.ends.spacing == pytest.approx(0.025, rel=1e-12)
    assert e.line_force_n == pytest.approx(25.0, rel=1e-12)
    ext = np.asarray(s.external_forces)
    assert np.sum(ext, axis=0) == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)
    x0 = np.asarray(s.positions)[:, 0].copy()
    s.run(20000)
    np.testing.assert_allclose(e.line_forces(), 25.0, rtol=1e-5)
    f = g.member_axial_forces(s)
    longi = np.asarray(g.member_direction) == geogrid.LONGITUDINAL
    assert np.abs(f[~longi]).max() < 1e-5 * 25.0
    x = np.asarray(s.positions)[:, 0]
    stretch = (x[e.ends.high] - x0[e.ends.high]).mean() - (x[e.ends.low] - x0[e.ends.low]).mean()
    assert stretch / 0.1 == pytest.approx(25.0 / (4e9 * np.pi * 1e-6), rel=1e-5)
    # set() replaces its own forces: back to 0, the ends are free again
    e.set(0.0)
    assert np.abs(np.asarray(s.external_forces)).max() == 0.0


def test_end_tension_on_a_woven_grid_gives_the_lines_their_mean():
    """A woven grid's end patch joins its lines through the transverse member, so the lines
    share the pull unevenly (measured 25.8 / 29.4 / 25.8 N); their mean is T x pitch."""
    from cpp_dem.protocols.prestress import EndTension

    s = cd.Scene(local_damping=0.7)
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=3, apertures_y=2, material=m)
    s.dt = 0.5 * s.critical_dt()
    e = EndTension(s, g)
    e.set(1000.0)
    s.run(40000)
    assert e.line_forces().mean() == pytest.approx(1000.0 * g.pitch[1], rel=1e-3)


def test_unlocked_prestress_handed_to_end_forces_keeps_its_force():
    """A locked prestress whose grips let go (Prestress.unlock) with the ends then pulled by
    the same tension (EndTension) keeps the lines at the target (the PRS element's hand-over
    of the FEM layer tension)."""
    from cpp_dem.protocols.prestress import EndTension

    s, g = _cylinders()
    p = Prestress(s, g, tension_per_m=800.0)
    p.tension(100000)
    p.unlock()
    assert not p.locked
    EndTension(s, g).set(800.0)
    s.run(20000)
    np.testing.assert_allclose(p.line_forces(), p.target_n, rtol=1e-5)


def test_end_tension_bad_input_names_the_field():
    from cpp_dem.protocols.prestress import EndTension

    s, g = _cylinders()
    e = EndTension(s, g)
    with pytest.raises(cd.ParameterError, match="tension_per_m=nan"):
        e.set(float("nan"))
    with pytest.raises(cd.ParameterError, match="direction='diagonal'"):
        EndTension(s, g, direction="diagonal")


def test_uniform_tension_gives_every_member_the_target():
    """tension_uniform stretches the whole (free) grid at once: every member carries the
    target (not only the lines' mean), the grid is held while locked and all of it is free
    after unlock."""
    s, g = _woven()
    p = Prestress(s, g, tension_per_m=1000.0)
    row = p.tension_uniform(100000)
    assert p.locked
    assert abs(np.mean(row["line_forces_n"]) / p.target_n - 1) <= 0.01
    np.testing.assert_allclose(p.member_forces(), p.target_n, rtol=0.03)
    s.run(200)  # held: nothing moves, the force stays
    np.testing.assert_allclose(p.line_forces(), row["line_forces_n"], rtol=1e-4)  # (the last step)
    assert all(np.asarray(s._blocked)[g.spheres])
    p.unlock()
    assert not any(np.asarray(s._blocked)[g.spheres])


def test_uniform_tension_unreachable_says_so():
    s, g = _woven()
    p = Prestress(s, g, tension_per_m=1000.0)
    with pytest.raises(PrestressError, match="uniform stretch"):
        p.tension_uniform(100)
