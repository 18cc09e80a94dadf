"""Tables in the docs come from committed data: scripts/docs_tables.py renders each marked
table from its data file, and the check fails when a table's text differs from its data."""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "docs_tables.py"

_spec = importlib.util.spec_from_file_location("docs_tables", SCRIPT)
dt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(dt)

PROVENANCE = {"command": ".venv/bin/python cases/prs_element_002.py --smoke --seeds 1-2",
              "commit": "0123456789abcdef0123456789abcdef01234567", "dirty": False,
              "date": "2026-01-02T03:04:05+00:00", "machine": "box: Linux x86_64, 2 cores"}


def _finding(**kw) -> dict:
    row = {"grid": "detailed", "name": "less vertical strain (1/Pa)", "expected_sign": -1,
           "compare": "diff", "re_mean": 1.8923456e-08, "re_sd": 2.278e-09,
           "prs_mean": 1.814e-08, "prs_sd": 3.042e-09, "diff_mean": -7.808123e-10,
           "diff_se": 5.396e-10, "n": 6, "verdict": "not resolved", "unconverged": [],
           "t_critical": 2.570581835636314, "pairs_left_out": []}
    row.update(kw)
    return row


def _data() -> dict:
    return {
        "params": {"n": 1800, "seeds": [1, 2, 3, 4, 5, 6]},
        "findings": [
            _finding(),
            _finding(grid="standard", name="mean |u| above - below (m)", expected_sign=1,
                     re_sd=float("nan"), verdict="agrees", pairs_left_out=["standard_s3"]),
            {k: v for k, v in _finding(name="an older row").items()   # before t crit
             if k not in ("t_critical", "pairs_left_out")},
        ],
        "measures": [{k: v for k, v in _finding(name="porosity").items()
                      if k not in ("expected_sign", "verdict", "t_critical",
                                   "pairs_left_out")}],
        "elements": {
            "detailed_RE_s1": {"num_grains": 1612, "porosity_final": 0.41234,
                               "coordination_final": 4.6512,
                               "rest": {"status": "at_rest", "inertial_number_max": 9.2e-5,
                                        "loading_inertial_number_max": 9.2e-4,
                                        "inertial_number_end": 4.1e-5, "hold_steps": 20000},
                               "loading_strain": [0.001, 0.0, 0.0031415926],
                               "strain_ratio_to_fem": [0.91, 1.0, 1.234567]},
            "detailed_PRS_s1": {"num_grains": 1612, "porosity_final": 0.4119,
                                "rest": {"status": "at_strength"}},
            "standard_RE_s1": {"num_grains": 1590},
        },
        "provenance": dict(PROVENANCE),
    }


PAGE = """# A study

Some text.

<!-- table: data/run.json findings -->
<!-- /table -->

The others:

<!-- table: data/run.json measures -->
stale text
<!-- /table -->

<!-- table: data/run.json elements grid=detailed -->
<!-- /table -->

<!-- table: data/run.json provenance -->
<!-- /table -->

```
<!-- table: data/in_a_code_block.json findings -->
```
"""


@pytest.fixture
def docs(tmp_path):
    d = tmp_path / "docs"
    (d / "data").mkdir(parents=True)
    (d / "data" / "run.json").write_text(json.dumps(_data(), indent=1))
    (d / "study.md").write_text(PAGE)
    return d


def test_fmt():
    assert dt.fmt(1.8923456e-08) == "1.892e-08"
    assert dt.fmt(0.41234) == "0.4123"
    assert dt.fmt(1612) == "1612"
    assert dt.fmt(None) == dt.fmt(float("nan")) == dt.fmt(math.inf) == "-"
    assert dt.fmt("|u|") == "\\|u\\|"


