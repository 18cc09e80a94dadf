"""One-way and two-way FEM <-> DEM coupling loops and the HDF5 handover history.

One way: :func:`one_way` solves the structure once and returns, per element region, the
FEM stress of the initial state (before the load stage) and after it, as
:class:`~femcoupling.coupling.handover.WallTargets` (compression positive).

Two way (:func:`two_way`): iterate

1. restore the initial state, solve the load stage, hand over each region's stresses and
   the tension of a geogrid layer that crosses it (:func:`region_targets`; the runner may
   pull its element's grid ends by it, as the case's element does);
2. run each region's DEM element from the initial targets to the new ones
   (``element_runner``; with ``workers`` > 1 or ``client=`` on Dask workers: each region an
   element of the one pool, ``cpp_dem.elements.pool.ElementPool.runners``, kept on its worker
   for the whole loop, saved there after every iteration, given to workers that join late
   and recovered after a lost worker: ``cpp_dem.elements.interface``);
3. the element's stiffness over the handed-over increment becomes that region's material:
   with ``stiffness="tangent"`` (the default) and an element that returns its tangent
   (``info["tangent_voigt_pa"]`` with the full strain and stress increment tensors: a
   periodic element's network tangent, the case's wall-bounded element's tangent by stress
   probes), the tangent made to reproduce the increment exactly
   (:func:`femcoupling.coupling.handover.secant_tangent`, a BFGS update) as an
   :class:`~femcoupling.materials.continuum.AnisotropicElastic`; otherwise (an element that returns
   none, or ``stiffness="isotropic"``) the isotropic secant (E, nu)
   (:func:`femcoupling.coupling.handover.secant_stiffness`), a least-squares fit of the three normal
   increments;

until the handed-over stresses change by less than ``tol`` (relative, max norm over the
regions) between two iterations, or ``max_iterations``. Noise-aware: an element that reports
its stress scatter (``info["stress_scatter_pa"]``, the bootstrap of its contacts:
``cpp_dem.measure.stress_scatter``) sets a floor; a change within ``scatter_factor`` times
the relative scatter ends the loop too, and says that ``tol`` was below it. The secant is
relaxed between iterations (Aitken's factor by default, on (log E, nu) or on the stiffness
matrix), which damps the 2-cycles a noisy element drives.

The loop ends in one status per region and the worst of them for the loop
(:mod:`femcoupling.coupling.status`; ``TwoWayResult.status``, ``.regions``):
``converged`` (the change within ``tol``, the principal axes within ``max_rotation_deg`` of
a walled element's walls, the element straining within [1 / ``max_strain_ratio``,
``max_strain_ratio``] times its region), ``stopped_at_scatter`` (every check held but the
change was only within the elements' scatter: the loop's map is deterministic, so that is
not convergence), ``stalled`` (the change settled, but the axes or the strains failed their
check: an element at its strength, a stiffness that cannot represent it, walls that miss
the shear; iterating on does not help, so the loop stops and says so) or ``failed`` (no
settling in ``max_iterations``).

Every iteration checks what a wall-bounded element can represent (``RegionWarning``, in the
log, the history and ``TwoWayResult.warnings``): principal axes of the FEM stress turned more
than ``max_rotation_deg`` from the walls, and an element that strains more than
``max_strain_ratio`` times its FEM region, or less than its inverse.

``element_runner(name, initial, final) -> ElementResponse`` is any callable (picklable, its
class or function importable on the workers, if ``workers > 1``). Under MPI it runs on rank 0
only and its results are broadcast, so the FEM part stays collective.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from femcoupling._checks import FemInputError
from femcoupling.coupling._inputs import check_client, check_names, check_positive
from femcoupling.coupling.handover import (HandoverError, WallTargets, fem_to_dem, secant_stiffness,
                                           secant_tangent)
from femcoupling.coupling.relaxation import check_relaxation, next_factor
from femcoupling.coupling.status import (CouplingStatus, check_limits, judge_region,
                                         strain_ratio_held, worst)
from femcoupling.fem.mpi_points import bcast_from_root
from femcoupling.materials.continuum import (AnisotropicElastic, LinearElastic, tensor_to_mandel,
                                             voigt_to_mandel_stiffness)

__all__ = ["ElementResponse", "HandoverHistory", "RegionWarning", "STIFFNESS_MODES",
           "TwoWayResult", "check_region", "element_stiffness", "one_way", "region_targets",
           "two_way"]


class RegionWarning(UserWarning):
    """A wall-bounded DEM element misrepresents its FEM region (turned principal axes, a
    strain far from the region's), or the two-way loop stopped at the elements' scatter."""


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
    ``secant_young_pa``, ``secant_poisson`` (the relaxed secant given to the region),
    ``fem_strain_increment`` and ``dem_strain_increment`` (n, 3, normal, compression
    positive), ``strain_ratio`` (DEM / FEM, largest components), ``scatter`` (the element's
    relative stress scatter), ``relaxation`` (the factor applied) and
    ``stiffness_mandel_pa`` (n, 6, 6: the full stiffness given to the region from the
    element's tangent; NaN where the region got the isotropic secant, whose isotropic
    projection the secant fields hold otherwise) and ``grid_tension_n_per_m`` (the tension of
    the geogrid layer crossing the region, handed to the element's grid ends; NaN where none
    does). Written on rank 0 only.
    """

    FIELDS = {"iteration": (), "region": (), "fem_stress_pa": (3, 3), "targets_pa": (3,),
              "shear_pa": (3,), "rotation_deg": (), "change": (), "dem_stress_pa": (3,),
              "secant_young_pa": (), "secant_poisson": (), "fem_strain_increment": (3,),
              "dem_strain_increment": (3,), "strain_ratio": (), "scatter": (),
              "relaxation": (), "stiffness_mandel_pa": (6, 6), "grid_tension_n_per_m": ()}

    def __init__(self, path: Any, *, regions: Sequence[str], metadata: dict | None = None,
                 rank: int = 0) -> None:
        self.path, self.rank, self.n = Path(path), rank, 0
        self.regions = list(regions)
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
        """Append one row (missing fields, and None, are NaN) and flush."""
        if self._f is None:
            return
        for name, shape in self.FIELDS.items():
            d = self._f[name]
            d.resize(self.n + 1, axis=0)
            d[self.n] = np.broadcast_to(np.asarray(row.get(name, np.nan), float), shape)
        self.n += 1
        self._f.flush()

    def append_file(self, path: Any) -> None:
        """Append every row of another history file (same fields; its region indices are
        kept, so it must list the same ``regions``) and flush: the record of a part of a run
        made in another process. A file of other attributes (``regions``, ``metadata``,
        units) is refused, naming them: it is the record of another run."""
        if self._f is None:
            return
        import h5py

        with h5py.File(path, "r") as src:
            if list(src.attrs["regions"]) != self.regions:
                raise FemInputError(f"path={str(path)!r}: its regions "
                                    f"{list(src.attrs['regions'])} are not {self.regions}")
            differ = [k for k in sorted(set(src.attrs) | set(self._f.attrs))
                      if not _same_attr(src.attrs.get(k), self._f.attrs.get(k))]
            if differ:
                raise FemInputError(
                    f"path={str(path)!r}: the record of a run with other metadata ("
                    + "; ".join(f"{k}: {_attr_text(src.attrs.get(k))} there, "
                                f"{_attr_text(self._f.attrs.get(k))} here" for k in differ)
                    + f"); only the parts of one run, written with the same metadata, are "
                    f"merged into {str(self.path)!r}")
            n = src["iteration"].shape[0]
            for name in self.FIELDS:
                d = self._f[name]
                d.resize(self.n + n, axis=0)
                d[self.n:] = src[name][:]
        self.n += n
        self._f.flush()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def __enter__(self) -> "HandoverHistory":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _same_attr(a: Any, b: Any) -> bool:
    """Two HDF5 attribute values (None: absent) are equal: the same shape and every element
    equal (NaN equal to NaN)."""
    if a is None or b is None:
        return a is b
    try:
        return bool(np.array_equal(a, b, equal_nan=True))
    except TypeError:  # (not numbers: strings)
        return bool(np.array_equal(a, b))


def _attr_text(v: Any) -> str:
    """An HDF5 attribute value for a message (absent: "none")."""
    if v is None:
        return "none"
    v = np.asarray(v)
    return repr(v.item() if v.ndim == 0 else v.tolist())


@dataclasses.dataclass
class TwoWayResult:
    """Outcome of :func:`two_way`.

    Attributes:
        status: how the loop ended, the worst of its regions' (:mod:`femcoupling.coupling.status`):
            "converged", "stopped_at_scatter", "stalled" or "failed".
        reason: one line per region that is not converged ("region: reason"), or that every
            check held.
        regions: per region its :class:`~femcoupling.coupling.status.CouplingStatus` (status,
            reason, final_change, tol, axes_rotation_deg, dem_fem_strain_ratio, checks).
        iterations: number of FEM solves of the load stage.
        changes: relative change after each iteration (the first is inf; max over regions).
        targets: final WallTargets per region.
        initial_targets: WallTargets of the initial state per region.
        responses: last ElementResponse per region.
        materials: last (E / Pa, nu) per region (relaxed; of the isotropic projection where
            the region got a full stiffness).
        stiffnesses: per region the last full stiffness given (6 x 6 Mandel, Pa), or None
            where the region got the isotropic secant.
        warnings: every RegionWarning message, in order.
        fem_strain_increments: per region its normal strain increment (3,) over the load
            stage in the last FEM solve, compression positive (None if the model has no
            ``region_strain``).
        tol: the tolerance the loop was given, -.
    """

    status: str
    iterations: int
    changes: list
    targets: dict
    initial_targets: dict
    responses: dict
    materials: dict
    warnings: list = dataclasses.field(default_factory=list)
    fem_strain_increments: dict = dataclasses.field(default_factory=dict)
    stiffnesses: dict = dataclasses.field(default_factory=dict)
    regions: dict = dataclasses.field(default_factory=dict)
    reason: str = ""
    tol: float = math.nan

    @property
    def converged(self) -> bool:
        """``status == "converged"`` (every check held)."""
        return self.status == "converged"

    @property
    def converged_on(self) -> str:
        """The older name of what ended the loop: "tol" (converged), "scatter"
        (stopped_at_scatter), "stalled" or "max_iterations" (failed). Read ``status``."""
        return {"converged": "tol", "stopped_at_scatter": "scatter", "stalled": "stalled",
                "failed": "max_iterations"}[self.status]

    @property
    def final_change(self) -> float:
        """The last relative change of the handed-over stresses (max over regions), -."""
        return float(self.changes[-1]) if self.changes else math.inf


STIFFNESS_MODES = ("tangent", "isotropic")


def element_stiffness(resp: ElementResponse, mode: str = "tangent"
                      ) -> tuple[float, float, np.ndarray | None]:
    """The stiffness of one element answer over its increment: (E / Pa, nu, C) with C the
    element's tangent made to reproduce the increment (6 x 6 Mandel, Pa) when ``mode`` is
    "tangent" and the answer carries the tangent and the full increment tensors, else C =
    None and (E, nu) the isotropic secant of the normal increments."""
    info = resp.info or {}
    t = info.get("tangent_voigt_pa")
    if mode == "tangent" and t is not None:
        de = tensor_to_mandel(np.asarray(info["strain_increment_tensor"], float), 6)
        ds = tensor_to_mandel(np.asarray(info["stress_increment_tensor"], float), 6)
        c = secant_tangent(voigt_to_mandel_stiffness(t), strain_increment=de,
                           stress_increment_pa=ds)
        mat = AnisotropicElastic(c)  # (refuses a C that is not positive definite)
        return mat.young_pa, mat.poisson, np.array(mat.c_mandel_pa)
    dsig = np.asarray(resp.stress_final_pa) - np.asarray(resp.stress_initial_pa)
    E, nu = secant_stiffness(stress_increment_pa=dsig, strain_increment=resp.strain_increment)
    return E, nu, None


def check_region(name: str, targets: WallTargets, *, fem_strain_increment=None,
                 dem_strain_increment=None, max_rotation_deg: float = 15.0,
                 max_strain_ratio: float = 2.0, full_tensor: bool = False
                 ) -> tuple[list, float]:
    """What a wall-bounded element cannot represent of its FEM region: the principal axes
    of the handed-over stress turned more than ``max_rotation_deg`` from the walls (not
    checked for an element that takes the ``full_tensor``), and the element's normal strain
    increment (3,) outside [1 / ``max_strain_ratio``, ``max_strain_ratio``] times its
    region's (both compression positive; largest components compared). Returns the messages
    and the strain ratio (NaN without both strains)."""
    msgs = []
    if not full_tensor and targets.rotation_deg > max_rotation_deg:
        msgs.append(f"region {name}: the FEM stress's principal axes are turned "
                    f"{targets.rotation_deg:.1f} deg from the element's walls (> "
                    f"{max_rotation_deg:g}): the walls impose the normal stresses on the wrong "
                    f"planes and miss the shear {np.round(targets.shear_pa / 1e3, 2).tolist()} "
                    f"kPa; a periodic element takes the full tensor")
    ratio = math.nan
    if fem_strain_increment is not None and dem_strain_increment is not None:
        fe = float(np.abs(np.asarray(fem_strain_increment, float)).max())
        de = float(np.abs(np.asarray(dem_strain_increment, float)).max())
        ratio = de / fe if fe > 0 else math.inf
        if not strain_ratio_held(ratio, max_strain_ratio):
            side = (f"> {max_strain_ratio:g}" if ratio > max_strain_ratio
                    else f"< 1/{max_strain_ratio:g}")
            msgs.append(f"region {name}: the DEM element strains {ratio:.3g} times its FEM "
                        f"region ({side}; DEM "
                        f"{np.round(dem_strain_increment, 6).tolist()}, FEM "
                        f"{np.round(fem_strain_increment, 6).tolist()}, compression +): the "
                        f"two scales do not describe the same soil")
    return msgs, ratio


def _full(resp: ElementResponse | None) -> bool:
    """The element took the full stress tensor (a periodic element), not three walls."""
    return bool(resp is not None and resp.info and resp.info.get("full_tensor"))


def _normal_strain(model: Any, region: str) -> np.ndarray | None:
    """The region's normal strains (3,), compression positive, if the model can say."""
    f = getattr(model, "region_strain", None)
    return None if f is None else -np.diag(np.asarray(f(region), float))


def region_targets(model: Any, region: str) -> WallTargets:
    """The WallTargets of ``region``: its soil cells' stress (:func:`fem_to_dem`) and, where a
    geogrid layer crosses it and the model can say (``region_layer_force``), the layer's
    tension (``grid_tension_n_per_m``, for the element's grid ends)."""
    t = fem_to_dem(model.region_stress(region))
    f = getattr(model, "region_layer_force", None)
    g = None if f is None else f(region)
    return t if g is None else dataclasses.replace(t, grid_tension_n_per_m=float(g))


def one_way(model: Any, *, regions: Sequence[str], load: Callable[[Any], Any]
            ) -> tuple[dict, dict]:
    """Initial and final WallTargets per region: the model's current state, then ``load(model)``.

    Returns ``(initial, final)`` dicts keyed by region name.
    """
    initial = {r: region_targets(model, r) for r in regions}
    load(model)
    final = {r: region_targets(model, r) for r in regions}
    return initial, final


def two_way(model: Any, *, regions: Sequence[str], load: Callable[[Any], Any],
            element_runner: Callable[[str, WallTargets, WallTargets], ElementResponse],
            tol: float = 0.02, max_iterations: int = 6, workers: int = 1,
            history: HandoverHistory | None = None,
            log: Callable[[str], None] | None = None, relaxation: str | float = "aitken",
            scatter_factor: float = 1.0, max_rotation_deg: float = 15.0,
            max_strain_ratio: float = 2.0,
            history_names: Sequence[str] | None = None,
            stiffness: str = "tangent", client: Any = None) -> TwoWayResult:
    """The two-way loop (module doc). ``model`` is a FemModel of the soil body in its initial state.

    Args:
        model: :class:`femcoupling.fem.model.FemModel` after its initial stages.
        regions: element region names coupled: a non-empty list of distinct strings.
        load: ``load(model)`` applies the load stage from the initial state.
        element_runner: runs one DEM element (see module doc).
        tol: relative change of the handed-over stresses that ends the loop, -, finite
            and > 0.
        max_iterations: FEM solves at most, >= 2.
        workers: Dask worker processes for the DEM elements (1: in this process; > 1 with
            several regions: a LocalCluster, each region's runner an element of
            ``cpp_dem.elements.pool.ElementPool.runners``, kept on one worker for the whole
            loop).
        client: a ``dask.distributed.Client`` of a running cluster to use instead (the
            regions' runners are kept on its workers; ``workers`` is then ignored).
        history: HDF5 record, appended per iteration.
        log: progress line sink (rank 0).
        relaxation: "aitken" (Aitken's factor on the secant (E, nu) between iterations),
            "none", or a fixed factor in (0, 1].
        scatter_factor: the loop also ends when the change is within this many times the
            elements' relative stress scatter (when they report it), > 0.
        max_rotation_deg, max_strain_ratio: the limits of :func:`check_region` (and of the
            status: :func:`femcoupling.coupling.status.judge_region`), deg and -, > 0 and > 1.
        history_names: the names the regions have in ``history`` (default: ``regions``),
            one per region, each listed in ``history.regions``.

    Every argument is checked before the first FEM solve (FemInputError naming the field).
        stiffness: "tangent" (the element's tangent, made to reproduce its increment, where
            the element returns one; else the isotropic secant) or "isotropic" (always the
            isotropic secant of the normal increments).
    """
    # Every argument is checked here, before the first FEM solve.
    regions = check_names("regions", regions, what="element regions")
    check_positive("tol", tol, " (the relative change of the handed-over stresses that ends "
                   "the loop)")
    if isinstance(max_iterations, bool) or not (isinstance(max_iterations, int)
                                                and max_iterations >= 2):
        raise FemInputError(f"max_iterations={max_iterations!r}: must be an integer >= 2")
    if isinstance(workers, bool) or not (isinstance(workers, int) and workers >= 1):
        raise FemInputError(f"workers={workers!r}: must be an integer >= 1")
    check_client(client)
    if isinstance(relaxation, bool):
        raise FemInputError(f"relaxation={relaxation!r}: 'aitken' (Aitken's dynamic factor "
                            "on the corrections), 'none', or a fixed factor in (0, 1]")
    check_relaxation(relaxation)
    if stiffness not in STIFFNESS_MODES:
        raise FemInputError(f"stiffness={stiffness!r}: must be one of {STIFFNESS_MODES}")
    check_positive("scatter_factor", scatter_factor, " (a change within this many times the "
                   "elements' relative scatter ends the loop)")
    check_limits(max_rotation_deg, max_strain_ratio)
    for name, f in (("load", load), ("element_runner", element_runner)):
        if not callable(f):
            raise FemInputError(f"{name}={f!r:.120}: must be callable")
    if log is not None and not callable(log):
        raise FemInputError(f"log={log!r:.120}: must be callable (a progress line sink), "
                            "or None")
    names = (check_names("history_names", history_names, what="regions' history names")
             if history_names is not None else regions)
    if len(names) != len(regions):
        raise FemInputError(f"history_names={names!r}: one per region {regions!r}")
    if history is not None:
        missing = [n for n in names if n not in history.regions]
        if missing:
            field = "history_names" if history_names is not None else "regions"
            raise FemInputError(
                f"{field}={names!r}: {missing} not among the history's regions "
                f"{list(history.regions)} (HandoverHistory(regions=)); name each region as "
                "the history lists it (history_names=), or list it there")
    hrow = {r: (history.regions.index(n) if history is not None else j)
            for j, (r, n) in enumerate(zip(regions, names))}
    comm = model.comm
    rank0 = comm.rank == 0
    say = (log if (log is not None and rank0) else (lambda msg: None))
    state0 = model.save_state()
    initial = {r: region_targets(model, r) for r in regions}
    strain0 = {r: _normal_strain(model, r) for r in regions}
    prev: dict | None = None
    changes: list = []
    responses: dict = {}
    materials: dict = {}
    stiffnesses: dict = {}
    final: dict = {}
    fem_de: dict = {}
    warned: list = []
    statuses: dict = {}  # per region its CouplingStatus, once the loop has ended
    rchange = {r: math.inf for r in regions}  # per region its last change
    scatter = 0.0  # the elements' largest relative stress scatter, last iteration
    # relaxation of the secant: per region the (E, nu) given and the last full update
    omega = {r: 1.0 for r in regions}
    last_step: dict = {}

    def warn(msg: str) -> None:
        import warnings

        warned.append(msg)
        say("WARNING: " + msg)
        if rank0:
            warnings.warn(msg, RegionWarning, stacklevel=3)

    def check(r: str) -> tuple[list, float]:
        """check_region of region r: this iteration's FEM state, its last element answer."""
        resp = responses.get(r)
        return check_region(r, final[r], fem_strain_increment=fem_de[r],
                            dem_strain_increment=None if resp is None else resp.strain_increment,
                            max_rotation_deg=max_rotation_deg,
                            max_strain_ratio=max_strain_ratio, full_tensor=_full(resp))

    def judge(r: str, settled: bool, ratio: float) -> CouplingStatus:
        """Region r's status (femcoupling.coupling.status.judge_region) at the loop's end."""
        return judge_region(settled=settled, final_change=rchange[r], tol=tol,
                            walled=not _full(responses.get(r)),
                            axes_rotation_deg=final[r].rotation_deg,
                            dem_fem_strain_ratio=ratio, scatter=scatter_factor * scatter,
                            max_rotation_deg=max_rotation_deg,
                            max_strain_ratio=max_strain_ratio, iterations=len(changes))

    def record(r: str, **row) -> None:
        """A history row of region r: the FEM side of this iteration and ``row``."""
        if history is not None:
            history.append(iteration=it, region=hrow[r], fem_stress_pa=final[r].fem_stress_pa,
                           targets_pa=final[r].normal_pa, shear_pa=final[r].shear_pa,
                           rotation_deg=final[r].rotation_deg, change=change,
                           grid_tension_n_per_m=final[r].grid_tension_n_per_m,
                           fem_strain_increment=(np.nan if fem_de[r] is None else fem_de[r]),
                           **row)

    pool = None  # the regions' runners as elements of the Dask pool, kept for the whole loop

    def run_elements(jobs: list) -> list:
        nonlocal pool
        if client is None and (workers <= 1 or len(jobs) <= 1):
            return [element_runner(*job) for job in jobs]
        if pool is None:
            from cpp_dem.elements.pool import ElementPool

            pool = ElementPool.runners(element_runner, list(regions), workers=workers,
                                       client=client, log=say)
            say(f"two-way: the regions' DEM elements on Dask workers {pool.workers()}, each "
                "kept on its worker between iterations")
        calls: list = [None] * len(regions)
        for name, ini, fin in jobs:
            calls[list(regions).index(name)] = (ini, fin)
        out = pool.run(calls)
        # Every iteration ends at a boundary: its state saved on the workers (a lost worker's
        # regions restart from it), and workers that joined meanwhile get regions next time.
        pool.accept()
        return [out[list(regions).index(name)] for name, _, _ in jobs]

    try:
        for it in range(1, max_iterations + 1):
            model.restore_state(state0)
            load(model)
            final = {r: region_targets(model, r) for r in regions}
            for r in regions:
                s1 = _normal_strain(model, r)
                fem_de[r] = None if s1 is None else s1 - strain0[r]
            if prev is None:
                change = float("inf")
            else:
                rchange = {r: float(np.abs(final[r].fem_stress_pa - prev[r].fem_stress_pa).max()
                                    / np.abs(prev[r].fem_stress_pa).max()) for r in regions}
                change = max(rchange.values())
            changes.append(change)
            for r in regions:
                say(f"iteration {it}, region {r}: {final[r].report()}; change {change:.3g}")
            stop, on = change < tol, "tol"
            if not stop and change < scatter_factor * scatter:
                stop, on = True, "scatter"
            if stop:
                # The stresses have settled; the coupled state must hold too: the strains met
                # (an element that strains far more than its region was not given a stiffness
                # that reproduces it: an element at its strength answering within its scatter, a
                # secant that cannot represent it) and a walled element's axes within the walls'
                # limit. Otherwise the loop has stalled, not converged. More iterations do not
                # help (measured: the periodic smoke element then jumps by 29 %), so it stops
                # and says so. A change within the scatter but above tol is not convergence
                # either: the loop's map is deterministic.
                checks = {r: check(r) for r in regions}
                statuses = {r: judge(r, True, checks[r][1]) for r in regions}
                within = "tol" if change < tol else "the elements' scatter"
                bad = {r: st for r, st in statuses.items() if st.status == "stalled"}
                if bad:
                    warn(f"iteration {it}: the change {change:.3g} is within {within}, but "
                         + "; ".join(f"region {r}: {'; '.join(st.failures)}"
                                     for r, st in bad.items())
                         + ": stopped, NOT converged (stalled)")
                if on == "scatter":
                    warn(f"two-way: the change {change:.3g} is within the elements' stress "
                         f"scatter ({scatter:.3g} relative, the bootstrap of their contacts) but "
                         f"above tol={tol:g}: the tolerance asked is below what the elements "
                         f"resolve; stopped at the scatter")
                for r in regions:
                    msgs, ratio = checks[r]
                    for msg in msgs:
                        warn(f"iteration {it} ({statuses[r].status}): {msg}")
                    record(r, strain_ratio=ratio)
                break
            jobs = [(r, initial[r], final[r]) for r in regions]
            out = run_elements(jobs) if rank0 else None
            out = bcast_from_root(comm, out)
            scatter = 0.0
            for r, resp in zip(regions, out):
                responses[r] = resp
                if resp.info and resp.info.get("message"):
                    warn(f"iteration {it}: {resp.info['message']}")
                try:
                    E_full, nu_full, c_full = element_stiffness(resp, stiffness)
                except (HandoverError, FemInputError) as exc:
                    warn(f"iteration {it}, region {r}: the element's tangent gives no stiffness "
                         f"({exc}); the region takes the isotropic secant")
                    E_full, nu_full, c_full = element_stiffness(resp, "isotropic")
                sc = resp.info.get("stress_scatter_pa") if resp.info else None
                rel = (float(np.abs(np.asarray(sc, float)).max()
                             / np.abs(np.asarray(resp.stress_final_pa, float)).max())
                       if sc is not None else 0.0)
                scatter = max(scatter, rel)
                # relax: x = (log E, nu), or the stiffness matrix; x_new = x + w (x_full - x)
                c_prev = stiffnesses.get(r)
                if r in materials and (c_full is None) == (c_prev is None):
                    if c_full is None:
                        x = np.array([math.log(materials[r][0]), materials[r][1]])
                        step = np.array([math.log(E_full), nu_full]) - x
                    else:
                        x, step = c_prev.ravel(), (c_full - c_prev).ravel()
                    omega[r] = next_factor(relaxation, omega[r], last_step.get(r), step)
                    last_step[r] = step
                    xe = x + omega[r] * step
                    E, nu, c = ((math.exp(xe[0]), float(xe[1]), None) if c_full is None
                                else (math.nan, math.nan, xe.reshape(6, 6)))
                else:  # the first element answer (of its kind) is taken whole
                    last_step.pop(r, None)
                    E, nu, c = E_full, nu_full, c_full
                stiffnesses[r] = c
                if c is None:
                    mat = LinearElastic(E, nu)
                else:  # (a convex combination of two positive definite matrices is one)
                    mat = AnisotropicElastic(c)
                    E, nu = mat.young_pa, mat.poisson
                materials[r] = (E, nu)
                model.set_region_material(r, mat)
                msgs, ratio = check(r)
                if it == 1:  # (later iterations: checked again at the end)
                    for msg in msgs:
                        warn(f"iteration {it}: {msg}")
                kind = "tangent (isotropic part: " if c_full is not None else "secant ("
                say(f"iteration {it}, region {r}: DEM reached "
                    f"{np.round(np.asarray(resp.stress_final_pa) / 1e3, 2).tolist()} kPa; {kind}"
                    f"E = {E_full / 1e6:.3g} MPa, nu = {nu_full:.3f}); given "
                    f"E = {E / 1e6:.3g} MPa, nu = {nu:.3f} (relaxation {omega[r]:.3g}); "
                    f"DEM/FEM strain {ratio:.3g}"
                    + (f"; scatter {rel:.3g}" if sc is not None else ""))
                record(r, dem_stress_pa=resp.stress_final_pa, secant_young_pa=E,
                       secant_poisson=nu, dem_strain_increment=resp.strain_increment,
                       strain_ratio=ratio, scatter=rel if sc is not None else np.nan,
                       relaxation=omega[r] if r in last_step else 1.0,
                       stiffness_mandel_pa=(np.nan if stiffnesses[r] is None
                                            else stiffnesses[r]))
            prev = final
    finally:
        if pool is not None:
            pool.close()
    if not statuses:  # (no settling in max_iterations)
        for r in regions:
            msgs, ratio = check(r)
            statuses[r] = judge(r, False, ratio)
            for msg in msgs:
                warn(f"not converged after {len(changes)} FEM solves: {msg}")
    status = worst(st.status for st in statuses.values())
    for r in regions:
        say(f"two-way, region {statuses[r].line(r)}")
    reason = ("; ".join(f"region {r}: {st.reason}" for r, st in statuses.items()
                        if st.status != "converged")
              or f"every check held in every region after {len(changes)} FEM solves")
    say(f"two-way: {status} after {len(changes)} FEM solves"
        + ("" if status == "converged" else " (NOT converged)"))
    return TwoWayResult(status=status, reason=reason, regions=statuses, tol=float(tol),
                        iterations=len(changes), changes=changes, targets=final,
                        initial_targets=initial, responses=responses, materials=materials,
                        warnings=warned, fem_strain_increments=dict(fem_de),
                        stiffnesses=stiffnesses)
