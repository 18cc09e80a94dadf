#!/usr/bin/env python3
"""002's prestressed reinforced-soil element, rebuilt with 002's own parts, RE against PRS on
paired seeds (docs/prs_element_002.md; its table "How 002 is read" states every reading).

The element:
- a 0.1 m cube of clumps (the shipped gravel templates, cpp_dem.build.clumps) with 002 Table 1's
  Hertz–Mindlin material: G = 30 GPa, nu = 0.2, mu = 0.8, 2640 kg/m^3;
- at mid-height, the woven geogrid of bonded spheres (cpp_dem.build.woven), in 002 Table 2's
  "detailed" and "standard" forms, its k_n, k_s read as PFC 4 ball properties in series
  (--convention);
- servo walls driven to the stresses of a FEM analysis (the prs_element case's plane-strain
  fill under a footing, with the grid form's tensile stiffness), or to --stresses (DEM only,
  no dolfinx); --fixed-walls holds some walls (002 Fig. 1).

Per grid form and seed (--seeds), one grown packing; from it:
- RE: the grid's longitudinal ends free;
- PRS: the same ends pulled by T_p (--prestress, N/m) throughout (--grid-ends grips: tensioned,
  then locked; RE then held by the same grips).

Outputs in --out, per element `<grid>_<RE|PRS>_s<seed>`: `.h5`/`.csv` series, `_measures.csv`
(002's measures over the loading), `_figure.npz`, `vtk/`; per grid and seed the figures
`<grid>_s<seed>_views/_grid/_rose` (.png, .pdf; RE and PRS on shared scales) and the growth
history; for the run `summary.json` ("findings": paired differences PRS - RE with verdicts)
and `report.md`. `jobs/` holds each finished packing's summary (--resume keeps them).

SI units. DEM stresses compression positive.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
import json
import math
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from geogrid_dem.cases import prs_element as _fem_case
from cpp_dem.elements.box import run_element
from geogrid_dem.cases import PRESTRESS_PAPER
from geogrid_dem.rundir import begin_run, end_run, run_main

GRIDS = ("detailed", "standard")
VARIANTS = ("RE", "PRS")


@dataclass
class Params(_fem_case.Params):
    """The 002 element: prs_element's parameters with 002's grains, law, woven grid,
    boundaries, gravity and damping stages (docs/prs_element_002.md, "How 002 is read")."""

    n: int = 2000                        #: clumps, before the grid's layer is cleared, -
    grains: str = "clumps:gravel"
    grain_law: str = "hertz"
    geogrid: str = "woven-detailed"
    growth_max_strain: float = 3e-6      #: -, per step (x 10 until the grains touch)
    servo_integral: bool = True          #: the creeping clump packing needs it (servo_stage)
    prep_friction_deg: float = 20.0      #: deg, during growth
    # 002's gravity and damping (Table 1: filling with viscous 0.97 and no local damping,
    # loading with local 0.9); the grid free while the grains grow to the stress. 002's fixed
    # walls (Fig. 1d) are an option (--fixed-walls x-,y-,z-): at smoke size their stage took
    # 73 600 steps against 1000 with all six walls servo (docs/prs_element_002.md).
    gravity: float = 9.81                #: m/s^2
    fill_viscous: float = 0.97           #: -, ratio of critical
    fill_local_damping: float = 0.0      #: -
    damping: float = 0.9                 #: local damping while loading, -
    grid_held: str = "fast"
    # The servo stages' rest criterion: a clump packing's unbalanced-force ratio levels off at
    # 0.02-0.05 at the FEM's 2-5 kPa (600 clumps, 002's damping: 0.024-0.045 after 140 000
    # steps, the walls on target within 0.2 %, inertial number 4e-4-1e-3), so 0.02 would run
    # every stage to its max_steps.
    unbalanced: float = 0.05             #: -
    # ... and where it stays above that, the stage ends NOT converged after 250 records
    # (50 000 steps) without a 5 % improvement, instead of at max_steps. (Full size, standard
    # PRS at 3.8/2.7/5.4 kPa: 0.073-0.083 from 200 000 to 310 000 steps, then 0.054 at
    # 337 000: a shorter window would have called a slow descent a floor.)
    plateau_records: int = 250           #: -
    grid_ends: str = "tension"           #: PRS pulled by T_p, RE free: the same end conditions
    grid_convention: str = "series"      #: 002's k_n, k_s as PFC 4 ball properties
    grids: tuple = GRIDS                 #: woven forms to run
    variants: tuple = VARIANTS           #: RE and/or PRS
    seeds: tuple = (1, 2)                #: packings; RE and PRS share each seed's


SMOKE = dict(_fem_case.SMOKE, n=150, hold_steps=400, max_steps=150_000, unbalanced=0.1,
             grids=("detailed",))


def log(msg: str) -> None:
    print(f"[prs_element_002] {msg}", flush=True)


# ---- 002's findings, RE against PRS over paired seeds ------------------------------------------

def _get(e: dict, *path):
    for k in path:
        e = e[k]
    return None if e is None else float(e)


#: 002's findings with a direction (PRS - RE, paired per seed; "PRS": PRS's own value):
#: (name, expected_sign, compare, value of an element summary).
FINDINGS = (
    ("tension varies less along the prestressed longitudinal members (std along, N)", -1,
     "PRS - RE", lambda e: _get(e, "interaction", "tension_variation",
                                "longitudinal_std_along_n")),
    ("the longitudinal members align less with prestress: out-of-plane deflection (m)", -1,
     "PRS - RE", lambda e: _get(e, "interaction", "waviness",
                                "out_of_plane_longitudinal_mean_m")),
    ("the longitudinal members align less with prestress: grain contacts per m", -1,
     "PRS - RE", lambda e: _get(e, "interaction", "contacts", "longitudinal_per_m")),
    ("less vertical strain for the same load with prestress (strain per Pa of the last "
     "stage's vertical load)", -1, "PRS - RE",
     lambda e: _get(e, "vertical_compliance_per_pa")),
    ("displacements above the grid larger than below, PRS (mean |u| above - below, m)", +1,
     "PRS", lambda e: _get(e, "interaction", "displacement", "above_mean_m")
     - _get(e, "interaction", "displacement", "below_mean_m")),
)

#: Measures reported RE against PRS without a direction from 002 (no verdict).
MEASURES = (
    ("transverse members: grain contacts per m (002: they still align under PRS)",
     lambda e: _get(e, "interaction", "contacts", "transverse_per_m")),
    ("transverse members: out-of-plane deflection (m)",
     lambda e: _get(e, "interaction", "waviness", "out_of_plane_transverse_mean_m")),
    ("tension varies along the transverse members (std along, N)",
     lambda e: _get(e, "interaction", "tension_variation", "transverse_std_along_n")),
    ("longitudinal tension across members (std of the member means, N)",
     lambda e: _get(e, "interaction", "tension_variation", "longitudinal_std_across_n")),
    ("grains in apertures (interlocking)",
     lambda e: _get(e, "interaction", "apertures", "grains_in_apertures")),
    ("members' sideways displacement, longitudinal (m)",
     lambda e: _get(e, "interaction", "sideways_displacement", "longitudinal_rms_m")),
    ("grains entered between strings (single-string interaction)",
     lambda e: _get(e, "interaction", "between_strings", "grains_entered")),
    ("clear gap between strings at the end, mean (m)",
     lambda e: _get(e, "interaction", "string_gaps", "longitudinal_now_mean_m")),
    ("porosity at the end", lambda e: _get(e, "porosity_final")),
)


def verdict(diff_mean: float, diff_se: float, n: int, expected_sign: int) -> str:
    """'agrees' when the paired difference has 002's sign and exceeds 2 standard errors,
    'opposes' when it has the other sign beyond 2 standard errors, else 'not resolved' (also
    with fewer than 2 seeds: no standard error)."""
    if n < 2 or not (math.isfinite(diff_mean) and math.isfinite(diff_se)):
        return "not resolved"
    if abs(diff_mean) <= 2.0 * diff_se or diff_mean == 0:
        return "not resolved"
    return "agrees" if np.sign(diff_mean) == expected_sign else "opposes"


def _stats(x: list) -> tuple[float, float]:
    a = np.asarray(x, float)
    return float(a.mean()), (float(a.std(ddof=1)) if len(a) > 1 else float("nan"))


#: The statistics of a finding or measure row (paired's keys but the per-seed values).
STAT_KEYS = ("re_mean", "re_sd", "prs_mean", "prs_sd", "diff_mean", "diff_se", "n")


def paired(elements: dict, grid: str, seeds, value) -> dict | None:
    """RE and PRS values of ``value`` over the seeds with both, and their paired difference
    (PRS - RE): means, sds, the difference's mean and standard error, n; 'unconverged': the
    labels of those elements with a stage that did not converge."""
    re_v, prs_v, unconverged = [], [], []
    for s in seeds:
        re_, prs = elements.get(f"{grid}_RE_s{s}"), elements.get(f"{grid}_PRS_s{s}")
        if re_ is None or prs is None:
            continue
        a, b = value(re_), value(prs)
        if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
            continue
        re_v.append(a)
        prs_v.append(b)
        unconverged += [f"{grid}_{v}_s{s}" for v, e in (("RE", re_), ("PRS", prs))
                        if not all(e.get("converged", [True]))]
    if not re_v:
        return None
    n = len(re_v)
    d = np.asarray(prs_v) - np.asarray(re_v)
    rm, rs = _stats(re_v)
    pm, ps = _stats(prs_v)
    dm, dsd = _stats(d)
    return {"re_mean": rm, "re_sd": rs, "prs_mean": pm, "prs_sd": ps, "diff_mean": dm,
            "diff_se": dsd / math.sqrt(n) if n > 1 else float("nan"), "n": n,
            "re_values": re_v, "prs_values": prs_v, "unconverged": unconverged}


def findings(elements: dict, seeds=(1,), grids=GRIDS) -> list[dict]:
    """002's findings per grid form: RE and PRS means and sds over the seeds, the paired
    difference PRS - RE (mean and standard error; for a finding about PRS alone, PRS's own
    mean and standard error), and the verdict (:func:`verdict`). A verdict rests on elements
    at rest: when a stage of one of them did not converge ('unconverged' names them) it is
    'not resolved', whatever the numbers."""
    out = []
    for grid in grids:
        for name, sign, compare, value in FINDINGS:
            st = paired(elements, grid, seeds, value)
            if st is None:
                continue
            if compare == "PRS":
                n = st["n"]
                st["diff_mean"] = st["prs_mean"]
                st["diff_se"] = st["prs_sd"] / math.sqrt(n) if n > 1 else float("nan")
            v = verdict(st["diff_mean"], st["diff_se"], st["n"], sign)
            out.append({"grid": grid, "name": name, "expected_sign": sign, "compare": compare,
                        **{k: st[k] for k in STAT_KEYS}, "unconverged": st["unconverged"],
                        "verdict": "not resolved" if st["unconverged"] else v})
    return out


def measures_table(elements: dict, seeds=(1,), grids=GRIDS) -> list[dict]:
    """The measures without a direction from 002: RE and PRS over the seeds, paired
    difference; no verdict."""
    out = []
    for grid in grids:
        for name, value in MEASURES:
            st = paired(elements, grid, seeds, value)
            if st is not None:
                out.append({"grid": grid, "name": name,
                            **{k: st[k] for k in STAT_KEYS}})
    return out


def _fmt(x) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.4g}"


def findings_table(rows: list[dict], *, with_verdict: bool = True) -> list[str]:
    """The markdown table of findings (or measures) rows."""
    head = "| grid | finding | RE mean ± sd | PRS mean ± sd | PRS − RE ± se | n |"
    lines = [head + (" 002 | verdict |" if with_verdict else ""),
             "|---|---|---|---|---|---|" + ("---|---|" if with_verdict else "")]
    for f in rows:
        line = (f"| {f['grid']} | {f['name']} | {_fmt(f['re_mean'])} ± {_fmt(f['re_sd'])} | "
                f"{_fmt(f['prs_mean'])} ± {_fmt(f['prs_sd'])} | {_fmt(f['diff_mean'])} ± "
                f"{_fmt(f['diff_se'])} | {f['n']} |")
        if with_verdict:
            line += f" {'+' if f['expected_sign'] > 0 else '−'} | {f['verdict']} |"
        lines.append(line)
    return lines


def write_report(out: Path, summary: dict) -> None:
    el = summary["elements"]
    lines = ["# The prestressed reinforced-soil element (clumps, woven grid): report", "",
             f'Source: "{PRESTRESS_PAPER}".', "",
             f"Mode: {summary['mode']}. Seeds: {summary['seeds']} (RE and PRS on each seed's "
             "grown packing). Stresses in kPa, compression positive.", "",
             "## 002's findings, paired over the seeds", "",
             "The difference is PRS − RE per seed (for a finding about PRS alone, PRS's own "
             "value). `agrees`: 002's sign beyond 2 standard errors; `opposes`: the other sign "
             "beyond 2 standard errors; else `not resolved` (also when an element behind "
             "it did not come to rest in a stage).", ""]
    lines += findings_table(summary["findings"])
    stalled = sorted({k for f in summary["findings"] for k in f.get("unconverged", [])})
    if stalled:
        lines += ["", f"**Not at rest:** {', '.join(stalled)} ended a stage NOT converged "
                  "(the elements' `stall`): the findings that rest on them are `not resolved`."]
    lines += ["", "## Other measures (no direction from 002)", ""]
    lines += findings_table(summary["measures"], with_verdict=False)
    rows = [("grains", lambda e: f"{e['num_grains']}"),
            ("walls reached (kPa)", lambda e: str(np.round(np.array(e["stress_final_pa"]) / 1e3,
                                                            2).tolist())),
            ("converged", lambda e: str(e["converged"])),
            ("held within (%)", lambda e: f"{100 * e['hold_max_rel_error']:.2f}"),
            ("vertical strain per stage; in its hold (creep)",
             lambda e: "; ".join(f"{a[2]:.2e}, {b[2]:.2e}" for a, b in
                                 zip(e.get("strain_stage", []), e.get("strain_hold", [])))
             or "-"),
            ("longitudinal member force, mean (N)",
             lambda e: f"{e['grid_force_longitudinal_mean_n']:.2f}"),
            ("porosity at the end", lambda e: f"{e['porosity_final']:.3f}"),
            ("time step (s)", lambda e: f"{e['density_scaling']['dt_s']:.3g}"),
            ("wall time: preparation, stages (s)",
             lambda e: f"{e['preparation_wall_time_s']:.0f}, "
                       + ", ".join(f"{t:.0f}" for t in e["stage_wall_time_s"])),
            ("wall time (s)", lambda e: f"{e['wall_time_s']:.0f}")]
    names = list(el)
    lines += ["", "## The elements", "", "| | " + " | ".join(names) + " |",
              "|---|" + "---|" * len(names)]
    for label, f in rows:
        lines.append(f"| {label} | " + " | ".join(f(el[n]) for n in names) + " |")
    lines += ["", "Figures: `<grid>_s<seed>_views`, `_grid`, `_rose` (.png, .pdf: RE and PRS on "
              "shared scales); histories of the measures: `<element>_measures.csv`; VTK in "
              "`vtk/`.", ""]
    (out / "report.md").write_text("\n".join(lines) + "\n")


# ---- the run -----------------------------------------------------------------------------------

JOBS = "jobs"  #: the folder of the finished (grid, seed) pairs' summaries (--resume keeps them)


def _job_file(grid: str, seed: int) -> str:
    return f"{JOBS}/{grid}_s{seed}.json"


def resume_keep(out: Path) -> list[str]:
    """The files of the finished (grid, seed) pairs in ``out`` (their summaries first), which
    --resume keeps; an empty list when none finished."""
    out = Path(out)
    done = sorted((out / JOBS).glob("*.json")) if (out / JOBS).is_dir() else []
    keep = [str(f.relative_to(out)) for f in done]
    for f in done:
        for e in json.loads(f.read_text())["labels"]:
            keep += [str(g.relative_to(out)) for g in sorted(out.rglob(f"{e}*"))
                     if g.is_file() and str(g.relative_to(out)) not in keep]
        stem = f.stem
        keep += [str(g.relative_to(out)) for g in sorted(out.glob(f"{stem}_*")) if g.is_file()]
    return keep


def run(p: Params, out: Path) -> dict:
    """The case in ``out`` (begun by run_main: with --resume the finished packings' files
    are kept there, and only the others run)."""
    t_start = time.perf_counter()
    begin_run(out, "prs_element_002", log=log)
    (out / JOBS).mkdir(parents=True, exist_ok=True)
    summary: dict = {"params": {k: (list(v) if isinstance(v, tuple) else v)
                                for k, v in asdict(p).items()},
                     "seeds": list(p.seeds), "elements": {}}
    targets: dict = {}
    with contextlib.ExitStack() as stack:
        hist = None
        if p.stresses:
            summary["mode"] = "DEM-only (stresses given)"
            for g in p.grids:
                for v in p.variants:
                    targets[(g, v)] = [np.asarray(r, float) for r in p.stresses]
        else:
            from femcoupling.drivers.prs_element import run_fem
            from femcoupling.twoway import HandoverHistory

            summary["mode"] = "FEM -> DEM (one-way)"
            summary["fem"] = {}
            hist = stack.enter_context(HandoverHistory(
                out / "handover.h5", regions=[f"{g}_{v}" for g in p.grids for v in p.variants],
                metadata={"case": "prs_element_002"}))
            for k, (g, v) in enumerate((g, v) for g in p.grids for v in p.variants):
                # The FEM layer has the grid form's tensile stiffness (and T_p for PRS); the
                # same for every seed.
                fem_out = out / f"fem_{g}"
                fem_out.mkdir(parents=True, exist_ok=True)
                ini, fin, _m, _s0, _load, info = run_fem(
                    replace(p, geogrid=f"woven-{g}"), fem_out, v)
                info.update(targets_initial_pa=ini.normal_pa.tolist(),
                            targets_final_pa=fin.normal_pa.tolist(),
                            shear_pa=fin.shear_pa.tolist(), rotation_deg=fin.rotation_deg)
                summary["fem"][f"{g}_{v}"] = info
                targets[(g, v)] = [ini.normal_pa, fin.normal_pa]
                hist.append(iteration=0, region=k, fem_stress_pa=fin.fem_stress_pa,
                            targets_pa=fin.normal_pa, shear_pa=fin.shear_pa,
                            rotation_deg=fin.rotation_deg, change=0.0,
                            dem_stress_pa=np.full(3, np.nan))
        jobs = [(g, s) for g in p.grids for s in p.seeds]
        todo = [(g, s) for g, s in jobs if not (out / _job_file(g, s)).is_file()]
        for g, s in jobs:
            if (g, s) not in todo:
                log(f"--resume: {g} seed {s} kept from the earlier run")
                summary["elements"].update(json.loads((out / _job_file(g, s)).read_text())
                                           ["elements"])
        t_dem = time.perf_counter()
        args = [(replace(p, geogrid=f"woven-{g}", seed=s), g, s,
                 {v: targets[(g, v)] for v in p.variants}, out) for g, s in todo]
        if p.workers > 1 and len(todo) > 1:
            # (grid, seed) pairs side by side in spawned processes (one thread each): each
            # pair's arithmetic is the serial run's, so the results are the same.
            n_proc = min(p.workers, len(todo))
            log(f"--workers {p.workers}: {len(todo)} packings (RE and PRS on each), {n_proc} "
                "at a time")
            ex = stack.enter_context(concurrent.futures.ProcessPoolExecutor(
                max_workers=n_proc, mp_context=multiprocessing.get_context("spawn")))
            results = ex.map(_pair_job, *zip(*args))
        else:
            results = (_pair_job(*a) for a in args)
        for k, ((g, s), res) in enumerate(zip(todo, results)):
            left = (time.perf_counter() - t_dem) / (k + 1) * (len(todo) - k - 1)
            log(f"packing {k + 1}/{len(todo)} ({g}, seed {s}) done"
                + (f"; about {left:.0f} s left" if k + 1 < len(todo) else ""))
            summary["elements"].update(res["elements"])
            # Written as the run goes: a stopped run keeps (and --resume reuses) the pairs
            # it finished.
            (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float)
                                              + "\n")
    _draw_pairs(p, out)
    summary["findings"] = findings(summary["elements"], p.seeds, p.grids)
    summary["measures"] = measures_table(summary["elements"], p.seeds, p.grids)
    summary["wall_time_total_s"] = time.perf_counter() - t_start
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    write_report(out, summary)
    end_run(out)
    for f in summary["findings"]:
        log(f"{f['grid']}: {f['name']}: PRS - RE {_fmt(f['diff_mean'])} ± "
            f"{_fmt(f['diff_se'])} (n = {f['n']}): {f['verdict']}")
    log(f"done in {summary['wall_time_total_s']:.1f} s; report in {out / 'report.md'}")
    return summary


def _draw_pairs(p: Params, out: Path) -> None:
    """RE against PRS per grid and seed on shared scales (cpp_dem.measure.grid_figures)."""
    from cpp_dem.measure import grid_figures

    for g in p.grids:
        for s in p.seeds:
            files = {v: out / f"{g}_{v}_s{s}_figure.npz" for v in p.variants}
            if all(f.is_file() for f in files.values()):
                grid_figures.draw_all({v: grid_figures.load_figure_data(f)
                                       for v, f in files.items()}, out, f"{g}_s{s}")


def _pair_job(p: Params, grid: str, seed: int, targets: dict, out: Path) -> dict:
    """RE and PRS on one grown packing (picklable: ``--workers`` runs them in other
    processes). Writes jobs/<grid>_s<seed>.json when both are done."""
    prepared: dict = {}
    grow = float(np.mean([np.mean(t[0]) for t in targets.values()]))
    res = {"grid": grid, "seed": seed, "elements": {}, "labels": []}
    for v, t in targets.items():
        label = f"{grid}_{v}_s{seed}"
        res["elements"][label] = run_element(p, t, prestressed=v == "PRS", label=label,
                                             out=out, log=log, prepared=prepared,
                                             grow_stress=grow, prep_label=f"{grid}_s{seed}",
                                             draw_figures=False)
        res["elements"][label]["seed"] = seed
        res["labels"].append(label)
    res["preparation_wall_time_s"] = prepared.get("wall_time_s")
    tmp = out / (_job_file(grid, seed) + ".tmp")
    tmp.write_text(json.dumps(res, indent=2, default=float) + "\n")
    tmp.replace(out / _job_file(grid, seed))
    return res


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
    ap.add_argument("--grids", default=None,
                    help=f"woven forms to run (default {','.join(GRIDS)}; --smoke: detailed)")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="RE and/or PRS")
    ap.add_argument("--workers", type=int, default=1,
                    help="processes: 2 or more run the elements side by side (one thread "
                         "each), with the same results")
    ap.add_argument("--grains", default=d.grains,
                    help="clumps:NAME (a shipped grain, 'gravel', or a template CSV) or spheres")
    ap.add_argument("--seeds", default=None,
                    help="packings 'A-B' or 'A,B,...': RE and PRS on each seed's grown packing, "
                         "findings paired over them (default: --seed and the next one; at "
                         "least 2 for a verdict)")
    ap.add_argument("--fixed-walls", default=d.fixed_walls,
                    help="walls that stay put, comma-separated of x-,x+,y-,y+,z-,z+ (at most one "
                         "per axis). Default: none, all six servo about the centre; the prestressed-"
                         "element paper's Fig. 1 fixes some, e.g. x-,y-,z-")
    ap.add_argument("--gravity", type=float, default=d.gravity, help="m/s^2 along -z")
    ap.add_argument("--convention", choices=("series", "contact"), default=d.grid_convention,
                    help="the paper's k_n, k_s: PFC 4 ball properties combined in series "
                         "(as PFC 4 used them, the default), or the contacts' stiffnesses")
    ap.add_argument("--grid-ends", choices=("tension", "grips"), default=d.grid_ends,
                    help="how the grid's longitudinal ends are held: 'tension' (PRS pulled by "
                         "T_p throughout, RE free) or 'grips' (PRS tensioned then locked in "
                         "place, RE held by the same grips untensioned)")
    ap.add_argument("--max-steps", type=int, default=None,
                    help=f"a servo stage's step limit (default {d.max_steps}; --smoke: "
                         f"{SMOKE['max_steps']}): a stage still off its criteria then ends NOT "
                         "converged")
    ap.add_argument("--resume", action="store_true",
                    help="continue an interrupted run in --out: the (grid, seed) pairs it "
                         "finished are kept, the others run")
    return ap


def parse_seeds(text: str, ap) -> tuple[int, ...]:
    """'1-3' -> (1, 2, 3); '1,4' -> (1, 4)."""
    try:
        if "-" in text.strip().lstrip("-"):
            a, b = text.split("-", 1)
            seeds = tuple(range(int(a), int(b) + 1))
        else:
            seeds = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        seeds = ()
    if not seeds or any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
        ap.error(f"--seeds={text!r}: must be 'A-B' (A <= B) or a comma-separated list of "
                 "distinct integers >= 0")
    return seeds


def parse_args(argv=None) -> tuple[Params, Path]:
    ap = build_parser()
    a = ap.parse_args(argv)
    p = _fem_case.apply_element_args(ap, a, Params(**SMOKE) if a.smoke else Params())
    if a.grids is not None:
        p.grids = _names(a.grids, GRIDS, "--grids", ap)
    p.variants = _names(a.variants, VARIANTS, "--variants", ap)
    p.grains = a.grains
    p.seeds = parse_seeds(a.seeds, ap) if a.seeds else (p.seed, p.seed + 1)
    p.fixed_walls, p.grid_convention, p.grid_ends = a.fixed_walls, a.convention, a.grid_ends
    p.re_grips = p.grid_ends == "grips"
    if not (math.isfinite(a.gravity) and a.gravity >= 0):
        ap.error(f"--gravity={a.gravity}: must be >= 0 (m/s^2)")
    p.gravity = a.gravity
    if a.preset and a.density_scaling is None:
        from cpp_dem.presets import preset

        p.density_scaling = preset(a.preset).density_scaling
    if a.workers < 1:
        ap.error(f"--workers={a.workers}: must be >= 1")
    if a.max_steps is not None:
        if a.max_steps < 1:
            ap.error(f"--max-steps={a.max_steps}: must be >= 1 (steps per servo stage)")
        p.max_steps = a.max_steps
    p.workers = a.workers
    from cpp_dem import ParameterError
    from cpp_dem.elements.box import check_element_params

    try:
        check_element_params(p)
    except ParameterError as e:
        ap.error(str(e).replace("fixed_walls=", "--fixed-walls="))
    if a.stresses:
        p.stresses = _fem_case.parse_stresses(a.stresses, ap)
    if a.resume and a.out is None:
        ap.error("--resume: give --out, the folder of the run to continue")
    p.resume = a.resume
    return p, a.out


def main(argv=None) -> int:
    p, out = parse_args(argv)
    keep = None
    if p.resume:
        keep = resume_keep(out) or [_job_file(p.grids[0], p.seeds[0])]  # (named as missing)
    return run_main("prs_element_002", out, lambda o: run(p, o), keep=keep)


if __name__ == "__main__":
    sys.exit(main())
