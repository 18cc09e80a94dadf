"""Run files, parameter rows and sweeps of the cases (the machinery behind ``geogrid-dem run``,
``geogrid-dem sweep`` and ``geogrid-dem calibrate``; docs/cli.md).

A run file's or a sweep row's parameters are a case's flags without their dashes. They are
checked against the case's own parser (geogrid_dem.options) before anything runs; a case runs
in its own interpreter (``python -m geogrid_dem.cases.MODULE``) so that Ctrl-C, a crash or a
killed Dask worker never takes the caller down with it.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import datetime as _dt
import difflib
import functools
import importlib
import io
import itertools
import json
import math
import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

from geogrid_dem import rundir
from geogrid_dem.cases import CASES
from geogrid_dem.provenance import git_commit, version


class RunFileError(Exception):
    """A run, sweep or calibration file (or a row of one) names a bad field; the message says
    which, its value and why. The command prints it and exits with status 1."""


class UsageError(RunFileError):
    """A command-line option of ``geogrid-dem`` itself has a bad value (exit status 2)."""

    def __init__(self, message: str, option: str | None = None):
        super().__init__(f"Invalid value for {option}: {message}" if option else message)


def case_command(name: str, *, field: str = "case") -> list[str]:
    """The interpreter command that runs case `name` (its module in geogrid_dem.cases)."""
    if not isinstance(name, str):
        raise RunFileError(f"{field}={name!r}: must be a string, the name of one case; "
                           f"allowed: {', '.join(CASES)}")
    if name not in CASES:
        raise RunFileError(f"{field}={name!r}: no such case; allowed: {', '.join(CASES)}")
    return [sys.executable, "-m", f"geogrid_dem.cases.{CASES[name].module}"]


@functools.lru_cache(maxsize=None)
def case_parser(case: str) -> argparse.ArgumentParser:
    """The argparse parser of case ``case``: the one its ``build_parser`` makes (the same one
    ``geogrid-dem run CASE`` and the case's script parse with)."""
    mod = importlib.import_module(f"geogrid_dem.cases.{CASES[case].module}")
    return mod.build_parser()


def _flags(case: str) -> dict[str, argparse.Action]:
    return {o: a for a in case_parser(case)._actions for o in a.option_strings
            if o.startswith("--")}


def param_action(case: str, key: str) -> argparse.Action | None:
    """The case's option that the run-file key ``key`` (a flag without its dashes, ``-`` or
    ``_``) names, or None."""
    return _flags(case).get("--" + key.replace("_", "-")) if isinstance(key, str) else None


def _spelling(key: str, where: str = "") -> str:
    return f"'{where}.{key}'" if where else repr(key)


def check_same_parameter(case: str, tables: list[tuple[str, dict[str, Any]]], *,
                         source: str) -> None:
    """Refuses two keys that set one parameter of the case, in one table or across
    ``tables`` (``(where, table)`` pairs, ``where`` e.g. "params" or "sweep"): two spellings
    (``cell-pressure`` and ``cell_pressure``) or a flag and its alias (``young`` and ``E``),
    which the last would settle without a word. Names both."""
    seen: dict[str, tuple[str, str]] = {}
    for where, table in tables:
        for key in table:
            act = param_action(case, key)
            if act is None:
                continue
            if act.dest in seen:
                k0, w0 = seen[act.dest]
                flag = next((o for o in act.option_strings if o.startswith("--")),
                            "--" + act.dest)
                raise RunFileError(
                    f"{source}: fields {_spelling(k0, w0)} and {_spelling(key, where)} set the "
                    f"same parameter ({' / '.join(act.option_strings)}): give {flag} once")
            seen[act.dest] = (key, where)


def check_params(case: str, params: dict[str, Any], *, source: str) -> None:
    """Refuses a parameter that is not a flag of the case (with a did-you-mean), ``help``,
    two keys that set one parameter (:func:`check_same_parameter`), a switch given a value
    other than true/false, and a flag that takes a value given true/false."""
    flags = _flags(case)
    for key, value in params.items():
        if not isinstance(key, str) or not key or key.startswith("-"):
            raise RunFileError(f"{source}: field {key!r}: write the flag's name without dashes")
        flag = "--" + key.replace("_", "-")
        act = flags.get(flag)
        if act is not None and act.dest == "help":
            raise RunFileError(f"{source}: field {key!r}: not a parameter (a run file runs the "
                               f"case); `geogrid-dem run {case} --help` lists its parameters")
        if act is None:
            names = sorted({f[2:] for f in flags if f not in ("--help",)})
            near = difflib.get_close_matches(key.replace("_", "-"), names, n=1)
            hint = f" (did you mean {near[0]}?)" if near else ""
            raise RunFileError(f"{source}: field {key!r}: not a parameter of the case {case!r}"
                               f"{hint}; allowed: {', '.join(names)}")
        scalar = isinstance(value, (bool, int, float, str))
        if not scalar and not (isinstance(value, list) and all(
                isinstance(v, (int, float, str)) and not isinstance(v, bool) for v in value)):
            raise RunFileError(f"{source}: field {key!r}={value!r}: must be a number, a "
                               "string, true/false or a list of numbers or strings")
        switch = act.nargs == 0
        if switch and not isinstance(value, bool):
            raise RunFileError(f"{source}: field {key}={value!r}: must be true or false (a "
                               "switch)")
        if not switch and isinstance(value, bool):
            raise RunFileError(f"{source}: field {key}={str(value).lower()}: takes a value "
                               f"({act.help or 'see the case --help'}), not true/false")
    check_same_parameter(case, [("", params)], source=source)


def check_argv(case: str, argv: list[str], *, source: str) -> None:
    """Parses ``argv`` with the case's own parse_args in this process (nothing is run), so a
    value the case refuses is reported against ``source`` before any work starts."""
    if "--help" in argv or "-h" in argv:
        return
    mod = importlib.import_module(f"geogrid_dem.cases.{CASES[case].module}")
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            mod.parse_args(list(argv))
    except SystemExit as e:
        if e.code in (0, None):
            return
        lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
        detail = lines[-1].split(": error: ", 1)[-1] if lines else f"exit status {e.code}"
        raise RunFileError(f"{source}: the case {case!r} refuses its parameters: {detail} "
                           f"(geogrid-dem run {case} --help lists them)") from None


def params_to_argv(params: dict[str, Any], *, source: str) -> list[str]:
    """The case's command-line flags from a table of parameters (keys without dashes). A value
    that starts with '-' (a negative number, a box below 0) is passed as ``--flag=value``, so
    that argparse does not take it for an option."""
    argv: list[str] = []

    def add(flag: str, text: str) -> None:
        if text.startswith("-"):
            argv.append(f"{flag}={text}")
        else:
            argv.extend((flag, text))

    for key, value in params.items():
        if not isinstance(key, str) or not key or key.startswith("-"):
            raise RunFileError(f"{source}: field {key!r}: write the flag's name without dashes")
        flag = "--" + key.replace("_", "-")
        if isinstance(value, bool):
            if value:
                argv.append(flag)
        elif isinstance(value, (int, float, str)):
            add(flag, str(value))
        elif isinstance(value, list) and all(isinstance(v, (int, float, str)) and
                                             not isinstance(v, bool) for v in value):
            add(flag, ",".join(str(v) for v in value))
        else:
            raise RunFileError(f"{source}: field {key!r}={value!r}: must be a number, a string, "
                               "true/false or a list of numbers or strings")
    return argv


def out_of(argv: list[str]) -> Path | None:
    """The results folder of ``argv``: its last --out, as argparse takes it."""
    found = None
    for k, a in enumerate(argv):
        if a == "--out" and k + 1 < len(argv):
            found = Path(argv[k + 1])
        elif a.startswith("--out="):
            found = Path(a.split("=", 1)[1])
    return found


def write_run_file(out: Path, case: str, params: dict[str, Any]) -> None:
    """OUT/run.toml: the case, its parameters and where they came from (rerunnable). Always
    valid TOML (UTF-8; keys and strings quoted and escaped as TOML has them, so that any text,
    an emoji in --out included, reads back as it was given). ``resume`` is not written (a run
    file runs the whole run; --resume is given on the command line), nor ``overwrite``. A
    value that is not text (a file name of bytes that are not UTF-8) is a RunFileError."""
    params = {k: v for k, v in params.items() if k not in ("resume", "overwrite")}
    lines = ["# Written by geogrid-dem; `geogrid-dem run` this file to run it again.",
             f"case = {_toml_str(case)}", "", "[params]"]
    for key, value in params.items():
        lines.append(f"{_toml_key(str(key))} = {_toml_value(value, key)}")
    lines += ["", "[provenance]", f"version = {_toml_str(version())}",
              f"commit = {_toml_str(git_commit())}",
              f"date = {_toml_str(_dt.datetime.now(_dt.timezone.utc).isoformat())}",
              f"python = {_toml_str(sys.version.split()[0])}", ""]
    text = "\n".join(lines)
    try:
        tomllib.loads(text)  # (written only when it reads back)
    except tomllib.TOMLDecodeError as e:
        raise RunFileError(f"{out / 'run.toml'}: would not be valid TOML ({e}); not "
                           "written") from None
    out.mkdir(parents=True, exist_ok=True)
    rundir.write_atomic(out / "run.toml", text)


#: TOML's escapes of a basic string; other control characters are written \uXXXX.
_TOML_ESCAPES = {"\\": "\\\\", '"': '\\"', "\b": "\\b", "\t": "\\t", "\n": "\\n",
                 "\f": "\\f", "\r": "\\r"}


def _toml_str(s: str, key: str = "") -> str:
    """``s`` as a TOML basic string (UTF-8 text as it is; backslash, quote and control
    characters escaped)."""
    try:
        s.encode("utf-8")
    except UnicodeEncodeError:
        raise RunFileError(f"run.toml: field {key or '?'!r}={s!r}: not valid UTF-8 text, "
                           "which a run file (TOML) cannot hold") from None
    out = []
    for ch in s:
        if ch in _TOML_ESCAPES:
            out.append(_TOML_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_key(key: str) -> str:
    """A TOML key: bare where it may be (letters, digits, '-', '_'), else quoted."""
    import re

    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_str(key, key)


def _toml_value(v: Any, key: str = "") -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int) and -2**63 <= v < 2**63:
        return repr(v)
    if isinstance(v, float):
        return repr(v)  # (nan, inf and -inf are TOML's too)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x, key) for x in v) + "]"
    return _toml_str(str(v), key)  # (an integer beyond TOML's 64 bits as its digits)


def _takes_text(act: argparse.Action | None) -> bool:
    """Whether the option ``act`` takes text (a folder, a name, a comma list), whose value a
    run file keeps as it was written, rather than a number."""
    if act is None:
        return False
    t = act.type
    return t is None or t is str or (isinstance(t, type) and issubclass(t, os.PathLike))


def argv_to_params(argv: list[str], case: str | None = None) -> dict[str, Any]:
    """The flags given on the command line as run-file parameters (for OUT/run.toml). A
    value is written as a number where the case's option (``case``'s parser) takes one; an
    option that takes text (``--out``, a comma list, a name) keeps its text unless the
    number reads back as the very same text (``--out 007`` stays "007", ``--out 1e3`` stays
    "1e3": as numbers they would name the folders 7 and 1000.0)."""
    params: dict[str, Any] = {}

    def value(key: str, text: str) -> Any:
        v = _number_or_string(text)
        if case is not None and not isinstance(v, str) and _takes_text(
                param_action(case, key)) and str(v) != text:
            return text
        return v

    k = 0
    while k < len(argv):
        a = argv[k]
        if not a.startswith("--"):
            k += 1
            continue
        key, _, inline = a[2:].partition("=")
        if inline:
            params[key] = value(key, inline)
        elif k + 1 < len(argv) and not argv[k + 1].startswith("--"):
            params[key] = value(key, argv[k + 1])
            k += 1
        else:
            params[key] = True
        k += 1
    return params


def _number_or_string(s: str) -> Any:
    for cast in (int, float):
        try:
            return cast(s)
        except ValueError:
            pass
    return s


def load_toml(path: Path, kind: str) -> dict[str, Any]:
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise RunFileError(f"{kind} file {path}: not found") from None
    except tomllib.TOMLDecodeError as e:
        raise RunFileError(f"{kind} file {path}: not valid TOML: {e}") from None
    if "case" not in data:
        raise RunFileError(f"{kind} file {path}: field 'case' is missing; allowed: "
                           f"{', '.join(CASES)}")
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise RunFileError(f"{kind} file {path}: field 'params' must be a table ([params])")
    known = {"case", "params", "provenance", "out", "sweep"}
    for key in data:
        if key not in known:
            raise RunFileError(f"{kind} file {path}: field {key!r} is not known; allowed at the "
                               f"top: {', '.join(sorted(known))} (a case's parameters go in "
                               "[params])")
    case_command(data["case"], field=f"{path}: case")
    return data


def run_case(case: str, argv: list[str], *, source: str | None = None) -> int:
    """Runs the case's script in a fresh interpreter with `argv` (its output passes through as
    it comes); an argparse rejection (exit 2) of a run file's parameters is reported against
    the run file. Returns the exit status."""
    # its own process group: a Ctrl-C reaches it once, forwarded from here (not also from the
    # terminal), and a SIGINT or SIGTERM sent to this command is passed on, not left behind.
    # The handler is installed before the case starts: a caught signal is reset to its default
    # in the new program, where an ignored one (this command started with SIGINT ignored, as a
    # shell's background job or a test runner's worker is) would stay ignored in the case, and
    # the forwarded Ctrl-C would be lost.
    import threading

    proc = None
    pending: list[int] = []

    def forward(sig, _frame):  # to the case's whole group (its worker processes too), as a
        if proc is None:         # terminal's Ctrl-C would
            pending.append(sig)
            return
        try:
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            try:
                proc.send_signal(sig)
            except ProcessLookupError:
                pass

    main_thread = threading.current_thread() is threading.main_thread()
    old = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)} \
        if main_thread else {}
    tail: list[str] = []
    try:
        proc = subprocess.Popen([*case_command(case), *argv], stderr=subprocess.PIPE,
                                text=True, bufsize=1, process_group=0)
        for sig in pending:
            forward(sig, None)
        for line in proc.stderr:
            sys.stderr.write(line)
            sys.stderr.flush()
            tail = (tail + [line.rstrip()])[-5:]
        status = proc.wait()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    if status == 2 and source is not None:
        detail = next((t for t in reversed(tail) if t.strip()), "")
        raise RunFileError(f"{source}: the case {case!r} rejected its parameters: {detail}; "
                           f"a field `name` is the case's flag --name (geogrid-dem run {case} "
                           "--help lists them)")
    return status


