"""Prestress of geogrid members (issue 16): tension to T_p, lock, hold within 1 %."""

import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem import geogrid, woven
from cpp_dem.prestress import Prestress, PrestressError


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
