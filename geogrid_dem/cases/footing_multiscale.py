#!/usr/bin/env python3
"""A strip footing on geogrid-reinforced soil, multiscale: a DEM element at every cell of the
zone under the footing, Drucker–Prager calibrated on the same grains around it.

Plane strain, the half next to the symmetry plane (z up); with --dim 3 a square footing in
3D, the quarter next to its two planes of symmetry. Three variants on the same seeds:
unreinforced, RE (one geogrid layer, an elastic band of stiffness J) and PRS (the same layer
prestressed by T_p). Each is seated to --seat with the fitted Drucker–Prager everywhere;
then every soil cell of the b x b zone under the footing takes its own dense periodic DEM
element at its cell's stress, and every cell of the layer's band in the zone a reinforced
RVE (the woven sheet and grains, the sheet at the band's tension; --band-grains), all on
--workers Dask workers, and the footing is pushed to
--levels equal pressure rises up to --pressure. The same body with the fitted
Drucker–Prager everywhere is run for each variant too. This is the prestressed-element
study's question at the scale of the structure: does prestress improve the
load–settlement behaviour? (geogrid_dem.studies.footing_multiscale;
docs/studies/footing_multiscale.md.)

Outputs in --out: load_settlement.csv (a row per level of every run, appended as it
runs), summary.json (settlement per variant and level: seed mean, sd, each seed, the
Drucker–Prager body; paired differences between variants over the seeds with their
standard errors; the coupling statuses; the cost), calibration.json,
load_settlement.png, fem_<variant>_seed<s>.xdmf (the FEM state at the takeover and at
each level: ParaView), zone_elements_<variant>_seed<s>.h5 (each element per load step).
SI units; pressures and settlements compression / downward positive. Interrupted (Ctrl-C,
SIGTERM), a run leaves summary.json marked "interrupted" with the levels each run reached
and load_settlement.png of them.

The exit status is 0 when every load step of every run converged, else the coupling's
(3: stopped within the elements' scatter; femcoupling.coupling.status).
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace

from geogrid_dem.cases import describe
from geogrid_dem.options import (MAX_SEED, case_parser, check_cap, distinct, given_options,
                                 parse_checked, refuse_unused, warn_below)
from geogrid_dem.rundir import on_interrupt, run_main

#: The test-sized run: a coarse mesh (14-20 zone cells), 80 grains an element, one load
#: level, two seeds.
SMOKE = dict(width=2.0, height=1.5, mesh_size=0.5, fine_size=0.35, cell_grains=80, levels=1,
             fit_points=4, pressure_pa=40e3, calibration_elements=8)
#: The smoke in 3D (--dim 3), over SMOKE: coarser zone cells and smaller elements (a zone
#: of 0.35 m cells has 93 tetrahedra unreinforced, 140 with the layer).
SMOKE_3D = dict(fine_size=0.5, cell_grains=50)


def log(msg: str) -> None:
    print(f"[footing_multiscale] {msg}", flush=True)


def levels_so_far(out) -> dict:
    """The levels every run reached, from load_settlement.csv (a row per level, flushed as it
    is reached): "<variant> <model>[ seed <s>]" -> {"pressure_pa": [...], "settlement_m":
    [...]} in the order reached."""
    import csv

    runs: dict = {}
    try:
        with open(out / "load_settlement.csv", newline="") as fh:
            for r in csv.DictReader(fh):
                name = f"{r['variant']} {r['model']}" + (f" seed {r['seed']}" if r["seed"] else "")
                run = runs.setdefault(name, {"pressure_pa": [], "settlement_m": []})
                run["pressure_pa"].append(float(r["pressure_pa"]))
                run["settlement_m"].append(float(r["settlement_m"]))
    except (OSError, KeyError, ValueError):
        pass
    return runs


def interrupted_report(p, out) -> None:
    """What an interrupted run reports (rundir.on_interrupt): summary.json with what finished
    (the calibration; per run, the levels it reached, from load_settlement.csv) and
    load_settlement.png of those levels, one curve a run (the seed means need every run)."""
    def summary() -> dict:
        runs = levels_so_far(out)
        return {"finished": (["calibration"] if (out / "calibration.json").is_file() else [])
                + [f"{k}: {len(r['pressure_pa'])} of {p.levels} levels" for k, r in runs.items()],
                "pressures_pa": p.pressures_pa, "levels_reached": runs}

    def figures() -> None:
        runs = levels_so_far(out)
        if not runs:
            return
        import matplotlib
        import numpy as np

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from cpp_dem.io.figures import save_figure

        colours = dict(zip(("unreinforced", "RE", "PRS"), ("k", "tab:blue", "tab:red")))
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        for name, r in runs.items():
            dp = "drucker_prager" in name
            ax.plot(1e3 * np.array(r["settlement_m"]), np.array(r["pressure_pa"]) / 1e3,
                    color=colours.get(name.split()[0], "C0"), ls="--" if dp else "-",
                    marker=None if dp else "o", label=name)
        ax.set_xlabel("footing settlement (mm)")
        ax.set_ylabel("footing pressure (kPa)")
        ax.invert_yaxis()
        ax.legend(fontsize=7)
        ax.set_title("Strip footing: load-settlement (interrupted: the levels reached)")
        fig.tight_layout()
        save_figure(fig, out / "load_settlement.png")
        plt.close(fig)

    on_interrupt(out, summary=summary, figures=figures)


def build_parser():
    """The case's parser: the shared options (geogrid_dem.options) and its own."""
    from geogrid_dem.studies.footing_multiscale import (BAND_TANGENTS, BUDGET_PARTS, VARIANTS,
                                                        FootingParams)

    d = FootingParams()
    ap = case_parser("footing-multiscale", describe("footing-multiscale",
                                                    __doc__.split("\n\n")[0]),
                     smoke=f"coarse mesh, {SMOKE['cell_grains']} grains an element, "
                           f"{SMOKE['levels']} level to {SMOKE['pressure_pa'] / 1e3:g} kPa, "
                           "2 seeds", seed=1, threads=1)
    ap.add_argument("--seeds", type=int, default=None,
                    help="runs per variant, the zone's elements from seeds --seed, --seed + "
                         "1, ...; 2 or more give the seed scatter and paired differences "
                         "(default 3, smoke 2)")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help=f"comma-separated selection of {', '.join(VARIANTS)}")
    ap.add_argument("--pressure", type=float, default=None,
                    help=f"largest footing pressure, Pa (default {d.pressure_pa:g}, smoke "
                         f"{SMOKE['pressure_pa']:g})")
    ap.add_argument("--seat", type=float, default=d.seat_pa,
                    help="seating pressure before the DEM zone takes over, Pa")
    ap.add_argument("--levels", type=int, default=None,
                    help=f"equal pressure rises from --seat to --pressure (default {d.levels}, "
                         f"smoke {SMOKE['levels']})")
    ap.add_argument("--footing-half-width", type=float, default=d.footing_b,
                    help="footing half width b, m; the DEM zone is b x b under it")
    ap.add_argument("--layer-depth", type=float, default=d.layer_depth,
                    help="the geogrid layer's depth, m")
    ap.add_argument("--layer-thickness", type=float, default=d.layer_thickness,
                    help="the geogrid layer's band thickness t in the FEM, m; with "
                         "--band-grains, each band RVE's stress is its grains' plus its "
                         "sheet's force per metre over t")
    ap.add_argument("--grid-stiffness", type=float, default=d.grid_stiffness,
                    help="the geogrid's axial stiffness J, N/m (default: the prestressed-"
                         "element study's woven grid)")
    ap.add_argument("--prestress", type=float, default=d.prestress,
                    help="PRS prestress T_p, N/m")
    ap.add_argument("--fine-size", type=float, default=None,
                    help=f"FEM cell size in the zone and along the layer, m (default "
                         f"{d.fine_size:g}, smoke {SMOKE['fine_size']:g})")
    ap.add_argument("--cell-grains", type=int, default=None,
                    help=f"grains of each zone cell's element (default {d.cell_grains}, smoke "
                         f"{SMOKE['cell_grains']}; at least 50)")
    ap.add_argument("--band-grains", type=int, default=None,
                    help=f"grains of the reinforced RVE (woven sheet and grains) of each of "
                         f"the layer's cells in the zone (default {d.band_grains}; 0: those "
                         "cells stay the FEM's elastic band)")
    ap.add_argument("--band-tangent", choices=BAND_TANGENTS, default=d.band_tangent,
                    help="the band RVEs' tangent: their contact network with the sheet's "
                         "bonds (network), the same with sliding contacts taken as stuck "
                         "(network-elastic), or forward differences of the plane's "
                         "components, three more runs of each RVE a trial (fd-forward)")
    ap.add_argument("--noise-ceiling", type=float, default=d.noise_ceiling,
                    help="Newton: a DEM zone step is accepted within the elements' noise only "
                         "up to this fraction of the zone's own internal force")
    ap.add_argument("--resolve-mm", type=float, default=None,
                    help="the smallest settlement difference the run is to resolve, mm: the "
                         "zone's ceiling becomes resolve / (4 x the continuum's settlement), "
                         "at most --noise-ceiling (default: the ceiling is --noise-ceiling, "
                         "and summary.json's acceptance says what it resolves)")
    ap.add_argument("--calibration-elements", type=int, default=None,
                    help="elements of the zone's grains the Drucker-Prager is fitted on, their "
                         f"mean (default {d.calibration_elements}, smoke "
                         f"{SMOKE['calibration_elements']}; seeds from --seed on)")
    ap.add_argument("--budget", default="",
                    help="the error budget's parts to measure, each by a rerun of every "
                         "variant with one thing changed: a comma-separated selection of "
                         + "; ".join(f"{k} ({v})" for k, v in BUDGET_PARTS.items())
                         + "; or all. Each difference is resolved only above its whole "
                           "budget (the seeds' part is always measured)")
    ap.add_argument("--workers", type=int, default=d.workers,
                    help="Dask workers of the zone's elements (a LocalCluster)")
    ap.add_argument("--dim", type=int, choices=(2, 3), default=d.dim,
                    help="2: a strip footing in plane strain; 3: a square footing 2b x 2b in "
                         "3D, a quarter of it modelled (the body as wide in y as in x, the "
                         f"zone a cube of edge b; smoke: --fine-size {SMOKE_3D['fine_size']:g}"
                         f", --cell-grains {SMOKE_3D['cell_grains']})")
    return ap


