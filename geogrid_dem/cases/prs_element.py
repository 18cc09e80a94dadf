#!/usr/bin/env python3
"""Prestressed reinforced-soil (PRS) element of 002, with its boundary stresses from a FEM model.

002 §3: a 0.1 m cube of grains with a geogrid at mid-height, six servo-controlled walls
driven to the stresses "calculated by a multiscale FEM analysis"; reinforced (RE) versus
prestressed reinforced (PRS) soil. Here:

1. **FEM** (``femcoupling``, dolfinx, plane strain): a reinforced fill under a strip footing
   (self-weight with a K0 state, two geogrid layers as thin bands of the geogrid's axial
   stiffness, Drucker–Prager soil matched to Mohr–Coulomb). Solved twice: RE (no prestress)
   and PRS (prestress T_p in the layers, equilibrated with the soil before the footing
   load). The stress averaged over the soil cells of the element region (a 0.1 m square on
   the upper layer under the footing) before and after the footing load is handed over
   (``femcoupling.handover.fem_to_dem``: tension positive -> compression positive; the shear
   components and the principal-axis rotation are reported, not imposed).
2. **DEM** (``cpp_dem``): a 0.1 m cube of spheres (the grains of 002 are clumps; spheres for
   now) with a square geogrid at mid-height (001 §5.1 layout; PET-like stiffness), prepared by
   radius growth, then servo walls to the initial (pre-load) stresses, then to the final ones.
   PRS: the grid's longitudinal (x) members are pulled at their ends by T_p x spacing (an
   external force on the end nodes: cpp_dem has no built-in prestress).
3. **Two-way** (``--two-way``): the element's stiffness goes back to the region's material
   (its tangent at the final state by three stress probes, ``--tangent-probe``, made to
   reproduce the handed-over increment; or, with ``--tangent-probe 0``, the isotropic
   secant) and the FEM re-solves until the handed-over stresses change by less than
   ``--tol``. ``--two-way-element periodic`` iterates with a dense
   periodic element of the case's grains instead (soil only: the full FEM tensor, shear
   included, and its tangent back as the region's full stiffness; the geogrid stays in the
   FEM's band), then drives the case's element to the converged targets.

DEM-only mode: ``--stresses sx,sy,sz`` (Pa, compression positive) or ``--stresses FILE.csv``
(columns sx,sy,sz, optionally time first: the element is driven through the rows in order)
runs the element with no FEM and **without importing dolfinx**.

Outputs in ``--out``: ``<label>.h5`` / ``<label>.csv`` (wall stresses, targets, box size,
geogrid forces; appended as the run goes), ``vtk/<label>_{spheres,contacts,geogrid,box}.vtp``
(contact force network, geogrid tensile forces), ``fem_<RE|PRS>.xdmf`` (displacement, stress,
cell tags: element region and layers marked; a time series: the state before the footing
load and after each load step, the coupled ones in two-way and hierarchical runs),
``fem_<RE|PRS>.png``, ``handover.h5`` (the handover history), ``report.md`` and
``summary.json``. SI units. DEM stresses and strains are
compression positive; FEM stresses tension positive.
"""

from __future__ import annotations

import functools
import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from cpp_dem.io.figures import save_figure
from geogrid_dem.cases import describe
from geogrid_dem.options import apply_threads, case_parser, check_common_args
from geogrid_dem.rundir import begin_run, end_run, run_main
from cpp_dem.elements import box as _element
from cpp_dem.elements.box import ElementParams, grid_axial_stiffness, grid_stiffness_per_metre



@dataclass
class Params(ElementParams):
    """Parameters of the PRS element case (SI): the DEM element's (cpp_dem.elements.box.
    ElementParams: grains, geogrid, servo) and the FEM structure's and coupling's below."""

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
    calibrate: bool = False          #: fit the FEM soil to a DEM element along the region's path
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


SMOKE = dict(n=300, hold_steps=600, fem_steps=3, mesh_size=1.0, fine_size=0.05,
             layer_thickness=0.02, max_steps=80_000, unbalanced=0.05)


def log(msg: str) -> None:
    print(f"[prs_element] {msg}", flush=True)


def make_element(p: Params, mean_stress: float, prestressed: bool):
    """The DEM element of :mod:`cpp_dem.elements.box` with this case's parameters and log."""
    return _element.make_element(p, mean_stress, prestressed, log=log)


def servo_stage(sample, grid, targets, stage: int, p: Params, rec) -> dict:
    return _element.servo_stage(sample, grid, targets, stage, p, rec, log=log)


