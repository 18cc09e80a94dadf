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
`summary.json` is written after each finished packing (`"status": "running"`); a stopped run
(Ctrl-C, SIGTERM) marks it `"interrupted"`, with the finished packings (`finished`), the
findings over them and their figures.

SI units. DEM stresses compression positive.
"""

from __future__ import annotations

import contextlib
import json
import math
import re
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from geogrid_dem.cases import prs_element as _fem_case
from cpp_dem.elements.box import GRID_ENDS, KINEMATICS, run_element
from geogrid_dem.cases import PRESTRESS_PAPER
from geogrid_dem.processes import process_pool, results_in_order
from geogrid_dem.rundir import begin_run, end_run, on_interrupt, run_main, write_atomic
from geogrid_dem.stats import t_critical

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
    # 002's gravity and damping (Table 1: filling with viscous 0.97 and no local damping,
    # loading with local 0.9); the grid free while the grains grow to the stress. 002's fixed
    # walls (Fig. 1d) are an option (--fixed-walls x-,y-,z-): at smoke size their stage took
    # 73 600 steps against 1000 with all six walls servo (docs/prs_element_002.md).
    gravity: float = 9.81                #: m/s^2
    fill_viscous: float = 0.97           #: -, ratio of critical
    fill_local_damping: float = 0.0      #: -
    damping: float = 0.9                 #: local damping while loading, -
    grid_held: str = "growth"
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
    grid_ends: str = "lock"              #: PRS tensioned, then released: the grains lock it in
    # The element at rest on its FEM region's path (docs/prs_element_002.md, "Rest"): the
    # loading ramps at a bounded inertial number and holds until the motion stops; the out-of-
    # plane axis is held (the FEM is plane strain) and x follows the FEM region's strain.
    ramp: bool = True
    kinematics: str = "fem-strain"       #: with --stresses (no FEM path): 'stress'
    # A dense fill (002: compacted): the grains grow frictionless, then take mu = 0.8.
    prep_friction_deg: float = 0.0       #: deg, during growth
    grid_convention: str = "series"      #: 002's k_n, k_s as PFC 4 ball properties
    grids: tuple = GRIDS                 #: woven forms to run
    variants: tuple = VARIANTS           #: RE and/or PRS
    seeds: tuple = (1, 2)                #: packings; RE and PRS share each seed's
    smoke: bool = False                  #: test-sized (--smoke): the report says so


# The smoke's grains are smaller than the apertures too (SMOKE_N: aperture / mean diameter
# >= APERTURE_RATIO_MIN, checked in check_grain_size).
# Test-sized: the gravel's shapes filled with 6 spheres each (not 24) and density scaling
# S = 8 for the preparation (the loading's rate is bounded on the scaled inertia, so it takes
# as many steps as without).
SMOKE = dict(_fem_case.SMOKE, smoke=True, n=500, hold_steps=2000, max_steps=150_000, unbalanced=0.1,
             grids=("detailed",), grains="clumps:gravel@6", density_scaling=8.0)
#: The grains pass through the apertures: aperture / mean grain diameter at least this, -.
APERTURE_RATIO_MIN = 1.2


def log(msg: str) -> None:
    print(f"[prs_element_002] {msg}", flush=True)


# ---- 002's findings, RE against PRS over paired seeds ------------------------------------------

def _get(e: dict, *path):
    """The number at ``path`` in an element's summary, None where it is missing."""
    for k in path:
        if not isinstance(e, dict) or e.get(k) is None:
            return None
        e = e[k]
    return float(e)


def _minus(a, b):
    return None if a is None or b is None else a - b


def _change(e: dict, *path):
    """A measure's change over the loading: its value at rest after the loading less its value
    where the loading started (the element's ``interaction`` against ``interaction_start``);
    None for an element without the start (run before the loading was measured)."""
    if "interaction_start" not in e:
        return None
    return _minus(_get(e, "interaction", *path), _get(e, "interaction_start", *path))


#: 002's findings with a direction (PRS - RE, paired per seed; "PRS": PRS's own value):
#: (name, expected_sign, compare, value of an element summary). Each is what the loading does
#: (its change from the start of the loading to rest): what the preparation or the pull
#: decided before the load cannot decide a verdict (the end values are among the MEASURES).
FINDINGS = (
    ("tension varies less along the prestressed longitudinal members: change of the std "
     "along over the loading (N)", -1, "PRS - RE",
     lambda e: _change(e, "tension_variation", "longitudinal_std_along_n")),
    ("the longitudinal members align less with prestress: change of the out-of-plane "
     "deflection over the loading (m)", -1, "PRS - RE",
     lambda e: _change(e, "waviness", "out_of_plane_longitudinal_mean_m")),
    ("the longitudinal members align less with prestress: change of the grain contacts per m "
     "over the loading", -1, "PRS - RE",
     lambda e: _change(e, "contacts", "longitudinal_per_m")),
    ("less vertical strain for the same load with prestress (strain per Pa of the loading's "
     "vertical load)", -1, "PRS - RE",
     lambda e: _get(e, "vertical_compliance_per_pa")),
    ("displacements above the grid larger than below over the loading, PRS (mean |u| above "
     "- below, m)", +1, "PRS",
     lambda e: _minus(_get(e, "interaction", "displacement", "above_mean_m"),
                      _get(e, "interaction", "displacement", "below_mean_m"))),
)

