"""The FEM side of ``geogrid-dem run footing-multiscale``: a strip footing on geogrid-reinforced
soil in plane strain, with a DEM element at every cell of the zone under the footing; or, with
``dim = 3``, a square footing in 3D.

The body (``femcoupling.fem.geometry``: the half next to the symmetry plane x = 0, z up) has
a square zone of edge b (the footing's half width) right under the footing. In 3D the body is
the quarter next to the planes x = 0 and y = 0 under a square footing 2b x 2b, ``width`` in x
and in y, and the zone a cube of edge b under it; the layer covers the body across y. The
run:

1. **Calibration.** The Drucker–Prager soil outside the zone is fitted on
   ``calibration_elements`` elements of the zone's own grains (their mean): E and nu each
   one's secant along the zone's mean stress path in a first FEM of the unreinforced body
   (from the seating pressure to the largest,
   ``femcoupling.coupling.continuum_fit.fit_along_path``), phi the peak of its plane-strain
   biaxial test at the path's final mean pressure; no cohesion (:func:`calibrate`).
2. **Variants** ``unreinforced``, ``RE`` (one geogrid layer: an elastic band of axial
   stiffness J, N/m) and ``PRS`` (the same layer with its prestress T_p locked in,
   ``FemModel.apply_prestress``). Each starts geostatic (K0 by Jaky; a fitted soil above
   35.9 deg starts on its yield cone instead: docs/fem.md), the footing is seated to
   ``seat_pa`` as a rigid smooth footing with the fitted soil everywhere, and then every
   soil cell of the zone takes its own dense periodic DEM element, prepared at that cell's
   stress (``FemModel.set_cell_elements``,
   ``femcoupling.materials.dem_elements.PoolRegionMaterials`` on Dask workers: element k of seed s
   packed with seed ``1000 s + k``). The layer's cells inside the zone stay the FEM band, or, with
   ``band_grains`` > 0, each gets a reinforced RVE
   (``femcoupling.materials.dem_elements.ReinforcedBandElement``: the woven sheet and grains, the
   sheet at the band cell's tension, the grains at the pressure of the zone's soil cells around it;
   band element j packed with seed ``1000 s + 500 + j``, 100 further at each new preparation
   attempt) in the same pool. The footing is then pushed to each load level in turn
   (``load_footing_to_pressure``); the settlement at each level is recorded where the
   footing stopped and at the level's own pressure (``at_level``).
3. **The same body with the fitted Drucker–Prager everywhere** (the zone too), for each
   variant: the continuum answer the DEM zone is compared with. These bodies run before the
   DEM zones: Newton's ceiling for the zone's steps is set from their settlements and the
   difference the run is to resolve (``zone_ceiling``, ``resolve_m``).

Every variant runs the same seeds, so the differences between variants are paired over
seeds (mean and standard error), at each level's pressure. SI units; FEM stresses tension
positive; pressures and settlements compression / downward positive.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

import numpy as np
from cpp_dem import fixedorder

from femcoupling.coupling.handover import target_grid
from femcoupling.fem.steps import NewtonFailure
from femcoupling.materials.dem_elements import BAND_TANGENTS
from geogrid_dem.provenance import code_record
from geogrid_dem.stats import t_critical
from geogrid_dem.studies import biaxial
from geogrid_dem.studies.prs_element import hierarchical_status, step_statuses

VARIANTS = ("unreinforced", "RE", "PRS")
#: The numerical error budget of a paired difference (issue 62): each part is measured by
#: rerunning the variants with one thing changed, the part being how far the difference moves.
#: The seeds' part (t(0.975, n - 1) x its standard error) is always measured.
BUDGET_PARTS = {
    "ceiling": "Newton's noise ceiling halved",
    "calibration": "the continuum refitted on the next calibration_elements element seeds",
    "rve": "twice the grains in every element",
    "mesh": "the zone's cells fine_size / sqrt(2) (about twice as many)"}
#: The Voigt components of the elements' finite-difference tangents: the x-z plane's in plane
#: strain (xx, zz, xz), all six in 3D.
FD_COMPONENTS = {2: (0, 2, 4), 3: (0, 1, 2, 3, 4, 5)}
#: The calibration's first FEM (the starting soil) that stops short of the largest pressure
#: gives the zone's path as far as it went if the footing's pressure rose by at least this
#: fraction of what was asked (in 3D with 0.35 and 0.25 m zone cells, the 35-degree starting
#: soil carried 87 kPa of 100: docs/studies/footing_multiscale.md); else the run stops.
PATH_SHORT_MIN = 0.5


@dataclasses.dataclass
class FootingParams:
    """The case's parameters (SI units)."""

    footing_b: float = 0.5          #: footing half width b, m; the DEM zone is b x b under it
    width: float = 3.0              #: body width from the symmetry plane, m
    height: float = 2.0             #: body height, m
    unit_weight: float = 18e3       #: soil unit weight, N/m^3
    layer_depth: float = 0.15       #: geogrid layer's depth below the surface, m
    layer_length: float = 1.5       #: geogrid layer's length from the symmetry plane, m
    layer_thickness: float = 0.02   #: the layer's band thickness, m
    grid_stiffness: float = 632257.0  #: J, N/m (002's woven grid, detailed, in series)
    prestress: float = 2000.0       #: PRS: T_p, N/m (002's)
    seat_pa: float = 20e3           #: seating pressure before the DEM zone takes over, Pa
    pressure_pa: float = 100e3      #: the largest footing pressure, Pa
    levels: int = 4                 #: load levels from the seating to ``pressure_pa``
    steps_per_level: int = 2        #: FEM load steps aimed at per level
    mesh_size: float = 0.5          #: FEM cell size far from the footing, m
    fine_size: float = 0.125        #: FEM cell size in the zone and along the layer, m
    cell_grains: int = 150          #: grains of each cell's periodic element
    band_grains: int = 0            #: grains of the reinforced RVE of each of the layer's
                                    #: cells in the zone (0: they stay the FEM's band)
    band_tangent: str = "network"   #: their tangent: "network" (with the sheet's bonds),
                                    #: "network-elastic" or "fd-forward" (dem_elements)
    radius_mean: float = 0.003      #: the grains' mean radius, m
    radius_spread: float = 0.2      #: radii uniform in r_mean (1 +- spread), -
    young: float = 50e6             #: grain Young's modulus (linear law), Pa
    poisson: float = 0.23           #: grain k_s / k_n, -
    friction_deg: float = 38.66     #: grain friction, deg
    density: float = 2640.0         #: grain density, kg/m^3
    seeds: tuple = (1, 2, 3)        #: seeds of the zone's elements (one run per seed)
    workers: int = 2                #: Dask workers of the zone's elements
    soil_young: float = 20e6        #: the first FEM's soil (calibration's start), Pa
    soil_poisson: float = 0.3       #: the first FEM's soil, -
    soil_friction: float = 35.0     #: the first FEM's soil, deg
    fit_points: int = 8             #: calibration: path points up to 4 x the zone's path
    variants: tuple = VARIANTS      #: which variants to run
    threads: int = 1                #: OpenMP threads of this process (the FEM; the elements
                                    #: run one thread each on their workers)
    dim: int = 2                    #: 2: a strip footing in plane strain; 3: a square one
    noise_ceiling: float = 1e-2     #: Newton: a DEM zone step is accepted within the
                                    #: elements' noise only up to this fraction of the
                                    #: zone's own internal force, -
    calibration_seed: int | None = None  #: the first element seed the continuum is fitted
                                    #: on (None: ``seeds[0]``)
    calibration_elements: int = 16  #: elements the continuum is fitted on (seeds from
                                    #: ``calibration_seed`` on; their mean: calibrate)
    resolve_m: float | None = None  #: the smallest settlement difference the run is to
                                    #: resolve, m: the zone's ceiling is then set from it
                                    #: (zone_ceiling); None: noise_ceiling
    budget: tuple = ()              #: the error budget's parts measured by reruns
                                    #: (BUDGET_PARTS; the seeds' part is always measured)

    def check(self) -> None:
        """Refuses a bad value, naming the field, the value and what is allowed."""
        from femcoupling import FemInputError

        def bad(name, allowed):
            raise FemInputError(f"{name}={getattr(self, name)!r}: must be {allowed}")

        for name in ("footing_b", "width", "height", "layer_depth", "layer_length",
                     "layer_thickness", "grid_stiffness", "seat_pa", "pressure_pa",
                     "mesh_size", "fine_size", "radius_mean", "young", "density",
                     "soil_young", "unit_weight"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                bad(name, "a finite number > 0 (SI units)")
        if not self.footing_b < self.width:
            bad("footing_b", f"< width ({self.width} m)")
        if not self.layer_depth < self.height:
            bad("layer_depth", f"< height ({self.height} m)")
        if not self.pressure_pa > self.seat_pa:
            bad("pressure_pa", f"> seat_pa ({self.seat_pa} Pa)")
        if not (self.prestress >= 0 and math.isfinite(self.prestress)):
            bad("prestress", ">= 0 N/m")
        for name, lo in (("levels", 1), ("steps_per_level", 1), ("cell_grains", 50),
                         ("workers", 1), ("fit_points", 2), ("calibration_elements", 1)):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= lo):
                bad(name, f"an integer >= {lo}")
        if not (isinstance(self.band_grains, int)
                and (self.band_grains == 0 or self.band_grains >= 50)):
            bad("band_grains", "0 (the layer's cells stay the FEM's band) or an integer >= 50")
        if self.band_tangent not in BAND_TANGENTS:
            bad("band_tangent", "one of " + ", ".join(map(repr, BAND_TANGENTS)))
        if not (0 <= self.poisson and 0 <= self.radius_spread < 1
                and 0 < self.friction_deg < 90 and 0 <= self.soil_poisson < 0.5
                and 0 < self.soil_friction < 90):
            raise FemInputError("poisson, radius_spread, friction_deg, soil_poisson, "
                                "soil_friction: >= 0, in [0, 1), in (0, 90) deg, in [0, 0.5), "
                                "in (0, 90) deg")
        if not self.seeds or len(set(self.seeds)) != len(self.seeds) or \
                any(int(s) != s or s < 0 for s in self.seeds):
            bad("seeds", "distinct whole numbers >= 0")
        if not self.variants or any(v not in VARIANTS for v in self.variants):
            bad("variants", f"a non-empty selection of {', '.join(VARIANTS)}")
        if self.dim not in (2, 3):
            bad("dim", "2 (a strip footing, plane strain) or 3 (a square footing)")
        if self.band_grains and not self.layer_depth < self.footing_b:
            bad("band_grains", f"0 when the layer is below the DEM zone (layer_depth "
                               f"{self.layer_depth} m >= the zone's depth, footing_b "
                               f"{self.footing_b} m): its RVEs are the layer's cells in the zone")
        if self.band_grains and set(self.variants) == {"unreinforced"}:
            bad("band_grains", "0 with variants ('unreinforced',) alone: the RVEs are the "
                               "layer's, and RE and PRS have the layer")
        if not (isinstance(self.noise_ceiling, (int, float)) and 0 < self.noise_ceiling < 1):
            bad("noise_ceiling", "a fraction in (0, 1)")
        if self.resolve_m is not None and not (
                isinstance(self.resolve_m, (int, float)) and math.isfinite(self.resolve_m)
                and self.resolve_m > 0):
            bad("resolve_m", "None (the ceiling is noise_ceiling) or a settlement difference "
                             "> 0, m")
        if self.calibration_seed is not None and not (
                isinstance(self.calibration_seed, int) and self.calibration_seed >= 0):
            bad("calibration_seed", "None (the first seed) or a whole number >= 0")
        if len(set(self.budget)) != len(self.budget) or \
                any(b not in BUDGET_PARTS for b in self.budget):
            bad("budget", "distinct parts of " + ", ".join(BUDGET_PARTS))
        if self.dim == 3 and self.band_grains:
            bad("band_grains", "0 in 3D (the layer's cells stay the FEM's band: the reinforced "
                               "RVEs are verified in plane strain only)")

    @property
    def pressures_pa(self) -> list:
        """The load levels, Pa: ``levels`` equal rises from the seating to ``pressure_pa``."""
        return [float(x) for x in np.linspace(self.seat_pa, self.pressure_pa,
                                              self.levels + 1)[1:]]


