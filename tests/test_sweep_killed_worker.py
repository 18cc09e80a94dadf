"""The sweep survives a killed Dask worker: the row that was running on it is run again
(from an empty folder, its orphaned case process gone with the worker) and every row ends
with the same numbers as in an undisturbed sweep."""

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
CASE = "geogrid_dem.cases.triaxial"


def _sweep_file(tmp_path, name):
    out = tmp_path / name
    f = tmp_path / f"{name}.toml"
    f.write_text(f'case = "triaxial"\nout = "{out}"\n[params]\nsmoke = true\nn = 100\n'
                 'stop-strain = 0.03\n[sweep]\nmode = "list"\nseed = [1, 2, 3, 4]\n')
    return f, out


def _cmd(f):
    return [sys.executable, "-m", "geogrid_dem.cli", "sweep", str(f), "--workers", "2"]


def _numbers(out):
    """Row -> its deterministic summary numbers (wall times and rates left out)."""
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert all(r["status"] == "ok" for r in rows), rows
    return {r["row"]: {k: v for k, v in r.items() if k.startswith("summary.")
                       and "wall" not in k and "per_s" not in k} for r in rows}


def test_sweep_survives_a_killed_worker(tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    f0, out0 = _sweep_file(tmp_path, "calm")
    r = subprocess.run(_cmd(f0), capture_output=True, text=True, cwd=ROOT, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    calm = _numbers(out0)
    assert len(calm) == 4

    f1, out1 = _sweep_file(tmp_path, "killed")
    proc = subprocess.Popen(_cmd(f1), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT, env=env)
    killed_worker = orphan = None
    try:
        deadline = time.monotonic() + 60
        while killed_worker is None and time.monotonic() < deadline and proc.poll() is None:
            for p in psutil.Process(proc.pid).children(recursive=True):
                try:
                    if CASE in " ".join(p.cmdline()):
                        worker = p.parent()
                        assert worker.pid != proc.pid  # the case runs under a worker process
                        orphan = p
                        worker.send_signal(signal.SIGKILL)
                        killed_worker = worker.pid
                        break
                except psutil.NoSuchProcess:
                    continue
            time.sleep(0.02)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert killed_worker is not None, "no row was caught running"
    assert proc.returncode == 0, stderr[-3000:] + stdout[-2000:]
    # The case process of the killed worker died with it (no orphan writing into the row).
    assert not orphan.is_running() or orphan.status() == psutil.STATUS_ZOMBIE
    assert "4 rows, 0 finished before, 4 to run" in stdout
    assert _numbers(out1) == calm


def test_an_orphan_row_never_starts(tmp_path):
    """The race the parent-death signal leaves open: a worker killed before its row's case
    armed the signal has already orphaned it. The wrapper sees a parent pid that is not the
    worker's and exits before the case starts (nothing written); with the right parent pid it
    runs the command."""
    from geogrid_dem.runs import _DIE_WITH_PARENT
    marker = tmp_path / "ran"
    cmd = [sys.executable, "-c", f"open({str(marker)!r}, 'w').write('x')"]
    wrong = subprocess.run([sys.executable, "-c", _DIE_WITH_PARENT, str(os.getpid() + 10**6),
                            *cmd])
    assert wrong.returncode == 137 and not marker.exists()
    right = subprocess.run([sys.executable, "-c", _DIE_WITH_PARENT, str(os.getpid()), *cmd])
    assert right.returncode == 0 and marker.read_text() == "x"
