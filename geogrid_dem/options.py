"""One command-line style for every case: the parser that ``geogrid-dem run NAME``,
``python cases/NAME.py`` and ``python -m geogrid_dem.cases.NAME`` all use.

A case declares its own options once, in its ``parse_args``, on the parser that
:func:`case_parser` makes; the options every case shares (``--smoke``, ``--out``,
``--overwrite``, ``--seed``, ``--threads`` and, where the case has presets, ``--preset``) are
declared here, once, with one meaning each:

- ``--threads N``: the OpenMP threads of this run; ``0`` is OpenMP's default (every core of the
  machine, or ``OMP_NUM_THREADS`` when set). Results do not depend on it.
- ``--out DIR``: the results folder (a new ``results/<case>/run_NNN`` when omitted); a folder
  that holds an earlier run needs ``--overwrite``.

Help shows each default once: an option whose help text already names its default (or whose
default is empty) gets nothing added; any other gets ``(default: X)``.
"""

from __future__ import annotations

import argparse
import re

from geogrid_dem.cases import CASES
from geogrid_dem.rundir import add_out_args, check_common_args

__all__ = ["HelpFormatter", "case_parser", "check_common_args", "parse_checked"]

PRESETS = ("fast", "balanced", "accurate")


class HelpFormatter(argparse.HelpFormatter):
    """Wraps the description paragraph by paragraph (blank lines kept) and adds
    ``(default: X)`` to an option's help only where the help does not already name the
    default and the default says something."""

    def _fill_text(self, text, width, indent):
        import textwrap

        return "\n\n".join(textwrap.fill(" ".join(par.split()), width, initial_indent=indent,
                                         subsequent_indent=indent)
                           for par in text.split("\n\n") if par.strip())

    def _get_help_string(self, action):
        text = action.help or ""
        if re.search(r"\(default\b|\bdefault[:=]|%\(default\)", text, re.IGNORECASE):
            return text  # the help names its default already
        d = action.default
        if d is None or d is False or d is argparse.SUPPRESS or (isinstance(d, str) and not d) \
                or action.nargs == 0:
            return text
        return f"{text} (default: %(default)s)" if text else "(default: %(default)s)"


def case_parser(name: str, description: str, *, smoke: str, seed: int, threads: int = 0,
                preset: str | None = None, out_help: str = "") -> argparse.ArgumentParser:
    """The parser of case ``name`` (its command name, e.g. ``pullout-000``) with the shared
    options: ``--smoke`` (``smoke`` says what the test-sized run is), ``--out`` and
    ``--overwrite`` (``out_help`` adds to the help of ``--out``), ``--seed`` (default
    ``seed``), ``--threads`` (default ``threads``; 0 = OpenMP's default) and, when ``preset``
    is given (its help text), ``--preset``. The case adds its own options to it."""
    ap = argparse.ArgumentParser(prog=f"geogrid-dem run {name}", description=description,
                                 formatter_class=HelpFormatter)
    ap.add_argument("--smoke", action="store_true", help=f"test-sized run: {smoke}")
    add_out_args(ap, CASES[name].folder, help_extra=out_help)
    ap.add_argument("--seed", type=int, default=seed, help="random seed of the packing")
    ap.add_argument("--threads", type=int, default=threads,
                    help="OpenMP threads of this run; 0: OpenMP's default (every core, or "
                         "OMP_NUM_THREADS); results do not depend on it")
    if preset is not None:
        ap.add_argument("--preset", choices=PRESETS, default="",
                        help=f"speed-accuracy preset {preset} (docs/speed_accuracy.md)")
    return ap


def parse_checked(ap: argparse.ArgumentParser, argv) -> argparse.Namespace:
    """``ap.parse_args(argv)`` with the shared options checked (a negative ``--threads``, an
    ``--out`` that cannot be written: ``ap.error`` naming the flag and the value)."""
    a = ap.parse_args(argv)
    check_common_args(ap, a)
    return a