def _value_key(x: Any) -> tuple:
    """What makes two values of a sweep list give the same run: equal numbers (1 and 1.0),
    equal text, the same switch."""
    if isinstance(x, bool):
        return ("switch", x)
    if isinstance(x, int):
        return ("number", x)
    if isinstance(x, float):
        return ("number", int(x)) if x.is_integer() else ("number", x)
    return (type(x).__name__, json.dumps(x, sort_keys=True, default=str))


#: The largest sweep run without --max-rows.
MAX_ROWS = 10_000


def sweep_rows(data: dict[str, Any], source: str,
               max_rows: int = MAX_ROWS) -> list[dict[str, Any]]:
    """The parameter table of a sweep file: one dict of varied parameters per row. A table of
    more than ``max_rows`` rows is refused (before it is built) with its size."""
    sweep = data.get("sweep")
    if not isinstance(sweep, dict) or not sweep:
        raise RunFileError(f"{source}: field 'sweep' is missing: a [sweep] table with lists of "
                           "values per parameter")
    mode = sweep.get("mode", "product")
    values = {k: v for k, v in sweep.items() if k != "mode"}
    if mode not in ("product", "list"):
        raise RunFileError(f"{source}: field 'sweep.mode'={mode!r}: must be 'product' or 'list'")
    for key, v in values.items():
        if not isinstance(v, list) or not v:
            raise RunFileError(f"{source}: field 'sweep.{key}'={v!r}: must be a non-empty list")
        if key == "out":
            raise RunFileError(f"{source}: field 'sweep.out': not a parameter to sweep (each "
                               "row writes into OUT/row_NNN of the top-level 'out')")
        if mode == "product":
            # (a value listed twice would run the same rows twice)
            seen: set = set()
            for x in v:
                if _value_key(x) in seen:
                    raise RunFileError(f"{source}: field 'sweep.{key}'={v!r}: {x!r} is listed "
                                       "twice (it would run the same rows twice); list each "
                                       "value once")
                seen.add(_value_key(x))
    if not values:
        raise RunFileError(f"{source}: [sweep] has no parameter lists")
    keys = list(values)
    n_rows = math.prod(len(v) for v in values.values()) if mode == "product" else \
        max(len(v) for v in values.values())
    if n_rows > max_rows:
        shape = " x ".join(f"{len(v)} {k}" for k, v in values.items())
        raise RunFileError(
            f"{source}: field 'sweep' makes {n_rows} rows ({shape}, mode {mode!r}): more than "
            f"the cap of {max_rows}. That is {n_rows} case runs and folders; at even 10 s a "
            f"row (a smoke run) on 10 workers about {n_rows * 10 / 10 / 86400:.3g} days. "
            "Shrink the table, or raise the cap with --max-rows N")
    if mode == "product":
        return [dict(zip(keys, combo)) for combo in itertools.product(*values.values())]
    lengths = {k: len(v) for k, v in values.items()}
    if len(set(lengths.values())) != 1:
        raise RunFileError(f"{source}: field 'sweep' (mode 'list'): the lists must have equal "
                           f"lengths, got {lengths}")
    n = next(iter(lengths.values()))
    rows = [{k: values[k][i] for k in keys} for i in range(n)]
    first: dict[tuple, int] = {}
    for i, row in enumerate(rows):
        text = tuple(sorted((k, _value_key(v)) for k, v in row.items()))
        if text in first:
            raise RunFileError(f"{source}: field 'sweep' (mode 'list'): rows {first[text]} and "
                               f"{i} are the same ({', '.join(f'{k}={v!r}' for k, v in row.items())}"
                               "): each would run the same case twice; list each row once")
        first[text] = i
    return rows


