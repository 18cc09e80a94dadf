"""Speed-accuracy trade of the coupled FEM -> DEM case (cases/prs_element.py; issue 7). Not a
test: one JSON line per run, a Markdown table on stderr, --out FILE.jsonl appends the lines.

    .venv/bin/python bench/coupled_accuracy.py --study mesh      # FEM mesh size, ~3 min
    .venv/bin/python bench/coupled_accuracy.py --study tol       # two-way tolerance, ~3 min
    .venv/bin/python bench/coupled_accuracy.py --study fem-time  # FEM time vs DEM steps, ~1 min
    .venv/bin/python bench/coupled_accuracy.py --study presets   # fast/balanced/accurate, ~10 min

mesh: the FEM of the case (RE and PRS) with the fine mesh size h (footing edge, element
region, layers) in --sizes, the coarse size 20 h; the finest is the reference. Outputs: the
handed-over wall targets of the element region after the footing load (x, y, z, Pa,
compression positive), and their PRS - RE difference (what the case compares). Errors: max
over x, y, z of |value - ref| / max |ref|, for the targets and for the difference.

tol: ONE two-way run (femcoupling.coupling.twoway.two_way) of the RE variant with the DEM
element at the case's smoke size (the FEM on the fine mesh BASE_FINE_SIZE_M, as in fem-time)
and a tight tolerance; the loop is deterministic, so a looser tolerance stops earlier on the
same sequence of iterations: for each tolerance, the iteration it stops at, the cumulative CPU
time, and the error of its handed-over targets against the last iteration. --check reruns one
looser tolerance on its own to confirm the sequence.

fem-time: the one-way case (FEM solved, stresses handed over, DEM element driven to them)
with the DEM element holding each target for 600 and 30 000 steps: the number of FEM solves and
the FEM CPU time must not change with the DEM work (FEM time is spent when the handed-over
boundary changes, not per DEM step).

presets: two-way runs (RE, smoke DEM element) with each preset's FEM mesh and tolerance
(cpp_dem.presets: fem_size_per_element, two_way_tol) against the accurate preset's mesh with
a tolerance of 1e-3.

Cost: CPU seconds of this process (time.process_time; the DEM runs in-process on one
thread).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases"))
sys.path.insert(0, str(ROOT / "bench"))

import prs_element as case  # noqa: E402
from geogrid_dem.studies import prs_element as drv  # noqa: E402
from _report import emit, markdown_table, pct  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


#: The fine FEM mesh size of the studies' base (m): the mesh of the tables in
#: docs/speed_accuracy.md, finer than the case's smoke mesh (0.1 m), which keeps the suite's
#: FEM solves test-sized.
BASE_FINE_SIZE_M = 0.05


def smoke_params(**kw) -> case.Params:
    """The case's smoke element on the fine mesh BASE_FINE_SIZE_M, one thread; ``kw`` on
    top."""
    return dataclasses.replace(case.Params(**case.SMOKE), threads=1,
                               **{"fine_size": BASE_FINE_SIZE_M, **kw})


class Timed:
    """Wraps a callable; counts calls and adds up their CPU time."""

    def __init__(self, fn):
        self.fn, self.calls, self.cpu_s = fn, 0, 0.0

    def __call__(self, *a, **kw):
        c0 = time.process_time()
        try:
            return self.fn(*a, **kw)
        finally:
            self.calls += 1
            self.cpu_s += time.process_time() - c0


def footing_load(p: case.Params):
    return lambda model: model.load_footing(pressure_pa=p.footing_pressure, steps=p.fem_steps)


def fem_handover(p: case.Params, variant: str) -> dict:
    """The FEM of one variant at p's mesh sizes: handed-over targets and cost."""
    from femcoupling.coupling.twoway import one_way

    c0 = time.process_time()
    m = drv.fem_model(p, variant == "PRS")
    c1 = time.process_time()
    ini, fin = one_way(m, regions=["element"], load=footing_load(p))
    c2 = time.process_time()
    return {"cells": int(m.mesh.topology.index_map(m.tdim).size_global),
            "dofs": int(m.V.dofmap.index_map.size_global * m.V.dofmap.index_map_bs),
            "targets_initial_pa": ini["element"].normal_pa.tolist(),
            "targets_final_pa": fin["element"].normal_pa.tolist(),
            "cpu_build_s": c1 - c0, "cpu_load_s": c2 - c1, "cpu_s": c2 - c0}


def rel_err(a, ref) -> float:
    a, ref = np.asarray(a, float), np.asarray(ref, float)
    return float(np.abs(a - ref).max() / np.abs(ref).max())


