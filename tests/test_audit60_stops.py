"""A stop is honest (issue 60 item 8): SIGTERM gives exit status 143 and an ``interrupted``
manifest also once the FEM stack (dolfinx, PETSc, MPI) is loaded and while a case's elements
are prepared on Dask workers, and no process of the run is left behind.

Two libraries below took SIGTERM from Python, so ``geogrid_dem.rundir.run_main``'s handler
never ran and the manifest was left ``running``, the Dask workers orphaned:
- PETSc's initialisation installed its own handler (of SIGTERM, SIGHUP, SIGSEGV, SIGFPE, ...):
  the process printed "Caught signal number 15" and ended with status 241.
  ``femcoupling._dolfinx.load`` now initialises PETSc with ``-no_signal_handler`` (and puts
  Python's handlers back if a script initialised PETSc before it);
- every ``gmsh.initialize()`` set SIGTERM (SIGQUIT, SIGPIPE, SIGHUP) back to its default: the
  process died at once (status -15). ``femcoupling.fem.gmsh_mesh`` puts Python's back after
  it."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ".geogrid-dem-run.json"


def _manifest(out: Path) -> dict:
    return json.loads((out / MANIFEST).read_text())


def _term_after(args, marker: str, *, timeout: float = 300.0, settle: float = 0.0, **kw):
    """Starts ``args``; once ``marker`` is on its stdout (and ``settle`` s more), sends
    SIGTERM. Returns (returncode, stdout, stderr, the pids of its descendants just before
    the signal)."""
    import psutil

    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, **kw)
    lines = []
    t0 = time.time()
    for line in proc.stdout:
        lines.append(line)
        if marker in line:
            break
        assert time.time() - t0 < timeout, "".join(lines)
    else:
        raise AssertionError(f"{marker!r} never came: " + "".join(lines)[-3000:]
                             + proc.stderr.read()[-3000:])
    time.sleep(settle)
    children = [c.pid for c in psutil.Process(proc.pid).children(recursive=True)]
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, "".join(lines) + out, err, children


def _left(pids, wait: float = 15.0) -> list:
    """The processes of ``pids`` still alive after ``wait`` seconds (zombies count as gone)."""
    import psutil

    procs = []
    for pid in pids:
        try:
            procs.append(psutil.Process(pid))
        except psutil.NoSuchProcess:
            pass
    _gone, alive = psutil.wait_procs(procs, timeout=wait)
    return [p.pid for p in alive if p.status() != psutil.STATUS_ZOMBIE]


_FEM_CHILD = textwrap.dedent("""
    import sys, time
    from geogrid_dem.rundir import run_main

    def work(out):
        if len(sys.argv) > 2:  # (PETSc initialised by a script's own import, before load)
            import dolfinx_solver
            from petsc4py import PETSc
        from geogrid_dem.studies.footing_multiscale import FootingParams, model
        from femcoupling.materials.continuum import DruckerPrager
        from geogrid_dem.cases.footing_multiscale import SMOKE

        # (gmsh meshes the body, dolfinx and PETSc solve it: the footing seated)
        model(FootingParams(**SMOKE), "RE", DruckerPrager(young_pa=20e6, poisson=0.3,
                                                          cohesion_pa=0.0, friction_deg=35.0))
        print("[fem] model built", flush=True)
        for _ in range(600):
            time.sleep(0.1)

    sys.exit(run_main("deposition", sys.argv[1], work))
""")


@pytest.mark.parametrize("petsc_first", [False, True], ids=["load", "petsc-imported-first"])
def test_sigterm_after_the_fem_stack_is_loaded_stops_the_run_honestly(tmp_path, petsc_first):
    """A run that has built an FEM model (gmsh, dolfinx, PETSc): SIGTERM gives 143, the
    manifest ``interrupted`` (SIGTERM), one line on stderr and no PETSc abort; also when a
    script imported petsc4py.PETSc before ``_dolfinx.load`` (its handlers are put back)."""
    out = tmp_path / "r"
    args = [sys.executable, "-c", _FEM_CHILD, str(out)] + (["petsc-first"] if petsc_first
                                                            else [])
    rc, so, se, _ = _term_after(args, "[fem] model built", timeout=120)
    assert rc == 143, (rc, se[-2000:])
    assert "Caught signal" not in se and "Traceback" not in se, se[-2000:]
    assert "interrupted (SIGTERM)" in se
    m = _manifest(out)
    assert m["status"] == "interrupted" and "SIGTERM" in m["reason"], m


def test_sigterm_while_footing_multiscale_prepares_on_dask_stops_it_and_its_workers(tmp_path):
    """footing-multiscale --smoke, stopped by SIGTERM while the first run's zone elements are
    prepared on its Dask workers (after the continuum body's level, which the log shows):
    exit status 143 (it was 241), the manifest ``interrupted`` (it was left ``running``),
    and none of its processes (the LocalCluster's nannies and workers) left behind."""
    out = tmp_path / "fm"
    rc, so, se, children = _term_after(
        [sys.executable, "-m", "geogrid_dem.cases.footing_multiscale", "--smoke",
         "--variants", "unreinforced", "--seeds", "1", "--out", str(out)],
        "unreinforced drucker_prager: level 1/1", settle=1.5,
        env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert children, "the Dask workers were not running at the signal"
    assert rc == 143, (rc, se[-3000:])
    assert "interrupted (SIGTERM)" in se and "Caught signal" not in se, se[-3000:]
    m = _manifest(out)
    assert m["status"] == "interrupted" and "SIGTERM" in m["reason"], m
    assert not (out / ".geogrid-dem.lock").exists()
    assert _left(children) == []
    # summary.json says what finished (issue 64): the calibration and the Drucker-Prager
    # body's level the log showed, drawn in load_settlement.png
    s = json.loads((out / "summary.json").read_text())
    assert s["status"] == "interrupted" and "SIGTERM" in s["reason"], s
    assert s["finished"][:2] == ["calibration", "unreinforced drucker_prager: 1 of 1 levels"], s
    assert "load_settlement.png" in s["figures"] and (out / "load_settlement.png").is_file()
