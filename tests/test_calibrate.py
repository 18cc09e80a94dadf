"""Calibration of E, nu and phi of the triaxial case (001 §6.1, Table 6.1): the misfit, the
Nelder-Mead wrapper around scipy.optimize.minimize, and a tiny grid + optimiser that recovers a
synthetic truth."""

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from geogrid_dem.calibrate import (Runner, TABLE_6_1, misfit, nelder_mead, rounded,
                                   scaling)

ROOT = Path(__file__).resolve().parents[1]


def _curve(e_max=0.04, n=41, q0=60e3, v0=-0.01):
    ea = np.linspace(0.0, e_max, n)
    return {"axial_strain": ea, "deviatoric_stress": q0 * np.tanh(ea / 0.01),
            "volumetric_strain": 0.004 * np.sin(ea / e_max * np.pi) + v0 * ea / e_max}


def test_misfit_is_zero_for_identical_curves_and_grows_with_a_perturbation():
    ref = _curve()
    assert misfit(ref, ref) == 0.0
    # Same curve, other sampling (the common eps_a grid): still (almost) zero.
    assert misfit(_curve(n=401), ref) < 5e-3
    last = 0.0
    for eps in (0.01, 0.05, 0.2):
        m = misfit(_curve(q0=60e3 * (1 + eps)), ref)
        assert m > last
        last = m
    # A 10 % larger q alone: M = sqrt(0.5) * 0.1 * rms(q)/max(q) (the formula, by hand).
    q = ref["deviatoric_stress"]
    e = np.linspace(0, 0.04, 50)
    qi = np.interp(e, ref["axial_strain"], q)
    expect = math.sqrt(0.5 * np.mean((0.1 * qi) ** 2) / qi.max() ** 2)
    assert math.isclose(misfit(_curve(q0=66e3), ref), expect, rel_tol=1e-9)
    # eps_v counts too, and the weight moves it.
    other_v = {**ref, "volumetric_strain": ref["volumetric_strain"] * 1.3}
    assert misfit(other_v, ref) > 0.05 and misfit(other_v, ref, w_q=1.0) == 0.0
    # No strain range in common: infinite.
    late = {**ref, "axial_strain": ref["axial_strain"] + 1.0}
    assert misfit(late, ref) == math.inf


def test_nelder_mead_is_deterministic_and_finds_a_bounded_minimum():
    target = np.array([0.3, 0.7, 0.55])
    f = lambda u: float(np.sum((u - target) ** 2))  # noqa: E731
    a = nelder_mead(f, [0.9, 0.1, 0.9], maxfev=200, xatol=1e-4, fatol=1e-10)
    b = nelder_mead(f, [0.9, 0.1, 0.9], maxfev=200, xatol=1e-4, fatol=1e-10)
    assert np.allclose(a["x"], target, atol=1e-3) and a["reason"] == "converged"
    assert [h[1] for h in a["history"]] == [h[1] for h in b["history"]]
    # The minimum outside the box: found on its face, never left.
    c = nelder_mead(lambda u: float(np.sum((u - 1.4) ** 2)), [0.2, 0.2, 0.2], maxfev=200)
    assert np.all(c["x"] <= 1.0) and np.allclose(c["x"], 1.0, atol=0.02)
    assert all(np.all((0 <= h[0]) & (h[0] <= 1)) for h in c["history"])


def test_the_wrapper_finds_a_bowl_minimum_in_the_scaled_box_honours_maxfev_and_reuses_points():
    """A quadratic bowl in the scaled (log10 E, nu, phi) box of the calibration file's grid,
    minimum at (4200 kPa, 0.31, 31.5 deg), through the same rounding (one point, one folder)
    as a calibration: found to within one rounding step (100 Pa, 1e-4, 1e-3 deg); maxfev is
    a hard limit; a point is evaluated once, and a second search on the same cache evaluates
    nothing."""
    grid = {"young": [2500e3, 5000e3], "poisson": [0.25, 0.5], "phi": [28.0, 34.0]}
    to_p, to_u = scaling(grid)
    truth = (4200e3, 0.31, 31.5)
    tu = to_u(truth)
    calls, batches = [], []

    def f(u):  # the bowl, evaluated at the rounded point as a case run would be
        calls.append(to_p(u))
        return float(np.sum((to_u(to_p(u)) - tu) ** 2))

    def batch(us):
        batches.append(len(us))
        return [f(u) for u in us]

    start = to_u((2500e3, 0.5, 28.0))  # the grid corner farthest from the truth
    cache = {}
    r = nelder_mead(f, start, step=0.15, maxfev=400, xatol=1e-4, fatol=1e-9, batch=batch,
                    key=to_p, cache=cache)
    e, nu, phi = to_p(r["x"])
    assert r["reason"] == "converged"
    assert abs(e - truth[0]) <= 100.0 and abs(nu - truth[1]) <= 1e-4 + 1e-12
    assert abs(phi - truth[2]) <= 1e-3 + 1e-12
    assert batches[0] == 4  # the initial simplex in one batch (in parallel on Dask)
    # Each rounded point evaluated once: the calls are the distinct points, fewer than
    # SciPy's evaluations (it asks again for points the rounding maps onto one).
    assert len(calls) == len(set(calls)) == r["new"] == len(cache) < r["nfev"]
    assert r["nfev"] == len(r["history"]) <= 400 + 4
    # The same search on the filled cache (a rerun after Ctrl-C): the same path, no call.
    n_calls = len(calls)
    again = nelder_mead(f, start, step=0.15, maxfev=400, xatol=1e-4, fatol=1e-9, batch=batch,
                        key=to_p, cache=cache)
    assert len(calls) == n_calls and again["new"] == 0
    assert [h[1] for h in again["history"]] == [h[1] for h in r["history"]]
    assert np.array_equal(again["x"], r["x"])
    # maxfev counts the evaluations after the initial simplex (4 points here), never more.
    for m in (1, 2, 3, 7, 15):
        calls.clear()
        c = nelder_mead(f, start, step=0.15, maxfev=m, xatol=1e-4, fatol=1e-9, key=to_p)
        assert c["nfev"] == len(c["history"]) == m + 4 and c["reason"] == "maxfev"
        assert len(calls) <= m + 4
        # The best of every evaluation, even one made in an iteration the limit cut short.
        assert c["fun"] == min(h[1] for h in c["history"])


