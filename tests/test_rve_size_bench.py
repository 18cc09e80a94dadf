"""bench/rve_size.py (issue 62 item 2): its decision rule on synthetic statistics (it can say
no), and its smoke end to end."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    spec = importlib.util.spec_from_file_location("rve_size", ROOT / "bench" / "rve_size.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _size(mean_e, se_e, n=16, **others):
    """Synthetic statistics of one size: E's mean and se; the others equal everywhere unless
    given as (mean, se)."""
    def st(mean, se):
        return {"mean": mean, "sd": se * n ** 0.5, "se": se, "cv": se * n ** 0.5 / mean,
                "n": n}
    params = {"young_pa": st(mean_e, se_e), "poisson": st(0.25, 0.005),
              "friction_deg": st(40.0, 0.5), "dilatancy_deg": st(20.0, 1.0)}
    params.update({k: st(*v) for k, v in others.items()})
    return {"params": params}


def test_the_representative_size_is_the_smallest_within_the_next_size_s_budget():
    """100 grains is 20 % stiffer than 200, far beyond 200's budget (t x se = 2.13 x 0.3
    MPa): not representative; 200 lies within 400's budget: the answer; 400 against 800 is
    judged too. With every size off its next, none is (None), and a next size with one seed
    has no budget (never within)."""
    rv = _bench()
    stats = {100: _size(15e6, 0.5e6), 200: _size(12.5e6, 0.3e6), 400: _size(12.2e6, 0.3e6),
             800: _size(12.1e6, 0.2e6)}
    rows, answer = rv.representative([100, 200, 400, 800], stats)
    assert answer == 200
    assert [r["within"] for r in rows] == [False, True, True]
    c = rows[0]["params"]["young_pa"]
    assert c["difference"] == pytest.approx(2.5e6)
    assert c["budget"] == pytest.approx(2.1314 * 0.3e6, rel=1e-4)
    assert c["relative"] == pytest.approx(2.5 / 12.5)
    # one parameter off is enough to refuse a size
    stats[200] = _size(12.5e6, 0.3e6, friction_deg=(43.0, 0.5))
    rows, answer = rv.representative([100, 200, 400, 800], stats)
    assert answer == 400 and rows[1]["params"]["friction_deg"]["within"] is False
    # nothing representative: every size drifts
    drift = {n: _size(10e6 + 1e6 * k, 0.1e6) for k, n in enumerate((100, 200, 400))}
    assert rv.representative([100, 200, 400], drift)[1] is None
    # the next size with one seed: no budget, never within
    one = {100: _size(12e6, 0.1e6), 200: _size(12e6, 0.1e6, n=1)}
    one[200]["params"]["young_pa"]["se"] = None
    assert rv.representative([100, 200], one)[0][0]["params"]["young_pa"]["within"] is False


def test_the_smoke_writes_each_fit_as_it_ends_and_the_statistics(tmp_path):
    out = tmp_path / "rve"
    p = subprocess.run([sys.executable, str(ROOT / "bench" / "rve_size.py"), "--smoke",
                        "--out", str(out)], capture_output=True, text=True, cwd=ROOT,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    lines = [json.loads(x) for x in (out / "rve_size.jsonl").read_text().splitlines()]
    assert [(f["grains"], f["seed"]) for f in lines] == [(50, 1), (50, 2), (80, 1), (80, 2)]
    s = json.loads((out / "rve_size.json").read_text())
    assert set(s["sizes"]) == {"50", "80"} and s["seeds"] == [1, 2]
    for n in ("50", "80"):
        st = s["sizes"][n]
        assert st["params"]["young_pa"]["n"] == 2 and st["state_bytes"] > 10_000
        assert st["fit_wall_s"] > 0
    assert s["sizes"]["80"]["state_bytes"] > s["sizes"]["50"]["state_bytes"]
    assert len(s["comparisons"]) == 1 and s["representative"] in (50, None)
    assert s["provenance"]["commit"]
    assert (out / "rve_size.png").stat().st_size > 1000
    assert json.loads(p.stdout.strip().splitlines()[-1])["sizes"] == [50, 80]


@pytest.mark.parametrize("args, words", [
    (["--sizes", "80,50"], "--sizes=80,50: at least two distinct sizes, increasing"),
    (["--sizes", "100"], "--sizes=100: at least two distinct sizes, increasing"),
    (["--sizes", "20,100"], "--sizes='20,100': 20 is not allowed"),
    (["--seeds", "1"], "--seeds=1: must be >= 2"),
])
def test_a_bad_input_is_one_line_naming_it(tmp_path, args, words):
    p = subprocess.run([sys.executable, str(ROOT / "bench" / "rve_size.py"), *args, "--out",
                        str(tmp_path / "o")], capture_output=True, text=True, cwd=ROOT,
                       timeout=120)
    assert p.returncode == 2 and words in p.stderr, p.stderr