def _row_params(fixed: dict[str, Any], row: dict[str, Any], row_dir: Path,
                threads: int) -> dict[str, Any]:
    params = {**fixed, **row, "out": str(row_dir)}
    params.setdefault("threads", threads)
    return params


def _row_finished(row_dir: Path, case: str, params: dict[str, Any]) -> bool:
    """The row's folder holds its finished run: a summary.json, a run.toml of the same case
    and parameters (``threads`` and ``workers`` aside: they do not change what a row
    computes, :data:`_RESULT_FREE`), and no manifest saying the run did not complete."""

    run_file = row_dir / "run.toml"
    if not (row_dir / "summary.json").exists() or not run_file.exists():
        return False
    try:
        with open(run_file, "rb") as f:
            old = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError):
        return False
    manifest = rundir.run_status(row_dir)
    if manifest is not None and manifest.get("status", "complete") != "complete":
        return False
    theirs = old.get("params") if isinstance(old.get("params"), dict) else {}

    def computed(d: dict) -> dict:
        return {k: v for k, v in d.items() if k not in _RESULT_FREE}

    return (old.get("case") == case
            and computed(theirs) == computed(json.loads(json.dumps(params))))


#: Row parameters that do not change what a row computes (docs/cli.md: the results do not
#: depend on the threads, nor on the workers of a case that runs its parts side by side).
_RESULT_FREE = ("threads", "workers")

