"""bench/band_rve_roughness.py at smoke size: the band RVE's answer to an increment is
repeatable bitwise, and a probe of 1e-9 moves it (the roughness the footing's Newton meets,
docs/studies/footing_multiscale.md); bad input is refused by name."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "band_rve_roughness.py"


def test_the_roughness_bench_runs_and_its_measure_can_tell():
    p = subprocess.run([sys.executable, str(BENCH), "--smoke"], capture_output=True,
                       text=True, cwd=ROOT, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    r = json.loads(p.stdout.strip().splitlines()[-1])
    (row,) = r["rows"]
    assert row["repeat_bitwise_equal"] and not row["bitwise_equal"]
    # a 1e-9 probe moves it by far more than a linear response would (1e-9 of a 10 MPa
    # stiffness is 1e-2 Pa, 3e-7 of the stress): measured 1.2e-5 (1.4e-3 grown loose), most
    # of it the grains'
    assert 3e-6 < row["total"] < 0.05
    assert row["grains"] > row["bonds"]


@pytest.mark.parametrize("argv, words", [
    (["--probe", "-1"], "--probe=-1.0: must be >= 0"),
    (["--unbalanced", "0"], "--unbalanced='0': numbers > 0"),
    (["--grains", "50"], "--grains=50: at least 80"),
])
def test_bad_input_is_named(argv, words):
    p = subprocess.run([sys.executable, str(BENCH), *argv], capture_output=True, text=True,
                       cwd=ROOT, timeout=60)
    assert p.returncode == 2 and words in p.stderr, p.stderr