# ---- the model -------------------------------------------------------------------------------


def body(p: FootingParams, reinforced: bool):
    """The body: the zone ``"zone"`` (edge b, under the footing, from the surface down) and,
    ``reinforced``, one geogrid layer ``layer_depth`` below the surface; plane strain, or
    (``p.dim`` 3) the quarter of a square footing, the body ``width`` in x and in y."""
    from femcoupling.fem.geometry import ElementRegion, GeogridLayer, ReinforcedSoilBody

    b, h = p.footing_b, p.height
    layers = (GeogridLayer(z_m=h - p.layer_depth, x_min_m=0.0, x_max_m=p.layer_length,
                           thickness_m=p.layer_thickness, name="geogrid"),) if reinforced \
        else ()
    centre = (0.5 * b, h - 0.5 * b) if p.dim == 2 else (0.5 * b, 0.5 * b, h - 0.5 * b)
    square = dict(dim=3, length_m=p.width, footing_length_m=b) if p.dim == 3 else {}
    return ReinforcedSoilBody(width_m=p.width, height_m=h, footing_half_width_m=b,
                              layers=layers, regions=(ElementRegion("zone", centre, b),),
                              mesh_size_m=p.mesh_size, fine_size_m=p.fine_size,
                              fine_radius_m=b, **square)