#: Row parameters that do not make a row another sweep's: its folder (a sweep folder that was
#: moved) and those of :data:`_RESULT_FREE`.
_ROW_FREE = ("out", *_RESULT_FREE)


def _links_in(folder: Path) -> list[Path]:
    """The symbolic links in ``folder`` and below (links to folders are not followed)."""
    found = []
    for here, dirs, files in os.walk(folder, followlinks=False):
        found += [Path(here) / n for n in dirs + files if os.path.islink(os.path.join(here, n))]
    return sorted(found)


def _row_unrecorded(row_dir: Path) -> list[Path]:
    """The files in ``row_dir`` (and below) that no run recorded: every run folder in it (the
    row's own, or the sub-runs of a study) lists what it wrote in its manifest (a killed run:
    what it wrote since it started, geogrid_dem.rundir); run.toml, manifests and locks are
    the sweep's and the runs' own."""

    recorded: set[Path] = set()
    for m in row_dir.rglob(rundir.MANIFEST):
        d = m.parent
        manifest = rundir.run_status(d) or {}
        status = manifest.get("status")
        if status == "running":
            status = "killed"
        files = rundir._files(d)
        bad = set(rundir._unrecorded(d, files, manifest, status))
        recorded |= {p for p in files if p not in bad}
    return sorted(p for p in row_dir.rglob("*")
                  if p.is_file() and p.name not in rundir._FREE and not rundir.is_temporary(p)
                  and p not in recorded)


