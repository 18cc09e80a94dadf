"""Per-wall boundary conditions of a box element: each of the six walls either fixed or
stress-controlled (002 Fig. 1: fixed boundaries and the stress boundaries sigma_v, sigma_h).

A box whose six walls all servo keeps the box's own :class:`cpp_dem._core.TriaxialController`
(both walls of an axis move about the centre). With fixed walls, :class:`WallServos` takes its
place: one :class:`cpp_dem._core.ServoWall` per stress-controlled wall, and none on a fixed
wall, which then stays where it is. It has the controller's interface that the element uses
(``set_stress``, ``goal``, ``max_speed``, ``enabled``), so a stage runs either way.

The stress an axis is held at is that of its stress-controlled walls (:func:`axis_stresses`): a
fixed wall also carries, under gravity, the weight of the grains above it, which the servo
wall must not see.

SI units; stresses compression positive.
"""

from __future__ import annotations

import numpy as np

from cpp_dem import _core
from cpp_dem import measure

#: The six walls of Scene.add_box, in order.
WALL_NAMES = ("x-", "x+", "y-", "y+", "z-", "z+")


def parse_fixed_walls(text: str) -> tuple[str, ...]:
    """``'x-,y-,z-'`` -> ('x-', 'y-', 'z-'); '' -> (). At most one wall per axis (an axis with
    both walls fixed cannot be brought to a stress). Raises ParameterError naming the value."""
    names = tuple(t.strip() for t in str(text).split(",") if t.strip())
    bad = [n for n in names if n not in WALL_NAMES]
    if bad:
        raise _core.ParameterError(f"fixed_walls={text!r}: {bad[0]!r} is not a wall; allowed: "
                                   f"a comma-separated list of {', '.join(WALL_NAMES)}")
    for a in "xyz":
        if f"{a}-" in names and f"{a}+" in names:
            raise _core.ParameterError(f"fixed_walls={text!r}: both {a} walls fixed: at most one "
                                       "wall per axis (the other brings the axis to its stress)")
    if len(set(names)) != len(names):
        raise _core.ParameterError(f"fixed_walls={text!r}: a wall is named twice")
    return names


class WallServos:
    """Stress control of a box with some walls fixed: a ServoWall on each free wall, added to
    ``scene`` now (disabled until ``enabled`` is set). ``walls``: the six walls; ``fixed``:
    their names (:data:`WALL_NAMES`) that stay put."""

    def __init__(self, scene, walls, fixed, *, gain: float = 0.5, max_speed: float):
        self.scene, self.walls = scene, list(walls)
        self.fixed = tuple(fixed)
        self.free = [k for k in range(6) if WALL_NAMES[k] not in self.fixed]
        self._goal = np.zeros(3)
        self.servos = {}
        for k in self.free:
            s = _core.ServoWall(wall=self.walls[k], target_stress=0.0, gain=gain,
                                max_speed=max_speed, box_walls=self.walls)
            s.enabled = False
            scene.add_controller(s)
            self.servos[k] = s
        self._enabled = False

    def set_stress(self, axis: int, stress: float) -> None:
        """The stress-controlled walls of ``axis`` servo to ``stress`` (Pa)."""
        self._goal[axis] = float(stress)
        for k in (2 * axis, 2 * axis + 1):
            if k in self.servos:
                self.servos[k].target_stress = float(stress)

    def goal(self, axis: int) -> float:
        """The target stress of ``axis``, Pa."""
        return float(self._goal[axis])

    def mode(self, axis: int) -> str:
        """How ``axis`` is controlled, in TriaxialController.mode's words: always 'stress'
        (the element's final state records it: box.save_final_state)."""
        if axis not in (0, 1, 2):
            raise _core.ParameterError(f"axis={axis!r}: must be 0 (x), 1 (y) or 2 (z)")
        return "stress"

    @property
    def max_speed(self) -> float:
        return next(iter(self.servos.values())).max_speed

    @max_speed.setter
    def max_speed(self, v: float) -> None:
        for s in self.servos.values():
            s.max_speed = float(v)

    @property
    def enabled(self) -> bool:
        return self._enabled

    @enabled.setter
    def enabled(self, on: bool) -> None:
        self._enabled = bool(on)
        for s in self.servos.values():
            s.enabled = bool(on)
        if not on:  # (a disabled servo leaves its last velocity on the wall)
            for k in self.servos:
                self.scene.set_wall_velocity(self.walls[k], (0.0, 0.0, 0.0))

    def limit_report(self) -> list:
        """The servo walls' reports of calls at their speed cap (ServoWall.limit_report)."""
        out = []
        for s in self.servos.values():
            out += s.limit_report()
        return out


