"""What a load step of :class:`femcoupling.fem.soil_model.SoilModel` ends in: its record
(:class:`StepResult`) or :class:`NewtonDivergence`."""

from __future__ import annotations

import dataclasses


class NewtonDivergence(RuntimeError):
    """Newton did not converge even after the step was cut ``max_cuts`` times."""


@dataclasses.dataclass(frozen=True)
class StepResult:
    """One accepted load step.

    Attributes:
        stage: 'geostatic', 'prestress' or 'footing'.
        load_factor: fraction of the stage's load applied, -.
        footing_settlement_m: mean downward displacement of the footing, m (positive down).
        footing_pressure_pa: mean footing pressure, Pa, **compression positive** (the reaction
            in displacement control; the applied pressure in load control).
        newton_iterations: iterations this step took.
        plastic_points: number of plastic quadrature points (global).
        converged_on: "tolerance" (``newton_rtol``), or "noise": with DEM region elements,
            Newton stalled above the tolerance within the elements' measured noise
            (``femcoupling.fem.quadrature.newton_solve``; said in ``SoilModel.warnings``).
        noise_residual: that noise, relative to the whole body's force scale (NaN where it
            was not measured).
        status: "converged" (``newton_rtol`` met) or "stopped_at_scatter" (within
            ``SoilModel.noise_factor`` times the noise and ``SoilModel.noise_ceiling`` of the
            DEM regions' own internal force, above the tolerance)
            (:mod:`femcoupling.coupling.status`).
        residual: the accepted residual relative to the force scale it is judged against:
            the DEM regions' own internal force where the model has region elements, else
            the body's, -.
        tol: ``newton_rtol`` on that same scale, -; ``status`` is "converged" when
            ``residual <= tol``.
        residual_pa: the accepted residual in stress units, Pa: ``residual`` times the
            largest stress magnitude of the points of that scale (the regions' with region
            elements, else the body's).
        redraws: the iterates Newton took after it had stalled within the elements' noise
            but above ``SoilModel.noise_ceiling``, before one was within both
            (``femcoupling.fem.quadrature.REDRAWS``); 0 where none was needed.
        noise: the elements' noise measured at the step's stall, on the scale of
            ``residual`` (NaN where Newton did not stall); a step above ``tol`` is accepted
            within ``SoilModel.noise_factor`` times it.
        ceiling: the largest residual a step may be accepted at within the noise, on the
            scale of ``residual`` (``SoilModel.noise_ceiling``; inf without DEM region
            elements).
    """

    stage: str
    load_factor: float
    footing_settlement_m: float
    footing_pressure_pa: float
    newton_iterations: int
    plastic_points: int
    converged_on: str = "tolerance"
    noise_residual: float = float("nan")
    status: str = "converged"
    residual: float = float("nan")
    tol: float = float("nan")
    residual_pa: float = float("nan")
    redraws: int = 0
    noise: float = float("nan")
    ceiling: float = float("nan")
