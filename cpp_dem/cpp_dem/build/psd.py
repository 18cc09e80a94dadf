"""Particle size distributions (PSD): radii from sieve curves or mean +- dispersion.

A sieve curve is given as sizes (particle *diameters*, m, strictly increasing, > 0) and the
cumulative fraction passing each size (non-decreasing, from 0 to 1), as 001 Appendix B
(``psdSizes``, ``psdCumm``). The fractions are by **mass** by default (that is what a sieve
analysis measures): within each class the mass is spread uniformly in diameter, so the
number density there goes as d^-3. ``by="count"`` reads the same curve as cumulative fractions
by number (what Yade's ``makeCloud`` does unless ``distributeMass=True``): within each class
the number is uniform in diameter.

Sampling is stratified (quantiles (k + U_k) / n of the class-resolved inverse CDF, shuffled
with the seed), so even a few hundred grains follow the curve closely. Its powers are the
C library's (``cpp_dem.fixedorder.powers``): NumPy's power of an array rounds otherwise on a
CPU without AVX-512, and 200 seeds' samples were other radii there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from cpp_dem._core import ParameterError
from cpp_dem.fixedorder import powers

#: 001 Appendix B sieve curve: diameters (m) and cumulative mass fractions passing.
APPENDIX_B_SIZES = (0.000074, 0.00015, 0.0004, 0.002, 0.004, 0.007, 0.01, 0.02, 0.025)
APPENDIX_B_PASSING = (0.0, 0.02, 0.05, 0.12, 0.21, 0.36, 0.45, 0.81, 1.0)


@dataclass(frozen=True)
class SieveCurve:
    """A validated sieve curve: diameters (m) and cumulative passing fractions, by mass or
    count."""

    sizes: tuple
    passing: tuple
    by: str = "mass"

    def __post_init__(self) -> None:
        validate_psd(self.sizes, self.passing, self.by)


def validate_psd(sizes, passing, by: str = "mass") -> None:
    """Raises ParameterError naming the field, the value and what is allowed."""
    if by not in ("mass", "count"):
        raise ParameterError(f"by={by!r}: must be 'mass' or 'count'")
    d = np.asarray(sizes, dtype=float).ravel()
    p = np.asarray(passing, dtype=float).ravel()
    if len(d) < 2:
        raise ParameterError(f"sizes: has {len(d)} values; need at least 2 (diameters, m)")
    if len(p) != len(d):
        raise ParameterError(f"passing: has {len(p)} values for {len(d)} sizes; need one "
                             "cumulative fraction per size")
    for k, x in enumerate(d):
        if not (math.isfinite(x) and x > 0):
            raise ParameterError(f"sizes[{k}]={x}: must be > 0 (particle diameter, m)")
    for k in range(1, len(d)):
        if not d[k] > d[k - 1]:
            raise ParameterError(f"sizes[{k}]={d[k]}: must be > sizes[{k - 1}]={d[k - 1]} "
                                 "(sizes strictly increasing)")
    for k, x in enumerate(p):
        if not (math.isfinite(x) and 0 <= x <= 1):
            raise ParameterError(f"passing[{k}]={x}: must be in [0, 1]")
    for k in range(1, len(p)):
        if p[k] < p[k - 1]:
            raise ParameterError(f"passing[{k}]={p[k]}: must be >= passing[{k - 1}]={p[k - 1]}"
                                 " (cumulative fractions are non-decreasing)")
    if p[0] != 0:
        raise ParameterError(f"passing[0]={p[0]}: must be 0 (nothing passes the smallest "
                             "size; add a smaller size with fraction 0)")
    if abs(p[-1] - 1.0) > 1e-9:
        raise ParameterError(f"passing[-1]={p[-1]}: must be 1 (all of the material passes the "
                             "largest size)")


def _count_weights(d: np.ndarray, p: np.ndarray, by: str) -> np.ndarray:
    """Probability (by number) of each class [d_k, d_k+1]."""
    dp = np.diff(p)
    if by == "count":
        w = dp.copy()
    else:
        # Mass uniform in d within the class: number ~ int dP/dd / d^3 dd.
        da, db = d[:-1], d[1:]
        w = dp / (db - da) * 0.5 * (powers(da, -2) - powers(db, -2))
    return w / w.sum()


def expected_count(sizes, passing, solid_volume: float, by: str = "mass") -> float:
    """Expected number of grains whose volumes add up to ``solid_volume`` (m^3)."""
    validate_psd(sizes, passing, by)
    d = np.asarray(sizes, float)
    p = np.asarray(passing, float)
    dp = np.diff(p)
    da, db = d[:-1], d[1:]
    if by == "mass":
        # N = V_s int dP / v(d), v = pi d^3 / 6.
        inv_v = np.sum(dp / (db - da) * 6.0 / math.pi * 0.5 * (powers(da, -2) - powers(db, -2)))
        return float(solid_volume * inv_v)
    # by count: mean volume = sum dP_k mean_{uniform d in class} pi d^3 / 6.
    mean_v = np.sum(dp * math.pi / 6.0 * (powers(db, 4) - powers(da, 4)) / (4.0 * (db - da)))
    return float(solid_volume / mean_v)


def truncate_psd(sizes, passing, d_min: float, by: str = "mass") -> tuple[np.ndarray, np.ndarray]:
    """The curve without the fraction finer than ``d_min`` (m), renormalised to end at 1
    ("scalping" of the fines, as DEM samples are usually built)."""
    validate_psd(sizes, passing, by)
    d = np.asarray(sizes, float)
    p = np.asarray(passing, float)
    if not (d[0] <= d_min < d[-1]):
        raise ParameterError(f"d_min={d_min}: must be in [{d[0]}, {d[-1]}) (m)")
    p_cut = float(np.interp(d_min, d, p))
    if p_cut >= 1:
        raise ParameterError(f"d_min={d_min}: nothing of the curve is coarser")
    keep = d > d_min
    d2 = np.concatenate([[d_min], d[keep]])
    p2 = (np.concatenate([[p_cut], p[keep]]) - p_cut) / (1.0 - p_cut)
    p2[0], p2[-1] = 0.0, 1.0
    return d2, p2


def fit_psd_to_count(sizes, passing, n_target: int, solid_volume: float, *, by: str = "mass",
                     method: str = "truncate") -> tuple[np.ndarray, np.ndarray, float]:
    """Adapts a sieve curve so that ``solid_volume`` (m^3) holds about ``n_target`` grains.

    method ``"truncate"``: cut the fines below the size d_min found by bisection (sizes kept
    as given); ``"scale"``: multiply every size by one factor s (curve shape kept), s =
    (N(1) / n_target)^(1/3). Returns (sizes, passing, parameter) with parameter d_min (m) or s.
    """
    if not (int(n_target) >= 1):
        raise ParameterError(f"n_target={n_target}: must be >= 1")
    if not (solid_volume > 0):
        raise ParameterError(f"solid_volume={solid_volume}: must be > 0 (m^3)")
    d = np.asarray(sizes, float)
    p = np.asarray(passing, float)
    n_full = expected_count(d, p, solid_volume, by)
    if method == "scale":
        s = (n_full / n_target) ** (1.0 / 3.0)
        return d * s, p.copy(), float(s)
    if method != "truncate":
        raise ParameterError(f"method={method!r}: must be 'truncate' or 'scale'")
    if n_full <= n_target:
        raise ParameterError(f"n_target={n_target}: the full curve gives only {n_full:.0f} "
                             "grains in this volume; truncation can only reduce the count "
                             "(use method='scale')")
    lo, hi = d[0], d[-1] * (1 - 1e-9)
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        n = expected_count(*truncate_psd(d, p, mid, by), solid_volume, by)
        if n > n_target:
            lo = mid
        else:
            hi = mid
        if hi / lo < 1 + 1e-10:
            break
    d2, p2 = truncate_psd(d, p, hi, by)
    return d2, p2, float(hi)


def radii_from_psd(sizes, passing, n: int, *, by: str = "mass", seed: int = 0) -> np.ndarray:
    """``n`` radii (m) following the sieve curve (diameters ``sizes``, m; cumulative fractions
    ``passing`` by mass or count). Stratified sampling, shuffled with ``seed``."""
    validate_psd(sizes, passing, by)
    n = int(n)
    if n < 1:
        raise ParameterError(f"n={n}: must be >= 1")
    d = np.asarray(sizes, float)
    p = np.asarray(passing, float)
    w = _count_weights(d, p, by)
    cw = np.concatenate([[0.0], np.cumsum(w)])
    cw[-1] = 1.0
    rng = np.random.default_rng(seed)
    u = (np.arange(n) + rng.random(n)) / n
    k = np.clip(np.searchsorted(cw, u, side="right") - 1, 0, len(w) - 1)
    t = (u - cw[k]) / np.where(w[k] > 0, w[k], 1.0)  # position within the class, [0, 1)
    da, db = d[k], d[k + 1]
    if by == "count":
        diam = da + t * (db - da)
    else:
        # Inverse of F(x) = (da^-2 - x^-2) / (da^-2 - db^-2).
        ia, ib = powers(da, -2), powers(db, -2)
        diam = powers(ia - t * (ia - ib), -0.5)
    return rng.permutation(0.5 * diam)


def radii_uniform(mean: float, dispersion: float, n: int, *, seed: int = 0) -> np.ndarray:
    """``n`` radii (m) uniform in [mean - dispersion, mean + dispersion] (000 Table 1: mean
    radius 1.2e-2 m, dispersion 6e-3 m). Stratified, shuffled with ``seed``."""
    if not (math.isfinite(mean) and mean > 0):
        raise ParameterError(f"mean={mean}: must be > 0 (m)")
    if not (math.isfinite(dispersion) and 0 <= dispersion < mean):
        raise ParameterError(f"dispersion={dispersion}: must be in [0, mean={mean}) (m), so "
                             "that every radius is > 0")
    n = int(n)
    if n < 1:
        raise ParameterError(f"n={n}: must be >= 1")
    rng = np.random.default_rng(seed)
    u = (np.arange(n) + rng.random(n)) / n
    return rng.permutation(mean - dispersion + 2 * dispersion * u)


def passing_of(radii, sizes, *, by: str = "mass") -> np.ndarray:
    """Cumulative fraction (by mass or count) of the grains with diameter < each size."""
    d = 2 * np.asarray(radii, float)
    w = powers(d, 3) if by == "mass" else np.ones_like(d)
    return np.array([w[d < s].sum() for s in np.asarray(sizes, float)]) / w.sum()