def model(p: FootingParams, variant: str, soil):
    """The FEM model of ``variant`` with ``soil`` (a DruckerPrager) everywhere: geostatic,
    then (PRS) the prestress locked in, then the footing seated to ``seat_pa``."""
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import GeogridLayerMaterial

    reinforced = variant != "unreinforced"
    layers = [GeogridLayerMaterial(axial_stiffness_n_per_m=p.grid_stiffness,
                                   prestress_n_per_m=p.prestress if variant == "PRS" else 0.0)
              ] if reinforced else []
    m = FemModel(body(p, reinforced), soil=soil, layers=layers,
                  unit_weight_n_m3=p.unit_weight, newton_rtol=1e-6)
    m.set_geostatic()
    if variant == "PRS" and p.prestress > 0:
        m.apply_prestress(steps=2)
    m.load_footing_to_pressure(p.seat_pa, steps=2)
    return m


def grain_options(p: FootingParams) -> dict:
    """``DemElement.periodic`` keywords of the zone's grains."""
    from cpp_dem.scene import linear_material

    mat = linear_material(density=p.density, young=p.young, poisson=p.poisson,
                          friction_angle_deg=p.friction_deg)
    return {"material": mat, "radius_mean": p.radius_mean, "radius_spread": p.radius_spread}


def band_options(p: FootingParams) -> dict:
    """``reinforced_element`` keywords of the layer's RVEs: the zone's grains, grown
    frictionless first as the zone's soil elements are (``prep_friction_deg=0``: grown at
    their friction they were at porosity 0.47 beside the sheet against the soil elements'
    0.36, and 4 to 5 times softer in zz and in shear), held to its own tolerances (0.5 % of
    the stress, unbalanced force 1e-4). At the zone elements' looser ones (2 %, 1e-2) the
    held state is not an equilibrium: released, a smoke run's cells lost 45-100 % of their
    sigma_zz and their sheets went to +-150 N/m."""
    return {**grain_options(p), "max_steps": 400_000, "prep_friction_deg": 0.0}


def band_sheet_tensions(group, first: int) -> list:
    """The sheet's tension along x (N/m) in each band element of ``group`` (the members from
    index ``first`` on), in their committed states."""
    from cpp_dem.elements.periodic import DemElement
    from cpp_dem.elements.reinforced import sheet_tension_per_metre

    pool = group.pool
    return [sheet_tension_per_metre(DemElement.from_bytes(b).scene)[0]
            for b in pool.states(range(first, pool.n))]


def zone_path(p: FootingParams, log) -> tuple:
    """The zone's mean stress path the continuum is fitted along: (s0, s1, record), the zone's
    stress tensors (3 x 3, Pa, tension positive) at the seating and at the largest pressure
    of a first FEM of the unreinforced body with the starting soil (``soil_young``, ...), and
    the record's path keys. A body that stops short is taken as far as it went when that is
    at least PATH_SHORT_MIN of the rise (the record's ``path_stopped`` says so; else its
    NewtonFailure is raised)."""
    from femcoupling.materials.continuum import DruckerPrager

    soil0 = DruckerPrager(young_pa=p.soil_young, poisson=p.soil_poisson, cohesion_pa=0.0,
                          friction_deg=p.soil_friction)
    m = model(p, "unreinforced", soil0)
    s0 = m.region_stress("zone")
    p_start, short = m.footing_pressure_pa(), None
    asked = p.pressure_pa - p_start
    try:
        m.load_footing_to_pressure(asked, steps=p.levels)
    except NewtonFailure as exc:
        # (the starting soil's body can be weaker than the fitted soil's: its bearing
        # capacity below the pressure; the zone's path is then taken as far as it went,
        # when that is at least PATH_SHORT_MIN of the rise, and the record says so)
        if not m.footing_pressure_pa() - p_start >= PATH_SHORT_MIN * asked:
            raise
        short = (f"the first FEM with the starting soil stopped at a footing pressure of "
                 f"{m.footing_pressure_pa() / 1e3:.1f} kPa of {p.pressure_pa / 1e3:g} ({exc})")
        log(f"calibration: WARNING: {short}; the zone's path is taken to there")
    s1 = m.region_stress("zone")
    # (both ends on one grid, the larger end's: what the FEM's rounding cannot move)
    s0, s1 = target_grid(s0, (s0, s1)), target_grid(s1, (s0, s1))
    return s0, s1, {"path_initial_pa": (-np.diag(s0)).tolist(),
                    "path_final_pa": (-np.diag(s1)).tolist(),
                    "path_footing_pressure_pa": m.footing_pressure_pa(),
                    "path_stopped": short}


def fit_element(p: FootingParams, s0, s1, seed: int) -> dict:
    """One element of the zone's grains (``p.cell_grains``, packing seed ``seed``) fitted as
    step 1 of the module doc: E and nu its secant along the path s0 -> s1
    (``fit_along_path``), phi and psi the peak of its plane-strain biaxial test at the path's
    final mean pressure (``biaxial.direct_biaxial`` to 6 % axial strain, ``rve_angles``).
    Returns a plain dict (it runs on a Dask worker too): ``seed``, ``grains``, ``young_pa``,
    ``poisson``, ``friction_deg``, ``dilatancy_deg``, ``peak_axial_strain``,
    ``peak_reached`` (False: no peak within 6 %, phi a lower bound), ``path_fit`` (the fit's
    sentence), ``wall_s``."""
    from cpp_dem.elements.periodic import DemElement
    from femcoupling.coupling.continuum_fit import fit_along_path

    t0 = time.perf_counter()
    s0, s1 = np.asarray(s0, float), np.asarray(s1, float)
    fit = fit_along_path(s0, s1, n=p.cell_grains, seed=seed, prep_friction_deg=0.0,
                         points=p.fit_points, options=grain_options(p), unbalanced=1e-2,
                         tol=0.02)
    pressure = float(-np.trace(s1) / 3)
    run = biaxial.direct_biaxial(
        lambda k: DemElement.periodic(p.cell_grains, stress=pressure, seed=k,
                                      prep_friction_deg=0.0, **grain_options(p)),
        [seed], pressure=pressure, strain=0.06, strain_per_step=1e-6, log=None)[0]
    angles = biaxial.rve_angles(run)
    return {"seed": int(seed), "grains": int(p.cell_grains),
            "young_pa": float(fit.material.young_pa), "poisson": float(fit.material.poisson),
            "friction_deg": float(angles["phi_peak_deg"]),
            "dilatancy_deg": float(angles["psi_deg"]),
            "peak_axial_strain": float(angles["peak_axial_strain"]),
            "peak_reached": bool(angles["peak_axial_strain"] < 0.06 - 1e-9),
            "path_fit": fit.message, "wall_s": time.perf_counter() - t0}


