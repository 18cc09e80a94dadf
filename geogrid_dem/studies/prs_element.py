"""The reinforced-soil element study (``geogrid-dem run prs-element``, and
``prs-element-002`` which builds on it): its parameters (:class:`Params`), the FEM model of
the structure, one-way and two-way runs of its element region, the region's material as a DEM
element inside the FEM's Newton (hierarchical, one element or one per cell), and the
calibration of the FEM soil to the element's grains.

``p`` is a :class:`Params`: a ``cpp_dem.elements.box.ElementParams`` with the FEM fields
(structure, soil, layers, coupling). The element itself is ``cpp_dem.elements.box``'s and the
FEM ``femcoupling``'s; this module composes them, and the case
(``geogrid_dem.cases.prs_element``) parses options, calls it and writes the report. SI units;
FEM stresses tension positive, DEM stresses compression positive.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from cpp_dem import apply_threads, fixedorder
from cpp_dem.elements import box as _element
from cpp_dem.elements.box import ElementParams, grid_stiffness_per_metre
from cpp_dem.io.figures import save_figure
from geogrid_dem.processes import process_pool, wait_result
from geogrid_dem.rundir import write_atomic


@dataclass
class Params(ElementParams):
    """Parameters of the PRS element study (SI): the DEM element's (cpp_dem.elements.box.
    ElementParams: grains, geogrid, servo) and the FEM structure's and coupling's below (the
    case ``geogrid-dem run prs-element`` and ``prs-element-002`` set them)."""

    # --- FEM structure (plane strain) ---
    fem_width: float = 4.0           #: half width of the modelled fill, m
    fem_height: float = 3.0          #: height of the fill, m
    footing_b: float = 0.5           #: footing half width, m
    footing_pressure: float = 100e3  #: footing pressure, Pa
    fem_steps: int = 6               #: load steps
    soil_young: float = 50e6         #: Pa
    soil_poisson: float = 0.3        #: -
    soil_cohesion: float = 10e3      #: Pa (apparent cohesion of a compacted gravelly fill)
    soil_friction: float = 35.0      #: deg
    unit_weight: float = 18e3        #: N/m^3
    layer_depths: tuple = (0.3, 0.6)  #: depths of the geogrid layers below the top, m
    layer_length: float = 2.0        #: layer extent from the symmetry plane, m
    layer_thickness: float = 0.01    #: band thickness, m
    region_x: float = 0.25           #: element region centre x (on the upper layer), m
    mesh_size: float = 0.5           #: coarse FEM mesh size, m
    fine_size: float = 0.025         #: fine FEM mesh size (footing edge, region, layers), m
    # --- coupling ---
    two_way: bool = False
    two_way_tol: float = 0.02
    max_iterations: int = 8
    workers: int = 1
    #: the FEM soil: "calibrated" (the default: set to the case's own element along the
    #: region's path, cohesion 0; calibrate_soil) or "given" (the soil_* fields)
    soil: str = "calibrated"
    #: the two-way loop's element: "walls" (the case's element, geogrid included, three
    #: normal stresses, its probed tangent back) or "periodic" (soil only, the full tensor, its
    #: network tangent back; the case's element is then driven to the converged targets)
    two_way_element: str = "walls"
    #: the walls element's tangent in the two-way loop: three stress probes of this size,
    #: relative to the mean stress (cpp_dem.elements.box.probe_tangent); 0: the isotropic secant
    tangent_probe: float = 0.05
    #: hand the FEM layer's tension across the element region to the element's grid ends
    #: (force-controlled; a PRS grid's grips let go), so the walls carry the soil's stress
    #: alone and the grid is counted once; False: free ends (RE), locked grips (PRS)
    grid_handover: bool = True
    #: hierarchical: the region's material is a dense periodic DEM element of the case's grains
    #: inside the FEM's Newton (its stress and tangent at every iterate), no two-way loop
    hierarchical: bool = False
    #: hierarchical: an element per cell of the element region instead of one for the region
    #: (each prepared at its cell's stress, seed + its index), on ``workers`` Dask workers
    cell_elements: bool = False
    #: grains of each cell's element (0: ``n``)
    cell_grains: int = 0
    stresses: list = field(default_factory=list)  #: DEM-only targets (rows of 3), Pa
    prs: bool = False                #: DEM-only: prestress the grid (else RE)


def log(msg: str) -> None:
    print(f"[prs_element] {msg}", flush=True)


def run_element(p: ElementParams, targets: list, *, prestressed: bool, label: str, out: Path,
                cache: dict | None = None, grid_tension: list | None = None,
                probe: float = 0.0, prepared: dict | None = None) -> dict:
    """:func:`cpp_dem.elements.box.run_element` with this case's log."""
    return _element.run_element(p, targets, prestressed=prestressed, label=label, out=out,
                                log=log, cache=cache, grid_tension=grid_tension, probe=probe,
                                prepared=prepared)


def packing_file(out: Path, seed: int) -> Path:
    """The grown packing of the calibration's element of ``seed`` in its folder ``out``
    (``cpp_dem.elements.box.save_prepared``): an interrupted calibration resumed in a new
    process restores it instead of growing it again (bitwise the same element); removed once
    the calibration is done."""
    return Path(out) / f"packing_s{int(seed)}.h5"


def handed_tension(p: Params, targets: list, label: str) -> list | None:
    """The geogrid tensions (N/m) handed to the element's grid ends for these WallTargets
    (``grid_tension_n_per_m``, the FEM layer across the region): None when
    ``p.grid_handover`` is off or the FEM has no layer there. A layer in compression is handed
    over as 0 (free ends: a geogrid carries no compression), and the log says so."""
    if not p.grid_handover or any(t.grid_tension_n_per_m is None for t in targets):
        return None
    ts = [float(t.grid_tension_n_per_m) for t in targets]
    if min(ts) < 0:
        log(f"{label}: the FEM layer is in compression across the region "
            f"({np.round(np.array(ts) / 1e3, 4).tolist()} kN/m): a geogrid carries none, so "
            "its ends are left free where it is")
    return [max(t, 0.0) for t in ts]


