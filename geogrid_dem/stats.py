"""Statistics the studies share."""

from __future__ import annotations


def t_critical(n: int, level: float = 0.95) -> float:
    """Student's t at (1 + level) / 2 with n - 1 degrees of freedom (two-sided ``level``), -;
    NaN below 2 seeds."""
    if n < 2:
        return float("nan")
    from scipy.stats import t as student_t

    return float(student_t.ppf(0.5 * (1.0 + level), n - 1))