#: The fitted parameters a calibration averages over its element seeds (fit_element's keys).
FIT_KEYS = ("young_pa", "poisson", "friction_deg", "dilatancy_deg")


def seed_scatter(fits: list, keys=FIT_KEYS) -> dict:
    """Per key, the mean over ``fits`` (fit_element's dicts), their sd (ddof 1), the mean's
    standard error and the coefficient of variation sd / |mean| (None for one fit), and n."""
    out = {}
    for key in keys:
        v = np.array([f[key] for f in fits], float)
        n = len(v)
        sd = float(v.std(ddof=1)) if n > 1 else None
        out[key] = {"mean": float(v.mean()), "sd": sd,
                    "se": sd / math.sqrt(n) if sd is not None else None,
                    "cv": sd / abs(float(v.mean())) if sd is not None and v.mean() else None,
                    "n": n}
    return out


def fit_elements(p: FootingParams, s0, s1, seeds, client=None, on_fit=None) -> list:
    """``fit_element`` of each seed, in the order of ``seeds`` (on ``client``'s Dask workers
    when given, one element a task; else here, one after the other): the same dicts either
    way, each element's fit depending on its seed alone. ``on_fit(fit)`` is called with each
    in that order as soon as it and those before it are done."""
    seeds = [int(s) for s in seeds]
    futures = None if client is None else client.map(
        fit_element, [p] * len(seeds), [s0] * len(seeds), [s1] * len(seeds), seeds,
        pure=False)
    fits = []
    for k, s in enumerate(seeds):
        fits.append(fit_element(p, s0, s1, s) if futures is None else futures[k].result())
        if on_fit is not None:
            on_fit(fits[-1])
    return fits


def calibration_seeds(p: FootingParams) -> list:
    """The element seeds the continuum is fitted on: ``calibration_elements`` seeds from
    ``calibration_seed`` (None: from ``seeds[0]``)."""
    first = p.seeds[0] if p.calibration_seed is None else p.calibration_seed
    return list(range(first, first + p.calibration_elements))


def calibrate(p: FootingParams, log, client=None) -> tuple:
    """Step 1 of the module doc: (the fitted DruckerPrager, its record). E, nu, phi: the mean
    over ``calibration_elements`` elements of the zone's grains (``calibration_seeds``), each
    fitted by :func:`fit_element` along the zone's path (:func:`zone_path`; on ``client``'s
    workers when given); no cohesion. One element's fit scatters over its packing seed (at
    80 grains E by 14 %, nu 11 %, phi 8 %: docs/studies/footing_multiscale.md) as it does
    over the CPU's rounding path, which decorrelates a chaotic element like another seed
    would: the mean over several is what rounding cannot move beyond its standard error. The
    record has each element's fit (``elements``) and the scatter (``seed_scatter``: mean,
    sd, se, cv per parameter)."""
    from femcoupling.materials.continuum import DruckerPrager

    t0 = time.perf_counter()
    s0, s1, path = zone_path(p, log)
    seeds = calibration_seeds(p)
    fits = fit_elements(p, s0, s1, seeds, client)
    spread = seed_scatter(fits)
    mat = DruckerPrager(young_pa=spread["young_pa"]["mean"],
                        poisson=spread["poisson"]["mean"], cohesion_pa=0.0,
                        friction_deg=spread["friction_deg"]["mean"])
    pressure = float(-np.trace(s1) / 3)
    short_of_peak = [f["seed"] for f in fits if not f["peak_reached"]]

    def pm(key, scale=1.0, unit=""):
        s = spread[key]
        return (f"{s['mean'] / scale:.4g}{unit}" if s["se"] is None else
                f"{s['mean'] / scale:.4g} ± {s['se'] / scale:.2g}{unit}")

    log(f"calibration on {len(seeds)} element{'s' * (len(seeds) > 1)} of {p.cell_grains} "
        f"grains (seeds {seeds[0]}-{seeds[-1]}; mean ± se): E {pm('young_pa', 1e6, ' MPa')}, "
        f"nu {pm('poisson')} along the zone's path; phi {pm('friction_deg', 1, ' deg')}, the "
        f"biaxial peak at {pressure / 1e3:.1f} kPa"
        + (f" (no peak within 6 % for seeds {short_of_peak}: a lower bound there)"
           if short_of_peak else "") + f", c = 0 ({time.perf_counter() - t0:.1f} s)")
    rec = {"young_pa": mat.young_pa, "poisson": mat.poisson, "friction_deg": mat.friction_deg,
           "cohesion_pa": 0.0, **path,
           "biaxial_pressure_pa": pressure,
           "biaxial_peak_axial_strain": float(np.mean([f["peak_axial_strain"] for f in fits])),
           "biaxial_peak_reached": not short_of_peak,
           "dilatancy_deg": spread["dilatancy_deg"]["mean"], "element_seeds": seeds,
           "element_grains": p.cell_grains, "seed_scatter": spread, "elements": fits,
           "start": {"young_pa": p.soil_young, "poisson": p.soil_poisson,
                     "friction_deg": p.soil_friction},
           "wall_time_s": time.perf_counter() - t0}
    return mat, rec


def at_level(target: float, p0: float, s0: float, p1: float, s1: float) -> float:
    """The settlement (m) at the level's pressure ``target`` (Pa), along the level's secant
    from its start (p0, s0) to where it stopped (p1, s1). ``load_footing_to_pressure``
    stops within 1 % of the level's rise (0.2 kPa of 20 kPa: about 0.02 mm at the full
    run's 100 kPa, the size of the variants' differences), so runs are compared here, at
    the same pressure, and not where each happened to stop."""
    return s1 + (target - p1) * (s1 - s0) / (p1 - p0) if p1 != p0 else s1


def load_levels(p: FootingParams, m, on_level, first_slope: float | None = None) -> None:
    """Pushes the footing to each of ``p.pressures_pa`` in turn; ``on_level(k, steps, at)``
    after each (its accepted LoadSteps, every step also in ``m.history``; ``at``: the
    settlement at the level's pressure, ``at_level``). Each level after the first starts
    from the last level's secant slope, the first from ``first_slope`` (Pa/m; None: the
    model's small first settlement, ``load_footing_to_pressure``)."""
    slope = first_slope
    for k, target in enumerate(p.pressures_pa):
        p0, s0 = m.footing_pressure_pa(), m.footing_settlement_m()
        got = m.load_footing_to_pressure(target - p0, steps=p.steps_per_level,
                                         slope_pa_per_m=slope)
        p1, s1 = m.footing_pressure_pa(), m.footing_settlement_m()
        slope = (p1 - p0) / (s1 - s0) if s1 > s0 else None
        on_level(k, got, at_level(target, p0, s0, p1, s1))


