"""The one command-line style of the benches a user runs (bench/README.md, "Inputs and
outputs"; docs/reliability.md): bad input is one line naming the option, the value and what
is allowed, never a traceback, and a second run never replaces the first one's results.

- :class:`BenchParser` (an ``argparse.ArgumentParser``) checks every number option after
  parsing: finite (``nan`` and ``inf`` are refused), and > 0, since a bench's numbers are
  magnitudes (grains, steps, strains, rates, pressures, sizes); >= 0 where the option's
  default is 0, or it is in :data:`ZERO_OK` or the bench's ``zero_ok`` (seeds take 0 too);
  any finite value where it is in :data:`SIGNED` or the bench's ``signed``.
- ``--out``: ``out="file"`` (the bench writes one results file), ``"folder"`` (it writes
  files into a folder) or ``"append"`` (it appends JSON lines: several runs into one file on
  purpose). A file or a folder that holds files of an earlier run is refused unless
  ``--overwrite`` (added by the parser) is given, naming it; without ``--out``, a default
  path that exists already becomes the next free numbered one (``name_001.json``,
  ``name_001/``), said on stderr. ``--out`` under a file, or a file where a folder is asked
  (and the reverse), is refused.
- :func:`numbers` parses a comma-separated list option by the same rules.
- :func:`run` calls a bench's ``main`` and turns a user-facing error (a ``cpp_dem``
  ``ParameterError``, a ``femcoupling`` ``FemInputError``, :class:`BenchInputError`, an
  ``OSError`` naming a file, a ``ValueError`` or ``TypeError`` of its input) into one line on
  stderr and exit status 2; Ctrl-C into "interrupted" and 130. ``BENCH_TRACEBACK=1`` shows
  the traceback as well.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

__all__ = ["BenchInputError", "BenchParser", "numbers", "run"]

#: Number options (dests) of any bench that may be 0: a count of extra or warm-up runs, an
#: OpenMP thread count (0: its default), a damping, a friction, a prestress, a wait.
ZERO_OK = frozenset({"threads", "warmup", "extra_repeats", "alone_runs", "big_seeds",
                     "wait_idle", "damping", "friction", "prestress", "prep_friction",
                     "periodic_prep_friction", "dump_contacts_at"})
#: ... and that may take any finite value: a sheet's tension (negative: a band in
#: compression).
SIGNED = frozenset({"tension"})


class BenchInputError(ValueError):
    """A bench's input refused (one line: the option, the value and what is allowed)."""


def _is_number_type(t) -> bool:
    return t in (int, float)


def _allowed(lo: str) -> str:
    return {"pos": "> 0 (a finite number)", "nonneg": ">= 0 (a finite number)",
            "signed": "a finite number"}[lo]


def _bad(x, lo: str) -> bool:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return False  # (not a number option's value: left to the bench)
    v = float(x)
    if not math.isfinite(v):
        return True
    return (lo == "pos" and not v > 0) or (lo == "nonneg" and not v >= 0)


def numbers(text, option: str, *, kind=float, lo: str = "pos", minimum=None) -> list:
    """The comma-separated list ``text`` of option ``option`` as numbers of ``kind``, each
    checked as :class:`BenchParser` checks a number option (``lo``: "pos", "nonneg" or
    "signed"; ``minimum``: also >= it); an empty list is refused. Raises
    BenchInputError."""
    parts = [p.strip() for p in str(text).split(",")]
    if not parts or any(not p for p in parts):
        raise BenchInputError(f"{option}={text!r}: must be a comma-separated list of "
                              f"{'whole numbers' if kind is int else 'numbers'}, none empty")
    out = []
    for p in parts:
        try:
            v = kind(p)
        except ValueError:
            raise BenchInputError(f"{option}={text!r}: {p!r} is not a "
                                  f"{'whole number' if kind is int else 'number'}") from None
        if _bad(v, lo) or (minimum is not None and not v >= minimum):
            what = _allowed(lo) + ("" if minimum is None else f", and >= {minimum:g}")
            raise BenchInputError(f"{option}={text!r}: {p} is not allowed; each must be {what}")
        out.append(v)
    return out


