"""cpp_dem.elements.boundaries (issue 35): per-wall boundaries of a box element, fixed or
stress-controlled (002 Fig. 1), and the check that a fixed wall carries what its opposite
servo wall does."""

import re

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core, measure
from cpp_dem.elements import boundaries
from cpp_dem.protocols.triaxial import build_box_sample


def one_sphere_box(gap=1e-4):
    """One elastic sphere between the walls of a box that it touches on z only."""
    r = 0.005
    s = build_box_sample(np.array([[0.01, 0.01, r + 0.5 * gap]]), np.array([r]), (0, 0, 0),
                         (0.02, 0.02, 2 * r + gap), young=1e7, poisson=0.3, friction_deg=30,
                         density=2600, local_damping=0.3)
    return s, r


def test_fixed_wall_stays_and_the_servo_wall_reaches_the_stress():
    s, r = one_sphere_box()
    sc = s.scene
    ws = boundaries.WallServos(sc, s.walls, ("z-",), max_speed=0.01)
    assert sorted(ws.servos) == [0, 1, 2, 3, 5]  # every wall but z-
    z0 = sc.wall_positions[s.walls[4]]
    ws.set_stress(2, 5e3)
    ws.enabled = True
    sc.set_auto_timestep(safety=0.5, period=10)
    area = 0.02 * 0.02
    for _ in range(60):
        sc.run(500)
        if abs(sc.wall_forces[s.walls[5]][2] / (5e3 * area) - 1) < 1e-4:
            break
    st = measure.wall_stresses(sc, s.walls)
    assert st[5] == pytest.approx(5e3, rel=1e-4)
    assert sc.wall_positions[s.walls[4]] == z0  # the fixed wall has not moved
    # The sphere carries the top wall's force through to the fixed bottom: no imbalance.
    assert st[4] == pytest.approx(st[5], rel=1e-3)
    imb = boundaries.imbalance(sc, s.walls, ("z-",), [1.0, 1.0, 5e3])
    assert imb[2] < 1e-3 and imb[0] == 0 and imb[1] == 0
    assert boundaries.axis_stresses(sc, s.walls, ("z-",))[2] == pytest.approx(st[5])
    ws.enabled = False
    assert np.all(np.asarray(sc.wall_velocities)[s.walls[5]] == 0)


def test_imbalance_sees_a_fixed_wall_that_carries_less():
    # A fixed bottom that carries less than the top (the packing still moving, or held
    # elsewhere) is found; the weight of what rests on the bottom is allowed for.
    s, r = one_sphere_box(gap=-1e-5)  # pressed between the z walls: equal forces
    sc = s.scene
    sc.run(1)
    st = measure.wall_stresses(sc, s.walls)
    assert st[4] > 0 and st[4] == pytest.approx(st[5])
    target = [1.0, 1.0, st[5]]
    assert boundaries.imbalance(sc, s.walls, ("z-",), target)[2] < 1e-9
    # The same forces, read as if 10 % of the target were weight on the bottom: the bottom
    # should then carry 10 % more than the top, and does not.
    w = 0.1 * st[5]
    assert boundaries.imbalance(sc, s.walls, ("z-",), target, w)[2] == pytest.approx(0.1)
    assert boundaries.imbalance(sc, s.walls, ("z+",), target, w)[2] == pytest.approx(0.1)
    # Signed: the fixed bottom carries less than it should (-); a fixed top more (+).
    assert boundaries.imbalance(sc, s.walls, ("z-",), target, w,
                                signed=True)[2] == pytest.approx(-0.1)
    assert boundaries.imbalance(sc, s.walls, ("z+",), target, w,
                                signed=True)[2] == pytest.approx(0.1)


@pytest.mark.parametrize("text, msg", [
    ("x-,q+", "'q+' is not a wall"),
    ("z-,z+", "both z walls fixed"),
    ("y-,y-", "named twice"),
])
def test_bad_fixed_walls_are_named(text, msg):
    with pytest.raises(_core.ParameterError, match=re.escape(msg)):
        boundaries.parse_fixed_walls(text)
    assert boundaries.parse_fixed_walls("x-, y-,z-") == ("x-", "y-", "z-")
    assert boundaries.parse_fixed_walls("") == ()


def test_weight_stress_is_the_solid_weight_over_the_base():
    s, r = one_sphere_box()
    w = boundaries.weight_stress(s.scene, s.walls, 9.81, 2600.0)
    assert w == pytest.approx(4 / 3 * np.pi * r**3 * 2600 * 9.81 / (0.02 * 0.02))
    assert boundaries.weight_stress(s.scene, s.walls, 0.0, 2600.0) == 0.0


def test_a_stage_at_its_unbalanced_floor_is_found_and_a_slow_descent_is_not():
    from cpp_dem.elements.box import at_floor

    rng = np.random.default_rng(1)
    floor = list(0.08 + 0.005 * rng.random(60))          # noise about a floor
    assert at_floor(floor, 20)
    descent = list(0.08 * 0.99 ** np.arange(60))          # 1 % per record: 18 % per window
    assert not at_floor(descent, 20)
    off = floor[:-1] + [float("inf")]                      # the walls off target at the end
    assert not at_floor(off, 20)
    assert not at_floor(floor[:40], 20)                    # too short to tell
    assert not at_floor(floor, 0)


def test_balance_is_judged_on_the_mean_over_a_window():
    """Wall forces that fluctuate by +-8 % about a balance pass once the window is full; a
    fixed wall that carries 10 % less throughout (a creeping packing) does not, whatever its
    fluctuation."""
    rng = np.random.default_rng(3)
    w = boundaries.BalanceWindow(records=25, tol=0.05)
    ratios = [w.add([rng.uniform(-0.08, 0.08), 0.0, 0.0]) for _ in range(60)]
    assert all(np.isinf(r) for r in ratios[:24]) and max(ratios[24:]) <= 1.0
    w = boundaries.BalanceWindow(records=25, tol=0.05)
    ratios = [w.add([0.0, 0.0, -0.1 + rng.uniform(-0.08, 0.08)]) for _ in range(60)]
    assert min(ratios[24:]) > 1.5