#: Preparations of a run's zone elements: a small dense element servoed from its isotropic
#: preparation to its cell's stress now and then rearranges on the way (at 80 grains and
#: 5-15 kPa, 2 of 12 seeds strained 3-4 % before they held it, most 0.1 %; one of a smoke
#: run's 14 strained past 15 %), so a failed set is prepared again from other packing seeds
#: (``1000 seed + 100 attempt + k``), and the run's record lists the failures.
PREPARATION_ATTEMPTS = 3


def zone_ceiling(p: FootingParams, settlements_m) -> dict:
    """Newton's ceiling for the DEM zone's steps, tied to the effect under study: a step
    accepted at a residual r of the zone's force leaves the settlement s off by about r s
    (the run's next step equilibrates the whole state again, so the errors do not add up),
    so for a difference ``p.resolve_m`` to stand above it 4 times over the ceiling is
    resolve_m / (4 s), s the largest of the continuum bodies' ``settlements_m`` at the last
    level, and never above ``p.noise_ceiling``. Without ``resolve_m``: ``noise_ceiling``,
    and what it resolves by the same rule. The summary's ``acceptance`` record."""
    s = max(float(x) for x in settlements_m)
    c = p.noise_ceiling if p.resolve_m is None else min(p.noise_ceiling,
                                                        p.resolve_m / (4.0 * s))
    return {"ceiling": c, "resolve_m": p.resolve_m, "reference_settlement_m": s,
            "settlement_error_bound_m": c * s, "resolvable_m": 4.0 * c * s,
            "rule": ("noise_ceiling (no resolve_m)" if p.resolve_m is None else
                     "min(noise_ceiling, resolve_m / (4 x the continuum's settlement))")}


def run_multiscale(p: FootingParams, variant: str, seed: int, soil, client, out: Path, log,
                   on_level, first_slope: float, ceiling: float) -> dict:
    """Step 2 of the module doc for one variant and seed: the record of the summary.
    ``first_slope``: the continuum's pressure–settlement slope over the first level (Pa/m),
    where the footing's first step is sized from; ``ceiling``: Newton's for the zone
    (``zone_ceiling``)."""
    from femcoupling.materials.dem_elements import (PeriodicRegionElement, PoolRegionMaterials,
                                                    ReinforcedBandElement)

    t0 = time.perf_counter()
    m = continuum(f"{variant} seed {seed}: the seating before the DEM zone takes over",
                  model, p, variant, soil)
    m.noise_ceiling = ceiling
    e0 = m.region_strain("zone")
    # (each cell's element prepared at its stress on the grid of TARGET_DIGITS)
    cells = {k: target_grid(v) for k, v in m.cell_stresses("zone").items()}
    # (the grains around a band cell: the zone's soil cells within 1.5 fine cells of it)
    bands = (m.band_cell_states("zone", 1.5 * p.fine_size)
             if p.band_grains and variant != "unreinforced" else {})
    if p.band_grains and variant != "unreinforced" and not bands:
        raise SystemExit(f"[footing_multiscale] --band-grains {p.band_grains}: the layer "
                         f"(depth {p.layer_depth} m) has no cell in the DEM zone of this mesh, "
                         "so no cell gets a reinforced RVE; a layer higher in the zone, a "
                         "finer --fine-size, or --band-grains 0")
    tag = f"{variant}_seed{seed}"
    group, failures, vols = None, [], []
    for attempt in range(PREPARATION_ATTEMPTS):
        base = 1000 * seed + 100 * attempt
        runner = PeriodicRegionElement(n=p.cell_grains, seed=base, prep_friction_deg=0.0,
                                       tol=0.02, unbalanced=1e-2, max_strain=0.15,
                                       options=grain_options(p))
        band = None
        if bands:  # (the layer's cells in the zone: reinforced RVEs, seeds base + 500 + j)
            band = (ReinforcedBandElement(n=p.band_grains, seed=base + 500,
                                          band_thickness_m=p.layer_thickness,
                                          options=band_options(p)), bands)
        try:
            group = PoolRegionMaterials.build(cells, runner, client=client,
                                              distinct_seeds=True, band=band,
                                              fd_components=FD_COMPONENTS[p.dim],
                                              band_tangent=p.band_tangent,
                                              records=out / f"zone_elements_{tag}.h5")
            break
        except RuntimeError as exc:
            failures.append(f"packing seeds {base} + k: {exc}")
            if attempt + 1 < PREPARATION_ATTEMPTS:
                log(f"{tag}: a cell's element could not be brought to its cell's stress "
                    f"({exc}); attempt {attempt + 2} of {PREPARATION_ATTEMPTS} with seeds "
                    f"{base + 100} + k")

    def record(status, reason, rows=(), sheets=(), calls=0, dem_s=0.0, t_prep=None,
               steps=()) -> dict:
        """The run's record: its levels ``rows`` (pressure, settlement, Newton iterations,
        statuses, settlement at the level's pressure) and how it ended."""
        return {"pressure_pa": [r[0] for r in rows], "settlement_m": [r[1] for r in rows],
                "settlement_at_level_m": [r[4] for r in rows],
                "zone_volumetric_strain": list(vols),
                "newton_iterations": [r[2] for r in rows],
                "level_statuses": [r[3] for r in rows], "status": status, "reason": reason,
                "cells": len(cells), "band_cells": len(bands),
                "band_sheet_tension_n_per_m": list(sheets), "element_seed_base": base,
                "preparation_failures": failures, "element_evaluations": calls,
                "dem_s": dem_s,
                "preparation_s": time.perf_counter() - t0 if t_prep is None else t_prep,
                "wall_time_s": time.perf_counter() - t0, "warnings": list(m.warnings),
                **step_statuses(list(steps))}

    if group is None:  # (the run fails before its first level; the others go on: see run)
        reason = (f"preparation: the zone's elements could not be prepared in "
                  f"{PREPARATION_ATTEMPTS} attempts: {failures[-1]}; try more --cell-grains "
                  "or a larger --seat")
        log(f"{tag}: FAILED at {reason}")
        return record("failed", reason)
    xdmf = out / f"fem_{tag}.xdmf"
    try:
        m.set_cell_elements("zone", group, band=bool(bands))
        t_prep = time.perf_counter() - t0
        log(f"{tag}: {len(cells)} cell elements of {runner.n} grains prepared"
            + (f", and {len(bands)} reinforced RVEs of {p.band_grains} grains in the layer's "
               f"cells (the band cells' tension {[round(t) for _, t in bands.values()]} "
               f"N/m; a sheet in compression starts unloaded)"
               if bands else "") + f" ({t_prep:.1f} s)")
        sheets = [band_sheet_tensions(group, len(cells))] if bands else []
        m.write_xdmf(xdmf, time=m.footing_pressure_pa() / 1e3)
        rows = []

        def level(k, got, at):
            m.write_xdmf(xdmf, time=m.footing_pressure_pa() / 1e3, append=True)
            rows.append((m.footing_pressure_pa(), m.footing_settlement_m(),
                         sum(r.newton_iterations for r in got),
                         [r.status for r in got], at))
            vols.append(zone_volumetric_strain(m, e0))
            if bands:
                sheets.append(band_sheet_tensions(group, len(cells)))
            on_level(variant, "multiscale", seed, k, rows[-1])

        n0, failed = len(m.history), None
        try:
            load_levels(p, m, level, first_slope)
        except NewtonFailure as exc:  # (the run stops; the others go on: see run)
            failed = f"level {len(rows) + 1}: {exc}"
            log(f"{tag}: FAILED at {failed}")
        steps = [r for r in m.history[n0:] if r.stage == "footing"]
        strains = np.array([-np.diag(e) for e in group.strains()])  # compression +
        vol = m.cell_volume[[int(k.rsplit("/", 1)[1]) for k in group.names]]
        calls, dem_s = group.calls, group.dem_s
    finally:
        group.close()
    if failed is None:
        hier = {**step_statuses(steps),
                "element_strain_increment": (fixedorder.weighted_rows(vol, strains)
                                             / math.fsum(vol)).tolist()}
        st = hierarchical_status(hier, -np.diag(m.region_strain("zone") - e0), math.nan)
        status, reason = st.status, st.reason
    else:
        status, reason = "failed", failed
    return record(status, reason, rows, sheets, calls, dem_s, t_prep, steps)


