"""One command-line style for every case: the parser that ``geogrid-dem run NAME``,
``python cases/NAME.py`` and ``python -m geogrid_dem.cases.NAME`` all use.

A case declares its own options once, in its ``parse_args``, on the parser that
:func:`case_parser` makes; the options every case shares (``--smoke``, ``--out``,
``--overwrite``, ``--seed``, ``--threads`` and, where the case has presets, ``--preset``) are
declared here, once, with one meaning each:

- ``--threads N``: the OpenMP threads of this run; ``0`` is automatic
  (``cpp_dem.apply_threads``: ``OMP_NUM_THREADS`` when set; else one thread for a scene below
  ``cpp_dem.scene.AUTO_SERIAL_BODIES`` bodies and the cores free of other work for a larger
  one, said on stderr when it leaves a core). Results do not depend on it.
- ``--out DIR``: the results folder (a new ``results/<case>/run_NNN`` when omitted); a folder
  that holds an earlier run needs ``--overwrite``.
- ``--allow-large``: lifts the caps (:data:`CAPS`) on the work one run may start: the count
  of seeds, of grains of a sample or element, of DEM elements or runs, of calibration grid
  points. Without it a case refuses a count above its cap, naming the count, the cap and the
  flag (:func:`check_cap`), before anything runs.

An option whose value would have no effect given the others is refused by name too
(:func:`given_options` tells the options given from those left at their default;
:func:`refuse_unused`).

Help shows each default once: an option whose help text already names its default (or whose
default is empty) gets nothing added; any other gets ``(default: X)``.
"""

from __future__ import annotations

import argparse
import re

from geogrid_dem.cases import CASES
from geogrid_dem.rundir import MAX_SEED, add_out_args, check_common_args, seed_error

__all__ = ["CAPS", "MAX_SEED", "HelpFormatter", "add_allow_large", "case_parser", "check_cap",
           "check_common_args", "check_seeds", "distinct", "given_options", "parse_checked",
           "refuse_unused", "warn_below"]

PRESETS = ("fast", "balanced", "accurate")

#: The most work one run starts without ``--allow-large`` (docs/cli.md, "Caps"): seeds
#: (packings of a study), grains of one sample or element (a clump counts as one), DEM
#: elements or runs of one command, points of a calibration grid.
CAPS = {"seeds": 100, "grains": 200_000, "elements or runs": 10_000, "grid points": 1_000,
        "snapshots": 100, "load levels": 100}
