"""A periodic DEM element for the region mode (issue 18): it takes the FEM region's full
stress tensor, shear included, where the wall-bounded element takes three normal stresses.

``PeriodicRegionElement`` is an ``element_runner`` for :func:`femcoupling.coupling.twoway.two_way`
(picklable, so it runs in the loop's worker processes). For a region it

1. prepares a periodic ``DemElement`` (``n`` grains, dense: grown frictionless, then at the
   material's friction) at the initial state's mean stress, and servo-controls all six
   components to the FEM's initial tensor;
2. keeps that state as bytes in the runner's memory (on the Dask worker that runs the
   region, when ``two_way`` runs on workers: ``cpp_dem.elements.pool.ElementPool.runners``;
   ``state()``/``set_state()`` carry those bytes, so the pool restores a region moved to a
   late worker or recovered from a lost one with its prepared element) and in
   ``cache_dir`` (``<name>_initial.bin``, with the tensor it was prepared at in
   ``<name>_initial.stress.npy``): the next two-way iterations start from it instead of
   preparing again (the element is kept between iterations, also across processes);
3. servo-controls all six components to the FEM's final tensor, and returns the normal
   stresses reached and the normal strain increment (compression positive), with the full
   strain-increment tensor, the shear reached and its stress scatter (the bootstrap of its
   contacts) in ``info``. ``info["full_tensor"]`` tells ``two_way`` that turned principal
   axes are imposed, not lost. ``info["tangent_voigt_pa"]`` is its tangent at the final
   state from its contact network, with the full stress increment in
   ``info["stress_increment_tensor"]``: ``two_way`` makes the tangent reproduce the
   increment and gives it to the region as a full stiffness.

A FEM stress beyond the element's strength (an elastic or cohesive FEM soil can hand over a
stress ratio no cohesionless packing carries) cannot be reached: the servo is stopped once
the element has strained ``max_strain`` (any component) on the way, and the state reached is
returned with ``info["message"]`` saying so; ``two_way`` warns with it. Its secant is then
the element's answer at its strength.

The element is soil only: a geogrid in the region stays in the FEM's layer band, so the grid is
counted once. SI units; the FEM tensors are tension positive.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np

from femcoupling._checks import FemInputError, _real
from femcoupling.coupling._inputs import check_client, check_fraction, check_int, check_open
from femcoupling.coupling.handover import HandoverError, fem_to_dem, spd_floor
from femcoupling.coupling.records import append_rows
from femcoupling.coupling.twoway import ElementResponse
from femcoupling.fem.quadrature import NewtonFailure
from femcoupling.materials.continuum import voigt_to_mandel_stiffness

__all__ = ["BAND_TANGENTS", "DemRegionMaterial", "PeriodicRegionElement",
           "PoolRegionMaterials", "servo", "trial_stiffness"]


def _plain(v):
    """``v`` as JSON values (floats round-trip exactly): an object by its type and public
    attributes (a ``Material``)."""
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    attrs = {a: getattr(v, a) for a in dir(v) if not a.startswith("_")}
    return {"type": type(v).__name__,
            **{a: _plain(x) if isinstance(x, (bool, int, float, str, type(None))) else str(x)
               for a, x in attrs.items() if not callable(x)}}


def servo(el, target, *, tol: float, unbalanced: float, chunk_steps: int,
          max_strain: float) -> tuple[np.ndarray, bool, float]:
    """Servo-controls all six stress components of the periodic element ``el`` to ``target``
    (3 x 3, Pa, tension positive) in chunks of ``chunk_steps``, giving up once it has strained
    more than ``max_strain`` (largest component) on the way: the target is beyond its
    strength. Returns the stress reached (tension positive), whether the target was reached,
    and the strain used. ``chunk_steps`` >= 1, ``max_strain`` in (0, 1), ``tol`` and
    ``unbalanced`` in (0, 1) (FemInputError otherwise: a chunk of no steps, or a limit never
    reached, would run forever)."""
    _check_servo(tol=tol, unbalanced=unbalanced, chunk_steps=chunk_steps,
                 max_strain=max_strain)
    e0 = el.strain()
    done = 0
    while True:
        try:
            s = el.apply_stress(target, tol=tol, unbalanced=unbalanced, max_steps=chunk_steps)
            return s, True, float(np.abs(el.strain() - e0).max())
        except RuntimeError:
            got = float(np.abs(el.strain() - e0).max())
            if got > max_strain:
                return el.stress(), False, got
            done += chunk_steps
            if done >= SERVO_MAX_STEPS:
                raise HandoverError(
                    f"the periodic element neither reached its target stress (tol={tol:g}, "
                    f"unbalanced={unbalanced:g}) nor strained past max_strain={max_strain:g} "
                    f"in {done} steps (it strained {got:.3g}): it hovers near the target "
                    "without settling; loosen tol or unbalanced, or lower max_strain") from None


#: The most DEM steps ``servo`` takes before it stops an element that hovers near its target
#: without meeting tol and unbalanced and without straining past max_strain (ten times
#: ``DemElement.apply_stress``'s own default budget).
SERVO_MAX_STEPS = 2_000_000


def _check_servo(*, tol, unbalanced, chunk_steps, max_strain) -> None:
    """The servo's settings (``servo``, ``PeriodicRegionElement``); FemInputError naming the
    first one out of its range."""
    check_open("tol", tol, 0.0, 1.0, " (the servo's relative tolerance on the stress)")
    check_open("unbalanced", unbalanced, 0.0, 1.0, " (the unbalanced force ratio of the "
               "servo's equilibrium)")
    check_int("chunk_steps", chunk_steps, 1, " (DEM steps per servo chunk)")
    check_open("max_strain", max_strain, 0.0, 1.0, " (the strain, largest component, past "
               "which a target beyond the element's strength is given up)")


#: The kind of PeriodicRegionElement.state() bytes (cpp_dem.elements.state_format).
_KEPT_KIND = "femcoupling.PeriodicRegionElement.state"


@dataclasses.dataclass
class PeriodicRegionElement:
    """See the module doc. ``n``: grains; ``seed``: packing seed; ``prep_friction_deg``: the
    friction angle the grains grow at (0: dense); ``tol``: the servo's relative tolerance;
    ``options``: more keywords for ``DemElement.periodic``; ``cache_dir``: where the prepared
    elements are also kept on disk (None: in the runner's memory only); ``tangent``: return
    the element's tangent at the final state (``DemElement.network_tangent``, from its
    contact network), so that ``two_way`` gives the region a full stiffness instead of an
    isotropic secant. Refused (FemInputError naming the field): ``n`` not a whole number
    >= 2, ``seed`` not one >= 0, ``prep_friction_deg`` outside [0, 90), ``tol``,
    ``unbalanced`` or ``max_strain`` outside (0, 1), ``chunk_steps`` not a whole number
    >= 1."""

    n: int = 400
    seed: int = 1
    prep_friction_deg: float | None = 0.0
    tol: float = 0.005
    unbalanced: float = 1e-3
    max_strain: float = 0.05
    chunk_steps: int = 2000
    cache_dir: str | None = None
    options: dict | None = None
    tangent: bool = True
    #: the prepared elements' bytes by (region, initial tensor): this runner's memory
    _kept: dict = dataclasses.field(default_factory=dict, init=False, repr=False,
                                    compare=False)
    #: the settings (``_settings()`` as JSON text) the elements in ``_kept`` were prepared with
    _kept_for: str | None = dataclasses.field(default=None, init=False, repr=False,
                                              compare=False)

    def __post_init__(self) -> None:
        self._check()

    def _check(self) -> None:
        """FemInputError naming the first field out of its range (the class doc)."""
        check_int("n", self.n, 2, " (grains; a periodic cell needs at least 2)")
        check_int("seed", self.seed, 0, " (the packing's seed)")
        if self.prep_friction_deg is not None:
            f = _real("prep_friction_deg", self.prep_friction_deg)
            if not 0.0 <= f < 90.0:
                raise FemInputError(f"prep_friction_deg={f!r}: must be in [0, 90) deg (the "
                                    "friction the grains grow at; 0: dense), or None")
        _check_servo(tol=self.tol, unbalanced=self.unbalanced, chunk_steps=self.chunk_steps,
                     max_strain=self.max_strain)
        if self.cache_dir is not None and not isinstance(self.cache_dir, (str, os.PathLike)):
            raise FemInputError(f"cache_dir={self.cache_dir!r}: must be a folder's path, or "
                                "None (the runner's memory only)")
        if self.options is not None and not isinstance(self.options, dict):
            raise FemInputError(f"options={self.options!r:.120}: must be a dict of "
                                "DemElement.periodic keywords, or None")

    def _kept_now(self, settings: str) -> dict:
        """``_kept``, emptied if its elements were prepared with settings other than
        ``settings`` (fields changed since)."""
        if self._kept and self._kept_for != settings:
            self._kept = {}
        self._kept_for = settings
        return self._kept

    def prepare(self, name: str, initial) -> tuple:
        """The element of region ``name`` at the ``initial`` WallTargets' full tensor: kept in
        this runner's memory after its first preparation (so in the worker that runs it), or
        in ``cache_dir``; else prepared (and kept in both). A kept element of a different
        initial tensor is not taken. Returns (element, whether it was kept)."""
        from cpp_dem.elements.periodic import DemElement

        self._check()  # (fields may have been set since the runner was made)
        self._kept_now(_settings_text(self._settings()))
        s0 = np.asarray(initial.fem_stress_pa, float)
        key = (name, s0.tobytes())
        if key in self._kept:
            return DemElement.from_bytes(self._kept[key]), True
        path = None if self.cache_dir is None else Path(self.cache_dir) / f"{name}_initial.bin"
        kpath = None if path is None else path.with_suffix(".key.json")
        disk_key = {"stress_pa": s0.tolist(), "settings": self._settings()}
        if (path is not None and path.exists() and kpath.exists()
                and json.loads(kpath.read_text()) == disk_key):
            data = path.read_bytes()
            try:
                el = DemElement.from_bytes(data)
            except ValueError as e:  # (ParameterError: not an element's bytes of this version)
                raise type(e)(f"{path}: {e}; remove it (a cache written by an older version, "
                              "or changed since) to prepare the element again") from None
            self._kept[key] = data
            return el, True
        el = DemElement.periodic(self.n, stress=float(-np.trace(s0) / 3), seed=self.seed,
                                 prep_friction_deg=self.prep_friction_deg,
                                 **(self.options or {}))
        _, ok, got = servo(el, s0, tol=self.tol, unbalanced=self.unbalanced,
                           chunk_steps=self.chunk_steps, max_strain=self.max_strain)
        if not ok:
            raise RuntimeError(f"region {name}: the periodic element cannot hold the FEM's "
                               f"initial stress {np.round(-s0 / 1e3, 2).tolist()} kPa "
                               f"(compression +): it strained {got:.3g} on the way; it is "
                               "beyond the packing's strength")
        data = el.to_bytes()
        self._kept[key] = data
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            for dst, text in ((kpath, json.dumps(disk_key).encode()), (path, data)):
                tmp = dst.with_name(dst.name + ".tmp")
                tmp.write_bytes(text)
                tmp.replace(dst)
        return el, False

    def state(self) -> bytes:
        """The elements this runner prepared (its memory: bytes by region and initial
        tensor), as bytes (``cpp_dem.elements.interface``: a runner's byte state) of
        cpp_dem's element format (``cpp_dem.elements.state_format``: nothing pickled), with
        the settings they were prepared with."""
        from cpp_dem.elements import state_format

        settings = self._settings()
        kept = self._kept_now(_settings_text(settings))
        keys = [[name, s0.hex()] for name, s0 in kept]
        return state_format.pack(_KEPT_KIND, {"keys": keys, "settings": settings},
                                 {str(k): v for k, v in enumerate(kept.values())})

    def set_state(self, data: bytes) -> None:
        """The prepared elements of ``state()`` back in this runner's memory. The state of a
        runner of other settings (grains, seed, preparation, servo, options: its elements
        are not this runner's) is refused (FemInputError naming what differs)."""
        from cpp_dem.elements import state_format

        if not isinstance(data, (bytes, bytearray)):
            raise ValueError(f"data: {type(data).__name__}, expected the bytes of "
                             "PeriodicRegionElement.state()")
        fields, parts = state_format.unpack(data, _KEPT_KIND)
        keys = fields.get("keys")
        try:
            kept = {(name, bytes.fromhex(s0)): parts[str(k)]
                    for k, (name, s0) in enumerate(keys)}
        except (TypeError, ValueError, KeyError):
            raise ValueError("data: not a PeriodicRegionElement.state() (its keys and "
                             "parts do not match)") from None
        mine = self._settings()
        theirs = fields.get("settings")
        if not isinstance(theirs, dict):
            raise FemInputError("data: a PeriodicRegionElement.state() without the settings "
                                "its elements were prepared with (written by an older "
                                "version); leave it out: the runner prepares its elements "
                                "again")
        if _settings_text(theirs) != _settings_text(mine):
            differ = sorted(k for k in set(theirs) | set(mine)
                            if _settings_text(theirs.get(k)) != _settings_text(mine.get(k)))
            raise FemInputError(
                "data: the state of a PeriodicRegionElement of other settings ("
                + "; ".join(f"{k}: {theirs.get(k)!r:.80} there, {mine.get(k)!r:.80} here"
                            for k in differ)
                + "): its elements are not this runner's; give it to a runner of the same "
                "settings, or leave it out: the runner prepares its elements again")
        self._kept = kept
        self._kept_for = _settings_text(mine)

    def _settings(self) -> dict:
        """What makes the prepared element (grains, seed, preparation, servo, options), as
        plain JSON values: a kept element prepared otherwise is not taken."""
        skip = {"cache_dir", "tangent", "_kept", "_kept_for"}
        return {f.name: _plain(getattr(self, f.name)) for f in dataclasses.fields(self)
                if f.name not in skip}

    def __call__(self, name: str, initial, final):
        t0 = time.perf_counter()
        el, cached = self.prepare(name, initial)
        e0, s_ini = el.strain(), el.stress()
        target = np.asarray(final.fem_stress_pa, float)
        s1, ok, got = servo(el, target, tol=self.tol, unbalanced=self.unbalanced,
                            chunk_steps=self.chunk_steps, max_strain=self.max_strain)
        message = None if ok else (
            f"region {name}: the periodic element cannot carry the FEM stress "
            f"{np.round(-target / 1e3, 2).tolist()} kPa (compression +): it strained {got:.3g}"
            f" (> max_strain={self.max_strain:g}) and holds "
            f"{np.round(-s1 / 1e3, 2).tolist()} kPa, its strength; its secant is that of the "
            "state reached")
        de = el.strain() - e0  # tension positive
        scatter = el.stress_scatter()
        # (A non-finite tangent is passed on: two_way then says so and takes the secant.)
        tangent = el.network_tangent()[0] if self.tangent else None
        return ElementResponse(
            stress_initial_pa=-np.diag(s_ini), stress_final_pa=-np.diag(s1),
            strain_increment=-np.diag(de),
            info={"full_tensor": True, "strain_increment_tensor": -de,
                  "stress_increment_tensor": -(s1 - s_ini),
                  **({"tangent_voigt_pa": tangent} if tangent is not None else {}),
                  "shear_final_pa": -np.array([s1[1, 2], s1[0, 2], s1[0, 1]]),
                  "stress_scatter_pa": np.diag(scatter), "prepared_from_cache": cached,
                  "contacts": el.contact_count(), "wall_s": time.perf_counter() - t0,
                  "porosity": _porosity(el),
                  "reached": message is None, **({"message": message} if message else {})})


def _settings_text(settings) -> str:
    """``PeriodicRegionElement._settings()`` (or one of its values) as canonical JSON text:
    equal text, equal settings."""
    return json.dumps(settings, sort_keys=True)


def _porosity(el) -> float:
    """The porosity of a periodic element's cell, -."""
    from cpp_dem import measure

    return float(measure.porosity(el.scene, ()))


def network_stiffness(element, min_eig_fraction: float = 1e-3, *,
                      voigt: np.ndarray | None = None) -> np.ndarray:
    """A periodic element's tangent from its contact network (or the given 6 x 6 Voigt one),
    as a 6 x 6 Mandel stiffness made symmetric and positive definite (eigenvalues floored at
    ``min_eig_fraction`` of the largest), Pa."""
    t = element.network_tangent()[0] if voigt is None else voigt
    return spd_floor(voigt_to_mandel_stiffness(t), min_eig_fraction)


def trial_stiffness(label: str, voigt, min_eig_fraction: float, increment,
                    contacts: int) -> np.ndarray:
    """``network_stiffness`` of an element's 6 x 6 Voigt network tangent at a Newton trial.
    An element with no stiffness left at the trial (its
    contacts opened: a cohesionless element stretched past its confinement) fails the Newton
    iterate (``NewtonFailure``: the model cuts the step and tries a shorter one), naming it
    by ``label``, its ``contacts`` and its strain ``increment``."""
    try:
        return network_stiffness(None, min_eig_fraction, voigt=voigt)
    except HandoverError as exc:
        raise NewtonFailure(
            f"{label}: no stiffness left at this iterate ({contacts} contacts; strain "
            f"increment {np.round(np.asarray(increment), 7).tolist()}): {exc}") from exc


def _new_records(records, overwrite: bool, remove: bool = True) -> Path | None:
    """``records`` as a Path (None: no records), refused (FemInputError) if the file exists
    (an earlier run's rows) unless ``overwrite``, then removed (if ``remove``)."""
    if not isinstance(overwrite, bool):
        raise FemInputError(f"overwrite={overwrite!r}: must be True or False")
    if records is None:
        return None
    if not isinstance(records, (str, os.PathLike)):
        raise FemInputError(f"records={records!r:.120}: must be an HDF5 file's path, or None")
    path = Path(records)
    if path.exists():
        if not overwrite:
            raise FemInputError(f"records={str(path)!r}: holds the records of an earlier run; "
                                "give a new file, or overwrite=True to replace them")
        if remove:
            path.unlink()
    return path


class DemRegionMaterial:
    """A periodic DEM element as the material of a ``FemModel`` element region (the soil body): the
    hierarchical mode on the reinforced-soil body, one element for the region's tagged group
    of cells (``FemModel.set_region_element``). At every Newton iterate the model hands it
    the region's mean strain increment since the start of the load step (the full tensor,
    shear included; plane strain holds the out-of-plane strain at zero); the element, restored
    to the start of the step, takes it and returns its stress and its tangent from its contact
    network. The model adds its stress increment (that stress less ``stress_n``, the stress at
    the start of the step) to every region point's stress of the start of the step and
    assembles Newton's Jacobian with the tangent. A converged step is
    committed (``commit``: the element's state kept as bytes); a rejected iterate leaves no
    trace. So the element strains exactly as its region does: the two scales agree by
    construction. SI units; tension positive.

    ``element``: a periodic ``cpp_dem.elements.periodic.DemElement`` in the region's initial state
    (``prepared`` makes one); ``strain_kw``: keywords for ``DemElement.apply_strain``;
    ``min_eig_fraction``: the tangent is made symmetric and positive definite, eigenvalues
    floored at this fraction of the largest, in (0, 1) (a network near its strength has soft
    or negative directions); ``records``: an HDF5 file that gets a row at every committed
    step (appended and flushed): step, strain since the element took over (3 x 3), stress
    (3 x 3, Pa), tangent (6 x 6 Mandel, Pa), contact count, element runs and DEM seconds so
    far. A ``records`` file that exists (an earlier run's rows) is refused unless
    ``overwrite`` (then it is removed): appending would mix two runs' rows.

    A ``femcoupling.fem.quadrature.QuadratureMaterial`` of ``strain_measure`` "tensor":
    ``trial`` returns the element's total stress; ``stress_n`` is its stress at the start of
    the step (the committed one); ``plastic`` is 0 (its plasticity is in its contacts).
    """

    strain_measure = "tensor"
    plastic = np.zeros(1)

    def __init__(self, element, *, strain_kw: dict | None = None,
                 min_eig_fraction: float = 1e-3, records=None,
                 overwrite: bool = False) -> None:
        if getattr(element, "kind", None) != "periodic":
            raise ValueError(f"element={element!r}: must be a periodic DemElement (it takes "
                             "the full strain tensor)")
        self.strain_kw = dict(strain_kw or {})
        self.min_eig_fraction = float(check_fraction(min_eig_fraction))
        self.records = _new_records(records, overwrite)
        self.steps = 0            #: committed steps
        self.calls = 0            #: element evaluations (DEM runs)
        self.dem_s = 0.0          #: wall seconds in them
        self._origin = element.strain()
        self._set(element)

    def _set(self, element, tangent: np.ndarray | None = None) -> None:
        """``element`` becomes the start of the step; ``tangent``: its stiffness, if known
        (the last trial's), else assembled from its contact network."""
        self.element = element
        self._committed = element.to_bytes()
        self._stress0 = element.stress()
        self._tangent0 = (network_stiffness(element, self.min_eig_fraction) if tangent is None
                          else tangent)
        self._trial_tangent = self._tangent0  # (of self.element)

    @classmethod
    def prepared(cls, name: str, stress_fem_pa, runner: "PeriodicRegionElement",
                 **kw) -> "DemRegionMaterial":
        """The material of region ``name``: ``runner``'s element (its grains, seed, cache)
        servo-controlled to ``stress_fem_pa`` (3 x 3, Pa, tension positive: the region's
        stress where the element takes over)."""
        el, _ = runner.prepare(name, fem_to_dem(stress_fem_pa))
        return cls(el, **kw)

    @property
    def stress_n(self) -> np.ndarray:
        """The element's committed stress (at the start of the step), 3 x 3, Pa."""
        return self._stress0

    def trial(self, strain_increment) -> tuple[np.ndarray, np.ndarray]:
        """The element, from the start of the step, through ``strain_increment`` (3 x 3, -):
        returns its stress (3 x 3, Pa) and its tangent (6 x 6 Mandel, Pa)."""
        from cpp_dem.elements.periodic import DemElement

        de = np.asarray(strain_increment, float)
        if not np.any(de):
            self.element = DemElement.from_bytes(self._committed)
            self._trial_tangent = self._tangent0
            return self._stress0.copy(), self._tangent0
        t0 = time.perf_counter()
        el = self.element = DemElement.from_bytes(self._committed)
        s = el.apply_strain(de, **self.strain_kw)
        c = self._trial_tangent = trial_stiffness("the region's element",
                                                  el.network_tangent()[0],
                                                  self.min_eig_fraction, de,
                                                  el.contact_count())
        self.calls += 1
        self.dem_s += time.perf_counter() - t0
        return s, c

    def commit(self) -> None:
        """The last trial becomes the start of the next step (and a row of ``records``)."""
        self._set(self.element, self._trial_tangent)
        self.steps += 1
        if self.records is not None:
            el = self.element
            append_rows(self.records, {
                "step": [self.steps], "strain": [el.strain() - self._origin],
                "stress_pa": [el.stress()], "tangent_mandel_pa": [self._tangent0],
                "contacts": [el.contact_count()], "element_runs": [self.calls],
                "dem_s": [self.dem_s]},
                units="SI; tension positive; strain since the element took over the region")

    def state(self) -> bytes:
        """The committed state (``set_state`` returns to it)."""
        return self._committed

    def set_state(self, data: bytes) -> None:
        from cpp_dem.elements.periodic import DemElement

        self._set(DemElement.from_bytes(data))

    def strain_since_start(self) -> np.ndarray:
        """The element's strain since it took over the region (3 x 3, -, tension +)."""
        return self.element.strain() - self._origin


#: The reinforced RVEs' tangents in a ``PoolRegionMaterials`` (``band_tangent``).
BAND_TANGENTS = ("network", "network-elastic", "fd-forward")


class PoolRegionMaterials:
    """The DEM elements of several element regions on Dask workers
    (``cpp_dem.elements.pool.ElementPool``, one element per region), for
    ``FemModel.set_region_element``: the model evaluates them all at once at every Newton
    iterate (``trial_many``), so the regions' DEM runs in parallel. Each region's element
    behaves as a ``DemRegionMaterial`` (the same answers, bitwise: every worker runs one
    element at a time on one thread). ``materials[name]`` is what to give the model.

    Build with ``PoolRegionMaterials.build(stresses, runner, workers=)``: each element
    prepared on the workers by ``runner`` (``PeriodicRegionElement``) at its stress, all at
    once. The same group serves ``FemModel.set_cell_elements`` (one element per cell of a
    region: ``stresses = model.cell_stresses(name)``), and can also hold reinforced RVEs for
    the cells of a geogrid band (``build(band=)``, ``ReinforcedBandElement``). The elements'
    tangents (Newton's Jacobian) are from their contact networks at every trial, the
    reinforced RVEs' with their sheets' bonds. ``band_tangent`` is the reinforced RVEs'
    (the pool's names): "network" (the default), "network-elastic" (sliding contacts taken
    as stuck), or "fd-forward": forward differences of the Voigt components
    ``fd_components`` at every trial (one run of the element each; plane strain in x-z
    needs (0, 2, 4)), the others filled (``_filled``).
    ``close()`` stops the pool's own cluster.

    ``records``: an HDF5 file that gets a row per element at every committed step (appended
    and flushed): step, element (its index in ``names``, which the file's ``names``
    attribute lists), strain since the element took over (3 x 3, -), stress (3 x 3, Pa),
    tangent (6 x 6 Mandel, Pa), contact count, and the DEM seconds of its last run; a file
    that exists is refused unless ``overwrite`` (as ``DemRegionMaterial``'s).
    ``min_eig_fraction``: in (0, 1), as ``DemRegionMaterial``'s.
    """

    def __init__(self, pool, names, *, min_eig_fraction: float = 1e-3,
                 strain_kw: dict | None = None, records=None,
                 fd_components=tuple(range(6)), band_tangent: str = "network",
                 overwrite: bool = False) -> None:
        from cpp_dem.elements.periodic import DemElement

        self.pool, self.names = pool, list(names)
        if pool.n != len(self.names):
            raise ValueError(f"names={self.names!r}: one per pool element ({pool.n})")
        self.min_eig_fraction = float(check_fraction(min_eig_fraction))
        self.strain_kw = dict(strain_kw or {})
        self.records = _new_records(records, overwrite)
        self.calls, self.dem_s, self.steps = 0, 0.0, 0
        if band_tangent not in BAND_TANGENTS:
            raise ValueError(f"band_tangent={band_tangent!r}: "
                             + ", ".join(map(repr, BAND_TANGENTS)))
        self.band_tangent = band_tangent
        self.fd_components = tuple(int(c) for c in fd_components)
        if not self.fd_components or any(not 0 <= c < 6 for c in self.fd_components):
            raise ValueError(f"fd_components={fd_components!r}: Voigt components 0..5")
        elements = [DemElement.from_bytes(b) for b in pool.states()]
        self._bonded = {k for k, el in enumerate(elements) if el.scene.num_bonds}
        self._start(elements)
        self._contacts0 = [el.contact_count() for el in elements]
        self._strain = [np.zeros((3, 3)) for _ in self.names]  # since they took over
        self._last = None
        self.materials = {n: _PoolMember(self, n) for n in self.names}

    def _start(self, elements) -> None:
        self._stress0, self._tangent0 = [], []
        from cpp_dem.elements.pool import element_tangent

        for k, el in enumerate(elements):  # (as a trial's)
            self._stress0.append(el.stress())
            voigt = element_tangent(el, ("network", self.band_tangent), self.strain_kw,
                                    self.fd_components)
            self._tangent0.append(network_stiffness(
                None, self.min_eig_fraction,
                voigt=self._filled(voigt) if k in self._bonded else voigt))

    def _filled(self, voigt) -> np.ndarray:
        """A finite-difference tangent of ``fd_components`` only, made whole: each column
        not computed is the transpose of its row where that is known (a symmetric
        tangent), with the computed diagonal's mean on the diagonal. Those components are
        ones the model does not strain (plane strain's yy, yz, xy), so they only keep the
        6 x 6 tangent's algebra whole."""
        d = np.array(voigt, float)
        if not np.isnan(d).any():  # (a whole tangent: the network's)
            return d
        done = list(self.fd_components)
        rest = [c for c in range(6) if c not in done]
        if not rest:
            return d
        for c in rest:
            d[:, c] = 0.0
            d[done, c] = d[c, done]
            d[c, c] = float(np.mean(np.diag(d)[done]))
        return d

    @classmethod
    def build(cls, stresses: dict, runner: "PeriodicRegionElement", *, workers: int = 2,
              client=None, distinct_seeds: bool = False,
              band: "tuple[ReinforcedBandElement, dict] | None" = None,
              **kw) -> "PoolRegionMaterials":
        """``stresses``: name -> the stress where its element takes over (3 x 3, Pa, tension
        positive); ``distinct_seeds``: element k packed with seed ``runner.seed + k`` (else
        every element from ``runner.seed``). ``band``: (a ``ReinforcedBandElement``, name ->
        (the grains' pressure, Pa, compression positive; the sheet's tension, N/m)): more
        members, reinforced cells of a geogrid band (``FemModel.band_cell_states``),
        after the soil's; band element j packed with seed ``band[0].seed + j``."""
        from cpp_dem.elements.pool import ElementPool

        check_client(client)
        # (the pool's own checks, before a cluster starts and the elements are prepared)
        check_fraction(kw.get("min_eig_fraction", 1e-3))
        _new_records(kw.get("records"), kw.get("overwrite", False), remove=False)
        names = list(stresses)
        make = _Prepare(runner, names, [np.asarray(stresses[n], float) for n in names],
                        distinct_seeds)
        if band is not None:
            brunner, states = band
            make = _Concat(((len(names), make),
                            (len(states), _PrepareBand(brunner, list(states.values())))))
            names += list(states)
        return cls(ElementPool.build(len(names), make, client=client, workers=workers), names,
                   **kw)

    def trial_many(self, increments: dict) -> dict:
        """Every region's element, from the start of the step, through its increment (name ->
        3 x 3, -): name -> (stress 3 x 3 Pa, tangent 6 x 6 Mandel Pa)."""
        des = [np.asarray(increments.get(n, np.zeros((3, 3))), float) for n in self.names]
        self.pool.reject()
        if not any(np.any(d) for d in des):
            self._last = None
            return {n: (self._stress0[k].copy(), self._tangent0[k])
                    for k, n in enumerate(self.names)}
        step = self.pool.apply_strain(des, tangent=("network", self.band_tangent),
                                      fd_components=self.fd_components,
                                      **self.strain_kw)
        self.calls += 1
        self.dem_s += float(sum(step.cpu_s))
        self._last = ([np.asarray(s) for s in step.stresses],
                      [trial_stiffness(f"element {self.names[k]}",
                                       self._filled(t) if k in self._bonded else t,
                                       self.min_eig_fraction, des[k], c)
                       for k, (t, c) in enumerate(zip(step.tangents, step.contacts))],
                      des, list(step.contacts), list(step.cpu_s))
        return {n: (self._last[0][k], self._last[1][k]) for k, n in enumerate(self.names)}

    def commit(self) -> None:
        """The last trial becomes the start of the next step on every worker (and rows of
        ``records``)."""
        self.pool.accept()
        cpu = [0.0] * len(self.names)
        if self._last is not None:  # (the last trial's stresses, stiffnesses, increments)
            self._stress0, self._tangent0, des, self._contacts0, cpu = self._last
            self._strain = [e + d for e, d in zip(self._strain, des)]
        self.steps += 1
        if self.records is not None:
            import h5py

            n = len(self.names)
            append_rows(self.records, {
                "step": [self.steps] * n, "element": list(range(n)), "strain": self._strain,
                "stress_pa": self._stress0, "tangent_mandel_pa": self._tangent0,
                "contacts": self._contacts0, "dem_s": cpu},
                units="SI: strain -, stress and tangent Pa (tension positive), dem_s s")
            with h5py.File(self.records, "a") as f:
                if "names" not in f.attrs:
                    f.attrs["names"] = self.names

    def strains(self) -> list:
        """The elements' strains since they took over, to their last committed state, in
        ``names`` order: 3 x 3, -, tension positive."""
        return [e.copy() for e in self._strain]

    def stresses(self) -> list:
        """The elements' stresses at the start of the step (their last committed state), in
        ``names`` order: 3 x 3, Pa, tension positive."""
        return [s.copy() for s in self._stress0]

    def state(self) -> tuple:
        return (self.pool.states(), list(self._stress0), list(self._tangent0),
                list(self._strain), list(self._contacts0), self.steps)

    def set_state(self, data: tuple) -> None:
        states, self._stress0, self._tangent0 = data[0], list(data[1]), list(data[2])
        self._strain, self._contacts0, self.steps = list(data[3]), list(data[4]), data[5]
        self.pool.load_states(states)

    def close(self) -> None:
        self.pool.close()


@dataclasses.dataclass
class _Prepare:
    """``ElementPool.build``'s factory for a ``PoolRegionMaterials``: element k is
    ``runner``'s element of ``names[k]`` prepared at ``stresses[k]`` (3 x 3, Pa, tension
    positive), on the worker."""

    runner: "PeriodicRegionElement"
    names: list
    stresses: list
    distinct_seeds: bool = False

    def __call__(self, k: int):
        runner = (dataclasses.replace(self.runner, seed=self.runner.seed + k)
                  if self.distinct_seeds else self.runner)
        return runner.prepare(self.names[k], fem_to_dem(self.stresses[k]))[0]


@dataclasses.dataclass
class ReinforcedBandElement:
    """The element of a cell of a continuum's geogrid band: the reinforced-soil RVE
    (``cpp_dem.elements.reinforced.reinforced_element``: ``n`` grains around the woven
    sheet in a periodic cell) standing for a band ``band_thickness_m`` thick
    (``DemElement.set_band_thickness``: its stress is the grains' plus the sheet's force per
    metre over the band's thickness). ``element(grains_pa, tension_n_per_m)`` prepares it
    with its grains at that mean pressure (Pa, compression positive) and its sheet at that
    tension along x (N/m; a band in compression is prepared with an unloaded sheet, the
    sheet not being able to hold a thrust); ``options``: more keywords for
    ``reinforced_element`` (``material``, ``radius_mean``, ``radius_spread``, ``preset``,
    ``tol``, ...). After that preparation the cell, held, relaxes until the unbalanced
    force is below ``unbalanced`` (a sheet left at hold_sheet's looser tolerance creeps:
    at 1e-2, an 80-grain cell's stress under a strain increment of 1e-4 drifted by 0.3 kPa
    with the increment or without it; relaxed to 1e-4, by less than 1 Pa). Its tangent is its
    network's, the sheet's bonds in it (``DemElement.network_tangent``). SI units."""

    n: int = 80
    seed: int = 1
    band_thickness_m: float = 0.02
    options: dict | None = None
    unbalanced: float = 1e-4
    max_relax_steps: int = 400_000

    def element(self, grains_pa: float, tension_n_per_m: float, seed: int | None = None):
        from cpp_dem.elements.reinforced import reinforced_element

        el = reinforced_element(self.n, stress=float(grains_pa),
                                prestress=max(float(tension_n_per_m), 0.0),
                                seed=self.seed if seed is None else int(seed),
                                **(self.options or {}))
        el.apply_strain(np.zeros((3, 3)), unbalanced=self.unbalanced,
                        max_relax_steps=self.max_relax_steps)
        if not el.last_report.relaxed:
            raise RuntimeError(f"a band cell's reinforced RVE (seed {seed}) did not relax to "
                               f"an unbalanced force of {self.unbalanced} in "
                               f"{self.max_relax_steps} steps (at "
                               f"{el.last_report.unbalanced_force:.3g})")
        el.set_band_thickness(self.band_thickness_m)
        return el


@dataclasses.dataclass
class _PrepareBand:
    """``ElementPool.build``'s factory of band elements: element j is ``runner``'s at
    ``states[j]`` (grains' pressure, Pa; sheet's tension, N/m), packed with seed
    ``runner.seed + j``."""

    runner: ReinforcedBandElement
    states: list

    def __call__(self, j: int):
        p, t = self.states[j]
        return self.runner.element(p, t, seed=self.runner.seed + j)


@dataclasses.dataclass
class _Concat:
    """Factories one after another: ``parts`` is ((count, factory), ...); element k is made
    by the part it falls in, with its index within that part."""

    parts: tuple

    def __call__(self, k: int):
        j = k
        for count, make in self.parts:
            if j < count:
                return make(j)
            j -= count
        raise IndexError(f"element {k} beyond the factories' {sum(c for c, _ in self.parts)}")


class _PoolMember:
    """One region of a ``PoolRegionMaterials``: what ``FemModel.set_region_element`` takes
    (the model finds the ``group`` and evaluates, commits and saves the group once); a
    ``QuadratureMaterial`` as ``DemRegionMaterial`` is."""

    strain_measure = "tensor"
    plastic = np.zeros(1)

    def __init__(self, group: PoolRegionMaterials, name: str) -> None:
        self.group, self.name = group, name
        self._k = group.names.index(name)

    @property
    def stress_n(self) -> np.ndarray:
        """The element's committed stress, 3 x 3, Pa."""
        return self.group._stress0[self._k]

    def trial(self, strain_increment):
        return self.group.trial_many({n: (strain_increment if n == self.name else
                                          np.zeros((3, 3))) for n in self.group.names}
                                     )[self.name]

    def commit(self) -> None:
        self.group.commit()

    def state(self):
        return self.group.state()

    def set_state(self, data) -> None:
        self.group.set_state(data)