#: The flags that set a FootingParams field one to one: flag -> field.
FLAGS = {"--pressure": "pressure_pa", "--seat": "seat_pa", "--levels": "levels",
         "--footing-half-width": "footing_b", "--layer-depth": "layer_depth",
         "--layer-thickness": "layer_thickness",
         "--grid-stiffness": "grid_stiffness", "--prestress": "prestress",
         "--fine-size": "fine_size", "--cell-grains": "cell_grains",
         "--band-grains": "band_grains", "--band-tangent": "band_tangent",
         "--workers": "workers", "--dim": "dim", "--noise-ceiling": "noise_ceiling",
         "--calibration-elements": "calibration_elements"}


def parse_args(argv=None):
    from geogrid_dem.studies.footing_multiscale import BUDGET_PARTS, VARIANTS, FootingParams

    ap = build_parser()
    a = parse_checked(ap, argv)
    given = given_options(ap, argv)
    p = FootingParams(**SMOKE) if a.smoke else FootingParams()
    if a.smoke and a.dim == 3:
        p = replace(p, **SMOKE_3D)
    seeds = a.seeds if a.seeds is not None else (2 if a.smoke else 3)
    if seeds < 1:
        ap.error(f"--seeds={seeds}: must be >= 1")
    check_cap(ap, a, "--seeds", seeds, seeds, "seeds", "seeds (runs per variant)")
    if a.seed < 0:
        ap.error(f"--seed={a.seed}: must be >= 0")
    if a.seed + seeds - 1 > MAX_SEED:
        ap.error(f"--seed={a.seed} with --seeds={seeds}: the seeds {a.seed} to "
                 f"{a.seed + seeds - 1} pass {MAX_SEED} (2**63 - 1: a run records its seed as "
                 "a 64-bit integer)")
    if a.levels is not None:
        # (each level is a Newton solve of the FEM with the DEM zone; the levels' pressures
        # are made before the cluster starts)
        check_cap(ap, a, "--levels", a.levels, a.levels, "load levels")
    variants = tuple(v.strip() for v in a.variants.split(",") if v.strip())
    bad = [v for v in variants if v not in VARIANTS]
    if bad or not variants:
        ap.error(f"--variants={a.variants!r}: a comma-separated selection of "
                 f"{', '.join(VARIANTS)}")
    distinct(ap, "--variants", repr(a.variants), variants)
    if a.calibration_elements is not None:
        check_cap(ap, a, "--calibration-elements", a.calibration_elements,
                  a.calibration_elements, "seeds", "element seeds of the calibration")
    for flag in ("--cell-grains", "--band-grains"):
        v = getattr(a, flag[2:].replace("-", "_"))
        if v is not None:
            check_cap(ap, a, flag, v, v, "grains", "grains an element")
    # options that would have no effect given the others (docs/cli.md)
    if not {"RE", "PRS"} & set(variants):
        for dest in ("grid_stiffness", "layer_depth", "layer_thickness", "band_tangent"):
            refuse_unused(ap, a, given, dest, f"without a reinforced variant (--variants "
                          f"{','.join(variants)}: no geogrid layer)", "add RE or PRS")
    if "PRS" not in variants:
        refuse_unused(ap, a, given, "prestress", f"without the PRS variant (--variants "
                      f"{','.join(variants)})", "add PRS")
    if not (a.band_grains if a.band_grains is not None else p.band_grains):
        refuse_unused(ap, a, given, "band_tangent", "without band RVEs (--band-grains 0: the "
                      "layer's cells stay the FEM's elastic band)", "give --band-grains N")
    budget = tuple(BUDGET_PARTS) if a.budget.strip() == "all" else tuple(
        b.strip() for b in a.budget.split(",") if b.strip())
    if any(b not in BUDGET_PARTS for b in budget):
        ap.error(f"--budget={a.budget!r}: a comma-separated selection of "
                 f"{', '.join(BUDGET_PARTS)}, or all")
    distinct(ap, "--budget", repr(a.budget), budget)
    p = replace(p, seeds=tuple(range(a.seed, a.seed + seeds)), variants=variants, budget=budget)
    for flag, field in FLAGS.items():  # (None: the smoke's or the full run's default)
        v = getattr(a, flag[2:].replace("-", "_"))
        if v is not None:
            p = replace(p, **{field: v})
    if a.resolve_mm is not None:
        if not (math.isfinite(a.resolve_mm) and a.resolve_mm > 0):
            ap.error(f"--resolve-mm={a.resolve_mm}: a settlement difference > 0, mm")
        p = replace(p, resolve_m=a.resolve_mm / 1e3)
    from femcoupling import FemInputError

    try:
        p.check()
    except FemInputError as e:
        field = str(e).split("=", 1)[0]
        flag = next((f for f, name in FLAGS.items() if name == field), field)
        ap.error(f"{flag}: {e}")
    warn_below("--pressure", p.pressure_pa, 1e3, "Pa",
               f"kPa given as Pa? {p.pressure_pa:g} kPa is --pressure {p.pressure_pa * 1e3:g}")
    return replace(p, threads=a.threads), a.out


