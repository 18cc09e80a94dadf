"""Calibration of E, nu and phi of the triaxial case (001 §6.1, Table 6.1): the misfit, the
deterministic Nelder-Mead, and a tiny grid + optimiser that recovers a synthetic truth."""

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from geogrid_dem.calibrate import Runner, TABLE_6_1, misfit, nelder_mead, rounded

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
    lo = np.array([math.log10(3e6), 0.25, 28.0])
    span = np.array([math.log10(5e6) - math.log10(3e6), 0.2, 6.0])
    to_p = lambda u: rounded((10 ** (lo[0] + u[0] * span[0]), *(lo[1:] + u[1:] * span[1:])))  # noqa: E731
    to_u = lambda p: (np.array([math.log10(p[0]), p[1], p[2]]) - lo) / span  # noqa: E731
    runner.run([truth])  # reused: the grid ran it
    curve_ref = runner.curves[rounded(truth)]

    def batch(us):
        ps = [to_p(u) for u in us]
        runner.run(ps)
        return [misfit(runner.curves[p], curve_ref) for p in ps]

    res = nelder_mead(None, to_u(start), step=0.3, maxfev=6, batch=batch)
    # Six evaluations on chaotic 100-grain curves: the best misfit over the start's, measured
    # over seeds 1-8 of this test: 0.39, 0.34, 0.42, 0.44, 0.40, 0.47, 0.14, 0.26 (mean 0.36,
    # sd 0.11); 0.70 on another machine at seed 1 (0.112 / 0.160), where the old bound 0.6
    # failed. Asserted: below 0.9. (The distance to the truth is not asserted: at seeds 2 and
    # 7 the best point was farther from it than the start, 1.30 and 1.09 against 1.0 in the
    # unit cube, with the misfit at 0.34 and 0.14 of the start's.)
    assert res["fun"] < 0.9 * ms[start]
    # The same runs give the same search, bitwise (the curves are cached: no new run).
    again = nelder_mead(None, to_u(start), step=0.3, maxfev=6, batch=batch)
    assert again["fun"] == res["fun"] and np.array_equal(again["x"], res["x"])
