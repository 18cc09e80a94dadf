"""How the cases and the command line show warnings (geogrid_dem.warnings_display): one line
each, no source line, a repeated warning once and then counted; a library user keeps
Python's display."""

import subprocess
import sys
import textwrap
from pathlib import Path

from geogrid_dem.warnings_display import WarningsDisplay, key

ROOT = Path(__file__).resolve().parents[1]

# A case's run (run_main) whose work warns 10 times, the numbers different each time, then
# once more of another kind; after it, a warning outside the run.
CASE_RUN = """
import warnings
from geogrid_dem.rundir import run_main

class DriftWarning(UserWarning):
    pass

def work(out):
    for k in range(10):
        warnings.warn(DriftWarning(f"element {{k}}: stress drifted to {{90 + k * 0.5}} kPa"))
    warnings.warn("only once", RuntimeWarning)

status = run_main("demo", {out!r}, work)
warnings.warn("after the run", UserWarning)
raise SystemExit(status)
"""


def _python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


def test_a_run_shows_a_repeated_warning_once_with_a_count_and_no_source_line(tmp_path):
    p = _python(CASE_RUN.format(out=str(tmp_path / "run")), ROOT)
    assert p.returncode == 0, p.stderr
    lines = p.stderr.splitlines()
    drift = [s for s in lines if "DriftWarning" in s]
    assert drift == ["[warning] DriftWarning: element 0: stress drifted to 90.0 kPa",
                     "[warning] DriftWarning: 9 more like it (element 0: stress drifted to "
                     "90.0 kPa)"], p.stderr
    assert "[warning] RuntimeWarning: only once" in lines
    assert not any("more like it" in s and "RuntimeWarning" in s for s in lines)
    assert "warnings.warn(" not in p.stderr  # no source line echoed
    # the counts come at the end of the run, after its own lines
    assert lines.index(drift[1]) > lines.index("[warning] RuntimeWarning: only once")
    # after the run, Python's own display is back (file:line: Category: message)
    assert any(s.endswith("UserWarning: after the run") and s.startswith("<string>:")
               for s in lines), p.stderr


def test_a_library_user_keeps_pythons_display(tmp_path):
    p = _python("""
        import warnings
        import cpp_dem, geogrid_dem.rundir, geogrid_dem.warnings_display
        assert warnings.showwarning is warnings._showwarning_orig
        warnings.warn("plain", UserWarning)
        """, ROOT)
    assert p.returncode == 0, p.stderr
    assert "<string>:5: UserWarning: plain" in p.stderr and "[warning]" not in p.stderr


def test_the_same_warning_is_the_same_message_but_for_its_numbers():
    assert key(UserWarning, "cap 2.895 1/s for 159 calls, 1e-4") == \
        key(UserWarning, "cap 3.056 1/s for 5 calls, -2.5E+03")
    assert key(UserWarning, "a 1") != key(RuntimeWarning, "a 1")
    assert key(UserWarning, "stage grow: 1") != key(UserWarning, "stage load: 1")


def test_a_display_under_a_recorder_changes_nothing():
    """Where warnings are recorded (pytest, catch_warnings(record=True)) the display is not
    installed: the recorder keeps them."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = WarningsDisplay()
        assert not d.install()
        warnings.warn("kept", UserWarning)
    assert [str(w.message) for w in caught] == ["kept"]
