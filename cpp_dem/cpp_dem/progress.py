"""Progress of long library stages: a line with the fraction done, the elapsed wall time and
an ETA, printed once a stage has run for ``FIRST_AFTER_S`` seconds and then every
``EVERY_S`` seconds (a pull-out, a triaxial stage, a servo stage). Short stages print
nothing.

Stages without a known end (a servo stage that runs until the walls hold their targets)
report how far from the target they are and the step budget left, the ETA then being the time
to use that budget up: an upper bound. ``set_progress(False)`` (or the environment variable
``CPP_DEM_PROGRESS=0``) silences every stage; ``set_progress(stream)`` sends the lines to
another stream (stdout by default).
"""

from __future__ import annotations

import os
import sys
import time

__all__ = ["FIRST_AFTER_S", "EVERY_S", "Progress", "set_progress"]

#: Seconds a stage runs before its first line.
FIRST_AFTER_S = 10.0
#: Seconds between two lines of a stage.
EVERY_S = 10.0

_stream = None if os.environ.get("CPP_DEM_PROGRESS", "1") == "0" else "stdout"


def set_progress(stream) -> None:
    """Where stages print progress: a text stream, True (stdout) or False/None (nowhere)."""
    global _stream
    _stream = "stdout" if stream is True else (stream or None)


class Progress:
    """Progress of one stage named ``label``: call ``update(fraction, detail)`` as it runs
    (fraction in [0, 1], or None when the end is not known; ``detail`` a short text such as
    the current values). Prints at most one line every ``EVERY_S`` seconds of wall time."""

    def __init__(self, label: str, *, first_after_s: float | None = None,
                 every_s: float | None = None, clock=time.perf_counter):
        self.label = label
        self._clock = clock
        self._t0 = clock()
        self._first = FIRST_AFTER_S if first_after_s is None else first_after_s
        self._every = EVERY_S if every_s is None else every_s
        self._next = self._t0 + self._first
        self.lines: list[str] = []

    def update(self, fraction: float | None, detail: str = "") -> str | None:
        """Prints (and returns) a progress line when one is due, else returns None."""
        now = self._clock()
        if now < self._next or _stream is None:
            return None
        self._next = now + self._every
        el = now - self._t0
        if fraction is not None and fraction > 0:
            f = min(max(float(fraction), 0.0), 1.0)
            eta = f"ETA {el * (1 - f) / f:.0f} s"
            done = f"{100 * f:.0f} %"
        else:
            eta, done = "ETA unknown", "running"
        line = f"[{self.label}] {done}, {el:.0f} s elapsed, {eta}" + (f"; {detail}" if detail
                                                                     else "")
        out = sys.stdout if _stream == "stdout" else _stream
        print(line, file=out, flush=True)
        self.lines.append(line)
        return line
