"""The FEM -> DEM handover: plain NumPy, no dolfinx (usable in DEM-only runs).

Sign conventions -- converted here, explicitly, and nowhere else:

- FEM (``femcoupling``): Cauchy stress **tension positive**, 3x3 ordered (x, y, z), z up.
- DEM (``cpp_dem`` servo walls, ``TriaxialController.set_stress``): **compression
  positive**, one normal stress per axis of the axis-aligned element.

So ``sigma_DEM = -sigma_FEM``. The element's walls are axis-aligned, frictionless and can only
impose the three *normal* stresses sigma_xx, sigma_yy, sigma_zz. The shear components of
the FEM tensor cannot be imposed; they are reported (:attr:`WallTargets.shear_pa`), together
with the principal stresses and the angle by which the principal axes are turned away from the
wall normals (:attr:`WallTargets.rotation_deg`), so that a user sees when the axis-aligned
element misrepresents the field: then the walls impose the right normal stresses on the wrong
planes and the element sees a mean stress right but a deviator too small.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
from cpp_dem import fixedorder

from femcoupling._checks import FemInputError, _real
from femcoupling.coupling._inputs import check_fraction

__all__ = ["HandoverError", "TARGET_DIGITS", "WallTargets", "fem_to_dem", "on_grid",
           "secant_stiffness", "secant_tangent", "spd_floor", "target_grid", "targets_on_grid"]


class HandoverError(ValueError):
    """A FEM stress that cannot become servo targets (names the value and the reason)."""


@dataclasses.dataclass(frozen=True)
class WallTargets:
    """Servo targets of an axis-aligned DEM element, **compression positive**, Pa.

    Attributes:
        normal_pa: (3,) targets of the x, y, z walls (``TriaxialController.set_stress``).
        shear_pa: (3,) the shear stresses (yz, xz, xy) the walls cannot impose, in the DEM
            sign convention (= minus the FEM ones).
        principal_pa: (3,) principal stresses, compression positive, descending.
        principal_axes: (3, 3) unit principal directions as columns, same order.
        rotation_deg: largest angle between a principal direction and its nearest coordinate
            axis, deg (0 when the principal axes are the wall normals).
        shear_ratio: max |shear| / mean normal stress, -.
        fem_stress_pa: the FEM tensor handed over (tension positive), for the record.
        grid_tension_n_per_m: the tension of the geogrid layer crossing the region, N/m of
            width, tension positive, for the element's grid ends; None where no layer
            crosses it (``femcoupling.coupling.twoway.region_targets``).
    """

    normal_pa: np.ndarray
    shear_pa: np.ndarray
    principal_pa: np.ndarray
    principal_axes: np.ndarray
    rotation_deg: float
    shear_ratio: float
    fem_stress_pa: np.ndarray
    grid_tension_n_per_m: float | None = None

    def report(self) -> str:
        """One line for the progress log."""
        n, s = self.normal_pa / 1e3, self.shear_pa / 1e3
        grid = ("" if self.grid_tension_n_per_m is None
                else f"; geogrid tension {self.grid_tension_n_per_m / 1e3:.4g} kN/m")
        return (f"walls x,y,z {n[0]:.2f}, {n[1]:.2f}, {n[2]:.2f} kPa (compression +); shear "
                f"yz,xz,xy {s[0]:.2f}, {s[1]:.2f}, {s[2]:.2f} kPa not imposed; principal axes "
                f"turned {self.rotation_deg:.1f} deg from the walls{grid}")


def _rotation_deg(axes: np.ndarray) -> float:
    """Largest angle between a column of ``axes`` and its nearest coordinate axis, deg."""
    cos = np.max(np.abs(axes), axis=0).clip(-1.0, 1.0)
    # (math's acos, not NumPy's: NumPy's arccos of an array takes its AVX-512 form on a CPU
    # that has it, and rounds otherwise there)
    return max(math.degrees(math.acos(float(c))) for c in cos)


def fem_to_dem(stress_fem_pa: npt.ArrayLike, *, min_stress_pa: float = 0.0) -> WallTargets:
    """Servo targets from a FEM stress tensor (3x3, (x, y, z), Pa, **tension positive**).

    The normal targets are ``-sigma_ii`` (compression positive). Raises
    :class:`HandoverError` if the tensor is not a finite symmetric 3x3 or a normal target is
    not above ``min_stress_pa`` (walls can push, not pull); FemInputError if
    ``min_stress_pa`` is not a finite number >= 0 Pa.
    """
    if _real("min_stress_pa", min_stress_pa) < 0.0:
        raise FemInputError(f"min_stress_pa={min_stress_pa!r}: must be >= 0 Pa (the least "
                            "compression a wall target may have: servo walls only push)")
    s = np.asarray(stress_fem_pa, dtype=float)
    if s.shape != (3, 3) or not np.all(np.isfinite(s)):
        raise HandoverError(f"stress_fem_pa={s.tolist()!r}: must be a finite 3x3 tensor")
    scale = max(float(np.abs(s).max()), 1e-300)
    if not np.allclose(s, s.T, rtol=0.0, atol=1e-9 * scale):
        raise HandoverError(f"stress_fem_pa={s.tolist()!r}: must be symmetric")
    s = 0.5 * (s + s.T)
    dem = -s  # FEM tension positive -> DEM compression positive
    normal = np.diag(dem).copy()
    for a, name in enumerate("xyz"):
        if not normal[a] > min_stress_pa:
            raise HandoverError(f"sigma_{name}{name}={float(s[a, a])!r} Pa (FEM, tension positive): "
                                f"the {name} walls would need {float(normal[a])!r} Pa compression; "
                                f"must be > {min_stress_pa!r} Pa (servo walls only push)")
    shear = np.array([dem[1, 2], dem[0, 2], dem[0, 1]])
    w, v = fixedorder.eigh(dem)
    order = np.argsort(w, kind="stable")[::-1]
    w, v = w[order], v[:, order]
    return WallTargets(normal_pa=normal, shear_pa=shear, principal_pa=w, principal_axes=v,
                       rotation_deg=_rotation_deg(v) if np.ptp(w) > 1e-9 * scale else 0.0,
                       shear_ratio=float(np.abs(shear).max() / normal.mean()),
                       fem_stress_pa=s)


#: Significant digits (of the largest component) a DEM element's target from the FEM keeps:
#: its stress, its strain and its geogrid tension. The FEM's last digits are its solver's
#: (Newton tolerance 1e-6) and its BLAS kernel's rounding, and an element servoed to a target
#: is chaotic: a path changed by 1e-7 grew into another sample of the element (one of the
#: footing's calibration elements moved from E 13.2 to 10.8 MPa). On a grid of 3 digits
#: (100 Pa at 100 kPa; an element holds its targets within 2 %) a 1e-7 change moves a
#: component to the next grid value with a chance of about 2e-4.
TARGET_DIGITS = 3


def on_grid(values: npt.ArrayLike, scale_of: npt.ArrayLike | None = None) -> np.ndarray:
    """``values`` (any shape, any unit) rounded to the grid of TARGET_DIGITS significant digits
    of the largest |component| of ``scale_of`` (an array or several; default ``values``)."""
    s = np.asarray(values, float)
    big = float(np.abs(np.asarray(s if scale_of is None else scale_of, float)).max())
    if not big > 0:
        return s.copy()
    step = 10.0 ** (math.floor(math.log10(big)) - TARGET_DIGITS + 1)
    return np.round(s / step) * step


def target_grid(stress_pa: npt.ArrayLike, scale_of: npt.ArrayLike | None = None) -> np.ndarray:
    """``stress_pa`` (3 x 3, Pa) on the grid of :func:`on_grid`, symmetric."""
    g = on_grid(stress_pa, scale_of)
    return 0.5 * (g + g.T)


def targets_on_grid(t: WallTargets) -> WallTargets:
    """``t`` made again from its FEM stress on the grid (:func:`target_grid`), its geogrid
    tension on the grid of its own digits: the targets a rounding-level change of the FEM
    (another BLAS kernel, another Newton iterate within the tolerance) leaves alone."""
    g = fem_to_dem(target_grid(t.fem_stress_pa))
    if t.grid_tension_n_per_m is None:
        return g
    return dataclasses.replace(g, grid_tension_n_per_m=float(on_grid(t.grid_tension_n_per_m)))


def _lstsq_2(x: np.ndarray, y: np.ndarray, rhs: np.ndarray) -> tuple[float, float]:
    """The least-squares (a, b) of a x + b y = rhs (three equations), the minimum-norm one
    where x and y are parallel to within 3 eps (as NumPy's lstsq, whose LAPACK calls BLAS:
    another CPU would give another last bit of a calibrated modulus): Gram–Schmidt on the
    two columns, every sum exactly rounded (``cpp_dem.fixedorder.dot``)."""
    d = fixedorder.dot
    nx, ny = math.sqrt(d(x, x)), math.sqrt(d(y, y))
    if nx == 0.0 and ny == 0.0:
        return 0.0, 0.0
    if nx == 0.0:  # (only y: its own fit)
        return 0.0, d(y, rhs) / (ny * ny)
    q1 = x / nx
    r12 = d(q1, y)
    w = y - r12 * q1
    r22 = math.sqrt(d(w, w))
    if r22 <= 3.0 * np.finfo(float).eps * max(nx, ny):
        # parallel: A = x [1, c]; the minimum-norm solution t / (1 + c^2) (1, c)
        c = r12 / nx
        t = d(x, rhs) / (nx * nx)
        return t / (1.0 + c * c), c * t / (1.0 + c * c)
    q2 = w / r22
    b = d(q2, rhs) / r22
    return (d(q1, rhs) - r12 * b) / nx, b


def secant_stiffness(*, stress_increment_pa: npt.ArrayLike, strain_increment: npt.ArrayLike,
                     poisson_bounds: tuple[float, float] = (0.0, 0.45)) -> tuple[float, float]:
    """Isotropic secant (E, nu) of an element from its normal stress and strain increments.

    Both increments are (3,) along x, y, z in the same sign convention (the DEM's
    compression positive, or both tension positive). Least squares on
    ``d_eps_i = (d_sig_i - nu (d_sig_j + d_sig_k)) / E``; nu is clipped to
    ``poisson_bounds`` (then E is refitted): a pair (lo, hi) of finite numbers with
    -1 <= lo <= hi < 0.5 (an isotropic solid's range; lo = hi fixes nu), FemInputError
    otherwise. Returns (E / Pa, nu / -).
    """
    _check_poisson_bounds(poisson_bounds)
    ds = np.asarray(stress_increment_pa, float)
    de = np.asarray(strain_increment, float)
    if ds.shape != (3,) or de.shape != (3,) or not (np.all(np.isfinite(ds))
                                                    and np.all(np.isfinite(de))):
        raise HandoverError(f"stress_increment_pa={ds.tolist()}, strain_increment="
                            f"{de.tolist()}: must be finite (3,) vectors")
    others = ds.sum() - ds
    a, b = _lstsq_2(ds, -others, de)  # unknowns (1/E, nu/E)
    nu = b / a if a > 0 else math.nan
    lo, hi = poisson_bounds
    if not (math.isfinite(nu) and lo <= nu <= hi):
        nu = min(max(nu, lo), hi) if math.isfinite(nu) else lo
        x = ds - nu * others
        xx = fixedorder.dot(x, x)
        a = fixedorder.dot(x, de) / xx if xx > 0 else math.nan
    if not (math.isfinite(a) and a > 0):
        raise HandoverError(f"secant stiffness: stress increment {ds.tolist()} Pa and strain "
                            f"increment {de.tolist()} give no positive modulus")
    return float(1.0 / a), float(nu)


def _check_poisson_bounds(bounds) -> None:
    """``bounds`` is (lo, hi), finite, -1 <= lo <= hi < 0.5; else FemInputError."""
    if isinstance(bounds, (str, bytes)):
        raise FemInputError(f"poisson_bounds={bounds!r}: must be a pair (lo, hi)")
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise FemInputError(f"poisson_bounds={bounds!r}: must be a pair (lo, hi)") from None
    _real("poisson_bounds[0]", lo)
    _real("poisson_bounds[1]", hi)
    if not -1.0 <= lo <= hi < 0.5:
        raise FemInputError(f"poisson_bounds={bounds!r}: must be (lo, hi) with "
                            "-1 <= lo <= hi < 0.5 (Poisson's ratio of an isotropic solid; "
                            "lo = hi fixes it)")


def spd_floor(t: npt.ArrayLike, min_eig_fraction: float = 1e-3, *,
              name: str = "spd_floor") -> np.ndarray:
    """The symmetric part of ``t`` with its eigenvalues raised to at least
    ``min_eig_fraction`` times the largest: a positive definite stiffness from a network
    tangent that is not quite symmetric (geometric terms) and soft or negative in some
    directions (sliding contacts near the strength). Raises HandoverError if ``t`` has no
    positive stiffness at all, FemInputError if ``min_eig_fraction`` is not in (0, 1)."""
    check_fraction(min_eig_fraction)
    t = np.asarray(t, float)
    lam, vec = fixedorder.eigh(0.5 * (t + t.T))
    if not lam[-1] > 0:
        raise HandoverError(f"{name}: the tangent has no positive stiffness "
                            f"(largest eigenvalue {lam[-1]:.3g} Pa)")
    return fixedorder.matmul(vec * np.maximum(lam, min_eig_fraction * lam[-1]), vec.T)


def secant_tangent(tangent_mandel_pa: npt.ArrayLike, *, strain_increment: npt.ArrayLike,
                   stress_increment_pa: npt.ArrayLike,
                   min_eig_fraction: float = 1e-3) -> np.ndarray:
    """The element's tangent made to reproduce its measured increment: a symmetric rank-two
    change of ``tangent_mandel_pa`` (6 x 6 Mandel, Pa) that maps the strain increment onto
    the stress increment (both Mandel (6,), the same sign convention), by the BFGS update
    (Nocedal & Wright, *Numerical Optimization*, 2006, eq. 6.19, with the strain and stress
    increments in the roles of the step and of the gradient change):

        C = T - (T de)(T de)^T / (de . T de) + ds ds^T / (ds . de)

    so that C de = ds exactly, C is symmetric, and it keeps T's response to every strain that
    does no work with T de nor with ds (four of the six directions). T is made symmetric first
    (a network tangent with geometric terms is not quite symmetric) and positive definite:
    eigenvalues below ``min_eig_fraction`` (in (0, 1)) times the largest are raised to it
    (an element near its strength has sliding contacts and a tangent soft, or negative, in
    some directions). C is then positive definite whenever ds . de > 0 (the element stored
    energy over the increment); otherwise a HandoverError names the reason. Returns C (Pa).
    """
    t = np.asarray(tangent_mandel_pa, float)
    de = np.asarray(strain_increment, float)
    ds = np.asarray(stress_increment_pa, float)
    if t.shape != (6, 6) or de.shape != (6,) or ds.shape != (6,) or not (
            np.all(np.isfinite(t)) and np.all(np.isfinite(de)) and np.all(np.isfinite(ds))):
        raise HandoverError(f"secant_tangent: tangent {t.shape}, strain increment {de.shape}, "
                            f"stress increment {ds.shape}: must be finite 6 x 6, (6,), (6,)")
    t = spd_floor(t, min_eig_fraction, name="secant_tangent")
    td = fixedorder.matmul(t, de)
    curv_t, curv = fixedorder.dot(de, td), fixedorder.dot(ds, de)
    if not curv_t > 0:  # (only for de = 0)
        raise HandoverError(f"secant_tangent: no strain increment (de . T de = {curv_t:.3g} "
                            "Pa)")
    if not curv > 0:
        raise HandoverError(f"secant_tangent: the element gave back energy over its increment "
                            f"(ds . de = {curv:.3g} Pa, strain {np.round(de, 8).tolist()}, "
                            f"stress {np.round(ds, 1).tolist()} Pa): no positive definite "
                            "secant exists")
    return t - np.outer(td, td) / curv_t + np.outer(ds, ds) / curv
