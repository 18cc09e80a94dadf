"""Issue 60, items 2, 5, 6 and 9: a resume continues the same run or refuses; work above a
stated cap needs --allow-large; an option with no effect given the others is refused by name;
errors in calibration files and run files are one line naming the field (docs/cli.md,
docs/reliability.md).

Everything here parses arguments, reads files or runs rundir.run_main on a work function of a
few milliseconds; one test runs a deposition of 20 spheres (about a second)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import pytest

from geogrid_dem import rundir

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


# ---- a resume continues the same run, or refuses -------------------------------------------------

@dataclass
class P:
    """A case's parameters, as the resuming cases pass them to run_main."""

    cell_pressure: float = 75e3
    seed: int = 1
    seeds: tuple = (1, 2)
    threads: int = 0
    workers: int = 1


CKPT = ("ckpt.h5", "jobs/*.json")


def _interrupted(out: Path, p: P, payload: bytes = b"state of seed 1") -> None:
    """A run of ``p`` that wrote its checkpoint and a job file, then was interrupted."""
    def work(o):
        (o / "ckpt.h5").write_bytes(payload)
        (o / "jobs").mkdir()
        (o / "jobs" / "a_s1.json").write_text('{"labels": []}')
        (o / "other.csv").write_text("1\n")
        raise KeyboardInterrupt

    assert rundir.run_main("triaxial", out, work, params=p, checkpoints=CKPT) == 130
    m = rundir.run_status(out)
    assert m["status"] == "interrupted"
    assert m["checkpoints"]["ckpt.h5"]["sha256"] == rundir.sha256_file(out / "ckpt.h5")
    assert set(m["checkpoints"]) == {"ckpt.h5", "jobs/a_s1.json"}


def _resume(out: Path, p: P, ran: list) -> int:
    return rundir.run_main("triaxial", out, lambda o: ran.append(o), params=p,
                           checkpoints=CKPT, keep=["ckpt.h5", "jobs/a_s1.json"])


def _files(out: Path) -> dict:
    return {str(f.relative_to(out)): f.read_bytes() for f in out.rglob("*") if f.is_file()
            and f.name != rundir.MANIFEST}


@pytest.mark.parametrize("change, message", [
    (dict(cell_pressure=100e3), "the parameter cell_pressure differs: 75000.0 in the earlier "
                                "run, 100000.0 now"),
    (dict(seed=2), "the parameter seed differs: 1 in the earlier run, 2 now"),
    (dict(seeds=(1, 2, 3)), "the parameter seeds differs: [1, 2] in the earlier run, [1, 2, 3] "
                            "now"),
])
def test_a_resume_with_other_parameters_is_refused_naming_the_first_difference(
        tmp_path, change, message):
    out = tmp_path / "r"
    _interrupted(out, P())
    before = _files(out)
    ran: list = []
    with pytest.raises(rundir.RunFolderError) as ei:
        _resume(out, replace(P(), **change), ran)
    msg = str(ei.value.code)
    assert message in msg and "--overwrite" in msg and "\n" not in msg, msg
    assert not ran and _files(out) == before  # nothing ran, nothing was removed


def test_a_resume_with_other_threads_or_workers_continues(tmp_path, capsys):
    out = tmp_path / "r"
    _interrupted(out, P())
    ran: list = []
    assert _resume(out, P(threads=4, workers=3), ran) == 0
    assert ran == [out] and (out / "ckpt.h5").read_bytes() == b"state of seed 1"
    assert not (out / "other.csv").exists()  # the run's other files were removed
    assert "--resume: kept ckpt.h5, jobs/a_s1.json" in capsys.readouterr().out
    m = rundir.run_status(out)
    assert m["status"] == "complete" and "ckpt.h5" in m["checkpoints"]