def check_row_folder(row_dir: Path, case: str, params: dict[str, Any], *, source: str) -> None:
    """Refuses (RunFileError, one line naming the row's folder) a row folder that the sweep
    may not write into: a symbolic link, or a link inside it; a folder that holds another
    sweep's row (its run.toml names another case or other parameters; ``out`` and
    ``threads`` aside); files without a run.toml (not a sweep's row); a row another live
    process is writing into; files that its earlier run did not record (yours?). A row of this
    sweep that did not finish passes: the case replaces only the files its earlier run
    recorded (``--overwrite``, added by the row). Nothing is removed here."""

    if row_dir.is_symlink():
        raise RunFileError(f"{source}: {row_dir} is a symbolic link (to {os.readlink(row_dir)}); "
                           "a sweep writes each row into a folder of its own and follows no "
                           "link: remove the link, or name another 'out'")
    if not row_dir.exists():
        return
    if not row_dir.is_dir():
        raise RunFileError(f"{source}: {row_dir} exists and is not a folder; move it, or name "
                           "another 'out'")
    links = _links_in(row_dir)
    if links:
        raise RunFileError(f"{source}: {row_dir} holds {len(links)} symbolic links (e.g. "
                           f"{links[0].relative_to(row_dir)}); a sweep follows no link in a "
                           "results folder: remove them, or name another 'out'")
    run_file = row_dir / "run.toml"
    if not run_file.is_file():
        held = sorted(row_dir.iterdir())
        if held:
            raise RunFileError(f"{source}: {row_dir} holds {len(held)} entries but no run.toml "
                               f"(e.g. {held[0].name}): not a row of a sweep (files of yours, "
                               "or of another run); nothing was removed: move them, or name "
                               "another 'out'")
        return
    try:
        with open(run_file, "rb") as f:
            old = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise RunFileError(f"{source}: {run_file} cannot be read ({e}); nothing was removed: "
                           "move that folder, or name another 'out'") from None
    mine = json.loads(json.dumps(params))
    theirs = old.get("params") if isinstance(old.get("params"), dict) else {}
    if old.get("case") != case:
        diff = f"case={old.get('case')!r} there, {case!r} here"
    else:
        keys = [k for k in {**theirs, **mine} if k not in _ROW_FREE
                and theirs.get(k, "(unset)") != mine.get(k, "(unset)")]
        diff = (f"{keys[0]}={theirs.get(keys[0], '(unset)')!r} there, "
                f"{mine.get(keys[0], '(unset)')!r} here") if keys else None
    if diff:
        raise RunFileError(f"{source}: {row_dir} holds a row of another sweep ({diff}); a sweep "
                           "replaces only its own rows: nothing was removed; name another "
                           "'out', or move that folder")
    lock = rundir._read_json(row_dir / rundir.LOCK) if (row_dir / rundir.LOCK).exists() else None
    if lock and isinstance(lock.get("pid"), int) and not rundir.lock_holder_gone(lock):
        raise RunFileError(f"{source}: {row_dir}: another run is writing into it (pid "
                           f"{lock.get('pid')} on {lock.get('host')}); wait for it to end, or "
                           "name another 'out'")
    unrecorded = _row_unrecorded(row_dir)
    if unrecorded:
        raise RunFileError(f"{source}: {row_dir} holds {len(unrecorded)} files that its earlier "
                           f"run did not record (e.g. {unrecorded[0].relative_to(row_dir)}): "
                           "files of yours? Nothing was removed; move them, or name another "
                           "'out'")