def run_element(p: Params, targets: list, *, prestressed: bool, label: str, out: Path,
                cache: dict | None = None, grid_tension: list | None = None,
                probe: float = 0.0) -> dict:
    """:func:`cpp_dem.elements.box.run_element` with this case's log."""
    return _element.run_element(p, targets, prestressed=prestressed, label=label, out=out,
                                log=log, cache=cache, grid_tension=grid_tension, probe=probe)


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


def element_runner(p_dict: dict, out: str, name: str, initial, final):
    """Picklable two-way runner: the element from the initial to the final WallTargets. In
    one process the element at the initial targets is prepared once and restored for the
    next iterations (``_ELEMENTS``)."""
    from femcoupling.twoway import ElementResponse

    p = Params(**p_dict)
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
        self.p, self.out, self.variant = asdict(p), str(out), variant

    def __call__(self, name, initial, final):
        return element_runner(self.p, self.out, f"{name}_{self.variant}", initial, final)


# ---- FEM structure ---------------------------------------------------------------------------


def fem_body(p: Params):
    from femcoupling.geometry import ElementRegion, GeogridLayer, ReinforcedSoilBody

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
    (``femcoupling.region.PeriodicRegionElement``, kept in ``out/region_elements/<variant>``)."""
    from femcoupling.region import PeriodicRegionElement

    return PeriodicRegionElement(n=p.n, seed=p.seed, prep_friction_deg=0.0, tol=0.02,
                                 unbalanced=1e-2, options=periodic_options(p),
                                 cache_dir=str(out / "region_elements" / variant))


def run_hierarchical(p: Params, out: Path, variant: str, m, load) -> dict:
    """The load stage with the region's material a periodic DEM element inside the FEM's
    Newton (``SoilModel.set_region_element``, ``femcoupling.region.DemRegionMaterial``),
    from the model's current (initial) state; with ``p.cell_elements`` an element per cell
    (``run_cell_elements``). Returns the record of the summary."""
    from femcoupling.region import DemRegionMaterial

    if p.cell_elements:
        return run_cell_elements(p, out, variant, m, load)
    t0 = time.perf_counter()
    try:
        mat = DemRegionMaterial.prepared("element", m.region_stress("element"),
                                         periodic_runner(p, out, variant),
                                         records=out / f"region_element_{variant}.h5")
    except RuntimeError as exc:  # (a periodic element that cannot start)
        raise SystemExit(f"[prs_element] hierarchical {variant}: {exc}; try --calibrate"
                         ) from exc
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
            "element_runs": mat.calls, "dem_s": mat.dem_s,
            "element_strain_increment": (-np.diag(de)).tolist(),
            "element_shear_strain_increment": [-de[1, 2], -de[0, 2], -de[0, 1]],  # yz xz xy
            "element_stress_final_pa": (-np.diag(mat.element.stress())).tolist(),
            "wall_time_s": time.perf_counter() - t0}


def run_cell_elements(p: Params, out: Path, variant: str, m, load) -> dict:
    """The load stage with every cell of the element region its own dense periodic element
    (``SoilModel.set_cell_elements``; ``femcoupling.region.PoolRegionMaterials`` on
    ``p.workers`` Dask workers, element k packed with seed ``p.seed + k`` at its cell's
    stress, ``p.cell_grains`` grains each), from the model's current (initial) state.
    Returns the record of the summary."""
    from dataclasses import replace

    from femcoupling.region import PoolRegionMaterials

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
                         "--calibrate or more --cell-grains") from exc
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
            "element_runs": group.calls, "dem_s": group.dem_s, "cells": len(cells),
            # their volume mean: the region's (each cell's element strains as its cell)
            "element_strain_increment": (vol @ strains / vol.sum()).tolist(),
            "cell_grains": runner.n, "preparation_s": t_prep,
            "cell_strain_increments": strains.tolist(),
            "cell_stresses_final_pa": stresses.tolist(),
            "wall_time_s": time.perf_counter() - t0}


def loop_runner(p: Params, out: Path, variant: str):
    """The two-way loop's element runner (``p.two_way_element``): the case's element, or a
    dense periodic element of its grains (``femcoupling.region.PeriodicRegionElement``, kept
    between iterations in ``out/region_elements/<variant>``)."""
    if p.two_way_element == "walls":
        return _Runner(p, out, variant)
    return periodic_runner(p, out, variant)


def calibrate_soil(p: Params, out: Path) -> tuple[Params, dict]:
    """Scales that agree (issue 18): the FEM soil fitted to a DEM element along the element
    region's stress path (``femcoupling.calibration.fit_along_path``). The region's path is
    the RE one-way FEM's (initial -> loaded); the fitting element is periodic, soil only,
    with this case's grains (material, size, count), prepared dense (grown frictionless: the
    case's loose growth friction left a cell that could not hold the region's initial
    stress). The fill's apparent cohesion (``soil_cohesion``) is kept as given; E, nu and phi
    are fitted. Returns the parameters with the fitted soil and the record."""
    from femcoupling.calibration import fit_along_path

    t0 = time.perf_counter()
    ini, fin, _m, _s0, _load, _info = run_fem(p, out, "RE")
    fit = fit_along_path(ini.fem_stress_pa, fin.fem_stress_pa, n=p.n, seed=p.seed,
                         prep_friction_deg=0.0, tol=0.02, unbalanced=1e-2,
                         cohesion_pa=p.soil_cohesion, options=periodic_options(p), log=log)
    log("calibration: " + fit.message)
    m = fit.material
    rec = {"young_pa": m.young_pa, "poisson": m.poisson, "friction_deg": m.friction_deg,
           "cohesion_pa": m.cohesion_pa, "strength_reached": fit.strength_reached,
           "path_t_reached": float(fit.t[-1]), "message": fit.message,
           "before": {"young_pa": p.soil_young, "poisson": p.soil_poisson,
                      "cohesion_pa": p.soil_cohesion, "friction_deg": p.soil_friction},
           "wall_time_s": time.perf_counter() - t0}
    return replace(p, soil_young=m.young_pa, soil_poisson=m.poisson,
                   soil_friction=m.friction_deg), rec


def fem_model(p: Params, prestressed: bool):
    """The FEM model of the structure in its initial state (geostatic, then the prestress)."""
    from femcoupling.elastoplastic import SoilModel
    from femcoupling.materials import DruckerPrager, GeogridLayerMaterial

    J = grid_stiffness_per_metre(p)
    layer = GeogridLayerMaterial(axial_stiffness_n_per_m=J,
                                 prestress_n_per_m=p.prestress if prestressed else 0.0)
    soil = DruckerPrager(young_pa=p.soil_young, poisson=p.soil_poisson,
                         cohesion_pa=p.soil_cohesion, friction_deg=p.soil_friction)
    m = SoilModel(fem_body(p), soil=soil, layers=[layer] * len(p.layer_depths),
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

    from femcoupling.materials import mandel_to_tensor

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
    from femcoupling.twoway import one_way

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

        return model.load_footing(pressure_pa=p.footing_pressure, steps=p.fem_steps,
                                  callback=step)

    xdmf = out / f"fem_{variant}.xdmf"
    initial, final = one_way(m, regions=["element"], load=functools.partial(load, xdmf=xdmf))
    ini, fin = initial["element"], final["element"]
    log(f"FEM {variant} handover, initial: {ini.report()}")
    log(f"FEM {variant} handover, loaded:  {fin.report()}")
    plot_fem(m, out / f"fem_{variant}.png", f"FEM {variant}: sigma_zz under "
             f"{p.footing_pressure / 1e3:g} kPa footing")
    info = {"cells": int(ncell), **fem_state(m),
            "grid_tension_n_per_m": [ini.grid_tension_n_per_m, fin.grid_tension_n_per_m],
            "strain_increment": (-np.diag(m.region_strain("element") - strain0)).tolist(),
            "wall_time_s": time.perf_counter() - t0}
    return ini, fin, m, state0, load, info


def fem_state(m) -> dict:
    """The FEM numbers of the report: settlement, upper layer force (everywhere and under the
    footing)."""
    return {"settlement_m": m.footing_settlement_m(),
            "layer_force_upper_n_per_m": m.layer_force_n_per_m(0),
            "layer_force_upper_under_footing_n_per_m":
                m.layer_force_n_per_m(0, x_range_m=(0.0, m.body.footing_half_width_m))}


def grid_line(f: dict, e: dict) -> str:
    """The report's line on the geogrid tension across the region (FEM ``f``, element
    ``e``)."""
    t = f.get("grid_tension_n_per_m")
    if not t or t[0] is None:
        return "- no FEM geogrid layer crosses the region: the element's grid ends are free"

    def kn(x: list) -> list:
        return np.round(np.array(x, float) / 1e3, 4).tolist()

    if e.get("grid_tension_n_per_m") is None:
        return (f"- FEM geogrid tension across the region {kn(t)} kN/m, not handed over "
                "(--no-grid-handover): the grid counts in the walls' stress too")
    return (f"- FEM geogrid tension across the region {kn(t)} kN/m (initial, final), handed "
            f"to the element's grid ends as {kn(e['grid_tension_n_per_m'])} kN/m: "
            f"{e['grid_end_force_n']:.2f} N per line at the end; the end members carry "
            f"{e['grid_force_end_members_mean_n']:.2f} N")


def write_report(out: Path, summary: dict) -> None:
    lines = ["# PRS element: report", ""]
    mode = summary["mode"]
    lines.append(f"Mode: {mode}. Stresses in kPa, DEM compression positive.")
    lines.append("")
    for v, e in summary["elements"].items():
        ini = np.array(e["targets_pa"][0]) / 1e3
        fin = np.array(e["targets_pa"][-1]) / 1e3
        lines += [f"## {v}", "",
                  f"- targets initial {np.round(ini, 2).tolist()}, final "
                  f"{np.round(fin, 2).tolist()} kPa; walls reached "
                  f"{np.round(np.array(e['stress_final_pa']) / 1e3, 2).tolist()} kPa, held "
                  f"within {100 * e['hold_max_rel_error']:.2f} %",
                  f"- strain increment (x, y, z) {np.round(e['strain_increment'], 5).tolist()}"
                  + (f"; {e['dem_fem_strain_ratio']:.3g} times the FEM region's"
                     if "dem_fem_strain_ratio" in e else ""),
                  f"- mean |displacement| above / below the geogrid "
                  f"{1e3 * e['disp_above_grid_mean_m']:.3f} / "
                  f"{1e3 * e['disp_below_grid_mean_m']:.3f} mm",
                  f"- geogrid force, longitudinal mean {e['grid_force_longitudinal_mean_n']:.2f}"
                  f" N (max {e['grid_force_longitudinal_max_n']:.2f} N, CV "
                  f"{e['grid_force_longitudinal_cv']:.2f}), transverse mean "
                  f"{e['grid_force_transverse_mean_n']:.2f} N", ""]
        if v in summary.get("fem", {}):
            f = summary["fem"][v]
            lines += [f"- FEM: {f['cells']} cells, settlement {1e3 * f['settlement_m']:.2f} mm,"
                      f" upper layer force {f['layer_force_upper_n_per_m'] / 1e3:.3f} kN/m; "
                      f"handover shear (yz, xz, xy) "
                      f"{np.round(np.array(f['shear_pa']) / 1e3, 2).tolist()} kPa, principal "
                      f"axes turned {f['rotation_deg']:.1f} deg from the walls",
                      grid_line(f, e), ""]
    if "two_way" in summary:
        lines += ["## Two-way", ""]
        for v, t in summary["two_way"].items():
            how = ("its network tangent" if t.get("element") == "periodic"
                   else "its tangent by stress probes")
            kind = (f"{how} made to reproduce the increment (isotropic part E, nu)"
                    if t.get("stiffness_mandel_pa") else "isotropic secant (E, nu)")
            lines.append(f"- {v}: {'converged' if t['converged'] else 'NOT converged'} "
                         f"({t['converged_on']}) in {t['iterations']} FEM solves with the "
                         f"{t.get('element', 'walls')} element; changes {t['changes']}; "
                         f"{kind} {t['materials']}")
        lines.append("")
    if "hierarchical" in summary:
        lines += ["## Hierarchical", ""]
        for v, h in summary["hierarchical"].items():
            if "cells" in h:
                ez = [e[2] for e in h["cell_strain_increments"]]
                sz = [s[2] for s in h["cell_stresses_final_pa"]]
                lines.append(f"- {v}: an element of {h['cell_grains']} grains per cell of the "
                             f"region ({h['cells']} cells) inside the FEM's Newton: "
                             f"iterations per load step {h['newton_iterations']}, "
                             f"{h['element_runs']} evaluations ({h['dem_s']:.1f} s of DEM, "
                             f"preparation {h['preparation_s']:.1f} s); the cells' strain "
                             f"increment z {min(ez):.3g} to {max(ez):.3g}, stress z "
                             f"{min(sz) / 1e3:.1f} to {max(sz) / 1e3:.1f} kPa")
                continue
            lines.append(f"- {v}: the region's material a periodic DEM element inside the "
                         f"FEM's Newton: iterations per load step {h['newton_iterations']}, "
                         f"{h['element_runs']} element runs ({h['dem_s']:.1f} s of DEM); its "
                         f"strain increment (x, y, z) "
                         f"{np.round(h['element_strain_increment'], 6).tolist()} (the "
                         "region's, by construction)")
        lines.append("")
    if "calibration" in summary:
        c = summary["calibration"]
        b = c["before"]
        lines += ["## Calibration of the FEM soil", "",
                  f"- {c['message']}",
                  f"- FEM soil: E {b['young_pa'] / 1e6:.3g} -> {c['young_pa'] / 1e6:.3g} MPa, "
                  f"nu {b['poisson']:.3f} -> {c['poisson']:.3f}, c {b['cohesion_pa'] / 1e3:g}"
                  f" -> {c['cohesion_pa'] / 1e3:g} kPa, phi {b['friction_deg']:.1f} -> "
                  f"{c['friction_deg']:.1f} deg", ""]
    warns = [w for e in summary["elements"].values() for w in e.get("warnings", [])]
    warns += [w for t in summary.get("two_way", {}).values() for w in t["warnings"]]
    warns += [w for h in summary.get("hierarchical", {}).values() for w in h["warnings"]]
    lines += [f"## Warnings ({len(warns)})", ""] + [f"- {w}" for w in warns] + [""]
    (out / "report.md").write_text("\n".join(lines) + "\n")


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


def run_variant(p: Params, out: Path, variant: str) -> dict:
    """One variant (RE or PRS) of the FEM mode: its FEM, the two-way loop if asked, then the
    case's element driven to the (coupled) targets. Its handover rows go to
    ``out/handover_<variant>.h5`` (``run`` merges them into handover.h5). Returns the
    summary parts: {"fem": ..., "element": ..., "two_way": ... or None, "hierarchical": ...
    or None}."""
    from femcoupling.twoway import HandoverHistory, check_region, region_targets, two_way

    # One thread unless asked (as run_element): the periodic elements prepared here before it
    # ran with OpenMP's default, and two variants side by side then took 23 x longer.
    apply_threads(p.threads)
    j = VARIANTS.index(variant)
    hier = None
    ini, fin, m, state0, load, info = run_fem(p, out, variant)
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
                                 "--calibrate, or --two-way-element walls") from exc
            fin = tw.targets["element"]
            stiff = tw.stiffnesses.get("element")
            tws = {"element": p.two_way_element,
                   "converged": tw.converged, "converged_on": tw.converged_on,
                   "iterations": tw.iterations,
                   "changes": [float(c) for c in tw.changes],
                   "materials": {k: list(v) for k, v in tw.materials.items()},
                   "stiffness_mandel_pa": None if stiff is None else stiff.tolist(),
                   "warnings": list(tw.warnings)}
            log(f"two-way {variant}: {'converged' if tw.converged else 'NOT converged'}"
                f" ({tw.converged_on}) after {tw.iterations} FEM solves, changes "
                f"{tw.changes}")
            coupled_fem_state(m, info, ini, fin, "two-way",
                              tw.fem_strain_increments["element"])
        elif p.hierarchical:
            m.restore_state(state0)
            e0 = m.region_strain("element")
            hier = run_hierarchical(p, out, variant, m, load)
            fin = region_targets(m, "element")
            coupled_fem_state(m, info, ini, fin, "hierarchical",
                              -np.diag(m.region_strain("element") - e0))
        label = f"element_{variant}"
        e = run_element(p, [ini.normal_pa, fin.normal_pa], prestressed=variant == "PRS",
                        label=label, out=out, grid_tension=handed_tension(p, [ini, fin], label))
        msgs, ratio = check_region(label, fin, fem_strain_increment=info["strain_increment"],
                                   dem_strain_increment=e["strain_increment"])
        e["dem_fem_strain_ratio"] = ratio
        e["warnings"] = msgs
        for msg in msgs:
            log("WARNING: " + msg)
        hist.append(iteration=0, region=j, fem_stress_pa=fin.fem_stress_pa,
                    targets_pa=fin.normal_pa, shear_pa=fin.shear_pa,
                    rotation_deg=fin.rotation_deg, change=0.0,
                    dem_stress_pa=e["stress_final_pa"],
                    grid_tension_n_per_m=fin.grid_tension_n_per_m)
    return {"fem": info, "element": e, "two_way": tws, "hierarchical": hier}


def run_variants(p: Params, out: Path) -> list:
    """RE and PRS (``run_variant``), in two processes with ``p.workers`` >= 2 (spawned: no fork
    of an MPI/PETSc process; each is the serial run's, so the results are the same)."""
    if p.workers < 2 or p.cell_elements:  # (cell elements: the workers are Dask's)
        return [run_variant(p, out, v) for v in VARIANTS]
    import concurrent.futures
    import multiprocessing

    log(f"--workers {p.workers}: RE and PRS run in two processes")
    ctx = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=2, mp_context=ctx) as ex:
        return list(ex.map(run_variant, [p] * len(VARIANTS), [out] * len(VARIANTS),
                           VARIANTS))


