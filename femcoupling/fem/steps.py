"""What a load step of every FEM model of this package ends in: its record
(:class:`LoadStep`, one for every body) or :class:`NewtonFailure` (the one failure type).

- :class:`NewtonFailure`: Newton did not converge. Inside a model a failed step is cut
  (halved) and taken again; raised out of a model's stage (the soil body's loading) or
  step (``FemModel.step``), it means the step failed even cut ``max_cuts`` times,
  and its message says where the load stopped and why the last Newton failed.
- :func:`load_path`: the one load-step loop of every model: a load (a stage of
  the soil body, a ``FemModel.step``) in equal increments, each Newton failure
  rolled back and the step halved, an easy step growing it back.
- :class:`LoadStep`: one accepted load step, the one record of every body: what Newton did
  (``newton_iterations``, ``residual``, ``status``, ...), what was loaded (the soil body's
  stage and load factor; a body's load) and what the body measures (the footing's
  settlement and pressure, the plastic points; the elements' stresses and timings).

SI units; a field's unit is in its name or its doc.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np

from femcoupling._checks import _max_cuts, _max_newton, _whole


class NewtonFailure(RuntimeError):
    """A load step could not be accepted: Newton did not converge (a model then cuts the
    step), or, raised out of a model's stage or step, it did not converge even with the step
    cut ``max_cuts`` times (the message says the load reached and the last failure)."""


def load_path(take: Callable[[float], "LoadStep"], rollback: Callable[[], None],
              restore: Callable[[float], None], *, steps: int, max_cuts: int,
              max_newton: int, where: str,
              accepted: Callable[[Any], None] | None = None) -> list:
    """The one load-step loop of every FEM model: a load from load factor 0 to 1 (-) in
    ``steps`` equal increments; returns the records of the accepted steps, in order.

    ``take(lf)`` sets the load at load factor ``lf``, solves, commits and returns the step's
    record (a :class:`LoadStep`), or raises :class:`NewtonFailure`. A failed step is rolled
    back (``rollback()``) and halved; an easy step (at most half of ``max_newton``
    iterations) doubles the next one back towards the nominal size. The step is never smaller
    than the nominal one over ``2**max_cuts``: a step that fails at that size, or would need
    to be cut below it, leaves the load where it was accepted last (``restore(lf)``) and
    raises :class:`NewtonFailure` naming ``where``, the load factors and the last failure.
    ``accepted(record)``, if given, is called on each accepted step after it is counted (what
    it raises, NewtonFailure included, ends the load as it is). Load factors are dyadic sums
    (exact in binary); the last is 1.0 exactly.

    ``steps`` and ``max_newton`` are whole numbers >= 1, ``max_cuts`` one in [0, 20]
    (``femcoupling._checks.MAX_CUTS_MAX``; else FemInputError). A cut step too small to move
    the load factor (below its floating-point resolution) is never taken: the load stops
    there with NewtonFailure, as past ``max_cuts``."""
    _whole("steps", steps, 1, None, "equal increments of the load")
    _max_cuts(max_cuts)
    _max_newton(max_newton)
    out: list = []
    lf_done, dlf = 0.0, 1.0 / steps
    depth = 0  # halvings of the step below its nominal size
    last = ""  # the last Newton failure
    while lf_done < 1.0 - 1e-12:
        lf = min(1.0, lf_done + dlf)
        if not lf > lf_done:  # (the cut step no longer moves the load: it would loop)
            restore(lf_done)
            raise NewtonFailure(
                f"{where}: the step cut to {dlf:.3g} of the load no longer moves the load "
                f"factor (below its floating-point resolution); the stage stopped at load "
                f"factor {lf_done!r}" + (f" (the last failure: {last})" if last else ""))
        try:
            r = take(lf)
        except NewtonFailure as e:
            rollback()
            depth += 1
            last = str(e)
            if depth > max_cuts:
                restore(lf_done)
                raise NewtonFailure(
                    f"{where}: Newton failed at load factor {lf:.6g} with the step cut "
                    f"{max_cuts} times (to 1/{2 ** max_cuts} of its nominal size); the stage "
                    f"stopped at load factor {lf_done:.6g}"
                    + (f" (the last failure: {last})" if last else "")) from None
            dlf /= 2.0
            continue
        lf_done = lf
        if r.newton_iterations <= max_newton // 2 and depth > 0:  # easy: grow back
            dlf *= 2.0
            depth -= 1
        out.append(r)
        if accepted is not None:
            accepted(r)
    return out


@dataclasses.dataclass(frozen=True, kw_only=True)
class LoadStep:
    """One accepted load step of :class:`femcoupling.fem.model.FemModel`, on every body: what
    Newton did, named the same on every body, what was loaded, and what the body measures.
    A field a body does not measure keeps its default (NaN, None, empty).

    What Newton did:
        newton_iterations: iterations this step took.
        residual: the accepted residual relative to the force scale it is judged against,
            -: on the soil body, the DEM regions' own internal force where the model has
            region elements, else the body's; on a body with elements at every point, the
            internal force scale (the largest element stress times the body's
            ``scale_length``).
        converged_on: "tolerance" (``newton_rtol``), or "noise": Newton stalled above the
            tolerance within the DEM elements' measured noise
            (``femcoupling.fem.quadrature.newton_solve``; said in the model's ``warnings``).
        status: "converged" (``newton_rtol`` met) or "stopped_at_scatter" (accepted within
            the elements' noise and the ceiling, above the tolerance)
            (:mod:`femcoupling.coupling.status`).
        noise_residual: the elements' noise measured at the step's stall, relative to the
            model's force scale (NaN where it was not measured).
        residual_pa: the accepted residual in stress units, Pa.
        noise_residual_pa: the noise's residual in Pa (bodies with elements; NaN if it was
            not measured).
        redraws: the iterates Newton took after it had stalled within the elements' noise
            but above the ceiling, before one was within both
            (``femcoupling.fem.quadrature.REDRAWS``); 0 where none was needed.
        relaxation: the relaxation factor of each Newton correction (1: plain Newton; empty
            where the model does not relax).
        tol: ``newton_rtol`` on the scale of ``residual``, - (the soil body; ``status`` is
            "converged" when ``residual <= tol``).
        noise: the elements' noise measured at the step's stall, on the scale of
            ``residual`` (the soil body; NaN where Newton did not stall); a step above
            ``tol`` is accepted within ``noise_factor`` times it.
        ceiling: the largest residual a step may be accepted at within the noise, on the
            scale of ``residual`` (the soil body: ``noise_ceiling``; inf without DEM region
            elements).

    What was loaded:
        stage: the soil body's 'geostatic', 'prestress' or 'footing'; 'step' for a
            ``FemModel.step``.
        load_factor: fraction of the stage's load (or of the step, when it was cut)
            applied, -.
        load: a body of ``femcoupling.fem.bodies``: its load, total since the start (the top
            displacement, m; a homogeneous box's G_zz, -).

    What the body measures:
        footing_settlement_m: the footing's mean downward displacement, m (positive down).
        footing_pressure_pa: the footing's mean pressure, Pa, **compression positive** (the
            reaction in displacement control; the soil body's applied pressure in load
            control).
        plastic_points: the soil body's plastic quadrature points (global).
        mean_stress: the elements' mean Voigt stress (xx, yy, xy; 3D: xx, yy, zz, yz, xz,
            xy), tension positive, Pa.
        element_stresses: (n_points, ncomp) the element stresses, Pa.
        element_scatter: (n_points, ncomp) each element's stress scatter, Pa: the bootstrap
            of its contact network (``DemElement.stress_scatter``), how far a sample of its
            size is from the material's mean.
        increments: (n_points, 3, 3) each element's increment of the step, -.
        dem_s: the DEM seconds (sum over the elements' work), s.
        fem_s: the FEM seconds (the step's wall time outside the pool's calls), s.
        wall_s: the step's wall time, s.
        recovered: the elements rebuilt after a lost worker.
    """

    newton_iterations: int
    residual: float = float("nan")
    converged_on: str = "tolerance"
    status: str = "converged"
    noise_residual: float = float("nan")
    residual_pa: float = float("nan")
    noise_residual_pa: float = float("nan")
    redraws: int = 0
    relaxation: tuple = ()
    tol: float = float("nan")
    noise: float = float("nan")
    ceiling: float = float("nan")
    stage: str = "step"
    load_factor: float = 1.0
    load: float = float("nan")
    footing_settlement_m: float = float("nan")
    footing_pressure_pa: float = float("nan")
    plastic_points: int = 0
    mean_stress: np.ndarray | None = None
    element_stresses: np.ndarray | None = None
    element_scatter: np.ndarray | None = None
    increments: np.ndarray | None = None
    dem_s: float = float("nan")
    fem_s: float = float("nan")
    wall_s: float = float("nan")
    recovered: list = dataclasses.field(default_factory=list)