#: The two-way loop's elements, kept between its iterations: per (parameters, region) the
#: element prepared and servoed to the initial targets, which every iteration shares. (The
#: case's loop has one region, which ``two_way`` runs in the variant's process.)
_ELEMENTS: dict = {}


def element_runner(cls, p_dict: dict, out: str, name: str, initial, final):
    """Picklable two-way runner: the element (parameters ``cls(**p_dict)``, ``cls`` the
    case's parameter class) from the initial to the final WallTargets. In
    one process the element at the initial targets is prepared once and restored for the
    next iterations (``_ELEMENTS``)."""
    from femcoupling.coupling.twoway import ElementResponse

    p = cls(**p_dict)
    prestressed = name.endswith("PRS")
    cache = _ELEMENTS.setdefault((json.dumps(p_dict, sort_keys=True, default=str), out, name),
                                 {})
    s = run_element(p, [initial.normal_pa, final.normal_pa], prestressed=prestressed,
                    label=f"twoway_{name}", out=Path(out), cache=cache,
                    grid_tension=handed_tension(p, [initial, final], f"twoway_{name}"),
                    probe=p.tangent_probe)
    ds = np.subtract(s["stress_final_pa"], s["stress_initial_pa"])
    tangent = {} if "tangent_voigt_pa" not in s else {
        "tangent_voigt_pa": np.array(s["tangent_voigt_pa"]),
        # (the walls' increments: normal only; the tangent's shear stays the probes')
        "strain_increment_tensor": np.diag(s["strain_increment"]),
        "stress_increment_tensor": np.diag(ds), "tangent_probes": s["tangent_probes"]}
    return ElementResponse(stress_initial_pa=np.array(s["stress_initial_pa"]),
                           stress_final_pa=np.array(s["stress_final_pa"]),
                           strain_increment=np.array(s["strain_increment"]),
                           info={"hold_max_rel_error": s["hold_max_rel_error"],
                                 "stress_scatter_pa": np.array(s["stress_scatter_pa"]),
                                 **tangent})


class _Runner:
    """Binds the case parameters to :func:`element_runner` (picklable)."""

    def __init__(self, p: Params, out: Path, variant: str):
        self.cls, self.p, self.out, self.variant = type(p), asdict(p), str(out), variant

    def __call__(self, name, initial, final):
        return element_runner(self.cls, self.p, self.out, f"{name}_{self.variant}", initial,
                              final)


# ---- FEM structure ---------------------------------------------------------------------------


def fem_body(p: Params):
    from femcoupling.fem.geometry import ElementRegion, GeogridLayer, ReinforcedSoilBody

    h = p.fem_height
    layers = tuple(GeogridLayer(z_m=h - d, x_min_m=0.0, x_max_m=p.layer_length,
                                thickness_m=p.layer_thickness, name=f"geogrid_{k}")
                   for k, d in enumerate(p.layer_depths))
    region = ElementRegion("element", (p.region_x, h - p.layer_depths[0]), p.edge)
    return ReinforcedSoilBody(width_m=p.fem_width, height_m=h, footing_half_width_m=p.footing_b,
                              layers=layers, regions=(region,), mesh_size_m=p.mesh_size,
                              fine_size_m=p.fine_size, fine_radius_m=2 * p.footing_b)


def periodic_options(p: Params) -> dict:
    """``DemElement.periodic`` keywords for a periodic element of this case's grains: their
    material and radii (the mean radius of ``p.n`` grains filling the element's cube at a
    solid fraction of 0.6)."""
    from cpp_dem.scene import linear_material

    r_mean = (0.6 * p.edge**3 / (p.n * 4.0 / 3.0 * math.pi)) ** (1.0 / 3.0)
    mat = linear_material(density=p.density, young=p.young, poisson=p.poisson,
                          friction_angle_deg=p.friction_deg)
    return {"material": mat, "radius_mean": r_mean, "radius_spread": p.radius_spread}


def periodic_runner(p: Params, out: Path, variant: str):
    """A dense periodic element of this case's grains for the region
    (``femcoupling.materials.dem_elements.PeriodicRegionElement``, kept in
    ``out/region_elements/<variant>``)."""
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    return PeriodicRegionElement(n=p.n, seed=p.seed, prep_friction_deg=0.0, tol=0.02,
                                 unbalanced=1e-2, options=periodic_options(p),
                                 cache_dir=str(out / "region_elements" / variant))