def mesh_study(sizes: list, out, log) -> list:
    base = case.Params()
    # Warm-up: the first solve of a process compiles the forms (FFCx); not part of any row.
    fem_handover(dataclasses.replace(base, fine_size=max(sizes), mesh_size=20 * max(sizes)), "RE")
    rows = []
    for h in sizes:
        p = dataclasses.replace(base, fine_size=h, mesh_size=20 * h)
        r = {"study": "mesh", "fine_size_m": h, "mesh_size_m": 20 * h}
        for v in ("RE", "PRS"):
            res = fem_handover(p, v)
            r.update({f"{v}_{k}": val for k, val in res.items()})
        r["cpu_s"] = r["RE_cpu_s"] + r["PRS_cpu_s"]
        r["prs_minus_re_pa"] = (np.asarray(r["PRS_targets_final_pa"])
                                - np.asarray(r["RE_targets_final_pa"])).tolist()
        log(f"h = {h} m: {r['RE_cells']} cells, RE final {np.round(r['RE_targets_final_pa'], 1)}"
            f" Pa, PRS-RE {np.round(r['prs_minus_re_pa'], 1)} Pa, {r['cpu_s']:.1f} s CPU")
        rows.append(r)
    ref = rows[int(np.argmin(sizes))]
    for r in rows:
        r["err_RE"] = rel_err(r["RE_targets_final_pa"], ref["RE_targets_final_pa"])
        r["err_PRS"] = rel_err(r["PRS_targets_final_pa"], ref["PRS_targets_final_pa"])
        r["err_prs_minus_re"] = rel_err(r["prs_minus_re_pa"], ref["prs_minus_re_pa"])
        r["cost_vs_reference"] = r["cpu_s"] / ref["cpu_s"]
        emit({"case": "coupled", "knob": "fem_mesh", "value": r["fine_size_m"],
              "err_main": r["err_RE"], **r}, out)
    markdown_table(rows, [
        ("fine h (m)", lambda r: f"{r['fine_size_m']:g}"),
        ("cells", lambda r: str(r["RE_cells"])), ("dofs", lambda r: str(r["RE_dofs"])),
        ("CPU RE+PRS (s)", lambda r: f"{r['cpu_s']:.1f}"),
        ("cost / ref", lambda r: f"{r['cost_vs_reference']:.3f}"),
        ("RE targets after load (kPa)",
         lambda r: ", ".join(f"{x / 1e3:.2f}" for x in r["RE_targets_final_pa"])),
        ("err RE", lambda r: pct(r["err_RE"])), ("err PRS", lambda r: pct(r["err_PRS"])),
        ("PRS − RE (kPa)", lambda r: ", ".join(f"{x / 1e3:.3f}" for x in r["prs_minus_re_pa"])),
        ("err PRS − RE", lambda r: pct(r["err_prs_minus_re"]))])
    return rows


def two_way_run(p: case.Params, tol: float, max_iterations: int, workdir: Path, log) -> dict:
    """The RE two-way loop: convergence, changes, final targets, CPU of FEM and DEM."""
    from femcoupling.coupling.twoway import two_way

    c0 = time.process_time()
    m = drv.fem_model(p, False)
    state0 = m.save_state()
    load = Timed(footing_load(p))
    runner = Timed(drv._Runner(p, workdir, "RE"))
    m.restore_state(state0)
    tw = two_way(m, regions=["element"], load=load, element_runner=runner, tol=tol,
                 max_iterations=max_iterations, log=log)
    return {"converged": tw.converged, "iterations": tw.iterations,
            "changes": [float(c) for c in tw.changes], "cpu_s": time.process_time() - c0,
            "fem_cpu_s": load.cpu_s, "dem_cpu_s": runner.cpu_s, "fem_solves": load.calls,
            "dem_runs": runner.calls,
            "targets_final_pa": tw.targets["element"].normal_pa.tolist()}