def main(argv=None) -> int:
    from cpp_dem import apply_threads
    from cpp_dem.progress import Progress
    from geogrid_dem.studies.footing_multiscale import run

    p, out = parse_args(argv)
    done: dict = {}

    def work(o):
        apply_threads(p.threads)
        interrupted_report(p, o)
        bar = Progress("footing_multiscale")
        done["summary"] = run(p, o, log, lambda f, detail: bar.update(f, detail))
        s = done["summary"]
        def mm(xs, nd):
            return [None if x is None else round(1e3 * x, nd) for x in xs]

        for v, pr in s["settlement_m"].items():
            log(f"{v}: settlement at {[round(x / 1e3, 1) for x in s['pressures_pa']]} kPa: "
                f"{mm(pr, 3)} mm (seed mean)")
        for k, d in s["paired_settlement_differences"].items():
            log(f"{k}: {mm(d['mean_m'], 4)} mm +- {mm(d['se_m'], 4)} (SE over "
                f"{d['seeds']} seeds)")

    status = run_main("footing_multiscale", out, work)
    c = done.get("summary", {}).get("coupling")
    if status != 0 or c is None or c["status"] == "converged":
        return status
    print("[footing_multiscale] the coupling did not converge at every step: "
          + ", ".join(f"{v} {st}" for v, st in c["variants"].items())
          + f" (exit status {c['exit_code']}; the statuses per step are in summary.json)",
          file=sys.stderr, flush=True)
    return c["exit_code"]


if __name__ == "__main__":
    sys.exit(main())
