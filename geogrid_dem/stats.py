"""Statistics the studies share."""

from __future__ import annotations


def t_critical(n: int, level: float = 0.95) -> float:
    """Student's t at (1 + level) / 2 with n - 1 degrees of freedom (two-sided ``level``), -;
    NaN below 2 seeds."""
    if n < 2:
        return float("nan")
    from scipy.stats import t as student_t

    return float(student_t.ppf(0.5 * (1.0 + level), n - 1))


def paired_difference(d) -> dict:
    """The paired differences ``d`` (one per seed): their count ``n``, ``mean``, standard
    error ``se`` (NaN below 2) and Student's ``t`` = mean / se (NaN where se is not > 0); the
    same units as ``d``, t dimensionless."""
    import math

    import numpy as np

    n = len(d)
    mean = float(np.mean(d)) if n else math.nan
    se = float(np.std(d, ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    t = mean / se if n > 1 and se > 0 else math.nan
    return {"n": n, "mean": mean, "se": se, "t": t}


def resolved(t: float, n: int, level: float = 0.95) -> bool:
    """Whether a paired difference of Student's ``t`` over ``n`` seeds is resolved at the
    two-sided ``level``: |t| > t_critical(n, level) (never below 2 seeds)."""
    import math

    return bool(math.isfinite(t) and n > 1 and abs(t) > t_critical(n, level))