#: Measures reported RE against PRS without a direction from 002 (no verdict).
MEASURES = (
    ("tension std along the longitudinal members at rest (N)",
     lambda e: _get(e, "interaction", "tension_variation", "longitudinal_std_along_n")),
    ("out-of-plane deflection of the longitudinal members at rest (m)",
     lambda e: _get(e, "interaction", "waviness", "out_of_plane_longitudinal_mean_m")),
    ("grain contacts per m of the longitudinal members at rest",
     lambda e: _get(e, "interaction", "contacts", "longitudinal_per_m")),
    ("longitudinal members' line force where the loading starts (N; PRS: the prestress held)",
     lambda e: _get(e, "prestress_at_loading_n")),
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
    ("interfriction: mobilised friction at grain–grid contacts, mean |F_t| / (mu F_n)",
     lambda e: _get(e, "interaction", "interfriction", "mean_ratio")),
    ("interfriction: grain–grid contacts sliding (fraction)",
     lambda e: _get(e, "interaction", "interfriction", "sliding_fraction")),
    ("gap between the grid and the grains below, mean (m)",
     lambda e: _get(e, "interaction", "gaps", "below_mean_m")),
    ("grid spheres unsupported from below (fraction)",
     lambda e: _get(e, "interaction", "gaps", "unsupported_below_fraction")),
    ("transverse members' longitudinal (axial) strain, interior members, mean (-)",
     lambda e: _get(e, "interaction", "member_strain", "transverse_mean")),
)


#: Below this many seeds a report's verdicts check the machinery; they are not findings.
SEEDS_FOR_FINDINGS = 6


def unjudgeable(diff_mean: float, diff_se: float, n: int) -> str:
    """Why a paired difference cannot be judged by Student's t, '' when it can: fewer than 2
    pairs (seeds with RE and PRS kept: no standard error), a mean or standard error not
    finite, or a standard error of 0 (up to rounding, 1e-9 of the mean): the pairs'
    differences all equal, as a counted measure whose pairs moved by the same count, give no
    estimate of its scatter, and t would be infinite."""
    if n < 2:
        return "fewer than 2 pairs: no standard error"
    if not (math.isfinite(diff_mean) and math.isfinite(diff_se)):
        return "its mean or standard error is not finite"
    if diff_se <= 1e-9 * abs(diff_mean):
        return "every pair's difference is the same: no scatter to judge it by"
    return ""


def verdict(diff_mean: float, diff_se: float, n: int, expected_sign: int) -> str:
    """At 95 % by Student's t over the n paired seeds: 'agrees' when the paired difference has
    002's sign and |d| > t(0.975, n - 1) x se, 'opposes' when it has the other sign beyond
    that, else 'not resolved' (also where :func:`unjudgeable` gives a reason)."""
    if unjudgeable(diff_mean, diff_se, n):
        return "not resolved"
    if abs(diff_mean) <= t_critical(n) * diff_se or diff_mean == 0:
        return "not resolved"
    return "agrees" if np.sign(diff_mean) == expected_sign else "opposes"


#: The element's strain over its FEM region's, per axis, that counts as on the region's path
#: (issue 59: within 0.5-2 by default); an element outside it is named (``off_fem_path``).
STRAIN_RATIO_RANGE = (0.5, 2.0)


def off_fem_path(e: dict) -> list[str]:
    """The axes ("x", "y", "z") on which an element's loading strain is outside
    STRAIN_RATIO_RANGE times its FEM region's (``strain_ratio_to_fem``; an axis without a
    ratio, the region's strain zero there, is not judged). Empty: on the region's path."""
    lo, hi = STRAIN_RATIO_RANGE
    return [ax for ax, r in zip("xyz", e.get("strain_ratio_to_fem") or [])
            if r is not None and not lo <= r <= hi]


def mark_off_fem_path(elements: dict, log) -> dict:
    """Sets each element's ``off_fem_path`` (:func:`off_fem_path`; elements with a strain
    ratio to the FEM only) and logs a WARNING naming those off it, with their ratios. Returns
    {label: element} of those off it."""
    off = {}
    for label, e in elements.items():
        if e.get("strain_ratio_to_fem") is not None:
            e["off_fem_path"] = off_fem_path(e)
            if e["off_fem_path"]:
                off[label] = e
    if off:
        lo, hi = STRAIN_RATIO_RANGE

        def ratios(e):
            r = e["strain_ratio_to_fem"]
            return ", ".join(f"{ax} {r['xyz'.index(ax)]:.3g}" for ax in e["off_fem_path"])

        log(f"WARNING: {len(off)} of {len(elements)} elements strained off their FEM region's "
            f"path (their strain over the region's outside {lo:g}-{hi:g} x): "
            + ", ".join(f"{k} ({ratios(e)})" for k, e in off.items())
            + "; the element is stiffer or softer there than the FEM's soil (summary.json: "
              "each element's off_fem_path)")
    return off


def _stats(x: list) -> tuple[float, float]:
    a = np.asarray(x, float)
    return float(a.mean()), (float(a.std(ddof=1)) if len(a) > 1 else float("nan"))


#: The statistics of a finding or measure row (paired's keys but the per-seed values).
STAT_KEYS = ("re_mean", "re_sd", "prs_mean", "prs_sd", "diff_mean", "diff_se", "n")


def not_at_rest(e: dict, key: str = "rest") -> bool:
    """Whether an element did not come to rest at its targets (its ``rest`` status is
    'at_strength', still moving, or 'not_at_rest', still but a force or servo check failed;
    ``cpp_dem.elements.box.rest_hold``): it is never measured unless at rest. With
    ``key="rest_initial"``: whether its initial hold, before the loading, did not."""
    return (e.get(key) or {}).get("status") in ("at_strength", "not_at_rest")