#: Run before the case, in a fresh interpreter (no threads): asks Linux to SIGKILL this
#: process when the worker thread that started it dies (PR_SET_PDEATHSIG, kept across exec),
#: then becomes the case. A killed Dask worker so leaves no orphan writing into the row's
#: folder while Dask runs the row again elsewhere. (A preexec_fn would run in the forked
#: child of a threaded worker, which is not safe.) A worker killed before the signal was
#: armed has already made this process an orphan (its parent pid is no longer the worker's,
#: given as the first argument): it exits at once rather than run the row beside the retry.
_DIE_WITH_PARENT = ("import ctypes, os, signal, sys\n"
                    "try:\n"
                    "    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))\n"
                    "except Exception:\n"
                    "    pass\n"
                    "if os.getppid() != int(sys.argv[1]):\n"
                    "    os._exit(137)\n"
                    "os.execv(sys.argv[2], sys.argv[2:])\n")


def _run_row(command: list[str], argv: list[str], env: dict[str, str]) -> dict[str, Any]:
    """One row, on a Dask worker: the case in its own interpreter. A row whose folder holds an
    earlier attempt (a row that did not finish, or one run again after a killed worker) is
    given ``--overwrite``: the case removes the files that attempt recorded, and only those
    (geogrid_dem.rundir); nothing else in the folder is removed."""

    dest = out_of(argv)
    if (dest is not None and dest.is_dir() and not dest.is_symlink()
            and "--overwrite" not in argv and "--resume" not in argv
            and any(dest.rglob(rundir.MANIFEST))):
        argv = [*argv, "--overwrite"]
    if dest is not None:
        # An earlier attempt's case dies with its killed worker (SIGKILL by the parent-death
        # signal) a moment after Dask has given the row to another worker: wait for it (at
        # most 30 s) rather than take its lock for another run's.
        lock, t_wait = rundir._read_json(dest / rundir.LOCK), time.perf_counter()
        while (lock and isinstance(lock.get("pid"), int) and rundir._pid_alive(lock["pid"])
               and time.perf_counter() - t_wait < 30):
            time.sleep(0.1)
    t0 = time.perf_counter()
    wrap = ([sys.executable, "-c", _DIE_WITH_PARENT, str(os.getpid())]
            if sys.platform.startswith("linux") else [])
    proc = subprocess.run([*wrap, *command, *argv], capture_output=True, text=True,
                          env={**os.environ, **env})
    return {"returncode": proc.returncode, "wall_s": time.perf_counter() - t0,
            "stderr_tail": "\n".join((proc.stderr or "").strip().splitlines()[-5:])}