def continuum(what: str, fn, *args):
    """``fn(*args)``; a Drucker–Prager FEM inside it (``what``: the calibration's first FEM,
    a variant's continuum body or the seating of its DEM zone) that does not converge stops
    the run with a message naming it and Newton's failure (SystemExit) instead of a
    traceback."""
    try:
        return fn(*args)
    except NewtonFailure as exc:
        raise SystemExit(
            f"[footing_multiscale] {what}: the Drucker–Prager FEM did not converge: {exc}. A "
            "body whose settlement grows fast before it stops is near its bearing capacity: a "
            "lower --pressure stays below it") from exc


def run_continuum(p: FootingParams, variant: str, soil, on_level) -> dict:
    """Step 3 of the module doc for one variant. A body that stops after its first level
    (near its bearing capacity) is recorded with the levels it reached (``levels_reached``)
    and why (``failure``; None when it reached every level); one that stops before raises
    its NewtonFailure (the multiscale runs start from its first level's slope)."""
    t0 = time.perf_counter()
    m = model(p, variant, soil)
    seated = m.footing_settlement_m()
    e0 = m.region_strain("zone")
    rows, vols = [], []

    def level(k, got, at):
        rows.append((m.footing_pressure_pa(), m.footing_settlement_m(),
                     sum(r.newton_iterations for r in got), [r.status for r in got], at))
        vols.append(zone_volumetric_strain(m, e0))
        on_level(variant, "drucker_prager", None, k, rows[-1])

    failure = None
    try:
        load_levels(p, m, level)
    except NewtonFailure as exc:
        if not rows:
            raise
        failure = str(exc)
    return {"pressure_pa": [r[0] for r in rows], "settlement_m": [r[1] for r in rows],
            "settlement_at_level_m": [r[4] for r in rows], "seated_settlement_m": seated,
            "zone_volumetric_strain": vols,
            "levels_reached": len(rows), "failure": failure,
            "wall_time_s": time.perf_counter() - t0}


def zone_volumetric_strain(m, e0: np.ndarray) -> float:
    """The DEM zone's volumetric strain since ``e0`` (its mean strain at the seating), -,
    dilation positive: the trace of the zone's volume-averaged strain change."""
    return float(np.trace(m.region_strain("zone") - e0))


def one_soil(variants: dict) -> dict:
    """Per variant, the DEM zone against the Drucker–Prager body fitted on its grains, level by
    level (issue 62: not only the settlement, the zone's volume change too: a continuum that
    dilates more or less than its grains shows it here): the multiscale runs' seed mean of
    the settlement at the level's pressure and of the zone's volumetric strain (dilation +;
    over the seeds that reached the level, ``seeds_used``), the body's, and their
    differences (multiscale − Drucker–Prager; None where either stopped before the level)."""
    out = {}
    for v, r in variants.items():
        ms, dp = r["multiscale"], r["drucker_prager"]
        n = len(ms["seeds_used"])

        def mean_of(key, k):  # (None where a run has no such record)
            xs = [ms["runs"][str(s)].get(key, [])[k:k + 1] for s in ms["seeds_used"][k]]
            return float(np.mean(xs)) if xs and all(xs) else None

        def dp_at(key, k):
            return (dp.get(key) or [])[k] if k < len(dp.get(key) or []) else None

        def diff(a, b):
            return None if a is None or b is None else a - b

        rows = {"settlement_multiscale_m": list(ms["settlement_mean_m"]),
                "settlement_drucker_prager_m": [dp_at("settlement_at_level_m", k)
                                                for k in range(n)],
                "volumetric_strain_multiscale": [mean_of("zone_volumetric_strain", k)
                                                 for k in range(n)],
                "volumetric_strain_drucker_prager": [dp_at("zone_volumetric_strain", k)
                                                     for k in range(n)]}
        rows["settlement_difference_m"] = [diff(a, b) for a, b in zip(
            rows["settlement_multiscale_m"], rows["settlement_drucker_prager_m"])]
        rows["volumetric_strain_difference"] = [diff(a, b) for a, b in zip(
            rows["volumetric_strain_multiscale"], rows["volumetric_strain_drucker_prager"])]
        out[v] = rows
    return out


def _last_differences(variants: dict, diffs: dict, levels: int) -> dict:
    """The run's differences at its last level, {name: (mean, se, n)} (m): the paired
    settlement differences between variants (``diffs``, :func:`statistics`'s, over the seeds
    that reached the level in every variant), and per variant the DEM zone against the
    Drucker–Prager body fitted on its grains (se: the zone's seed scatter; the body is one
    run). (None, None, n) where no seed reached it."""
    k = levels - 1
    out = {f"{a} - {b}": (d["mean_m"][k], d["se_m"][k], d["seeds"][k])
           for (a, b), d in ((key.split("-"), d) for key, d in diffs.items())}

    def at(v):
        ms = variants[v]["multiscale"]
        used = ms["seeds_used"][k]
        return np.array([ms["runs"][str(s)]["settlement_at_level_m"][k] for s in used])

    for v, r in variants.items():
        z, dp = at(v), r["drucker_prager"].get("settlement_at_level_m") or []
        n = len(z)
        mean = float(z.mean() - dp[k]) if n and len(dp) > k else None
        out[f"{v}: DEM zone - Drucker-Prager"] = (
            mean, float(z.std(ddof=1) / math.sqrt(n)) if n > 1 and mean is not None else None,
            n)
    return out


