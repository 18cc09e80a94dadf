"""Shared helpers for the test suite."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

# A suite started in the background of a non-interactive shell (`cmd &`, as a CI runner without
# job control may) inherits SIGINT ignored, and so would every case it starts: the Ctrl-C tests
# would then see their runs finish instead of stopping. The suite tests Ctrl-C itself, so it
# takes Python's own handler back, which the processes it starts inherit as the default.
signal.signal(signal.SIGINT, signal.default_int_handler)

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


def sphere_mass(density: float, radius: float) -> float:
    """Mass of a sphere, kg."""
    return density * 4.0 / 3.0 * math.pi * radius**3


@pytest.fixture(autouse=True)
def _dem_threads_restored():
    """Every test leaves the DEM core's thread count as it found it (OMP_NUM_THREADS under
    `make test`: 1). A test that sets it and leaves 2 makes every later DEM run of its pytest
    worker two-threaded: on this machine's two cores, beside the other worker, that cost the
    suite's worker a futex sleep and wake-up per parallel region (a test's system time rose
    from 1 to 20 s)."""
    import cpp_dem

    before = cpp_dem.get_num_threads()
    yield
    if cpp_dem.get_num_threads() != before:
        cpp_dem.set_num_threads(before)


@pytest.fixture
def linear_mat():
    import cpp_dem as dem

    return dem.Material(model="linear", density=2600.0, young=1e7, poisson=0.3,
                        friction_angle_deg=30.0)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


#: The flags each case's --smoke run is made with, shared by tests/test_cases_smoke.py (which
#: finds every case by glob) and the case's own physics tests, so each smoke runs once per
#: session. A new case needs no entry: it runs with --smoke and --out alone.
def load_bench(name: str):
    """The module of ``bench/<name>.py`` (bench/ put on the path first, for its own imports)."""
    import importlib.util

    path = ROOT / "bench" / f"{name}.py"
    sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


SMOKE_ARGS: dict[str, tuple[str, ...]] = {
    "deposition": ("--threads", "2"),
    "triaxial": ("--threads", "2"),
    "pullout_000": ("--threads", "2"),
    "prs_element": (),
    # The documented smoke, FEM path included: two seeds, RE and PRS on each seed's packing,
    # the two packings side by side (test_case_prs_element_002 checks one against a serial
    # run).
    "prs_element_002": ("--workers", "2"),
    "pullout_001": (),
    "footing_multiscale": (),
}


def run_list_item_example(page: str, marker: str) -> str:
    """Runs the first ```python block after ``marker`` in ``docs/<page>`` (a list item's
    example: its two-space indent removed) as shown, the ControllerLimitWarning of a
    compaction at the cap silenced; returns what it printed."""
    import contextlib
    import io
    import re
    import warnings

    import cpp_dem as dem

    text = (ROOT / "docs" / page).read_text()
    code = re.search(r"```python\n(.*?)```", text[text.index(marker):], re.S)[1]
    code = "\n".join(line[2:] for line in code.splitlines())
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()) as out:
        warnings.simplefilter("ignore", dem.ControllerLimitWarning)
        exec(compile(code, f"docs/{page}", "exec"), {})
    return out.getvalue()


def case_names() -> list[str]:
    """The runnable cases: cases/*.py that run as a script (the thin wrappers of
    geogrid_dem.cases; helpers such as pullout_common.py do not)."""
    return sorted(p.stem for p in (ROOT / "cases").glob("*.py")
                  if '__name__ == "__main__"' in p.read_text())


@pytest.fixture(scope="session")
def case_smoke(tmp_path_factory, worker_id):
    """case_smoke(name) -> (out folder, CompletedProcess) of ``cases/<name>.py --smoke`` with
    its SMOKE_ARGS, run once per session: under pytest-xdist (``make test``) the first worker
    to ask runs it under a file lock in the folder the workers share, and the others read its
    outputs and its recorded process."""
    import fcntl
    import json

    base = tmp_path_factory.getbasetemp()
    shared = base if worker_id == "master" else base.parent
    runs: dict[str, tuple[Path, subprocess.CompletedProcess]] = {}

    def run(name: str):
        if name in runs:
            return runs[name]
        out = shared / f"smoke_{name}"
        record = shared / f"smoke_{name}.json"
        with open(shared / f"smoke_{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not record.exists():
                out.mkdir(parents=True, exist_ok=True)
                cmd = [PYTHON, str(ROOT / "cases" / f"{name}.py"), "--smoke",
                       "--out", str(out), *SMOKE_ARGS.get(name, ())]
                p = subprocess.run(cmd, capture_output=True, text=True, timeout=900, cwd=ROOT)
                record.write_text(json.dumps({"args": cmd, "returncode": p.returncode,
                                              "stdout": p.stdout, "stderr": p.stderr}))
            r = json.loads(record.read_text())
        runs[name] = (out, subprocess.CompletedProcess(r["args"], r["returncode"],
                                                       r["stdout"], r["stderr"]))
        return runs[name]

    return run
