"""Results folders, run files, sweeps and interrupted runs at the case level.

Most tests run a tiny deposition (20 spheres, about a second), interrupt a deposition smoke
early, or only parse arguments; one resumes the triaxial smoke (shared with the session's
case_smoke). docs/reliability.md, "Results folders and interrupted runs".
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
DEPOSITION = [PY, str(ROOT / "cases" / "deposition.py"), "--smoke", "--threads", "1"]
CLI = [PY, "-m", "geogrid_dem.cli"]
MANIFEST = ".geogrid-dem-run.json"
#: A deposition of 20 spheres for 0.01 s: every file of the case, in about a second.
TINY = ["--n", "20", "--duration", "0.01"]


def manifest(out: Path) -> dict:
    return json.loads((out / MANIFEST).read_text())


def run(args, cwd=None, timeout=300, **kw):
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout, cwd=cwd, **kw)


# ---- the results folder ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """One completed (tiny) deposition in a folder of its own."""
    out = tmp_path_factory.mktemp("dep") / "out"
    p = run([*DEPOSITION, *TINY, "--out", str(out)])
    assert p.returncode == 0, p.stderr
    return out


def _snapshot(out: Path) -> dict[str, float]:
    return {str(p.relative_to(out)): p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}


def test_a_completed_run_is_never_replaced_without_overwrite(first_run):
    m = manifest(first_run)
    assert m["status"] == "complete" and m["complete"] is True and m["files"]
    assert not (first_run / ".geogrid-dem.lock").exists()
    before = _snapshot(first_run)
    again = run([*DEPOSITION, *TINY, "--out", str(first_run)])
    assert again.returncode != 0
    assert f"--out={first_run}: holds a completed run of deposition" in again.stderr
    assert "--overwrite" in again.stderr
    assert _snapshot(first_run) == before  # not a file touched


def test_a_foreign_file_refuses_the_overwrite_before_anything_is_deleted(first_run, tmp_path):
    """The first defect of the audit: the earlier run's files were removed, then the foreign
    file made it refuse. Now the whole folder is checked first."""
    mine = first_run / "vtk" / "notes_of_mine.txt"
    mine.write_text("mine")
    try:
        before = _snapshot(first_run)
        p = run([*DEPOSITION, *TINY, "--out", str(first_run), "--overwrite"])
        assert p.returncode != 0
        assert "did not record (e.g. vtk/notes_of_mine.txt)" in p.stderr
        assert "Nothing was removed" in p.stderr
        assert _snapshot(first_run) == before
    finally:
        mine.unlink()


def test_overwrite_replaces_only_the_recorded_files(tmp_path):
    out = tmp_path / "o"
    assert run([*DEPOSITION, *TINY, "--out", str(out)]).returncode == 0
    old = manifest(out)["started"]
    time.sleep(1.1)
    p = run([*DEPOSITION, *TINY, "--out", str(out), "--overwrite"])
    assert p.returncode == 0, p.stderr
    assert "--overwrite: removed the" in p.stdout
    m = manifest(out)
    assert m["status"] == "complete" and m["started"] != old


def test_without_out_every_run_gets_a_new_numbered_folder(tmp_path):
    for _ in range(2):
        p = run([*DEPOSITION, *TINY], cwd=tmp_path)
        assert p.returncode == 0, p.stderr
    base = tmp_path / "results" / "deposition"
    assert sorted(d.name for d in base.iterdir()) == ["run_001", "run_002"]
    for d in base.iterdir():
        assert manifest(d)["status"] == "complete"
    assert f"results in {Path('results') / 'deposition' / 'run_002'}" in p.stdout


def test_a_live_lock_refuses_a_second_run_naming_the_holder(tmp_path):
    out = tmp_path / "locked"
    out.mkdir()
    holder = subprocess.Popen([PY, "-c", "import time; time.sleep(60)"])
    try:
        (out / ".geogrid-dem.lock").write_text(json.dumps(
            {"pid": holder.pid, "host": socket.gethostname(), "case": "triaxial",
             "started": "2026-01-01T00:00:00+00:00"}))
        p = run([*DEPOSITION, *TINY, "--out", str(out)])
        assert p.returncode != 0
        assert f"another run is writing into it: pid {holder.pid} on {socket.gethostname()}" \
            in p.stderr
    finally:
        holder.kill()
        holder.wait()
    # the holder is gone: its lock is stale and taken over, with a message
    p = run([*DEPOSITION, *TINY, "--out", str(out)])
    assert p.returncode == 0, p.stderr
    assert f"taking over the lock of pid {holder.pid}" in p.stdout
    assert manifest(out)["status"] == "complete"


def test_an_unwritable_or_file_out_is_a_clear_error(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    p = run([*DEPOSITION, "--out", str(f / "sub")])
    assert p.returncode == 2 and f"--out={f / 'sub'}: cannot be created: {f} is a file" \
        in p.stderr, p.stderr
    # a place nobody can create folders in (root included): /proc
    p = run([*DEPOSITION, *TINY, "--out", "/proc/geogrid_dem_no_such/x"])
    assert p.returncode == 1, p.stderr
    assert "--out=/proc/geogrid_dem_no_such/x: cannot be written into" in p.stderr
    assert "Traceback" not in p.stderr
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            p = run([*DEPOSITION, "--out", str(ro / "x")])
            assert p.returncode == 2 and "is not writable" in p.stderr, p.stderr
            assert "Traceback" not in p.stderr
        finally:
            ro.chmod(0o700)


# ---- interrupted runs and full disks -----------------------------------------------------------

def _interrupt_after(args, marker: str, timeout: float = 120.0, **kw):
    """Starts ``args``, sends SIGINT once ``marker`` appears on its stdout; returns
    (returncode, stdout, stderr)."""
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **kw)
    lines = []
    t0 = time.time()
    for line in proc.stdout:
        lines.append(line)
        if marker in line:
            proc.send_signal(signal.SIGINT)
            break
        assert time.time() - t0 < timeout
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, "".join(lines) + out, err


def test_sigint_in_the_middle_of_a_case_closes_its_files_and_marks_it_interrupted(tmp_path):
    from cpp_dem.io import read_csv_series, read_h5_series

    out = tmp_path / "i"
    # the second progress line: the run is under way, its recorders hold rows
    rc, so, se = _interrupt_after([*DEPOSITION, "--duration", "100", "--out", str(out)],
                                  "[deposition] t=")
    assert rc == 130, se
    assert "interrupted (SIGINT / Ctrl-C): the run is incomplete" in se
    assert f"the files written so far are in {out}" in se
    assert "Traceback" not in se
    m = manifest(out)
    assert m["status"] == "interrupted" and m["complete"] is False and "SIGINT" in m["reason"]
    assert not (out / ".geogrid-dem.lock").exists()
    h5 = read_h5_series(out / "deposition.h5")
    csv = read_csv_series(out / "deposition.csv")
    assert len(h5["time"]) >= 1 and len(csv["time"]) >= 1
    # the summary says so (deposition gives rundir.on_interrupt nothing: the minimal one)
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "interrupted" and "SIGINT" in s["reason"] and s["case"] == "deposition"
    assert {"deposition.h5", "deposition.csv", "summary.json"} <= set(s["files"])
    assert "summary.json" in m["files"]  # the run's file: an --overwrite removes it
    # an interrupted run is not replaced silently either
    p = run([*DEPOSITION, *TINY, "--out", str(out)])
    assert p.returncode != 0 and "holds an interrupted run of deposition" in p.stderr


def test_geogrid_dem_run_passes_130_on_and_forwards_sigint_to_the_case(tmp_path):
    out = tmp_path / "c"
    rc, so, se = _interrupt_after([*CLI, "run", "deposition", "--smoke", "--threads", "1",
                                   "--duration", "100", "--out", str(out)], "[deposition] t=",
                                  cwd=tmp_path)
    assert rc == 130, se
    assert manifest(out)["status"] == "interrupted"
    # the run file goes with the results, so the run can be made again (with --overwrite)
    assert 'case = "deposition"' in (out / "run.toml").read_text()


def test_geogrid_dem_run_forwards_sigint_when_started_with_it_ignored(tmp_path):
    """Started with SIGINT ignored (a shell's background job, a test runner's worker), the
    command still catches and forwards it, and the case it starts does not inherit the ignore:
    the forwarded Ctrl-C interrupts the case (it ran to its end, exit 0, when the command
    started the case before installing its handler)."""
    out = tmp_path / "c"
    rc, so, se = _interrupt_after([*CLI, "run", "deposition", "--smoke", "--threads", "1",
                                   "--duration", "100", "--out", str(out)], "[deposition] t=",
                                  cwd=tmp_path,
                                  preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert rc == 130, se
    assert manifest(out)["status"] == "interrupted"


_FSIZE = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # as a full disk: the write fails with EFBIG
resource.setrlimit(resource.RLIMIT_FSIZE, (700_000, 700_000))  # the h5 ends near 1 MB
sys.argv = ["deposition", *sys.argv[1:]]
from geogrid_dem.cases import deposition
sys.exit(deposition.main())
"""