def differences(variants: dict, diffs: dict, reruns: dict, levels: int) -> list:
    """The error budget of every difference the run reports (issue 62), at the last level:
    ``{"name", "mean", "se", "n", "budget": {"ceiling", "calibration", "rve", "mesh",
    "seeds"}, "total", "resolved", "unmeasured"}`` (m). ``diffs``: :func:`statistics`'s
    paired differences of ``variants``. Each part of ``reruns`` (BUDGET_PARTS: (variants,
    diffs) rerun with one thing changed) is how far the difference moved, |rerun -
    run|; "seeds" is t(0.975, n - 1) x se. ``total`` is their sum (no independence assumed),
    None while a part is unmeasured (``unmeasured`` names them); ``resolved`` only when
    every part is measured and |mean| exceeds the total."""
    base = _last_differences(variants, diffs, levels)
    moved = {part: _last_differences(v, d, levels) for part, (v, d) in reruns.items()}
    rows = []
    for name, (mean, se, n) in base.items():
        budget = {part: None for part in BUDGET_PARTS}
        for part, d in moved.items():
            other = d.get(name, (None,))[0]
            if mean is not None and other is not None:
                budget[part] = abs(other - mean)
        budget["seeds"] = t_critical(n) * se if se is not None else None
        unmeasured = [k for k, x in budget.items() if x is None or not math.isfinite(x)]
        total = None if unmeasured else float(sum(budget.values()))
        rows.append({"name": name, "mean": mean, "se": se, "n": n, "budget": budget,
                     "total": total, "unmeasured": unmeasured,
                     "resolved": bool(total is not None and abs(mean) > total)})
    return rows


def paired(a: np.ndarray, b: np.ndarray) -> dict:
    """The paired difference a - b over seeds (rows) at each level (columns): mean and
    standard error (None with one seed), m."""
    d = np.asarray(a, float) - np.asarray(b, float)
    n = d.shape[0]
    se = (d.std(axis=0, ddof=1) / math.sqrt(n)).tolist() if n > 1 else None
    return {"mean_m": d.mean(axis=0).tolist(), "se_m": se, "seeds": n}


def statistics(variants: dict, seeds, levels: int) -> dict:
    """The statistics of the run, level by level over the seeds whose runs reached that
    level in every variant (a run that failed keeps the levels it reached): each variant's
    ``multiscale`` record gets ``seeds_used`` (per level, the seeds), ``settlement_mean_m``
    and ``settlement_sd_m`` (per level, of the settlements at the level's pressure,
    ``settlement_at_level_m``; None where no seed, or one, is left). Returns the
    paired differences RE - unreinforced, PRS - RE and PRS - unreinforced (``paired`` per
    level: ``mean_m``, ``se_m`` and ``seeds``, lists over the levels)."""
    def reached(s, k):
        return all(len(r["multiscale"]["runs"][str(s)]["settlement_m"]) > k
                   for r in variants.values())

    used = [[s for s in seeds if reached(s, k)] for k in range(levels)]

    def column(v, k):  # (at the level's pressure: see at_level)
        return np.array([variants[v]["multiscale"]["runs"][str(s)]["settlement_at_level_m"][k]
                         for s in used[k]])

    for v, r in variants.items():
        cols = [column(v, k) for k in range(levels)]
        r["multiscale"].update(
            seeds_used=used, seeds=[len(u) for u in used],
            settlement_mean_m=[float(c.mean()) if len(c) else None for c in cols],
            settlement_sd_m=[float(c.std(ddof=1)) if len(c) > 1 else None for c in cols])
    diffs = {}
    for a, b in (("RE", "unreinforced"), ("PRS", "RE"), ("PRS", "unreinforced")):
        if a not in variants or b not in variants:
            continue
        per = [paired(column(a, k)[:, None], column(b, k)[:, None]) if used[k] else None
               for k in range(levels)]
        diffs[f"{a}-{b}"] = {
            "mean_m": [d["mean_m"][0] if d else None for d in per],
            "se_m": [d["se_m"][0] if d and d["se_m"] else None for d in per],
            "seeds": [len(u) for u in used]}
    return diffs


def figure(summary: dict, png: Path) -> None:
    """Load–settlement: the multiscale runs' seed mean (bars: the seeds' sd) and the
    Drucker–Prager-only body, per variant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpp_dem.io.figures import save_figure

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for (v, r), col in zip(summary["variants"].items(), ("k", "tab:blue", "tab:red")):
        ms = r["multiscale"]
        p = np.array(summary["pressures_pa"]) / 1e3
        mean = np.array([np.nan if x is None else x for x in ms["settlement_mean_m"]])
        sd = np.array([0.0 if x is None else x for x in ms["settlement_sd_m"]])
        ax.errorbar(1e3 * mean, p, xerr=1e3 * sd, color=col, marker="o", capsize=3,
                    label=f"{v}: DEM zone (seeds per level {ms['seeds']})")
        ax.plot(1e3 * np.array(r["drucker_prager"]["settlement_m"]),
                np.array(r["drucker_prager"]["pressure_pa"]) / 1e3, color=col, ls="--",
                label=f"{v}: Drucker-Prager only")
    ax.set_xlabel("footing settlement (mm)")
    ax.set_ylabel("footing pressure (kPa)")
    ax.invert_yaxis()
    ax.legend(fontsize=8)
    ax.set_title("Strip footing: load-settlement")
    fig.tight_layout()
    save_figure(fig, png)
    plt.close(fig)


def budget_params(p: FootingParams, part: str) -> FootingParams:
    """The parameters of the rerun that measures the budget's ``part`` (BUDGET_PARTS)."""
    change = {"ceiling": dict(noise_ceiling=0.5 * p.noise_ceiling,
                              resolve_m=None if p.resolve_m is None else 0.5 * p.resolve_m),
              "calibration": dict(calibration_seed=calibration_seeds(p)[-1] + 1),
              "rve": dict(cell_grains=2 * p.cell_grains, band_grains=2 * p.band_grains),
              "mesh": dict(fine_size=p.fine_size / math.sqrt(2.0))}[part]
    return dataclasses.replace(p, budget=(), **change)


def _csv_rows(path: Path):
    """A load-settlement CSV (its header written now) and the function that appends a row."""
    path.write_text("variant,model,seed,level,pressure_pa,settlement_m,"
                    "settlement_at_level_m,newton_iterations,statuses\n")

    def add(variant, kind, seed, k, row):
        pres, settle, its, statuses, at = row
        with path.open("a") as f:
            f.write(f"{variant},{kind},{'' if seed is None else seed},{k + 1},{pres:.6g},"
                    f"{settle:.6g},{at:.6g},{its},{' '.join(statuses)}\n")
            f.flush()
    return add


