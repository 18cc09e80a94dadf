"""The checks of a DEM element's strain increment (``DemElement.apply_strain``): its
arguments by name, a bound on the stretch of one call, and the report of an element that
lost every contact on the way (docs/periodic.md, docs/reliability.md).

- **One call strains at most** :data:`MAX_STRAIN_INCREMENT` (10 %) along any principal
  direction of F = I + de (a rigid rotation stretches nothing, so it is not bounded). A call
  loads at a constant rate and relaxes once at its end; an FEM trial hands an element 1e-6 to
  1e-2 (the footing's and the shear band's Newton). A larger change is a loading path: give it
  as several calls, each relaxed, or raise ``max_increment`` on purpose.
- **A packing that falls apart is said.** An element that had contacts before the call and
  has none after it (a cohesionless packing stretched past its overlaps: +1 % along z is
  enough for a dense 60-grain element at 10 kPa) carries no stress and no stiffness; its
  stress, zero, is not a material's answer. :class:`ContactLossWarning` names the increment,
  the contacts before and the unbalanced force. (The FEM's Newton also fails such a trial, by
  name: ``femcoupling.materials.dem_elements.trial_stiffness``.)
"""

from __future__ import annotations

import math
import numbers
import warnings

import numpy as np

from cpp_dem._checks import positive
from cpp_dem import fixedorder
from cpp_dem._core import ParameterError

__all__ = ["ContactLossWarning", "MAX_STRAIN_INCREMENT", "check_strain_call",
           "principal_stretch", "report_contact_loss"]

#: The largest principal stretch change |lambda - 1| of one ``apply_strain`` call (-).
MAX_STRAIN_INCREMENT = 0.1


class ContactLossWarning(UserWarning):
    """A DEM element lost every contact in a strain increment: its stress and stiffness are
    zero (a cohesionless packing pulled apart), which no continuum can take as an answer."""


def _whole(name: str, v, lo: int, allowed: str) -> int:
    ok = isinstance(v, numbers.Integral) and not isinstance(v, bool)
    if not ok and isinstance(v, numbers.Real) and not isinstance(v, bool):
        ok = math.isfinite(float(v)) and float(v).is_integer()
    if not ok or int(v) < lo:
        raise ParameterError(f"{name}={v!r}: must be a whole number >= {lo} ({allowed})")
    return int(v)


def principal_stretch(de: np.ndarray) -> float:
    """The largest |lambda - 1| of the principal stretches lambda of F = I + ``de`` (the
    square roots of the eigenvalues of F^T F): 0 for a rigid rotation."""
    f = np.eye(3) + np.asarray(de, float)
    lam = np.sqrt(np.clip(fixedorder.eigvalsh(fixedorder.matmul3(f.T, f)), 0.0, None))
    return float(np.abs(lam - 1.0).max())


def check_strain_call(de: np.ndarray, *, steps, max_strain_per_step, unbalanced,
                      max_relax_steps, max_increment) -> None:
    """Refuses a bad argument of ``apply_strain`` by name, before anything runs: ``steps``
    (None or a whole number >= 1), ``max_strain_per_step`` and ``unbalanced`` (finite, >
    0), ``max_relax_steps`` (a whole number >= 0), ``max_increment`` (finite, > 0) and an
    increment ``de`` that stretches more than ``max_increment`` in one call."""
    if steps is not None:
        _whole("steps", steps, 1, "DEM steps of the loading; None: from max_strain_per_step")
    positive("max_strain_per_step", max_strain_per_step,
              "the largest strain of one DEM step, -")
    positive("unbalanced", unbalanced, "the unbalanced-force ratio the relaxation ends at, -")
    _whole("max_relax_steps", max_relax_steps, 0, "DEM steps of the relaxation at most")
    bound = positive("max_increment", max_increment,
                      "the largest principal stretch change of one call, -")
    got = principal_stretch(de)
    if got > bound:
        raise ParameterError(
            f"de: a principal stretch change of {got:.4g} ({100 * got:+.3g} %) in one call, "
            f"beyond max_increment={bound:g}: one call loads at a constant rate and relaxes "
            f"once at its end (an FEM trial is 1e-6 to 1e-2); give the path as several calls "
            f"of at most {bound:g} each, or raise max_increment on purpose")


def report_contact_loss(element, de: np.ndarray, before: int) -> None:
    """Warns (:class:`ContactLossWarning`) when ``element`` had ``before`` > 0 contacts and
    has none after the increment ``de``."""
    if before <= 0 or element.contact_count() > 0:
        return
    u = float(element.scene.unbalanced_force())
    warnings.warn(
        f"DemElement ({element.kind}): the strain increment "
        f"{np.round(np.asarray(de), 7).tolist()} opened all {before} contacts of the element: "
        f"its grains no longer touch, so its stress and stiffness are zero (unbalanced force "
        f"{u:.3g}); a cohesionless packing stretched past its overlaps is no material point "
        "(a smaller or compressive increment, or a higher confinement, keeps it together)",
        ContactLossWarning, stacklevel=3)
