"""Scales that agree (issue 18): fit the FEM soil (Drucker–Prager matched to Mohr–Coulomb) to
a DEM element along the stress path of its FEM region.

:func:`fit_along_path` drives a dense periodic element (``femcoupling.materials.dem_elements``) from
the region's initial stress tensor along the straight path to its loaded one, and on beyond it,
sigma(t) = sigma_0 + t (sigma_1 - sigma_0), t = beyond / points, 2 beyond / points, ...,
until a point cannot be reached (the element strains more than ``max_strain`` on the way: it
is at its strength) or t = ``beyond``. Then

- **E, nu**: the secant over the region's own path (t from 0 to 1, or to the last point
  reached if it fails before), least squares on the normal components
  (``handover.secant_stiffness``);
- **phi**: the Mohr–Coulomb angle of the state the element held when it failed, from its
  in-plane principal stresses (the FEM's plane is the element's x–z):
  sin phi = (s1 - s3) / (s1 + s3 + 2 c cot phi), with the given cohesion ``c`` (0 for
  cohesionless grains).

The fitted ``DruckerPrager`` then carries the stress ratio the element carries. If the element
never failed up to ``beyond``, phi is a lower bound (``strength_reached`` False) and the fit
says so. SI units; FEM tensors tension positive.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from cpp_dem import fixedorder

from femcoupling._checks import FemInputError
from femcoupling.coupling.handover import fem_to_dem, secant_stiffness
from femcoupling.materials.continuum import DruckerPrager
from femcoupling.materials.dem_elements import PeriodicRegionElement, servo

__all__ = ["PathFit", "fit_along_path", "friction_angle_deg"]


@dataclasses.dataclass
class PathFit:
    """What :func:`fit_along_path` found.

    Attributes:
        material: the fitted DruckerPrager (E, nu, c, phi).
        t: the path parameters reached (0 first), -.
        stresses_pa: (k, 3, 3) the element's stress at each, tension positive.
        strains: (k, 3, 3) its strain since the initial state, tension positive.
        strength_reached: the element failed before ``beyond`` (phi is then its strength).
        message: a sentence for the log.
    """

    material: DruckerPrager
    t: np.ndarray
    stresses_pa: np.ndarray
    strains: np.ndarray
    strength_reached: bool
    message: str

    @property
    def failure_stress_pa(self) -> np.ndarray:
        """(3, 3) the last stress the element carried below failure, tension positive."""
        return self.stresses_pa[-1]


def friction_angle_deg(stress_pa, cohesion_pa: float = 0.0) -> float:
    """The Mohr–Coulomb friction angle (deg) at which the stress (3 x 3, tension positive, the
    FEM's plane the x–z one) is at failure with cohesion ``cohesion_pa``."""
    s = -np.asarray(stress_pa, float)  # compression positive
    m = np.array([[s[0, 0], s[0, 2]], [s[2, 0], s[2, 2]]])
    lo, hi = fixedorder.eigvalsh(0.5 * (m + m.T))
    if not hi > 0:
        raise FemInputError(f"stress_pa={np.round(-s, 1).tolist()}: no compression in the plane")
    if cohesion_pa == 0.0:
        return math.degrees(math.asin(min((hi - lo) / (hi + lo), 1.0)))
    # (s1 - s3) = (s1 + s3) sin phi + 2 c cos phi: solve for phi by bisection
    f = lambda p: (hi - lo) - (hi + lo) * math.sin(p) - 2 * cohesion_pa * math.cos(p)  # noqa: E731
    a, b = 0.0, math.radians(60.0)
    if f(a) <= 0:
        return 0.0
    for _ in range(80):
        c = 0.5 * (a + b)
        a, b = (c, b) if f(c) > 0 else (a, c)
    return math.degrees(0.5 * (a + b))


def fit_along_path(initial_pa, final_pa, *, n: int = 200, seed: int = 1,
                   prep_friction_deg: float | None = 0.0, beyond: float = 4.0,
                   points: int = 16, max_strain: float = 0.03, cohesion_pa: float = 0.0,
                   tol: float = 0.01, unbalanced: float = 1e-3, options: dict | None = None,
                   log=None) -> PathFit:
    """See the module doc. ``initial_pa``, ``final_pa``: the region's FEM stress tensors
    (3 x 3, Pa, tension positive) before and after the load; ``n``, ``seed``,
    ``prep_friction_deg``, ``options`` (more ``DemElement.periodic`` keywords: material,
    radius_mean, ...): the element (``PeriodicRegionElement``)."""
    s0, s1 = np.asarray(initial_pa, float), np.asarray(final_pa, float)
    for name, v in (("initial_pa", s0), ("final_pa", s1)):
        if v.shape != (3, 3) or not np.all(np.isfinite(v)):
            raise FemInputError(f"{name}: must be a finite 3 x 3 tensor (Pa)")
    if not (beyond >= 1.0 and points >= 2):
        raise FemInputError(f"beyond={beyond}, points={points}: beyond >= 1 (the path "
                            "continues past the region's) and points >= 2")
    runner = PeriodicRegionElement(n=n, seed=seed, prep_friction_deg=prep_friction_deg,
                                   tol=tol, unbalanced=unbalanced, options=options)
    el, _ = runner.prepare("fit", fem_to_dem(s0))
    e0 = el.strain()
    ts, stresses, strains = [0.0], [el.stress()], [np.zeros((3, 3))]
    t_failed = None  # the path point the element could not reach
    dt = beyond / points
    t = 0.0
    halvings = 0
    while t < beyond - 1e-12:
        keep = el.clone()  # (the state at t: a failed try restarts from it)
        t_try = min(t + dt, beyond)
        s, ok, _ = servo(el, s0 + t_try * (s1 - s0), tol=tol, unbalanced=unbalanced,
                         chunk_steps=2000, max_strain=max_strain)
        if not ok:
            # past the strength: bracket it closer (three halvings of the step), then stop
            t_failed = t_try
            if halvings == 3:
                break
            el, dt, halvings = keep, 0.5 * dt, halvings + 1
            continue
        t, t_failed = t_try, None  # (a failure that a shorter step got past is no failure)
        ts.append(t)
        stresses.append(s)
        strains.append(el.strain() - e0)
        if log is not None:
            log(f"[fit] t = {t:.4g}: reached, strain {np.abs(strains[-1]).max():.3g}")
    ts_a, st_a, ep_a = np.array(ts), np.array(stresses), np.array(strains)
    # the secant over the region's own path (t <= 1), or what was reached of it
    j = int(np.searchsorted(ts_a, 1.0 + 1e-12)) - 1
    if j < 1:
        raise FemInputError("fit_along_path: the element failed before the first point of "
                            "the region's own path; its FEM stresses are beyond the "
                            "element's strength from the start (raise points)")
    E, nu = secant_stiffness(stress_increment_pa=-np.diag(st_a[j] - st_a[0]),
                             strain_increment=-np.diag(ep_a[j]))
    # the strength: the last state reached below the failing point (the state held after
    # failing is past the peak: softened), a lower bound within the bracket
    phi = friction_angle_deg(st_a[-1], cohesion_pa)
    mat = DruckerPrager(young_pa=E, poisson=nu, cohesion_pa=cohesion_pa,
                        friction_deg=max(phi, 1e-6 if cohesion_pa > 0 else 1.0))
    if t_failed is not None:
        phi_fail = friction_angle_deg(s0 + t_failed * (s1 - s0), cohesion_pa)
        msg = (f"fitted along the region's path: E {E / 1e6:.3g} MPa, nu {nu:.3f} (secant to "
               f"t = {ts_a[j]:.3g}); the element carried t = {ts_a[-1]:.4g} (phi = {phi:.1f} "
               f"deg) and failed at t = {t_failed:.4g} (phi = {phi_fail:.1f} deg), c = "
               f"{cohesion_pa:g} Pa")
    else:
        msg = (f"fitted along the region's path: E {E / 1e6:.3g} MPa, nu {nu:.3f}; the element "
               f"carried the path to t = {beyond:g} without failing: phi = {phi:.1f} deg is a "
               "lower bound (raise beyond)")
    return PathFit(material=mat, t=ts_a, stresses_pa=st_a, strains=ep_a,
                   strength_reached=t_failed is not None,
                   message=msg)