def test_render_writes_the_tables_and_is_idempotent(docs):
    page = docs / "study.md"
    assert dt.process(page, write=False)          # not rendered yet: the check fails
    assert dt.process(page, write=True) == []
    text = page.read_text()
    first = text
    assert dt.process(page, write=True) == [] and page.read_text() == first
    assert dt.process(page, write=False) == []
    assert "stale text" not in text and text.startswith("# A study\n\nSome text.")
    assert "<!-- table: data/in_a_code_block.json findings -->" in text   # code is text

    lines = text.splitlines()
    head = ("| grid | finding | RE mean ± sd | PRS mean ± sd | PRS − RE ± se | n | t crit | "
            "002 | verdict | pairs left out |")
    assert head in lines
    assert ("| detailed | less vertical strain (1/Pa) | 1.892e-08 ± 2.278e-09 | 1.814e-08 ± "
            "3.042e-09 | -7.808e-10 ± 5.396e-10 | 6 | 2.571 | − | not resolved | - |") in lines
    assert ("| standard | mean \\|u\\| above - below (m) | 1.892e-08 ± - | 1.814e-08 ± "
            "3.042e-09 | -7.808e-10 ± 5.396e-10 | 6 | 2.571 | + | agrees | standard_s3 |"
            ) in lines
    older = next(x for x in lines if "an older row" in x)
    assert older.endswith("| 6 | - | − | not resolved | - |")
    # measures: no 002, no verdict, no t crit (no row has one), no pairs left out
    assert ("| grid | measure | RE mean ± sd | PRS mean ± sd | PRS − RE ± se | n |") in lines
    assert any(x.startswith("| detailed | porosity | 1.892e-08 ± ") and x.endswith(" | 6 |")
               for x in lines)
    # elements, the detailed grid's only; missing keys are '-'
    assert ("| element | grains | porosity | coordination | rest | I loading (max) | "
            "I hold (end) | loading strain z | strain / FEM (x, y, z) |") in lines
    assert ("| detailed_RE_s1 | 1612 | 0.4123 | 4.651 | at_rest | 0.00092 | 4.1e-05 | "
            "0.003142 | 0.91, 1, 1.235 |") in lines
    assert "| detailed_PRS_s1 | 1612 | 0.4119 | - | at_strength | - | - | - | - |" in lines
    assert not any("standard_RE_s1" in x for x in lines)
    assert ("Command: `.venv/bin/python cases/prs_element_002.py --smoke --seeds 1-2` at "
            "commit 0123456 on 2026-01-02 (box: Linux x86_64, 2 cores).") in lines


def test_no_pairs_left_out_column_without_any(docs):
    data = _data()
    for r in data["findings"]:
        r.pop("pairs_left_out", None)
    lines = dt.findings_table(data, {})
    assert "pairs left out" not in lines[0] and lines[0].endswith("| 002 | verdict |")
    assert dt.findings_table(data, {"grid": "standard"})[2].startswith("| standard |")
    assert len(dt.findings_table(data, {"grid": "standard"})) == 3


def test_check_fails_on_an_edited_number(docs):
    page = docs / "study.md"
    assert dt.process(page, write=True) == []
    good = page.read_text()
    page.write_text(good.replace("| 0.4123 | 4.651 | at_rest |", "| 0.4124 | 4.651 | at_rest |"))
    problems = dt.process(page, write=False)
    assert len(problems) == 1
    assert "table 3" in problems[0] and "elements" in problems[0] and "0.4124" in problems[0]
    # and through the command line: non-zero, naming the page and table
    r = subprocess.run([sys.executable, str(SCRIPT), "check", str(docs)], capture_output=True,
                       text=True)
    assert r.returncode == 1 and "study.md: table 3" in r.stderr
    # new data, old table: fails too
    page.write_text(good)
    data = _data()
    data["findings"][0]["diff_mean"] = -7.9e-10
    (docs / "data" / "run.json").write_text(json.dumps(data))
    problems = dt.process(page, write=False)
    assert len(problems) == 1 and "table 1" in problems[0]
    # render mends it
    assert dt.process(page, write=True) == [] and dt.process(page, write=False) == []


def test_check_fails_without_data_or_provenance(docs):
    page = docs / "study.md"
    page.write_text(PAGE.replace("data/run.json measures", "data/gone.json measures"))
    problems = dt.process(page, write=True)
    assert len(problems) == 1 and "table 2" in problems[0] and "gone.json" in problems[0]
    assert "missing" in problems[0]
    data = _data()
    del data["provenance"]
    (docs / "data" / "run.json").write_text(json.dumps(data))
    page.write_text(PAGE)
    problems = dt.process(page, write=True)
    assert len(problems) == 4 and all("provenance" in p for p in problems)