def _flatten(prefix: str, obj: Any, out: dict[str, Any]) -> None:
    if isinstance(obj, dict):
        for k, v in obj.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(obj, (int, float, str, bool)) or obj is None:
        out[prefix] = obj


def write_results(out: Path, rows: list[dict[str, Any]]) -> Path:
    """OUT/results.csv (rewritten atomically), and results.parquet where pyarrow is."""
    columns: list[str] = []
    for r in rows:
        for k in r:
            if k not in columns:
                columns.append(k)
    tmp = out / ".results.csv.tmp"
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        for r in rows:
            w.writerow(r)
        f.flush()
        os.fsync(f.fileno())
    tmp.replace(out / "results.csv")
    return out / "results.csv"


def _summary_of(row_dir: Path) -> dict[str, Any]:
    flat: dict[str, Any] = {}
    try:
        _flatten("", json.loads((row_dir / "summary.json").read_text()), flat)
    except (OSError, json.JSONDecodeError):
        pass
    return {f"summary.{k}": v for k, v in flat.items()}


def _dask_client(scheduler: str | None, workers: int):
    """(client, cluster): the scheduler at ``scheduler`` (an address or a scheduler file), or
    a LocalCluster of ``workers`` single-threaded processes (cluster None for a scheduler)."""
    from cpp_dem import ParameterError
    from cpp_dem.elements.cluster import dask_client

    try:
        return dask_client(scheduler, workers)
    except ParameterError as e:
        raise UsageError(str(e), option="--scheduler") from None
    except Exception as e:  # noqa: BLE001  (unreachable, refused, a bad scheduler file ...)
        if not scheduler:
            raise RunFileError(f"--workers={workers}: the local Dask cluster did not "
                               f"start: {type(e).__name__}: {e}") from None
        raise UsageError(
            f"{scheduler!r}: could not connect to a Dask scheduler there "
            f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else 'no detail'}); is "
            "it running, and is the address (tcp://host:port) or the scheduler file right?",
            option="--scheduler") from None


