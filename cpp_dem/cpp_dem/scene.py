"""The Python face of a DEM scene: typed helpers around the compiled `_core.Scene`."""

from __future__ import annotations

import math
import sys
import time as _time
from typing import Callable, Iterable, Sequence

import numpy as np

from . import _core
from ._core import Material, ParameterError

_DOF_BITS = {"x": 1, "y": 2, "z": 4, "rx": 8, "ry": 16, "rz": 32}

#: Wall order of :meth:`Scene.add_box`.
BOX_WALLS = ("x-", "x+", "y-", "y+", "z-", "z+")


def linear_material(*, density: float, young: float, poisson: float,
                    friction_angle_deg: float, **parts: float) -> Material:
    """Material for the linear Cundall–Strack law (000 eqs 1–6). SI units (kg/m^3, Pa, deg).

    ``parts`` are the optional law parts: damping_normal, damping_shear (ratios of critical),
    rolling_stiffness, rolling_friction.
    """
    return Material(model="linear", density=density, young=young, poisson=poisson,
                    friction_angle_deg=friction_angle_deg, **parts)


def hertz_mindlin_material(*, density: float, shear_modulus: float, poisson: float,
                           friction_coefficient: float, **parts: float) -> Material:
    """Hertz–Mindlin material from the parameters PFC uses (002 Table 1).

    shear_modulus: G, Pa; poisson: nu, -; friction_coefficient: mu = tan(phi), -;
    density: kg/m^3. Young's modulus is E = 2 G (1 + nu).
    """
    if not (friction_coefficient >= 0 and math.isfinite(friction_coefficient)):
        raise ParameterError(f"friction_coefficient={friction_coefficient}: must be >= 0")
    if not (shear_modulus > 0 and math.isfinite(shear_modulus)):
        raise ParameterError(f"shear_modulus={shear_modulus}: must be > 0 (Pa)")
    return Material(model="hertz_mindlin", density=density,
                    young=2.0 * shear_modulus * (1.0 + poisson), poisson=poisson,
                    friction_angle_deg=math.degrees(math.atan(friction_coefficient)), **parts)


class Scene(_core.Scene):
    """A DEM scene: spheres, walls, materials, contacts and the step loop (in C++).

    Parameters
    ----------
    gravity : gravitational acceleration, m/s^2 (3 values).
    dt : time step, s (or use :meth:`set_auto_timestep`).
    local_damping : Cundall local damping coefficient, -.
    """

    def __init__(self, *, gravity: Sequence[float] = (0.0, 0.0, 0.0), dt: float | None = None,
                 local_damping: float = 0.0) -> None:
        super().__init__()
        self.gravity = np.asarray(gravity, dtype=float)
        if dt is not None:
            self.dt = dt
        self.local_damping = local_damping

    # ---- building ------------------------------------------------------------------------
    def add_spheres(self, centers, radii, *, material: int) -> np.ndarray:
        """Adds spheres with centres (n, 3) in m and radii (n,) in m; returns their ids."""
        c = np.atleast_2d(np.asarray(centers, dtype=float))
        r = np.atleast_1d(np.asarray(radii, dtype=float))
        first = self._add_spheres(c, r, material)
        return np.arange(first, first + len(r))

    def add_box(self, lo: Sequence[float], hi: Sequence[float], *, material: int) -> list[int]:
        """Adds the six walls of the box [lo, hi] (m), facing inwards.

        Returns the wall ids in the order x-, x+, y-, y+, z-, z+ (see ``BOX_WALLS``).
        """
        lo_a = np.asarray(lo, dtype=float)
        hi_a = np.asarray(hi, dtype=float)
        if lo_a.shape != (3,) or hi_a.shape != (3,):
            raise ParameterError("lo, hi: expected 3 values each (m)")
        for a in range(3):
            if not hi_a[a] > lo_a[a]:
                raise ParameterError(f"hi[{a}]={hi_a[a]}: must be > lo[{a}]={lo_a[a]} (m)")
        ids = []
        for a in range(3):
            ids.append(self.add_wall(axis=a, position=float(lo_a[a]), sense=+1, material=material))
            ids.append(self.add_wall(axis=a, position=float(hi_a[a]), sense=-1, material=material))
        return ids

    def block_dofs(self, bodies: Iterable[int] | int, dofs: str) -> None:
        """Blocks DOFs of bodies: ``dofs`` is a space-separated subset of 'x y z rx ry rz'
        (or 'xyz', 'all', '' to free). A blocked DOF keeps its (possibly imposed) velocity."""
        mask = 0
        words = dofs.replace(",", " ").split()
        for w in words:
            if w == "all":
                mask |= 63
            elif w == "xyz":
                mask |= 7
            elif w == "rot":
                mask |= 56
            elif w in _DOF_BITS:
                mask |= _DOF_BITS[w]
            else:
                raise ParameterError(f"dofs='{dofs}': unknown DOF '{w}'; allowed: x y z rx ry rz "
                                     "xyz rot all")
        for b in np.atleast_1d(np.asarray(bodies, dtype=int)):
            self._set_blocked(int(b), mask)

    def blocked_dofs(self, body: int) -> str:
        """The blocked DOFs of a body as a string like 'x y rz'."""
        mask = self._blocked[body]
        return " ".join(k for k, bit in _DOF_BITS.items() if mask & bit)

    # ---- running ---------------------------------------------------------------------------
    def run(self, steps: int, *, every: int = 0, callback: Callable[["Scene"], None] | None = None,
            progress: bool = False, label: str = "run") -> None:
        """Runs ``steps`` steps in C++.

        If ``every`` > 0, the loop returns to Python every ``every`` steps to call
        ``callback(scene)`` (never per contact) and, with ``progress``, to print a line.
        """
        steps = int(steps)
        if steps < 0:
            raise ParameterError(f"steps={steps}: must be >= 0")
        if every <= 0:
            self._run(steps)
            return
        t0 = _time.perf_counter()
        done = 0
        while done < steps:
            n = min(every, steps - done)
            self._run(n)
            done += n
            if callback is not None:
                callback(self)
            if progress:
                el = _time.perf_counter() - t0
                print(f"[{label}] step {done}/{steps}  t={self.time:.4g} s  dt={self.dt:.3g} s  "
                      f"contacts={self.num_active_contacts}  "
                      f"unbalanced={self.unbalanced_force():.3g}  wall {el:.1f} s",
                      file=sys.stdout, flush=True)
