"""Density scaling for quasi-static stages: a larger time step bought with heavier bodies.

In a quasi-static test the grains' inertia only has to be small against the confining forces;
its value does not enter the answer. Density (mass) scaling uses this: each body's inertia
is raised until its own critical step reaches a target dt, so the whole sample runs at that
dt instead of at the step of its stiffest, lightest grain. PFC calls this timestep scaling
and Yade ``densityScaling`` with its ``GlobalStiffnessTimeStepper``; this is our own form of
the same idea, in the core (``Scene.set_density_scaling``):

- every ``period`` steps each free body and each clump takes the factor
  s = max(1, (target_dt / (safety x d_b))^2), d_b its critical step from the stiffness of its
  active contacts, bonds and links (sqrt(2 m / K) per axis, translation and rotation);
- the factor multiplies the mass and the moments of inertia (a clump's: the clump's), not the
  weight: gravity and any imposed force stay the true ones, so a settled column still presses
  its true weight on the floor, and a body with no contact (s = 1) falls at g;
- while it is on, critical_dt() and the dt check use the scaled inertia, without the stiffness
  floor of a grain with no contact: the factors follow each body's own contacts instead.

What it costs: the sample's inertia is larger, so at a given loading rate its inertial number
is sqrt(s) larger. :func:`report` gives that number from the contacts (see
``Scene.density_scaling_stats``); :func:`check` warns (``InertialNumberWarning``) when it
leaves the quasi-static range, I <= ``QUASI_STATIC_LIMIT`` (1e-2; the range and its errors are
in cpp_dem.measure.inertial and docs/speed_accuracy.md). A dynamic problem (an impact, a
pull-out at speed, a free fall onto the sample) is not quasi-static: there the scaled inertia
changes the answer, and the check says so. The measured trade (error of the stress path
against the speed-up) is in docs/quasi_static.md (``bench/quasi_static.py``).
"""

from __future__ import annotations

import math
import warnings

from cpp_dem._core import ParameterError
from cpp_dem.measure.inertial import QUASI_STATIC_LIMIT, InertialNumberWarning

#: Default safety of the scaled step: each body's scaled critical step is target_dt / safety.
SAFETY = 0.5
#: Default steps between updates of the inertia factors: every step, so that a contact that
#: forms at full stiffness (the linear law) is covered in the step it forms. A scene whose new
#: contacts form soft (Hertz–Mindlin) or stiff only against heavy bodies may update less often
#: (the 002 element: every 10 steps; an update costs a fifth to a half of a step there).
PERIOD = 1


def reference_dt(scene) -> float:
    """The step the unscaled scene takes once its grains touch, s: the automatic time step's
    safety (``scene.timestep_safety``) times the critical estimate with every grain's
    stiffness floor (``critical_dt_body(contact_seen=True)``). Needs scaling off."""
    if scene.density_scaling:
        raise ParameterError("reference_dt: density scaling is on; the reference step is that "
                             "of the unscaled scene (call disable first)")
    return scene.timestep_safety * scene.critical_dt_body(contact_seen=True)[0]


def enable(scene, speedup: float, *, safety: float = SAFETY, period: int = PERIOD) -> float:
    """Turns density scaling on with target dt = ``speedup`` x :func:`reference_dt`; returns
    that target, s. ``speedup`` >= 1 (1: the unscaled step, with only the bodies whose own
    contacts need it scaled)."""
    if not (isinstance(speedup, (int, float)) and math.isfinite(speedup) and speedup >= 1):
        raise ParameterError(f"density_scaling={speedup!r}: must be a number >= 1 (the target "
                             "time step over the unscaled one, -; 0 switches scaling off)")
    target = float(speedup) * reference_dt(scene)
    scene.set_density_scaling(target_dt=target, safety=safety, period=period)
    return target


def disable(scene) -> None:
    """Turns density scaling off; dt goes back to the automatic time step's choice."""
    if not scene.density_scaling:
        return
    scene.clear_density_scaling()
    scene.dt = reference_dt(scene)


def report(scene) -> dict:
    """What scaling does now: ``dt_s``, ``target_dt_s`` (0 when off), and the core's
    ``density_scaling_stats`` (max_factor, mean_factor, scaled_share, scaled, movable,
    inertial_number)."""
    st = dict(scene.density_scaling_stats())
    st["dt_s"] = scene.dt
    st["target_dt_s"] = scene.density_scaling_target_dt if scene.density_scaling else 0.0
    return st


def describe(st: dict) -> str:
    """One line for progress output from :func:`report`'s dict."""
    if not st["target_dt_s"]:
        return f"dt {st['dt_s']:.3g} s, no density scaling; I {st['inertial_number']:.2g}"
    return (f"dt {st['dt_s']:.3g} s (density scaling: largest factor "
            f"{st['max_factor']:.3g}, {100 * st['scaled_share']:.0f} % of bodies scaled); "
            f"I {st['inertial_number']:.2g}")


def effective_density(scene, density: float) -> float:
    """The density a loading's inertial number takes, kg/m^3: ``density`` times the
    mass-weighted mean inertia factor with scaling on (the scaled grains are that much
    heavier to the loading), ``density`` itself with it off."""
    if not scene.density_scaling:
        return density
    return density * scene.density_scaling_stats()["mean_factor"]


def check(scene, stage: str, *, limit: float = QUASI_STATIC_LIMIT, stacklevel: int = 2) -> bool:
    """Warns (InertialNumberWarning) when ``stage`` runs with density scaling at a sample
    inertial number (``report``) above ``limit``; returns True when it warned. Without
    scaling it does nothing (the cases check their own loading rates)."""
    if not scene.density_scaling:
        return False
    st = report(scene)
    i = st["inertial_number"]
    if not i > limit:
        return False
    warnings.warn(InertialNumberWarning(
        f"{stage}: with density scaling (largest inertia factor {st['max_factor']:.3g}, "
        f"{100 * st['scaled_share']:.0f} % of bodies scaled) the sample's inertial number is "
        f"I = {i:.3g}, above {limit:g}: the scaled inertia is not small against the "
        "confinement here, so it changes the answer (an impact or a fast loading is not "
        "quasi-static); lower the density scaling or the loading rate"), stacklevel=stacklevel + 1)
    return True


__all__ = ["SAFETY", "PERIOD", "reference_dt", "enable", "disable", "report", "describe", "effective_density",
           "check"]
