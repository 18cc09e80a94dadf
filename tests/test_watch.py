"""`geogrid-dem watch RUN_DIR` (geogrid_dem.watch; issue 64 item 8): a running case's main
curve redrawn as its CSV grows, until the run ends; nothing written into the run folder."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from geogrid_dem import rundir
from geogrid_dem.watch import WatchError, main_watch, pick_series, read_curve, run_state

ROOT = Path(__file__).resolve().parents[1]


def _pullout_rows(path: Path, rows: range, *, header: bool) -> None:
    with open(path, "a", newline="") as fh:
        w = csv.writer(fh)
        if header:
            w.writerow(["time", "step", "displacement", "pull_force", "unbalanced_force"])
        for k in rows:
            w.writerow([k * 1e-3, k * 100, k * 1e-3, 50.0 * k, 0.01])
        fh.flush()


def test_watch_follows_a_running_case_to_its_end_and_leaves_its_folder_alone(tmp_path):
    """A case writing pull-out rows (a thread here, the run folder begun and ended as a case
    does it): watch draws as the rows come and stops, after a last drawing of every row,
    once the run has completed; the run folder holds only the run's own files."""
    out = rundir.begin_run(tmp_path / "run", "pullout_000", log=lambda *_: None,
                           params={"n": 1})
    _pullout_rows(out / "pullout.csv", range(0, 3), header=True)
    started = threading.Event()

    def case():
        started.wait(10)
        for k in range(3, 30, 3):
            time.sleep(0.15)
            _pullout_rows(out / "pullout.csv", range(k, k + 3), header=False)
        rundir.end_run(out)

    lines: list[str] = []

    def log(s):
        lines.append(s)
        started.set()

    t = threading.Thread(target=case)
    t.start()
    assert main_watch(out, every_s=0.1, log=log) == 0
    t.join()
    assert lines[0].startswith("[watch] running: pullout.csv:")
    assert lines[-1].startswith("[watch] complete: pullout.csv: 30 rows, pull_force 1450 at "
                                "displacement 0.029;")
    assert sum("running" in s for s in lines) >= 2  # redrawn while it ran
    png = tmp_path / "run_watch.png"
    assert png.stat().st_size > 5000 and not list(tmp_path.glob("*.tmp.png"))
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [rundir.MANIFEST, "pullout.csv"])  # (the lock released; nothing of watch's)


def test_a_killed_run_ends_the_watch(tmp_path):
    """The manifest says running, but the lock's process is gone: watch draws once, says
    killed and stops."""
    out = tmp_path / "k"
    out.mkdir()
    (out / rundir.MANIFEST).write_text(json.dumps({"status": "running", "case": "triaxial"}))
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    import socket

    (out / rundir.LOCK).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(),
                                               "case": "triaxial"}))
    with open(out / "triaxial.csv", "w") as fh:
        fh.write("step,axial_strain,deviatoric_stress\n0,0,0\n1,0.01,5e4\n")
    assert run_state(out) == "killed"
    lines = []
    assert main_watch(out, every_s=0.1, log=lines.append) == 0
    assert len(lines) == 1 and lines[0].startswith("[watch] killed: triaxial.csv: 2 rows, "
                                                   "deviatoric_stress 50000 at axial_strain "
                                                   "0.01")


def test_the_series_written_last_is_watched_and_a_footings_variants_are_curves(tmp_path):
    a, b = tmp_path / "detailed_RE_s1.csv", tmp_path / "load_settlement.csv"
    a.write_text("stage,step,sigma_z,lz\n0,1,5000,0.1\n")
    b.write_text("variant,model,seed,level,pressure_pa,settlement_m\n"
                 "RE,multiscale,1,1,2e4,0.001\nRE,multiscale,1,2,4e4,0.003\n"
                 "PRS,multiscale,1,1,2e4,0.0009\n")
    os.utime(a, ns=(1, 1))
    s = pick_series(tmp_path)
    assert s.path == b and (s.x, s.y) == ("settlement_m", "pressure_pa")
    curves = read_curve(s)
    assert [(k, len(x)) for k, x, _y in curves] == [("RE multiscale 1", 2),
                                                   ("PRS multiscale 1", 1)]
    os.utime(b, ns=(0, 0))
    s = pick_series(tmp_path)
    assert s.path == a and (s.x, s.y) == ("step", "sigma_z")


def test_what_cannot_be_watched_is_named(tmp_path):
    with pytest.raises(WatchError, match="not a folder"):
        main_watch(tmp_path / "nothing", once=True)
    with pytest.raises(WatchError, match="no CSV file"):
        main_watch(tmp_path, once=True)
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    with pytest.raises(WatchError, match="known curve.*give --x and --y"):
        main_watch(tmp_path, once=True)
    with pytest.raises(WatchError, match="--x='a' and --y='c'"):
        main_watch(tmp_path, x="a", y="c", once=True)
    with pytest.raises(WatchError, match="--every=0"):
        main_watch(tmp_path, every_s=0, once=True)
    # the command: one line naming the folder, exit status 2
    r = subprocess.run([sys.executable, "-m", "geogrid_dem.cli", "watch",
                        str(tmp_path / "nothing")], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "RUN_DIR=" in r.stderr and "not a folder" in r.stderr


def test_the_documented_command_draws_a_finished_run(tmp_path):
    """docs/output.md's `geogrid-dem watch RUN_DIR --once` on a finished run folder."""
    out = rundir.begin_run(tmp_path / "done", "pullout_000", log=lambda *_: None,
                           params={"n": 1})
    _pullout_rows(out / "pullout.csv", range(5), header=True)
    rundir.end_run(out)
    r = subprocess.run([sys.executable, "-m", "geogrid_dem.cli", "watch", str(out), "--once",
                        "--png", str(tmp_path / "w.png")], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("[watch] complete: pullout.csv: 5 rows, pull_force 200 at")
    assert (tmp_path / "w.png").stat().st_size > 5000
    text = (ROOT / "docs" / "output.md").read_text()
    assert "geogrid-dem watch RUN_DIR" in text and "--once" in text
