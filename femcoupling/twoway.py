"""One-way and two-way FEM <-> DEM coupling loops and the HDF5 handover history.

One way: :func:`one_way` solves the structure once and returns, per element region, the
FEM stress of the initial state (before the load stage) and after it, as
:class:`~femcoupling.handover.WallTargets` (compression positive).

Two way (:func:`two_way`): iterate

1. restore the initial state, solve the load stage, hand over each region's stresses;
2. run each region's DEM element from the initial targets to the new ones
   (``element_runner``, possibly in parallel processes);
3. the element's measured secant (E, nu) over the handed-over increment
   (:func:`femcoupling.handover.secant_stiffness`) becomes that region's material;

until the handed-over stresses change by less than ``tol`` (relative, max norm over the
regions) between two iterations, or ``max_iterations``.

``element_runner(name, initial, final) -> ElementResponse`` is any picklable callable (a
module-level function if ``workers > 1``). Under MPI it runs on rank 0 only and its results
are broadcast, so the FEM part stays collective.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import multiprocessing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from femcoupling.geometry import FemInputError
from femcoupling.handover import WallTargets, fem_to_dem, secant_stiffness

__all__ = ["ElementResponse", "HandoverHistory", "TwoWayResult", "one_way", "two_way"]


@dataclasses.dataclass(frozen=True)
class ElementResponse:
    """What a DEM element run reports back (compression positive).

    Attributes:
        stress_initial_pa: (3,) wall stresses reached at the initial targets, Pa.
        stress_final_pa: (3,) wall stresses reached at the final targets, Pa.
        strain_increment: (3,) normal strain increment from the initial to the final state
            along x, y, z, compression positive (shortening / initial length), -.
        info: anything else worth recording (numbers only).
    """

    stress_initial_pa: np.ndarray
    stress_final_pa: np.ndarray
    strain_increment: np.ndarray
    info: dict = dataclasses.field(default_factory=dict)


class HandoverHistory:
    """HDF5 record of the handover, one row per (iteration, region), appended and flushed.

    Datasets (all resizable along the first axis): ``iteration``, ``region`` (index into the
    ``regions`` attribute), ``fem_stress_pa`` (n, 3, 3, tension positive), ``targets_pa``
    (n, 3, compression positive), ``shear_pa`` (n, 3), ``rotation_deg``, ``change``
    (relative change of the handed-over stresses since the previous iteration),
    ``dem_stress_pa`` (n, 3, reached by the walls; NaN in one-way runs without DEM),
    ``secant_young_pa``, ``secant_poisson``. Written on rank 0 only.
    """

    FIELDS = {"iteration": (), "region": (), "fem_stress_pa": (3, 3), "targets_pa": (3,),
              "shear_pa": (3,), "rotation_deg": (), "change": (), "dem_stress_pa": (3,),
              "secant_young_pa": (), "secant_poisson": ()}

    def __init__(self, path: Any, *, regions: Sequence[str], metadata: dict | None = None,
                 rank: int = 0) -> None:
        self.path, self.rank, self.n = Path(path), rank, 0
        self._f = None
        if rank != 0:
            return
        import h5py

        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._f = h5py.File(self.path, "w")
        self._f.attrs["regions"] = list(regions)
        self._f.attrs["units"] = ("SI; fem_stress_pa tension positive; targets_pa, shear_pa, "
                                  "dem_stress_pa compression positive")
        for k, v in (metadata or {}).items():
            self._f.attrs[k] = v
        for name, shape in self.FIELDS.items():
            self._f.create_dataset(name, shape=(0, *shape), maxshape=(None, *shape),
                                   dtype="f8", chunks=(16, *shape))
        self._f.flush()

    def append(self, **row: Any) -> None:
        """Append one row (missing fields are NaN) and flush."""
        if self._f is None:
            return
        for name, shape in self.FIELDS.items():
            d = self._f[name]
            d.resize(self.n + 1, axis=0)
            d[self.n] = np.broadcast_to(np.asarray(row.get(name, np.nan), float), shape)
        self.n += 1
        self._f.flush()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def __enter__(self) -> "HandoverHistory":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


@dataclasses.dataclass
class TwoWayResult:
    """Outcome of :func:`two_way`.

    Attributes:
        converged: the handed-over stresses changed by less than ``tol``.
        iterations: number of FEM solves of the load stage.
        changes: relative change after each iteration (the first is inf).
        targets: final WallTargets per region.
        initial_targets: WallTargets of the initial state per region.
        responses: last ElementResponse per region.
        materials: last (E / Pa, nu) per region.
    """

    converged: bool
    iterations: int
    changes: list
    targets: dict
    initial_targets: dict
    responses: dict
    materials: dict


def one_way(model: Any, *, regions: Sequence[str], load: Callable[[Any], Any]
            ) -> tuple[dict, dict]:
    """Initial and final WallTargets per region: the model's current state, then ``load(model)``.

    Returns ``(initial, final)`` dicts keyed by region name.
    """
    initial = {r: fem_to_dem(model.region_stress(r)) for r in regions}
    load(model)
    final = {r: fem_to_dem(model.region_stress(r)) for r in regions}
    return initial, final


def _run_elements(runner: Callable, jobs: list, workers: int) -> list:
    if workers <= 1 or len(jobs) <= 1:
        return [runner(*job) for job in jobs]
    ctx = multiprocessing.get_context("spawn")  # no fork of an MPI/PETSc process
    with concurrent.futures.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        return list(ex.map(runner, *zip(*jobs)))


def two_way(model: Any, *, regions: Sequence[str], load: Callable[[Any], Any],
            element_runner: Callable[[str, WallTargets, WallTargets], ElementResponse],
            tol: float = 0.02, max_iterations: int = 6, workers: int = 1,
            history: HandoverHistory | None = None,
            log: Callable[[str], None] | None = None) -> TwoWayResult:
    """The two-way loop (module doc). ``model`` is a SoilModel in its initial state.

    Args:
        model: :class:`femcoupling.elastoplastic.SoilModel` after its initial stages.
        regions: element region names coupled.
        load: ``load(model)`` applies the load stage from the initial state.
        element_runner: runs one DEM element (see module doc).
        tol: relative change of the handed-over stresses that ends the loop, -, > 0.
        max_iterations: FEM solves at most, >= 2.
        workers: parallel processes for the DEM elements (1: in this process).
        history: HDF5 record, appended per iteration.
        log: progress line sink (rank 0).
    """
    if not tol > 0:
        raise FemInputError(f"tol={tol!r}: must be > 0")
    if not (isinstance(max_iterations, int) and max_iterations >= 2):
        raise FemInputError(f"max_iterations={max_iterations!r}: must be an integer >= 2")
    if not (isinstance(workers, int) and workers >= 1):
        raise FemInputError(f"workers={workers!r}: must be an integer >= 1")
    regions = list(regions)
    comm = model.comm
    rank0 = comm.rank == 0
    say = (log if (log is not None and rank0) else (lambda msg: None))
    state0 = model.save_state()
    initial = {r: fem_to_dem(model.region_stress(r)) for r in regions}
    prev: dict | None = None
    changes: list = []
    responses: dict = {}
    materials: dict = {}
    final: dict = {}
    converged = False
    for it in range(1, max_iterations + 1):
        model.restore_state(state0)
        load(model)
        final = {r: fem_to_dem(model.region_stress(r)) for r in regions}
        if prev is None:
            change = float("inf")
        else:
            change = max(float(np.abs(final[r].fem_stress_pa - prev[r].fem_stress_pa).max()
                               / np.abs(prev[r].fem_stress_pa).max()) for r in regions)
        changes.append(change)
        for r in regions:
            say(f"iteration {it}, region {r}: {final[r].report()}; change {change:.3g}")
        if change < tol:
            converged = True
            for j, r in enumerate(regions):
                if history is not None:
                    history.append(iteration=it, region=j, fem_stress_pa=final[r].fem_stress_pa,
                                   targets_pa=final[r].normal_pa, shear_pa=final[r].shear_pa,
                                   rotation_deg=final[r].rotation_deg, change=change)
            break
        jobs = [(r, initial[r], final[r]) for r in regions]
        out = _run_elements(element_runner, jobs, workers) if rank0 else None
        out = comm.bcast(out, root=0)
        for j, (r, resp) in enumerate(zip(regions, out)):
            responses[r] = resp
            dsig = np.asarray(resp.stress_final_pa) - np.asarray(resp.stress_initial_pa)
            E, nu = secant_stiffness(stress_increment_pa=dsig,
                                     strain_increment=resp.strain_increment)
            materials[r] = (E, nu)
            from femcoupling.materials import LinearElastic

            model.set_region_material(r, LinearElastic(E, nu))
            say(f"iteration {it}, region {r}: DEM walls reached "
                f"{np.round(np.asarray(resp.stress_final_pa) / 1e3, 2).tolist()} kPa; secant "
                f"E = {E / 1e6:.3g} MPa, nu = {nu:.3f}")
            if history is not None:
                history.append(iteration=it, region=j, fem_stress_pa=final[r].fem_stress_pa,
                               targets_pa=final[r].normal_pa, shear_pa=final[r].shear_pa,
                               rotation_deg=final[r].rotation_deg, change=change,
                               dem_stress_pa=resp.stress_final_pa, secant_young_pa=E,
                               secant_poisson=nu)
        prev = final
    return TwoWayResult(converged=converged, iterations=len(changes), changes=changes,
                        targets=final, initial_targets=initial, responses=responses,
                        materials=materials)
