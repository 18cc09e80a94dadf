"""scripts/setup.sh (which `make test` and `make demo` run first) leaves the project's own
modules byte-compiled. Where PYTHONDONTWRITEBYTECODE is set, as on CI machines, Python never
writes them itself, and every process of a run (a case, a Dask worker, a test's subprocess)
compiled them again: `tests/test_cli.py` and the examples took 30 s with the bytecode missing
against 25-26 s with it."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = (ROOT / "cpp_dem" / "cpp_dem", ROOT / "femcoupling", ROOT / "geogrid_dem")


def _stale(src: Path) -> str:
    """Why ``src``'s cached bytecode would not be used ('' when it would)."""
    pyc = Path(importlib.util.cache_from_source(str(src)))
    if not pyc.exists():
        return "no bytecode"
    head = pyc.read_bytes()[:16]
    if head[:4] != importlib.util.MAGIC_NUMBER:
        return "another Python's bytecode"
    if int.from_bytes(head[4:8], "little") != 0:
        return ""  # (checked by the source's hash, not its time stamp)
    st = src.stat()
    mtime, size = (int.from_bytes(head[k:k + 4], "little") for k in (8, 12))
    if (mtime, size) != (int(st.st_mtime) & 0xFFFFFFFF, st.st_size & 0xFFFFFFFF):
        return "bytecode older than the source"
    return ""


def test_setup_leaves_every_project_module_byte_compiled():
    """Every module as it was at the set-up's last run (its stamp) has current bytecode; one
    edited since is the developer's, compiled at the next set-up (`make test` runs it)."""
    stamp = ROOT / ".venv" / ".bytecode-stamp"
    assert stamp.exists(), "scripts/setup.sh did not byte-compile the modules (no stamp)"
    since = stamp.stat().st_mtime
    stale = {str(src.relative_to(ROOT)): why for pkg in PACKAGES for src in pkg.rglob("*.py")
             if src.stat().st_mtime <= since and (why := _stale(src))}
    assert not stale, (f"{len(stale)} module(s) without current bytecode (run "
                       f"scripts/setup.sh, as `make test` does): {dict(list(stale.items())[:5])}")


def test_the_check_sees_a_module_changed_after_setup(tmp_path):
    """The check above can fail: a module written after its bytecode, or never compiled."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    src = pkg / "m.py"
    src.write_text("X = 1\n")
    assert _stale(src) == "no bytecode"
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(pkg)], check=True)
    assert _stale(src) == ""
    src.write_text("X = 22\n")  # (another size: the check does not wait for the clock)
    assert _stale(src) == "bytecode older than the source"
