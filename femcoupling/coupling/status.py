"""How a coupled loop ended: one status from a fixed set, and what it rests on (issue 37).

Every coupled loop of this package (the two-way region loop, :mod:`femcoupling.coupling.twoway`; the
hierarchical Newton of :class:`femcoupling.fem.model.FemModel`; the region mode's Newton in
:class:`femcoupling.fem.model.FemModel`) ends in exactly one of :data:`STATUSES`:

``converged``
    every check held: the tolerance was met, the principal axes of the FEM stress are within
    the walls' limit (for a walled element: one that imposes three normal stresses), and the
    element strains within a factor ``max_strain_ratio`` (2) of its FEM region, in
    [1 / max_strain_ratio, max_strain_ratio].
``stopped_at_scatter``
    every check held but the tolerance: the loop stopped on a change (or a residual) within
    the elements' own scatter or noise, above the tolerance asked. The loop's map is
    deterministic (elements are restored bitwise), so this is not convergence; it says that
    the tolerance is below what the elements resolve.
``stalled``
    the loop stopped (its change settled, or Newton stopped halving its residual) but a check
    of the coupled state did not hold: the axes past the walls' limit, the strains of the two
    scales apart, or (Newton) a step taken at its best iterate above the tolerance.
``failed``
    no coupled state: the loop did not settle within its iterations (or a step could not be
    accepted).

The statuses are ordered from best to worst; :func:`worst` gives a loop of several regions
(or load steps) its status. :data:`EXIT_CODES` are the exit statuses a case gives them.
Pure Python and NumPy: no dolfinx here.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable

from femcoupling._checks import FemInputError, _real

__all__ = ["EXIT_CODES", "STATUSES", "CouplingStatus", "NoiseWarning", "check_limits", "exit_code",
           "judge_region", "judge_steps", "newton_acceptance", "worst"]

#: the statuses, best first
STATUSES = ("converged", "stopped_at_scatter", "stalled", "failed")

#: the exit status of a case whose requested coupling ended so (0: converged, or no coupling
#: asked; 1, 2, 130 and 143 are taken by errors, bad arguments and interrupts)
EXIT_CODES = {"converged": 0, "stopped_at_scatter": 3, "stalled": 4, "failed": 5}


class NoiseWarning(UserWarning):
    """The tolerance asked for is below what the DEM elements can resolve: re-running them
    on (to 1e-9) the same increment moves the residual by more, so a load step is accepted at
    that noise instead (below the ceiling: stopped_at_scatter, not converged). Warned by the
    Newton of the hierarchical models and of the soil body with DEM element regions."""


def _check_status(status: str) -> str:
    if status not in STATUSES:
        raise FemInputError(f"status={status!r}: must be one of {STATUSES}")
    return status


def worst(statuses: Iterable[str]) -> str:
    """The worst of ``statuses`` (the order of :data:`STATUSES`); "converged" for none."""
    out = STATUSES[0]
    for s in statuses:
        if STATUSES.index(_check_status(s)) > STATUSES.index(out):
            out = s
    return out


def exit_code(status: str) -> int:
    """The exit status of a case whose coupling ended in ``status`` (:data:`EXIT_CODES`)."""
    return EXIT_CODES[_check_status(status)]


def _num(x) -> float:
    return math.nan if x is None else float(x)


@dataclasses.dataclass(frozen=True)
class CouplingStatus:
    """How one region (or element) of a coupled loop ended.

    Attributes:
        status: one of :data:`STATUSES`.
        reason: one line: every check that did not hold, or that every check held.
        final_change: the loop's last relative change of the handed-over stresses in this
            region (two-way), or the accepted Newton residual relative to the force scale it
            is judged against (hierarchical), -.
        tol: the tolerance ``final_change`` is held to, -.
        axes_rotation_deg: the angle between the FEM stress's principal axes and the
            element's walls, deg (NaN where unknown).
        dem_fem_strain_ratio: the element's largest normal strain increment over its FEM
            region's, - (NaN where unknown).
        checks: per check ("tolerance", "axes", "strain_ratio") whether it held; None where
            it does not apply (the axes of an element that takes the full tensor).
        failures: the checks of the coupled state (axes, strains) that did not hold, in
            words.
    """

    status: str
    reason: str
    final_change: float
    tol: float
    axes_rotation_deg: float = math.nan
    dem_fem_strain_ratio: float = math.nan
    checks: dict = dataclasses.field(default_factory=dict)
    failures: tuple = ()

    def __post_init__(self) -> None:
        _check_status(self.status)

    @property
    def converged(self) -> bool:
        return self.status == "converged"

    def as_dict(self) -> dict:
        """JSON-ready (NaN and inf as None)."""
        def clean(x):
            return x if x is None or not isinstance(x, float) or math.isfinite(x) else None

        return {"status": self.status, "reason": self.reason,
                "final_change": clean(float(self.final_change)), "tol": clean(float(self.tol)),
                "axes_rotation_deg": clean(float(self.axes_rotation_deg)),
                "dem_fem_strain_ratio": clean(float(self.dem_fem_strain_ratio)),
                "checks": dict(self.checks)}

    def line(self, name: str) -> str:
        """One line for a log or a report."""
        def g(x: float, fmt: str) -> str:
            return "unknown" if not math.isfinite(x) else format(x, fmt)

        return (f"{name}: {self.status} (final change {g(self.final_change, '.3g')}, tol "
                f"{g(self.tol, '.3g')}, axes {g(self.axes_rotation_deg, '.1f')} deg, DEM/FEM "
                f"strain {g(self.dem_fem_strain_ratio, '.3g')}): {self.reason}")


def strain_ratio_held(ratio: float, max_strain_ratio: float = 2.0) -> bool:
    """Whether the DEM/FEM strain ratio is within [1 / max_strain_ratio, max_strain_ratio]
    (False for NaN: the strains were not both measured)."""
    return bool(1.0 / max_strain_ratio <= ratio <= max_strain_ratio)


def check_limits(max_rotation_deg: float, max_strain_ratio: float) -> None:
    """The checks' limits: ``max_rotation_deg`` > 0 (deg), ``max_strain_ratio`` > 1 (-);
    raises FemInputError naming the field and the value."""
    if not (_real("max_rotation_deg", max_rotation_deg) > 0):
        raise FemInputError(f"max_rotation_deg={max_rotation_deg!r}: must be > 0 (deg)")
    if not (_real("max_strain_ratio", max_strain_ratio) > 1):
        raise FemInputError(f"max_strain_ratio={max_strain_ratio!r}: must be > 1 (the element "
                            "and its region strain within that factor of each other)")


def judge_region(*, settled: bool, final_change: float, tol: float, walled: bool,
                 axes_rotation_deg: float = math.nan, dem_fem_strain_ratio: float = math.nan,
                 scatter: float = 0.0, max_rotation_deg: float = 15.0,
                 max_strain_ratio: float = 2.0, iterations: int | None = None
                 ) -> CouplingStatus:
    """The status of one region of a two-way loop (module doc).

    Args:
        settled: the loop stopped on its change (within ``tol`` or the elements' scatter);
            False: it ran out of iterations.
        final_change: the region's last relative change of the handed-over stresses, -.
        tol: the loop's tolerance on that change, -, > 0.
        walled: the element imposes three normal stresses with walls (the axes are checked);
            False: it takes the full tensor (a periodic element).
        axes_rotation_deg: the FEM stress's principal axes against the walls, deg.
        dem_fem_strain_ratio: the element's normal strain increment over the region's
            (largest components), -.
        scatter: the change the elements' scatter allows (relative), -, for the reason.
        max_rotation_deg: the walls' limit, deg, > 0.
        max_strain_ratio: the strains must be within this factor of each other, > 1.
        iterations: the loop's FEM solves, for the reason.
    """
    if not (tol > 0 and math.isfinite(tol)):
        raise FemInputError(f"tol={tol!r}: must be > 0 (relative)")
    check_limits(max_rotation_deg, max_strain_ratio)
    change, rot, q = _num(final_change), _num(axes_rotation_deg), _num(dem_fem_strain_ratio)
    checks: dict = {"tolerance": bool(change <= tol)}
    fails = []
    if walled:
        checks["axes"] = bool(rot <= max_rotation_deg)
        if not checks["axes"]:
            fails.append(f"the principal axes are turned {rot:.1f} deg from the walls (> "
                         f"{max_rotation_deg:g}: the walls impose the normal stresses on the "
                         "wrong planes and miss the shear)" if math.isfinite(rot) else
                         "the principal axes' rotation is unknown")
    else:
        checks["axes"] = None  # (the element takes the full tensor: nothing is lost)
    lo, hi = 1.0 / max_strain_ratio, max_strain_ratio
    checks["strain_ratio"] = strain_ratio_held(q, max_strain_ratio)
    if not checks["strain_ratio"]:
        fails.append(f"the element strains {q:.3g} times its FEM region (outside [{lo:g}, "
                     f"{hi:g}]: the scales have not met)" if math.isfinite(q) or q == math.inf
                     else "the DEM/FEM strain ratio is unknown (the strains were not both "
                          "measured)")
    solves = "" if iterations is None else f" after {iterations} FEM solves"
    if not settled:
        status = "failed"
        reason = (f"not settled{solves}: the change {change:.3g} is above tol {tol:g}"
                  + (f" and the elements' scatter ({scatter:.3g})" if scatter > 0 else ""))
        if fails:
            reason += "; also " + "; ".join(fails)
    elif fails:
        status = "stalled"
        reason = (f"stopped{solves} on a change of {change:.3g} ("
                  + (f"within tol {tol:g}" if checks["tolerance"] else
                     f"above tol {tol:g}, within the elements' scatter {scatter:.3g}")
                  + "), but " + "; ".join(fails))
    elif checks["tolerance"]:
        status = "converged"
        reason = (f"every check held{solves}: the change {change:.3g} within tol {tol:g}"
                  + (f", the axes {rot:.1f} deg within {max_rotation_deg:g}" if walled
                     else " (axes not checked: the element takes the full tensor)")
                  + f", the strain ratio {q:.3g} within [{lo:g}, {hi:g}]")
    else:
        status = "stopped_at_scatter"
        reason = (f"stopped{solves} at the elements' scatter: the change {change:.3g} is "
                  f"above tol {tol:g}, within the scatter ({scatter:.3g}); the loop's map is "
                  "deterministic, so this is not convergence (the tolerance is below what "
                  "the elements resolve)")
    return CouplingStatus(status=status, reason=reason, final_change=change, tol=float(tol),
                          axes_rotation_deg=rot, dem_fem_strain_ratio=q, checks=checks,
                          failures=tuple(fails))


def newton_acceptance(residual: float, *, rtol: float, noise_residual: float = math.nan,
                      noise_factor: float = 2.0, ceiling: float = math.inf) -> str | None:
    """Whether a hierarchical Newton step may be accepted at ``residual`` (relative to its
    force scale, like ``rtol``, ``noise_residual`` and ``ceiling``): "converged" when it is
    within ``rtol``; "stopped_at_scatter" when it is above ``rtol`` but within
    ``noise_factor`` times the elements' measured noise (``noise_residual``) and within the
    ``ceiling``; None otherwise (not acceptable: Newton goes on, or the step is cut)."""
    r = _num(residual)
    if r <= rtol:
        return "converged"
    if math.isfinite(_num(noise_residual)) and r <= noise_factor * noise_residual \
            and r <= ceiling:
        return "stopped_at_scatter"
    return None


def judge_steps(steps, *, dem_fem_strain_ratio: float = math.nan, walled: bool = False,
                axes_rotation_deg: float = math.nan, max_rotation_deg: float = 15.0,
                max_strain_ratio: float = 2.0) -> CouplingStatus:
    """The status of a region coupled inside the FEM's Newton (the region mode's hierarchical
    load stage) over its accepted load ``steps`` (each with ``status``, ``residual`` and
    ``tol``, as ``femcoupling.fem.steps.LoadStep``): "stalled" where a check of the
    coupled state fails (the element's strain not within [1 / ``max_strain_ratio``,
    ``max_strain_ratio``] of its region's or, for a ``walled`` element, the axes past
    ``max_rotation_deg``; or a step taken at a stall); else "stopped_at_scatter" where a step
    stopped within the elements' noise above its tolerance; else "converged"; "failed"
    without a step. ``final_change`` and ``tol`` are those of the step furthest above its
    tolerance (the last step if none is)."""
    if not (max_strain_ratio > 1 and math.isfinite(max_strain_ratio)):
        raise FemInputError(f"max_strain_ratio={max_strain_ratio!r}: must be > 1")
    steps = list(steps)
    rot, q = _num(axes_rotation_deg), _num(dem_fem_strain_ratio)
    if not steps:
        return CouplingStatus("failed", "no load step was accepted", math.inf, math.nan, rot, q,
                              {"tolerance": False})
    for k, r in enumerate(steps):
        _check_status(r.status)
        if r.status == "failed":
            raise FemInputError(f"steps[{k}].status={r.status!r}: an accepted Newton step of "
                                "the region mode is 'converged', 'stopped_at_scatter' or "
                                "'stalled'")
    res = [_num(r.residual) for r in steps]
    tols = [_num(r.tol) for r in steps]
    k = max(range(len(steps)), key=lambda i: (res[i] / tols[i]
                                              if tols[i] > 0 and math.isfinite(res[i])
                                              else math.inf, i))
    stalled = [i for i, r in enumerate(steps) if r.status == "stalled"]
    scatter = [i for i, r in enumerate(steps) if r.status == "stopped_at_scatter"]
    checks: dict = {"tolerance": not stalled and not scatter}
    fails = []
    if walled:
        checks["axes"] = bool(rot <= max_rotation_deg)
        if not checks["axes"]:
            fails.append(f"the principal axes are turned {rot:.1f} deg from the walls (> "
                         f"{max_rotation_deg:g})")
    else:
        checks["axes"] = None
    lo, hi = 1.0 / max_strain_ratio, max_strain_ratio
    checks["strain_ratio"] = strain_ratio_held(q, max_strain_ratio)
    if not checks["strain_ratio"]:
        fails.append(f"the element strains {q:.3g} times its FEM region (outside [{lo:g}, "
                     f"{hi:g}])" if not math.isnan(q) else
                     "the DEM/FEM strain ratio is unknown")
    if stalled:
        fails.insert(0, f"{len(stalled)} of {len(steps)} load steps taken at a stall (the "
                        f"largest residual {res[k]:.3g} of the region's own internal force, "
                        f"above tol {tols[k]:.3g})")
    if fails:
        return CouplingStatus("stalled", "; ".join(fails), res[k], tols[k], rot, q, checks,
                              tuple(fails))
    if scatter:
        why = (f"{len(scatter)} of {len(steps)} load steps stopped within the DEM elements' "
               f"noise above newton_rtol (the largest residual {res[k]:.3g} of the region's "
               f"own internal force, tol {tols[k]:.3g}); the axes and the strain ratio "
               f"{q:.3g} held")
        return CouplingStatus("stopped_at_scatter", why, res[k], tols[k], rot, q, checks)
    return CouplingStatus("converged", f"every check held: all {len(steps)} load steps within "
                          f"newton_rtol (the largest residual {res[k]:.3g}, tol {tols[k]:.3g})"
                          f", the strain ratio {q:.3g} within [{lo:g}, {hi:g}]", res[k],
                          tols[k], rot, q, checks)