def tol_study(tight: float, max_iterations: int, tols: list, check: float | None, out,
              log) -> list:
    """One tight two-way run; what each looser tolerance would have given (module doc)."""
    from femcoupling.coupling import twoway

    p = smoke_params()
    history: list = []  # (targets after FEM solve k, cumulative CPU at that point)
    c0 = time.process_time()
    orig = twoway.fem_to_dem

    def spy(stress):
        t = orig(stress)
        history.append((t.normal_pa.copy(), time.process_time() - c0))
        return t

    twoway.fem_to_dem = spy
    try:
        with tempfile.TemporaryDirectory() as d:
            res = two_way_run(p, tight, max_iterations, Path(d), log)
    finally:
        twoway.fem_to_dem = orig
    # fem_to_dem is called once for the initial state, then once per FEM solve.
    solves = history[1:]
    last = solves[-1][0]
    changes = res["changes"]
    rows = []
    for tol in tols:
        k = next((i for i, c in enumerate(changes) if c < tol), None)
        stop = k if k is not None else len(changes) - 1
        targets, cpu = solves[stop]
        rows.append({"study": "tol", "tol": tol, "stops_at_solve": stop + 1,
                     "converged": k is not None, "cpu_s": cpu,
                     "targets_pa": targets.tolist(),
                     "err_vs_last": rel_err(targets, last),
                     "change_at_stop": changes[stop]})
    ref_cpu = rows[-1]["cpu_s"] if rows else 1.0
    for r in rows:
        r["cost_vs_reference"] = r["cpu_s"] / ref_cpu
        emit({"case": "coupled", "knob": "two_way_tol", "value": r["tol"],
              "err_main": r["err_vs_last"], **r}, out)
    emit({"case": "coupled", "knob": "two_way_run", "value": tight, **res,
          "solve_targets_pa": [s[0].tolist() for s in solves]}, out)
    markdown_table(rows, [
        ("tol", lambda r: f"{r['tol']:g}"),
        ("FEM solves", lambda r: f"{r['stops_at_solve']}" + ("" if r["converged"] else
                                                              " (not converged)")),
        ("change at stop", lambda r: f"{r['change_at_stop']:.3g}"),
        ("CPU (s)", lambda r: f"{r['cpu_s']:.1f}"),
        ("targets (kPa)", lambda r: ", ".join(f"{x / 1e3:.3f}" for x in r["targets_pa"])),
        ("err vs last solve", lambda r: pct(r["err_vs_last"]))])
    log(f"tight run: changes {[f'{c:.3g}' for c in changes]}; FEM {res['fem_solves']} solves "
        f"{res['fem_cpu_s']:.1f} s CPU, DEM {res['dem_runs']} runs {res['dem_cpu_s']:.1f} s CPU")
    if check is not None:
        with tempfile.TemporaryDirectory() as d:
            alone = two_way_run(p, check, max_iterations, Path(d), log)
        n = alone["iterations"]
        same = (alone["changes"] == changes[:n]
                and np.array_equal(alone["targets_final_pa"], solves[n - 1][0]))
        emit({"case": "coupled", "knob": "two_way_check", "value": check,
              "iterations": n, "changes": alone["changes"], "same_sequence": bool(same)}, out)
        log(f"check: tol {check} on its own stops after {n} solves; same sequence and targets "
            f"as the tight run: {same}")
    return rows


def fem_time_study(holds: list, out, log) -> list:
    """One-way case with the DEM element held for each of ``holds`` steps (module doc)."""
    from femcoupling.coupling.twoway import one_way

    rows = []
    fem_handover(smoke_params(), "RE")  # warm-up: the form compilation is not per solve
    for hold in holds:
        p = smoke_params(hold_steps=hold)
        c0 = time.process_time()
        m = drv.fem_model(p, False)
        load = Timed(footing_load(p))
        ini, fin = one_way(m, regions=["element"], load=load)
        c_fem = time.process_time() - c0
        c1 = time.process_time()
        with tempfile.TemporaryDirectory() as d:
            e = case.run_element(p, [ini["element"].normal_pa, fin["element"].normal_pa],
                                 prestressed=False, label="element", out=Path(d))
        c_dem = time.process_time() - c1
        r = {"study": "fem-time", "hold_steps": hold, "fem_solves": load.calls,
             "fem_cpu_s": c_fem, "fem_load_cpu_s": load.cpu_s, "dem_cpu_s": c_dem,
             "dem_steps": int(sum(e["servo_steps"]) + len(e["servo_steps"]) * hold)}
        log(f"hold {hold}: FEM {r['fem_solves']} solve(s) {c_fem:.1f} s CPU, DEM "
            f"{r['dem_steps']} steps {c_dem:.1f} s CPU")
        rows.append(r)
    for r in rows:
        r["fem_cpu_vs_first"] = r["fem_cpu_s"] / rows[0]["fem_cpu_s"]
        r["dem_cpu_vs_first"] = r["dem_cpu_s"] / rows[0]["dem_cpu_s"]
        emit({"case": "coupled", "knob": "fem_time", "value": r["hold_steps"], **r}, out)
    markdown_table(rows, [
        ("DEM hold steps", lambda r: str(r["hold_steps"])),
        ("DEM steps", lambda r: str(r["dem_steps"])),
        ("DEM CPU (s)", lambda r: f"{r['dem_cpu_s']:.1f}"),
        ("FEM solves", lambda r: str(r["fem_solves"])),
        ("FEM CPU (s)", lambda r: f"{r['fem_cpu_s']:.1f}"),
        ("FEM CPU / first", lambda r: f"{r['fem_cpu_vs_first']:.2f}"),
        ("DEM CPU / first", lambda r: f"{r['dem_cpu_vs_first']:.2f}")])
    return rows