def axis_stresses(scene, walls, fixed=()) -> np.ndarray:
    """Per axis, the mean normal stress of its stress-controlled walls, Pa (both walls when
    none is fixed: measure.axis_stresses)."""
    if not fixed:
        return measure.axis_stresses(scene, walls)
    s = measure.wall_stresses(scene, walls)
    out = np.zeros(3)
    for a in range(3):
        ks = [k for k in (2 * a, 2 * a + 1) if WALL_NAMES[k] not in fixed]
        out[a] = float(np.mean(s[ks]))
    return out


#: A box with fixed walls is at rest only when each fixed wall carries what its opposite
#: stress-controlled wall does (plus, at the bottom, the weight above it): within this share
#: of the axis's target stress, -, ...
BALANCE_TOL = 0.05
#: ... averaged over this many records (the walls' forces fluctuate from record to record
#: by several % at a few kPa; the mean is what a creeping packing moves).
BALANCE_RECORDS = 25


def imbalance(scene, walls, fixed, targets, weight_stress_pa: float = 0.0, *,
              signed: bool = False) -> np.ndarray:
    """Per axis with a fixed wall, |sigma_fixed - sigma_free - w| / target, -: how far the
    packing is from carrying the servo wall's stress through to the fixed one. ``w`` is
    ``weight_stress_pa`` (the weight of what lies on the bottom wall per its area, Pa) for a
    fixed z- wall, minus it for a fixed z+ wall, 0 for x and y. Axes without a fixed wall: 0.
    ``signed``: without the absolute value (negative: the fixed wall carries less).

    A packing that creeps towards its fixed walls is not at rest, and under local damping the
    damping forces then carry part of the load: the fixed wall carries less than the servo
    wall, by a share that falls with the creep (docs/prs_element_002.md)."""
    s = measure.wall_stresses(scene, walls)
    out = np.zeros(3)
    for a in range(3):
        for k, other in ((2 * a, 2 * a + 1), (2 * a + 1, 2 * a)):
            if WALL_NAMES[k] in fixed:
                w = 0.0 if a < 2 else (weight_stress_pa if k == 4 else -weight_stress_pa)
                out[a] = (s[k] - s[other] - w) / abs(float(targets[a]))
    return out if signed else np.abs(out)


class BalanceWindow:
    """The fixed walls' imbalance over the last :data:`BALANCE_RECORDS` records: ``add`` one
    record's signed imbalance (:func:`imbalance` with signed=True, per axis, -) and get the
    largest |mean| over :data:`BALANCE_TOL` (<= 1: balanced; inf until the window is full)."""

    def __init__(self, records: int = BALANCE_RECORDS, tol: float = BALANCE_TOL):
        self.records, self.tol = int(records), float(tol)
        self._rows: list = []

    def add(self, signed_imbalance) -> float:
        self._rows.append(np.asarray(signed_imbalance, float))
        del self._rows[:-self.records]
        if len(self._rows) < self.records:
            return float("inf")
        return float(np.max(np.abs(np.mean(self._rows, axis=0)))) / self.tol


def weight(scene, gravity: float, density: float) -> float:
    """The weight of the grains and the grid, N: the solid volume (m^3) times ``density``
    (kg/m^3) times ``gravity`` (m/s^2)."""
    if gravity <= 0:
        return 0.0
    return measure.solid_volume(scene) * density * gravity


def weight_stress(scene, walls, gravity: float, density: float) -> float:
    """:func:`weight` per the box's x-y (bottom) area, Pa."""
    size = measure.box_size(scene, walls)
    return weight(scene, gravity, density) / float(size[0] * size[1])
