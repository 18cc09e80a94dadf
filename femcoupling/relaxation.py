"""Relaxation of coupled iterations (hierarchical Newton, the two-way loop)."""

from __future__ import annotations

import numpy as np

__all__ = ["aitken_factor"]


def aitken_factor(omega: float, d_prev: np.ndarray, d: np.ndarray, lo: float = 0.1,
                  hi: float = 1.0) -> float:
    """Aitken's relaxation factor (Irons & Tuck) for the next correction, from the last
    factor ``omega`` and the last two full corrections: -omega d_prev.(d - d_prev) /
    |d - d_prev|^2, kept in [lo, hi]. A steady approach (d = a d_prev, 0 < a < 1) raises it by
    1 / (1 - a); a 2-cycle (d = -d_prev) halves it. Unchanged if the corrections are equal to
    the last bit."""
    diff = np.asarray(d, float) - np.asarray(d_prev, float)
    den = float(diff @ diff)
    if den == 0.0:
        return float(omega)
    return float(np.clip(-omega * float(np.asarray(d_prev, float) @ diff) / den, lo, hi))