def test_table_6_1_is_the_thesis_grid():
    assert len(TABLE_6_1["young"]) == 9 and len(TABLE_6_1["poisson"]) == 9
    assert TABLE_6_1["phi"] == [28.0, 29.0, 30.0, 31.0, 32.0, 33.0, 34.0]
    assert rounded((4500e3 + 12.3, 0.330004, 31.99999)) == (4500e3, 0.33, 32.0)


TINY = """out = "{out}"
[params]
smoke = true
n = 100
stop-strain = 0.02
seed = 1
[reference]
young = {E}
poisson = {nu}
phi = {phi}
[grid]
young = [3e6, 5e6]
poisson = [0.25, 0.45]
phi = [28, 34]
[optimiser]
maxfev = 4
"""


def test_a_tiny_calibration_recovers_the_synthetic_truth_and_beats_a_wrong_start(tmp_path):
    """2 x 2 x 2 grid at 100 grains to 2 % strain on 2 Dask workers, the synthetic truth on a
    grid corner: the grid finds it (misfit 0, every other point > 0); then the optimiser
    started from the worst corner lowers the misfit, and does so deterministically."""
    truth = (5e6, 0.25, 34.0)
    f = tmp_path / "cal.toml"
    out = tmp_path / "cal"
    f.write_text(TINY.format(out=out, E=truth[0], nu=truth[1], phi=truth[2]))
    r = subprocess.run([sys.executable, "-m", "geogrid_dem.cli", "calibrate", str(f),
                        "--workers", "2"], capture_output=True, text=True, cwd=ROOT,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert r.returncode == 0, r.stderr[-3000:] + r.stdout[-2000:]
    assert "ETA" in r.stdout and "elapsed" in r.stdout
    with open(out / "grid.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 8
    ms = {(float(x["young_Pa"]), float(x["poisson"]), float(x["phi_deg"])): float(x["misfit"])
          for x in rows}
    assert ms[truth] == 0.0  # the same engine, seed and threads: the very same curve
    # The nearest other corner's misfit, over seeds 1-8: 0.022 to 0.106 (asserted > 0.01).
    assert min(v for k, v in ms.items() if k != truth) > 0.01
    best = json.loads((out / "best.json").read_text())
    assert (best["best"]["young_Pa"], best["best"]["poisson"], best["best"]["phi_deg"]) == truth
    for name in ("misfit.png", "misfit.pdf", "curves.png", "optimiser.csv"):
        assert (out / name).stat().st_size > 0

    # The optimiser from the worst grid corner, in this process (no Dask), on the same runs.
    ref = json.loads((out / "runs" / "E5000.0k_nu0.2500_phi34.000" / "point.json").read_text())
    fixed = {k: v for k, v in ref.items() if k not in ("young", "poisson", "phi", "out")}
    runner = Runner(out, fixed, threads=1, log=lambda s: None)
    start = max(ms, key=ms.get)
    to_p, to_u = scaling({"young": [3e6, 5e6], "poisson": [0.25, 0.45], "phi": [28.0, 34.0]})
    runner.run([truth])  # reused: the grid ran it
    curve_ref = runner.curves[rounded(truth)]

    def batch_on(run):
        def batch(us):
            ps = [to_p(u) for u in us]
            run.run(ps)
            return [misfit(run.curves[p], curve_ref) for p in ps]
        return batch

    res = nelder_mead(None, to_u(start), step=0.3, maxfev=6, batch=batch_on(runner), key=to_p)
    # Six evaluations after the initial simplex on chaotic 100-grain curves: the best misfit
    # over the start's, measured over seeds 1-8 of this test: 0.39, 0.34, 0.43, 0.48, 0.40,
    # 0.47, 0.14, 0.26 (mean 0.36, sd 0.11); 0.70 on another machine at seed 1 (0.112 /
    # 0.160), where a bound of 0.6 failed. Asserted: below 0.9. (The distance to the truth is
    # not asserted: at seeds 2 and 7 the best point is farther from it than the start, 1.30
    # and 1.09 against 1.0 in the unit cube, with the misfit at 0.34 and 0.14 of the start's.)
    assert res["fun"] < 0.9 * ms[start]
    assert res["nfev"] == 6 + 4 and res["reason"] == "maxfev"
    # A rerun (a new Runner, as after Ctrl-C) reads every point from its folder: no case
    # runs, and the same search, bitwise.
    ran = []
    rerun = Runner(out, fixed, threads=1, log=ran.append)
    again = nelder_mead(None, to_u(start), step=0.3, maxfev=6, batch=batch_on(rerun),
                        key=to_p)
    assert ran == [] and len(rerun.curves) == res["new"] > 0
    assert again["fun"] == res["fun"] and np.array_equal(again["x"], res["x"])
    assert [h[1] for h in again["history"]] == [h[1] for h in res["history"]]