def run(p: Params, out: Path) -> dict:
    t_start = time.perf_counter()
    begin_run(out, "prs_element", log=log)
    summary: dict = {"params": {k: v for k, v in asdict(p).items()}, "elements": {}}
    if p.stresses:
        summary["mode"] = "DEM-only (stresses given)"
        log(f"DEM-only: {len(p.stresses)} target row(s), no FEM")
        summary["elements"]["PRS" if p.prs else "RE"] = run_element(
            p, p.stresses, prestressed=p.prs, label="element", out=out)
    else:
        from femcoupling.twoway import HandoverHistory

        summary["mode"] = "FEM -> DEM" + (" (two-way)" if p.two_way else " (hierarchical)"
                                          if p.hierarchical else " (one-way)")
        if p.two_way and p.two_way_element == "periodic":
            log("two-way element: periodic, soil only (the full FEM tensor, its tangent back "
                "as the region's stiffness); the geogrid stays in the FEM's layer band, "
                "counted once; the case's element, geogrid included, is then driven to the "
                "converged targets")
        if p.calibrate:
            p, summary["calibration"] = calibrate_soil(p, out)
        parts = run_variants(p, out)
        summary["fem"] = {v: r["fem"] for v, r in zip(VARIANTS, parts)}
        summary["elements"] = {v: r["element"] for v, r in zip(VARIANTS, parts)}
        if p.two_way:
            summary["two_way"] = {v: r["two_way"] for v, r in zip(VARIANTS, parts)}
        if p.hierarchical:
            summary["hierarchical"] = {v: r["hierarchical"] for v, r in zip(VARIANTS, parts)}
        # one handover record, RE's rows then PRS's, whatever ran where
        with HandoverHistory(out / "handover.h5", regions=HISTORY_REGIONS,
                             metadata={"case": "prs_element"}) as hist:
            for v in VARIANTS:
                part = out / f"handover_{v}.h5"
                hist.append_file(part)
                part.unlink()
    summary["wall_time_total_s"] = time.perf_counter() - t_start
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    end_run(out)
    write_report(out, summary)
    for v, e in summary["elements"].items():
        log(f"{v}: walls held within {100 * e['hold_max_rel_error']:.2f} %; |u| above/below "
            f"grid {1e3 * e['disp_above_grid_mean_m']:.3f}/{1e3 * e['disp_below_grid_mean_m']:.3f}"
            f" mm; longitudinal grid force {e['grid_force_longitudinal_mean_n']:.2f} N")
    log(f"done in {summary['wall_time_total_s']:.1f} s; report in {out / 'report.md'}")
    return summary


