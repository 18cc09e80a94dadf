"""Relaxation of coupled iterations (hierarchical Newton, the two-way loop)."""

from __future__ import annotations

import numpy as np
from cpp_dem import fixedorder

from femcoupling._checks import FemInputError

__all__ = ["aitken_factor", "check_relaxation", "next_factor"]


def aitken_factor(omega: float, d_prev: np.ndarray, d: np.ndarray, lo: float = 0.1,
                  hi: float = 1.0) -> float:
    """Aitken's relaxation factor (Irons & Tuck) for the next correction, from the last
    factor ``omega`` and the last two full corrections: -omega d_prev.(d - d_prev) /
    |d - d_prev|^2, kept in [lo, hi]. A steady approach (d = a d_prev, 0 < a < 1) raises it by
    1 / (1 - a); a 2-cycle (d = -d_prev) halves it. Unchanged if the corrections are equal to
    the last bit."""
    diff = np.asarray(d, float) - np.asarray(d_prev, float)
    den = fixedorder.dot(diff, diff)
    if den == 0.0:
        return float(omega)
    return float(np.clip(-omega * fixedorder.dot(d_prev, diff) / den, lo, hi))


def check_relaxation(relaxation) -> str | float:
    """``relaxation`` if it is "aitken", "none" or a fixed factor in (0, 1]; else a
    FemInputError naming the value and what is allowed."""
    if relaxation in ("aitken", "none") or (
            isinstance(relaxation, (int, float)) and 0 < float(relaxation) <= 1):
        return relaxation
    raise FemInputError(f"relaxation={relaxation!r}: 'aitken' (Aitken's dynamic factor on "
                        "the corrections), 'none', or a fixed factor in (0, 1]")


def next_factor(relaxation, omega: float, d_prev, d) -> float:
    """The relaxation factor for the full correction ``d`` after ``d_prev`` (None for the
    first): Aitken's update of ``omega``, 1 for "none", or the fixed factor."""
    if relaxation == "aitken":
        return omega if d_prev is None else aitken_factor(omega, d_prev, d)
    return 1.0 if relaxation == "none" else float(relaxation)
