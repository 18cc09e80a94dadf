"""The geogrid-dem command: cases, run files (validated, written back into every results
folder) and sweeps on Dask (results table, resume)."""

import csv
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def cli(*args, cwd=None):
    exe = shutil.which("geogrid-dem", path=str(Path(sys.executable).parent))
    cmd = [exe] if exe else [sys.executable, "-m", "geogrid_dem.cli"]
    return subprocess.run([*cmd, *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, env={**os.environ, "OMP_NUM_THREADS": "1"})


def test_the_command_is_installed_and_lists_the_cases():
    assert shutil.which("geogrid-dem", path=str(Path(sys.executable).parent)), \
        "pip install -e . installs the console script geogrid-dem"
    r = cli("--version")
    assert r.returncode == 0 and "geogrid-dem, version" in r.stdout
    r = cli("cases")
    assert r.returncode == 0
    for name in ("pullout-000", "pullout-001", "triaxial", "prs-element", "deposition"):
        assert name in r.stdout


def test_run_a_case_writes_a_rerunnable_run_file(tmp_path):
    out = tmp_path / "tri"
    r = cli("run", "triaxial", "--smoke", "--out", out, "--seed", 3, "--threads", 1)
    assert r.returncode == 0, r.stderr
    assert (out / "summary.json").exists()
    with open(out / "run.toml", "rb") as f:
        run = tomllib.load(f)
    assert run["case"] == "triaxial"
    assert run["params"]["smoke"] is True and run["params"]["seed"] == 3
    assert run["params"]["out"] == str(out)
    assert run["provenance"]["version"] and run["provenance"]["commit"]
    # The run file runs it again (into another folder).
    out2 = tmp_path / "again"
    r = cli("run", out / "run.toml", "--out", out2)
    assert r.returncode == 0, r.stderr
    assert (out2 / "summary.json").exists()


@pytest.mark.parametrize("text, expect", [
    ('case = "triax"\n', "case='triax': no such case; allowed: pullout-000"),
    ('case = "triaxial"\nsmoke = true\n', "field 'smoke' is not known"),
    ('case = "triaxial"\n[params]\nsmoke = true\ncel-pressure = 1e5\n',
     r"field 'cel-pressure': not a parameter of the case 'triaxial' \(did you mean "
     r"cell-pressure\?\)"),
    ('case = "triaxial"\n[params]\nsmoke = {a = 1}\n', "field 'smoke'="),
    ('case = "triaxial"\n[params\n', "not valid TOML"),
])
def test_a_bad_run_file_names_the_field(tmp_path, text, expect):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    r = cli("run", f)
    assert r.returncode != 0
    import re
    assert re.search(expect, r.stderr), r.stderr


def test_sweep_runs_rows_on_dask_gathers_results_and_resumes(tmp_path):
    out = tmp_path / "sweep"
    f = tmp_path / "sweep.toml"
    f.write_text(f'case = "triaxial"\nout = "{out}"\n[params]\nsmoke = true\n'
                 '[sweep]\nmode = "list"\nseed = [1, 2]\n')
    r = cli("sweep", f, "--workers", 2)
    assert r.returncode == 0, r.stderr + r.stdout
    assert "2 rows, 0 finished before, 2 to run" in r.stdout and "ETA" in r.stdout
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [row["param.seed"] for row in sorted(rows, key=lambda x: x["row"])] == ["1", "2"]
    assert all(row["status"] == "ok" for row in rows)
    assert any(k.startswith("summary.") for k in rows[0])  # the case's numbers
    # Different seeds, different samples: the rows are not copies of each other.
    summaries = {tuple(v for k, v in row.items() if k.startswith("summary.")) for row in rows}
    assert len(summaries) == 2
    stamp = (out / "row_000" / "summary.json").stat().st_mtime_ns
    # Resume: both rows are finished, nothing runs again.
    r = cli("sweep", f, "--workers", 1)
    assert r.returncode == 0, r.stderr
    assert "2 finished before, 0 to run" in r.stdout
    assert (out / "row_000" / "summary.json").stat().st_mtime_ns == stamp


def test_sweep_file_errors_name_the_field(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('case = "triaxial"\nout = "x"\n[sweep]\nmode = "list"\nseed = [1, 2]\n'
                 'cell-pressure = [1e5]\n')
    r = cli("sweep", f)
    assert r.returncode != 0 and "must have equal lengths" in r.stderr
    f.write_text('case = "triaxial"\n[sweep]\nseed = [1]\n')
    r = cli("sweep", f)
    assert r.returncode != 0 and "field 'out' is missing" in r.stderr


def test_scene_run_progress_prints_an_eta(capsys):
    import cpp_dem as dem

    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_spheres([[0, 0, 0]], [0.005], material=m)
    s.dt = 1e-5
    s.run(100, every=50, progress=True, label="demo")
    out = capsys.readouterr().out
    assert "[demo] step 50/100" in out and "ETA" in out


# ---- one command-line style ----------------------------------------------------------------

def _option_helps(text: str) -> dict[str, str]:
    """An argparse --help text's options and their (joined) help lines."""
    helps, cur = {}, None
    for line in text.splitlines():
        m = re.match(r"^  (-\S.*?)(?:\s{2,}(.*))?$", line)
        if m:
            cur = m.group(1).split(", ")[0].split()[0]
            helps[cur] = (m.group(2) or "").strip()
        elif cur and line.startswith("      "):
            helps[cur] += " " + line.strip()
        elif not line.strip():
            cur = None
    return helps


def _doubled(helps: dict[str, str]) -> list[str]:
    return [k for k, h in helps.items()
            if len(re.findall(r"\(default", h)) > 1 or "(default: None)" in h
            or "(default: )" in h]


def test_the_help_checker_finds_a_doubled_default():
    text = ("options:\n  --tol TOL   tolerance (default 0.1) (default: None)\n"
            "  --n N       grains (default: 3)\n")
    helps = _option_helps(text)
    assert helps["--n"] == "grains (default: 3)"
    assert _doubled(helps) == ["--tol"]


@pytest.mark.parametrize("case", ["pullout-000", "pullout-001", "triaxial", "prs-element",
                                  "prs-element-002", "deposition"])
def test_every_case_has_one_help_style(case):
    r = cli("run", case, "--help")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"usage: geogrid-dem run {case} ")
    helps = _option_helps(r.stdout)
    assert not _doubled(helps), _doubled(helps)
    for flag in ("--smoke", "--out", "--overwrite", "--seed", "--threads"):
        assert helps.get(flag), f"{case}: {flag} has no help line"
    # --threads means the same everywhere: 0 is automatic (cpp_dem.apply_threads)
    assert "0: automatic (OMP_NUM_THREADS when set; else one thread for a small scene" \
        in helps["--threads"]
    from geogrid_dem.cases import CASES

    if CASES[case].study:  # the study is named by its title, not a number
        assert CASES[case].study.split()[0] in r.stdout
    assert not re.search(r"\b00[012]\b", r.stdout.replace(case, "")), r.stdout


def test_the_case_scripts_parse_with_the_same_parser():
    from geogrid_dem.cases import CASES
    from geogrid_dem.runs import case_parser

    for name, case in CASES.items():
        r = subprocess.run([sys.executable, str(ROOT / "cases" / f"{case.module}.py"), "--help"],
                           capture_output=True, text=True)
        assert r.returncode == 0 and r.stdout == case_parser(name).format_help(), name


def test_ctrl_c_in_each_command_exits_130_with_one_line(tmp_path, monkeypatch, capsys):
    """A KeyboardInterrupt inside calibrate and sweep ends the command with status 130 and one
    line on stderr (no traceback): the message is printed the way the command prints."""
    from geogrid_dem import calibrate as cal
    from geogrid_dem import cli

    f = tmp_path / "c.toml"
    f.write_text('out = "cal"\n[params]\nsmoke = true\n[reference]\nyoung = 4200e3\n'
                 'poisson = 0.31\nphi = 31.5\n[grid]\nyoung = [4000e3]\npoisson = [0.3]\n'
                 'phi = [31.0]\n')
    monkeypatch.chdir(tmp_path)

    def interrupted(*_a, **_k):
        raise KeyboardInterrupt

    monkeypatch.setattr(cal, "calibrate", interrupted)
    with pytest.raises(SystemExit) as e:
        cli.main(["calibrate", str(f), "--workers", "0"])
    assert e.value.code == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("[calibrate] interrupted"), err

    s = tmp_path / "s.toml"
    s.write_text('case = "deposition"\nout = "sw"\n[params]\nsmoke = true\n[sweep]\n'
                 'seed = [1, 2]\n')
    monkeypatch.setattr(cli, "_run_on_dask", interrupted)
    with pytest.raises(SystemExit) as e:
        cli.main(["sweep", str(s)])
    assert e.value.code == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("[sweep] interrupted"), err


def test_a_completed_run_that_exits_with_a_coupling_status_keeps_its_run_file(tmp_path,
                                                                               monkeypatch):
    """A coupled case that completes but did not converge exits 3, 4 or 5
    (femcoupling.coupling.status.EXIT_CODES): its folder still gets run.toml, as a converged run's;
    a run that failed gets none."""
    from geogrid_dem import cli as gcli
    from geogrid_dem import rundir

    def completed(case, argv, source=None, code=4, state="complete"):
        out = Path(argv[argv.index("--out") + 1])
        rundir.begin_run(out, case, log=lambda m: None)
        (out / "summary.json").write_text("{}\n")
        rundir.end_run(out, state)
        return code

    out = tmp_path / "stalled"
    monkeypatch.setattr(gcli, "run_case", completed)
    with pytest.raises(SystemExit) as e:
        gcli.run_cmd("triaxial", ["--smoke", "--out", str(out)])
    assert e.value.code == 4
    assert (out / "run.toml").is_file()
    out = tmp_path / "failed"
    monkeypatch.setattr(gcli, "run_case",
                        lambda c, a, source=None: completed(c, a, code=1, state="failed"))
    with pytest.raises(SystemExit):
        gcli.run_cmd("triaxial", ["--smoke", "--out", str(out)])
    assert not (out / "run.toml").exists()


@pytest.mark.parametrize("var", ["PMI_SIZE", "OMPI_COMM_WORLD_SIZE"])
def test_a_case_started_as_several_mpi_ranks_is_refused(tmp_path, monkeypatch, capsys, var):
    """Under ``mpiexec -n 2`` every rank would run a case whole and write the same results:
    each case refuses it before it starts (its launcher's environment, read without MPI)."""
    from geogrid_dem.cases import footing_multiscale, triaxial
    from geogrid_dem.rundir import mpi_ranks

    assert mpi_ranks() == 1
    monkeypatch.setenv(var, "2")
    assert mpi_ranks() == 2
    for mod in (triaxial, footing_multiscale):
        with pytest.raises(SystemExit) as e:
            mod.main(["--smoke", "--out", str(tmp_path / mod.__name__)])
        assert e.value.code == 2
        assert "started as 2 MPI ranks (mpiexec -n 2)" in capsys.readouterr().err
        assert not (tmp_path / mod.__name__).exists()
    monkeypatch.setenv(var, "1")
    assert mpi_ranks() == 1


def test_a_run_file_keeps_out_as_given_or_leaves_the_numbered_folder_out(tmp_path, monkeypatch):
    """run.toml keeps a relative --out relative (as given), and leaves out the default
    numbered folder: copied elsewhere, the run file reruns into a new folder of its own."""
    from geogrid_dem import cli as cli_mod

    ran = []
    monkeypatch.setattr(cli_mod, "run_case",
                        lambda case, argv, source=None: ran.append(list(argv)) or 0)
    monkeypatch.chdir(tmp_path)

    def params(path):
        with open(path, "rb") as f:
            return tomllib.load(f)["params"]

    cli_mod.run_cmd("triaxial", ["--smoke", "--out", "rel/t1"])
    assert params(tmp_path / "rel" / "t1" / "run.toml")["out"] == "rel/t1"

    cli_mod.run_cmd("triaxial", ["--smoke"])  # the default: results/triaxial/run_001
    first = tmp_path / "results" / "triaxial" / "run_001"
    assert "out" not in params(first / "run.toml")
    copy = tmp_path / "elsewhere" / "run.toml"
    copy.parent.mkdir()
    shutil.copy(first / "run.toml", copy)
    cli_mod.run_cmd(str(copy), [])
    second = tmp_path / "results" / "triaxial" / "run_002"
    assert ran[-1][-2:] == ["--out", str(Path("results/triaxial/run_002"))]
    assert params(second / "run.toml") == params(first / "run.toml") == {"smoke": True}
