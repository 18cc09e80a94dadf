"""A small strip footing by hierarchical FEM x DEM and by direct DEM of the same grains
(issue 38, item 2: "compare a small footing with a direct DEM of the same grains, where that
fits on this machine"; docs/studies/footing_direct_dem.md).

The body is plane strain, the half beside the footing's symmetry plane: ``length`` (x) by
``depth`` (z), a rigid smooth footing of half width ``footing_b`` on the top at x <= b, the
surcharge ``surcharge_pa`` on the rest of the top, smooth sides and bottom, no gravity. Both
models start from the isotropic stress q = ``surcharge_pa`` everywhere, and the footing is
pushed down to the same settlements; both relax to equilibrium at each (quasi-static).

- :func:`fem_dem_footing`: a ``femcoupling.fem.model.FemModel`` on a ``Rectangle`` with
  ``platens="footing"`` (nx by ny cells of triangles, a periodic element at each quadrature
  point: one per P1 triangle, three per P2), the footing's pressure from its reaction.
- The direct DEM is ``cpp_dem.protocols.footing`` (a box of the grains between smooth walls,
  the top wall split into the footing and the surcharge).
- :func:`element_factory`: the elements of "the same grains": the box's material, radii and
  preparation (grown frictionless, then at the grains' friction: dense), at q.

Pressures are **compression positive**, Pa; settlements m, downward positive.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

__all__ = ["fem_dem_footing", "element_factory", "paired_pressures"]

#: the columns of ``footing_fem_dem.csv`` (one row per settlement reached)
FEM_DEM_COLUMNS = ("settlement_m", "footing_pressure_pa", "status", "iterations", "wall_s")


def element_factory(box, *, grains: int, seed: int):
    """The periodic elements of the grains of a ``cpp_dem.protocols.footing.StripFootingBox``
    ``box``: ``grains`` spheres each, its material (linear law: E, k_s/k_n, friction,
    density), radii (grown from the box's cloud radius, ``box.cloud_radius_mean``, so that
    they end near ``box.radius_mean`` as the box's do), damping, preparation friction,
    tolerance and unbalanced force, at the isotropic stress q (servoed in all six
    components: the FEM's free surface takes no shear at the start); element k from packing
    seed ``seed + k``."""
    from cpp_dem import _core
    from cpp_dem.elements.pool import PeriodicFactory

    material = _core.Material(model="linear", density=box.density, young=box.young,
                              poisson=box.poisson, friction_angle_deg=box.friction_deg)
    return PeriodicFactory(n=grains, stress=box.surcharge_pa, seed=seed, isotropic=True,
                           options=dict(material=material, radius_mean=box.cloud_radius_mean,
                                        radius_spread=box.radius_spread,
                                        prep_friction_deg=box.prep_friction_deg,
                                        damping=box.damping, tol=box.tol,
                                        unbalanced=box.unbalanced))


def fem_dem_footing(pool, *, length: float, depth: float, nx: int, ny: int, footing_b: float,
                    surcharge_pa: float, settlements_m: Sequence[float],
                    log: Callable | None = print, out: Path | None = None,
                    overwrite: bool = False, **model_kw) -> dict:
    """The footing by hierarchical FEM x DEM: ``pool`` holds one element per quadrature
    point (2 nx ny, times 3 with ``degree=2`` in ``model_kw``; ``element_factory``),
    ``footing_b`` a multiple of ``length / nx``. The footing is
    pushed to each of ``settlements_m`` (m, increasing) in a load step (cut in halves where
    Newton fails: ``FemModel.step``; ``model_kw``: the ``Rectangle``'s ``degree``, the
    rest the ``FemModel``'s). Returns ``settlement_m`` and
    ``footing_pressure_pa`` (row 0: zero settlement, the start), ``status`` and
    ``iterations`` per settlement, ``failed`` (None, or the settlement and the reason of a
    step that failed after its cuts: the run ends there, its rows kept), ``model`` and
    ``wall_s``. With ``out``: ``footing_fem_dem.csv`` (a row per settlement, appended and
    flushed as each is reached) and the model's records in ``out/records``."""
    from cpp_dem.protocols.footing import check_settlements
    from femcoupling.fem.bodies import Rectangle
    from femcoupling.fem.model import FemModel, split_options
    from femcoupling.fem.steps import NewtonFailure

    s_targets = check_settlements(settlements_m, depth)
    t0 = time.perf_counter()
    records = None if out is None else Path(out) / "records"
    csv = None if out is None else Path(out) / "footing_fem_dem.csv"
    if csv is not None and csv.exists() and not overwrite:
        raise FileExistsError(f"{csv}: holds an earlier run; give a new folder, or "
                              "overwrite=True")
    body_kw, model_kw = split_options(Rectangle, model_kw)
    m = FemModel(Rectangle(lx=length, ly=depth, nx=nx, ny=ny, confining_pa=surcharge_pa,
                           platens="footing", footing_b=footing_b, **body_kw),
                 elements=pool, out=records, overwrite=overwrite, **model_kw)
    rows: list[tuple] = []
    if csv is not None:
        csv.parent.mkdir(parents=True, exist_ok=True)
        csv.write_text(",".join(FEM_DEM_COLUMNS) + "\n")

    def keep(row) -> None:
        rows.append(row)
        if csv is not None:
            with open(csv, "a") as fh:
                fh.write(",".join(repr(v) if isinstance(v, float) else str(v) for v in row)
                         + "\n")

    keep((0.0, m.footing_pressure_pa(), "start", 0, 0.0))
    failed = None
    t1 = time.perf_counter()
    for k, s in enumerate(s_targets, start=1):
        try:
            r = m.step(top_displacement=-float(s))
        except NewtonFailure as e:
            failed = {"settlement_m": float(s), "reason": str(e)}
            if log is not None:
                log(f"[fem x dem footing] settlement {s * 1e3:.3f} mm: FAILED ({e}); the run "
                    "ends here")
            break
        keep((float(s), m.footing_pressure_pa(), r.status, r.newton_iterations, r.wall_s))
        if log is not None:
            done = time.perf_counter() - t1
            log(f"[fem x dem footing] {k}/{len(s_targets)}: settlement {s * 1e3:.3f} mm, "
                f"footing {rows[-1][1] / 1e3:.1f} kPa, Newton {r.newton_iterations} ({r.status}), "
                f"wall {r.wall_s:.1f} s, ETA {done / k * (len(s_targets) - k):.0f} s")
    return {"settlement_m": np.array([r[0] for r in rows]),
            "footing_pressure_pa": np.array([r[1] for r in rows]),
            "status": [r[2] for r in rows], "iterations": [r[3] for r in rows],
            "failed": failed, "model": m, "wall_s": time.perf_counter() - t0}


def paired_pressures(fem_dem: Sequence[dict], dem: Sequence[dict]) -> dict:
    """The paired difference FEM x DEM - direct DEM of the footing pressure (Pa) at each
    settlement both reached, over the seeds (``fem_dem[i]`` and ``dem[i]`` share seed i):
    ``settlement_m``, the means of each, ``difference_pa`` (mean) and ``se_pa`` (its standard
    error; NaN with one seed) and ``seeds`` (how many reached that settlement in both)."""
    if len(fem_dem) != len(dem) or not fem_dem:
        raise ValueError(f"paired_pressures: {len(fem_dem)} FEM x DEM runs against "
                         f"{len(dem)} direct DEM runs: one of each per seed")
    n = min(min(len(a["footing_pressure_pa"]), len(b["footing_pressure_pa"]))
            for a, b in zip(fem_dem, dem))
    s0 = np.asarray(fem_dem[0]["settlement_m"][:n], float)
    for a, b in zip(fem_dem, dem):
        for run in (a, b):
            if not np.allclose(np.asarray(run["settlement_m"][:n], float), s0, rtol=0,
                               atol=1e-12):
                raise ValueError("paired_pressures: the runs' settlements differ: "
                                 "pair runs of the same settlements")
    fa = np.array([np.asarray(a["footing_pressure_pa"][:n], float) for a in fem_dem])
    db = np.array([np.asarray(b["footing_pressure_pa"][:n], float) for b in dem])
    d = fa - db
    k = len(d)
    se = d.std(axis=0, ddof=1) / np.sqrt(k) if k > 1 else np.full(n, np.nan)
    return {"settlement_m": s0, "fem_dem_pa": fa.mean(axis=0), "dem_pa": db.mean(axis=0),
            "difference_pa": d.mean(axis=0), "se_pa": se, "seeds": k}
