#!/usr/bin/env python3
"""The prestressed reinforced-soil (PRS) element of the prestressed-element paper (002), with
its boundary stresses from a FEM model.

002 §3: a 0.1 m cube of grains with a geogrid at mid-height, six servo-controlled walls
driven to the stresses "calculated by a multiscale FEM analysis"; reinforced (RE) versus
prestressed reinforced (PRS) soil. Here:

1. **FEM** (``femcoupling``, dolfinx, plane strain): a reinforced fill under a strip footing
   (self-weight with a K0 state, two geogrid layers as thin bands of the geogrid's axial
   stiffness, Drucker–Prager soil matched to Mohr–Coulomb). Solved twice: RE (no prestress)
   and PRS (prestress T_p in the layers, equilibrated with the soil before the footing
   load). The stress averaged over the soil cells of the element region (a 0.1 m square on
   the upper layer under the footing) before and after the footing load is handed over
   (``femcoupling.coupling.handover.fem_to_dem``: tension positive -> compression positive; the
   shear components and the principal-axis rotation are reported, not imposed).
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

The FEM soil (``--soil``): by default calibrated on the case's own element, by passes (the
element driven along its region's path; the soil its secant E and nu, until the element
strains within 2 x its FEM region; no cohesion, the footing then a rigid smooth one pushed to
its pressure; ``geogrid_dem.studies.prs_element.calibrate_soil``). ``--soil given`` keeps the
fill of the paper's set-up (``soil_*``); ``--soil E,NU,PHI,C`` gives one.

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
compression positive; FEM stresses tension positive. Interrupted (Ctrl-C, SIGTERM), a run
leaves ``summary.json`` marked ``interrupted`` with the soil calibration and the variants
that finished (``finished``).

A coupled run (``--two-way``, ``--hierarchical``) ends each variant in a status
(``femcoupling.coupling.status``): ``converged``, ``stopped_at_scatter``, ``stalled`` or ``failed``,
with its checks (summary ``two_way.<RE|PRS>`` or ``hierarchical.<RE|PRS>``: ``status``,
``reason``, ``final_change``, ``tol``, ``axes_rotation_deg``, ``dem_fem_strain_ratio``;
``coupling`` the worst of them). Exit status: 0 when the run completed and the coupling asked
for (if any) converged; 3 ``stopped_at_scatter``, 4 ``stalled``, 5 ``failed`` (the worst
variant's; the results are written all the same, and one line on stderr says it); 1 an
error, 2 bad arguments, 130 / 143 interrupted.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from geogrid_dem.cases import PRESTRESS_PAPER, describe
from geogrid_dem.options import (case_parser, check_cap, check_common_args, given_options,
                                 refuse_unused, warn_below)
from geogrid_dem.rundir import begin_run, end_run, on_interrupt, run_main
from geogrid_dem.studies.prs_element import (HISTORY_REGIONS, VARIANTS, Params, calibrate_soil, log,
                                             run_element, run_variant)


# The smoke's FEM mesh: fine size 0.1 m (753 cells). At 0.05 m (2 001 cells) the LU
# factorisations of the calibrated soil's Newton steps (13-25 iterations a load step) took 75 %
# of this smoke's CPU; docs/speed_accuracy.md gives each mesh's error.
SMOKE = dict(n=300, hold_steps=600, fem_steps=3, mesh_size=1.0, fine_size=0.1,
             layer_thickness=0.02, max_steps=80_000, unbalanced=0.05)


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


def status_checks(t: dict) -> str:
    """The report's words on a coupled variant's checks (its summary record ``t``): the final
    change against its tolerance, the principal axes, the DEM/FEM strain ratio."""
    def g(x, fmt: str) -> str:
        return "unknown" if x is None else format(x, fmt)

    axes = t.get("checks", {}).get("axes")
    limit = (" (not checked: the element takes the full tensor)" if axes is None else
             " (the walls' limit 15 deg: " + ("held" if axes else "NOT held") + ")")
    return (f"final change {g(t['final_change'], '.3g')} (tol {g(t['tol'], '.3g')}), principal "
            f"axes {g(t['axes_rotation_deg'], '.1f')} deg{limit}, DEM/FEM strain ratio "
            f"{g(t['dem_fem_strain_ratio'], '.3g')} (within [0.5, 2]: "
            + ("held" if t.get("checks", {}).get("strain_ratio") else "NOT held") + ")")


def coupling_summary(summary: dict) -> dict | None:
    """The summary's ``coupling`` record of a coupled run (two-way or hierarchical): the mode,
    each variant's status, the worst of them and its exit status (femcoupling.coupling.status); None
    for a run without coupling."""
    from femcoupling.coupling.status import exit_code, worst

    for mode, key in (("two-way", "two_way"), ("hierarchical", "hierarchical")):
        if key in summary:
            variants = {v: t["status"] for v, t in summary[key].items()}
            status = worst(variants.values())
            return {"mode": mode, "status": status, "exit_code": exit_code(status),
                    "variants": variants}
    return None


def write_report(out: Path, summary: dict) -> None:
    lines = ["# The PRS element, driven by FEM stresses: report", "",
             f'Source: the prestressed-element paper, "{PRESTRESS_PAPER}" (docs/studies.md).', ""]
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
    if "coupling" in summary:
        c = summary["coupling"]
        lines += ["## Coupling status", "",
                  f"- {c['mode']}: **{c['status']}** (exit status {c['exit_code']}): "
                  + ", ".join(f"{v} {st}" for v, st in c["variants"].items()), ""]
    if "two_way" in summary:
        lines += ["## Two-way", ""]
        for v, t in summary["two_way"].items():
            how = ("its network tangent" if t.get("element") == "periodic"
                   else "its tangent by stress probes")
            kind = (f"{how} made to reproduce the increment (isotropic part E, nu)"
                    if t.get("stiffness_mandel_pa") else "isotropic secant (E, nu)")
            por = ""
            if t.get("porosity_loop_element") is not None:
                por = (f" (porosity {t['porosity_loop_element']:.4f}; the case's element's "
                       f"{summary['elements'][v]['porosity_final']:.4f})")
            lines.append(f"- {v}: **{t['status']}** in {t['iterations']} FEM solves with the "
                         f"{t.get('element', 'walls')} element{por}: {status_checks(t)}; "
                         f"{t['reason']}; changes {t['changes']}; {kind} {t['materials']}")
        lines.append("")
    if "hierarchical" in summary:
        lines += ["## Hierarchical", ""]
        for v, h in summary["hierarchical"].items():
            if "cells" in h:
                ez = [e[2] for e in h["cell_strain_increments"]]
                sz = [s[2] for s in h["cell_stresses_final_pa"]]
                lines.append(f"- {v}: an element of {h['cell_grains']} grains per cell of the "
                             f"region ({h['cells']} cells) inside the FEM's Newton: "
                             f"**{h['status']}** ({status_checks(h)}; {h['reason']}); "
                             f"iterations per load step {h['newton_iterations']}, "
                             f"{h['element_runs']} evaluations ({h['dem_s']:.1f} s of DEM, "
                             f"preparation {h['preparation_s']:.1f} s); the cells' strain "
                             f"increment z {min(ez):.3g} to {max(ez):.3g}, stress z "
                             f"{min(sz) / 1e3:.1f} to {max(sz) / 1e3:.1f} kPa")
                continue
            lines.append(f"- {v}: the region's material a periodic DEM element inside the "
                         f"FEM's Newton: **{h['status']}** ({status_checks(h)}; "
                         f"{h['reason']}); iterations per load step {h['newton_iterations']}, "
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


def run_variants(p: Params, out: Path, fems: dict | None = None,
                 done: dict | None = None) -> list:
    """RE and PRS (``run_variant``), in two processes with ``p.workers`` >= 2 (spawned: no fork
    of an MPI/PETSc process; each is the serial run's, so the results are the same). ``fems``:
    a variant's FEM already solved with ``p``'s soil (the calibration's last pass), taken by
    the serial path; the processes solve their own. ``done``: variant -> its parts, filled as
    each finishes (an interrupted run reports them)."""
    fems = fems or {}
    done = {} if done is None else done
    if p.workers < 2 or p.cell_elements:  # (cell elements: the workers are Dask's)
        for v in VARIANTS:
            done[v] = run_variant(p, out, v, fem=fems.get(v))
        return [done[v] for v in VARIANTS]
    from geogrid_dem.processes import process_pool, results_in_order

    log(f"--workers {p.workers}: RE and PRS run in two processes")
    with process_pool(2) as ex:
        for v, r in zip(VARIANTS, results_in_order(ex, run_variant, [p] * len(VARIANTS),
                                                   [out] * len(VARIANTS), VARIANTS)):
            done[v] = r
    return [done[v] for v in VARIANTS]


def interrupted_report(out: Path, summary: dict, done: dict) -> None:
    """What an interrupted run reports (rundir.on_interrupt): its summary so far, the soil
    calibration if it finished and the variants (FEM, coupling, element) that finished, named
    in ``finished``. Their figures (fem_<variant>.png, the elements') are drawn as each part
    finishes: none is left to draw."""
    def partial() -> dict:
        s = {**summary, "finished": ["soil calibration"] if "calibration" in summary else []}
        if done:
            s["fem"] = {v: r["fem"] for v, r in done.items()}
            s["elements"] = {v: r["element"] for v, r in done.items()}
            for key in ("two_way", "hierarchical"):
                if any(r.get(key) is not None for r in done.values()):
                    s[key] = {v: r[key] for v, r in done.items()}
            s["finished"] += [f"variant {v}" for v in done]
        return s

    on_interrupt(out, summary=partial)


def run(p: Params, out: Path) -> dict:
    t_start = time.perf_counter()
    begin_run(out, "prs_element", log=log)
    summary: dict = {"params": {k: v for k, v in asdict(p).items()}, "elements": {}}
    done: dict = {}  # variant -> its parts, as each finishes
    interrupted_report(out, summary, done)
    if p.stresses:
        summary["mode"] = "DEM-only (stresses given)"
        log(f"DEM-only: {len(p.stresses)} target row(s), no FEM")
        summary["elements"]["PRS" if p.prs else "RE"] = run_element(
            p, p.stresses, prestressed=p.prs, label="element", out=out)
    else:
        from femcoupling.coupling.twoway import HandoverHistory

        summary["mode"] = "FEM -> DEM" + (" (two-way)" if p.two_way else " (hierarchical)"
                                          if p.hierarchical else " (one-way)")
        if p.two_way and p.two_way_element == "periodic":
            log("two-way element: periodic, soil only (the full FEM tensor, its tangent back "
                "as the region's stiffness); the geogrid stays in the FEM's layer band, "
                "counted once; the case's element, geogrid included, is then driven to the "
                "converged targets")
        fems: dict = {}  # (the calibration's last RE FEM, solved with the soil it returns)
        if p.soil == "calibrated":
            p, summary["calibration"] = calibrate_soil(p, out, keep=fems)
        summary["soil"] = {"source": p.soil, "young_pa": p.soil_young,
                           "poisson": p.soil_poisson, "cohesion_pa": p.soil_cohesion,
                           "friction_deg": p.soil_friction,
                           "footing": ("rigid smooth, pushed to the pressure (a cohesionless "
                                       "soil)" if p.soil_cohesion == 0 else "a pressure")}
        log(f"FEM soil ({p.soil}): E {p.soil_young / 1e6:.4g} MPa, nu {p.soil_poisson:.3f}, "
            f"c {p.soil_cohesion / 1e3:g} kPa, phi {p.soil_friction:g} deg")
        parts = run_variants(p, out, fems, done)
        fems.clear()
        summary["fem"] = {v: r["fem"] for v, r in zip(VARIANTS, parts)}
        summary["elements"] = {v: r["element"] for v, r in zip(VARIANTS, parts)}
        if p.two_way:
            summary["two_way"] = {v: r["two_way"] for v, r in zip(VARIANTS, parts)}
        if p.hierarchical:
            summary["hierarchical"] = {v: r["hierarchical"] for v, r in zip(VARIANTS, parts)}
        coupling = coupling_summary(summary)
        if coupling is not None:
            summary["coupling"] = coupling
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
    if "coupling" in summary:
        c = summary["coupling"]
        log(f"{c['mode']} coupling: {c['status']} ("
            + ", ".join(f"{v} {st}" for v, st in c["variants"].items()) + ")")
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
    ap.add_argument("--density-scaling", type=float, default=None,
                    help="density scaling of the element's growth and servo stages: the "
                         f"target time step over the unscaled one (>= 1; 0: off; default "
                         f"{d.density_scaling:g}, or the --preset's where the case has one; "
                         "docs/quasi_static.md)")
    return ap


def apply_element_args(ap, a, p, given=frozenset()):
    """Checks the shared options (element_parser) and sets them on ``p``; returns it.
    ``given``: the options given (geogrid_dem.options.given_options), for the refusal of one
    that has no effect (--footing-pressure with --stresses)."""
    check_common_args(ap, a)
    if a.n is not None:
        if a.n < 50:
            ap.error(f"--n={a.n}: must be >= 50")
        check_cap(ap, a, "--n", a.n, a.n, "grains")
        p.n = a.n
    if a.stresses:
        refuse_unused(ap, a, given, "footing_pressure",
                      "with --stresses (no FEM: the stresses are given)")
    if not (math.isfinite(a.prestress) and a.prestress >= 0):
        ap.error(f"--prestress={a.prestress}: must be >= 0 (N/m)")
    if not (math.isfinite(a.footing_pressure) and a.footing_pressure > 0):
        ap.error(f"--footing-pressure={a.footing_pressure}: must be > 0 (Pa)")
    if not a.stresses:
        warn_below("--footing-pressure", a.footing_pressure, 1e3, "Pa",
                   f"kPa given as Pa? {a.footing_pressure:g} kPa is --footing-pressure "
                   f"{a.footing_pressure * 1e3:g}")
    if a.density_scaling is not None and not (
            math.isfinite(a.density_scaling) and (a.density_scaling == 0 or a.density_scaling >= 1)):
        ap.error(f"--density-scaling={a.density_scaling}: must be 0 (off) or >= 1 (the target "
                 "time step over the unscaled one)")
    p.prestress, p.footing_pressure, p.seed, p.threads = (a.prestress, a.footing_pressure,
                                                           a.seed, a.threads)
    if a.density_scaling is not None:
        p.density_scaling = a.density_scaling
    return p


def add_soil_arg(ap, d: Params) -> None:
    """``--soil``: the FEM soil, calibrated on the case's element, given, or four numbers."""
    ap.add_argument("--soil", type=str, default=None,
                    help="the FEM soil (Drucker-Prager matched to Mohr-Coulomb): 'calibrated' "
                         "(the default: E and nu the case's own element's secant along the "
                         "element region's stress path, no cohesion, phi as given), 'given' "
                         f"(E {d.soil_young:g} Pa, nu {d.soil_poisson:g}, phi "
                         f"{d.soil_friction:g} deg, c {d.soil_cohesion:g} Pa), or "
                         "E,NU,PHI,C (Pa, -, deg, Pa)")


def apply_soil_arg(ap, a, p: Params) -> None:
    """Sets ``p.soil`` (and with four numbers the soil's E, nu, phi, c) from ``--soil``;
    refused with --stresses (no FEM) and with bad numbers, naming the field."""
    if a.soil is not None and a.stresses:
        ap.error(f"--soil={a.soil}: the FEM soil; not with --stresses (no FEM)")
    soil = a.soil or "calibrated"
    if soil in ("calibrated", "given"):
        p.soil = soil
        return
    try:
        E, nu, phi, c = (float(x) for x in soil.split(","))
    except ValueError:
        ap.error(f"--soil={soil!r}: 'calibrated', 'given' or four numbers E,NU,PHI,C "
                 "(Pa, -, deg, Pa)")
    for name, v, ok, allowed in (("E", E, E > 0, "> 0 Pa"),
                                 ("NU", nu, 0 <= nu < 0.5, "in [0, 0.5)"),
                                 ("PHI", phi, 0 < phi < 90, "in (0, 90) deg"),
                                 ("C", c, c >= 0, ">= 0 Pa")):
        if not (math.isfinite(v) and ok):
            ap.error(f"--soil={soil!r}: {name}={v:g} must be {allowed}")
    p.soil = "given"
    p.soil_young, p.soil_poisson, p.soil_friction, p.soil_cohesion = E, nu, phi, c


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
    add_soil_arg(ap, d)
    ap.add_argument("--calibrate", action="store_true", help=argparse.SUPPRESS)
    return ap


def parse_args(argv=None) -> tuple[Params, Path]:
    ap = build_parser()
    a = ap.parse_args(argv)
    given = given_options(ap, argv)
    p = apply_element_args(ap, a, Params(**SMOKE) if a.smoke else Params(), given)
    if not (math.isfinite(a.tol) and 0 < a.tol < 1):
        ap.error(f"--tol={a.tol}: must be in (0, 1): the relative change of the handed-over "
                 "stresses that ends the two-way loop (1 or more would accept any change)")
    if a.max_iterations < 2:
        ap.error(f"--max-iterations={a.max_iterations}: must be >= 2")
    if a.workers < 1:
        ap.error(f"--workers={a.workers}: must be >= 1")
    p.two_way, p.two_way_tol, p.max_iterations, p.workers = (a.two_way, a.tol, a.max_iterations,
                                                             a.workers)
    if a.calibrate and (a.soil or "calibrated") != "calibrated" and not a.stresses:
        ap.error(f"--calibrate (kept for older run files: it means --soil calibrated) with "
                 f"--soil={a.soil!r}: give one of them")
    apply_soil_arg(ap, a, p)
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
    check_cap(ap, a, "--cell-grains", a.cell_grains, a.cell_grains, "grains",
              "grains an element")
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
        refuse_unused(ap, a, given, "tol",
                      f"with --preset {a.preset} (the preset sets the two-way tolerance)")
        p = apply_coupling_preset(p, a.preset)
    if a.stresses:
        if a.two_way or a.hierarchical:
            ap.error("--two-way and --hierarchical need the FEM: not with --stresses")
        p.stresses = parse_stresses(a.stresses, ap)
        p.prs = a.prs
    elif a.prs:
        ap.error("--prs is for DEM-only runs (--stresses); the FEM mode runs RE and PRS")
    # options that would have no effect given the others (docs/cli.md)
    if a.stresses:
        if not a.prs:
            refuse_unused(ap, a, given, "prestress", "with --stresses and no --prs (the "
                          "element is RE)", "add --prs")
        refuse_unused(ap, a, given, "workers", "with --stresses (one element runs)")
    if not a.two_way:
        for dest in ("tol", "max_iterations", "tangent_probe"):
            refuse_unused(ap, a, given, dest, "without --two-way (the two-way loop's)",
                          "add --two-way")
    elif a.two_way_element != "walls":
        refuse_unused(ap, a, given, "tangent_probe", "with --two-way-element "
                      f"{a.two_way_element} (the walls element's tangent)")
    return p, a.out


def coupling_exit(summary: dict | None, status: int, out) -> int:
    """The exit status of a completed run (``status`` 0 from run_main) whose coupling did not
    converge: its code (femcoupling.coupling.status.EXIT_CODES), said in one line on stderr; any
    other status unchanged."""
    c = None if summary is None else summary.get("coupling")
    if status != 0 or c is None or c["status"] == "converged":
        return status
    print(f"[prs_element] the {c['mode']} coupling did not converge: "
          + ", ".join(f"{v} {st}" for v, st in c["variants"].items())
          + f" (exit status {c['exit_code']}; the results are in {out}, the checks in "
          "report.md)", file=sys.stderr, flush=True)
    return c["exit_code"]


def main(argv=None) -> int:
    p, out = parse_args(argv)
    done: dict = {}

    def work(o):
        done["out"] = o
        done["summary"] = run(p, o)

    status = run_main("prs_element", out, work)
    return coupling_exit(done.get("summary"), status, done.get("out", out))


if __name__ == "__main__":
    sys.exit(main())
