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


#: Cases whose smoke is a coupled run: a completed run exits with its coupling's status
#: (femcoupling.coupling.status.EXIT_CODES: 0 converged, 3 stopped within the elements' scatter),
#: the one summary.json gives.
COUPLED = {"footing_multiscale"}


@pytest.mark.parametrize("name", case_names())
def test_case_smoke_runs_and_writes_results(case_smoke, name):
    out, proc = case_smoke(name)
    assert (out / "summary.json").exists(), proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    expected = summary["coupling"]["exit_code"] if name in COUPLED else 0
    assert expected in (0, 3), summary.get("coupling")  # converged, or within the scatter
    assert proc.returncode == expected, proc.stdout[-3000:] + proc.stderr[-3000:]
    files = [p for p in out.rglob("*") if p.is_file()]
    assert len(files) >= 2, f"{name}: only {files} in --out"
    assert summary, f"{name}: empty summary.json"
    assert summary["status"] == "finished", summary.get("status")  # (rundir.end_run)
    assert (proc.stdout + proc.stderr).strip(), f"{name}: printed no progress"
