"""`make wheel` (issue 64 item 9): an install that is not a source build. The wheel installs
into a fresh venv (its dependencies from the package index or pip's cache, no compiler, not
the repository's tree) and runs example 01 and the `geogrid-dem` command there."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_wheel_installs_into_a_fresh_venv_and_runs_example_01(tmp_path):
    dist = tmp_path / "dist"
    r = subprocess.run(["make", "-s", "wheel", f"DIST={dist}"], cwd=ROOT, capture_output=True,
                       text=True, timeout=1200)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    (whl,) = dist.glob("geogrid_dem-*.whl")
    assert whl.name.endswith("-cp312-cp312-linux_x86_64.whl"), whl.name
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    py = venv / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", str(whl)], capture_output=True,
                       text=True, timeout=1200, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    run = tmp_path / "elsewhere"  # (not the repository: nothing of its tree on the path)
    run.mkdir()
    r = subprocess.run([str(py), "-c", "import cpp_dem, geogrid_dem; "
                        "print(cpp_dem.__file__); print(geogrid_dem.__file__)"],
                       capture_output=True, text=True, cwd=run, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert all(str(venv) in line for line in r.stdout.split()), r.stdout
    out = tmp_path / "ex01"
    r = subprocess.run([str(py), str(ROOT / "examples" / "01_pullout_dem_only.py"), "--smoke",
                        "--out", str(out)], capture_output=True, text=True, cwd=run, env=env,
                       timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert (out / "pullout.csv").stat().st_size > 0 and (out / "pullout.png").is_file()
    r = subprocess.run([str(venv / "bin" / "geogrid-dem"), "cases"], capture_output=True,
                       text=True, cwd=run, env=env, timeout=300)
    assert r.returncode == 0 and "pullout-000" in r.stdout, r.stderr[-2000:]
