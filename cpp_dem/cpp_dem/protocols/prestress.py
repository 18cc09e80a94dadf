"""Prestress of geogrid members (002's PRS): tension chosen members to T_p, then lock it in.

:class:`Prestress` grips a geogrid at both ends along the members' direction. It holds one
end, and pulls the other line by line until each line's members carry the target tension.
Then it locks the grips (ends held) and reports the locked-in force as the run goes.

- **Which grids.** It works for the woven grids of bonded spheres (cpp_dem.build.woven) and for the
  cylinder and PFacet grids (cpp_dem.build.geogrid). They share the member labels and
  ``member_axial_forces``.
- **Line.** A line is the row (longitudinal members) or column (transverse members) of
  members between the grips. Its force is the mean of its members' mid-section forces.
- **Target.** Per member, N (``tension_n``), or per metre of width (``tension_per_m``, N/m,
  times the lines' spacing).
- **Grips.**
  - They are the grid's bodies within ``grip_width`` of the grid's two ends along the
    members' direction: by default the end junctions.
  - Each end body belongs to the line nearest to it.
  - All their DOFs are held; the pulled ones move at the servo's velocity.
- **Servo.**
  - Every ``period`` steps each line's grip moves at v = gain (T_p - T) / (k period dt).
  - k is the line's measured secant stiffness.
  - v is capped at ``max_speed``. The default is 1e-4 of the smallest radius per step.
- **Uniform.** :meth:`Prestress.tension_uniform` holds and stretches the whole grid at once
  instead (one strain along the members, servoed on the lines' mean force): a sheet
  tensioned before the fill, whose members all carry the target, where grips pulling the
  ends of a grid already in a fill tension the end members more than the inner ones.
- **Lock.** The grips lock when every line has been within ``tolerance`` of the target for
  ``settle_checks`` checks in a row. A target not reached within the steps allowed raises
  :class:`PrestressError`, naming the lines and their forces. :meth:`Prestress.unlock` lets
  the grips go again.
- **End forces.** :class:`EndTension` pulls the same ends by given forces instead of moving
  them: T per metre of width (N/m) times the lines' spacing at each end of every line. The
  two-way coupling hands an FEM layer's tension to a DEM element this way.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from cpp_dem._core import ParameterError
from cpp_dem.build.geogrid import LONGITUDINAL, TRANSVERSE


class PrestressError(RuntimeError):
    """The prestress could not be reached (or was lost): the message names the lines."""


def _grid_bodies(grid) -> np.ndarray:
    return np.asarray(grid.spheres if hasattr(grid, "spheres") else grid.nodes, dtype=int)


def _member_bodies(scene, grid, m: int) -> np.ndarray:
    if hasattr(grid, "member_bonds"):
        return np.unique(np.asarray(scene.bond_spheres)[grid.member_bonds[m]])
    return np.unique(np.asarray(scene.grid_link_nodes)[grid.member_links[m]])


class GridEnds:
    """The two ends of ``grid`` along its members of ``direction``, line by line: the grips
    of :class:`Prestress` and the loaded ends of :class:`EndTension` (module docstring:
    "Line", "Grips").

    Attributes: axis (0 for x, 1 for y), members (the members of ``direction``), lines (their
    line labels), line_members, line_coord (each line's cross coordinate, m), spacing (the
    lines' median spacing, m; NaN for one line), low and high (the bodies of the two ends)
    and low_line, high_line (each end body's line: an index into ``lines``).
    """

    def __init__(self, scene, grid, direction: str = LONGITUDINAL,
                 grip_width: float | None = None):
        if direction not in (LONGITUDINAL, TRANSVERSE):
            raise ParameterError(f"direction={direction!r}: must be '{LONGITUDINAL}' or "
                                 f"'{TRANSVERSE}'")
        self.axis = 0 if direction == LONGITUDINAL else 1
        cross = 1 - self.axis
        self.members = np.flatnonzero(np.asarray(grid.member_direction) == direction)
        if len(self.members) == 0:
            raise ParameterError(f"direction={direction!r}: the grid has no such members")
        line_of = np.asarray(grid.member_cell)[self.members, 1 if self.axis == 0 else 0]
        self.lines = np.unique(line_of)
        self.line_members = [self.members[line_of == ln] for ln in self.lines]
        pos = np.asarray(scene.positions)
        self.line_coord = np.array([
            np.mean(pos[np.concatenate([_member_bodies(scene, grid, m) for m in ms]), cross])
            for ms in self.line_members])
        self.spacing = (float(np.median(np.diff(np.sort(self.line_coord))))
                        if len(self.lines) > 1 else math.nan)
        bodies = _grid_bodies(grid)
        x = pos[bodies, self.axis]
        lo, hi = x.min(), x.max()
        if grip_width is None:
            # The end junctions: a woven grid's patch of crossings (its member width less a
            # sphere diameter), a node grid's end nodes; a woven grid with tails along this
            # axis is held at their tips.
            if getattr(grid, "tails", (0, 0))[self.axis] > 0:
                grip_width = 1e-6 * (hi - lo)
            elif hasattr(grid, "member_width"):
                r_grid = float(np.asarray(scene.radii)[bodies[0]])
                grip_width = grid.member_width - 2 * r_grid + 1e-9 * (hi - lo)
            else:
                grip_width = 1e-6 * (hi - lo)
        if not (math.isfinite(grip_width) and 0 <= grip_width < 0.5 * (hi - lo)):
            raise ParameterError(f"grip_width={grip_width}: must be in [0, half the grid's "
                                 f"extent {0.5 * (hi - lo):g} m)")
        self.low = bodies[x <= lo + grip_width + 1e-12]
        self.high = bodies[x >= hi - grip_width - 1e-12]

        def line_of_body(b: np.ndarray) -> np.ndarray:
            return np.argmin(np.abs(pos[b, cross][:, None] - self.line_coord[None, :]), axis=1)

        self.low_line, self.high_line = line_of_body(self.low), line_of_body(self.high)


class Prestress:
    """Tensions the members of ``direction`` of ``grid`` in ``scene`` (module docstring).

    tension_n : target tension per member, N; or tension_per_m : N per metre of width.
    grip_width : m; default: the end junctions (a woven grid's patch of crossings, a node
        grid's end nodes).
    tolerance : relative, -. period : steps between servo updates. gain : -, in (0, 1].
    max_speed : m/s.
    """

    def __init__(self, scene, grid, *, tension_n: float | None = None,
                 tension_per_m: float | None = None, direction: str = LONGITUDINAL,
                 grip_width: float | None = None, tolerance: float = 0.01, period: int = 50,
                 gain: float = 0.5, settle_checks: int = 5, max_speed: float | None = None):
        if (tension_n is None) == (tension_per_m is None):
            raise ParameterError("give one of tension_n (N per member) or tension_per_m (N/m)")
        for name, v in (("tolerance", tolerance), ("gain", gain)):
            if not (math.isfinite(v) and 0 < v <= 1):
                raise ParameterError(f"{name}={v}: must be in (0, 1]")
        if not (isinstance(period, int) and period >= 1):
            raise ParameterError(f"period={period!r}: must be an integer >= 1 (steps)")
        self.scene, self.grid, self.direction = scene, grid, direction
        self.tolerance, self.period, self.gain = tolerance, period, gain
        self.settle_checks = settle_checks
        ends = GridEnds(scene, grid, direction, grip_width)
        self.axis, self.members, self.lines = ends.axis, ends.members, ends.lines
        self.line_members, self.line_coord = ends.line_members, ends.line_coord
        if tension_n is None:
            if len(self.lines) < 2:
                raise ParameterError("tension_per_m needs at least two member lines (their "
                                     "spacing is the width per member); give tension_n")
            tension_n = float(tension_per_m) * ends.spacing
        if not (math.isfinite(tension_n) and tension_n > 0):
            raise ParameterError(f"tension={tension_n}: must be > 0 (N per member)")
        self.target_n = float(tension_n)
        self.held, self.pulled, self.pulled_line = ends.low, ends.high, ends.high_line
        scene.block_dofs(np.concatenate([self.held, self.pulled]), "all")
        bodies = _grid_bodies(grid)
        pos = np.asarray(scene.positions)
        r = float(np.min(np.asarray(scene.radii)[bodies]))
        self.max_speed = max_speed if max_speed is not None else 1e-4 * r / scene.dt
        self.start = pos[self.pulled, self.axis].copy()
        self.stiffness = np.full(len(self.lines), np.nan)  # N/m per line (secant)
        self.locked = False
        self._all = None  # every grid body, once tension_uniform holds them all
        self.history: list[dict] = []

    # ---- measuring ------------------------------------------------------------------------
    def line_forces(self) -> np.ndarray:
        """Mean tensile force of each line's members, N."""
        f = self.grid.member_axial_forces(self.scene)
        return np.array([f[ms].mean() for ms in self.line_members])

    def member_forces(self) -> np.ndarray:
        """Tensile force of every prestressed member (self.members), N."""
        return self.grid.member_axial_forces(self.scene)[self.members]

    def record(self) -> dict:
        """Appends and returns the state now: step, time (s), locked, line forces (N), and
        their largest deviation from the target (relative)."""
        f = self.line_forces()
        row = dict(step=self.scene.step_count, time=self.scene.time, locked=self.locked,
                   line_forces_n=f, deviation=float(np.max(np.abs(f / self.target_n - 1))))
        self.history.append(row)
        return row

    # ---- driving --------------------------------------------------------------------------
    def _set_speeds(self, speeds: np.ndarray) -> None:
        v = np.asarray(self.scene.velocities).copy()
        v[self.pulled] = 0.0
        v[self.pulled, self.axis] = speeds[self.pulled_line]
        v[self.held] = 0.0
        self.scene.velocities = v

    def _update(self) -> bool:
        f = self.line_forces()
        disp = np.array([np.mean(np.asarray(self.scene.positions)[self.pulled[self.pulled_line == k],
                                                                 self.axis]
                                 - self.start[self.pulled_line == k]) for k in range(len(self.lines))])
        ok = np.abs(f - self.target_n) <= self.tolerance * self.target_n
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where((disp > 0) & (f > 0.05 * self.target_n), f / disp, np.nan)
        self.stiffness = np.where(np.isfinite(k), k, self.stiffness)
        dt = self.scene.dt
        speed = np.where(np.isfinite(self.stiffness),
                         self.gain * (self.target_n - f) / (self.stiffness * self.period * dt),
                         self.max_speed)
        self._set_speeds(np.clip(speed, -self.max_speed, self.max_speed))
        return bool(np.all(ok))

    def tension(self, max_steps: int, *, progress: bool = False) -> dict:
        """Runs the scene until every line holds the target within the tolerance, then locks
        the grips; returns the record at locking. Raises PrestressError after ``max_steps``."""
        if self.locked:
            raise PrestressError("the prestress is locked already")
        good, done, t0 = 0, 0, time.perf_counter()
        while done < max_steps:
            good = good + 1 if self._update() else 0
            if good >= self.settle_checks:
                self._set_speeds(np.zeros(len(self.lines)))
                self.locked = True
                return self.record()
            self.scene.run(self.period)
            done += self.period
            if progress and (done // self.period) % 20 == 0:
                row = self.record()
                eta = (time.perf_counter() - t0) / done * (max_steps - done)
                print(f"[prestress] step {done}/{max_steps}: line forces "
                      f"{np.round(row['line_forces_n'], 3).tolist()} N (target "
                      f"{self.target_n:g} N), at most {eta:.0f} s left", file=sys.stderr,
                      flush=True)
        f = self.line_forces()
        self._set_speeds(np.zeros(len(self.lines)))
        bad = [f"line {int(ln)}: {fv:.4g} N" for ln, fv in zip(self.lines, f)
               if abs(fv - self.target_n) > self.tolerance * self.target_n]
        raise PrestressError(
            f"prestress not reached in {max_steps} steps (target {self.target_n:.4g} N per "
            f"member, tolerance {self.tolerance:g}): {', '.join(bad) or 'not settled'}; "
            f"the grips stop where they are (max_speed={self.max_speed:.3g} m/s)")

    def tension_uniform(self, max_steps: int) -> dict:
        """Tensions the whole grid at once, as a sheet tensioned before the fill: every grid
        body is held (all DOFs) and moved with one uniform stretch along the members'
        direction about the grid's centre, v = rate x (x - centre), the rate servoed on the
        lines' mean force as :meth:`tension` servoes the grips, until the lines are within
        the tolerance in their mean for ``settle_checks`` checks (one strain sets the mean;
        each line's force is in the record); then the grid is locked where it is, all
        of it held (:meth:`unlock` lets all of it go). Returns the record at locking; raises
        PrestressError after ``max_steps``.

        Against :meth:`tension` (the ends pulled in an existing fill): grains interlocked in
        the apertures anchor the members next to the grips, so the grips' pull reaches the
        inner members only in part (the lines' mean is on target, the end members above it,
        the inner ones below); released, the difference loads the soil between the end
        ribs and the walls. A uniform stretch gives every member the same strain, T_p / J:
        the fill is around a grid that is tensioned all along (002's concept), and each
        grid body moves by at most that strain times half the grid's length."""
        if self.locked:
            raise PrestressError("the prestress is locked already")
        sc, ax = self.scene, self.axis
        bodies = _grid_bodies(self.grid)
        sc.block_dofs(bodies, "all")
        self._all = bodies
        x0 = np.asarray(sc.positions)[bodies, ax].copy()
        centre = 0.5 * (x0.min() + x0.max())
        half = 0.5 * (x0.max() - x0.min())
        max_rate = self.max_speed / half  # 1/s: the ends at the grips' max_speed
        stiffness = math.nan  # N per unit strain (secant), the lines' mean

        def set_rate(rate: float) -> None:
            v = np.asarray(sc.velocities).copy()
            v[bodies] = 0.0
            v[bodies, ax] = rate * (np.asarray(sc.positions)[bodies, ax] - centre)
            sc.velocities = v

        good, done = 0, 0
        while done < max_steps:
            # (one strain for all lines: their mean is what it sets; their spread is the
            # lines' own, recorded in the row)
            fm = float(np.mean(self.line_forces()))
            ok = abs(fm - self.target_n) <= self.tolerance * self.target_n
            good = good + 1 if ok else 0
            if good >= self.settle_checks:
                set_rate(0.0)
                self.locked = True
                return self.record()
            strain = float(np.mean((np.asarray(sc.positions)[bodies, ax] - centre)
                                   * (x0 - centre)) / np.mean((x0 - centre) ** 2)) - 1.0
            if strain > 0 and fm > 0.05 * self.target_n:
                stiffness = fm / strain
            rate = (self.gain * (self.target_n - fm) / (stiffness * self.period * sc.dt)
                    if math.isfinite(stiffness) else max_rate)
            set_rate(float(np.clip(rate, -max_rate, max_rate)))
            sc.run(self.period)
            done += self.period
        set_rate(0.0)
        f = self.line_forces()
        raise PrestressError(
            f"prestress not reached by a uniform stretch in {max_steps} steps (target "
            f"{self.target_n:.4g} N per member, tolerance {self.tolerance:g}): line forces "
            f"{np.round(f, 4).tolist()} N; the grid stops where it is")

    def check_locked(self, tolerance: float | None = None) -> dict:
        """Records the locked-in force now; raises PrestressError if a line has left the
        target by more than ``tolerance`` (default: the tensioning tolerance)."""
        row = self.record()
        tol = self.tolerance if tolerance is None else tolerance
        if row["deviation"] > tol:
            raise PrestressError(
                f"the locked-in prestress drifted: line forces "
                f"{np.round(row['line_forces_n'], 4).tolist()} N against {self.target_n:.4g} N "
                f"(largest deviation {row['deviation']:.3g} > {tol:g})")
        return row

    def unlock(self) -> None:
        """The grips let go: their bodies move freely again. The locked-in force then rests on
        whatever else holds the ends (an :class:`EndTension`, or nothing)."""
        self.scene.block_dofs(np.concatenate([self.held, self.pulled]) if self._all is None
                              else self._all, "")
        self.locked = False


class EndTension:
    """Force-controlled grid ends: every line of members of ``direction`` is pulled at its two
    ends by equal and opposite forces T x spacing (T per metre of width, N/m; the spacing of
    the lines, as for :class:`Prestress`'s ``tension_per_m``), shared equally among the
    line's end bodies (:class:`GridEnds`). With the ends free otherwise, the members then
    carry T x spacing where no grains take it up. This is how an FEM layer's tension across
    the faces of a DEM element is handed over (``cpp_dem.elements.box``, issue 18).

    The forces are the end bodies' external forces (``scene.external_forces``), which this
    object owns: :meth:`set` replaces them, other bodies' are left alone.
    """

    def __init__(self, scene, grid, *, direction: str = LONGITUDINAL,
                 grip_width: float | None = None):
        self.scene, self.grid = scene, grid
        self.ends = GridEnds(scene, grid, direction, grip_width)
        if len(self.ends.lines) < 2:
            raise ParameterError("EndTension needs at least two member lines (their spacing "
                                 "is the width each line carries)")
        self.tension_per_m = 0.0

    @property
    def line_force_n(self) -> float:
        """The force applied at each end of every line, N (tension_per_m x spacing)."""
        return self.tension_per_m * self.ends.spacing

    def set(self, tension_per_m: float) -> None:
        """Pulls the ends with ``tension_per_m`` (N/m, tension positive; 0 leaves them
        free)."""
        t = float(tension_per_m)
        if not math.isfinite(t):
            raise ParameterError(f"tension_per_m={tension_per_m!r}: must be finite (N/m)")
        e = self.ends
        ext = np.asarray(self.scene.external_forces).copy()
        for bodies, line, sign in ((e.low, e.low_line, -1.0), (e.high, e.high_line, 1.0)):
            share = np.bincount(line, minlength=len(e.lines))[line]
            ext[bodies] = 0.0
            ext[bodies, e.axis] = sign * t * e.spacing / share
        self.scene.external_forces = ext
        self.tension_per_m = t

    def line_forces(self) -> np.ndarray:
        """Mean tensile force of each line's members, N."""
        f = self.grid.member_axial_forces(self.scene)
        return np.array([f[ms].mean() for ms in self.ends.line_members])

    def end_member_forces(self) -> np.ndarray:
        """Tensile force of the members that hold an end body, N: where the pull enters the
        grid (the applied line force, less what grains take up within half a member). Where
        no member holds an end body (a woven grid pulled at its tails' tips, a grid whose end
        nodes are in no member), the members of its first and last cells along the pull."""
        e = self.ends
        end = np.concatenate([e.low, e.high])
        m = [k for k in e.members
             if np.isin(_member_bodies(self.scene, self.grid, k), end).any()]
        if not m:
            along = np.asarray(self.grid.member_cell)[e.members, e.axis]
            m = e.members[(along == along.min()) | (along == along.max())]
        return self.grid.member_axial_forces(self.scene)[m]
