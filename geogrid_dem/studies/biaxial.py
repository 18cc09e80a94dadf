"""A plane-strain biaxial test by hierarchical FEM x DEM and by direct DEM of the same grains
(issue 18, "against direct DEM"; docs/studies/biaxial.md).

- :func:`fem_dem_biaxial`: a ``femcoupling.fem.model.FemModel`` on a ``Rectangle`` with a periodic
  DEM element per cell, the right side at the confining pressure, the top pushed down in equal
  load steps.
- :func:`direct_biaxial`: a periodic DEM cell under the same path (x at the pressure, y held,
  z shortened: ``cpp_dem.protocols.periodic.plane_strain_biaxial``). Give it the element factory to run
  every element alone (what the FEM x DEM must reproduce when the field is near homogeneous),
  or a bigger cell of all their grains.

Every result is a dict of arrays, **compression positive** (soil mechanics): ``axial_strain``
(-), ``sigma_axial`` and ``sigma_lateral`` (Pa), ``volumetric_strain`` (-, contraction
positive), and the peak: ``peak_sigma_axial`` (Pa), ``peak_axial_strain``,
``peak_volumetric_strain``. :func:`summarise` gives the mean and the standard deviation over
seeds.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import numpy as np
from cpp_dem import fixedorder

__all__ = ["fem_dem_biaxial", "direct_biaxial", "summarise", "at_strain", "rve_angles",
           "WeakZoneFactory", "weak_zone"]


@dataclasses.dataclass(frozen=True)
class WeakZoneFactory:
    """An imperfection for a shear band (issue 38): a picklable element maker for
    ``ElementPool.build`` that makes element k with ``base`` (e.g. a ``PeriodicFactory``),
    except the elements in ``weak``, which ``base`` makes with ``weak_options`` laid over its
    options (e.g. ``{"prep_friction_deg": None}``: grown at the material's friction, a looser
    and weaker packing than the dense default). Every element keeps its own seed (base.seed +
    k), so the field is also a seeded random field of packings."""

    base: object
    weak: tuple = ()
    weak_options: dict = dataclasses.field(default_factory=dict)

    def __call__(self, index: int):
        if index in self.weak:
            opts = {**(getattr(self.base, "options", None) or {}), **self.weak_options}
            return dataclasses.replace(self.base, options=opts)(index)
        return self.base(index)


def weak_zone(points: np.ndarray, centre, radius: float) -> tuple:
    """The elements whose quadrature point (``points``, m, shape (n, 2): from
    ``femcoupling.fem.bodies.quadrature_points``) lies within ``radius`` (m) of
    ``centre`` (m): the weaker zone of a ``WeakZoneFactory``. Raises ValueError when none does."""
    d = np.linalg.norm(np.asarray(points, float) - np.asarray(centre, float)[None, :], axis=1)
    k = tuple(int(i) for i in np.flatnonzero(d <= radius))
    if not k:
        raise ValueError(f"weak_zone(centre={list(centre)}, radius={radius}): no quadrature "
                         f"point lies within it (the nearest is {d.min():.3g} m away)")
    return k


def _peak(out: dict) -> dict:
    k = int(np.argmax(out["sigma_axial"]))
    out["peak_sigma_axial"] = float(out["sigma_axial"][k])
    out["peak_axial_strain"] = float(out["axial_strain"][k])
    out["peak_volumetric_strain"] = float(out["volumetric_strain"][k])
    return out


def fem_dem_biaxial(pool, *, lx: float, ly: float, nx: int, ny: int, pressure: float,
                    strain: float, steps: int, log: Callable | None = print,
                    stop_on_failure: bool = False, **model_kw) -> dict:
    """Runs the hierarchical biaxial (``pool``: one element per cell, 2 nx ny) to the axial
    ``strain`` (-) in ``steps`` equal load steps; ``model_kw`` go to the
    ``Rectangle`` (its own arguments: ``degree``, ``platens``) or the ``FemModel``. Besides the curve (see the module doc; the stresses are the
    elements' means, which in equilibrium are the boundary tractions), ``iterations``,
    ``residual``, ``converged_on`` per step, ``steps`` (the LoadStep of each load step),
    ``model`` (the FemModel) and ``wall_s``. Prints progress with an ETA
    through ``log``. A load step that fails (``NewtonFailure``) raises, or with
    ``stop_on_failure`` ends the run there: ``failed`` then gives its axial strain and the
    reason (None for a run that reached ``strain``), and the curve is the steps before."""
    from femcoupling.fem.bodies import Rectangle
    from femcoupling.fem.model import FemModel, split_options
    from femcoupling.fem.steps import NewtonFailure

    t0 = time.perf_counter()
    body_kw, model_kw = split_options(Rectangle, model_kw)
    m = FemModel(Rectangle(lx=lx, ly=ly, nx=nx, ny=ny, confining_pa=pressure, **body_kw),
                 elements=pool, **model_kw)
    rows, steps_done = [], []
    ev = 0.0
    t1 = time.perf_counter()
    failed = None
    for k in range(1, steps + 1):
        eps = strain * k / steps
        before = len(m.history)
        try:
            r = m.step(top_displacement=-eps * ly)
        except NewtonFailure as e:
            if not stop_on_failure:
                raise
            failed = {"axial_strain": eps, "reason": str(e)}
            if log is not None:
                log(f"[fem x dem] step {k}/{steps}: FAILED at axial strain {eps:.4f}: {e}; "
                    "the run ends here")
            break
        steps_done.append(r)
        for h in m.history[before:]:  # (a cut step adds its halves)
            ev -= float(np.mean(h.increments[:, 0, 0] + h.increments[:, 2, 2]))
        s = r.mean_stress
        rows.append((eps, -s[1], -s[0], ev, r.newton_iterations, r.residual, r.converged_on))
        if log is not None:
            done = time.perf_counter() - t1
            log(f"[fem x dem] step {k}/{steps}: axial strain {eps:.4f}, sigma_axial "
                f"{-s[1] / 1e3:.1f} kPa, sigma_lateral {-s[0] / 1e3:.1f} kPa, Newton "
                f"{r.newton_iterations} (residual {r.residual:.1e}, noise {r.noise_residual:.1e}, "
                f"on {r.converged_on}), DEM {r.dem_s:.1f} s, FEM {r.fem_s:.2f} s, wall "
                f"{r.wall_s:.1f} s, ETA {done / k * (steps - k):.0f} s")
    out = {"axial_strain": np.array([r[0] for r in rows]),
           "sigma_axial": np.array([r[1] for r in rows]),
           "sigma_lateral": np.array([r[2] for r in rows]),
           "volumetric_strain": np.array([r[3] for r in rows]),
           "iterations": [r[4] for r in rows], "residual": [r[5] for r in rows],
           "converged_on": [r[6] for r in rows], "steps": steps_done, "model": m,
           "wall_s": time.perf_counter() - t0, "failed": failed}
    return _peak(out)


def direct_biaxial(make: Callable[[int], object], seeds: Sequence[int], *, pressure: float,
                   strain: float, strain_per_step: float = 5e-7, points: int = 100,
                   log: Callable | None = print) -> list[dict]:
    """The direct DEM: for each k in ``seeds`` the element ``make(k)`` (a periodic
    ``DemElement``, e.g. a ``PeriodicFactory``: then element k of the FEM x DEM run alone)
    under ``cpp_dem.protocols.periodic.plane_strain_biaxial`` to the axial ``strain``. One result dict
    per seed (the module doc), with ``grains``, ``porosity_initial`` (-, before the shear)
    and ``wall_s``."""
    from cpp_dem.protocols import periodic

    out = []
    t1 = time.perf_counter()
    for i, k in enumerate(seeds):
        t0 = time.perf_counter()
        el = make(k)
        if getattr(el, "kind", None) != "periodic":
            raise ValueError(f"make({k}): a periodic DemElement expected, got {el!r}")
        el.controller.enabled = False
        from cpp_dem import measure

        phi0 = float(measure.porosity(el.scene, ()))
        r = periodic.plane_strain_biaxial(el.scene, pressure=pressure, strain=strain,
                                          strain_per_step=strain_per_step, points=points)
        res = _peak({"axial_strain": r["axial_strain"], "sigma_axial": r["sigma_z"],
                     "sigma_lateral": r["sigma_x"],
                     "volumetric_strain": r["volumetric_strain"]})
        res["grains"] = int(el.scene.num_bodies)
        res["porosity_initial"] = phi0  # before the shear, -
        res["wall_s"] = time.perf_counter() - t0
        out.append(res)
        if log is not None:
            done = time.perf_counter() - t1
            log(f"[direct] {i + 1}/{len(seeds)} (make({k}), {res['grains']} grains): peak "
                f"{res['peak_sigma_axial'] / 1e3:.1f} kPa at {res['peak_axial_strain']:.4f}, "
                f"ETA {done / (i + 1) * (len(seeds) - i - 1):.0f} s")
    return out


def at_strain(res: dict, strain: float) -> float:
    """The axial stress (Pa) of a result at an axial strain, linearly interpolated."""
    return float(np.interp(strain, res["axial_strain"], res["sigma_axial"]))


def rve_angles(res: dict) -> dict:
    """phi (peak friction angle, deg) and psi (dilatancy angle at the peak, deg) of one RVE's
    plane-strain biaxial (``direct_biaxial``'s dict, compression positive): sin phi =
    (s1 - s3)/(s1 + s3) at the peak; sin psi = -d eps_v / d gamma, gamma = eps_1 - eps_3 =
    2 eps_1 - eps_v, the slope over the records within 0.5 % axial strain of the peak."""
    s1, s3 = np.asarray(res["sigma_axial"]), np.asarray(res["sigma_lateral"])
    e1, ev = np.asarray(res["axial_strain"]), np.asarray(res["volumetric_strain"])
    k = int(np.argmax(s1))
    phi = math.degrees(math.asin((s1[k] - s3[k]) / (s1[k] + s3[k])))
    near = np.abs(e1 - e1[k]) <= 0.005
    gam = 2 * e1 - ev
    slope = fixedorder.line_slope(gam[near], ev[near]) if near.sum() >= 3 else float("nan")
    psi = math.degrees(math.asin(float(np.clip(-slope, -1, 1))))
    return {"phi_peak_deg": phi, "psi_deg": psi, "peak_axial_strain": float(e1[k])}


def summarise(results: Sequence[dict], keys=("peak_sigma_axial", "peak_axial_strain",
                                              "peak_volumetric_strain")) -> dict:
    """Mean, standard deviation (ddof 1; NaN for one result) and count of each key."""
    out = {}
    for key in keys:
        v = np.array([r[key] for r in results], float)
        out[key] = {"mean": float(v.mean()),
                    "std": float(v.std(ddof=1)) if len(v) > 1 else math.nan, "n": len(v)}
    return out
