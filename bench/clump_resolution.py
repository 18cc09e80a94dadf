#!/usr/bin/env python3
"""Clump resolution: the 002 element, DEM only, with the shipped gravel grains filled with 6, 12
and 24 spheres (``--grains clumps:gravel@N``, docs/clumps.md "Clump resolution"). Not a test:
prints one JSON line per resolution, then one with all of them, and a Markdown table on stderr.

Each run is the prs_element_002 case's smoke element (``Params(**SMOKE)``: woven-detailed grid,
Hertz–Mindlin grains, RE) with ``grains = "clumps:gravel@N"`` and one thread, driven to the
given wall stresses (default 20, 20, 40 kPa) by ``cpp_dem.elements.box.run_element``; the same
seed gives the same equivalent diameters at every resolution (each clump is placed at its
template's volume-equivalent diameter), so only the grains' shapes' resolution changes.

Per resolution: wall time (s), grains and spheres (the grains' ``num_grains x N``; the summary's
``num_spheres`` counts the grid's spheres too), porosity, final wall stresses (Pa), whether the
servo converged, and the grid measures of the element summary (``interaction``: grid contacts,
grains between strings and in apertures, waviness, member forces; ``grid_force_*``).

    .venv/bin/python bench/clump_resolution.py                     # 6, 12, 24; 150 grains
    .venv/bin/python bench/clump_resolution.py --n 60 --resolutions 6 --out /tmp/cr
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one thread (set before the core loads OpenMP)

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _report import markdown_table  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def _log(msg: str) -> None:
    print(f"[element] {msg}", file=sys.stderr, flush=True)


def run_one(n_spheres: int, args, fill_s: float) -> dict:
    """The element at one resolution; its row (plain numbers). fill_s: the time the templates
    took to fill (s; main fills them all first, to check the resolutions)."""
    from geogrid_dem.cases import prs_element_002 as c
    from cpp_dem.build.clump_mesh import (mesh_mass_properties, shipped_mesh, shipped_templates,
                                          templates_from_spec)
    from cpp_dem.elements.box import run_element

    p = c.Params(**c.SMOKE)
    p.grains = f"clumps:gravel@{n_spheres}"
    p.threads = 1
    p.n = args.n
    p.seed = args.seed
    templates = templates_from_spec(p.grains)  # filled in main already (cached)
    deq = []
    for grain, t in zip(shipped_templates(), templates):  # gravel_a .. gravel_d, in order
        mp = mesh_mass_properties(*shipped_mesh(grain))
        deq.append(t.equivalent_diameter / (6.0 * mp.volume / np.pi) ** (1.0 / 3.0))
    t1 = time.perf_counter()
    s = run_element(p, [np.array(args.stresses)], prestressed=False, label=f"res{n_spheres}",
                    out=Path(args.out), log=_log)
    wall = time.perf_counter() - t1
    return {
        "bench": "clump_resolution", "resolution": n_spheres, "grains": p.grains,
        "n_requested": p.n, "seed": p.seed, "geogrid": p.geogrid, "grain_law": p.grain_law,
        "wall_time_s": wall, "fill_time_s": fill_s,
        "preparation_wall_time_s": s["preparation_wall_time_s"],
        "num_grains": s["num_grains"],
        "grain_spheres": s["num_grains"] * n_spheres,
        "num_spheres": s["num_spheres"],
        "template_deq_over_mesh": [round(x, 4) for x in deq],
        "porosity_final": s["porosity_final"],
        "targets_pa": s["targets_pa"][-1],
        "stress_final_pa": s["stress_final_pa"],
        "converged": s["converged"],
        "servo_steps": s["servo_steps"],
        "interaction": s.get("interaction"),
        **{k: v for k, v in s.items() if k.startswith("grid_force_")},
    }


def _resolutions(text: str) -> list[int]:
    try:
        out = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: must be comma-separated integers, e.g. "
                                         "6,12,24") from None
    if not out:
        raise argparse.ArgumentTypeError(f"{text!r}: no resolution given, e.g. 6,12,24")
    if any(x < 1 for x in out):
        raise argparse.ArgumentTypeError(f"{text!r}: each resolution must be >= 1")
    return out


def main(argv=None) -> int:
    from geogrid_dem.cases import prs_element_002 as c

    ap = _cli.BenchParser(out="folder",
        prog="bench/clump_resolution.py",
        description="The 002 element (DEM only, smoke settings, 1 thread) with the gravel grains "
                    "filled with N spheres each (clumps:gravel@N): wall time, grains, spheres, "
                    "porosity, final wall stresses and grid measures per resolution, as JSON "
                    "lines on stdout (a table on stderr).")
    ap.add_argument("--resolutions", type=_resolutions, default=[6, 12, 24],
                    help="spheres per grain, comma-separated (default 6,12,24; each in "
                         "[1, 256]; 24 is the shipped templates)")
    ap.add_argument("--n", type=int, default=c.SMOKE["n"],
                    help=f"grains before the grid's layer is cleared (default {c.SMOKE['n']}, "
                         "the case's smoke)")
    ap.add_argument("--seed", type=int, default=c.Params().seed, help="RNG seed (default "
                    f"{c.Params().seed})")
    ap.add_argument("--stresses", type=float, nargs=3, default=[20e3, 20e3, 40e3],
                    metavar=("SXX", "SYY", "SZZ"),
                    help="wall stress targets, Pa, compression positive (default 20e3 20e3 40e3)")
    ap.add_argument("--out", default=None,
                    help="folder for the elements' files (h5, csv, vtk; default a new "
                         "temporary folder) and clump_resolution.json")
    a = ap.parse_args(argv)
    from cpp_dem._core import ParameterError
    from cpp_dem.build.clump_mesh import templates_from_spec

    fill_s = {}
    for n in a.resolutions:  # fills (and so checks) every resolution before the first run
        t0 = time.perf_counter()
        try:
            templates_from_spec(f"clumps:gravel@{n}")
        except ParameterError as e:
            ap.error(f"--resolutions: {e}")
        fill_s[n] = time.perf_counter() - t0
    if a.n < 1:
        ap.error(f"--n={a.n}: must be >= 1")
    a.out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="clump_resolution_"))
    a.out.mkdir(parents=True, exist_ok=True)
    print(f"[clump_resolution] output in {a.out}", file=sys.stderr, flush=True)
    rows = []
    for n in a.resolutions:
        row = run_one(n, a, fill_s[n])
        rows.append(row)
        print(json.dumps(row, default=float), flush=True)
    final = {"bench": "clump_resolution", "summary": True, "n_requested": a.n, "seed": a.seed,
             "stresses_pa": a.stresses, "rows": rows}
    print(json.dumps(final, default=float), flush=True)
    (a.out / "clump_resolution.json").write_text(json.dumps(final, indent=1, default=float))

    def kpa(r):
        return ", ".join(f"{x / 1e3:.1f}" for x in r["stress_final_pa"])

    def contacts(r):
        c_ = (r.get("interaction") or {}).get("contacts") or {}
        return f"{c_.get('contacts', '-')} / {c_.get('grains_touching', '-')}"

    markdown_table(rows, [
        ("spheres / grain", lambda r: f"{r['resolution']}"),
        ("grains", lambda r: f"{r['num_grains']}"),
        ("grain spheres", lambda r: f"{r['grain_spheres']}"),
        ("wall time (s)", lambda r: f"{r['wall_time_s']:.1f}"),
        ("porosity", lambda r: f"{r['porosity_final']:.3f}"),
        ("final wall stresses (kPa)", lambda r: kpa(r)),
        ("converged", lambda r: f"{all(r['converged'])}"),
        ("grid contacts / grains touching", contacts),
        ("grid force long. mean (N)", lambda r: f"{r.get('grid_force_longitudinal_mean_n', float('nan')):.4g}"),
    ])
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