def _numbered(path: Path) -> Path:
    """The next free numbered sibling of ``path``: ``stem_001.suffix`` (a file) or
    ``name_001`` (a folder)."""
    for k in range(1, 100_000):
        cand = path.with_name(f"{path.stem}_{k:03d}{path.suffix}") if path.suffix \
            else path.with_name(f"{path.name}_{k:03d}")
        if not cand.exists():
            return cand
    raise BenchInputError(f"--out={path}: no free numbered name beside it; give --out")


class BenchParser(argparse.ArgumentParser):
    """See the module doc. ``out``: how the bench writes its ``--out`` ("file", "folder",
    "append" or None: it has no ``--out``); ``zero_ok``, ``signed``: options (their dests)
    that may be 0, or any finite number."""

    def __init__(self, *args, out: str | None = None, zero_ok=(), signed=(), **kw):
        super().__init__(*args, **kw)
        if out not in (None, "file", "folder", "append"):
            raise ValueError(f"out={out!r}: one of 'file', 'folder', 'append' or None")
        self._out_mode = out
        self._zero_ok = set(zero_ok) | ZERO_OK
        self._signed = set(signed) | SIGNED
        self._out_default = None
        self._out_type = None
        if out in ("file", "folder"):
            self.add_argument("--overwrite", action="store_true",
                              help="replace the results of an earlier run in --out")

    def add_argument(self, *args, **kw):
        if "--out" in args and self._out_mode is not None:
            # (the default is applied in parse_args, where a path of an earlier run becomes
            # a numbered one)
            self._out_default = kw.get("default")
            self._out_type = kw.get("type")
            kw["default"] = None
        return super().add_argument(*args, **kw)

    def _domain(self, action) -> str:
        if action.dest in self._signed:
            return "signed"
        default = action.default
        zero_default = (default == 0 if isinstance(default, (int, float))
                        and not isinstance(default, bool) else False)
        if action.dest in self._zero_ok or zero_default or "seed" in action.dest:
            return "nonneg"
        return "pos"

    def parse_args(self, args=None, namespace=None):
        ns = super().parse_args(args, namespace)
        for action in self._actions:
            if not _is_number_type(action.type) or not hasattr(ns, action.dest):
                continue
            v = getattr(ns, action.dest)
            if v is None:
                continue
            lo = self._domain(action)
            flag = action.option_strings[-1] if action.option_strings else action.dest
            for x in (v if isinstance(v, (list, tuple)) else [v]):
                if _bad(x, lo):
                    self.error(f"{flag}={x!r}: must be {_allowed(lo)}")
        if self._out_mode is not None and hasattr(ns, "out"):
            ns.out = self._check_out(ns)
        return ns

    def _check_out(self, ns):
        given = ns.out is not None
        raw = ns.out if given else self._out_default
        if raw is None:
            return None
        path = Path(raw)
        mode = self._out_mode
        for parent in path.parents:
            if parent.exists():
                if not parent.is_dir():
                    self.error(f"--out={path}: {parent} is a file, not a folder")
                if not path.exists() and not os.access(parent, os.W_OK | os.X_OK):
                    self.error(f"--out={path}: cannot be written: {parent} is not writable")
                break
        overwrite = bool(getattr(ns, "overwrite", False))
        if mode == "append":
            if path.is_dir():
                self.error(f"--out={path}: is a folder; name a file (JSON lines are appended "
                           "to it)")
        elif mode == "file":
            if path.is_dir():
                self.error(f"--out={path}: is a folder; name a file (the results are written "
                           "to it)")
            if path.exists() and not overwrite:
                if given:
                    self.error(f"--out={path}: holds the results of an earlier run; give "
                               "another file, or --overwrite to replace them")
                path = _numbered(path)
                print(f"[{self.prog}] {raw} holds an earlier run's results: writing {path}",
                      file=sys.stderr, flush=True)
        else:  # folder
            if path.exists() and not path.is_dir():
                self.error(f"--out={path}: exists and is not a folder; name a folder")
            if path.is_dir() and any(path.iterdir()) and not overwrite:
                if given:
                    self.error(f"--out={path}: holds the files of an earlier run; give "
                               "another folder, or --overwrite to write over them")
                path = _numbered(path)
                print(f"[{self.prog}] {raw} holds an earlier run's files: writing into "
                      f"{path}", file=sys.stderr, flush=True)
        try:  # (the folder the results go into, made now: a place no one can write in is
            # said before the run, not after it)
            (path if mode == "folder" else path.parent).mkdir(parents=True, exist_ok=True)
        except OSError as e:
            self.error(f"--out={path}: cannot be written: {e.strerror or e}")
        if path.exists() and not os.access(path, os.W_OK):
            self.error(f"--out={path}: is not writable")
        return self._out_type(str(path)) if callable(self._out_type) else \
            (str(path) if isinstance(raw, str) else path)