def paired(elements: dict, grid: str, seeds, value) -> dict | None:
    """RE and PRS values of ``value`` over the seeds with both, and their paired difference
    (PRS - RE): means, sds, the difference's mean and standard error, n; 'unconverged': the
    labels of those elements with a stage that did not converge; 'pairs_left_out': the
    labels of the pairs left out because an element of theirs is not at rest at the end, or
    was loaded before its initial hold came to rest (:func:`not_at_rest` of ``rest`` and of
    ``rest_initial``): a measure's change over the loading starts from that hold, so it
    would count what the element still moved under the initial targets."""
    re_v, prs_v, unconverged, left_out = [], [], [], []
    for s in seeds:
        re_, prs = elements.get(f"{grid}_RE_s{s}"), elements.get(f"{grid}_PRS_s{s}")
        if re_ is None or prs is None:
            continue
        if any(not_at_rest(e, key) for e in (re_, prs) for key in ("rest", "rest_initial")):
            left_out.append(f"{grid}_s{s}")
            continue
        a, b = value(re_), value(prs)
        if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
            continue
        re_v.append(a)
        prs_v.append(b)
        unconverged += [f"{grid}_{v}_s{s}" for v, e in (("RE", re_), ("PRS", prs))
                        if not all(e.get("converged", [True]))]
    if not re_v:
        return None if not left_out else {
            "re_mean": math.nan, "re_sd": math.nan, "prs_mean": math.nan, "prs_sd": math.nan,
            "diff_mean": math.nan, "diff_se": math.nan, "n": 0, "re_values": [],
            "prs_values": [], "unconverged": [], "pairs_left_out": left_out}
    n = len(re_v)
    d = np.asarray(prs_v) - np.asarray(re_v)
    rm, rs = _stats(re_v)
    pm, ps = _stats(prs_v)
    dm, dsd = _stats(d)
    return {"re_mean": rm, "re_sd": rs, "prs_mean": pm, "prs_sd": ps, "diff_mean": dm,
            "diff_se": dsd / math.sqrt(n) if n > 1 else float("nan"), "n": n,
            "re_values": re_v, "prs_values": prs_v, "unconverged": unconverged,
            "pairs_left_out": left_out}


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
                        "t_critical": t_critical(st["n"]),
                        "pairs_left_out": st["pairs_left_out"],
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


def _alone(f: dict) -> str:
    """The label of a finding about PRS alone, whose difference column holds PRS's own mean
    and standard error (not PRS - RE)."""
    return "PRS alone: " if f.get("compare") == "PRS" else ""


def unresolved_reason(f: dict) -> str:
    """Why a finding is 'not resolved' where its numbers alone do not say it (an element
    behind it unconverged, fewer than 2 pairs, a mean or standard error not finite, no
    scatter of the pairs' differences), with the pairs left out (an element not at rest)
    where there are any; empty otherwise (within t crit x se)."""
    if f.get("verdict") != "not resolved":
        return ""
    if f.get("unconverged"):
        return "an element behind it did not converge: " + ", ".join(f["unconverged"])
    nan = float("nan")
    d, se = f.get("diff_mean"), f.get("diff_se")
    why = unjudgeable(nan if d is None else d, nan if se is None else se, f.get("n", 0))
    if why and f.get("pairs_left_out"):
        why += "; left out, an element not at rest: " + ", ".join(f["pairs_left_out"])
    return why


def findings_table(rows: list[dict], *, with_verdict: bool = True) -> list[str]:
    """The markdown table of findings (or measures) rows."""
    head = "| grid | finding | RE mean ± sd | PRS mean ± sd | PRS − RE ± se | n |"
    lines = [head + (" t crit | 002 | verdict | pairs left out |" if with_verdict else ""),
             "|---|---|---|---|---|---|" + ("---|---|---|---|" if with_verdict else "")]
    for f in rows:
        line = (f"| {f['grid']} | {f['name']} | {_fmt(f['re_mean'])} ± {_fmt(f['re_sd'])} | "
                f"{_fmt(f['prs_mean'])} ± {_fmt(f['prs_sd'])} | "
                f"{_alone(f)}{_fmt(f['diff_mean'])} ± {_fmt(f['diff_se'])} | {f['n']} |")
        if with_verdict:
            line += (f" {_fmt(f.get('t_critical'))} | {'+' if f['expected_sign'] > 0 else '−'}"
                     f" | {f['verdict']} | {', '.join(f.get('pairs_left_out') or []) or '-'} |")
        lines.append(line.replace("|u|", "\\|u\\|"))
    return lines


def variants_of(summary: dict) -> list[str]:
    """The variants a run's summary ran (its params' ``variants``; both where it has none)."""
    return (summary.get("params") or {}).get("variants") or list(VARIANTS)


def no_pairs_reason(summary: dict) -> str:
    """Why a run has no findings (no seed with its RE and PRS both measured): the variants
    it ran, when one is missing, or else that no seed has both."""
    variants = variants_of(summary)
    missing = [v for v in VARIANTS if v not in variants]
    if missing:
        return (f"the run has no {' or '.join(missing)} element (--variants "
                f"{','.join(variants)}); a finding is a paired difference PRS − RE per seed")
    return "no seed has both its RE and PRS elements measured"


