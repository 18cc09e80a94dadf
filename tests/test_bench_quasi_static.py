"""bench/quasi_static.py's measures on synthetic paths: the rms error and the bias find a known
offset, the noise floor and the speed-up are read as documented, and --help works."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "quasi_static.py"


def _row(seed, setting, wall, sz_scale=1.0, noise=0.0):
    e = np.linspace(0, 0.01, 101)
    rng = np.random.default_rng(seed + int(10 * setting) + 100)
    sz = (20e3 + 2e6 * e) * sz_scale + noise * rng.standard_normal(e.size)
    m = {"contacts_longitudinal_per_m": 100.0 + setting, "grains_touching": 40.0,
         "out_of_plane_longitudinal_mean_m": 5e-4, "grid_force_longitudinal_mean_n": 1.0,
         "disp_above_mean_m": 5e-4, "disp_below_mean_m": 5e-4}
    return {"speedup_setting": setting, "seed": seed, "wall_s": wall, "steps": 1000,
            "dt_s": 1e-7 * max(setting, 1), "max_factor": max(setting, 1.0) ** 2,
            "scaled_share": 0.7 if setting > 0 else 0.0, "inertial_number_sample": 1e-3,
            "porosity": 0.53, "measures": m,
            "path": {"axial_strain": e.tolist(), "sigma_x": [20e3] * e.size,
                     "sigma_y": [20e3] * e.size, "sigma_z": sz.tolist()}}


def test_the_errors_find_a_known_offset(tmp_path):
    rows = []
    for seed in (1, 2, 3):
        rows += [_row(seed, 0.0, 60.0), _row(seed, -1.0, 66.0, noise=200.0),
                 _row(seed, 8.0, 10.0, sz_scale=1.05)]
    f = tmp_path / "rows.jsonl"
    f.write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    out = subprocess.run([sys.executable, str(BENCH), "--reanalyse", str(f), "--bins", "10",
                          "--main", "8"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    final = json.loads(out.stdout.splitlines()[-1])
    assert final["speedup"] == pytest.approx(6.0)
    # sigma_z 5 % high on a path whose three stresses have an rms of about 25 kPa.
    sz = 20e3 + 2e6 * np.linspace(0, 0.01, 101)
    s = np.array([np.full(101, 20e3), np.full(101, 20e3), sz])
    expected = np.sqrt(np.mean((0.05 * sz) ** 2) / 3 / np.mean(s ** 2))
    assert final["stress_error_rms"] == pytest.approx(expected, rel=0.02)
    assert final["sigma_z_bias"][0] > 0.04 and final["sigma_z_bias"][1] < 1e-6
    # The floor run: noise only, no bias beyond its standard error.
    assert 0 < final["noise_floor_stress_rms"] < 0.01
    b, se = final["noise_floor_stress_bias"]
    assert abs(b) < 4 * se + 1e-4
    # The measures: the paired difference of the setting's rows and the seed scatter.
    c = final["measures_002"]["contacts_longitudinal_per_m"]
    assert c["paired_difference"] == pytest.approx(8.0) and c["unscaled_seed_sd"] == 0.0


def test_help():
    out = subprocess.run([sys.executable, str(BENCH), "--help"], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0 and "--density-scaling" not in out.stdout
    assert "--sweep" in out.stdout and "--reanalyse" in out.stdout