def _started_client(scheduler: str | None, workers: int, box: list) -> bool:
    """_dask_client with a Ctrl-C during the start held back until the cluster is up (a
    cluster stopped half-started is not closed cleanly). Puts (client, cluster) into ``box``
    before Ctrl-C is let through again (the caller closes what is in it, in a ``finally``
    around this call); returns whether a Ctrl-C came during the start."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        box.extend(_dask_client(scheduler, workers))
        return False
    held: list[int] = []
    old = signal.signal(signal.SIGINT, lambda *_: held.append(1))
    try:
        box.extend(_dask_client(scheduler, workers))
    finally:
        signal.signal(signal.SIGINT, old)
    return bool(held)


def _close_client(client, cluster) -> None:
    """Closes the client and the local cluster; a second Ctrl-C does not cut it short."""
    import threading

    old = None
    if threading.current_thread() is threading.main_thread():
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    finally:
        if old is not None:
            signal.signal(signal.SIGINT, old)


def _run_on_dask(todo, results, script, case, scheduler, workers, threads, out) -> None:
    from dask.distributed import as_completed

    env = {"OMP_NUM_THREADS": str(threads or (os.cpu_count() or 1))}
    box: list = []
    try:
        if _started_client(scheduler, workers, box):
            raise KeyboardInterrupt
        client = box[0]
        futures = {}
        for i, row_dir, params, argv, base in todo:
            # The row's run.toml first: its folder is this sweep's row from now on (an
            # unfinished row's files are replaced by the case, those it recorded only).
            write_run_file(row_dir, case, params)
            # retries: a row whose worker died is run again (Dask itself reschedules a task
            # lost with its worker up to distributed.scheduler.allowed-failures times; a
            # KilledWorker after that, or any error, makes the row 'failed', not the sweep).
            fut = client.submit(_run_row, script, argv, env, pure=False, key=f"row-{i:03d}",
                                retries=2)
            futures[fut] = (i, row_dir, params, base)
        t0 = time.perf_counter()
        for n_done, fut in enumerate(as_completed(futures), start=1):
            i, row_dir, params, base = futures[fut]
            try:
                r = fut.result()
            except Exception as e:  # noqa: BLE001  (KilledWorker, a lost scheduler ...)
                r = {"returncode": -1, "wall_s": 0.0,
                     "stderr_tail": f"{type(e).__name__}: {e}"}
            # A row that completed but exits non-zero (a coupled run that did not converge:
            # femcoupling.coupling.status.EXIT_CODES) keeps its results: 'completed', with its code.
            done = ((rundir.run_status(row_dir) or {}).get("status") == "complete"
                    if row_dir.is_dir() else False)
            ok = r["returncode"] == 0 or done
            if ok:
                write_run_file(row_dir, case, params)
            results[i] = {**base, "status": ("ok" if r["returncode"] == 0 else
                                             "completed" if ok else "failed"),
                          "exit_code": r["returncode"], "wall_s": round(r["wall_s"], 3),
                          **(_summary_of(row_dir) if ok else {"error": r["stderr_tail"]})}
            write_results(out, [x for x in results if x is not None])
            el = time.perf_counter() - t0
            eta = el / n_done * (len(todo) - n_done)
            said = results[i]["status"].upper() if not ok else (
                "ok" if r["returncode"] == 0 else f"completed (exit {r['returncode']})")
            print(f"[sweep] row {i:03d} {said} in {r['wall_s']:.1f} s "
                       f"({n_done}/{len(todo)}, elapsed {el:.0f} s, ETA {eta:.0f} s)")
            if not ok:
                print(f"[sweep] row {i:03d}: {r['stderr_tail']}", file=sys.stderr, flush=True)
    finally:
        if box:
            _close_client(*box)