def run_variants(p: FootingParams, soil, client, out: Path, log, on_level) -> tuple:
    """Steps 3 and 2 of the module doc for every variant: the continuum bodies first (the
    zone's ceiling is set from their settlements: ``zone_ceiling``), then the DEM zones.
    Returns ({variant: {"multiscale": {"status", "runs"}, "drucker_prager": ...}}, the
    ``zone_ceiling`` record)."""
    from femcoupling.coupling.status import worst

    variants: dict = {}
    bodies = {}
    for v in p.variants:
        dp = bodies[v] = continuum(f"{v}: the Drucker–Prager body", run_continuum, p, v, soil,
                                   on_level)
        if dp["failure"] is not None:
            log(f"WARNING: {v}: the Drucker–Prager body stopped after level "
                f"{dp['levels_reached']} of {p.levels} (near its bearing capacity?): "
                f"{dp['failure']}")
    acc = zone_ceiling(p, [dp["settlement_m"][-1] for dp in bodies.values()])
    log(f"the DEM zone's Newton ceiling: {acc['ceiling']:.3g} of its force ({acc['rule']}): "
        f"a settlement off by up to {1e3 * acc['settlement_error_bound_m']:.4f} mm, "
        f"differences from {1e3 * acc['resolvable_m']:.4f} mm resolvable by it")
    for v, dp in bodies.items():
        slope = (dp["pressure_pa"][0] - p.seat_pa) / (dp["settlement_m"][0]
                                                       - dp["seated_settlement_m"])
        runs = {s: run_multiscale(p, v, s, soil, client, out, log, on_level, slope,
                                  acc["ceiling"])
                for s in p.seeds}
        variants[v] = {"multiscale": {"status": worst(r["status"] for r in runs.values()),
                                      "runs": {str(s): r for s, r in runs.items()}},
                       "drucker_prager": dp}
    return variants, acc


def run(p: FootingParams, out: Path, log, progress=None) -> dict:
    """The whole case (module doc); writes ``load_settlement.csv`` (a row per level as it
    is reached, flushed), ``calibration.json``, ``summary.json`` and
    ``load_settlement.png``; with ``p.budget``, each part's rerun in ``budget_<part>/``
    (its own ``load_settlement.csv``, and ``calibration.json`` when refitted). Returns the
    summary."""
    from cpp_dem.elements.cluster import local_client
    from femcoupling.coupling.status import exit_code, worst

    p.check()
    t0 = time.perf_counter()
    add_row = _csv_rows(out / "load_settlement.csv")
    # (the progress counts the DEM zone's levels: the continuum's take seconds)
    n_units = (1 + len(p.budget)) * len(p.variants) * len(p.seeds) * p.levels
    done = [0]

    def level_rows(add, what=""):
        def on_level(variant, kind, seed, k, row):
            add(variant, kind, seed, k, row)
            done[0] += kind == "multiscale"
            log(f"{what}{variant} {kind}{'' if seed is None else f' seed {seed}'}: level "
                f"{k + 1}/{p.levels}: {row[0] / 1e3:.1f} kPa, settlement {1e3 * row[1]:.3f} mm")
            if progress is not None:
                progress(done[0] / n_units, f"{what}{variant} {kind} level {k + 1}")
        return on_level

    reruns: dict = {}
    client, cluster = local_client(p.workers)
    try:
        soil, cal = continuum("the calibration's first FEM (the unreinforced body with the "
                              f"starting soil: E {p.soil_young / 1e6:g} MPa, nu "
                              f"{p.soil_poisson:g}, phi {p.soil_friction:g} deg, no cohesion)",
                              calibrate, p, log, client)
        (out / "calibration.json").write_text(json.dumps(cal, indent=2) + "\n")
        variants, acceptance = run_variants(p, soil, client, out, log, level_rows(add_row))
        for part in p.budget:
            q, sub = budget_params(p, part), out / f"budget_{part}"
            sub.mkdir(exist_ok=True)
            log(f"budget: {part}: {BUDGET_PARTS[part]}")
            soil_q = soil
            if part == "calibration":
                soil_q, cal_q = continuum("the budget's refitted calibration", calibrate, q,
                                          log, client)
                (sub / "calibration.json").write_text(json.dumps(cal_q, indent=2) + "\n")
            vq, _ = run_variants(q, soil_q, client, sub, log,
                                 level_rows(_csv_rows(sub / "load_settlement.csv"),
                                            f"budget {part}: "))
            reruns[part] = (vq, statistics(vq, q.seeds, q.levels))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    diffs = statistics(variants, p.seeds, p.levels)
    short = {v: [s for s in p.seeds if r["multiscale"]["runs"][str(s)]["status"] == "failed"]
             for v, r in variants.items()}
    if any(short.values()):
        log("WARNING: runs failed before the last level (" + ", ".join(
            f"{v} seeds {x}" for v, x in short.items() if x) + "): each level's statistics "
            "are over the seeds that reached it in every variant (summary.json: seeds_used)")
    status = worst(r["multiscale"]["status"] for r in variants.values())
    summary = {
        "case": "footing_multiscale", "pressures_pa": p.pressures_pa, "seat_pa": p.seat_pa,
        "settlement_m": {v: r["multiscale"]["settlement_mean_m"] for v, r in variants.items()},
        "variants": variants, "paired_settlement_differences": diffs,
        "one_soil": one_soil(variants), "acceptance": acceptance,
        "differences": differences(variants, diffs, reruns, p.levels),
        "calibration": cal,
        "coupling": {"mode": "hierarchical (an element per zone cell)", "status": status,
                     "exit_code": exit_code(status),
                     "variants": {v: r["multiscale"]["status"] for v, r in variants.items()}},
        "cost": {"wall_time_s": time.perf_counter() - t0, "workers": p.workers,
                 "cells": next(iter(next(iter(variants.values()))["multiscale"]["runs"]
                                     .values()))["cells"],
                 "element_evaluations": sum(r["element_evaluations"]
                                            for v in variants.values()
                                            for r in v["multiscale"]["runs"].values()),
                 "dem_s": sum(r["dem_s"] for v in variants.values()
                              for r in v["multiscale"]["runs"].values())},
        "params": {k: (list(v) if isinstance(v, tuple) else v)
                   for k, v in dataclasses.asdict(p).items()},
        "provenance": code_record()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    figure(summary, out / "load_settlement.png")
    for d in summary["differences"]:
        if d["mean"] is None:
            continue
        log(f"{d['name']} at {p.pressures_pa[-1] / 1e3:g} kPa: {1e3 * d['mean']:+.4f} mm "
            + ("(one seed)" if d["se"] is None else f"± {1e3 * d['se']:.4f} (se, n = {d['n']})")
            + (f": resolved above its budget {1e3 * d['total']:.4f} mm" if d["resolved"] else
               f": not resolved (budget {1e3 * d['total']:.4f} mm)" if d["total"] is not None
               else f": not resolved, its budget not measured ({', '.join(d['unmeasured'])};"
                    " --budget)"))
    return summary