def _user_errors() -> tuple:
    errs = [BenchInputError, OSError, ValueError, TypeError]
    try:
        from cpp_dem import ParameterError

        errs.append(ParameterError)
    except ImportError:
        pass
    return tuple(errs)


def run(main, argv=None) -> int:
    """``main(argv)``'s exit status, with a user-facing error as one line on stderr (exit
    status 2) and Ctrl-C as "interrupted" (130). See the module doc."""
    prog = Path(sys.argv[0]).name
    try:
        status = main(argv) if argv is not None else main()
    except KeyboardInterrupt:
        print(f"[{prog}] interrupted", file=sys.stderr, flush=True)
        return 130
    except _user_errors() as e:
        if os.environ.get("BENCH_TRACEBACK") == "1":
            raise
        text = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if isinstance(e, OSError) and e.filename and str(e.filename) not in text:
            text = f"{e.filename}: {text}"
        name = "" if isinstance(e, BenchInputError) else f"{type(e).__name__}: "
        print(f"{prog}: error: {name}{text}", file=sys.stderr, flush=True)
        return 2
    return status if isinstance(status, int) and not isinstance(status, bool) else 0


def study_parser(name: str, doc: str, *, runs: bool = False) -> BenchParser:
    """The parser of a study over seeds whose docs table is rendered from its data file:
    ``--out`` (the data file, default ``results/bench_runs/<name>.json``), ``--table FILE``
    (print the docs' table of a data file and run nothing) and, with ``runs``, ``--runs``
    (the folder of the case's runs, default beside ``--out``). ``doc`` is the bench's
    module doc."""
    import argparse

    ap = BenchParser(out="file", description=doc,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=f"results/bench_runs/{name}.json",
                    help="the JSON file of the runs and the paired differences")
    ap.add_argument("--table", default="", help="print the docs' table of this data file, "
                    "and run nothing")
    if runs:
        ap.add_argument("--runs", default="", help="the folder of the case's runs (default: "
                        "beside --out, <out stem>_runs/)")
    return ap


def parse_study(ap: argparse.ArgumentParser, table) -> argparse.Namespace | None:
    """A study's arguments (:func:`study_parser`), its ``--seeds`` and ``--at`` lists parsed;
    None after printing ``table(data)`` of ``--table``'s data file (nothing to run)."""
    import json

    a = ap.parse_args()
    if a.table:
        print("\n".join(table(json.loads(Path(a.table).read_text()))))
        return None
    a.seeds = numbers(a.seeds, "--seeds", kind=int, lo="nonneg")
    a.at = numbers(a.at, "--at")
    return a


def run_triaxial_case(args: list, what: str) -> None:
    """``cases/triaxial.py`` with ``args`` in a process of one OpenMP thread;
    :class:`BenchInputError` naming ``what`` (the run) and the case's last words if it
    fails."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    p = subprocess.run([sys.executable, str(root / "cases" / "triaxial.py"), *args],
                       capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    if p.returncode != 0:
        raise BenchInputError(f"{what}: the case failed (exit {p.returncode}): "
                              f"{(p.stderr or p.stdout).strip()[-600:]}")