# ---- command line ----------------------------------------------------------------------------


def apply_coupling_preset(p: Params, name: str) -> Params:
    """The coupling part of a speed-accuracy preset (cpp_dem.presets): fine FEM mesh size =
    preset.fem_size_per_element x the element edge (coarse size 20 x that) and the two-way
    tolerance. The DEM element's own settings are not changed."""
    from cpp_dem.presets import preset

    ps = preset(name)
    h = ps.fem_size_per_element * p.edge
    log(f"preset {name!r}: fine FEM mesh {h:g} m, coarse {20 * h:g} m, two-way tolerance "
        f"{ps.two_way_tol:g}")
    return replace(p, fine_size=h, mesh_size=20 * h, two_way_tol=ps.two_way_tol)


def parse_stresses(text: str, ap) -> list:
    """'sx,sy,sz' (Pa) or a CSV file with columns sx,sy,sz (optionally time first)."""
    path = Path(text)
    rows = []
    if path.suffix.lower() == ".csv" or path.is_file():
        if not path.is_file():
            ap.error(f"--stresses={text}: no such file")
        for k, line in enumerate(path.read_text().splitlines()):
            cells = [c.strip() for c in line.split(",") if c.strip()]
            if not cells or cells[0].startswith("#"):
                continue
            try:
                vals = [float(c) for c in cells]
            except ValueError:
                if k == 0:
                    continue  # header
                ap.error(f"--stresses={text}: line {k + 1} {line!r} is not numbers")
            if len(vals) == 4:
                vals = vals[1:]
            if len(vals) != 3:
                ap.error(f"--stresses={text}: line {k + 1} has {len(vals)} values, need 3 "
                         "(sx,sy,sz) or 4 (time,sx,sy,sz)")
            rows.append(vals)
    else:
        try:
            vals = [float(c) for c in text.split(",")]
        except ValueError:
            ap.error(f"--stresses={text!r}: need three numbers sx,sy,sz in Pa")
        if len(vals) != 3:
            ap.error(f"--stresses={text!r}: need three numbers sx,sy,sz in Pa, got {len(vals)}")
        rows.append(vals)
    if not rows:
        ap.error(f"--stresses={text}: no rows")
    for row in rows:
        for name, v in zip(("sx", "sy", "sz"), row):
            if not (math.isfinite(v) and v > 0):
                ap.error(f"--stresses: {name}={v}: must be > 0 (Pa, compression positive; "
                         "servo walls only push)")
    return rows