@pytest.mark.parametrize("text, message", [
    ("<!-- table: data/run.json findings -->\n", "no <!-- /table -->"),
    ("<!-- /table -->\n", "without its start"),
    ("<!-- table: data/run.json -->\n<!-- /table -->\n", "not a table marker"),
    ("<!-- table: data/run.json pie -->\n<!-- /table -->\n", "unknown kind"),
    ("<!-- table: data/run.json findings sort -->\n<!-- /table -->\n", "key=value"),
    ("<!-- table: data/run.json provenance grid=a -->\n<!-- /table -->\n", "no option"),
    ("<!-- table: data/run.json elements labels=nope -->\n<!-- /table -->\n", "no element"),
])
def test_bad_markers_are_reported(docs, text, message):
    page = docs / "bad.md"
    page.write_text("# bad\n\n" + text)
    problems = dt.process(page, write=True)
    assert len(problems) == 1 and message in problems[0], problems
    assert page.read_text() == "# bad\n\n" + text      # left as it was


def test_the_repository_docs_match_their_data():
    """Every marked table under docs/ is what its committed data file gives."""
    problems = [p for page in dt.pages([str(ROOT / "docs")])
                for p in dt.process(page, write=False)]
    assert problems == [], ("\n".join(problems) + "\n(run `make docs-tables`, or "
                            "`.venv/bin/python scripts/docs_tables.py render docs/PAGE.md`)")


