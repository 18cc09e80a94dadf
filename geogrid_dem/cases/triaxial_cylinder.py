"""The triaxial case's cylindrical specimen in a flexible membrane (``triaxial --specimen
cylinder``; issue 65; docs/triaxial.md, "A cylindrical specimen"): the laboratory's test beside
the thesis's cubical one.

The specimen is about the box's inscribed cylinder: diameter the box's x side, height its z
side (0.3 x 0.6 m by default, H / D = 2 as in the laboratory; the smoke scales it with the
grain count as it scales the box). The mould starts that cylinder scaled by (solid fraction /
cloud fraction)^(1/3), to hold the loose cloud, and its servos compact it to the cell
pressure: the specimen's size is what the compaction leaves (summary.json). The grains are
the App. B sieve curve fitted to ``--n`` in the cylinder's volume.
:func:`cpp_dem.protocols.cylinder_triaxial.prepare` compacts them in a rigid mould to the cell
pressure and then holds them in a membrane (modulus 1 MPa, 0.3 mm thick: a latex membrane)
under the cell pressure alone, the platens frictionless;
:func:`cpp_dem.protocols.cylinder_triaxial.shear` moves the lid down at the strain rate with
the cell pressure held on the membrane.

With ``--geogrid square`` or ``triangular`` the specimen holds a disc of the box's grid at
mid-height (:class:`Disc`, :func:`cpp_dem.build.geogrid.disc_grid`): 9.5 cm across, or 0.6
of the specimen's diameter in a smaller one, the grains that cut its slab removed. The disc
and the membrane do not touch each other in the model; a run whose disc ends with a node
outside the membrane says so and exits with an error.

Outputs in --out: triaxial.csv (axial_strain, volumetric_strain from the volume inside the
membrane, deviatoric_stress on the current cross-section, axial_stress at the lid and
base_stress at the base (less by what the membrane carries through its friction with the
grains, and by the loading's dynamics: summary.json's platen_difference_max),
unbalanced_force (as the box's), radial_stress: the grains' radial stress on the membrane's
middle third, membrane_correction: it less the cell pressure, area, grains_outside),
triaxial.png and .pdf, vtk/ (the spheres, membrane nodes included, at the end of the hold and
at the end; geogrid_final.vtp with a disc), summary.json. SI units; stresses and strains
compression positive.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem.build import geogrid, psd
from cpp_dem.io import CsvRecorder, PvdWriter, write_vtk_spheres
from cpp_dem.measure import inertial
from cpp_dem.protocols import cylinder_triaxial as cyl
from geogrid_dem.cases import thesis_grids

#: triaxial.csv's columns: (None, unit), as the box's SERIES
SERIES = {"time": (None, "s"), "step": (None, "-"), "axial_strain": (None, "-"),
          "volumetric_strain": (None, "-"), "deviatoric_stress": (None, "Pa"),
          "axial_stress": (None, "Pa"), "base_stress": (None, "Pa"),
          "radial_stress": (None, "Pa"),
          "membrane_correction": (None, "Pa"), "area": (None, "m^2"),
          "unbalanced_force": (None, "-"),
          "grains_outside": (None, "-")}


def geometry(box) -> tuple[float, float]:
    """The specimen's radius and height (m) from the case's box (x, y, z): the inscribed
    cylinder, diameter the x side, height the z side."""
    return 0.5 * float(box[0]), float(box[2])


def radii(p, log) -> tuple[np.ndarray, dict]:
    """The grains' radii (m): App. B by mass, fitted to ``p.n`` grains at ``p.solid_fraction``
    of the cylinder's volume (the box's truncation rule), times ``p.grain_scale``."""
    r_m, h_m = geometry(p.box)
    vol_solid = p.solid_fraction * math.pi * r_m ** 2 * h_m
    d, pc, d_min = psd.fit_psd_to_count(psd.APPENDIX_B_SIZES, psd.APPENDIX_B_PASSING, p.n,
                                        vol_solid, by="mass", method="truncate")
    d = d * p.grain_scale
    n = int(round(psd.expected_count(d, pc, vol_solid, by="mass")))
    rad = psd.radii_from_psd(d, pc, n, by="mass", seed=p.seed)
    log(f"PSD: App. B by mass in the cylinder, fines below d_min = "
        f"{d_min * p.grain_scale * 1e3:.2f} mm removed -> {n} grains, d = "
        f"{2 * rad.min() * 1e3:.1f}-{2 * rad.max() * 1e3:.1f} mm")
    return rad, {"d_min_m": d_min * p.grain_scale, "sizes_m": d.tolist(),
                 "passing_mass": pc.tolist(), "grains": "spheres"}


@dataclass
class Disc:
    """A geogrid disc at mid-height of the mould (``--geogrid`` with ``--specimen cylinder``):
    the box's layer cut round, 9.5 cm across (or 0.6 of the specimen's diameter in a smaller
    specimen: the mould compacts to about 0.9 of it), the same material and members; free
    from the start, it is compacted with the grains. ``pattern="none"`` (``--clear-layer``)
    removes the same grains and adds no grid: the same packing without it."""

    pattern: str
    radius_m: float
    grid: object = None

    def __call__(self, sc, centres, radii):
        """The cylinder protocol's ``inclusion``: adds the disc at mid-height of the grains'
        cloud and returns the grains to keep (those that do not cut its slab,
        :data:`geogrid_dem.cases.thesis_grids.SLAB_M` either side of its plane over its
        footprint, whatever the grid: the box's rule)."""
        z = 0.5 * (float(np.min(centres[:, 2] - radii)) + float(np.max(centres[:, 2] + radii)))
        if self.pattern != "none":
            mat, beam = thesis_grids.add_grid_material(sc, self.pattern)
            self.grid = geogrid.disc_grid(sc, centre=[0.0, 0.0, z], radius=self.radius_m,
                                          spacing=thesis_grids.GRIDS[self.pattern][1],
                                          pattern=self.pattern, params=beam, material=mat,
                                          density=2650.0)
            # soft grain-grid contacts (R_c in the mixing rule), as in the box: overlaps to
            # 0.95 R
            sc.max_overlap_ratio = 0.95
        slab = thesis_grids.SLAB_M
        cuts = ((np.linalg.norm(centres[:, :2], axis=1) < self.radius_m + radii + slab)
                & (np.abs(centres[:, 2] - z) < radii + slab))
        return ~cuts


def disc(p, r_m: float):
    """The case's disc for ``p.geogrid`` in a specimen of radius ``r_m`` (m): a grid, the
    slab cleared without one (``p.clear_layer``), or None."""
    if p.geogrid == "none" and not p.clear_layer:
        return None
    return Disc(p.geogrid, 0.5 * min(0.095, 0.6 * 2 * r_m))


def nodes_outside(spec, grid) -> int:
    """The disc's nodes beyond the membrane's mid-surface (the membrane and the grid do not
    touch each other in the model: a disc that reached the membrane would pass through it)."""
    x = np.asarray(spec.scene.positions)[grid.nodes]
    r = np.linalg.norm(x[:, :2] - spec.membrane.centre[:2], axis=1)
    bound = spec.membrane.surface_radius_m(spec.scene, x)
    return int(np.count_nonzero(~(r < bound)))


def _rows_to_series(sc, r: dict, t0: float) -> dict:
    return {"time": sc.time - t0, "step": r["step"], "axial_strain": r["axial_strain"],
            "volumetric_strain": r["volumetric_strain"],
            "deviatoric_stress": r["deviatoric_stress_pa"], "axial_stress": r["axial_stress_pa"],
            "base_stress": r["base_stress_pa"],
            "radial_stress": r["radial_stress_pa"],
            "membrane_correction": r["membrane_correction_pa"], "area": r["area_m2"],
            "unbalanced_force": r["unbalanced_force"],
            "grains_outside": r["grains_outside"]}


def run(p, out: Path, log, plot) -> dict:
    """The cylindrical specimen's test into ``out`` (the module doc); ``plot(rows, png, p,
    note)`` draws the box's three panels. Returns the summary."""
    t_start = time.perf_counter()
    r_m, h_m = geometry(p.box)
    rad, psd_info = radii(p, log)
    mat = dem.linear_material(density=p.density, young=p.young, poisson=p.poisson,
                              friction_angle_deg=p.phi)
    log(f"cylinder: radius {r_m:.4f} m, height {h_m:.4f} m (H / D = {h_m / (2 * r_m):.2f}), "
        f"{len(rad)} grains, membrane 1 MPa x 0.3 mm, frictionless platens")
    # the mould holds the loose cloud (at the box's cloud fraction); the servos compact it
    # to about the specimen's size at the solid fraction
    grow = (p.solid_fraction / p.cloud_fraction) ** (1.0 / 3.0)
    t0 = time.perf_counter()
    layer = disc(p, r_m)
    spec = cyl.prepare(rad, radius_m=grow * r_m, height_m=grow * h_m,
                       pressure_pa=p.cell_pressure, material=mat, seed=p.seed,
                       damping=p.damping, membrane_side=p.membrane_side,
                       dt_safety=p.dt_safety, inclusion=layer, log=log)
    mb = spec.membrane
    log(f"membrane: {len(mb.nodes)} nodes, links {1e3 * mb.link_length_m:.2f} mm long "
        f"(--membrane-side {p.membrane_side:g}: its triangles' side in smallest grain radii); "
        + ("time step 0.3 of the grains' p-wave estimate in the mould, kept: "
           f"{spec.scene.dt:.3g} s" if p.dt_safety is None else
           f"time step {p.dt_safety:g} of the critical one, renewed every 100 steps: "
           f"{spec.scene.dt:.3g} s at the hold"))
    grid = layer.grid if layer is not None else None
    if layer is not None and grid is None:
        log(f"the disc's slab cleared ({2 * layer.radius_m * 1e3:.0f} mm across, at "
            "mid-height), no grid: --clear-layer")
    if grid is not None:
        log(f"{p.geogrid} geogrid disc: {len(grid.nodes)} nodes, {len(grid.links)} members, "
            f"{2 * layer.radius_m * 1e3:.0f} mm across, at mid-height, free from the start")
    t_prep = time.perf_counter() - t0
    sc, prepared = spec.scene, spec.prepared
    if not prepared.get("reached", False):
        raise SystemExit(f"error: the cylindrical specimen did not reach the cell pressure "
                         f"in its preparation ({prepared}); give more grains (--n) or a "
                         "lower --cell-pressure")
    held = cyl.row(spec)
    log(f"held in the membrane: radial stress {held['radial_stress_pa'] / 1e3:.2f} kPa "
        f"(cell {p.cell_pressure / 1e3:g} kPa: membrane correction "
        f"{held['membrane_correction_pa'] / 1e3:+.2f} kPa), axial "
        f"{held['axial_stress_pa'] / 1e3:.2f} kPa, {held['grains_outside']} grains outside "
        f"({t_prep:.1f} s)")
    (out / "vtk").mkdir(exist_ok=True)
    pvd = PvdWriter(out / "vtk" / "spheres.pvd", overwrite=True)
    pvd.add(sc.time, write_vtk_spheres(out / "vtk" / "spheres_isotropic.vtp", sc).name)
    csv = CsvRecorder(out / "triaxial.csv", series=SERIES, overwrite=True)
    t_shear0, last = sc.time, [time.perf_counter()]
    n_steps = p.stop_strain / (p.strain_rate * sc.dt)

    def on_row(r: dict) -> None:
        csv.record(**_rows_to_series(sc, r, t_shear0))
        if time.perf_counter() - last[0] > 5:
            last[0] = time.perf_counter()
            done = r["axial_strain"] / p.stop_strain
            el = time.perf_counter() - t1
            log(f"eps_a {100 * r['axial_strain']:.2f} %  eps_v "
                f"{100 * r['volumetric_strain']:.3f} %  q {r['deviatoric_stress_pa'] / 1e3:.2f}"
                f" kPa  ({100 * done:.0f} %, ETA {el / max(done, 1e-9) * (1 - done):.0f} s)")

    spec_inertial = cyl.inertial_number(spec, p.strain_rate)
    log(f"shearing at {p.strain_rate:g} /s: inertial number {spec_inertial:.2g}"
        + (f", above the strict quasi-static {inertial.QUASI_STATIC_STRICT:g}: the rate shows "
           "in q (docs/triaxial.md)" if spec_inertial > inertial.QUASI_STATIC_STRICT else
           f" (quasi-static below {inertial.QUASI_STATIC_STRICT:g})"))
    t1 = time.perf_counter()
    steps0 = sc.step_count
    try:
        csv.record(**_rows_to_series(sc, held, t_shear0))
        rows = cyl.shear(spec, strain_rate=p.strain_rate, stop_strain=p.stop_strain,
                         record_every=p.record_every, on_row=on_row)
    finally:
        csv.close()
    t_dev = time.perf_counter() - t1
    dev_steps = sc.step_count - steps0
    pvd.add(sc.time, write_vtk_spheres(out / "vtk" / "spheres_final.vtp", sc).name)
    if grid is not None:
        geogrid.write_vtk_geogrid(out / "vtk" / "geogrid_final.vtp", sc, grid)
    n_grains = int(np.count_nonzero(np.asarray(sc.body_kinds) == 0))
    series = {k: np.array([r[key] for r in rows], float)
              for k, key in (("axial_strain", "axial_strain"),
                             ("volumetric_strain", "volumetric_strain"),
                             ("deviatoric_stress", "deviatoric_stress_pa"))}
    series["time"] = np.arange(len(rows)) * p.record_every * sc.dt
    plot(series, out / "triaxial.png", p, " (cylindrical specimen in a membrane)")
    q = series["deviatoric_stress"]
    k = int(np.argmax(q))
    s_peak = q[k] + p.cell_pressure
    corr = np.array([r["membrane_correction_pa"] for r in rows])
    # The lid (the load cell) against the base: the base carries less by what the membrane
    # takes through its friction with the grains, and by the loading's dynamics.
    platen = max((abs(r["axial_stress_pa"] - r["base_stress_pa"]) / r["axial_stress_pa"]
                  for r in rows), default=0.0)
    summary = {
        "specimen": "cylinder", "radius_m": r_m, "height_m": h_m, "num_grains": n_grains,
        "geogrid": p.geogrid, "geogrid_members": int(len(grid.links)) if grid else 0,
        "geogrid_max_axial_force_N": (float(np.max(grid.member_axial_forces(sc))) if grid
                                      else 0.0),
        "geogrid_disc_diameter_m": 2 * layer.radius_m if layer else 0.0,
        "clear_layer": bool(p.clear_layer),
        "geogrid_nodes_outside": nodes_outside(spec, grid) if grid else 0,
        "psd": psd_info, "membrane": {"young_pa": 1e6, "thickness_m": 3e-4,
                                      "nodes": int(len(spec.membrane.nodes)),
                                      "side": p.membrane_side,
                                      "dt_safety": p.dt_safety,
                                      "link_length_m": spec.membrane.link_length_m},
        "held": {k2: held[k2] for k2 in ("radial_stress_pa", "axial_stress_pa",
                                         "membrane_correction_pa", "grains_outside")},
        "preparation": json.loads(json.dumps(prepared, default=str)),
        "q_peak_Pa": float(q[k]), "axial_strain_at_peak": float(series["axial_strain"][k]),
        "friction_angle_peak_deg": math.degrees(math.asin(q[k] / (s_peak + p.cell_pressure))),
        "volumetric_strain_final": float(series["volumetric_strain"][-1]),
        "volumetric_strain_min": float(series["volumetric_strain"].min()),
        "membrane_correction_max_abs_Pa": float(np.max(np.abs(corr))),
        "platen_difference_max": float(platen),
        "unbalanced_force_max": float(max(r["unbalanced_force"] for r in rows[1:]))
        if len(rows) > 1 else None,
        "inertial_number": spec_inertial,
        "grains_outside_max": int(max(r["grains_outside"] for r in rows)),
        "deviatoric_steps": int(dev_steps), "deviatoric_steps_planned": int(n_steps),
        "wall_time_preparation_s": t_prep, "wall_time_deviatoric_s": t_dev,
        "wall_time_total_s": time.perf_counter() - t_start,
        "threads": dem.get_num_threads(), "params": asdict(p)}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str) + "\n")
    log(f"peak q {q[k] / 1e3:.2f} kPa at eps_a {100 * series['axial_strain'][k]:.2f} % "
        f"(mobilised friction {summary['friction_angle_peak_deg']:.1f} deg); final eps_v "
        f"{100 * summary['volumetric_strain_final']:.3f} % (from the membrane's volume); "
        f"membrane correction up to {summary['membrane_correction_max_abs_Pa'] / 1e3:.2f} kPa;"
        f" {summary['grains_outside_max']} grains outside")
    if summary["geogrid_nodes_outside"]:
        raise SystemExit(f"error: {summary['geogrid_nodes_outside']} of the geogrid disc's "
                         f"nodes ended outside the membrane (the grid and the membrane do not "
                         f"touch in the model): the results in {out} do not hold; give a larger "
                         "specimen (--n) beside the disc")
    return summary
