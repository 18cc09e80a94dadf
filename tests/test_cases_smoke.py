"""Every case's --smoke, found by glob (cases/*.py with a main()): it runs, exits 0, prints its
progress, and leaves its results (summary.json and more) in --out. The runs are shared with
the cases' own physics tests (conftest.case_smoke)."""

import json

import pytest

from conftest import case_names


def test_the_glob_finds_the_known_cases():
    names = case_names()
    for known in ("deposition", "prs_element", "pullout_000", "pullout_001", "triaxial"):
        assert known in names
    assert "pullout_common" not in names  # a helper module, not a case


@pytest.mark.parametrize("name", case_names())
def test_case_smoke_runs_and_writes_results(case_smoke, name):
    out, proc = case_smoke(name)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    files = [p for p in out.rglob("*") if p.is_file()]
    assert len(files) >= 2, f"{name}: only {files} in --out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary, f"{name}: empty summary.json"
    assert (proc.stdout + proc.stderr).strip(), f"{name}: printed no progress"