def test_capture_writes_provenance(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    summary = _data()
    del summary["provenance"]
    summary["elements"]["detailed_RE_s1"]["history"] = list(range(500))   # not a scalar
    summary["elements"]["detailed_RE_s1"]["interaction"] = {"contacts": {"per_m": 135.4},
                                                            "long": [0.0] * 100}
    summary["fem"] = {"detailed_RE": {"settlement_m": 0.0026, "field": [[0.0] * 3] * 50}}
    (run / "summary.json").write_text(json.dumps(summary))
    (run / ".geogrid-dem-run.json").write_text(json.dumps(
        {"status": "complete", "finished": "2026-11-28T19:22:59+00:00"}))
    dest = tmp_path / "docs" / "data" / "run.json"
    cmd = ".venv/bin/python cases/prs_element_002.py --seeds 1-6 --out /work/runs/x"
    r = subprocess.run([sys.executable, str(SCRIPT), "capture", str(run / "summary.json"),
                        str(dest), "--command", cmd], capture_output=True, text=True,
                       cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(dest.read_text())
    p = out["provenance"]
    assert p["command"] == cmd
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    assert p["commit"] == head and len(head) == 40
    assert isinstance(p["dirty"], bool)
    assert p["date"] == "2026-11-28T19:22:59+00:00"       # the run's end, from its manifest
    assert p["machine"] and "cores" in p["machine"]
    # trimmed to what the tables need; the rest unchanged
    assert out["findings"][:2] == json.loads(json.dumps(summary["findings"][:2]))
    assert out["params"] == summary["params"]
    e = out["elements"]["detailed_RE_s1"]
    assert "history" not in e and e["interaction"] == {"contacts": {"per_m": 135.4}}
    assert e["rest"]["status"] == "at_rest" and e["strain_ratio_to_fem"][2] == 1.234567
    assert out["fem"] == {"detailed_RE": {"settlement_m": 0.0026}}
    # a page over the captured file renders, with its provenance line
    page = dest.parent.parent / "p.md"
    page.write_text("<!-- table: data/run.json provenance -->\n<!-- /table -->\n")
    assert dt.process(page, write=True) == []
    assert f"Command: `{cmd}` at commit {head[:7]}" in page.read_text()
    # a given commit and date override
    dt.capture(run / "summary.json", dest, cmd, commit="abc", date="2020-01-01")
    p = json.loads(dest.read_text())["provenance"]
    assert p["commit"] == "abc" and p["date"] == "2020-01-01" and p["dirty"] is None


def test_generated_lines_are_those_between_markers(docs):
    page = docs / "study.md"
    assert dt.process(page, write=True) == []
    lines = page.read_text().split("\n")
    gen = dt.generated_lines(page.read_text())
    prov = next(k for k, x in enumerate(lines, 1) if x.startswith("Command: "))
    assert prov in gen
    assert all(not lines[k - 1].startswith("<!--") for k in gen)
    assert not any(lines[k - 1] in ("Some text.", "The others:") for k in gen)
    assert dt.generated_lines("<!-- table: data/x.json findings -->\n") == set()


def test_the_rve_size_and_differences_kinds_render_their_rows():
    """bench/rve_size.py's statistics and footing-multiscale's differences with their budget
    (issue 62): a row per size and per difference, in the units of their heads."""
    def st(mean, sd, cv, n=4):
        return {"mean": mean, "sd": sd, "se": sd / 2, "cv": cv, "n": n}

    data = {"sizes": {
        "200": {"params": {"young_pa": st(12.5e6, 1.25e6, 0.1), "poisson": st(0.25, 0.02, 0.08),
                           "friction_deg": st(40.0, 2.0, 0.05),
                           "dilatancy_deg": st(20.0, 3.0, 0.15)},
                "fit_wall_s": 4.2, "state_bytes": 310000},
        "100": {"params": {"young_pa": st(11e6, 2e6, 0.18), "poisson": st(0.26, 0.03, 0.115),
                           "friction_deg": st(41.0, 3.0, 0.073),
                           "dilatancy_deg": st(22.0, 4.0, 0.18)},
                "fit_wall_s": 1.9, "state_bytes": 160000}},
        "comparisons": [{"grains": 100, "next": 200, "within": False}]}
    lines = dt.rve_size_table(data, {})
    assert lines[0].startswith("| grains | seeds | E (MPa) mean ± sd | E cv |")
    assert lines[2] == ("| 100 | 4 | 11 ± 2 | 18.0 % | 0.26 ± 0.03 | 11.5 % | 41 ± 3 | 7.3 % "
                        "| 22 ± 4 | 1.9 | 160 | no |")
    assert lines[3].startswith("| 200 | 4 | 12.5 ± 1.25 | 10.0 % |") and lines[3].endswith(
        "| 4.2 | 310 | - |")
    diffs = {"differences": [{"name": "PRS - RE", "mean": -1e-3, "se": 1e-5, "n": 3,
                              "budget": {"ceiling": 1e-4, "calibration": None, "rve": 2e-4,
                                         "mesh": 3e-4, "seeds": 4.3e-5},
                              "total": None, "resolved": False}]}
    lines = dt.differences_table(diffs, {})
    assert lines[0] == ("| difference | mean (mm) | se (mm) | n | ceiling (mm) | calibration (mm)"
                        " | rve (mm) | mesh (mm) | seeds (mm) | total (mm) | resolved |")
    assert lines[2] == "| PRS - RE | -1 | 0.01 | 3 | 0.1 | - | 0.2 | 0.3 | 0.043 | - | no |"
    # on a page, each is followed by its source line, as a study page's table is
    line = dt.source_line({"provenance": dict(PROVENANCE)}, "../data/run.json")
    assert line == ("Command: `.venv/bin/python cases/prs_element_002.py --smoke --seeds 1-2` "
                    "· commit `0123456` (2026-01-02) · data: ../data/run.json.")
    assert dt.SOURCED == {"rve_size", "differences", "band_meshes"}
    with pytest.raises(dt.TableError, match="no 'sizes'"):
        dt.rve_size_table({}, {})
    with pytest.raises(dt.TableError, match="no 'differences'"):
        dt.differences_table({}, {})


def test_the_band_meshes_kind_renders_a_row_per_mesh():
    """bench/shear_band.py --compare's mesh study (issue 62 item 6): a row per mesh, the
    angle's move from the coarser mesh with its error and whether it exceeds it."""
    def mesh(name, cell, angle, width, length=0.0):
        return {"mesh": name, "elements": 216, "cell_m": cell, "nonlocal_length_m": length,
                "angle_deg": angle, "angle_error_deg": 1.5, "width_m": width,
                "width_se_m": 4e-4, "localization_index": 4.6, "axial_strain": 0.03}

    data = {"meshes": [mesh("4x9", 0.0125, 54.5, 0.0082), mesh("5x11", 0.01, 50.25, 0.006,
                                                                0.006)],
            "pairs": [{"from": "4x9", "to": "5x11", "angle_move_deg": -4.25,
                       "angle_error_deg": 2.121, "angle_moves": True}]}
    lines = dt.band_meshes_table(data, {})
    assert lines[0].startswith("| mesh | elements | runs | cell (mm) | nonlocal length (mm) |")
    assert lines[2] == ("| 4x9 | 216 | 1 | 12.5 | local | 3 | 4.6 | 54.5 ± 1.5 | 8.2 ± 0.4 "
                        "| 0.656 | - | - |")
    assert lines[3] == ("| 5x11 | 216 | 1 | 10 | 6 | 3 | 4.6 | 50.25 ± 1.5 | 6 ± 0.4 | 0.6 "
                        "| -4.25 ± 2.121 | yes |")
    with pytest.raises(dt.TableError, match="no 'meshes'"):
        dt.band_meshes_table({}, {})