def test_a_file_size_limit_names_the_file_and_marks_the_run_failed(tmp_path):
    out = tmp_path / "f"
    p = run([PY, "-c", _FSIZE, "--smoke", "--threads", "1", "--out", str(out)])
    assert p.returncode == 1, p.stderr
    err = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(err) == 1, p.stderr  # one line, no traceback, no HDF5 dump
    assert "could not be written: the file-size limit (ulimit -f) is reached (errno 27)" \
        in err[0]
    assert str(out) in err[0]
    m = manifest(out)
    assert m["status"] == "failed" and "could not be written" in m["reason"]
    assert not (out / ".geogrid-dem.lock").exists()
    # what was written before the limit stays readable
    from cpp_dem.io import read_csv_series, read_h5_series

    n_h5 = len(read_h5_series(out / "deposition.h5")["time"])
    assert n_h5 > 10 and len(read_csv_series(out / "deposition.csv")["time"]) >= n_h5


# ---- run files, sweeps and calibrations: checked before any work --------------------------------

def _toml(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_switch_given_a_string_names_the_field_and_what_is_allowed(tmp_path):
    f = _toml(tmp_path / "r.toml", 'case = "triaxial"\n[params]\nsmoke = "yes"\n')
    p = run([*CLI, "run", str(f)], cwd=tmp_path)
    assert p.returncode == 1
    assert "field smoke='yes': must be true or false" in p.stderr
    assert "unrecognized arguments" not in p.stderr
    assert not (tmp_path / "results").exists()  # refused before any folder was made


def test_a_misspelt_parameter_gets_a_did_you_mean_before_the_case_starts(tmp_path):
    f = _toml(tmp_path / "r.toml", 'case = "triaxial"\n[params]\nsmoke = true\n'
              'cel-pressure = 5e4\n')
    p = run([*CLI, "run", str(f)], cwd=tmp_path)
    assert p.returncode == 1
    assert "field 'cel-pressure': not a parameter of the case 'triaxial' (did you mean " \
        "cell-pressure?)" in p.stderr


def test_the_run_file_goes_where_the_results_go(tmp_path):
    a, b = tmp_path / "A", tmp_path / "B"
    tiny = [*TINY, "--threads", "1"]
    assert run([*CLI, "run", "deposition", *tiny, "--out", str(a)], cwd=tmp_path).returncode == 0
    record_a = (a / "run.toml").read_text()
    p = run([*CLI, "run", str(a / "run.toml"), "--out", str(b)], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert (a / "run.toml").read_text() == record_a  # A's record untouched
    assert f'out = "{b}"' in (b / "run.toml").read_text()
    assert manifest(b)["status"] == "complete"


def test_deposition_refuses_an_infinite_or_absurd_duration_with_the_estimate():
    p = run([*DEPOSITION, "--duration", "inf"])
    assert p.returncode == 2 and "--duration=inf: must be a finite number > 0 (s)" in p.stderr
    p = run([*DEPOSITION, "--duration", "1e7"])
    assert p.returncode == 2 and "--duration=10000000.0: about 4.9e+11 steps" in p.stderr


def test_a_pull_out_distance_beyond_the_box_is_refused():
    p = run([PY, str(ROOT / "cases" / "pullout_000.py"), "--smoke", "--distance", "5"])
    assert p.returncode == 2
    assert "--distance=5.0: must be < the box length 0.5 m" in p.stderr


def _sweep(tmp_path: Path, body: str, *args, env=None, timeout=120):
    f = _toml(tmp_path / "s.toml", body)
    return run([*CLI, "sweep", str(f), *args], cwd=tmp_path, timeout=timeout,
               env={**os.environ, **(env or {})})


def test_a_typo_in_one_sweep_row_fails_at_once_naming_the_row(tmp_path):
    t0 = time.time()
    p = _sweep(tmp_path, 'case = "deposition"\nout = "sw"\n[params]\nsmoke = true\n'
               '[sweep]\nmode = "list"\nduration = [0.01, 0.02, -1]\n')
    assert p.returncode == 1
    assert "row 2 (duration=-1)" in p.stderr and "--duration=-1.0: must be a finite" in p.stderr
    assert not (tmp_path / "sw").exists()  # before Dask, before any folder
    assert time.time() - t0 < 60
    p = _sweep(tmp_path, 'case = "deposition"\nout = "sw"\n[sweep]\nsmok = [true]\n')
    assert p.returncode == 1 and "(did you mean smoke?)" in p.stderr


def test_a_sweep_of_a_million_rows_is_refused_up_front_with_its_size(tmp_path):
    body = ('case = "deposition"\nout = "sw"\n[sweep]\nseed = ' + str(list(range(1000)))
            + '\nn = ' + str(list(range(20, 1020))) + '\n')
    t0 = time.time()
    p = _sweep(tmp_path, body)
    assert p.returncode == 1
    assert "makes 1000000 rows (1000 seed x 1000 n, mode 'product'): more than the cap of " \
        "10000" in p.stderr and "--max-rows" in p.stderr
    assert time.time() - t0 < 30
    p = _sweep(tmp_path, body, "--max-rows", "0")
    assert p.returncode == 2 and "--max-rows=0: must be >= 1" in p.stderr


def test_a_sweep_into_a_file_or_to_an_unreachable_scheduler_is_one_clear_error(tmp_path):
    (tmp_path / "afile").write_text("x")
    p = _sweep(tmp_path, 'case = "deposition"\nout = "afile"\n[sweep]\nseed = [1]\n')
    assert p.returncode == 1 and "field 'out'='afile': exists and is not a directory" \
        in p.stderr and "Traceback" not in p.stderr
    p = _sweep(tmp_path, 'case = "deposition"\nout = "/proc/geogrid_dem_no/x"\n[sweep]\n'
               'seed = [1]\n')
    assert p.returncode == 1 and "field 'out'='/proc/geogrid_dem_no/x': cannot be created" \
        in p.stderr and "Traceback" not in p.stderr
    p = _sweep(tmp_path, 'case = "deposition"\nout = "sw"\n[params]\nsmoke = true\n'
               '[sweep]\nseed = [1]\n', "--scheduler", "tcp://127.0.0.1:9",
               env={"DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "3s"})
    assert p.returncode == 2, p.stderr
    assert "could not connect to a Dask scheduler there" in p.stderr
    assert "Traceback" not in p.stderr


_CAL = """out = "cal"
[params]
smoke = true
[reference]
young = 4200e3
poisson = 0.31
phi = 31.5
[grid]
young = [4000e3]
poisson = [0.3]
phi = [31.0]
"""


@pytest.mark.parametrize("extra, message", [
    ("[optimiser]\nmax_fev = 2\n", "field 'optimiser.max_fev': not known (did you mean "
                                   "maxfev?)"),
    ("[misfit]\nw_q = 2\n", "field 'misfit.w_q'=2: must be in [0, 1]"),
    ("[misfit]\npoints = 1\n", "field 'misfit.points'=1: must be a whole number in [2, "
                               "100000]"),
    ("[misfit]\nponts = 50\n", "(did you mean points?)"),
    ("[optimiser]\nstep = 0\n", "field 'optimiser.step'=0: must be in (0, 1]"),
])
def test_calibration_files_refuse_unknown_keys_and_values_out_of_range(tmp_path, extra,
                                                                        message):
    f = _toml(tmp_path / "c.toml", _CAL + extra)
    p = run([*CLI, "calibrate", str(f), "--workers", "0"], cwd=tmp_path)
    assert p.returncode == 1 and message in p.stderr, p.stderr
    assert not (tmp_path / "cal").exists()


def test_calibration_params_are_checked_against_the_triaxial_case(tmp_path):
    f = _toml(tmp_path / "c.toml", _CAL.replace("smoke = true", "smoke = true\nstop-strain = 2"))
    p = run([*CLI, "calibrate", str(f), "--workers", "0"], cwd=tmp_path)
    assert p.returncode == 1
    assert "--stop-strain=2.0: must be in (0, 0.5)" in p.stderr
    assert not (tmp_path / "cal").exists()


def test_ctrl_c_stops_a_sweep_with_130_and_says_how_to_continue(tmp_path):
    f = _toml(tmp_path / "s.toml", 'case = "deposition"\nout = "sw"\n[params]\nsmoke = true\n'
              'duration = 100\n[sweep]\nseed = [1, 2]\n')
    proc = subprocess.Popen([*CLI, "sweep", str(f), "--workers", "2"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if "to run on" in line:  # the cluster is starting: a Ctrl-C is held until it is up
            time.sleep(1.0)
            proc.send_signal(signal.SIGINT)
            break
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "[sweep] interrupted: 0 of 2 rows finished" in err
    assert "the same command again runs the rest" in err
    assert "Traceback" not in err


@pytest.mark.parametrize("args, message", [
    (["--local-damping", "nan"], "--local-damping=nan: must be in [0, 1)"),
    (["--damping-normal", "inf"], "--damping-normal=inf: must be in [0, 1]"),
    (["--dt-safety", "inf"], "--dt-safety=inf: must be in (0, 1]"),
])
def test_deposition_refuses_non_finite_damping_and_safety(args, message):
    p = run([*DEPOSITION, *args])
    assert p.returncode == 2 and message in p.stderr, p.stderr


def test_a_two_way_tolerance_that_accepts_anything_is_refused():
    from geogrid_dem.cases import prs_element

    for tol in ("inf", "1", "nan"):
        with pytest.raises(SystemExit) as ei:
            prs_element.parse_args(["--smoke", "--two-way", "--tol", tol])
        assert ei.value.code == 2


def test_triaxial_resume_continues_from_its_checkpoint_as_the_run_would_have(tmp_path,
                                                                             case_smoke):
    """Ctrl-C in the deviatoric stage, then --resume: the state after the isotropic stage is
    loaded from isotropic.h5 and the deviatoric stage runs again; its curve is the very one
    of the uninterrupted smoke (same engine, parameters and threads: bitwise)."""
    from conftest import SMOKE_ARGS

    ref_out, ref = case_smoke("triaxial")
    assert ref.returncode == 0, ref.stderr
    out = tmp_path / "t"
    args = [PY, str(ROOT / "cases" / "triaxial.py"), "--smoke", "--out", str(out),
            *SMOKE_ARGS["triaxial"]]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if "axial loading at" in line:  # the checkpoint follows at once
            break
    t0 = time.time()
    while not (out / "triaxial.csv").exists() and time.time() - t0 < 120:
        time.sleep(0.05)  # the deviatoric stage has begun: isotropic.h5 is complete
    time.sleep(0.3)
    proc.send_signal(signal.SIGINT)
    _o, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert manifest(out)["status"] == "interrupted"
    p = run([*args, "--resume"], timeout=900)
    assert p.returncode == 0, p.stderr
    assert "--resume: kept isotropic.h5" in p.stdout
    assert (out / "triaxial.csv").read_bytes() == (ref_out / "triaxial.csv").read_bytes()
    s, r = (json.loads((d / "summary.json").read_text()) for d in (out, ref_out))
    assert s["q_peak_Pa"] == r["q_peak_Pa"] and s["porosity_isotropic"] == \
        r["porosity_isotropic"]
    # nothing to resume in a completed run: said, exit status 0, nothing run (docs/cli.md)
    before = (out / "triaxial.csv").stat().st_mtime_ns
    p = run([*args, "--resume"])
    assert p.returncode == 0 and "--resume: the run is already complete" in p.stdout
    assert (out / "triaxial.csv").stat().st_mtime_ns == before


def test_an_interrupted_run_in_process_gives_ctrl_c_back(tmp_path):
    """run_main ignores a second Ctrl-C while an interrupted run closes its files, then puts
    the caller's handler back: a script or session that called it can be interrupted again,
    and the processes it starts do not inherit the ignore (which once left the rest of the
    test session's subprocesses deaf to SIGINT)."""
    from geogrid_dem.rundir import run_main

    before = signal.getsignal(signal.SIGINT)

    def work(_out):
        raise KeyboardInterrupt

    assert run_main("deposition", tmp_path / "r", work) == 130
    assert signal.getsignal(signal.SIGINT) is before


def test_a_ctrl_c_inside_an_import_is_an_interrupt(tmp_path):
    """A Ctrl-C that arrives while a C extension initialises surfaces as an ImportError caused
    by the KeyboardInterrupt (seen in CI: the triaxial smoke interrupted in matplotlib's
    ft2font). run_main takes it as the interrupt it is: exit status 130 and the folder marked
    interrupted; an error not caused by one is still an error."""
    import json

    from geogrid_dem.rundir import MANIFEST, run_main

    def work(_out):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as k:
            raise ImportError("initialization failed") from k

    assert run_main("deposition", tmp_path / "r", work) == 130
    assert json.loads((tmp_path / "r" / MANIFEST).read_text())["status"] == "interrupted"

    def broken(_out):
        raise ImportError("no such module")

    with pytest.raises(ImportError, match="no such module"):
        run_main("deposition", tmp_path / "s", broken)


def test_a_run_the_core_stops_says_so_in_one_line(tmp_path):
    """A case whose simulation the core stops (here grains of E = 20 kPa under 75 kPa: an
    overlap beyond the blow-up limit in the preparation) exits 6 through ``geogrid-dem run``
    with one line on stderr giving the core's message (the step, the bodies, the cause) and
    the folder, no traceback, and its folder marked failed."""
    out = tmp_path / "stopped"
    p = subprocess.run([str(Path(PY).parent / "geogrid-dem"), "run", "triaxial", "--smoke",
                        "--young", "2e4", "--out", str(out)], capture_output=True, text=True,
                       timeout=300, cwd=tmp_path, env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert p.returncode == 6, p.stderr[-3000:]
    assert "Traceback" not in p.stderr
    line = [x for x in p.stderr.splitlines() if x.startswith("error: [triaxial] the simulation "
                                                              "stopped: blow-up at step")]
    assert len(line) == 1 and "max_overlap_ratio" in line[0] and str(out) in line[0]
    manifest = json.loads((out / ".geogrid-dem-run.json").read_text())
    assert manifest["status"] == "failed" and "BlowUpError" in manifest["reason"]