def element_parser(name: str, description: str, d, *, smoke: str, preset: str | None = None):
    """The parser of an element case (``name``: its command name) with the options the
    element cases share: the common ones (geogrid_dem.options.case_parser; one thread by
    default), --stresses, --n, --prestress and --footing-pressure (defaults from the
    parameters ``d``)."""
    ap = case_parser(name, describe(name, description), smoke=smoke, seed=d.seed,
                     threads=d.threads, preset=preset)
    ap.add_argument("--stresses", type=str, default="",
                    help="DEM-only: 'sx,sy,sz' in Pa (compression positive) or a CSV table "
                         "(sx,sy,sz or time,sx,sy,sz per row, driven in order)")
    ap.add_argument("--n", type=int, default=None, help=f"number of grains (default {d.n})")
    ap.add_argument("--prestress", type=float, default=d.prestress,
                    help="PRS prestress T_p, N/m (>= 0; 0: PRS is RE)")
    ap.add_argument("--footing-pressure", type=float, default=d.footing_pressure,
                    help="FEM footing pressure, Pa (> 0)")
    return ap


def apply_element_args(ap, a, p):
    """Checks the shared options (element_parser) and sets them on ``p``; returns it."""
    check_common_args(ap, a)
    if a.n is not None:
        if a.n < 50:
            ap.error(f"--n={a.n}: must be >= 50")
        p.n = a.n
    if not (math.isfinite(a.prestress) and a.prestress >= 0):
        ap.error(f"--prestress={a.prestress}: must be >= 0 (N/m)")
    if not (math.isfinite(a.footing_pressure) and a.footing_pressure > 0):
        ap.error(f"--footing-pressure={a.footing_pressure}: must be > 0 (Pa)")
    p.prestress, p.footing_pressure, p.seed, p.threads = (a.prestress, a.footing_pressure,
                                                           a.seed, a.threads)
    return p


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    d = Params()
    ap = element_parser(
        "prs-element", "Reinforced (RE) and prestressed (PRS) soil element: a 0.1 m cube of "
        "grains with a geogrid, servo walls driven to FEM stresses, or to given stresses "
        "(--stresses, DEM only, no dolfinx). z is vertical; DEM stresses compression "
        "positive.", d, smoke=f"{SMOKE['n']} grains, coarse FEM mesh",
        preset="of the coupling: fine FEM mesh size (x the element edge; coarse size 20 x "
               "that) and the two-way tolerance (overrides --tol)")
    ap.add_argument("--prs", action="store_true",
                    help="DEM-only: prestress the geogrid by --prestress (default: RE)")
    ap.add_argument("--two-way", action="store_true", help="iterate FEM <-> DEM")
    ap.add_argument("--tol", type=float, default=d.two_way_tol,
                    help="two-way tolerance on the handed-over stresses, relative")
    ap.add_argument("--max-iterations", type=int, default=d.max_iterations,
                    help="most FEM <-> DEM iterations of the two-way loop")
    ap.add_argument("--workers", type=int, default=1,
                    help="processes: 2 or more runs RE and PRS (each its FEM, two-way loop "
                         "and element) side by side, with the same results; with "
                         "--cell-elements, the Dask workers of the cells' elements (RE and "
                         "PRS one after the other)")
    ap.add_argument("--two-way-element", choices=("walls", "periodic"), default="walls",
                    help="the two-way loop's element: the case's (walls, geogrid included; "
                         "its tangent by stress probes back) or a dense periodic one of its "
                         "grains (soil only, the full tensor; its network tangent back)")
    ap.add_argument("--tangent-probe", type=float, default=d.tangent_probe,
                    help="the walls element's tangent in the two-way loop: three stress "
                         "probes of this size relative to the mean stress; 0: the isotropic "
                         "secant instead")
    ap.add_argument("--hierarchical", action="store_true",
                    help="the region's material is a dense periodic DEM element of the case's "
                         "grains inside the FEM's Newton (stress and tangent at every "
                         "iterate; no two-way loop); the case's element is then driven to the "
                         "coupled targets")
    ap.add_argument("--cell-elements", action="store_true",
                    help="with --hierarchical: an element per cell of the element region "
                         "(each at its cell's stress, its own seed), on --workers Dask workers")
    ap.add_argument("--cell-grains", type=int, default=0,
                    help="grains of each cell's element with --cell-elements (default: --n)")
    ap.add_argument("--no-grid-handover", action="store_true",
                    help="leave the element's grid ends free (RE) or in the locked grips "
                         "(PRS) instead of pulling them by the FEM layer's tension across the "
                         "region (then the grid also counts in the walls' stress: twice)")
    ap.add_argument("--calibrate", action="store_true",
                    help="fit the FEM soil (Drucker-Prager/Mohr-Coulomb) to a DEM element of "
                         "the case's grains along the region's stress path first")
    return ap


