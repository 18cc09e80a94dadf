"""Input checks of the geogrid-dem command and the cases' parsers (docs/cli.md): abbreviated
flags, the run file's record of text options, bounds on --threads, --workers, --snapshots,
--levels and the seeds, options without effect, run and sweep files that set a parameter
twice, sweep folders and finished rows, unit slips. Mostly parse-level: nothing runs."""

import contextlib
import importlib
import io
import json
import tomllib
import warnings
from pathlib import Path

import pytest

from geogrid_dem import cli, rundir, runs
from geogrid_dem.cases import CASES

ROOT = Path(__file__).resolve().parents[1]
CALIBRATION = ROOT / "cases" / "calibrate_triaxial.toml"
BOUND = rundir.local_bound()
MAX_SEED = 2**63 - 1


@pytest.fixture(autouse=True)
def no_work(monkeypatch):
    """A sweep or a calibration that got past its checks fails here, before Dask starts."""
    def refuse(*a, **k):
        raise AssertionError("the input was taken: work would start")

    monkeypatch.setattr(cli, "_run_on_dask", refuse)
    monkeypatch.setattr(cli, "_started_client", refuse)
    monkeypatch.setattr(runs, "_dask_client", refuse)


def parse(case: str, *args, out: Path | None = None):
    """(exit status or None, stderr) of the case's parse_args on ``args`` (nothing runs)."""
    mod = importlib.import_module(f"geogrid_dem.cases.{CASES[case].module}")
    argv = [*(["--out", str(out)] if out else []), *map(str, args)]
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            mod.parse_args(argv)
    except SystemExit as e:
        return e.code, err.getvalue()
    return None, err.getvalue()


def main(*args) -> tuple[int, str]:
    """(exit status, stderr + stdout) of ``geogrid-dem ARGS`` in this process."""
    err, out = io.StringIO(), io.StringIO()
    code = 0
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            cli.main([str(a) for a in args])
    except SystemExit as e:
        code = e.code
    return code, err.getvalue() + out.getvalue()


