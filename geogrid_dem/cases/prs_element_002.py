#!/usr/bin/env python3
"""002's prestressed reinforced-soil element, rebuilt with 002's own parts.

The element:
- a 0.1 m cube of clumps (the shipped gravel templates, cpp_dem.build.clumps) with 002 Table 1's
  Hertz–Mindlin material: G = 30 GPa, nu = 0.2, mu = 0.8, 2640 kg/m^3;
- at mid-height, the woven geogrid of bonded spheres (cpp_dem.build.woven), in 002 Table 2's
  "detailed" and "standard" forms, with 002's linear grid–grain contact (k_n = 3.9e6 N/m,
  k_s = 9e5 N/m, mu = 0.5);
- six servo walls driven to the stresses of a FEM analysis. The FEM is the
  prs_element case's plane-strain fill under a footing, with the grid form's tensile
  stiffness; or the stresses are given with --stresses (DEM only, no dolfinx).

The variants:
- RE: the grid lies free in the soil;
- PRS: its longitudinal members are tensioned to T_p (--prestress, N/m) after the sample is
  grown, and locked in with the ends held (cpp_dem.protocols.prestress). The locked-in force is
  recorded as the run goes.

Outputs in --out, per element `<grid>_<RE|PRS>`:
- `.h5` / `.csv`: wall stresses, targets, box, grid forces, locked-in prestress;
- `vtk/`: spheres, contact force network, the grid's bonds with their tensions, the box;
- `_views.png/.pdf`: contact forces and bond tensions in plan, side and front view, as 002
  Figs 3–4.

And for the whole run:
- `summary.json`;
- `report.md`, which compares RE against PRS on 002's three effects (interlocking,
  single-string interaction, alignment), on the tensile force along the longitudinal
  members, and on the displacement above against below the grid, and checks 002's findings.

SI units. DEM stresses compression positive.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
import json
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from geogrid_dem.cases import prs_element as _fem_case
from cpp_dem.elements.box import run_element
from femcoupling.drivers.prs_element import run_fem
from geogrid_dem.cases import PRESTRESS_PAPER
from geogrid_dem.rundir import begin_run, end_run, run_main

GRIDS = ("detailed", "standard")
VARIANTS = ("RE", "PRS")


@dataclass
class Params(_fem_case.Params):
    """The 002 element: prs_element's parameters with 002's grains, law and woven grid."""

    n: int = 2000                        #: clumps, before the grid's layer is cleared, -
    grains: str = "clumps:gravel"
    grain_law: str = "hertz"
    geogrid: str = "woven-detailed"
    growth_max_strain: float = 3e-6      #: -, per step (x 10 until the grains touch)
    servo_integral: bool = True          #: the creeping clump packing needs it (servo_stage)
    prep_friction_deg: float = 20.0      #: deg, during growth
    grids: tuple = GRIDS                 #: woven forms to run
    variants: tuple = VARIANTS           #: RE and/or PRS


SMOKE = dict(_fem_case.SMOKE, n=150, hold_steps=400, max_steps=150_000, unbalanced=0.1)


def log(msg: str) -> None:
    print(f"[prs_element_002] {msg}", flush=True)


# ---- comparison with 002's findings ------------------------------------------------------------


def findings(elements: dict) -> list[dict]:
    """002's findings, RE against PRS for each grid form: what 002 reports, the numbers here,
    and whether they agree."""
    out = []
    for grid in GRIDS:
        re_, prs = elements.get(f"{grid}_RE"), elements.get(f"{grid}_PRS")
        if prs is not None:
            d = prs["interaction"]["displacement"]
            out.append({
                "grid": grid, "finding": "larger displacements above the grid than below (PRS)",
                "here": f"{1e3 * d['above_mean_m']:.3f} mm above, {1e3 * d['below_mean_m']:.3f} "
                        "mm below", "agrees": bool(d["above_mean_m"] > d["below_mean_m"])})
        if re_ is None or prs is None:
            continue
        cr, cp = re_["grid_force_longitudinal_cov_along"], prs["grid_force_longitudinal_cov_along"]
        out.append({"grid": grid,
                    "finding": "tensile force more uniform along prestressed longitudinal members",
                    "here": f"CoV along the members {cr:.3f} (RE) against {cp:.3f} (PRS)",
                    "agrees": bool(cp < cr)})
        ar = re_["interaction"]["contacts"]["longitudinal_per_m"]
        ap = prs["interaction"]["contacts"]["longitudinal_per_m"]
        wr = re_["interaction"]["waviness"]["out_of_plane_longitudinal_mean_m"]
        wp = prs["interaction"]["waviness"]["out_of_plane_longitudinal_mean_m"]
        out.append({"grid": grid, "finding": "less alignment of the longitudinal members with "
                    "prestress (fewer grain contacts, less out-of-plane deflection)",
                    "here": f"contacts {ar:.1f} against {ap:.1f} per m; out-of-plane "
                            f"{1e6 * wr:.1f} against {1e6 * wp:.1f} um (RE against PRS)",
                    "agrees": bool(ap <= ar and wp <= wr)})
    return out


def write_report(out: Path, summary: dict) -> None:
    el = summary["elements"]
    lines = ["# The prestressed reinforced-soil element (clumps, woven grid): report", "",
             f'Source: "{PRESTRESS_PAPER}".', "",
             f"Mode: {summary['mode']}. Stresses in kPa, compression positive.", ""]
    rows = [("grains", lambda e: f"{e['num_grains']}"),
            ("walls reached (kPa)", lambda e: str(np.round(np.array(e["stress_final_pa"]) / 1e3,
                                                            2).tolist())),
            ("held within (%)", lambda e: f"{100 * e['hold_max_rel_error']:.2f}"),
            ("longitudinal member force, mean (N)",
             lambda e: f"{e['grid_force_longitudinal_mean_n']:.2f}"),
            ("CoV along the longitudinal members",
             lambda e: f"{e['grid_force_longitudinal_cov_along']:.3f}"),
            ("grains in apertures (interlocking)",
             lambda e: f"{e['interaction']['apertures']['grains_in_apertures']}"),
            ("sideways waviness, longitudinal (um)",
             lambda e: f"{1e6 * e['interaction']['waviness']['sideways_longitudinal_mean_m']:.1f}"),
            ("grains touching two strings (single-string)",
             lambda e: f"{e['interaction']['between_strings']['grains_touching_two_strings']}"),
            ("grain spheres between strings",
             lambda e: f"{e['interaction']['between_strings']['grain_spheres_between_strings']}"),
            ("grain contacts per m, longitudinal (alignment)",
             lambda e: f"{e['interaction']['contacts']['longitudinal_per_m']:.1f}"),
            ("out-of-plane waviness, longitudinal (um)",
             lambda e: f"{1e6 * e['interaction']['waviness']['out_of_plane_longitudinal_mean_m']:.1f}"),
            ("mean |u| above / below the grid (mm)",
             lambda e: f"{1e3 * e['interaction']['displacement']['above_mean_m']:.3f} / "
                       f"{1e3 * e['interaction']['displacement']['below_mean_m']:.3f}"),
            ("locked-in prestress at the end (N per member)",
             lambda e: (str(np.round(e["prestress_locked_final_n"], 1).tolist())
                        if "prestress_locked_final_n" in e else "-")),
            ("porosity at the end", lambda e: f"{e['porosity_final']:.3f}"),
            ("time step (s)", lambda e: f"{e['density_scaling']['dt_s']:.3g}"),
            ("density scaling: largest factor, bodies scaled",
             lambda e: (f"{e['density_scaling']['max_factor']:.3g}, "
                        f"{100 * e['density_scaling']['scaled_share']:.0f} %"
                        if e["density_scaling"]["target_dt_s"] else "off")),
            ("wall time: preparation, stages (s)",
             lambda e: f"{e['preparation_wall_time_s']:.0f}, "
                       + ", ".join(f"{t:.0f}" for t in e["stage_wall_time_s"])),
            ("wall time (s)", lambda e: f"{e['wall_time_s']:.0f}")]
    names = list(el)
    lines += ["| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for label, f in rows:
        lines.append(f"| {label} | " + " | ".join(f(el[n]) for n in names) + " |")
    lines += ["", "## The paper's findings", ""]
    for f in summary["findings"]:
        lines.append(f"- {f['grid']}: {f['finding']}: {f['here']}: "
                     f"{'agrees' if f['agrees'] else 'does NOT agree'}.")
    lines += ["", "Figures: `<element>_views.png` (plan, side, front); VTK in `vtk/`.", ""]
    (out / "report.md").write_text("\n".join(lines) + "\n")


# ---- the run -----------------------------------------------------------------------------------


def run(p: Params, out: Path) -> dict:
    t_start = time.perf_counter()
    begin_run(out, "prs_element_002", log=log)
    summary: dict = {"params": {k: (list(v) if isinstance(v, tuple) else v)
                                for k, v in asdict(p).items()}, "elements": {}}
    jobs = [(g, v) for g in p.grids for v in p.variants]
    targets: dict = {}
    with contextlib.ExitStack() as stack:
        hist = None
        if p.stresses:
            summary["mode"] = "DEM-only (stresses given)"
            for job in jobs:
                targets[job] = [np.asarray(r, float) for r in p.stresses]
        else:
            from femcoupling.twoway import HandoverHistory

            summary["mode"] = "FEM -> DEM (one-way)"
            summary["fem"] = {}
            hist = stack.enter_context(HandoverHistory(
                out / "handover.h5", regions=[f"{g}_{v}" for g, v in jobs],
                metadata={"case": "prs_element_002"}))
            handed = {}
            for g, v in jobs:
                # The FEM layer has the grid form's tensile stiffness (and T_p for PRS).
                fem_out = out / f"fem_{g}"
                fem_out.mkdir(parents=True, exist_ok=True)
                ini, fin, _m, _s0, _load, info = run_fem(
                    replace(p, geogrid=f"woven-{g}"), fem_out, v)
                info.update(targets_initial_pa=ini.normal_pa.tolist(),
                            targets_final_pa=fin.normal_pa.tolist(),
                            shear_pa=fin.shear_pa.tolist(), rotation_deg=fin.rotation_deg)
                summary["fem"][f"{g}_{v}"] = info
                targets[(g, v)] = [ini.normal_pa, fin.normal_pa]
                handed[(g, v)] = fin
        t_dem = time.perf_counter()
        args = [(replace(p, geogrid=f"woven-{g}"), targets[(g, v)], v == "PRS", f"{g}_{v}",
                 out) for g, v in jobs]
        if p.workers > 1 and len(jobs) > 1:
            # Elements side by side in spawned processes (one thread each): each element's
            # arithmetic is the serial run's, so the results are the same.
            n_proc = min(p.workers, len(jobs))
            log(f"--workers {p.workers}: {len(jobs)} elements, {n_proc} at a time")
            ex = stack.enter_context(concurrent.futures.ProcessPoolExecutor(
                max_workers=n_proc, mp_context=multiprocessing.get_context("spawn")))
            results = ex.map(_element_job, *zip(*args))
        else:
            results = (_element_job(*a) for a in args)
        for k, ((g, v), e) in enumerate(zip(jobs, results)):
            left = (time.perf_counter() - t_dem) / (k + 1) * (len(jobs) - k - 1)
            log(f"element {k + 1}/{len(jobs)} ({g} {v}) done"
                + (f"; about {left:.0f} s left" if k + 1 < len(jobs) else ""))
            summary["elements"][f"{g}_{v}"] = e
            if hist is not None:
                fin = handed[(g, v)]
                hist.append(iteration=0, region=k, fem_stress_pa=fin.fem_stress_pa,
                            targets_pa=fin.normal_pa, shear_pa=fin.shear_pa,
                            rotation_deg=fin.rotation_deg, change=0.0,
                            dem_stress_pa=e["stress_final_pa"])
            # Written as the run goes: a stopped run keeps the elements it finished.
            (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float)
                                              + "\n")
    summary["findings"] = findings(summary["elements"])
    summary["wall_time_total_s"] = time.perf_counter() - t_start
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    write_report(out, summary)
    end_run(out)
    for f in summary["findings"]:
        log(f"{f['grid']}: {f['finding']}: {f['here']} "
            f"({'agrees' if f['agrees'] else 'does NOT agree'} with the paper)")
    log(f"done in {summary['wall_time_total_s']:.1f} s; report in {out / 'report.md'}")
    return summary


def _element_job(p: Params, targets, prestressed: bool, label: str, out: Path) -> dict:
    """One element of the run (picklable: ``--workers`` runs them in other processes)."""
    return run_element(p, targets, prestressed=prestressed, label=label, out=out, log=log)


def _names(text: str, allowed: tuple, flag: str, ap) -> tuple:
    names = tuple(t.strip() for t in text.split(",") if t.strip())
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        ap.error(f"{flag}={text!r}: must be a comma-separated list of {', '.join(allowed)}")
    return names


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    d = Params()
    ap = _fem_case.element_parser(
        "prs-element-002", "The prestressed reinforced-soil element rebuilt from the paper's "
        "parts: clumps with Hertz-Mindlin (its Table 1), the woven geogrid of bonded spheres "
        "(its Table 2, detailed and standard), servo walls to FEM stresses or to --stresses; "
        "RE against PRS with the paper's interaction measures.", d,
        smoke=f"{SMOKE['n']} clumps, coarse FEM mesh",
        preset="of the element: density scaling of its growth and servo stages "
               "(--density-scaling overrides it)")
    ap.add_argument("--grids", default=",".join(GRIDS), help="woven forms to run")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="RE and/or PRS")
    ap.add_argument("--workers", type=int, default=1,
                    help="processes: 2 or more run the elements side by side (one thread "
                         "each), with the same results")
    ap.add_argument("--grains", default=d.grains,
                    help="clumps:NAME (a shipped grain, 'gravel', or a template CSV) or spheres")
    return ap


def parse_args(argv=None) -> tuple[Params, Path]:
    ap = build_parser()
    a = ap.parse_args(argv)
    p = _fem_case.apply_element_args(ap, a, Params(**SMOKE) if a.smoke else Params())
    p.grids = _names(a.grids, GRIDS, "--grids", ap)
    p.variants = _names(a.variants, VARIANTS, "--variants", ap)
    p.grains = a.grains
    if a.preset and a.density_scaling is None:
        from cpp_dem.presets import preset

        p.density_scaling = preset(a.preset).density_scaling
    if a.workers < 1:
        ap.error(f"--workers={a.workers}: must be >= 1")
    p.workers = a.workers
    from cpp_dem import ParameterError
    from cpp_dem.elements.box import check_element_params

    try:
        check_element_params(p)
    except ParameterError as e:
        ap.error(str(e))
    if a.stresses:
        p.stresses = _fem_case.parse_stresses(a.stresses, ap)
    return p, a.out


def main(argv=None) -> int:
    p, out = parse_args(argv)
    return run_main("prs_element_002", out, lambda o: run(p, o))


if __name__ == "__main__":
    sys.exit(main())
