"""scripts/suite_profile.py: the shares of a py-spy raw file by category, and the breakdowns
by innermost frames and by callers, on a synthetic file whose shares are known."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import suite_profile as sp  # noqa: E402

RAW = """\
process 1:"python -m pytest";run (cpp_dem/scene.py:10);Scene.run (cpp_dem/scene.py:99) 50
process 1:"python -m pytest";grow_grains (cpp_dem/protocols/periodic.py:253);grow_to_stress (cpp_dem/protocols/prep.py:191);Scene.run (cpp_dem/scene.py:99) 30
process 2:"x";newton_solve (femcoupling/fem/quadrature.py:448);correction (femcoupling/fem/quadrature.py:587) 15
process 2:"x";savefig (matplotlib/figure.py:1) 4
a line that is not a stack
process 3:"y";select (selectors.py:468) 1
"""


@pytest.fixture()
def raw(tmp_path):
    path = tmp_path / "suite.raw"
    path.write_text(RAW)
    return path


def test_the_shares_by_category_are_the_samples_of_the_first_category_that_matches(raw):
    total, cats = sp.categories(raw)
    assert total == 100
    assert cats == {"the DEM's steps (Scene.run)": 80, "the FEM (femcoupling)": 15,
                    "figures (matplotlib, PIL)": 4, "other": 1}


def test_the_breakdowns_by_innermost_frames_and_by_callers(raw):
    total, matched, keys = sp.breakdown(raw, callers=r"Scene\.run \(")
    assert (total, matched) == (100, 80)
    assert keys == {"run (scene.py:10) <- process 1:\"python -m pytest\"": 50,
                    "grow_to_stress (prep.py:191) <- grow_grains (periodic.py:253)": 30}
    total, matched, keys = sp.breakdown(raw, where="quadrature")
    assert matched == 15 and list(keys) == [
        'process 2:"x" ; newton_solve (quadrature.py:448) ; correction (quadrature.py:587)']


def test_the_command_prints_the_shares_and_refuses_what_it_cannot_read(raw, tmp_path):
    script = ROOT / "scripts" / "suite_profile.py"
    p = subprocess.run([sys.executable, str(script), str(raw)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[:2] == ["100 samples", " 80.00 %  the DEM's steps (Scene.run)"]
    empty = tmp_path / "empty.raw"
    empty.write_text("nothing here\n")
    p = subprocess.run([sys.executable, str(script), str(empty)], capture_output=True, text=True)
    assert p.returncode == 2 and "no samples" in p.stderr
    p = subprocess.run([sys.executable, str(script), str(raw), "--top", "0"], capture_output=True,
                       text=True)
    assert p.returncode == 2 and "--top=0: must be >= 1" in p.stderr
