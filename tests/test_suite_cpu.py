"""scripts/suite_cpu.py (docs/developing.md): each test's CPU, its own process's and its
children's, as the suite's time is measured."""

from __future__ import annotations

import json
import subprocess
import sys

from conftest import ROOT

BURN = """
import subprocess, sys, time


def _burn(seconds):
    t = time.process_time()
    while time.process_time() - t < seconds:
        pass


def test_own():
    _burn(0.4)


def test_child():
    subprocess.run([sys.executable, "-c", "import time\\nt = time.process_time()\\n"
                    "while time.process_time() - t < 0.4: pass"], check=True)
"""


def test_it_counts_a_tests_own_cpu_and_its_childrens(tmp_path):
    f = tmp_path / "test_burn.py"
    f.write_text(BURN)
    out = tmp_path / "rows.jsonl"
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "suite_cpu.py"), "--jobs", "1",
                        "--top", "2", "--out", str(out), str(f)],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    rows = {r["id"].split("::")[-1]: r for r in map(json.loads, out.read_text().splitlines())}
    assert set(rows) == {"test_own", "test_child"}
    own, child = rows["test_own"], rows["test_child"]
    assert own["su"] + own["ss"] >= 0.35 and own["cu"] + own["cs"] < 0.1
    # the child's CPU is the child's, not the test process's
    assert child["cu"] + child["cs"] >= 0.35 and child["su"] + child["ss"] < 0.3
    assert "2 tests:" in p.stdout and "test_burn.py::test_" in p.stdout


def test_bad_options_are_named():
    p = subprocess.run([sys.executable, str(ROOT / "scripts" / "suite_cpu.py"), "--jobs", "0"],
                       capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert p.returncode == 2 and "--jobs=0" in p.stderr
