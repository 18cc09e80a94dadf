"""How the command line and the cases show Python warnings: one line each,
``[warning] <Category>: <message>``, with no source line, and a warning that comes again (the
same category, the same message but for its numbers) printed once and then counted: at the
end of the run, one line ``[warning] <Category>: N more like it (<first message>)`` per
repeated warning.

``geogrid-dem`` and every case's run (:func:`geogrid_dem.rundir.run_main`) show warnings
this way (:func:`shown_once`). A program that imports ``cpp_dem`` or ``femcoupling`` keeps
Python's own display; so does a run where something else already shows or records the
warnings (``warnings.catch_warnings(record=True)``, pytest, ``logging.captureWarnings``).
Filters keep their meaning: an ignored warning stays ignored, an ``error`` one raises. Worker
processes (``--workers``, the Dask pool) keep Python's display.
"""

from __future__ import annotations

import contextlib
import re
import sys
import warnings

__all__ = ["WarningsDisplay", "key", "shown_once"]

#: A number in a message (integer, decimal, exponent; a sign is part of it).
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def key(category: type, message) -> tuple[str, str]:
    """What makes two warnings "the same": the category's name and the message with each
    number replaced by ``#``."""
    return category.__name__, NUMBER.sub("#", str(message))


def _python_shows() -> bool:
    """Python's own display is in place: nobody replaced ``warnings.showwarning`` nor records
    the warnings (``catch_warnings(record=True)`` swaps ``_showwarnmsg_impl``)."""
    impl = getattr(warnings, "_showwarnmsg_impl", None)
    return (warnings.showwarning is getattr(warnings, "_showwarning_orig", None)
            and getattr(impl, "__name__", "") == "_showwarnmsg_impl")


class WarningsDisplay:
    """Shows each kind of warning once on stderr (see the module) and counts the rest."""

    def __init__(self) -> None:
        #: key -> [count, first message], in the order first seen
        self.seen: dict[tuple[str, str], list] = {}
        self._saved = None

    def show(self, message, category, filename, lineno, file=None, line=None) -> None:
        """``warnings.showwarning``'s signature; prints the first of its kind only."""
        k = key(category, message)
        if k in self.seen:
            self.seen[k][0] += 1
            return
        self.seen[k] = [1, str(message)]
        print(f"[warning] {category.__name__}: {message}", file=file or sys.stderr, flush=True)

    def report(self) -> list[str]:
        """One line per warning that came more than once: how many more, and its first
        message (shortened)."""
        lines = []
        for (cat, _masked), (n, first) in self.seen.items():
            if n > 1:
                short = first if len(first) <= 80 else first[:79] + "…"
                lines.append(f"[warning] {cat}: {n - 1} more like it ({short})")
        return lines

    def install(self) -> bool:
        """Takes over the display where Python's own is in place (True), else changes nothing
        (False). Every warning a filter lets through reaches :meth:`show` (the catch-all
        action becomes ``always``, after the filters already set)."""
        if self._saved is not None or not _python_shows():
            return False
        self._saved = (warnings.showwarning, list(warnings.filters))
        warnings.filterwarnings("always", append=True)
        warnings.showwarning = self.show
        return True

    def uninstall(self) -> None:
        """Puts Python's display and the filters back as they were."""
        if self._saved is None:
            return
        show, filters = self._saved
        self._saved = None
        warnings.showwarning = show
        warnings.filters[:] = filters
        mutated = getattr(warnings, "_filters_mutated", None)
        if mutated is not None:
            mutated()


@contextlib.contextmanager
def shown_once():
    """Inside, warnings are shown as the module says; on the way out (an error or Ctrl-C
    too) the ``N more like it`` lines are printed and Python's display comes back. Nested
    uses, or one where another display is in place, change nothing."""
    display = WarningsDisplay()
    installed = display.install()
    try:
        yield display
    finally:
        if installed:
            display.uninstall()
            for line in display.report():
                print(line, file=sys.stderr, flush=True)