def _finite_or_none(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def step_statuses(steps) -> dict:
    """Per load step of the FEM's Newton (``LoadStep``): its status, its accepted residual
    (relative to the DEM region's own internal force), the tolerance on that scale and the
    residual in Pa, the iterates it took after a stall above the noise ceiling
    (``LoadStep.redraws``), and on the residual's scale the elements' noise measured at its
    stall and the ceiling (None: not measured, no ceiling): the summary's record."""
    return {"step_statuses": [r.status for r in steps],
            "step_residuals": [float(r.residual) for r in steps],
            "step_tols": [float(r.tol) for r in steps],
            "step_residuals_pa": [float(r.residual_pa) for r in steps],
            "step_redraws": [int(getattr(r, "redraws", 0)) for r in steps],
            "step_noise": [_finite_or_none(getattr(r, "noise", math.nan)) for r in steps],
            "step_ceilings": [_finite_or_none(getattr(r, "ceiling", math.nan))
                              for r in steps]}


def hierarchical_status(hier: dict, fem_strain_increment, rotation_deg: float):
    """The status of a hierarchical load stage (``femcoupling.coupling.status.judge_steps``) from
    its record (``run_hierarchical``): its steps' statuses and residuals, and the element's (or
    the cells' volume mean) strain increment against its FEM region's (compression
    positive). The periodic elements take the full tensor: the axes are reported, not
    checked."""
    from types import SimpleNamespace

    from femcoupling.coupling.status import judge_steps

    steps = [SimpleNamespace(status=st, residual=r, tol=t) for st, r, t in
             zip(hier["step_statuses"], hier["step_residuals"], hier["step_tols"])]
    fe = float(np.abs(np.asarray(fem_strain_increment, float)).max())
    de = float(np.abs(np.asarray(hier["element_strain_increment"], float)).max())
    ratio = de / fe if fe > 0 else math.inf
    return judge_steps(steps, dem_fem_strain_ratio=ratio, walled=False,
                       axes_rotation_deg=rotation_deg)


def run_hierarchical(p: Params, out: Path, variant: str, m, load) -> dict:
    """The load stage with the region's material a periodic DEM element inside the FEM's
    Newton (``FemModel.set_region_element``,
    ``femcoupling.materials.dem_elements.DemRegionMaterial``), from the model's current (initial)
    state; with ``p.cell_elements`` an element per cell (``run_cell_elements``). Returns the record
    of the summary."""
    from femcoupling.materials.dem_elements import DemRegionMaterial

    if p.cell_elements:
        return run_cell_elements(p, out, variant, m, load)
    t0 = time.perf_counter()
    try:
        mat = DemRegionMaterial.prepared("element", m.region_stress("element"),
                                         periodic_runner(p, out, variant),
                                         records=out / f"region_element_{variant}.h5")
    except RuntimeError as exc:  # (a periodic element that cannot start)
        raise SystemExit(f"[prs_element] hierarchical {variant}: {exc}; try more grains "
                         "(--n)") from exc
    m.set_region_element("element", mat)
    log(f"hierarchical {variant}: the region's material is a periodic element of {p.n} "
        f"grains, prepared at {np.round(-np.diag(mat.element.stress()) / 1e3, 2).tolist()} kPa"
        f" ({time.perf_counter() - t0:.1f} s)")
    n0 = len(m.history)
    load(m)
    steps = m.history[n0:]
    de = mat.strain_since_start()
    log(f"hierarchical {variant}: {len(steps)} load steps, Newton iterations "
        f"{[r.newton_iterations for r in steps]}, {mat.calls} element runs "
        f"({mat.dem_s:.1f} s of DEM)")
    return {"newton_iterations": [int(r.newton_iterations) for r in steps],
            "converged_on": [r.converged_on for r in steps], "warnings": list(m.warnings),
            **step_statuses(steps),
            "element_runs": mat.calls, "dem_s": mat.dem_s,
            "element_strain_increment": (-np.diag(de)).tolist(),
            "element_shear_strain_increment": [-de[1, 2], -de[0, 2], -de[0, 1]],  # yz xz xy
            "element_stress_final_pa": (-np.diag(mat.element.stress())).tolist(),
            "wall_time_s": time.perf_counter() - t0}


def run_cell_elements(p: Params, out: Path, variant: str, m, load) -> dict:
    """The load stage with every cell of the element region its own dense periodic element
    (``FemModel.set_cell_elements``; ``femcoupling.materials.dem_elements.PoolRegionMaterials`` on
    ``p.workers`` Dask workers, element k packed with seed ``p.seed + k`` at its cell's
    stress, ``p.cell_grains`` grains each), from the model's current (initial) state.
    Returns the record of the summary."""
    from dataclasses import replace

    from femcoupling.materials.dem_elements import PoolRegionMaterials

    t0 = time.perf_counter()
    cells = m.cell_stresses("element")
    runner = replace(periodic_runner(replace(p, n=p.cell_grains or p.n), out, variant),
                     cache_dir=None)  # (kept in the workers' memory)
    log(f"hierarchical {variant}: preparing {len(cells)} cell elements of {runner.n} grains "
        f"on {p.workers} Dask worker(s)")
    try:
        group = PoolRegionMaterials.build(cells, runner, workers=p.workers,
                                          distinct_seeds=True,
                                          records=out / f"region_element_{variant}.h5")
    except RuntimeError as exc:  # (a cell's periodic element that cannot start)
        raise SystemExit(f"[prs_element] hierarchical {variant}, cell elements: {exc}; try "
                         "more --cell-grains") from exc
    try:
        m.set_cell_elements("element", group)
        t_prep = time.perf_counter() - t0
        log(f"hierarchical {variant}: {len(cells)} cell elements prepared ({t_prep:.1f} s)")
        n0 = len(m.history)
        load(m)
        steps = m.history[n0:]
        strains = np.array([-np.diag(e) for e in group.strains()])  # compression +
        stresses = np.array([-np.diag(s) for s in group.stresses()])
        vol = m.cell_volume[[int(k.rsplit("/", 1)[1]) for k in group.names]]
    finally:
        group.close()
    log(f"hierarchical {variant}: {len(steps)} load steps, Newton iterations "
        f"{[r.newton_iterations for r in steps]}, {group.calls} evaluations of the "
        f"{len(cells)} elements ({group.dem_s:.1f} s of DEM); the cells' strain increment z "
        f"{strains[:, 2].min():.3g} to {strains[:, 2].max():.3g}")
    return {"newton_iterations": [int(r.newton_iterations) for r in steps],
            "converged_on": [r.converged_on for r in steps], "warnings": list(m.warnings),
            **step_statuses(steps),
            "element_runs": group.calls, "dem_s": group.dem_s, "cells": len(cells),
            # their volume mean: the region's (each cell's element strains as its cell)
            "element_strain_increment": (fixedorder.weighted_rows(vol, strains)
                                         / math.fsum(vol)).tolist(),
            "cell_grains": runner.n, "preparation_s": t_prep,
            "cell_strain_increments": strains.tolist(),
            "cell_stresses_final_pa": stresses.tolist(),
            "wall_time_s": time.perf_counter() - t0}


def loop_runner(p: Params, out: Path, variant: str):
    """The two-way loop's element runner (``p.two_way_element``): the case's element, or a
    dense periodic element of its grains
    (``femcoupling.materials.dem_elements.PeriodicRegionElement``, kept between iterations in
    ``out/region_elements/<variant>``)."""
    if p.two_way_element == "walls":
        return _Runner(p, out, variant)
    return periodic_runner(p, out, variant)


#: The largest Poisson's ratio the FEM soil takes (Drucker–Prager; near 0.5 it locks): a
#: larger fitted value is set to it, and the calibration record and the log say so.
POISSON_MAX = 0.45


def _element_secant(e: dict) -> tuple[float, float, float]:
    """(E Pa, nu fitted, nu) of an element summary's secant over its last stage (nu at most
    POISSON_MAX, E refitted then)."""
    from femcoupling.coupling.handover import secant_stiffness

    ds = np.subtract(e["stress_final_pa"], e["stress_initial_pa"])  # compression positive
    de = np.asarray(e["strain_increment"], float)
    E, nu_raw = secant_stiffness(stress_increment_pa=ds, strain_increment=de,
                                 poisson_bounds=(0.0, 0.4999))
    nu = min(nu_raw, POISSON_MAX)
    if nu < nu_raw:
        E, _ = secant_stiffness(stress_increment_pa=ds, strain_increment=de,
                                poisson_bounds=(nu, nu))
    return E, nu_raw, nu


#: The calibration's elements in a worker process, kept between its passes: per (run key,
#: seed) the element prepared and servoed to the initial targets (``run_element``'s cache).
_CALIBRATION_ELEMENTS: dict = {}


def next_soil_young(passes: list[dict]) -> tuple[float, str]:
    """The FEM soil's Young's modulus (Pa) for the calibration's next pass, and how it was
    chosen, from the passes so far (each row: ``soil_young_pa``, ``dem_fem_strain_ratio``,
    ``secant_young_pa``). The element's strain ratio grows with the FEM soil's modulus (a
    stiffer soil strains its region less), so the modulus that makes it 1 is a root:

    - when two passes bracket it (a ratio below 1 and one above), the modulus interpolated
      between the closest two in log-log (ln E linear in ln ratio, to ratio 1): inside the
      bracket, so the next pass narrows it;
    - otherwise the last pass's element secant (the soil that strains as the element did
      along that path): the first update, and any without a bracket.

    The plain secant update (the second rule alone) is a fixed-point iteration whose map
    falls with E; where it falls steeper than 1 : 1 in log-log it swings about the root
    (measured, the smoke element: ratios 87, 0.29, 2.3, 0.41 over four passes) and never
    lands inside [1/2, 2]; the bracket stops that."""
    rows = [r for r in passes if math.isfinite(float(r["dem_fem_strain_ratio"]))
            and float(r["dem_fem_strain_ratio"]) > 0 and float(r["soil_young_pa"]) > 0]
    below = [r for r in rows if float(r["dem_fem_strain_ratio"]) < 1.0]
    above = [r for r in rows if float(r["dem_fem_strain_ratio"]) > 1.0]
    if below and above:
        lo = max(below, key=lambda r: float(r["dem_fem_strain_ratio"]))
        hi = min(above, key=lambda r: float(r["dem_fem_strain_ratio"]))
        ra, rb = math.log(float(lo["dem_fem_strain_ratio"])), math.log(
            float(hi["dem_fem_strain_ratio"]))
        ea, eb = math.log(float(lo["soil_young_pa"])), math.log(float(hi["soil_young_pa"]))
        e = ea + (0.0 - ra) * (eb - ea) / (rb - ra)
        return math.exp(e), (f"interpolated to ratio 1 between passes {lo['pass']} and "
                             f"{hi['pass']} (ratios {math.exp(ra):.3g}, {math.exp(rb):.3g})")
    last = passes[-1]
    return float(last["secant_young_pa"]), f"the element's secant of pass {last['pass']}"


def _calibration_elements(q: Params, seeds: list, rows: list, tension: list | None, k: int,
                          out: Path, key: str) -> list[dict]:
    """Pass ``k``'s RE elements of ``seeds`` (in turn, in this process) along ``rows``
    (picklable: a calibration on several seeds runs groups of them side by side; each seed's
    element keeps its preparation between passes in the process that runs it)."""
    res = []
    for s in seeds:
        cache = _CALIBRATION_ELEMENTS.setdefault((key, int(s)), {})
        res.append(run_element(replace(q, seed=int(s)), rows, prestressed=False,
                               label=f"calibration_RE_s{s}_{k}", out=out, grid_tension=tension,
                               cache=cache, prepared={"file": packing_file(out, s)}))
    return res


def _mean_element(es: list[dict]) -> dict:
    """The seeds' mean element: the mean of their initial and final stresses and of their
    strain increments (one element when there is one)."""
    if len(es) == 1:
        return es[0]
    return {key: np.mean([np.asarray(e[key], float) for e in es], axis=0).tolist()
            for key in ("stress_initial_pa", "stress_final_pa", "strain_increment",
                        "porosity_final")}


def calibrate_soil(p: Params, out: Path, *, max_passes: int = 4,
                   keep: dict | None = None, seeds: list | None = None,
                   workers: int = 1, resume: bool = False) -> tuple[Params, dict]:
    """One soil on both scales (the default of the FEM modes): the FEM soil set to the case's
    own element, by passes. Each pass solves the RE FEM with the current soil, drives the
    case's element (the same grains, preparation and seed as the run's, so the same
    porosity; the geogrid's ends take the FEM layer's tension, so the walls carry the soil
    alone) along the element region's stress path (initial -> loaded), and compares the two:

    - if the element strains within [1/2, 2] times its FEM region (the largest normal
      strains, ``twoway.check_region``), the current soil is the element's along its own
      path: the calibration has converged and keeps it;
    - otherwise the next pass starts with the element's secant over that path (E, nu: least
      squares on the three normal components, ``handover.secant_stiffness``; nu above
      POISSON_MAX is set to it, said), except that once two passes bracket the ratio 1 the
      next E is interpolated between them (``next_soil_young``: the plain secant update swings
      about the root when the element's response to its path is steep); each row gives the
      next E and its rule (``next_young_pa``, ``next_rule``).

    The first pass starts from the given soil. The calibrated soil has no cohesion (the grains
    have none; the FEM then loads the footing as a rigid smooth footing to its pressure,
    ``FemModel.load_footing_to_pressure``) and the given phi (the element is not taken to
    its strength here; the record gives the friction it mobilised at the path's end).
    After ``max_passes`` without convergence the last update is kept and the record says
    ``converged`` False. Returns the parameters with that soil and the record (also
    ``calibration.json``). With ``keep`` (a dict) and a converged calibration, keep["RE"] is
    the last pass's ``run_fem`` result: the RE FEM with the returned soil, already solved
    (``run_variant(fem=)`` takes it instead of solving it again).

    ``seeds`` (default ``[p.seed]``): with several, each pass drives every seed's element
    (same grains and preparation, its own packing) along the path, and the soil is fitted to
    their mean (mean stresses, mean strain increment; the strain ratio is the mean's): one
    element is one sample of a chaotic packing, whose secant moves with the seed and with the
    CPU's rounding path; the mean moves about 1/sqrt(seeds) as much. ``workers`` (> 1): the
    seeds' elements in that many spawned processes (one thread each; each seed always in the
    same process, which keeps its preparation between passes), the same numbers as in one.
    Each pass's row lists the seeds' own ratios and secants (``seeds``).

    Each finished pass is written to ``calibration_passes.json`` (its row, the warnings and the
    soil of the next pass) before the next starts. With ``resume``, an interrupted calibration
    goes on from that file at the next pass, with the same numbers as one run without a
    break (every pass drives elements prepared afresh from the same seeds and preparation);
    a file of another calibration (other seeds, passes or starting soil) is refused, naming
    what differs."""
    from femcoupling.coupling.continuum_fit import friction_angle_deg
    from femcoupling.coupling.status import strain_ratio_held
    from femcoupling.coupling.twoway import check_region

    t0 = time.perf_counter()
    q = p
    passes, warnings = [], []
    converged = False
    seeds = [int(p.seed)] if seeds is None else [int(s) for s in seeds]
    if not seeds:
        raise ValueError("calibrate_soil: seeds=[]: give at least one element seed")
    before = {"young_pa": p.soil_young, "poisson": p.soil_poisson,
              "cohesion_pa": p.soil_cohesion, "friction_deg": p.soil_friction}
    progress = out / "calibration_passes.json"
    first, earlier_s = 1, 0.0
    if resume and progress.is_file():
        q, passes, warnings, earlier_s = _resumed_passes(progress, p, seeds, max_passes, before)
        first = len(passes) + 1
        log(f"--resume: the calibration goes on at pass {first} ({progress})")
    cache: dict = {}  # the element at the initial targets, prepared once for every pass
    n_groups = max(1, min(int(workers), len(seeds)))
    groups = [seeds[j::n_groups] for j in range(n_groups)]
    key = json.dumps([str(out), time.time_ns()])  # (this calibration's, in its workers)
    with contextlib.ExitStack() as stack:
        pools = ([stack.enter_context(process_pool(1)) for _ in groups] if len(groups) > 1
                 else [])
        for k in range(first, max_passes + 1):
            fem = run_fem(q, out, "RE")
            ini, fin, _m, _s0, _load, info = fem
            label = f"calibration_RE_{k}"
            tension = handed_tension(q, [ini, fin], label)
            rows = [ini.normal_pa, fin.normal_pa]
            if len(seeds) == 1:
                es = [run_element(q, rows, prestressed=False, label=label, out=out,
                                  grid_tension=tension, cache=cache,
                                  prepared={"file": packing_file(out, q.seed)})]
            elif pools:
                futs = [ex.submit(_calibration_elements, q, g, rows, tension, k, out, key)
                        for ex, g in zip(pools, groups)]
                by_seed = {}
                for g, f in zip(groups, futs):
                    by_seed.update(zip(g, wait_result(f)))
                es = [by_seed[s] for s in seeds]
            else:
                es = _calibration_elements(q, seeds, rows, tension, k, out, key)
            e = _mean_element(es)
            _msgs, ratio = check_region(label, fin,
                                        fem_strain_increment=info["strain_increment"],
                                        dem_strain_increment=e["strain_increment"])
            E, nu_raw, nu = _element_secant(e)
            row = {"pass": k, "soil_young_pa": q.soil_young, "soil_poisson": q.soil_poisson,
                   "soil_cohesion_pa": q.soil_cohesion, "dem_fem_strain_ratio": ratio,
                   "secant_young_pa": E, "secant_poisson_fitted": nu_raw, "secant_poisson": nu,
                   "rotation_deg": fin.rotation_deg,
                   "path_initial_pa": ini.normal_pa.tolist(), "path_final_pa": fin.normal_pa.tolist(),
                   "element_strain_increment": e["strain_increment"],
                   "fem_strain_increment": info["strain_increment"],
                   "porosity_element": e["porosity_final"],
                   "friction_mobilised_deg": friction_angle_deg(-np.diag(e["stress_final_pa"]))}
            if len(seeds) > 1:
                row["seeds"] = []
                for s, es_k in zip(seeds, es):
                    E_k, nu_k, _ = _element_secant(es_k)
                    row["seeds"].append({
                        "seed": s, "dem_fem_strain_ratio": check_region(
                            f"{label}_s{s}", fin, fem_strain_increment=info["strain_increment"],
                            dem_strain_increment=es_k["strain_increment"])[1],
                        "secant_young_pa": E_k, "secant_poisson_fitted": nu_k,
                        "element_strain_increment": es_k["strain_increment"],
                        "porosity_element": es_k["porosity_final"]})
                log(f"calibration pass {k}, the seeds' own: strain ratio "
                    + ", ".join(f"{r['dem_fem_strain_ratio']:.3g}" for r in row["seeds"])
                    + "; secant E " + ", ".join(f"{r['secant_young_pa'] / 1e6:.4g}"
                                                for r in row["seeds"]) + " MPa")
            passes.append(row)
            log(f"calibration pass {k}: soil E {q.soil_young / 1e6:.4g} MPa, nu "
                f"{q.soil_poisson:.3f}: the element strains {ratio:.3g} x its FEM region; its "
                f"secant along that path: E {E / 1e6:.4g} MPa, nu {nu_raw:.3f}")
            if k > 1 and strain_ratio_held(ratio):
                converged = True
                if keep is not None:  # (this pass's soil is the one returned)
                    keep["RE"] = fem
                break
            if nu < nu_raw:
                warnings.append(f"calibration pass {k}: the element's secant Poisson's ratio "
                                f"{nu_raw:.3f} is above the FEM soil's limit {POISSON_MAX}: nu = "
                                f"{POISSON_MAX} (E refitted: {E / 1e6:.4g} MPa)")
                log("WARNING: " + warnings[-1])
            E_next, rule = next_soil_young(passes)
            row["next_young_pa"], row["next_rule"] = E_next, rule
            if E_next != E:
                log(f"calibration pass {k}: next soil E {E_next / 1e6:.4g} MPa, {rule}")
            q = replace(q, soil_young=E_next, soil_poisson=nu, soil_cohesion=0.0)
            write_atomic(progress, json.dumps({
                "seeds": seeds, "max_passes": max_passes, "before": before, "passes": passes,
                "warnings": warnings, "wall_time_s": earlier_s + time.perf_counter() - t0,
                "next_soil": {"young_pa": E_next, "poisson": nu, "cohesion_pa": 0.0}},
                indent=2, default=float) + "\n")
    last = passes[-1]
    rec = {"method": ("the case's element along the RE region's path, by passes" if len(seeds)
                      == 1 else f"the mean of the case's elements of seeds {seeds} along the RE "
                      "region's path, by passes"), "seeds": seeds,
           "converged": converged, "passes": passes,
           "young_pa": q.soil_young, "poisson": q.soil_poisson, "cohesion_pa": 0.0,
           "friction_deg": p.soil_friction, "friction_source": "given",
           "friction_mobilised_deg": last["friction_mobilised_deg"],
           "dem_fem_strain_ratio": last["dem_fem_strain_ratio"] if converged else None,
           "porosity_element": last["porosity_element"],
           "before": before,
           "warnings": warnings, "wall_time_s": earlier_s + time.perf_counter() - t0}
    if not converged:
        warnings.append(f"calibration: no soil within {max_passes} passes made the element "
                        f"strain within [1/2, 2] x its FEM region (last "
                        f"{last['dem_fem_strain_ratio']:.3g}); the last update is kept")
        log("WARNING: " + warnings[-1])
    rec["message"] = (f"{'converged' if converged else 'NOT converged'} in {len(passes)} "
                      f"passes: E {q.soil_young / 1e6:.4g} MPa, nu {q.soil_poisson:.3f}, c = 0 "
                      f"(no cohesion in the grains), phi {p.soil_friction:g} deg as given (the "
                      f"element mobilised {last['friction_mobilised_deg']:.1f} deg at the "
                      f"path's end); element strain / FEM region strain by pass "
                      + ", ".join(f"{r['dem_fem_strain_ratio']:.3g}" for r in passes)
                      + f"; element porosity {last['porosity_element']:.4f}; "
                      f"{rec['wall_time_s']:.1f} s")
    log("calibration: " + rec["message"])
    (out / "calibration.json").write_text(json.dumps(rec, indent=2, default=float) + "\n")
    for s in seeds:  # (the grown packings: a finished calibration is not resumed)
        packing_file(out, s).unlink(missing_ok=True)
    return replace(q, soil_friction=p.soil_friction, soil_cohesion=0.0), rec


def _resumed_passes(path: Path, p: Params, seeds: list, max_passes: int, before: dict):
    """(the soil of the next pass, the passes, the warnings, the seconds they took) of an
    interrupted calibration (``calibration_passes.json``); a ValueError naming the field when
    the file is of another calibration."""
    try:
        got = json.loads(path.read_text())
        mine = {"seeds": seeds, "max_passes": max_passes, "before": before}
        for key, want in mine.items():
            if got[key] != want:
                raise ValueError(f"{path}: {key}={got[key]!r}, but this calibration has "
                                 f"{key}={want!r}: the file is another calibration's; remove "
                                 "it (or the run folder) to calibrate afresh")
        soil = got["next_soil"]
        q = replace(p, soil_young=float(soil["young_pa"]), soil_poisson=float(soil["poisson"]),
                    soil_cohesion=float(soil["cohesion_pa"]))
        return q, list(got["passes"]), list(got["warnings"]), float(got["wall_time_s"])
    except (KeyError, TypeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path}: not a calibration's passes ({type(e).__name__}: {e}); "
                         "remove it to calibrate afresh") from e