@pytest.mark.parametrize("name", ["ckpt.h5", "jobs/a_s1.json"])
def test_a_checkpoint_of_another_sample_copied_in_is_refused(tmp_path, name):
    """The checkpoint (or a job file) of another seed's run copied over this run's: refused
    by its SHA-256, naming the file; nothing is removed."""
    out, other = tmp_path / "r", tmp_path / "other"
    _interrupted(out, P())
    _interrupted(other, P(seed=2), payload=b"state of seed 2")
    (other / "jobs" / "a_s1.json").write_text('{"labels": ["x"]}')
    (out / name).write_bytes((other / name).read_bytes())
    before = _files(out)
    ran: list = []
    with pytest.raises(rundir.RunFolderError) as ei:
        _resume(out, P(), ran)
    msg = str(ei.value.code)
    assert f"--resume: {name} is not the file this run wrote (SHA-256" in msg, msg
    assert not ran and _files(out) == before


def test_a_checkpoint_with_no_recorded_checksum_is_refused(tmp_path):
    out = tmp_path / "r"
    _interrupted(out, P())
    m = rundir.run_status(out)
    del m["checkpoints"]["ckpt.h5"]
    (out / rundir.MANIFEST).write_text(json.dumps(m))
    with pytest.raises(rundir.RunFolderError) as ei:
        _resume(out, P(), [])
    assert "ckpt.h5 has no SHA-256 in the run's record" in str(ei.value.code)


def test_a_run_without_recorded_parameters_is_not_resumed(tmp_path):
    """A run an older version wrote (no parameters in its manifest) cannot be told to be the
    same run."""
    out = tmp_path / "r"
    _interrupted(out, P())
    m = rundir.run_status(out)
    del m["params"]
    (out / rundir.MANIFEST).write_text(json.dumps(m))
    with pytest.raises(rundir.RunFolderError) as ei:
        _resume(out, P(), [])
    assert "the earlier run recorded no parameters" in str(ei.value.code)


def test_a_resume_of_a_completed_run_says_so_and_does_not_run(tmp_path, capsys):
    out = tmp_path / "r"
    assert rundir.run_main("triaxial", out, lambda o: (o / "ckpt.h5").write_bytes(b"s"),
                           params=P(), checkpoints=CKPT) == 0
    before, manifest = _files(out), rundir.run_status(out)
    ran: list = []
    assert _resume(out, P(), ran) == 0
    assert not ran and _files(out) == before and rundir.run_status(out) == manifest
    assert "--resume: the run is already complete" in capsys.readouterr().out
    with pytest.raises(rundir.RunFolderError) as ei:  # other parameters: refused all the same
        _resume(out, P(cell_pressure=1.0), ran)
    assert "the parameter cell_pressure differs" in str(ei.value.code)


def test_a_checkpoint_is_recorded_while_the_run_goes_on(tmp_path):
    """Its SHA-256 is in the manifest within about a second of its writing (a run killed
    after that can be resumed from it), not only when the run ends."""
    seen = {}

    def work(o):
        (o / "ckpt.h5").write_bytes(b"written once")
        t0 = time.time()
        while time.time() - t0 < 5:
            rec = (rundir.run_status(o) or {}).get("checkpoints", {})
            if "ckpt.h5" in rec:
                seen.update(rec["ckpt.h5"], status=rundir.run_status(o)["status"])
                return
            time.sleep(0.05)

    assert rundir.run_main("triaxial", tmp_path / "r", work, params=P(),
                           checkpoints=CKPT) == 0
    assert seen.get("status") == "running", seen
    assert seen["sha256"] == rundir.sha256_file(tmp_path / "r" / "ckpt.h5")


def _completed_manifest(out: Path, case: str, params) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / rundir.MANIFEST).write_text(json.dumps({
        "status": "complete", "complete": True, "case": case, "started": "2026-01-01",
        "finished": "2026-01-01", "params": rundir.params_record(params), "files": []}))