ALLOW_LARGE = "--allow-large"


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
    ``seed``), ``--threads`` (default ``threads``; 0 = automatic) and, when ``preset``
    is given (its help text), ``--preset``. The case adds its own options to it."""
    # (allow_abbrev=False: an abbreviated flag, --ou for --out, is refused rather than taken
    # for the flag it starts, which run.toml and the results folder would then miss)
    ap = argparse.ArgumentParser(prog=f"geogrid-dem run {name}", description=description,
                                 formatter_class=HelpFormatter, allow_abbrev=False)
    ap.add_argument("--smoke", action="store_true", help=f"test-sized run: {smoke}")
    add_out_args(ap, CASES[name].folder, help_extra=out_help)
    ap.add_argument("--seed", type=int, default=seed, help="random seed of the packing")
    ap.add_argument("--threads", type=int, default=threads,
                    help="OpenMP threads of this run; 0: automatic (OMP_NUM_THREADS when set; "
                         "else one thread for a small scene, the cores free of other work for "
                         "a large one); results do not depend on it")
    if preset is not None:
        ap.add_argument("--preset", choices=PRESETS, default="",
                        help=f"speed-accuracy preset {preset} (docs/speed_accuracy.md)")
    add_allow_large(ap)
    return ap


def add_allow_large(ap: argparse.ArgumentParser) -> None:
    """``--allow-large``, the one flag that lifts the caps of :data:`CAPS` (the cases' parsers
    and ``geogrid-dem calibrate``)."""
    caps = ", ".join(f"{v} {k}" for k, v in CAPS.items())
    ap.add_argument(ALLOW_LARGE, action="store_true",
                    help=f"run work above the caps ({caps}; docs/cli.md), which are refused "
                         "without it")


def _num(x: float) -> str:
    return f"{int(x)}" if float(x).is_integer() and abs(x) < 1e15 else f"{x:.3g}"


def cap_error(flag: str, value, count: float, kind: str, what: str = "",
              estimate: bool = False) -> str | None:
    """The refusal of ``count`` (``what``, default ``kind``) above the cap ``CAPS[kind]``, or
    None within it: names the flag and its value, the count, the cap and --allow-large."""
    cap = CAPS[kind]
    if not count > cap:
        return None
    return (f"{flag}={value}: {'about ' if estimate else ''}{_num(count)} {what or kind}, "
            f"more than the cap of {cap} {kind}; add {ALLOW_LARGE} to run it")


def check_cap(ap: argparse.ArgumentParser, a: argparse.Namespace, flag: str, value,
              count: float, kind: str, what: str = "", *, estimate: bool = False) -> None:
    """``ap.error`` (exit status 2) when ``count`` passes the cap ``CAPS[kind]`` and
    ``--allow-large`` was not given (see :func:`cap_error` for the words)."""
    msg = cap_error(flag, value, count, kind, what, estimate)
    if msg and not getattr(a, "allow_large", False):
        ap.error(msg)


_UNSET = object()


def given_options(ap: argparse.ArgumentParser, argv=None) -> frozenset[str]:
    """The dests of the options ``argv`` gives (None: ``sys.argv[1:]``), as opposed to those
    left at their default: parses ``argv`` again into a namespace whose every dest holds a
    marker, which argparse leaves where nothing was given. Call it after a parse that
    succeeded (the values are checked there)."""
    ns = argparse.Namespace(**{act.dest: _UNSET for act in ap._actions
                               if act.dest is not argparse.SUPPRESS})
    ns, _ = ap.parse_known_args(argv, ns)
    return frozenset(k for k, v in vars(ns).items() if v is not _UNSET)


def _flag(ap: argparse.ArgumentParser, dest: str) -> str:
    for act in ap._actions:
        if act.dest == dest:
            return next((o for o in act.option_strings if o.startswith("--")),
                        act.option_strings[0] if act.option_strings else dest)
    return "--" + dest.replace("_", "-")


def refuse_unused(ap: argparse.ArgumentParser, a: argparse.Namespace, given, dest: str,
                  why: str, fix: str = "") -> None:
    """``ap.error`` when the option ``dest`` was given (``given``: :func:`given_options`) but
    has no effect ``why`` (e.g. "without a PRS variant (--variants RE)"): names the flag, its
    value, why, and ``fix`` (what would make it count) or leaving it out."""
    if dest not in given:
        return
    flag = _flag(ap, dest)
    v = getattr(a, dest, None)
    shown = flag if isinstance(v, bool) else f"{flag}={v}"
    ap.error(f"{shown}: has no effect {why}; {fix + ', or ' if fix else ''}leave {flag} out")


def distinct(ap: argparse.ArgumentParser, flag: str, text, items) -> None:
    """``ap.error`` when ``items`` (the parsed values of ``flag``, given as ``text``) list one
    twice: a value listed twice would run twice, or once and say nothing."""
    seen: set = set()
    for x in items:
        if x in seen:
            ap.error(f"{flag}={text}: {x} is listed twice; list each once")
        seen.add(x)


def check_seeds(ap: argparse.ArgumentParser, flag: str, text, seeds) -> None:
    """``ap.error`` when a seed of ``seeds`` (the parsed values of ``flag``, given as ``text``)
    lies outside [0, :data:`MAX_SEED`]."""
    for s in seeds:
        if seed_error(flag, s):
            ap.error(f"{flag}={text}: the seed {s} is outside [0, {MAX_SEED}] (0 to 2**63 - "
                     "1: a run records its seed as a 64-bit integer)")


def warn_below(flag: str, value: float, low: float, unit: str, slip: str) -> None:
    """A ``cpp_dem.PhysicalRangeWarning`` (one line, ``[warning] ...``) when ``value`` of
    ``flag`` is below ``low`` (in ``unit``): a value that small is most likely a unit slip
    (``slip`` says which, e.g. "kPa given as Pa"). The run goes on: a tiny value may be
    meant."""
    if not value < low:
        return
    import warnings

    from cpp_dem.scene import PhysicalRangeWarning
    from geogrid_dem.warnings_display import shown_once

    with shown_once():
        warnings.warn(f"{flag}={value:g}: below {low:g} {unit}, likely a unit slip ({slip}); "
                      "the run goes on with it (filter cpp_dem.PhysicalRangeWarning if it is "
                      "meant)", PhysicalRangeWarning, stacklevel=2)


def parse_checked(ap: argparse.ArgumentParser, argv) -> argparse.Namespace:
    """``ap.parse_args(argv)`` with the shared options checked (a negative ``--threads``, an
    ``--out`` that cannot be written: ``ap.error`` naming the flag and the value)."""
    a = ap.parse_args(argv)
    check_common_args(ap, a)
    return a
