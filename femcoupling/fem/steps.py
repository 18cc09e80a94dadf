"""What a load step of every FEM model of this package ends in: its record
(:class:`LoadStep`, the same Newton fields in every model) or :class:`NewtonFailure` (the one
failure type).

- :class:`NewtonFailure`: Newton did not converge. Inside a model a failed step is cut
  (halved) and taken again; raised out of a model's stage (``SoilModel``'s loading) or step
  (the hierarchical models' ``step``), it means the step failed even cut ``max_cuts`` times,
  and its message says where the load stopped and why the last Newton failed.
- :class:`LoadStep`: one accepted load step: what Newton did (``newton_iterations``,
  ``residual``, ``status``, ...). Each model's record adds what it loads and measures:
  :class:`StepResult` (``femcoupling.fem.soil_model.SoilModel``: the stage, its load factor,
  the footing's settlement and pressure) and ``femcoupling.coupling.hierarchical.HierStep``
  (the hierarchical models: the top displacement, the elements' stresses and timings).

SI units; a field's unit is in its name or its doc.
"""

from __future__ import annotations

import dataclasses


class NewtonFailure(RuntimeError):
    """A load step could not be accepted: Newton did not converge (a model then cuts the
    step), or, raised out of a model's stage or step, it did not converge even with the step
    cut ``max_cuts`` times (the message says the load reached and the last failure)."""


@dataclasses.dataclass(frozen=True, kw_only=True)
class LoadStep:
    """One accepted load step: what Newton did, named the same in every model.

    Attributes:
        newton_iterations: iterations this step took.
        residual: the accepted residual relative to the force scale it is judged against
            (the model's doc says which), -.
        converged_on: "tolerance" (``newton_rtol``), or "noise": Newton stalled above the
            tolerance within the DEM elements' measured noise
            (``femcoupling.fem.quadrature.newton_solve``; said in the model's ``warnings``).
        status: "converged" (``newton_rtol`` met) or "stopped_at_scatter" (accepted within
            the elements' noise and the ceiling, above the tolerance)
            (:mod:`femcoupling.coupling.status`).
        noise_residual: the elements' noise measured at the step's stall, relative to the
            model's force scale (NaN where it was not measured).
        residual_pa: the accepted residual in stress units, Pa.
        redraws: the iterates Newton took after it had stalled within the elements' noise
            but above the ceiling, before one was within both
            (``femcoupling.fem.quadrature.REDRAWS``); 0 where none was needed.
        relaxation: the relaxation factor of each Newton correction (1: plain Newton; empty
            where the model does not relax).
    """

    newton_iterations: int
    residual: float = float("nan")
    converged_on: str = "tolerance"
    status: str = "converged"
    noise_residual: float = float("nan")
    residual_pa: float = float("nan")
    redraws: int = 0
    relaxation: tuple = ()


@dataclasses.dataclass(frozen=True, kw_only=True)
class StepResult(LoadStep):
    """One accepted load step of ``femcoupling.fem.soil_model.SoilModel`` (the Newton fields:
    :class:`LoadStep`; ``residual`` is relative to the DEM regions' own internal force where
    the model has region elements, else to the body's).

    Attributes:
        stage: 'geostatic', 'prestress' or 'footing'.
        load_factor: fraction of the stage's load applied, -.
        footing_settlement_m: mean downward displacement of the footing, m (positive down).
        footing_pressure_pa: mean footing pressure, Pa, **compression positive** (the reaction
            in displacement control; the applied pressure in load control).
        plastic_points: number of plastic quadrature points (global).
        tol: ``newton_rtol`` on the scale of ``residual``, -; ``status`` is "converged" when
            ``residual <= tol``.
        noise: the elements' noise measured at the step's stall, on the scale of
            ``residual`` (NaN where Newton did not stall); a step above ``tol`` is accepted
            within ``SoilModel.noise_factor`` times it. (``noise_residual`` is the same
            noise relative to the whole body's force scale.)
        ceiling: the largest residual a step may be accepted at within the noise, on the
            scale of ``residual`` (``SoilModel.noise_ceiling``; inf without DEM region
            elements).
    """

    stage: str
    load_factor: float
    footing_settlement_m: float
    footing_pressure_pa: float
    plastic_points: int
    tol: float = float("nan")
    noise: float = float("nan")
    ceiling: float = float("nan")
