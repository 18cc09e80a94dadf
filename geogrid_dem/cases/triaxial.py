#!/usr/bin/env python3
"""Drained triaxial test of a granular sample in a box (the thesis, 001 chapter 6 and App. B).

Axis z is the axial axis (the 0.6 m side of the default 0.3 x 0.3 x 0.6 m box); x and y are
the lateral axes held at the cell pressure. Six frictionless, servo-controlled walls.

Stages: (0) sample: radii from the App. B sieve curve (by mass; truncated below d_min so the
box holds about --n grains, see docs/triaxial.md), a random loose cloud, radius expansion to
the cell pressure at the preparation friction (--prep-friction, App. B's compFricDegree);
(1) isotropic: servo walls to the cell pressure until all axis stresses are within 1 % and
the unbalanced force is below 0.01, at the contact friction --phi; (2) deviatoric: the z
walls move at a constant axial strain rate with the x and y stresses held, until
--stop-strain. With --packing CSV (x,y,z,r) the given spheres are used in the box they span
and the run starts at stage (1).

Outputs in --out: triaxial.h5 (series + final snapshot; with a geogrid also the series
member_axial_force, (n_records, n_members) N), triaxial.csv (columns axial_strain,
volumetric_strain, deviatoric_stress, ...), triaxial.png and .pdf (eps_v-eps_a, q-eps_a,
eps_v-time), isotropic.h5 (checkpoint after stage 1), packing_isotropic.csv (grains only),
vtk/ (spheres and box at the end of each stage), summary.json. SI units; stresses and
strains compression positive; q = sigma_z - (sigma_x + sigma_y) / 2. Interrupted (Ctrl-C,
SIGTERM), a run leaves summary.json marked "interrupted" with the stages it finished (the
axial loading to the strain reached) and triaxial.png of the loading so far.

--resume continues an interrupted (or failed) run in --out from its checkpoint isotropic.h5:
the sample is rebuilt from the same parameters, the state after stage 1 loaded (bitwise), and
stage 2 runs again from its start; the checkpoint is kept, the other files replaced.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from cpp_dem.io.figures import save_figure
from geogrid_dem.cases import describe, thesis_grids, triaxial_cylinder
from cpp_dem import apply_threads
from geogrid_dem.options import (case_parser, check_cap, given_options, parse_checked,
                                 refuse_unused, warn_below)
from geogrid_dem.rundir import begin_run, end_run, on_interrupt, run_main
import cpp_dem as dem
from cpp_dem.build import geogrid
from cpp_dem import measure
from cpp_dem.protocols import prep
from cpp_dem.build import psd
from cpp_dem.checkpoint import load_checkpoint, save_checkpoint
from geogrid_dem.cases.grains_option import (HELP as GRAINS_HELP, check_grains, grain_templates,
                                         write_grains_csv)
from cpp_dem.io import CsvRecorder, H5Recorder, PvdWriter, write_vtk_box, write_vtk_spheres
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import (apply_preset, build_box_sample, deviatoric_stage,
                              isotropic_stage)



@dataclass
class Params:
    """Parameters of the triaxial case (SI)."""

    n: int = 15000                   #: target number of grains, -
    box: tuple = (0.3, 0.3, 0.6)     #: box x, y, z (axial), m
    seed: int = 1                    #: RNG seed, -
    young: float = 4.5e6             #: E of the linear law, Pa (001 §6, App. B)
    poisson: float = 0.33            #: k_s / k_n of the linear law, - (App. B)
    phi: float = 32.0                #: contact friction angle, deg (App. B finalFricDegree)
    prep_friction: float = 32.0      #: friction during the expansion, deg (compFricDegree)
    density: float = 2650.0          #: grain density, kg/m^3
    damping: float = 0.2             #: Cundall local damping, - (App. B damp)
    cell_pressure: float = 75e3      #: Pa (001 §6)
    strain_rate: float = 0.1         #: axial strain rate, 1/s
    stop_strain: float = 0.15        #: axial strain at which to stop, -
    solid_fraction: float = 0.6      #: assumed solid fraction to size the PSD truncation, -
    cloud_fraction: float = 0.25     #: solid fraction of the initial cloud, -
    dt_safety: float = 0.5           #: dt = safety x critical_dt, -
    record_every: int = 100          #: steps between records, -
    threads: int = 0                 #: OpenMP threads (0: library default)
    packing: str = ""                #: packing file to start from ('' = generate)
    packing_format: str = "csv"      #: csv (x,y,z,r), yade, liggghts or pfc
    box: tuple = ()                  #: wall planes (x0, y0, z0, x1, y1, z1), m ('' = the
                                     #: packing's bounding box, or a LIGGGHTS file's box)
    skip_isotropic: bool = False     #: take the packing's state as it is (no growth, no
                                     #: isotropic stage): continue another code's state
    geogrid: str = "none"            #: geogrid layer at mid-height: none, square, triangular
    clear_layer: bool = False        #: remove the grains in the geogrid layer (also without
                                     #: a geogrid, for a same-packing comparison)
    preset: str = ""                 #: speed-accuracy preset of the loading ('' = none)
    grain_scale: float = 1.0         #: every grain size x this factor after the PSD is fitted
                                     #: to n (same box: about n / grain_scale^3 grains), -
    grains: str = "spheres"          #: spheres, or clumps:NAME (a shipped grain gravel_a ..
                                     #: gravel_d, 'gravel' for the four mixed, or a template
                                     #: CSV x,y,z,r); sizes are equivalent-volume diameters
    specimen: str = "box"            #: box (six servo walls), or cylinder: the box's
                                     #: inscribed cylinder in a flexible membrane
    membrane_side: float = 1.0       #: the cylinder's membrane: its triangles' side in
                                     #: smallest grain radii, 0.75 to 2, -


#: The fewest grains a sample may have, from a packing or a PSD, -.
MIN_GRAINS = 10

SMOKE = dict(n=300, strain_rate=0.5, stop_strain=0.04, record_every=50)


def smoke_box(p: Params) -> tuple:
    """The box scaled with the grain count (grain sizes kept): (n / 15000)^(1/3) x 0.3 ..."""
    f = (p.n / 15000.0) ** (1.0 / 3.0)
    return tuple(float(x * f) for x in (0.3, 0.3, 0.6))


def make_sample(p: Params, log) -> tuple:
    """Centres, radii and the box (lo, hi) of the sample; info about the PSD; and for clumps
    (cloud, templates) (the centres and radii are then the clumps' bounding spheres), else
    None."""
    if p.packing:
        from cpp_dem.io import foreign

        readers = {"csv": dem.read_packing_csv, "yade": foreign.read_yade_text,
                   "liggghts": foreign.read_liggghts_data, "pfc": foreign.read_pfc_balls}
        c, r = readers[p.packing_format](p.packing)
        if len(r) < MIN_GRAINS:
            raise SystemExit(f"error: --packing={p.packing}: {len(r)} "
                             f"sphere{'' if len(r) == 1 else 's'}; a triaxial sample needs at "
                             f"least {MIN_GRAINS} grains (its stress is a mean over the grain "
                             "contacts)")
        if p.box:
            lo, hi = np.asarray(p.box[:3], float), np.asarray(p.box[3:], float)
        elif p.packing_format == "liggghts":
            lo, hi = foreign.read_liggghts_box(p.packing)
        else:
            lo = (c - r[:, None]).min(0)
            hi = (c + r[:, None]).max(0)
        outside = np.any((c < lo) | (c > hi), axis=1)
        if np.any(outside):
            raise SystemExit(f"error: --packing={p.packing}: {int(outside.sum())} centres lie "
                             f"outside the box {lo.tolist()}-{hi.tolist()} m (--box)")
        log(f"packing {p.packing} ({p.packing_format}): {len(r)} spheres, walls at "
            f"{np.round(lo, 5).tolist()} - {np.round(hi, 5).tolist()} m")
        return c, r, lo, hi, {"source": str(p.packing), "format": p.packing_format}, None
    box = np.asarray(p.box, float)
    vol_solid = p.solid_fraction * float(np.prod(box))
    d, pc, d_min = psd.fit_psd_to_count(psd.APPENDIX_B_SIZES, psd.APPENDIX_B_PASSING, p.n,
                                        vol_solid, by="mass", method="truncate")
    if p.grain_scale != 1.0:  # coarser (> 1) or finer (< 1) grains in the same box
        d = d * p.grain_scale
        log(f"grain sizes x {p.grain_scale:g} (--grain-scale)")
    n = int(round(psd.expected_count(d, pc, vol_solid, by="mass")))
    if n < MIN_GRAINS:
        raise SystemExit(f"error: --grain-scale={p.grain_scale:g}: leaves {n} grains in the "
                         f"{np.round(box, 4).tolist()} m box (at least {MIN_GRAINS} are "
                         "needed); use a "
                         "smaller factor or a larger box")
    radii = psd.radii_from_psd(d, pc, n, by="mass", seed=p.seed)
    info = {"d_min_m": d_min * p.grain_scale, "sizes_m": d.tolist(),
            "passing_mass": pc.tolist(), "grains": p.grains}
    log(f"PSD: App. B by mass, fines below d_min = {d_min * p.grain_scale * 1e3:.2f} mm removed -> {n} grains,"
        f" d = {2 * radii.min() * 1e3:.1f}-{2 * radii.max() * 1e3:.1f} mm")
    if p.grains != "spheres":
        # Clumps of the template(s) at the PSD's equivalent-volume diameters, random seeded
        # orientations; their bounding spheres are placed, loose enough to be placed at random.
        from cpp_dem.build.clumps import clump_cloud

        templates = grain_templates(p.grains)
        from cpp_dem.build.clumps import bounding_volume_factor

        k = bounding_volume_factor(templates)
        shrink = (p.cloud_fraction / (p.solid_fraction * k)) ** (1.0 / 3.0)
        cloud = clump_cloud(templates, 2.0 * radii * shrink, (0, 0, 0), box, seed=p.seed)
        rb = cloud.scales * np.array([templates[t].bounding_radius for t in cloud.template])
        log(f"grains: clumps of {', '.join(t.name for t in templates)} "
            f"({sum(t.num_members for t in templates) / len(templates):.0f} spheres each), "
            f"cloud at diameters x {shrink:.3f}")
        return cloud.positions, rb, np.zeros(3), box, {**info, "cloud_shrink": shrink}, \
            (cloud, templates)
    shrink = (p.cloud_fraction / p.solid_fraction) ** (1.0 / 3.0)
    c, r = loose_cloud(radii * shrink, (0, 0, 0), box, seed=p.seed)
    log(f"cloud at radii x {shrink:.3f}")
    return c, r, np.zeros(3), box, {**info, "cloud_shrink": shrink}, None


@dataclass
class GridLayer:
    """A geogrid layer at mid-height of the sample (001 §6.3): the §5.1 grids, 9.5 cm wide
    (or 0.8 of the box width in a smaller smoke box), centred in x and y."""

    z: float
    centre: np.ndarray
    width: float

    def radius(self, p: Params) -> float:
        """Cylinder radius, m: 1 mm for the square grid, 0.5 mm for the triangular (001 §5.1)."""
        return thesis_grids.GRIDS[p.geogrid][0]

    def overlaps(self, c: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Grains (at the cloud's radii) that cut the layer slab over the grid's footprint."""
        half = 0.5 * self.width
        inside = np.all(np.abs(c[:, :2] - self.centre) < half + r[:, None], axis=1)
        return inside & (np.abs(c[:, 2] - self.z) < r + thesis_grids.SLAB_M)

    def build(self, sc, p: Params):
        """Adds the geogrid: 001 Table 5.1 material with cohesive links (App. A;
        :func:`geogrid_dem.cases.thesis_grids.add_grid_material`)."""
        mat, beam = thesis_grids.add_grid_material(sc, p.geogrid)
        o = np.array([self.centre[0] - 0.5 * self.width, self.centre[1] - 0.5 * self.width,
                      self.z])
        if p.geogrid == "square":
            n = max(2, int(round(10 * self.width / 0.095)))
            return geogrid.square_grid(sc, origin=o, length=self.width, width=self.width,
                                       nodes_x=n, nodes_y=n, params=beam, material=mat,
                                       density=2650.0)
        return geogrid.triangular_grid(sc, origin=o, length=self.width, width=self.width,
                                       side=thesis_grids.GRIDS["triangular"][1], params=beam,
                                       material=mat, density=2650.0)


def grid_layer(p: Params, lo, hi) -> GridLayer | None:
    """The mid-height geogrid layer of the sample in [lo, hi], or None without one."""
    if p.geogrid == "none" and not p.clear_layer:
        return None
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    width = min(0.095, 0.8 * float(min(hi[0] - lo[0], hi[1] - lo[1])))
    return GridLayer(z=0.5 * (lo[2] + hi[2]), centre=0.5 * (lo[:2] + hi[:2]), width=width)


def plot(rows: dict, png: Path, p: Params, note: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    ea = 100 * rows["axial_strain"]
    ax[0].plot(ea, 100 * rows["volumetric_strain"])
    ax[0].set_xlabel("axial strain (%)")
    ax[0].set_ylabel("volumetric strain (%, compression +)")
    ax[1].plot(ea, rows["deviatoric_stress"] / 1e3)
    ax[1].set_xlabel("axial strain (%)")
    ax[1].set_ylabel("q = sigma_z - (sigma_x + sigma_y)/2 (kPa)")
    ax[2].plot(rows["time"], 100 * rows["volumetric_strain"])
    ax[2].set_xlabel("time in the deviatoric stage (s)")
    ax[2].set_ylabel("volumetric strain (%)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(f"Triaxial test, cell pressure {p.cell_pressure / 1e3:g} kPa, "
                 f"E = {p.young / 1e6:g} MPa, phi = {p.phi:g} deg{note}")
    fig.tight_layout()
    save_figure(fig, png)
    plt.close(fig)


SERIES = {"time": (None, "s"), "step": (None, "-"), "axial_strain": (None, "-"),
          "volumetric_strain": (None, "-"), "deviatoric_stress": (None, "Pa"),
          "mean_stress": (None, "Pa"), "sigma_x": (None, "Pa"), "sigma_y": (None, "Pa"),
          "sigma_z": (None, "Pa"), "porosity": (None, "-"), "unbalanced_force": (None, "-")}


@dataclass
class Prepared:
    """A sample after the isotropic stage (stages 0 and 1)."""

    sample: object          #: cpp_dem.protocols.triaxial.TriaxialSample
    grid: object            #: geogrid.Geogrid or None
    n_grains: int
    psd_info: dict
    grow: object            #: prep.StageResult of the expansion, or None (given packing)
    iso: object             #: prep.StageResult of the isotropic stage
    t_iso: float            #: wall time of the isotropic stage, s


def build(p: Params, log) -> tuple:
    """Stage 0 without running: the sample (or the given packing) in its box with its walls
    and controller, and the geogrid layer if any; returns (sample, grid, layer, n_grains,
    psd_info)."""
    c, r, lo, hi, psd_info, clumps = make_sample(p, log)
    layer = grid_layer(p, lo, hi)
    if layer is not None and (p.clear_layer or p.geogrid != "none"):
        keep = ~layer.overlaps(c, r)
        log(f"geogrid layer at z = {layer.z:.4f} m: {int((~keep).sum())} grains removed from it "
            f"({'with' if p.geogrid != 'none' else 'without'} a geogrid)")
        c, r = c[keep], r[keep]
        if clumps is not None:
            from cpp_dem.build.clumps import ClumpCloud

            cl, tpl = clumps
            clumps = (ClumpCloud(cl.template[keep], cl.positions[keep], cl.orientations[keep],
                                 cl.scales[keep]), tpl)
    sample = build_box_sample(c, r, lo, hi, young=p.young, poisson=p.poisson,
                              friction_deg=p.prep_friction if not p.packing else p.phi,
                              density=p.density, local_damping=p.damping,
                              dt_safety=p.dt_safety, clumps=clumps)
    sc, walls = sample.scene, sample.walls
    # Soft grains under high confinement overlap by design (0.07 of the radius at 75 kPa and
    # E = 4.5 MPa, the axial stress reaches 3-4 times the cell pressure): see overlap_limit.
    sc.max_overlap_ratio = prep.overlap_limit(p.cell_pressure, p.young)
    grid = layer.build(sc, p) if (layer is not None and p.geogrid != "none") else None
    if grid is not None:
        sc.block_dofs(grid.nodes, "all")  # held during the expansion (as 000 §2.3)
        # Grain–geogrid contacts are soft: the mixing rule takes the virtual sphere's radius
        # R_c (001 §4.2), so k_n ~ E R_c and, at 75 kPa, a 1 cm grain sinks by a large
        # fraction of its radius into a 0.5 mm grid. Allow overlaps up to 0.95 R (the grain's
        # centre stays clear of the grid's axis); deeper still stops the run.
        sc.max_overlap_ratio = 0.95
        log(f"{p.geogrid} geogrid: {len(grid.nodes)} nodes, {len(grid.links)} members, "
            f"R_c = {layer.radius(p) * 1e3:.2f} mm, held until the isotropic stage")
    n_grains = measure.grain_of_body(sc)[1]
    what = (f"{n_grains} grains (clumps of {sc.num_bodies} spheres in all)" if sc.num_clumps
            else f"{n_grains} grains")
    log(f"{what}, box {np.round(measure.box_size(sc, walls), 4)} m, "
        f"{dem.threads_for(sc)} threads, dt {sc.dt:.3g} s")
    return sample, grid, layer, n_grains, psd_info


#: The file --resume keeps and starts from (the other files of stage 1 are written again
#: from the loaded state, the same bytes).
RESUME_KEEP = ("isotropic.h5",)


def restore(p: Params, out: Path, log) -> Prepared:
    """The state after stage 1 of an earlier run of the same parameters, from its checkpoint
    ``out/isotropic.h5`` (--resume): the sample is rebuilt and the checkpoint loaded into it
    (its controllers' state included), so stage 2 runs as it did."""
    sample, grid, _layer, n_grains, psd_info = build(p, log)
    sc = sample.scene
    growth = None
    if not p.packing and not p.skip_isotropic:
        # the expansion's controller, as prepare() left it (disabled): the checkpoint holds
        # the state of the same controllers in the same order
        growth = dem.RadiusGrowth(walls=list(sample.walls), bodies=[],
                                  target_stress=p.cell_pressure, gain=0.5, max_strain=1e-4)
        sc.add_controller(growth)
    extra = load_checkpoint(out / "isotropic.h5", sc)
    if growth is not None:
        growth.enabled = False
    if not p.packing and p.prep_friction != p.phi:
        prep.set_friction(sc, np.flatnonzero(measure.sphere_mask(sc)),
                          sc.material(sample.material), p.phi)
    if grid is not None:
        sc.block_dofs(grid.nodes, "")
    st = extra.get("isotropic")
    if not isinstance(st, dict):
        raise SystemExit(f"error: --resume: {out / 'isotropic.h5'} has no record of the "
                         "isotropic stage (written by an older version); run again with "
                         "--overwrite")
    iso = prep.StageResult(True, int(st["steps"]), np.asarray(st["axis_stresses"], float),
                           float(st["mean_stress"]), float(st["unbalanced_force"]),
                           float(st["porosity"]), dict(st.get("extra", {})))
    gf = extra.get("growth_factor")
    grow = prep.StageResult(True, 0, iso.axis_stresses, iso.mean_stress, 0.0, 0.0,
                            {"growth_factor": gf}) if gf is not None else None
    log(f"--resume: the state after the isotropic stage loaded from {out / 'isotropic.h5'} "
        f"(step {sc.step_count}, t = {sc.time:.4g} s); the deviatoric stage runs again")
    return Prepared(sample, grid, n_grains, psd_info, grow, iso, float(st.get("wall_s", 0.0)))


def prepare(p: Params, log) -> Prepared:
    """Stages 0 and 1: the sample (or the given packing), the geogrid layer if any, the
    expansion to the cell pressure, the isotropic stage; progress lines go to ``log``.
    Raises SystemExit if the isotropic stage does not converge."""
    sample, grid, layer, n_grains, psd_info = build(p, log)
    sc, walls = sample.scene, sample.walls

    def progress(s) -> None:
        if s.step_count % 2000 == 0:
            ax = measure.axis_stresses(s, walls)
            log(f"step {s.step_count}: axis stresses {np.round(ax / 1e3, 2)} kPa, unbalanced "
                f"{s.unbalanced_force():.3g}, porosity {measure.porosity(s, walls):.4f}")

    grow = None
    if p.skip_isotropic:
        # Another code's state, continued as it is: the walls where it had them, no growth, no
        # servo stage; the controller holds the cell pressure from the deviatoric stage on.
        if grid is not None:
            sc.block_dofs(grid.nodes, "")
        sample.controller.enabled = False
        sc.run(1)  # the contact forces of the given state
        ax = measure.axis_stresses(sc, walls)
        iso = prep.StageResult(True, 1, ax, float(ax.mean()), float(sc.unbalanced_force()),
                               measure.porosity(sc, walls), {"skipped": True})
        log(f"isotropic stage skipped (--skip-isotropic): axis stresses of the given state "
            f"{np.round(ax / 1e3, 3)} kPa, porosity {iso.porosity:.4f}")
        for a in range(3):
            sample.controller.set_stress(a, p.cell_pressure)
        sample.controller.enabled = True
        return Prepared(sample, grid, n_grains, psd_info, None, iso, 0.0)
    if not p.packing:
        t0 = time.perf_counter()
        # Slow growth (1e-4 radius strain per step at most) lets the grains rearrange.
        grow = prep.grow_to_stress(sc, walls, p.cell_pressure, tol=0.05, unbalanced=0.05,
                                   max_strain=1e-4,
                                   max_steps=200_000, callback=progress)
        log(f"expansion: {grow.steps} steps, growth factor {grow.extra['growth_factor']:.4f}, "
            f"mean stress {grow.mean_stress / 1e3:.2f} kPa, porosity {grow.porosity:.4f} "
            f"({time.perf_counter() - t0:.1f} s)")
        if p.prep_friction != p.phi:
            prep.set_friction(sc, np.flatnonzero(measure.sphere_mask(sc)),
                              sc.material(sample.material), p.phi)
    if grid is not None:
        sc.block_dofs(grid.nodes, "")  # the geogrid is free from the isotropic stage on
    t0 = time.perf_counter()
    iso = isotropic_stage(sample, p.cell_pressure, callback=progress)
    t_iso = time.perf_counter() - t0
    if not iso.converged:
        raise SystemExit(f"error: isotropic stage did not converge in {iso.steps} steps "
                         f"(axis stresses {iso.axis_stresses} Pa, unbalanced "
                         f"{iso.unbalanced_force:.3g})")
    log(f"isotropic: {iso.steps} steps, axis stresses {np.round(iso.axis_stresses / 1e3, 3)} "
        f"kPa, unbalanced {iso.unbalanced_force:.4f}, porosity {iso.porosity:.4f} "
        f"({t_iso:.1f} s)")
    return Prepared(sample, grid, n_grains, psd_info, grow, iso, t_iso)


def inertial_number(sc, p: Params) -> float:
    """Inertial number of the axial loading, I = strain_rate x d_mean x sqrt(rho / p_cell), -
    (d_mean: mean grain diameter, m). Below ~1e-3 the loading is quasi-static."""
    d_mean = float(np.mean(measure.grain_diameters(sc)))
    return p.strain_rate * d_mean * math.sqrt(p.density / p.cell_pressure)


def interrupted_report(p: Params, out: Path, finished: list, numbers: dict) -> None:
    """What an interrupted run reports (rundir.on_interrupt): summary.json with the stages
    it finished (``finished``; the axial loading to the strain reached) and their numbers
    (``numbers``: the isotropic state; the peak q so far, read from triaxial.csv), and
    triaxial.png of the loading so far."""
    def loading():
        from cpp_dem.io import read_csv_series

        try:
            rows = read_csv_series(out / "triaxial.csv")
        except (FileNotFoundError, ValueError):
            return None
        return rows if len(rows.get("axial_strain", ())) >= 2 else None

    def summary() -> dict:
        s = {"finished": list(finished), **numbers}
        rows = loading()
        if rows is not None:
            ea, q = rows["axial_strain"], rows["deviatoric_stress"]
            k = int(np.argmax(q))
            s["finished"].append(f"axial loading to {100 * ea[-1]:.3g} % of "
                                 f"{100 * p.stop_strain:g} %")
            s.update(axial_strain_reached=float(ea[-1]), q_peak_so_far_Pa=float(q[k]),
                     axial_strain_at_peak_so_far=float(ea[k]),
                     volumetric_strain_last=float(rows["volumetric_strain"][-1]))
        return s

    def figures() -> None:
        rows = loading()
        if rows is not None:
            plot(rows, out / "triaxial.png", p, f" (interrupted at axial strain "
                                                f"{100 * rows['axial_strain'][-1]:.3g} %)")

    on_interrupt(out, summary=summary, figures=figures)


def run(p: Params, out: Path, *, resume: bool = False) -> dict:
    """Runs the case into ``out``; ``resume``: from the checkpoint of stage 1 there."""
    t_start = time.perf_counter()
    apply_threads(p.threads)
    begin_run(out, "triaxial", keep=RESUME_KEEP if resume else None)
    (out / "vtk").mkdir(exist_ok=True)
    finished: list[str] = []  # for the summary of an interrupted run
    numbers: dict = {}
    interrupted_report(p, out, finished, numbers)

    def log(msg: str) -> None:
        print(f"[triaxial] {msg}", flush=True)

    if p.specimen == "cylinder":
        summary = triaxial_cylinder.run(p, out, log, plot)
        end_run(out)
        return summary

    prepared = restore(p, out, log) if resume else prepare(p, log)
    sample, grid, n_grains, iso, t_iso = (prepared.sample, prepared.grid, prepared.n_grains,
                                          prepared.iso, prepared.t_iso)
    sc, walls, grow, psd_info = sample.scene, sample.walls, prepared.grow, prepared.psd_info
    finished += (["expansion"] if grow is not None and not resume else []) + [
        "isotropic stage" + (" (skipped: --skip-isotropic)" if p.skip_isotropic else
                             " (loaded from isotropic.h5: --resume)" if resume else "")]
    numbers.update(num_grains=n_grains, porosity_isotropic=iso.porosity,
                   isotropic_axis_stresses_Pa=np.asarray(iso.axis_stresses).tolist(),
                   isotropic_unbalanced=iso.unbalanced_force,
                   expansion_growth_factor=grow.extra["growth_factor"] if grow else None)
    if p.preset:
        p.strain_rate = apply_preset(sample, p.preset, pressure=p.cell_pressure,
                                     density=p.density)
        log(f"preset {p.preset!r}: dt {sc.dt:.3g} s, local damping {sc.local_damping:g}, "
            f"strain rate {p.strain_rate:.3g} 1/s")
    log(f"axial loading at {p.strain_rate:g} 1/s: inertial number "
        f"{inertial_number(sc, p):.2g} (quasi-static below ~1e-3)")
    state_iso = measure.sample_state(sc, walls)
    if not resume:
        save_checkpoint(out / "isotropic.h5", sc, extra={
            "walls": list(walls), "growth_factor": grow.extra["growth_factor"] if grow else None,
            "isotropic": {"steps": iso.steps, "axis_stresses": np.asarray(
                iso.axis_stresses, float).tolist(), "mean_stress": float(iso.mean_stress),
                "unbalanced_force": float(iso.unbalanced_force),
                "porosity": float(iso.porosity), "wall_s": t_iso,
                "extra": json.loads(json.dumps(iso.extra, default=str))}})
    write_grains_csv(sc, out, "isotropic")  # packing_ (grains only) and clumps_isotropic.csv
    # The series vtk/spheres.pvd and vtk/box.pvd: the isotropic (prepared) state, then the end.
    pvds = {k: PvdWriter(out / "vtk" / f"{k}.pvd", overwrite=True) for k in ("spheres", "box")}

    def write_vtk_stage(name: str) -> None:
        size = measure.box_size(sc, walls)
        lo_now = np.array([sc.wall_positions[walls[2 * a]] for a in range(3)])
        files = {"spheres": write_vtk_spheres(out / "vtk" / f"spheres_{name}.vtp", sc),
                 "box": write_vtk_box(out / "vtk" / f"box_{name}.vtp", lo_now, lo_now + size,
                                      time=sc.time)}
        for k, f in files.items():
            pvds[k].add(sc.time, f.name)

    write_vtk_stage("isotropic")

    meta = {**asdict(p), "case": "triaxial", "axial_axis": "z", "psd": psd_info,
            "units": "SI; stresses and strains compression positive"}
    h5_series = dict(SERIES)
    if grid is not None:
        # The geogrid's member forces with every record: (n_members,) N, tension positive.
        h5_series["member_axial_force"] = (lambda scene: grid.member_axial_forces(scene), "N")
    h5 = H5Recorder(out / "triaxial.h5", sc, series=h5_series, metadata=meta, overwrite=True,
                    snapshot_fields=("positions", "velocities", "radii"))
    csv = CsvRecorder(out / "triaxial.csv", series=SERIES, overwrite=True)
    last = [time.perf_counter()]

    def on_record(row: dict) -> None:
        h5.record(**row)
        csv.record(**row)
        if time.perf_counter() - last[0] > 5:
            last[0] = time.perf_counter()
            log(f"eps_a {100 * row['axial_strain']:.2f} %  eps_v "
                f"{100 * row['volumetric_strain']:.3f} %  q {row['deviatoric_stress'] / 1e3:.2f}"
                f" kPa  sigma_x,y {row['sigma_x'] / 1e3:.2f},{row['sigma_y'] / 1e3:.2f} kPa")

    t0 = time.perf_counter()
    steps0 = sc.step_count
    try:
        rows = deviatoric_stage(sample, p.cell_pressure, p.strain_rate, p.stop_strain,
                                record_every=p.record_every, on_record=on_record)
        h5.snapshot(sc)
    finally:
        h5.close()
        csv.close()
    t_dev = time.perf_counter() - t0
    dev_steps = sc.step_count - steps0
    write_vtk_stage("final")
    if grid is not None:
        geogrid.write_vtk_geogrid(out / "vtk" / "geogrid_final.vtp", sc, grid)
    plot(rows, out / "triaxial.png", p)

    ea = rows["axial_strain"]
    late = ea > 0.2 * p.stop_strain  # lateral hold measured once loading is under way
    lat = np.concatenate([rows["sigma_x"][late], rows["sigma_y"][late]])
    k_peak = int(np.argmax(rows["deviatoric_stress"]))
    q_peak = float(rows["deviatoric_stress"][k_peak])
    s_peak = q_peak + p.cell_pressure
    summary = {
        "num_grains": n_grains, "grains": p.grains, "num_clumps": int(sc.num_clumps),
        "num_spheres": int(np.count_nonzero(measure.sphere_mask(sc))), "axial_axis": "z",
        "geogrid": p.geogrid, "geogrid_members": int(len(grid.links)) if grid else 0,
        "geogrid_max_axial_force_N": float(np.max(grid.member_axial_forces(sc))) if grid
        else None,
        "porosity_isotropic": iso.porosity,
        "isotropic_axis_stresses_Pa": iso.axis_stresses.tolist(),
        "isotropic_unbalanced": iso.unbalanced_force,
        "isotropic_love_weber_Pa": np.diag(state_iso["love_weber"]).tolist(),
        "coordination_isotropic": state_iso["coordination"],
        "coordination_mechanical_isotropic": state_iso["coordination_mechanical"],
        "q_peak_Pa": q_peak, "axial_strain_at_peak": float(ea[k_peak]),
        "friction_angle_peak_deg": math.degrees(math.asin((s_peak - p.cell_pressure) /
                                                          (s_peak + p.cell_pressure))),
        "volumetric_strain_final": float(rows["volumetric_strain"][-1]),
        "volumetric_strain_min": float(rows["volumetric_strain"].min()),
        "lateral_stress_max_rel_error": float(np.max(np.abs(lat / p.cell_pressure - 1)))
        if lat.size else float("nan"),
        "deviatoric_steps": dev_steps,
        "inertial_number": inertial_number(sc, p),
        "wall_time_isotropic_s": t_iso, "wall_time_deviatoric_s": t_dev,
        "particle_steps_per_s_deviatoric": n_grains * dev_steps / t_dev,
        "wall_time_total_s": time.perf_counter() - t_start,
        "expansion_growth_factor": grow.extra["growth_factor"] if grow else None,
        "threads": dem.get_num_threads(),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    end_run(out)
    log(f"peak q {q_peak / 1e3:.2f} kPa at eps_a {100 * ea[k_peak]:.2f} % (mobilised friction "
        f"{summary['friction_angle_peak_deg']:.1f} deg); final eps_v "
        f"{100 * summary['volumetric_strain_final']:.3f} %; lateral stress within "
        f"{100 * summary['lateral_stress_max_rel_error']:.2f} % of the cell pressure")
    log(f"wall time: isotropic {t_iso:.1f} s, deviatoric {t_dev:.1f} s ({dev_steps} steps, "
        f"{summary['particle_steps_per_s_deviatoric']:.3g} particle-steps/s), total "
        f"{summary['wall_time_total_s']:.1f} s")
    return summary


def _positive(name: str, ap):
    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            ap.error(f"{name}={s!r}: not a number")
        if not (math.isfinite(v) and v > 0):
            ap.error(f"{name}={v}: must be > 0")
        return v
    return conv


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    d = Params()
    ap = case_parser(
        "triaxial", describe("triaxial", "Triaxial test of the thesis's chapter 6 (its "
                             "Appendix B script). The AXIAL axis is z; x and y are held at "
                             "the cell pressure. Stresses and strains compression positive."),
        smoke=f"{SMOKE['n']} grains in a box scaled down with the count, faster loading, stop "
              "at 4 %% axial strain", seed=d.seed,
        preset="of the axial loading (dt safety, local damping, strain rate from an inertial "
               "number; overrides --strain-rate, --damping, --dt-safety for that stage)")
    ap.add_argument("--packing", type=str, default="",
                    help="start from these spheres (m), in the box they span or --box")
    ap.add_argument("--packing-format", choices=("csv", "yade", "liggghts", "pfc"),
                    default="csv", help="csv (x,y,z,r), Yade text, LIGGGHTS data file, PFC "
                    "ball list (cpp_dem.io.foreign)")
    ap.add_argument("--box", type=str, default="",
                    help="wall planes x0,y0,z0,x1,y1,z1 (m) of the --packing (default: its "
                         "bounding box, or a LIGGGHTS file's box)")
    ap.add_argument("--resume", action="store_true",
                    help="continue the interrupted run in --out (same parameters) from its "
                         "checkpoint isotropic.h5: stage 2 runs again from its start")
    ap.add_argument("--skip-isotropic", action="store_true",
                    help="with --packing: take its state as it is (walls at --box, no growth, "
                         "no isotropic stage) and go straight to the axial loading")
    ap.add_argument("--n", type=int, default=None, help="target number of grains (default "
                    f"{d.n}; the box is scaled with it when != {d.n})")
    ap.add_argument("--cell-pressure", type=_positive("--cell-pressure", ap),
                    default=d.cell_pressure, help="cell (confining) pressure, Pa, > 0")
    ap.add_argument("--strain-rate", type=_positive("--strain-rate", ap), default=None,
                    help=f"axial strain rate, 1/s (default {d.strain_rate})")
    ap.add_argument("--stop-strain", type=float, default=None,
                    help=f"axial strain to stop at, - (default {d.stop_strain})")
    ap.add_argument("--damping", type=float, default=d.damping, help="local damping, [0, 1)")
    ap.add_argument("--young", "--E", dest="young", type=_positive("--young", ap),
                    default=d.young, help="Young's modulus of the grains, Pa")
    ap.add_argument("--poisson", "--nu", dest="poisson", type=float, default=d.poisson,
                    help="k_s/k_n of the linear law, (0, 0.5]")
    ap.add_argument("--phi", type=float, default=d.phi, help="contact friction angle, deg")
    ap.add_argument("--prep-friction", type=float, default=None,
                    help="friction during sample expansion, deg (default = --phi; 0 gives a "
                         "dense sample)")
    ap.add_argument("--density", type=_positive("--density", ap), default=d.density,
                    help="grain density, kg/m^3")
    ap.add_argument("--geogrid", choices=("none", "square", "triangular"), default="none",
                    help="geogrid layer at mid-height (the thesis's §6.3, its grids of §5.1); "
                         "with --specimen cylinder a disc of the same grid")
    ap.add_argument("--clear-layer", action="store_true",
                    help="remove the grains of the geogrid layer even without a geogrid, so "
                    "that runs with and without one start from the same packing")
    ap.add_argument("--grain-scale", type=_positive("--grain-scale", ap), default=1.0,
                    help="multiply every grain size by this after the PSD is fitted to --n: "
                    "the same box with about n / scale^3 grains (coarse graining), > 0")
    ap.add_argument("--grains", type=str, default=d.grains,
                    help=GRAINS_HELP + "; the PSD gives equivalent-volume diameters")
    ap.add_argument("--dt-safety", type=float, default=d.dt_safety,
                    help="time step = safety x critical estimate, (0, 1], renewed every 100 "
                         "steps (with --specimen cylinder, without it: the protocol's, 0.3 of "
                         "the grains' p-wave estimate in the mould, kept)")
    ap.add_argument("--specimen", choices=("box", "cylinder"), default=d.specimen,
                    help="box: six servo-controlled walls (the thesis); cylinder: the box's "
                         "inscribed cylinder (diameter its x side, height its z side) in a "
                         "flexible membrane under the cell pressure, as in the laboratory "
                         "(docs/triaxial.md)")
    ap.add_argument("--membrane-side", type=float, default=d.membrane_side,
                    help="with --specimen cylinder: the membrane's triangles' side in "
                         "smallest grain radii, 0.75 to 2 (1: finer than the grains, as "
                         "rubber; 2: as wide as the smallest grain, about 4 x fewer nodes "
                         "and faster: docs/studies/membrane_resolution.md)")
    return ap


def parse_args(argv=None) -> tuple[Params, Path]:
    ap = build_parser()
    a = parse_checked(ap, argv)
    given = given_options(ap, argv)
    p = Params(**SMOKE) if a.smoke else Params()
    if a.n is not None:
        if a.n < 10:
            ap.error(f"--n={a.n}: must be >= 10")
        p.n = a.n
    if p.n != 15000:
        p.box = smoke_box(p)
    p.cell_pressure, p.damping, p.young, p.poisson = (a.cell_pressure, a.damping, a.young,
                                                       a.poisson)
    p.phi, p.density, p.seed, p.threads = a.phi, a.density, a.seed, a.threads
    p.geogrid, p.clear_layer = a.geogrid, a.clear_layer
    p.grain_scale, p.dt_safety, p.preset = a.grain_scale, a.dt_safety, a.preset
    check_grains(ap, a.grains)
    if a.grains != "spheres":
        if a.packing:
            ap.error("--grains: clumps are generated; --packing gives spheres")
    p.grains = a.grains
    if not (0 < p.dt_safety <= 1):
        ap.error(f"--dt-safety={p.dt_safety}: must be in (0, 1]")
    p.prep_friction = a.prep_friction if a.prep_friction is not None else a.phi
    if a.strain_rate is not None:
        p.strain_rate = a.strain_rate
    if a.stop_strain is not None:
        p.stop_strain = a.stop_strain
    if not (0 < p.stop_strain < 0.5):
        ap.error(f"--stop-strain={p.stop_strain}: must be in (0, 0.5)")
    if not (0 <= p.damping < 1):
        ap.error(f"--damping={p.damping}: must be in [0, 1)")
    if not (0 < p.poisson <= 0.5):
        ap.error(f"--poisson={p.poisson}: must be in (0, 0.5] for the linear law")
    for name, v in (("--phi", p.phi), ("--prep-friction", p.prep_friction)):
        if not (0 <= v < 90):
            ap.error(f"{name}={v}: must be in [0, 90) deg")
    if a.packing:
        if not Path(a.packing).is_file():
            ap.error(f"--packing={a.packing}: no such file")
        p.packing = a.packing
    p.packing_format = a.packing_format
    if a.box:
        try:
            box = tuple(float(v) for v in a.box.split(","))
        except ValueError:
            ap.error(f"--box={a.box}: must be 6 numbers x0,y0,z0,x1,y1,z1 (m)")
        if len(box) != 6 or not all(math.isfinite(v) for v in box) or \
                not all(box[k + 3] > box[k] for k in range(3)):
            ap.error(f"--box={a.box}: must be 6 finite numbers x0,y0,z0,x1,y1,z1 (m) with "
                     "x1 > x0, y1 > y0, z1 > z0")
        if not a.packing:
            ap.error("--box: goes with --packing")
        p.box = box
    if a.skip_isotropic and not a.packing:
        ap.error("--skip-isotropic: goes with --packing (the state to continue)")
    p.skip_isotropic = a.skip_isotropic
    # options that would have no effect given the others (docs/cli.md)
    if a.packing:
        for dest in ("n", "grain_scale", "seed"):
            refuse_unused(ap, a, given, dest, "with --packing (its spheres are the sample)")
        refuse_unused(ap, a, given, "prep_friction",
                      "with --packing (no expansion: the packing is given)")
    else:
        refuse_unused(ap, a, given, "packing_format", "without --packing",
                      "give the --packing it reads")
    if a.preset:
        refuse_unused(ap, a, given, "strain_rate",
                      f"with --preset {a.preset} (the preset sets the axial strain rate)")
    if a.geogrid != "none":
        refuse_unused(ap, a, given, "clear_layer",
                      f"with --geogrid {a.geogrid} (its layer is cleared anyway)")
    if not a.packing:
        check_cap(ap, a, "--n" if p.grain_scale == 1.0 else "--n/--grain-scale",
                  p.n if p.grain_scale == 1.0 else f"{p.n}/{p.grain_scale:g}",
                  p.n / p.grain_scale ** 3, "grains", estimate=p.grain_scale != 1.0)
    if a.resume:
        if a.out is None:
            ap.error("--resume: name the folder of the interrupted run with --out")
        if a.overwrite:
            ap.error("--resume and --overwrite: choose one (--resume keeps stage 1's files)")
    p.resume = a.resume
    p.specimen = a.specimen
    from cpp_dem.protocols.cylinder_triaxial import membrane_side_problem

    problem = membrane_side_problem(a.membrane_side)
    if problem:
        ap.error(f"--membrane-side={a.membrane_side}: {problem}")
    p.membrane_side = a.membrane_side
    if a.specimen != "cylinder":
        refuse_unused(ap, a, given, "membrane_side",
                      f"with --specimen {a.specimen} (there is no membrane)")
    if a.specimen == "cylinder":
        why = "with --specimen cylinder"
        for dest, what in (("packing", "(the cylinder's grains are generated)"),
                           ("skip_isotropic", "(the membrane holds the specimen first)"),
                           ("prep_friction", "(the mould compacts at --phi)"),
                           ("preset", "(its loading runs at --strain-rate)"),
                           ("resume", "(it keeps no checkpoint)")):
            refuse_unused(ap, a, given, dest, f"{why} {what}")
        if a.grains != "spheres":
            ap.error(f"--grains={a.grains}: {why}: spheres only (the box takes clumps)")
        # (given: that fraction of the critical step, renewed; else the protocol's step)
        p.dt_safety = a.dt_safety if "dt_safety" in given else None
    warn_below("--cell-pressure", a.cell_pressure, 1e3, "Pa",
               f"kPa given as Pa? {a.cell_pressure:g} kPa is --cell-pressure "
               f"{a.cell_pressure * 1e3:g}")
    warn_below("--density", a.density, 500.0, "kg/m^3",
               f"g/cm^3 or t/m^3 given as kg/m^3? {a.density:g} g/cm^3 is --density "
               f"{a.density * 1e3:g}")
    return p, a.out


def main(argv=None) -> int:
    p, out = parse_args(argv)
    resume = p.__dict__.pop("resume", False)
    # (the parameters and isotropic.h5's SHA-256 go into the manifest: --resume continues
    # the same run or refuses, rundir.begin_run)
    return run_main("triaxial", out, lambda o: run(p, o, resume=resume),
                    keep=RESUME_KEEP if resume else None, params=p, checkpoints=RESUME_KEEP)


if __name__ == "__main__":
    sys.exit(main())