def fem_model(p: Params, prestressed: bool):
    """The FEM model of the structure in its initial state (geostatic, then the prestress)."""
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import DruckerPrager, GeogridLayerMaterial

    J = grid_stiffness_per_metre(p)
    layer = GeogridLayerMaterial(axial_stiffness_n_per_m=J,
                                 prestress_n_per_m=p.prestress if prestressed else 0.0)
    soil = DruckerPrager(young_pa=p.soil_young, poisson=p.soil_poisson,
                         cohesion_pa=p.soil_cohesion, friction_deg=p.soil_friction)
    m = FemModel(fem_body(p), soil=soil, layers=[layer] * len(p.layer_depths),
                  unit_weight_n_m3=p.unit_weight, newton_rtol=1e-6)
    m.set_geostatic()
    if prestressed:
        m.apply_prestress(steps=2)
    return m


def plot_fem(m, png: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from femcoupling.materials.continuum import mandel_to_tensor

    g = m.mesh.geometry
    cells = g.dofmaps[0][: m.n_owned]
    xy = g.x[:, :2][cells[:, :3]]
    szz = mandel_to_tensor(m.cell_mean_stress()[: m.n_owned])[:, 2, 2]
    fig, ax = plt.subplots(figsize=(9, 5))
    pc = PolyCollection(xy, array=szz / 1e3, cmap="viridis", edgecolors="none")
    ax.add_collection(pc)
    fig.colorbar(pc, ax=ax, label="sigma_zz (kPa, tension +)")
    tags = m.cell_tag_of[: m.n_owned]
    for tag, col in ((200, "red"),):
        sel = tags == tag
        if sel.any():
            ax.add_collection(PolyCollection(xy[sel], facecolors="none", edgecolors=col, lw=0.3))
    for k in range(len(m.layers)):
        sel = tags == 100 + k
        ax.add_collection(PolyCollection(xy[sel], facecolors="white", edgecolors="white",
                                         lw=0.2))
    r = m.body.regions[0]
    s = r.size_m / 2
    ax.plot([r.center_m[0] - s, r.center_m[0] + s, r.center_m[0] + s, r.center_m[0] - s,
             r.center_m[0] - s], [r.center_m[1] - s, r.center_m[1] - s, r.center_m[1] + s,
                                  r.center_m[1] + s, r.center_m[1] - s], "r-", lw=1.5,
            label="DEM element region")
    ax.set_xlim(0, min(m.body.width_m, 2.5))
    ax.set_ylim(m.body.height_m - 1.5, m.body.height_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.legend(loc="lower right")
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, png)
    plt.close(fig)


def run_fem(p: Params, out: Path, variant: str) -> tuple:
    """FEM of the structure for RE or PRS; returns (initial, final) WallTargets, the model,
    and numbers for the report."""
    from femcoupling.coupling.handover import on_grid, targets_on_grid
    from femcoupling.coupling.twoway import one_way

    t0 = time.perf_counter()
    prestressed = variant == "PRS"
    m = fem_model(p, prestressed)
    ncell = m.mesh.topology.index_map(m.tdim).size_global
    log(f"FEM {variant}: {ncell} cells (P2, plane strain), K0 state"
        + (f", prestress {p.prestress / 1e3:g} kN/m equilibrated: upper layer force "
           f"{m.layer_force_n_per_m(0) / 1e3:.3f} kN/m" if prestressed else ""))
    state0 = m.save_state()
    strain0 = m.region_strain("element")

    def load(model, xdmf: Path | None = None):
        """The footing load stage; with ``xdmf`` the state before it (time 0) and after each
        load step (time = load factor) are written there (ParaView: a time series)."""
        if xdmf is not None:
            model.write_xdmf(xdmf)

        def step(r) -> None:
            log(f"FEM {variant}: footing {r.footing_pressure_pa / 1e3:.1f} kPa, settlement "
                f"{1e3 * r.footing_settlement_m:.2f} mm, {r.newton_iterations} Newton its, "
                f"{r.plastic_points} plastic points")
            if xdmf is not None:
                model.write_xdmf(xdmf, time=r.load_factor, append=True)

        if p.soil_cohesion == 0:
            # (a pressure on a cohesionless surface fails at the footing's edge: the footing
            # is a rigid smooth one, pushed down until it carries the pressure)
            return model.load_footing_to_pressure(p.footing_pressure, steps=p.fem_steps,
                                                  callback=step)
        return model.load_footing(pressure_pa=p.footing_pressure, steps=p.fem_steps,
                                  callback=step)

    xdmf = out / f"fem_{variant}.xdmf"
    initial, final = one_way(m, regions=["element"], load=functools.partial(load, xdmf=xdmf))
    # (what the element takes, on the grid of TARGET_DIGITS: a last-bit change of the FEM, its
    # BLAS kernel's, cannot move it; other load steps of the FEM can: docs/prs_element_002.md)
    ini, fin = targets_on_grid(initial["element"]), targets_on_grid(final["element"])
    log(f"FEM {variant} handover, initial: {ini.report()}")
    log(f"FEM {variant} handover, loaded:  {fin.report()}")
    plot_fem(m, out / f"fem_{variant}.png", f"FEM {variant}: sigma_zz under "
             f"{p.footing_pressure / 1e3:g} kPa footing")
    info = {"cells": int(ncell), **fem_state(m),
            "grid_tension_n_per_m": [ini.grid_tension_n_per_m, fin.grid_tension_n_per_m],
            "strain_increment": on_grid(-np.diag(m.region_strain("element") - strain0)).tolist(),
            "wall_time_s": time.perf_counter() - t0}
    return ini, fin, m, state0, load, info


def fem_state(m) -> dict:
    """The FEM numbers of the report: settlement, upper layer force (everywhere and under the
    footing)."""
    return {"settlement_m": m.footing_settlement_m(),
            "layer_force_upper_n_per_m": m.layer_force_n_per_m(0),
            "layer_force_upper_under_footing_n_per_m":
                m.layer_force_n_per_m(0, x_range_m=(0.0, m.body.footing_half_width_m))}


def coupled_fem_state(m, info: dict, ini, fin, state: str, strain_increment) -> None:
    """The report and the summary (``info``) show the coupled FEM state (two-way or
    hierarchical): its numbers, the final targets, and the region's normal strain increment
    (compression positive). (Its XDMF series is written by the coupled load stage.)"""
    info.update(fem_state(m), shear_pa=fin.shear_pa.tolist(), rotation_deg=fin.rotation_deg,
                grid_tension_n_per_m=[ini.grid_tension_n_per_m, fin.grid_tension_n_per_m],
                targets_final_pa=fin.normal_pa.tolist(), state=state,
                strain_increment=np.asarray(strain_increment, float).tolist())


VARIANTS = ("RE", "PRS")
HISTORY_REGIONS = [f"element_{v}" for v in VARIANTS]


def run_variant(p: Params, out: Path, variant: str, fem: tuple | None = None) -> dict:
    """One variant (RE or PRS) of the FEM mode: its FEM (``fem``: a ``run_fem`` result of this
    variant with ``p``'s soil, already solved: the calibration's last pass), the two-way loop
    if asked, then the case's element driven to the (coupled) targets. Its handover rows go to
    ``out/handover_<variant>.h5`` (``run`` merges them into handover.h5). Returns the
    summary parts: {"fem": ..., "element": ..., "two_way": ... or None, "hierarchical": ...
    or None}."""
    from femcoupling.coupling.twoway import HandoverHistory, check_region, region_targets, two_way

    # One thread unless asked (as run_element): the periodic elements prepared here before it
    # ran with OpenMP's default, and two variants side by side then took 23 x longer.
    apply_threads(p.threads)
    j = VARIANTS.index(variant)
    hier = None
    if fem is None:
        fem = run_fem(p, out, variant)
    else:
        log(f"FEM {variant}: the calibration's last pass, with this soil (not solved again)")
    ini, fin, m, state0, load, info = fem
    # The coupled load stage writes the FEM state at every load step (two-way: each
    # iteration rewrites it, so the file holds the last, coupled one)
    load = functools.partial(load, xdmf=out / f"fem_{variant}.xdmf")
    info.update(shear_pa=fin.shear_pa.tolist(), rotation_deg=fin.rotation_deg,
                targets_initial_pa=ini.normal_pa.tolist(),
                targets_final_pa=fin.normal_pa.tolist())
    tws = None
    with HandoverHistory(out / f"handover_{variant}.h5", regions=HISTORY_REGIONS,
                         metadata={"case": "prs_element"}) as hist:
        if p.two_way:
            m.restore_state(state0)
            try:
                tw = two_way(m, regions=["element"], load=load,
                             element_runner=loop_runner(p, out, variant),
                             tol=p.two_way_tol, max_iterations=p.max_iterations,
                             history=hist, log=log, history_names=[f"element_{variant}"])
            except RuntimeError as exc:  # (a periodic element that cannot start)
                raise SystemExit(f"[prs_element] two-way {variant} with the "
                                 f"{p.two_way_element} element: {exc}; try "
                                 "--two-way-element walls") from exc
            fin = tw.targets["element"]
            stiff = tw.stiffnesses.get("element")
            st = tw.regions["element"]
            # status, reason, final_change, tol, axes_rotation_deg, dem_fem_strain_ratio,
            # checks: the loop's element against its region (femcoupling.coupling.status)
            resp = tw.responses.get("element")
            tws = {"element": p.two_way_element, **st.as_dict(),
                   # the loop element's porosity (periodic: dense; the case's element's is
                   # the element summary's porosity_final)
                   "porosity_loop_element": (resp.info or {}).get("porosity")
                   if resp is not None else None,
                   "iterations": tw.iterations,
                   "changes": [float(c) for c in tw.changes],
                   "materials": {k: list(v) for k, v in tw.materials.items()},
                   "stiffness_mandel_pa": None if stiff is None else stiff.tolist(),
                   "warnings": list(tw.warnings)}
            log(f"two-way {variant}: {st.line('status')} ({tw.iterations} FEM solves, "
                f"changes {np.round(tw.changes, 4).tolist()})")
            coupled_fem_state(m, info, ini, fin, "two-way",
                              tw.fem_strain_increments["element"])
        elif p.hierarchical:
            m.restore_state(state0)
            e0 = m.region_strain("element")
            hier = run_hierarchical(p, out, variant, m, load)
            fin = region_targets(m, "element")
            coupled_fem_state(m, info, ini, fin, "hierarchical",
                              -np.diag(m.region_strain("element") - e0))
            st = hierarchical_status(hier, info["strain_increment"], fin.rotation_deg)
            hier.update(st.as_dict())
            log(f"hierarchical {variant}: {st.line('status')}")
        label = f"element_{variant}"
        e = run_element(p, [ini.normal_pa, fin.normal_pa], prestressed=variant == "PRS",
                        label=label, out=out, grid_tension=handed_tension(p, [ini, fin], label))
        msgs, ratio = check_region(label, fin, fem_strain_increment=info["strain_increment"],
                                   dem_strain_increment=e["strain_increment"])
        e["dem_fem_strain_ratio"] = ratio
        e["warnings"] = msgs
        if tws is not None and tws.get("porosity_loop_element") is not None:
            log(f"two-way {variant}: porosity of the loop's periodic element "
                f"{tws['porosity_loop_element']:.4f}, of the case's element "
                f"{e['porosity_final']:.4f}")
        for msg in msgs:
            log("WARNING: " + msg)
        hist.append(iteration=0, region=j, fem_stress_pa=fin.fem_stress_pa,
                    targets_pa=fin.normal_pa, shear_pa=fin.shear_pa,
                    rotation_deg=fin.rotation_deg, change=0.0,
                    dem_stress_pa=e["stress_final_pa"],
                    grid_tension_n_per_m=fin.grid_tension_n_per_m)
    return {"fem": info, "element": e, "two_way": tws, "hierarchical": hier}