@pytest.mark.parametrize("module, argv", [
    ("triaxial", ["--smoke"]),
    ("prs_element_002", ["--smoke", "--stresses", "20000,20000,40000"]),
])
def test_the_resuming_cases_say_already_complete_and_exit_0(tmp_path, module, argv):
    """--resume on a completed run of the case (its parameters recorded): one line, exit
    status 0, at once (the 002 case once hung there); with another parameter: refused."""
    import importlib

    mod = importlib.import_module(f"geogrid_dem.cases.{module}")
    out = tmp_path / "done"
    p, _ = mod.parse_args([*argv, "--out", str(out), "--resume"])
    p.__dict__.pop("resume", None)
    _completed_manifest(out, module, p)
    cmd = [PY, "-m", f"geogrid_dem.cases.{module}", *argv, "--out", str(out), "--resume"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "--resume: the run is already complete" in r.stdout
    assert sorted(f.name for f in out.iterdir()) == [rundir.MANIFEST]
    r = subprocess.run([*cmd, "--seed", "7"] if module == "triaxial" else
                       [*cmd, "--gravity", "5"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "--resume: the parameter" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


# ---- work is estimated before it starts; options take effect or are refused --------------------

def _refused(module: str, argv: list[str], capsys) -> str:
    import importlib

    mod = importlib.import_module(f"geogrid_dem.cases.{module}")
    with pytest.raises(SystemExit) as ei:
        mod.parse_args(argv)
    assert ei.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    return err[-1]


CAPPED = [
    ("prs_element_002", ["--smoke", "--seeds", "1-100000"],
     "--seeds='1-100000': 100000 seeds, more than the cap of 100 seeds; add --allow-large"),
    ("prs_element_002", ["--smoke", "--n", "300000"], "--n=300000: 300000 grains, more than "
                                                       "the cap of 200000 grains"),
    ("footing_multiscale", ["--smoke", "--seeds", "100000"], "--seeds=100000: 100000 seeds"),
    ("footing_multiscale", ["--smoke", "--cell-grains", "100000000"],
     "--cell-grains=100000000: 100000000 grains an element, more than the cap of 200000"),
    ("footing_multiscale", ["--smoke", "--variants", "RE", "--band-grains", "1000000"],
     "--band-grains=1000000: 1000000 grains an element"),
    ("prs_element", ["--smoke", "--hierarchical", "--cell-elements", "--cell-grains",
                     "100000000"], "--cell-grains=100000000: 100000000 grains an element"),
    ("triaxial", ["--smoke", "--n", "1000000"], "--n=1000000: 1000000 grains"),
    ("triaxial", ["--smoke", "--grain-scale", "0.05"],
     "--n/--grain-scale=300/0.05: about 2.4e+06 grains"),
    ("pullout_000", ["--smoke", "--spheres", "500000"], "--spheres=500000: 500000 grains in "
                                                         "the largest run"),
    ("pullout_001", ["--smoke", "--study", "--jitter", "0.1", "--seeds", "1-100000"],
     "--seeds='1-100000': 100000 seeds, more than the cap of 100 seeds"),
    ("pullout_001", ["--smoke", "--radius", "1e-4"], "--radius=0.0001: about 1.13e+07 grains"),
    ("deposition", ["--smoke", "--n", "10000000"], "--n=10000000: 10000000 grains"),
]


@pytest.mark.parametrize("module, argv, message", CAPPED,
                         ids=[f"{m}:{' '.join(a[1:])}" for m, a, _ in CAPPED])
def test_work_above_a_cap_is_refused_naming_the_count_the_cap_and_the_flag(
        module, argv, message, capsys):
    line = _refused(module, argv, capsys)
    assert message in line and "add --allow-large to run it" in line, line


@pytest.mark.parametrize("module, argv", [
    ("prs_element_002", ["--smoke", "--seeds", "1-150", "--stresses", "2e4,2e4,4e4"]),
    ("footing_multiscale", ["--smoke", "--seeds", "150"]),
    ("triaxial", ["--smoke", "--n", "300000"]),
    ("pullout_001", ["--smoke", "--study", "--jitter", "0.1", "--seeds", "1-150"]),
    ("deposition", ["--smoke", "--n", "300000"]),
])
def test_allow_large_lifts_the_cap(module, argv):
    import importlib

    mod = importlib.import_module(f"geogrid_dem.cases.{module}")
    mod.parse_args([*argv, "--allow-large"])


def test_a_seed_range_beyond_the_cap_is_refused_before_it_is_made():
    """(a range of 10^12 seeds would fill the memory before being counted)"""
    import importlib

    mod = importlib.import_module("geogrid_dem.cases.prs_element_002")
    t0 = time.perf_counter()
    with pytest.raises(SystemExit):
        mod.parse_args(["--smoke", "--seeds", "1-1000000000000"])
    assert time.perf_counter() - t0 < 5


UNUSED = [
    ("prs_element_002", ["--smoke", "--seeds", ""], "--seeds='': must be 'A-B' (A <= B) or a "
                                                    "comma-separated list"),
    ("prs_element_002", ["--smoke", "--seeds", "1,2,1"], "--seeds='1,2,1': 1 is listed twice"),
    ("prs_element_002", ["--smoke", "--variants", "RE,PRS,RE"],
     "--variants='RE,PRS,RE': RE is listed twice"),
    ("prs_element_002", ["--smoke", "--grids", "standard,standard"],
     "--grids='standard,standard': standard is listed twice"),
    ("prs_element_002", ["--smoke", "--variants", "RE", "--prestress", "3000"],
     "--prestress=3000.0: has no effect without the PRS variant (--variants RE)"),
    ("prs_element_002", ["--smoke", "--seeds", "1-2", "--seed", "3"],
     "--seed=3: has no effect with --seeds 1-2"),
    ("prs_element_002", ["--smoke", "--stresses", "2e4,2e4,4e4", "--footing-pressure", "5e4"],
     "--footing-pressure=50000.0: has no effect with --stresses"),
    ("prs_element_002", ["--smoke", "--preset", "fast", "--density-scaling", "2"],
     "--preset fast with --density-scaling=2.0"),
    ("prs_element_002", ["--smoke", "--seeds", "3", "--workers", "2"],
     "--workers=2: has no effect with one packing (grid detailed, seed 3)"),
    ("prs_element_002", ["--smoke", "--out", "x", "--resume", "--overwrite"],
     "--resume and --overwrite: choose one"),
    ("footing_multiscale", ["--smoke", "--variants", "unreinforced", "--prestress", "100"],
     "--prestress=100.0: has no effect without the PRS variant (--variants unreinforced)"),
    ("footing_multiscale", ["--smoke", "--variants", "unreinforced,RE", "--prestress", "100"],
     "--prestress=100.0: has no effect without the PRS variant"),
    ("footing_multiscale", ["--smoke", "--variants", "unreinforced", "--grid-stiffness", "1e5"],
     "--grid-stiffness=100000.0: has no effect without a reinforced variant"),
    ("footing_multiscale", ["--smoke", "--variants", "unreinforced", "--layer-depth", "0.2"],
     "--layer-depth=0.2: has no effect without a reinforced variant"),
    ("footing_multiscale", ["--smoke", "--band-tangent", "fd-forward"],
     "--band-tangent=fd-forward: has no effect without band RVEs (--band-grains 0"),
    ("footing_multiscale", ["--smoke", "--variants", "RE,PRS,RE"],
     "--variants='RE,PRS,RE': RE is listed twice"),
    ("prs_element", ["--smoke", "--stresses", "2e4,2e4,4e4", "--prestress", "100"],
     "--prestress=100.0: has no effect with --stresses and no --prs"),
    ("prs_element", ["--smoke", "--stresses", "2e4,2e4,4e4", "--footing-pressure", "1e5"],
     "--footing-pressure=100000.0: has no effect with --stresses"),
    ("prs_element", ["--smoke", "--stresses", "2e4,2e4,4e4", "--workers", "2"],
     "--workers=2: has no effect with --stresses (one element runs)"),
    ("prs_element", ["--smoke", "--tol", "0.1"], "--tol=0.1: has no effect without --two-way"),
    ("prs_element", ["--smoke", "--max-iterations", "3"],
     "--max-iterations=3: has no effect without --two-way"),
    ("prs_element", ["--smoke", "--tangent-probe", "0.1"],
     "--tangent-probe=0.1: has no effect without --two-way"),
    ("prs_element", ["--smoke", "--two-way", "--two-way-element", "periodic",
                     "--tangent-probe", "0.1"],
     "--tangent-probe=0.1: has no effect with --two-way-element periodic"),
    ("prs_element", ["--smoke", "--two-way", "--preset", "fast", "--tol", "0.1"],
     "--tol=0.1: has no effect with --preset fast"),
    ("triaxial", ["--smoke", "--packing-format", "yade"],
     "--packing-format=yade: has no effect without --packing"),
    ("triaxial", ["--smoke", "--preset", "fast", "--strain-rate", "0.3"],
     "--strain-rate=0.3: has no effect with --preset fast"),
    ("triaxial", ["--smoke", "--geogrid", "square", "--clear-layer"],
     "--clear-layer: has no effect with --geogrid square"),
    ("pullout_000", ["--smoke", "--spheres", "3000,6000,3000"],
     "--spheres=3000,6000,3000: 3000 is listed twice"),
    ("pullout_000", ["--smoke", "--preset", "fast", "--velocity", "0.1"],
     "--velocity=0.1: has no effect with --preset fast"),
    ("pullout_001", ["--smoke", "--radius", ""], "--radius='': expected a number"),
    ("pullout_001", ["--smoke", "--pressure", ""], "--pressure='': expected a number"),
    ("pullout_001", ["--smoke", "--study", "--radius", "1e-3,2e-3,1e-3"],
     "--radius=1e-3,2e-3,1e-3: 0.001 is listed twice"),
    ("pullout_001", ["--smoke", "--study", "--grids", "square,square"],
     "--grids=square,square: square is listed twice"),
    ("pullout_001", ["--smoke", "--grids", "square"], "--grids=square: has no effect without "
                                                       "--study"),
    ("pullout_001", ["--smoke", "--study", "--grid", "triangular"],
     "--grid=triangular: has no effect with --study"),
    ("pullout_001", ["--smoke", "--study", "--jitter", "0.1", "--seeds", "1-3", "--seed", "2"],
     "--seed=2: has no effect with --seeds 1-3"),
    ("pullout_001", ["--smoke", "--grains", "clumps:gravel_a", "--jitter", "0.1"],
     "--jitter=0.1: has no effect with --grains clumps:gravel_a"),
]


@pytest.mark.parametrize("module, argv, message", UNUSED,
                         ids=[f"{m}:{' '.join(a[1:])}" for m, a, _ in UNUSED])
def test_an_option_without_effect_or_listed_twice_is_refused_by_name(module, argv, message,
                                                                      capsys):
    line = _refused(module, argv, capsys)
    assert message in line, line


def test_packing_options_that_a_packing_replaces_are_refused(tmp_path, capsys):
    f = tmp_path / "p.csv"
    f.write_text("x,y,z,r\n")
    for flag, value in (("--n", "500"), ("--seed", "4"), ("--grain-scale", "2"),
                        ("--prep-friction", "5")):
        line = _refused("triaxial", ["--smoke", "--packing", str(f), flag, value], capsys)
        assert line.split("error: ")[1].startswith(f"{flag}=") and "has no effect with "\
            "--packing" in line, line


def test_options_at_their_default_value_given_explicitly_count_as_given(capsys):
    """(given, not different from the default: a run file that writes the default out is
    refused the same way)"""
    from geogrid_dem.studies.footing_multiscale import FootingParams

    line = _refused("footing_multiscale", ["--smoke", "--variants", "RE", "--prestress",
                                           str(FootingParams().prestress)], capsys)
    assert "has no effect without the PRS variant" in line


def test_a_name_that_is_not_utf8_is_refused(tmp_path, capsys):
    line = _refused("deposition", ["--smoke", "--out", str(tmp_path) + "/r\udcff"], capsys)
    assert "--out=" in line and "not valid UTF-8 text" in line, line


# ---- errors in words: calibration files ------------------------------------------------------

_CAL = """out = "cal"
[params]
smoke = true
[reference]
young = 4200e3
poisson = 0.31
phi = 31.5
[grid]
young = [4000e3, 4500e3]
poisson = [0.3]
phi = [31.0]
"""


def _cal(tmp_path: Path, text: str) -> Path:
    f = tmp_path / "c.toml"
    f.write_text(text)
    return f


BAD_CAL = [
    (_CAL.replace('out = "cal"', "out = 5"), "field 'out'=5: must be a folder name"),
    (_CAL.replace("[params]\nsmoke = true\n", "params = 3\n"),
     "field 'params'=3: must be a table [params]"),
    (_CAL.replace("young = [4000e3, 4500e3]", 'young = ["a"]'),
     "field 'grid.young' has 'a': each must be a finite number > 0 (Pa)"),
    (_CAL.replace("young = [4000e3, 4500e3]", "young = [4000e3, nan]"),
     "field 'grid.young' has nan: each must be a finite number > 0"),
    (_CAL.replace("young = [4000e3, 4500e3]", "young = [-4000e3]"),
     "field 'grid.young' has -4000000.0: each must be a finite number > 0"),
    (_CAL.replace("young = [4000e3, 4500e3]", "young = [4000e3, 4000e3]"),
     "field 'grid.young' lists 4000000.0 twice"),
    (_CAL.replace("phi = [31.0]", "phi = [95.0]"), "field 'grid.phi' has 95.0: each must be a "
                                                    "number in (0, 90) (deg)"),
    (_CAL.replace("phi = [31.0]\n", ""), "field 'grid.phi' is missing"),
    (_CAL.replace("phi = 31.5", 'phi = "steep"'), "field 'reference.phi'='steep': must be a "
                                                  "number in (0, 90) (deg)"),
    (_CAL.replace("young = 4200e3", "young = -1.0"),
     "field 'reference.young'=-1.0: must be a finite number > 0"),
    (_CAL.replace("young = 4200e3\npoisson = 0.31\nphi = 31.5", 'csv = "nowhere.csv"'),
     "field 'reference.csv'='nowhere.csv': no such file"),
    (_CAL.replace("young = 4200e3\n", 'csv = "nowhere.csv"\n'),
     "field 'reference.poisson': has no effect with reference.csv"),
    ("grid = 3\n" + _CAL.split("[grid]")[0], "field 'grid'=3: must be a table [grid]"),
    ("reference = 3\n" + _CAL.replace("[reference]\nyoung = 4200e3\npoisson = 0.31\n"
                                      "phi = 31.5\n", ""),
     "field 'reference'=3: must be a table [reference]"),
    ("out = [", "not valid TOML"),
]


@pytest.mark.parametrize("text, message", BAD_CAL, ids=[m[:40] for _, m in BAD_CAL])
def test_a_bad_calibration_file_is_one_line_naming_the_field(tmp_path, text, message):
    from geogrid_dem.calibrate import Config

    with pytest.raises(ValueError) as ei:
        Config.load(_cal(tmp_path, text))
    assert message in str(ei.value) and "\n" not in str(ei.value), str(ei.value)


def test_a_calibration_file_that_cannot_be_read_is_named(tmp_path):
    from geogrid_dem.calibrate import Config

    (tmp_path / "bin.toml").write_bytes(b'out = "\xff"\n')
    with pytest.raises(ValueError, match="bin.toml: not UTF-8 text"):
        Config.load(tmp_path / "bin.toml")
    with pytest.raises(ValueError, match="is a folder, not a calibration file"):
        Config.load(tmp_path)


def test_a_calibration_grid_above_the_cap_needs_allow_large(tmp_path):
    from geogrid_dem.calibrate import Config

    big = _CAL.replace("young = [4000e3, 4500e3]",
                       "young = [" + ", ".join(f"{1e6 + 1e3 * k:g}" for k in range(100)) + "]")
    big = big.replace("poisson = [0.3]", "poisson = [" + ", ".join(
        f"{0.001 + 0.004 * k:.3f}" for k in range(100)) + "]")
    big = big.replace("phi = [31.0]", "phi = [" + ", ".join(
        f"{1 + 0.5 * k:g}" for k in range(100)) + "]")
    f = _cal(tmp_path, big)
    with pytest.raises(ValueError) as ei:
        Config.load(f)
    assert ("field 'grid': 100 x 100 x 100 = 1000000 points (a triaxial run each), more than "
            "the cap of 1000 grid points; add --allow-large to run it") in str(ei.value)
    assert len(Config.load(f, allow_large=True).grid["phi"]) == 100
    p = subprocess.run([PY, "-m", "geogrid_dem.cli", "calibrate", str(f), "--workers", "0"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert p.returncode == 1 and "1000000 points" in p.stderr and "Traceback" not in p.stderr
    assert not (tmp_path / "cal").exists()


# ---- run files ---------------------------------------------------------------------------------

def test_run_toml_is_valid_toml_for_any_text(tmp_path):
    from geogrid_dem.runs import argv_to_params, params_to_argv, write_run_file

    argv = ["--smoke", "--out", "results/r\U0001F600 é \"q\" \\ tab\tend", "--box=-0.1,0,0,1,1,1",
            "--cell-pressure", "1e5", "--resume"]
    write_run_file(tmp_path, "triaxial", argv_to_params(argv))
    data = tomllib.loads((tmp_path / "run.toml").read_text(encoding="utf-8"))
    assert data["params"]["out"] == "results/r\U0001F600 é \"q\" \\ tab\tend"
    assert data["params"]["box"] == "-0.1,0,0,1,1,1"
    assert "resume" not in data["params"]  # (a run file runs the whole run)
    back = params_to_argv(data["params"], source="run.toml")
    assert "--box=-0.1,0,0,1,1,1" in back  # (not taken by argparse for an option)
    assert back[back.index("--out") + 1] == argv[2]


def test_a_run_into_a_folder_named_with_an_emoji_writes_a_readable_run_toml(tmp_path):
    out = tmp_path / "run \U0001F600"
    p = subprocess.run([PY, "-m", "geogrid_dem.cli", "run", "deposition", "--smoke", "--n",
                        "20", "--duration", "0.01", "--threads", "1", "--out", str(out)],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    data = tomllib.loads((out / "run.toml").read_text(encoding="utf-8"))
    assert data["case"] == "deposition" and data["params"]["out"] == str(out)


def test_a_002_run_stopped_in_its_calibration_resumes_at_the_next_pass(tmp_path, capsys):
    """prs-element-002 interrupted during its soil calibration (no packing finished yet):
    --resume keeps the calibration's record of its finished passes and the grown packings
    (checkpoints, by their SHA-256) and the files of those passes, and removes the unfinished
    pass's files; before,
    it refused ("jobs/detailed_s1.json is not there") and a full-size run lost hours."""
    from geogrid_dem.cases import prs_element_002 as case

    out = tmp_path / "r"

    def work(o):
        fem = o / "fem_detailed"
        fem.mkdir()
        (fem / "calibration_passes.json").write_text(json.dumps({"passes": [{"k": 1}]}))
        for name in ("calibration_RE_s1_1.csv", "calibration_RE_s2_1_final.h5",
                     "calibration_RE_s1_2_growth.csv", "fem_RE.h5", "packing_s1.h5"):
            (fem / name).write_text(name)
        raise KeyboardInterrupt

    assert rundir.run_main("prs_element_002", out, work, params=P(),
                           checkpoints=case.CHECKPOINTS) == 130
    assert "fem_detailed/calibration_passes.json" in rundir.run_status(out)["checkpoints"]
    keep = case.resume_keep(out)
    assert keep == ["fem_detailed/packing_s1.h5", "fem_detailed/calibration_passes.json",
                    "fem_detailed/calibration_RE_s1_1.csv",
                    "fem_detailed/calibration_RE_s2_1_final.h5"], keep
    ran: list = []
    assert rundir.run_main("prs_element_002", out, lambda o: ran.append(o), params=P(),
                           checkpoints=case.CHECKPOINTS, keep=keep) == 0
    assert ran == [out]
    left = sorted(str(f.relative_to(out)) for f in (out / "fem_detailed").iterdir())
    assert left == sorted(keep)  # the unfinished pass 2 and its FEM run are gone
    # a passes record changed since it was written is refused by its SHA-256
    out2 = tmp_path / "r2"
    assert rundir.run_main("prs_element_002", out2, work, params=P(),
                           checkpoints=case.CHECKPOINTS) == 130
    (out2 / "fem_detailed" / "calibration_passes.json").write_text('{"passes": [1, 2]}')
    with pytest.raises(rundir.RunFolderError, match="calibration_passes.json is not the file "
                                                     "this run wrote"):
        rundir.run_main("prs_element_002", out2, lambda o: None, params=P(),
                        checkpoints=case.CHECKPOINTS, keep=case.resume_keep(out2))