def presets_study(out, log) -> list:
    """Two-way RE runs with each preset's FEM mesh and tolerance (the DEM element at the smoke
    size, unchanged) against the accurate mesh with a tight tolerance."""
    from cpp_dem.presets import PRESETS

    base = smoke_params(max_iterations=10)
    ref_p = case.apply_coupling_preset(base, "accurate")
    runs = [("reference", dataclasses.replace(ref_p, two_way_tol=1e-3))]
    runs += [(name, case.apply_coupling_preset(base, name)) for name in PRESETS]
    rows = []
    for name, p in runs:
        with tempfile.TemporaryDirectory() as d:
            res = two_way_run(p, p.two_way_tol, p.max_iterations, Path(d), log)
        rows.append({"study": "presets", "preset": name, "fine_size_m": p.fine_size,
                     "two_way_tol": p.two_way_tol, **res})
        log(f"{name}: {res['fem_solves']} FEM solves, {res['cpu_s']:.1f} s CPU, targets "
            f"{np.round(np.asarray(res['targets_final_pa']) / 1e3, 3)} kPa")
    ref = rows[0]
    for r in rows:
        r["err_vs_reference"] = rel_err(r["targets_final_pa"], ref["targets_final_pa"])
        r["cost_vs_reference"] = r["cpu_s"] / ref["cpu_s"]
        emit({"case": "coupled", "knob": "preset", "value": r["preset"],
              "err_main": r["err_vs_reference"], **r}, out)
    markdown_table(rows, [
        ("preset", lambda r: r["preset"]), ("fine h (m)", lambda r: f"{r['fine_size_m']:g}"),
        ("tol", lambda r: f"{r['two_way_tol']:g}"),
        ("FEM solves", lambda r: str(r["fem_solves"]) + ("" if r["converged"] else " (NOT "
                                                           "converged)")),
        ("CPU (s)", lambda r: f"{r['cpu_s']:.1f}"),
        ("FEM / DEM CPU (s)", lambda r: f"{r['fem_cpu_s']:.1f} / {r['dem_cpu_s']:.1f}"),
        ("cost / ref", lambda r: f"{r['cost_vs_reference']:.2f}"),
        ("targets (kPa)",
         lambda r: ", ".join(f"{x / 1e3:.3f}" for x in r["targets_final_pa"])),
        ("err vs reference", lambda r: pct(r["err_vs_reference"]))])
    return rows


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="append", description=__doc__.split("\n\n")[0])
    ap.add_argument("--study", nargs="+", choices=("mesh", "tol", "fem-time", "presets"),
                    default=["mesh", "tol", "fem-time"])
    ap.add_argument("--sizes", type=float, nargs="+", default=[0.2, 0.1, 0.05, 0.025, 0.0125],
                    help="fine FEM mesh sizes h, m (> 0; the smallest is the reference)")
    ap.add_argument("--tight", type=float, default=1e-3, help="two-way tolerance of the run")
    ap.add_argument("--max-iterations", type=int, default=8, help="FEM solves at most, >= 2")
    ap.add_argument("--tols", type=float, nargs="+", default=[0.2, 0.1, 0.05, 0.02, 0.01,
                                                              0.005, 0.002, 0.001])
    ap.add_argument("--check", type=float, default=None,
                    help="rerun this looser tolerance alone to confirm the sequence")
    ap.add_argument("--holds", type=int, nargs="+", default=[600, 30000],
                    help="DEM hold steps of the fem-time study")
    ap.add_argument("--out", type=Path, default=None, help="append the JSON lines here")
    a = ap.parse_args(argv)
    for name, vals in (("--sizes", a.sizes), ("--tols", a.tols)):
        bad = [v for v in vals if not v > 0]
        if bad:
            ap.error(f"{name}: {bad[0]} must be > 0")
    if not a.tight > 0:
        ap.error(f"--tight={a.tight}: must be > 0")
    if a.max_iterations < 2:
        ap.error(f"--max-iterations={a.max_iterations}: must be >= 2")
    if any(h < 1 for h in a.holds):
        ap.error(f"--holds: {min(a.holds)} must be >= 1")

    def log(msg: str) -> None:
        print(f"[coupled_accuracy] {msg}", file=sys.stderr, flush=True)

    if "mesh" in a.study:
        mesh_study(a.sizes, a.out, log)
    if "fem-time" in a.study:
        fem_time_study(a.holds, a.out, log)
    if "tol" in a.study:
        tol_study(a.tight, a.max_iterations, sorted(a.tols, reverse=True), a.check, a.out, log)
    if "presets" in a.study:
        presets_study(a.out, log)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