def write_report(out: Path, summary: dict) -> None:
    el = summary["elements"]
    variants = variants_of(summary)
    lines = ["# The prestressed reinforced-soil element (clumps, woven grid): report", "",
             f'Source: "{PRESTRESS_PAPER}".', "",
             f"Mode: {summary['mode']}. Seeds: {summary['seeds']} ({' and '.join(variants)} "
             "on each seed's grown packing). Stresses in kPa, compression positive.", ""]
    for g, soil in summary.get("soil", {}).items():
        cal = summary.get("calibration", {}).get(g)
        lines += [f"FEM soil of the {g} grid ({soil['source']}): E "
                  f"{soil['young_pa'] / 1e6:.4g} MPa, nu {soil['poisson']:.3f}, phi "
                  f"{soil['friction_deg']:g} deg, c {soil['cohesion_pa']:g} Pa"
                  + (f"; calibrated on RE seed {summary['seeds'][0]}'s element, "
                     f"{cal['message']}" if cal else "") + ".", ""]
    lines += ["## 002's findings, paired over the seeds", ""]
    n_seeds = len(summary["seeds"])
    if n_seeds < SEEDS_FOR_FINDINGS:
        lines += [f"**{n_seeds} seed(s), fewer than {SEEDS_FOR_FINDINGS}: these verdicts check "
                  "the machinery; they are not findings.**", ""]
    if summary.get("smoke"):
        lines += ["**Smoke size** (test-sized grains and element): not 002's element.", ""]
    lines += ["The difference is PRS − RE per seed, of what the loading does (a measure's change "
              "from the start of the loading to rest; for a finding about PRS alone, PRS's own "
              "value). At 95 % by Student's t over the n pairs: `agrees`: 002's sign with "
              "|d| > t crit × se; `opposes`: the other sign beyond it; else `not resolved` "
              "(also when an element behind it did not converge). A pair with an element "
              "not at rest at its targets (`at_strength`: still moving; `not_at_rest`: still, "
              "but its unbalanced force or its walls' error failed), at the end or in its "
              "initial hold before the loading, is left out and named.",
              ""]
    lines += findings_table(summary["findings"])
    if not summary["findings"]:
        lines += ["", f"**No findings:** {no_pairs_reason(summary)}."]
    stalled = sorted({k for f in summary["findings"] for k in f.get("unconverged", [])})
    if stalled:
        lines += ["", f"**Not at rest:** {', '.join(stalled)} ended a stage NOT converged "
                  "(the elements' `stall`): the findings that rest on them are `not resolved`."]
    off = {k: e["off_fem_path"] for k, e in summary["elements"].items()
           if e.get("off_fem_path")}
    if off:
        lo, hi = STRAIN_RATIO_RANGE
        named = ", ".join(f"{k} ({'/'.join(v)})" for k, v in off.items())
        lines += ["", f"**Off the FEM path:** {named} strained outside {lo:g}–{hi:g} × their "
                  "FEM region on those axes: the element is stiffer or softer there than the "
                  "FEM's soil."]
    unsettled = {k: e["rest_initial"] for k, e in summary["elements"].items()
                 if not_at_rest(e, "rest_initial")}
    if unsettled:
        named = "; ".join(f"{k} ({', '.join(r.get('failed') or ['not at rest'])} after "
                          f"{r['hold_steps']} steps)" for k, r in unsettled.items())
        lines += ["", f"**Loaded before the initial hold came to rest:** {named}. Its "
                  "loading's measures would include what it still moved under the initial "
                  "targets (the table's vertical strain in the first stage's hold), so its "
                  "pair is left out of the findings and measures."]
    lines += ["", "## Other measures (no direction from 002)", ""]
    lines += findings_table(summary["measures"], with_verdict=False)
    rows = [("grains", lambda e: f"{e['num_grains']}"),
            ("walls reached (kPa)", lambda e: str(np.round(np.array(e["stress_final_pa"]) / 1e3,
                                                            2).tolist())),
            ("converged", lambda e: str(e["converged"])),
            ("rest (max inertial number loading / end of hold)",
             lambda e: (f"{e['rest']['status']} ({_fmt(e['rest'].get('loading_inertial_number_max'))}"
                        f" / {_fmt(e['rest']['inertial_number_end'])})") if e.get("rest") else "-"),
            ("loading strain x, y, z", lambda e: ", ".join(
                f"{x:.3g}" for x in e["loading_strain"]) if e.get("loading_strain") else "-"),
            ("strain / FEM region x, y, z", lambda e: ", ".join(
                _fmt(x) for x in e["strain_ratio_to_fem"]) if e.get("strain_ratio_to_fem")
             else "-"),
            ("held within (%)", lambda e: f"{100 * e['hold_max_rel_error']:.2f}"),
            ("vertical strain per stage; in its hold (creep)",
             lambda e: "; ".join(f"{a[2]:.2e}, {b[2]:.2e}" for a, b in
                                 zip(e.get("strain_stage", []), e.get("strain_hold", [])))
             or "-"),
            ("longitudinal member force, mean (N)",
             lambda e: f"{e['grid_force_longitudinal_mean_n']:.2f}"),
            ("porosity at the end", lambda e: f"{e['porosity_final']:.3f}"),
            ("coordination number at the end", lambda e: _fmt(e.get("coordination_final"))),
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


PACKINGS = "packings"  #: the folder of the unfinished pairs' grown packings (--resume keeps)


def _packing_file(grid: str, seed: int) -> str:
    return f"{PACKINGS}/{grid}_s{seed}.h5"


#: The calibration's records in each grid's FEM folder (``fem_<grid>/``) that --resume keeps
#: (checkpoints: their SHA-256 is recorded as they are written): a finished calibration, and
#: the passes an unfinished one finished (``geogrid_dem.studies.prs_element.calibrate_soil``).
CALIBRATION_RECORDS = ("calibration.json", "calibration_passes.json")
#: What --resume keeps only when its bytes are the run's (SHA-256 recorded as written): the
#: pairs' job files, the calibrations' records, and the grown packings of the unfinished pairs
#: and calibrations (``cpp_dem.elements.box.save_prepared``).
PACKING_FILES = (f"{PACKINGS}/*.h5", "fem_*/packing_s*.h5")
CHECKPOINTS = (f"{JOBS}/*.json", *(f"fem_*/{name}" for name in CALIBRATION_RECORDS),
               *PACKING_FILES)


def resume_keep(out: Path) -> list[str]:
    """The files --resume keeps in ``out``: those of the finished (grid, seed) pairs (their
    summaries first), the grown packings of the unfinished ones and of an unfinished
    calibration (restored, not grown again), then each grid's calibration records
    (CALIBRATION_RECORDS) with the files of its passes (``fem_<grid>/calibration_*``), so a
    run stopped during the calibration goes on at its next pass; an empty list when nothing
    finished."""
    out = Path(out)
    keep = _finished_pairs(out)
    keep += [str(f.relative_to(out)) for pat in PACKING_FILES for f in sorted(out.glob(pat))]
    seen = set(keep)
    for fem_dir in sorted(out.glob("fem_*")):
        records = [fem_dir / n for n in CALIBRATION_RECORDS if (fem_dir / n).is_file()]
        if not records:
            continue
        done = _calibration_passes_done(records[0])
        for g in [*records, *sorted(fem_dir.glob("calibration_*"))]:
            rel = str(g.relative_to(out))
            m = _PASS_FILE.match(g.name)
            if g in records or (m and int(m.group(1)) <= done):  # (an unfinished pass: not)
                if g.is_file() and rel not in seen:
                    keep.append(rel)
                    seen.add(rel)
    return keep


#: A calibration pass's element files: calibration_<variant>[_s<seed>]_<pass>...
_PASS_FILE = re.compile(r"calibration_[A-Za-z]+(?:_s\d+)?_(\d+)(?![0-9])")


def _calibration_passes_done(record: Path) -> int:
    """The passes a calibration record holds (0 if it cannot be read: begin_run then refuses
    a file that is not the run's by its SHA-256)."""
    try:
        return len(json.loads(record.read_text())["passes"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0


def _finished_pairs(out: Path) -> list[str]:
    """The files of the finished (grid, seed) pairs in ``out``, their summaries first."""
    done = sorted((out / JOBS).glob("*.json")) if (out / JOBS).is_dir() else []
    keep = [str(f.relative_to(out)) for f in done]
    seen = set(keep)
    for f in done:
        try:
            labels = [str(e) for e in json.loads(f.read_text())["labels"]]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # (not a job file this run wrote: begin_run refuses it by its SHA-256)
        for e in labels:
            keep += [str(g.relative_to(out)) for g in sorted(out.rglob(f"{e}*"))
                     if g.is_file() and str(g.relative_to(out)) not in seen]
            seen.update(keep)
        stem = f.stem
        keep += [str(g.relative_to(out)) for g in sorted(out.glob(f"{stem}_*")) if g.is_file()]
        seen.update(keep)
    return keep


def interrupted_report(p: Params, out: Path, summary: dict) -> None:
    """What an interrupted run reports (rundir.on_interrupt): its summary so far (the FEM
    variants solved, the elements of every finished packing, also those a worker finished
    out of order: their job files) with ``finished`` naming them, the findings and measures
    over the finished packings; the figures of each finished (grid, seed) pair."""
    def partial() -> dict:
        s = {**summary, "elements": dict(summary["elements"])}
        done = []
        for g, sd in ((g, sd) for g in p.grids for sd in p.seeds):
            f = out / _job_file(g, sd)
            if f.is_file():
                s["elements"].update(json.loads(f.read_text())["elements"])
                done.append(f"packing {g} seed {sd} (RE and PRS)")
        s["finished"] = [f"FEM {k}" for k in summary.get("fem", {})] + done
        s["findings"] = findings(s["elements"], p.seeds, p.grids)
        s["measures"] = measures_table(s["elements"], p.seeds, p.grids)
        return s

    on_interrupt(out, summary=partial, figures=lambda: _draw_pairs(p, out))


def run(p: Params, out: Path) -> dict:
    """The case in ``out`` (begun by run_main: with --resume the finished packings' files
    are kept there, and only the others run)."""
    t_start = time.perf_counter()
    begin_run(out, "prs_element_002", log=log)
    (out / JOBS).mkdir(parents=True, exist_ok=True)
    summary: dict = {"params": {k: (list(v) if isinstance(v, tuple) else v)
                                for k, v in asdict(p).items()},
                     "seeds": list(p.seeds), "smoke": bool(p.smoke), "elements": {}}
    interrupted_report(p, out, summary)
    targets: dict = {}
    with contextlib.ExitStack() as stack:
        hist = None
        if p.stresses:
            summary["mode"] = "DEM-only (stresses given)"
            for g in p.grids:
                for v in p.variants:
                    targets[(g, v)] = {"rows": [np.asarray(r, float) for r in p.stresses],
                                       "tension": None, "strain": None}
        else:
            from femcoupling.coupling.twoway import HandoverHistory
            from geogrid_dem.studies.prs_element import run_fem

            summary["mode"] = "FEM -> DEM (one-way)"
            summary["fem"] = {}
            soils, fems = {}, {}
            for g in p.grids:
                soils[g], fems[g] = fem_soil(p, g, out / f"fem_{g}", summary)
            hist = stack.enter_context(HandoverHistory(
                out / "handover.h5", regions=[f"{g}_{v}" for g in p.grids for v in p.variants],
                metadata={"case": "prs_element_002"}))
            for k, (g, v) in enumerate((g, v) for g in p.grids for v in p.variants):
                # The FEM layer has the grid form's tensile stiffness (and T_p for PRS); the
                # same for every seed.
                fem_out = out / f"fem_{g}"
                fem_out.mkdir(parents=True, exist_ok=True)
                ini, fin, _m, _s0, _load, info = (fems.get(g, {}).get(v) or run_fem(
                    replace(p, geogrid=f"woven-{g}", **soils[g]), fem_out, v))
                info.update(targets_initial_pa=ini.normal_pa.tolist(),
                            targets_final_pa=fin.normal_pa.tolist(),
                            shear_pa=fin.shear_pa.tolist(), rotation_deg=fin.rotation_deg,
                            shear_omitted=shear_omitted(fin))
                so = info["shear_omitted"]
                log(f"FEM {v}: the walls cannot shear the element: the FEM's principal "
                    f"stresses mobilise {so['friction_principal_deg']:.1f} deg, the diagonal "
                    f"handed over {so['friction_diagonal_deg']:.1f} deg (the omission: "
                    f"{so['friction_omitted_deg']:.1f} deg)")
                summary["fem"][f"{g}_{v}"] = info
                targets[(g, v)] = handover(p, ini, fin, info, label=f"{g}_{v}")
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
            ex = stack.enter_context(process_pool(n_proc))
            results = results_in_order(ex, _pair_job, *zip(*args))
        else:
            results = (_pair_job(*a) for a in args)
        for k, ((g, s), res) in enumerate(zip(todo, results)):
            left = (time.perf_counter() - t_dem) / (k + 1) * (len(todo) - k - 1)
            log(f"packing {k + 1}/{len(todo)} ({g}, seed {s}) done"
                + (f"; about {left:.0f} s left" if k + 1 < len(todo) else ""))
            summary["elements"].update(res["elements"])
            # Written as the run goes ("running"; a stop marks it "interrupted"): a stopped
            # run keeps (and --resume reuses) the pairs it finished.
            (out / "summary.json").write_text(json.dumps({"status": "running", **summary},
                                                         indent=2, default=float) + "\n")
    _draw_pairs(p, out)
    mark_off_fem_path(summary["elements"], log)
    summary["findings"] = findings(summary["elements"], p.seeds, p.grids)
    summary["measures"] = measures_table(summary["elements"], p.seeds, p.grids)
    summary["wall_time_total_s"] = time.perf_counter() - t_start
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    write_report(out, summary)
    end_run(out)
    if not summary["findings"]:
        log(f"no findings: {no_pairs_reason(summary)}")
    for f in summary["findings"]:
        why = unresolved_reason(f)
        log(f"{f['grid']}: {f['name']}: {f['compare']} {_fmt(f['diff_mean'])} ± "
            f"{_fmt(f['diff_se'])} (n = {f['n']}): {f['verdict']}" + (f" ({why})" if why else ""))
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


def shear_omitted(fin) -> dict:
    """The bound on what the walls leave out: they impose the FEM region's normal stresses (the
    diagonal) and cannot shear the element. The friction angle the full FEM stress mobilises
    (its largest and least principal stresses) against the diagonal's (deg), their difference,
    and the shear and rotation themselves (Pa, deg)."""
    from cpp_dem.elements.box import mobilised_friction_deg

    full = mobilised_friction_deg(fin.principal_pa)
    diag = mobilised_friction_deg(fin.normal_pa)
    return {"shear_pa": [float(x) for x in fin.shear_pa], "rotation_deg": float(fin.rotation_deg),
            "principal_pa": [float(x) for x in fin.principal_pa],
            "friction_principal_deg": full, "friction_diagonal_deg": diag,
            "friction_omitted_deg": full - diag}


def fem_soil(p: Params, grid: str, fem_out: Path, summary: dict) -> tuple[dict, dict]:
    """The FEM soil of ``grid``'s runs, one soil on both scales: with ``p.soil`` 'calibrated'
    calibrated on the mean of this grid's RE elements of the run's seeds (the same grains and
    preparation; ``geogrid_dem.studies.prs_element.calibrate_soil``, on ``p.workers``
    processes; its record in ``fem_out``), else as
    given. With ``p.resume`` a calibration the interrupted run finished (its
    ``calibration.json``) is kept, not run again, and one it left unfinished goes on at its
    next pass (``calibration_passes.json``). Returns the soil's Params fields and the
    FEM runs the calibration solved with it (variant -> ``run_fem``'s result, to be reused);
    fills ``summary["soil"][grid]`` (and ``["calibration"][grid]``)."""
    from geogrid_dem.studies.prs_element import calibrate_soil

    fem_out.mkdir(parents=True, exist_ok=True)
    q = replace(p, geogrid=f"woven-{grid}", seed=p.seeds[0])
    kept: dict = {}
    if p.soil == "calibrated":
        path = fem_out / "calibration.json"
        if getattr(p, "resume", False) and path.is_file():
            rec = json.loads(path.read_text())
            q = replace(q, soil_young=float(rec["young_pa"]), soil_poisson=float(rec["poisson"]),
                        soil_cohesion=0.0)
            log(f"--resume: the {grid} grid's soil calibration kept from the earlier run "
                f"({path})")
        else:
            q, rec = calibrate_soil(q, fem_out, keep=kept, seeds=list(p.seeds),
                                    workers=p.workers, resume=getattr(p, "resume", False))
        summary.setdefault("calibration", {})[grid] = rec
    soil = {k: getattr(q, k) for k in ("soil_young", "soil_poisson", "soil_friction",
                                       "soil_cohesion")}
    summary.setdefault("soil", {})[grid] = {
        "source": p.soil, "young_pa": q.soil_young, "poisson": q.soil_poisson,
        "friction_deg": q.soil_friction, "cohesion_pa": q.soil_cohesion}
    log(f"FEM soil of the {grid} grid ({p.soil}): E {q.soil_young / 1e6:.4g} MPa, nu "
        f"{q.soil_poisson:.3f}, phi {q.soil_friction:g} deg, c {q.soil_cohesion:g} Pa")
    return soil, kept


def handover(p: Params, ini, fin, info: dict, label: str = "") -> dict:
    """What the FEM hands to a variant's element: the wall targets before and after the
    footing (``rows``, Pa); with the prestress locked in (grid_ends 'lock') the FEM layer's
    tension across the region before and after the footing (``tension``, N/m), which the
    grid's ends carry: the structure's fill holds the layer's prestress (the FEM tensions its
    layer and lets the soil take it up), and the element is a piece of it; and the FEM
    region's strain over the loading (``strain``, 3, compression positive), which the
    element's strain-controlled axes follow. ``label`` names the region in the log."""
    tension = None
    t0, t1 = ini.grid_tension_n_per_m, fin.grid_tension_n_per_m
    if p.grid_ends == "lock" and t0 is not None and t1 is not None:
        tension = [float(t0), float(t1)]
        if min(tension) < 0:
            # (a geogrid carries no compression: pushed, its ends would buckle it)
            log(f"{label + ': ' if label else ''}the FEM layer is in compression across the "
                f"region ({np.round(np.array(tension) / 1e3, 4).tolist()} kN/m): a geogrid "
                "carries none, so its ends take 0 there")
            tension = [max(t, 0.0) for t in tension]
    return {"rows": [ini.normal_pa, fin.normal_pa], "tension": tension,
            "strain": [float(x) for x in info["strain_increment"]]}


def _pair_job(p: Params, grid: str, seed: int, targets: dict, out: Path) -> dict:
    """RE and PRS on one grown packing (picklable: ``--workers`` runs them in other
    processes); ``targets``: per variant, :func:`handover`'s dict. Writes
    jobs/<grid>_s<seed>.json when both are done."""
    # (the grown packing on disk while the pair runs: a resumed run restores it instead of
    # growing it again; removed with the pair's job file written)
    prepared: dict = {"file": out / _packing_file(grid, seed)}
    grow = float(np.mean([np.mean(t["rows"][0]) for t in targets.values()]))
    res = {"grid": grid, "seed": seed, "elements": {}, "labels": []}
    for v, t in targets.items():
        label = f"{grid}_{v}_s{seed}"
        res["elements"][label] = run_element(p, t["rows"], prestressed=v == "PRS", label=label,
                                             out=out, log=log, prepared=prepared,
                                             grow_stress=grow, prep_label=f"{grid}_s{seed}",
                                             draw_figures=False, grid_tension=t["tension"],
                                             fem_strain_increment=t["strain"])
        res["elements"][label]["seed"] = seed
        res["labels"].append(label)
    res["preparation_wall_time_s"] = prepared.get("wall_time_s")
    write_atomic(out / _job_file(grid, seed), json.dumps(res, indent=2, default=float) + "\n")
    prepared["file"].unlink(missing_ok=True)
    return res


def _grain_diameter(p: Params, n: int) -> float:
    """The grains' mean diameter that the preparation grows n of them to, m (their solid
    volume 0.6 of the element's: cpp_dem.elements.box.prepare_woven_element)."""
    return (0.6 * p.edge**3 / (n * math.pi / 6.0)) ** (1.0 / 3.0)


def aperture_ratio(p: Params, grid: str) -> float:
    """The woven grid's aperture over the grains' mean diameter, -."""
    from cpp_dem.build.woven import PRESETS

    return PRESETS[grid]["aperture"] / _grain_diameter(p, p.n)


def min_grains(p: Params, grid: str) -> int:
    """The least grain count whose grains pass the grid's apertures (APERTURE_RATIO_MIN)."""
    from cpp_dem.build.woven import PRESETS

    d = PRESETS[grid]["aperture"] / APERTURE_RATIO_MIN
    return int(math.ceil(0.6 * p.edge**3 / (math.pi / 6.0 * d**3)))


def _names(text: str, allowed: tuple, flag: str, ap) -> tuple:
    """The names of a comma list ``text`` of ``flag``, each one of ``allowed`` and listed
    once (ap.error naming the flag, the value and what is allowed)."""
    from geogrid_dem.options import distinct

    names = tuple(t.strip() for t in text.split(",") if t.strip())
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        ap.error(f"{flag}={text!r}: must be a comma-separated list of {', '.join(allowed)}")
    distinct(ap, flag, repr(text), names)
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
    _fem_case.add_soil_arg(ap, d)
    ap.add_argument("--grids", default=None,
                    help=f"woven forms to run (default {','.join(GRIDS)}; --smoke: detailed)")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="RE and/or PRS")
    ap.add_argument("--workers", type=int, default=1,
                    help="processes: 2 or more run the elements side by side (one thread "
                         "each), with the same results")
    ap.add_argument("--grains", default=None,
                    help=f"clumps:NAME (a shipped grain, 'gravel', or a template CSV; NAME@N: "
                         f"filled with N spheres) or spheres (default {d.grains}; --smoke: "
                         f"{SMOKE['grains']})")
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
    ap.add_argument("--grid-ends", choices=GRID_ENDS, default=d.grid_ends,
                    help="how the grid's longitudinal ends are held: 'lock' (the default: PRS "
                         "tensioned to T_p by grips, which are then released, so the grains "
                         "hold the prestress; RE untouched; both ends then take the FEM "
                         "layer's tension increment), 'tension' (PRS pulled by T_p throughout, "
                         "RE free: a dead load) or 'grips' (PRS tensioned then held in place, "
                         "RE held by the same grips untensioned)")
    ap.add_argument("--kinematics", choices=tuple(KINEMATICS), default=None,
                    help="the loading's walls: 'fem-strain' (the default with the FEM: y "
                         "held as the plane-strain FEM, x following the FEM region's strain, "
                         "z servoed to the FEM's stress), 'plane-strain' (y held, x and z "
                         "servoed) or 'stress' (every axis servoed; the default with "
                         "--stresses)")
    ap.add_argument("--max-steps", type=int, default=None,
                    help=f"a servo stage's step limit (default {d.max_steps}; --smoke: "
                         f"{SMOKE['max_steps']}): a stage still off its criteria then ends NOT "
                         "converged")
    ap.add_argument("--resume", action="store_true",
                    help="continue an interrupted run in --out: the (grid, seed) pairs it "
                         "finished are kept, the others run")
    return ap


def parse_seeds(text: str, ap, args=None) -> tuple[int, ...]:
    """'1-3' -> (1, 2, 3); '1,4' -> (1, 4). An empty text, a seed listed twice and more seeds
    than the cap (without --allow-large in ``args``, the parsed namespace; checked before
    the list is made) are refused, naming --seeds."""
    from geogrid_dem.options import check_cap, check_seeds, distinct

    try:
        if "-" in text.strip().lstrip("-"):
            a, b = text.split("-", 1)
            check_cap(ap, args, "--seeds", repr(text), int(b) - int(a) + 1, "seeds")
            seeds = tuple(range(int(a), int(b) + 1))
        else:
            seeds = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        seeds = ()
    if not seeds or any(s < 0 for s in seeds):
        ap.error(f"--seeds={text!r}: must be 'A-B' (A <= B) or a comma-separated list of "
                 "distinct integers >= 0")
    distinct(ap, "--seeds", repr(text), seeds)
    check_cap(ap, args, "--seeds", repr(text), len(seeds), "seeds")
    check_seeds(ap, "--seeds", repr(text), seeds)
    return seeds


def parse_args(argv=None) -> tuple[Params, Path]:
    from geogrid_dem.options import check_cap, check_seeds, given_options, refuse_unused

    ap = build_parser()
    a = ap.parse_args(argv)
    given = given_options(ap, argv)
    p = _fem_case.apply_element_args(ap, a, Params(**SMOKE) if a.smoke else Params(), given)
    if a.grids is not None:
        p.grids = _names(a.grids, GRIDS, "--grids", ap)
    p.variants = _names(a.variants, VARIANTS, "--variants", ap)
    p.grains = a.grains or p.grains
    # (an empty --seeds is refused by parse_seeds, not replaced by the default)
    p.seeds = parse_seeds(a.seeds, ap, a) if a.seeds is not None else (p.seed, p.seed + 1)
    if a.seeds is None:
        check_seeds(ap, "--seed", f"{p.seed} (the packings' seeds --seed and the next one)",
                    p.seeds)
    n_elements = len(p.grids) * len(p.variants) * len(p.seeds)
    check_cap(ap, a, "--grids/--variants/--seeds",
              f"{','.join(p.grids)}/{','.join(p.variants)}/{a.seeds}", n_elements,
              "elements or runs", "elements")
    # options that would have no effect given the others (docs/cli.md)
    if "PRS" not in p.variants:
        refuse_unused(ap, a, given, "prestress", f"without the PRS variant (--variants "
                      f"{','.join(p.variants)})", "add PRS to --variants")
    if a.seeds is not None:
        refuse_unused(ap, a, given, "seed", f"with --seeds {a.seeds} (the packings' seeds)")
    if a.workers > 1 and len(p.grids) * len(p.seeds) < 2:
        refuse_unused(ap, a, given, "workers", f"with one packing (grid {p.grids[0]}, seed "
                      f"{p.seeds[0]}): the workers run packings side by side",
                      "give more --seeds or --grids")
    if a.density_scaling is not None and a.preset:
        ap.error(f"--preset {a.preset} with --density-scaling={a.density_scaling}: the preset "
                 "sets only the density scaling here, which --density-scaling overrides; give "
                 "one of them")
    p.fixed_walls, p.grid_convention, p.grid_ends = a.fixed_walls, a.convention, a.grid_ends
    p.re_grips = p.grid_ends == "grips"
    if a.kinematics == "fem-strain" and a.stresses:
        ap.error("--kinematics=fem-strain: needs the FEM's strain path; with --stresses use "
                 "'stress' or 'plane-strain'")
    p.kinematics = a.kinematics or ("stress" if a.stresses else p.kinematics)
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
    for g in p.grids:
        ratio = aperture_ratio(p, g)
        if ratio < APERTURE_RATIO_MIN:
            ap.error(f"--n={p.n}: the {g} grid's apertures are {ratio:.2f} x the mean grain "
                     f"diameter; they must be at least {APERTURE_RATIO_MIN:g} x (grains "
                     f"that pass through them, as in 002): give --n >= "
                     f"{min_grains(p, g)}")
    if a.stresses:
        p.stresses = _fem_case.parse_stresses(a.stresses, ap)
    _fem_case.apply_soil_arg(ap, a, p)
    if a.resume and a.out is None:
        ap.error("--resume: give --out, the folder of the run to continue")
    if a.resume and a.overwrite:
        ap.error("--resume and --overwrite: choose one (--resume keeps the finished packings' "
                 "files)")
    p.resume = a.resume
    return p, a.out


def main(argv=None) -> int:
    p, out = parse_args(argv)
    keep = None
    if p.resume:
        keep = resume_keep(out) or [_job_file(p.grids[0], p.seeds[0])]  # (named as missing)
    # (the parameters and each checkpoint's SHA-256 go into the manifest: --resume continues
    # the same run or refuses, rundir.begin_run)
    return run_main("prs_element_002", out, lambda o: run(p, o), keep=keep, params=p,
                    checkpoints=CHECKPOINTS)


if __name__ == "__main__":
    sys.exit(main())
