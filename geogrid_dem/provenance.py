"""Where a result came from: the package version and, when the code runs from a git checkout,
its commit (with ``+dirty`` when tracked files differ), and the CPU dispatch the run's
arithmetic took (``cpp_dem.dispatch.cpu_dispatch``: the DEM core's SIMD path, the BLAS
kernels). Nothing here assumes a source tree: git is asked about the folder of this file, and
an installed copy reports ``unknown``."""

from __future__ import annotations

import subprocess
from pathlib import Path

_HERE = Path(__file__).resolve().parent


def version() -> str:
    """The installed distribution's version, or ``unknown``."""
    try:
        from importlib.metadata import version as _v

        return _v("geogrid-dem")
    except Exception:  # noqa: BLE001  (not installed as a distribution)
        return "unknown"


def _git(*args: str) -> subprocess.CompletedProcess | None:
    try:
        return subprocess.run(["git", "-C", str(_HERE), *args], capture_output=True, text=True,
                              timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None


def git_commit() -> str:
    """The commit of the checkout this code runs from (``+dirty`` when tracked files were
    changed), or ``unknown`` outside a git checkout."""
    out = _git("rev-parse", "HEAD")
    if out is None or out.returncode != 0:
        return "unknown"
    status = _git("status", "--porcelain", "--untracked-files=no")
    dirty = status is not None and status.stdout.strip()
    return out.stdout.strip() + ("+dirty" if dirty else "")


def git_revision() -> str:
    """A short name of the checkout's commit (``git describe --always --dirty``), or
    ``unknown``."""
    out = _git("describe", "--always", "--dirty")
    return (out.stdout.strip() if out is not None and out.returncode == 0 else "") or "unknown"


def code_record() -> dict:
    """What a run records of its code (the manifest's ``code``, a summary's ``provenance``):
    ``version``, ``commit`` and ``cpu_dispatch``."""
    from cpp_dem.dispatch import cpu_dispatch

    return {"version": version(), "commit": git_commit(), "cpu_dispatch": cpu_dispatch()}
