"""bench/calibration_spread.py at a tiny size: the footing's calibration on two rounding paths
that must give the same bits (the DEM core's two vector forms, docs/core.md "Determinism and
threads"), so a rounding-only change of the DEM cannot move the fitted continuum."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_narrow_vector_form_fits_the_same_continuum_bitwise(tmp_path):
    out = tmp_path / "spread.jsonl"
    r = subprocess.run([sys.executable, str(ROOT / "bench" / "calibration_spread.py"),
                        "--counts", "2", "--paths", "default,narrow", "--cell-grains", "50",
                        "--out", str(out)], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = {x["path"]: x for x in map(json.loads, out.read_text().splitlines())}
    d, n = rows["default"], rows["narrow"]
    assert len(d["seeds_E"]) == 2 and d["seeds_E"][0] != d["seeds_E"][1]
    for key in ("E", "nu", "phi", "seeds_E", "seeds_phi", "path_final_pa"):
        assert n[key] == d[key], key
    assert "E vs default" in r.stdout and "+0.0000" in r.stdout


def test_bad_counts_and_paths_are_refused():
    for argv, msg in ((["--counts", "0"], "--counts='0'"), (["--paths", "fast"], "--paths='fast'"),
                      (["--cell-grains", "10"], "--cell-grains=10")):
        r = subprocess.run([sys.executable, str(ROOT / "bench" / "calibration_spread.py"),
                            *argv], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and msg in r.stderr, r.stderr
