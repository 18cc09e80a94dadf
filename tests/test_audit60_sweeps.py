"""Issue 60, item 4: a sweep removes or replaces only what its own rows' runs wrote, and refuses,
by name and in one line, a row folder that is a symbolic link or holds one, another sweep's
row, or files no run of the row recorded. All refusals come before Dask starts and before
anything is written."""

import json
import subprocess
import sys
from pathlib import Path

from geogrid_dem import rundir
from geogrid_dem.runs import _run_row, check_row_folder, write_run_file

ROOT = Path(__file__).resolve().parents[1]


def _sweep(tmp_path, out, seeds=(1,)):
    f = tmp_path / "s.toml"
    f.write_text(f'case = "triaxial"\nout = "{out}"\n[params]\nsmoke = true\n'
                 f'[sweep]\nmode = "list"\nseed = {list(seeds)}\n')
    p = subprocess.run([sys.executable, "-m", "geogrid_dem.cli", "sweep", str(f), "--workers",
                        "1"], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    return p


def _one_line_error(p, *words):
    assert p.returncode == 1, p.stdout + p.stderr
    assert "Traceback" not in p.stderr, p.stderr
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, p.stderr
    for w in words:
        assert w in lines[0], lines[0]
    assert "to run on" not in p.stdout  # refused before Dask


def _finished_row(row, case="triaxial", params=None, extra=()):
    """A finished row as a sweep leaves it: the case's files, its manifest listing them, its
    run.toml."""
    row.mkdir(parents=True)
    (row / "summary.json").write_text('{"peak": 1.0}')
    (row / "triaxial.csv").write_text("a,b\n1,2\n")
    for name in extra:
        (row / name).write_text("mine\n")
    files = ["summary.json", "triaxial.csv"]
    (row / rundir.MANIFEST).write_text(json.dumps({"status": "complete", "case": case,
                                                   "files": files}))
    write_run_file(row, case, params if params is not None else
                   {"smoke": True, "seed": 9, "out": str(row), "threads": 0})


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def test_another_sweeps_finished_row_with_a_file_of_yours_is_not_deleted(tmp_path):
    out = tmp_path / "sw"
    _finished_row(out / "row_000", extra=("my_notes.txt",))
    before = _snapshot(out)
    p = _sweep(tmp_path, out, seeds=(1,))
    _one_line_error(p, "row 0", "row_000", "holds a row of another sweep",
                    "seed=9 there, 1 here", "nothing was removed")
    assert _snapshot(out) == before


def test_a_row_folder_that_is_a_symbolic_link_is_refused_by_name(tmp_path):
    out, elsewhere = tmp_path / "sw", tmp_path / "elsewhere"
    out.mkdir()
    _finished_row(elsewhere)
    (out / "row_000").symlink_to(elsewhere, target_is_directory=True)
    before = _snapshot(elsewhere)
    p = _sweep(tmp_path, out)
    _one_line_error(p, "row_000 is a symbolic link", "follows no link")
    assert _snapshot(elsewhere) == before and (out / "row_000").is_symlink()
    # A link inside a row of this sweep, and a linked results.csv, too.
    (out / "row_000").unlink()
    row = out / "row_000"
    row.mkdir()
    write_run_file(row, "triaxial", {"smoke": True, "seed": 1, "out": str(row), "threads": 0})
    (row / "triaxial.h5").symlink_to(elsewhere / "triaxial.csv")
    p = _sweep(tmp_path, out)
    _one_line_error(p, "row_000 holds 1 symbolic links", "triaxial.h5")
    (out / "results.csv").symlink_to(elsewhere / "summary.json")
    p = _sweep(tmp_path, out)
    _one_line_error(p, "results.csv is a symbolic link")
    assert _snapshot(elsewhere) == before


def test_an_unfinished_row_of_this_sweep_keeps_files_it_did_not_record(tmp_path):
    row = tmp_path / "sw" / "row_000"
    params = {"smoke": True, "seed": 1, "out": str(row), "threads": 4}
    row.mkdir(parents=True)
    write_run_file(row, "triaxial", params)
    (row / "triaxial.csv").write_text("partial\n")
    (row / "yours.txt").write_text("mine\n")
    (row / rundir.MANIFEST).write_text(json.dumps({"status": "failed", "case": "triaxial",
                                                   "files": ["triaxial.csv"]}))
    src = "s.toml: row 0"
    try:
        check_row_folder(row, "triaxial", {**params, "threads": 0}, source=src)
    except Exception as e:  # noqa: BLE001
        msg = str(e)
    assert "holds 1 files that its earlier run did not record (e.g. yours.txt)" in msg
    assert (row / "yours.txt").exists() and (row / "triaxial.csv").exists()
    # Without it, the row is this sweep's (threads aside) and passes: nothing is removed
    # here; the case removes what its earlier run recorded.
    (row / "yours.txt").unlink()
    check_row_folder(row, "triaxial", {**params, "threads": 0}, source=src)
    assert (row / "triaxial.csv").exists()
    # Files with no run.toml: not a sweep's row.
    stray = tmp_path / "sw" / "row_001"
    stray.mkdir()
    (stray / "data.csv").write_text("x\n")
    try:
        check_row_folder(stray, "triaxial", params, source="s.toml: row 1")
    except Exception as e:  # noqa: BLE001
        msg = str(e)
    assert "row_001 holds 1 entries but no run.toml (e.g. data.csv)" in msg


def test_a_row_run_again_replaces_only_its_recorded_files(tmp_path):
    """_run_row no longer empties the folder: it gives the case --overwrite when an earlier
    attempt's manifest is there (the case removes what that attempt recorded), else nothing."""
    row = tmp_path / "row_000"
    row.mkdir()
    (row / "keep.txt").write_text("mine\n")
    echo = [sys.executable, "-c", "import sys; sys.stderr.write(' '.join(sys.argv[1:]))"]
    r = _run_row(echo, ["--smoke", "--out", str(row)], {})
    assert r["returncode"] == 0 and "--overwrite" not in r["stderr_tail"]
    (row / rundir.MANIFEST).write_text(json.dumps({"status": "running", "case": "triaxial"}))
    r = _run_row(echo, ["--smoke", "--out", str(row)], {})
    assert r["stderr_tail"].endswith("--out " + str(row) + " --overwrite")
    r = _run_row(echo, ["--resume", "--out", str(row)], {})
    assert "--overwrite" not in r["stderr_tail"]  # (a resume keeps its files itself)
    assert (row / "keep.txt").read_text() == "mine\n"


def test_a_zombie_holds_no_folder():
    """A sweep row's case killed with its Dask worker is a zombie until reaped: it writes
    nothing, so its lock does not stop the row's rerun (it did: 'another run is writing into
    it: pid N')."""
    import os
    import subprocess
    import sys
    import time

    from geogrid_dem import rundir

    child = subprocess.Popen([sys.executable, "-c", "pass"])
    t0 = time.time()
    while time.time() - t0 < 10:  # exited, not reaped: a zombie
        state = open(f"/proc/{child.pid}/stat").read().rsplit(")", 1)[1].split()[0]
        if state == "Z":
            break
        time.sleep(0.05)
    assert state == "Z"
    assert not rundir._pid_alive(child.pid)
    assert rundir._pid_alive(os.getpid())
    child.wait()