def parse_args(argv=None) -> tuple[Params, Path]:
    ap = build_parser()
    a = ap.parse_args(argv)
    p = apply_element_args(ap, a, Params(**SMOKE) if a.smoke else Params())
    if not (math.isfinite(a.tol) and 0 < a.tol < 1):
        ap.error(f"--tol={a.tol}: must be in (0, 1): the relative change of the handed-over "
                 "stresses that ends the two-way loop (1 or more would accept any change)")
    if a.max_iterations < 2:
        ap.error(f"--max-iterations={a.max_iterations}: must be >= 2")
    if a.workers < 1:
        ap.error(f"--workers={a.workers}: must be >= 1")
    p.two_way, p.two_way_tol, p.max_iterations, p.workers = (a.two_way, a.tol, a.max_iterations,
                                                             a.workers)
    p.calibrate = a.calibrate
    p.grid_handover = not a.no_grid_handover
    if a.hierarchical and a.two_way:
        ap.error("--hierarchical: the element is inside the FEM's Newton; not with --two-way")
    p.hierarchical = a.hierarchical
    if a.cell_elements and not a.hierarchical:
        ap.error("--cell-elements: elements per cell of the region's material; needs "
                 "--hierarchical")
    if a.cell_grains and not a.cell_elements:
        ap.error(f"--cell-grains={a.cell_grains}: the cells' elements; needs --cell-elements")
    if a.cell_grains and a.cell_grains < 50:
        ap.error(f"--cell-grains={a.cell_grains}: must be >= 50 (or 0: --n)")
    p.cell_elements, p.cell_grains = a.cell_elements, a.cell_grains
    if a.no_grid_handover and a.stresses:
        ap.error("--no-grid-handover: the grid tension comes from the FEM; not with --stresses")
    if a.two_way_element != "walls" and not a.two_way:
        ap.error(f"--two-way-element {a.two_way_element}: the loop's element; needs --two-way")
    p.two_way_element = a.two_way_element
    if not 0 <= a.tangent_probe <= 0.5:
        ap.error(f"--tangent-probe={a.tangent_probe}: the probe's size relative to the mean "
                 "stress, in (0, 0.5], or 0 for the isotropic secant")
    p.tangent_probe = a.tangent_probe
    if a.preset:
        if a.stresses:
            ap.error("--preset sets the FEM mesh and the two-way tolerance: not with --stresses")
        p = apply_coupling_preset(p, a.preset)
    if a.stresses:
        if a.two_way or a.calibrate or a.hierarchical:
            ap.error("--two-way, --hierarchical and --calibrate need the FEM: not with "
                     "--stresses")
        p.stresses = parse_stresses(a.stresses, ap)
        p.prs = a.prs
    elif a.prs:
        ap.error("--prs is for DEM-only runs (--stresses); the FEM mode runs RE and PRS")
    return p, a.out


def main(argv=None) -> int:
    p, out = parse_args(argv)
    return run_main("prs_element", out, lambda o: run(p, o))


if __name__ == "__main__":
    sys.exit(main())