def toml(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# 1. abbreviated flags are refused, not taken for the flag they start

@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("abbrev", ["--ou", "--overw"])
def test_1_an_abbreviated_flag_is_refused_by_every_case(case, abbrev, tmp_path):
    code, err = parse(case, "--smoke", abbrev, *(["x"] if abbrev == "--ou" else []))
    assert code == 2 and f"unrecognized arguments: {abbrev}" in err, err


def test_1_an_abbreviated_flag_of_the_command_is_refused(tmp_path):
    f = toml(tmp_path / "s.toml", f'case = "triaxial"\nout = "{tmp_path / "o"}"\n'
                                  '[params]\nsmoke = true\n[sweep]\nseed = [1]\n')
    code, msg = main("sweep", f, "--work", "2")
    assert code == 2 and "unrecognized arguments: --work" in msg, msg


def test_1_run_with_an_abbreviated_flag_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _ = main("run", "triaxial", "--smoke", "--ou", tmp_path / "o")
    assert code == 2
    assert not (tmp_path / "results").exists() and not (tmp_path / "o").exists()


# 2. run.toml keeps the text of an option that takes text

def test_2_run_toml_keeps_text_options_as_given(tmp_path):
    for text in ("007", "1e3", "1_000"):
        p = runs.argv_to_params(["--smoke", "--out", text, "--seed", "007",
                                 "--cell-pressure", "1e5"], "triaxial")
        assert p == {"smoke": True, "out": text, "seed": 7, "cell-pressure": 100000.0}, p
        runs.write_run_file(tmp_path, "triaxial", p)
        with open(tmp_path / "run.toml", "rb") as f:
            assert tomllib.load(f)["params"]["out"] == text
    # a text option whose number reads back as given is written as before
    assert runs.argv_to_params(["--spheres", "3000"], "pullout-000") == {"spheres": 3000}
    assert runs.argv_to_params(["--out=-007"], "triaxial") == {"out": "-007"}


# 3. --threads above 4 x the cores

@pytest.mark.parametrize("case", ["triaxial", "pullout-000", "prs-element-002",
                                  "footing-multiscale"])
def test_3_threads_above_the_bound_are_refused(case):
    code, err = parse(case, "--smoke", "--threads", 100000)
    assert code == 2 and "--threads=100000: more than" in err and \
        f"allowed: 0 (automatic) to {BOUND}" in err, err
    assert parse(case, "--smoke", "--threads", BOUND + 1)[0] == 2
    assert parse("triaxial", "--smoke", "--threads", BOUND)[0] is None


def test_3_sweep_threads_above_the_bound_are_refused(tmp_path):
    f = toml(tmp_path / "s.toml", f'case = "triaxial"\nout = "{tmp_path / "o"}"\n'
                                  '[params]\nsmoke = true\n[sweep]\nseed = [1, 2]\n')
    code, msg = main("sweep", f, "--threads", 100000)
    assert code == 2 and "--threads=100000" in msg and f"0 to {BOUND}" in msg, msg
    assert not (tmp_path / "o").exists()
    code, msg = main("calibrate", CALIBRATION, "--threads", 100000,
                     "--out", tmp_path / "c")
    assert code == 2 and "--threads=100000" in msg, msg


# 4. --workers of a local cluster above 4 x the cores

@pytest.mark.parametrize("case, extra", [("footing-multiscale", []), ("prs-element", []),
                                         ("prs-element-002", ["--seeds", "1-2"])])
def test_4_workers_above_the_bound_are_refused(case, extra):
    code, err = parse(case, "--smoke", *extra, "--workers", 100000)
    assert code == 2 and "--workers=100000: more than" in err and \
        f"allowed: 1 to {BOUND}" in err, err


def test_4_sweep_and_calibrate_workers_above_the_bound_are_refused(tmp_path):
    f = toml(tmp_path / "s.toml", f'case = "triaxial"\nout = "{tmp_path / "o"}"\n'
                                  '[params]\nsmoke = true\n[sweep]\nseed = [1, 2]\n')
    code, msg = main("sweep", f, "--workers", 100000)
    assert code == 2 and "--workers=100000" in msg and f"1 to {BOUND}" in msg, msg
    code, msg = main("calibrate", CALIBRATION, "--workers", 100000,
                     "--out", tmp_path / "c")
    assert code == 2 and "--workers=100000" in msg and f"0 to {BOUND}" in msg, msg
    assert not (tmp_path / "o").exists() and not (tmp_path / "c").exists()


# 5. pullout-000 --snapshots capped

def test_5_snapshots_above_the_cap_are_refused():
    code, err = parse("pullout-000", "--smoke", "--snapshots", 3000)
    assert code == 2 and "--snapshots=3000" in err and "cap of 100 snapshots" in err and \
        "--allow-large" in err, err
    assert parse("pullout-000", "--smoke", "--snapshots", 100)[0] is None
    assert parse("pullout-000", "--smoke", "--snapshots", 3000, "--allow-large")[0] is None


# 6. footing-multiscale --levels capped

def test_6_levels_above_the_cap_are_refused():
    code, err = parse("footing-multiscale", "--smoke", "--levels", 10**9)
    assert code == 2 and "--levels=1000000000" in err and "cap of 100 load levels" in err, err
    assert parse("footing-multiscale", "--smoke", "--levels", 100)[0] is None


# 7, 8. seeds in [0, 2**63 - 1]

@pytest.mark.parametrize("case", ["triaxial", "pullout-000", "prs-element",
                                  "prs-element-002", "deposition", "footing-multiscale"])
@pytest.mark.parametrize("seed", [-1, 2**63, 2**64])
def test_7_8_a_seed_outside_the_range_is_refused_before_any_folder(case, seed, tmp_path):
    out = tmp_path / "o"
    code, err = parse(case, "--smoke", "--seed", seed, out=out)
    assert code == 2 and f"--seed={seed}" in err and str(MAX_SEED) in err, err
    assert not out.exists()


def test_8_the_largest_seed_is_taken_and_derived_seeds_are_checked():
    assert parse("triaxial", "--smoke", "--seed", MAX_SEED)[0] is None
    code, err = parse("prs-element-002", "--smoke", "--seed", MAX_SEED)
    assert code == 2 and "the next one" in err and str(MAX_SEED + 1) in err, err
    code, err = parse("footing-multiscale", "--smoke", "--seed", MAX_SEED)
    assert code == 2 and "--seeds=2" in err, err
    code, err = parse("pullout-001", "--smoke", "--study", "--seeds", "-1", "--jitter", 0.1)
    assert code == 2 and "the seed -1 is outside" in err, err


# 9. pullout-001 --seed without effect

def test_9_pullout_001_seed_without_jitter_is_refused():
    code, err = parse("pullout-001", "--smoke", "--seed", 7)
    assert code == 2 and "--seed=7: has no effect with sphere grains and --jitter 0" in err, err
    assert parse("pullout-001", "--smoke", "--seed", 7, "--jitter", 0.1)[0] is None
    assert parse("pullout-001", "--smoke", "--seed", 1)[0] is None  # the default


# 10. a run file with a [sweep] table

def test_10_a_run_file_with_a_sweep_table_is_refused(tmp_path):
    out = tmp_path / "o"
    f = toml(tmp_path / "r.toml", f'case = "triaxial"\nout = "{out}"\n[params]\nsmoke = true\n'
                                  '[sweep]\ncell-pressure = [50e3, 100e3]\n')
    code, msg = main("run", f)
    assert code == 1 and "field 'sweep'" in msg and "geogrid-dem sweep" in msg, msg
    assert not out.exists()


# 11. a parameter given twice

@pytest.mark.parametrize("body, words", [
    ('out = "A"\n[params]\nsmoke = true\nout = "B"\n', "fields 'out' and 'params.out'"),
    ('[params]\nsmoke = true\ncell-pressure = 50e3\ncell_pressure = 100e3\n',
     "fields 'cell-pressure' and 'cell_pressure' set the same parameter"),
    ('[params]\nsmoke = true\nyoung = 4.5e6\nE = 9e6\n',
     "fields 'young' and 'E' set the same parameter (--young / --E)"),
])
def test_11_a_run_file_setting_a_parameter_twice_is_refused(tmp_path, monkeypatch, body,
                                                            words):
    monkeypatch.chdir(tmp_path)  # (the folders A, B; results/ for the others)
    f = toml(tmp_path / "r.toml", 'case = "triaxial"\n' + body)
    code, msg = main("run", f)
    assert code == 1 and words in msg, msg


@pytest.mark.parametrize("body, words", [
    ('[params]\nsmoke = true\ncell-pressure = 50e3\n[sweep]\ncell_pressure = [60e3]\n',
     "fields 'params.cell-pressure' and 'sweep.cell_pressure' set the same parameter"),
    ('[params]\nsmoke = true\nseed = 1\n[sweep]\nseed = [1, 2]\n',
     "fields 'params.seed' and 'sweep.seed'"),
    ('[params]\nsmoke = true\n[sweep]\nout = ["elsewhere"]\n', "field 'sweep.out'"),
])
def test_11_a_sweep_setting_a_parameter_twice_is_refused(tmp_path, body, words):
    out = tmp_path / "o"
    f = toml(tmp_path / "s.toml", f'case = "triaxial"\nout = "{out}"\n' + body)
    code, msg = main("sweep", f)
    assert code == 1 and words in msg, msg
    assert not out.exists()


@pytest.mark.parametrize("key", ["E", "nu", "young"])
def test_11_calibration_params_of_the_fitted_parameters_are_refused(tmp_path, key):
    text = CALIBRATION.read_text()
    assert "\n[params]" in text, "the shipped calibration file has a [params] table"
    f = toml(tmp_path / "c.toml", text.replace("\n[params]", f"\n[params]\n{key} = 0.3", 1))
    code, msg = main("calibrate", f, "--out", tmp_path / "c")
    assert code == 1 and f"field 'params.{key}'" in msg and "set by the calibration" in msg, \
        msg


# 12. a value listed twice in a sweep

def test_12_a_sweep_value_listed_twice_is_refused(tmp_path):
    with pytest.raises(runs.RunFileError, match=r"'sweep.seed'=\[1, 1\]: 1 is listed twice"):
        runs.sweep_rows({"sweep": {"seed": [1, 1]}}, "s.toml")
    with pytest.raises(runs.RunFileError, match="is listed twice"):
        runs.sweep_rows({"sweep": {"cell-pressure": [1e5, 100000]}}, "s.toml")
    with pytest.raises(runs.RunFileError, match="rows 0 and 2 are the same"):
        runs.sweep_rows({"sweep": {"mode": "list", "seed": [1, 2, 1],
                                   "n": [300, 300, 300]}}, "s.toml")
    # list mode: a column may repeat a value when the rows differ
    rows = runs.sweep_rows({"sweep": {"mode": "list", "seed": [1, 1], "n": [300, 400]}}, "s")
    assert rows == [{"seed": 1, "n": 300}, {"seed": 1, "n": 400}]
    out = tmp_path / "o"
    f = toml(tmp_path / "s.toml", f'case = "triaxial"\nout = "{out}"\n[params]\nsmoke = true\n'
                                  '[sweep]\nseed = [1, 1]\n')
    code, msg = main("sweep", f)
    assert code == 1 and "listed twice" in msg and not out.exists(), msg


# 13. a sweep into another run's folder

def test_13_a_sweep_into_a_case_run_folder_is_refused(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / rundir.MANIFEST).write_text(json.dumps({"status": "complete", "case": "triaxial",
                                                   "started": "2026-01-01T00:00:00"}))
    (run / "summary.json").write_text("{}")
    f = toml(tmp_path / "s.toml", f'case = "triaxial"\nout = "{run}"\n[params]\nsmoke = true\n'
                                  '[sweep]\nseed = [1]\n')
    code, msg = main("sweep", f)
    assert code == 1 and "holds a run of triaxial (complete" in msg, msg
    assert sorted(p.name for p in run.iterdir()) == [rundir.MANIFEST, "summary.json"]


# 14. threads and workers do not make a finished row unfinished

def test_14_a_finished_row_is_finished_whatever_its_threads(tmp_path):
    row = tmp_path / "row_000"
    params = {"smoke": True, "seed": 1, "out": str(row), "threads": 1}
    runs.write_run_file(row, "triaxial", params)
    (row / "summary.json").write_text("{}")
    assert runs._row_finished(row, "triaxial", params)
    assert runs._row_finished(row, "triaxial", {**params, "threads": 2})
    assert runs._row_finished(row, "triaxial", {**params, "workers": 3})
    assert not runs._row_finished(row, "triaxial", {**params, "seed": 2})
    (row / "summary.json").unlink()  # (an unfinished row of this sweep, with other workers)
    runs.check_row_folder(row, "triaxial", {**params, "workers": 3}, source="s")
    with pytest.raises(runs.RunFileError, match="holds a row of another sweep"):
        runs.check_row_folder(row, "triaxial", {**params, "seed": 2}, source="s")


# smaller: the case as a list, help as a parameter, unit slips

def test_a_case_that_is_not_a_string_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    f = toml(tmp_path / "r.toml", 'case = ["triaxial"]\n[params]\nsmoke = true\n')
    code, msg = main("run", f)
    assert code == 1 and "case=['triaxial']: must be a string" in msg and \
        "allowed: pullout-000" in msg, msg


def test_help_as_a_parameter_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    f = toml(tmp_path / "r.toml", 'case = "triaxial"\n[params]\nhelp = true\n')
    code, msg = main("run", f)
    assert code == 1 and "field 'help': not a parameter" in msg, msg


@pytest.mark.parametrize("case, args, words", [
    ("triaxial", ["--cell-pressure", 75], "--cell-pressure=75: below 1000 Pa"),
    ("triaxial", ["--density", 2.65], "--density=2.65: below 500 kg/m^3"),
    ("pullout-000", ["--pressure", 25], "--pressure=25: below 1000 Pa"),
    ("pullout-001", ["--pressure", 75], "--pressure=75: below 1000 Pa"),
])
def test_a_unit_slip_is_warned_of_not_refused(case, args, words):
    from cpp_dem import PhysicalRangeWarning

    with pytest.warns(PhysicalRangeWarning, match=words.replace("^", r"\^")):
        assert parse(case, "--smoke", *args)[0] is None
    with warnings.catch_warnings():
        warnings.simplefilter("error", PhysicalRangeWarning)
        assert parse("triaxial", "--smoke")[0] is None  # the defaults: no warning
