"""The ``geogrid-dem`` command: run a case, a run file, or a sweep of runs on Dask.

    geogrid-dem cases                                  # the cases and what they are
    geogrid-dem run triaxial --smoke --out results/t   # a case, with its own flags after it
    geogrid-dem run my_run.toml                        # a run file (TOML)
    geogrid-dem sweep my_sweep.toml --workers 2        # a parameter table, on Dask
    geogrid-dem calibrate cases/calibrate_triaxial.toml  # fit E, nu, phi (001 §6.1)

Shared options (same names and units for every case): ``--out DIR``, ``--seed N``,
``--threads N`` (0 = all cores), ``--preset fast|balanced|accurate`` (where the case has
presets), ``--smoke``. Everything after the case name that the command does not know is
passed to the case as it is (``geogrid-dem run triaxial --help`` shows the case's flags).

A **run file** names the case and its parameters; the keys are the case's flags without the
leading dashes (``cell-pressure`` or ``cell_pressure``), ``true`` switches a flag on, a list
becomes a comma list::

    case = "triaxial"
    [params]
    smoke = true
    cell-pressure = 100e3     # Pa
    out = "results/tri_100k"

Every results folder gets ``run.toml``: the case, the parameters, the package version, the
git commit and the date, so ``geogrid-dem run DIR/run.toml --out NEW`` runs it again (the
last ``--out`` wins, as for the case itself, and the run file goes where the results go).
Without ``--out`` every run gets a new folder ``results/<case>/run_NNN``; a folder that holds
an earlier run is refused unless ``--overwrite`` is given. A run file's parameters are checked
against the case's own flags before the case starts (a misspelt flag, a switch given a value).
Ctrl-C stops the case: its files are closed, its folder is marked interrupted and the command
exits with status 130.

A **sweep file** adds a table of values, as a product of the lists or row by row::

    case = "triaxial"
    out = "results/sweep"
    [params]                  # the same for every row
    smoke = true
    [sweep]
    mode = "product"          # or "list" (equal-length lists, one row per index)
    cell-pressure = [50e3, 100e3]
    seed = [1, 2]

Rows run as separate processes on ``dask.distributed`` workers (a ``LocalCluster`` of
``--workers`` processes by default, or ``--scheduler ADDRESS|FILE`` for a cluster), each in
``OUT/row_NNN/``. A row whose folder holds a ``summary.json`` and a ``run.toml`` with the
same parameters is finished and skipped, so a sweep resumes where it stopped; a row lost with
a killed worker is run again by Dask. ``OUT/results.csv`` (and ``results.parquet`` where
pyarrow is installed) gathers one line per row: its parameters, status, wall time and the
scalar numbers of its ``summary.json``; the CSV is rewritten after every finished row.
Every row's parameters are checked against the case's flags before Dask starts; a sweep of
more than ``--max-rows`` rows (10 000 by default) is refused with its size.
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
import shutil
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

import click

from geogrid_dem.provenance import git_commit, version

#: The cases: command name -> (module in geogrid_dem.cases, one line).
CASES = {
    "pullout-000": ("pullout_000", "geogrid pull-out of 000 (Yade, 3000-9000 spheres)"),
    "pullout-001": ("pullout_001", "pull-out of 001 (square and triangular grids, Table 5.2)"),
    "triaxial": ("triaxial", "triaxial test of 001 ch. 6, with or without geogrid"),
    "prs-element": ("prs_element", "002's reinforced vs prestressed element from FEM stresses"),
    "prs-element-002": ("prs_element_002", "002's element rebuilt: clumps, woven bonded grid, "
                        "RE vs PRS"),
    "deposition": ("deposition", "spheres deposited into a box under gravity"),
}
#: Cases whose --threads 0 means one thread rather than all (translated by the command).
_THREADS_ZERO_IS_ONE = {"prs-element", "prs-element-002"}


class RunFileError(click.ClickException):
    """A run or sweep file names a bad field; the message says which, its value and why."""


def case_command(name: str, *, field: str = "case") -> list[str]:
    """The interpreter command that runs case `name` (its module in geogrid_dem.cases)."""
    if name not in CASES:
        raise RunFileError(f"{field}={name!r}: no such case; allowed: {', '.join(CASES)}")
    return [sys.executable, "-m", f"geogrid_dem.cases.{CASES[name][0]}"]


# ---- parameters -> the case's flags -----------------------------------------------------------

class _Parser(Exception):
    """Carries the parser out of a case's parse_args (case_parser)."""


@functools.lru_cache(maxsize=None)
def case_parser(case: str) -> argparse.ArgumentParser:
    """The argparse parser of case ``case`` (its module's parse_args, stopped where it parses)."""
    mod = importlib.import_module(f"geogrid_dem.cases.{CASES[case][0]}")
    orig = argparse.ArgumentParser.parse_args

    def grab(self, *_a, **_k):
        raise _Parser(self)

    argparse.ArgumentParser.parse_args = grab
    try:
        mod.parse_args([])
    except _Parser as e:
        return e.args[0]
    finally:
        argparse.ArgumentParser.parse_args = orig
    raise RuntimeError(f"case {case!r}: its parse_args did not build a parser")


def _flags(case: str) -> dict[str, argparse.Action]:
    return {o: a for a in case_parser(case)._actions for o in a.option_strings
            if o.startswith("--")}


def check_params(case: str, params: dict[str, Any], *, source: str) -> None:
    """Refuses a parameter that is not a flag of the case (with a did-you-mean), a switch
    given a value other than true/false, and a flag that takes a value given true/false."""
    flags = _flags(case)
    for key, value in params.items():
        if not isinstance(key, str) or not key or key.startswith("-"):
            raise RunFileError(f"{source}: field {key!r}: write the flag's name without dashes")
        flag = "--" + key.replace("_", "-")
        act = flags.get(flag)
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


def check_argv(case: str, argv: list[str], *, source: str) -> None:
    """Parses ``argv`` with the case's own parse_args in this process (nothing is run), so a
    value the case refuses is reported against ``source`` before any work starts."""
    if "--help" in argv or "-h" in argv:
        return
    mod = importlib.import_module(f"geogrid_dem.cases.{CASES[case][0]}")
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
    """The case's command-line flags from a table of parameters (keys without dashes)."""
    argv: list[str] = []
    for key, value in params.items():
        if not isinstance(key, str) or not key or key.startswith("-"):
            raise RunFileError(f"{source}: field {key!r}: write the flag's name without dashes")
        flag = "--" + key.replace("_", "-")
        if isinstance(value, bool):
            if value:
                argv.append(flag)
        elif isinstance(value, (int, float, str)):
            argv += [flag, str(value)]
        elif isinstance(value, list) and all(isinstance(v, (int, float, str)) and
                                             not isinstance(v, bool) for v in value):
            argv += [flag, ",".join(str(v) for v in value)]
        else:
            raise RunFileError(f"{source}: field {key!r}={value!r}: must be a number, a string, "
                               "true/false or a list of numbers or strings")
    return argv


def shared_argv(case: str, out: str | None, seed: int | None, threads: int | None,
                preset: str | None, smoke: bool, overwrite: bool = False) -> list[str]:
    argv: list[str] = []
    if smoke:
        argv.append("--smoke")
    if overwrite:
        argv.append("--overwrite")
    if out is not None:
        argv += ["--out", str(out)]
    if seed is not None:
        argv += ["--seed", str(seed)]
    if threads is not None:
        if threads < 0:
            raise click.BadParameter(f"--threads={threads}: must be >= 0 (0 = all cores)")
        if threads == 0 and case in _THREADS_ZERO_IS_ONE:
            threads = os.cpu_count() or 1
        argv += ["--threads", str(threads)]
    if preset:
        argv += ["--preset", preset]
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
    """OUT/run.toml: the case, its parameters and where they came from (rerunnable)."""
    lines = ["# Written by geogrid-dem; `geogrid-dem run` this file to run it again.",
             f"case = {json.dumps(case)}", "", "[params]"]
    for key, value in params.items():
        lines.append(f"{key} = {_toml_value(value)}")
    lines += ["", "[provenance]", f"version = {json.dumps(version())}",
              f"commit = {json.dumps(git_commit())}",
              f"date = {json.dumps(_dt.datetime.now(_dt.timezone.utc).isoformat())}",
              f"python = {json.dumps(sys.version.split()[0])}", ""]
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / ".run.toml.tmp"
    tmp.write_text("\n".join(lines))
    tmp.replace(out / "run.toml")


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(str(v))


def argv_to_params(argv: list[str]) -> dict[str, Any]:
    """The flags given on the command line as run-file parameters (for OUT/run.toml)."""
    params: dict[str, Any] = {}
    k = 0
    while k < len(argv):
        a = argv[k]
        if not a.startswith("--"):
            k += 1
            continue
        key, _, inline = a[2:].partition("=")
        if inline:
            params[key] = _number_or_string(inline)
        elif k + 1 < len(argv) and not argv[k + 1].startswith("--"):
            params[key] = _number_or_string(argv[k + 1])
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
    # terminal), and a SIGINT or SIGTERM sent to this command is passed on, not left behind
    proc = subprocess.Popen([*case_command(case), *argv], stderr=subprocess.PIPE, text=True,
                            bufsize=1, process_group=0)

    def forward(sig, _frame):  # to the case's whole group (its worker processes too), as a
        try:                     # terminal's Ctrl-C would
            os.killpg(proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            try:
                proc.send_signal(sig)
            except ProcessLookupError:
                pass

    import threading

    main_thread = threading.current_thread() is threading.main_thread()
    old = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)} \
        if main_thread else {}
    tail: list[str] = []
    try:
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


# ---- the command ----------------------------------------------------------------------------

@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version(), prog_name="geogrid-dem")
def main() -> None:
    """Coupled DEM-FEM for geogrid-reinforced soil: cases, run files and sweeps."""


@main.command("cases")
def list_cases() -> None:
    """Lists the cases."""
    for name, (_, what) in CASES.items():
        click.echo(f"{name:12s} {what}")


_SHARED = [
    click.option("--out", type=click.Path(path_type=Path), default=None,
                 help="results folder (default: a new folder results/<case>/run_NNN per run); "
                      "one holding an earlier run needs --overwrite"),
    click.option("--overwrite", is_flag=True,
                 help="replace the earlier run in --out (only the files it recorded)"),
    click.option("--seed", type=int, default=None, help="random seed"),
    click.option("--threads", type=int, default=None, help="OpenMP threads, 0 = all cores"),
    click.option("--preset", type=click.Choice(["fast", "balanced", "accurate"]), default=None,
                 help="speed-accuracy preset (cases that have presets)"),
    click.option("--smoke", is_flag=True, help="test-sized run"),
]


def _shared(f):
    for opt in reversed(_SHARED):
        f = opt(f)
    return f


@main.command("run", context_settings={"ignore_unknown_options": True,
                                       "allow_extra_args": True, "help_option_names": []})
@click.argument("target")
@_shared
@click.pass_context
def run_cmd(ctx, target: str, out, overwrite, seed, threads, preset, smoke) -> None:
    """Runs a case (TARGET = its name, then its own flags) or a run file (TARGET.toml)."""
    from geogrid_dem import rundir

    extra = list(ctx.args)
    source = None
    if target.endswith(".toml"):
        path = Path(target)
        source = str(path)
        data = load_toml(path, "run")
        case = data["case"]
        params = dict(data.get("params", {}))
        if "out" in data and "out" not in params:
            params["out"] = data["out"]
        check_params(case, params, source=source)
        argv = params_to_argv(params, source=source)
        argv += shared_argv(case, out, seed, threads, preset, smoke, overwrite) + extra
        check_argv(case, argv, source=source)
    else:
        if target in ("-h", "--help"):
            click.echo(ctx.get_help())
            return
        case = target
        case_command(case, field="case")
        argv = shared_argv(case, out, seed, threads, preset, smoke, overwrite) + extra
    helping = "--help" in argv or "-h" in argv
    valid = True
    if source is None and not helping:
        try:
            check_argv(case, argv, source=case)
        except RunFileError:
            valid = False  # the case itself says why (argparse, exit status 2)
    if out_of(argv) is None and not helping and valid:
        # the case's default, made here so that run.toml goes into the same new folder
        argv += ["--out", str(rundir.numbered_run_dir(rundir.default_base(CASES[case][0])))]
    status = run_case(case, argv, source=source)
    dest = out_of(argv)
    if dest is not None and not helping:
        state = (rundir.run_status(dest) or {}).get("status")
        if status == 0 or (status == rundir.EXIT_INTERRUPTED and state == "interrupted"):
            params = argv_to_params(argv)
            params.pop("overwrite", None)  # a run file never replaces a run by itself
            write_run_file(dest, case, params)
        if status == rundir.EXIT_INTERRUPTED:
            click.echo(f"[geogrid-dem] {case} interrupted: results so far in {dest}; run it "
                       f"again with geogrid-dem run {dest / 'run.toml'} --overwrite", err=True)
    if status != 0:
        sys.exit(status)


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
    return [{k: values[k][i] for k in keys} for i in range(n)]


def _row_params(fixed: dict[str, Any], row: dict[str, Any], row_dir: Path,
                threads: int) -> dict[str, Any]:
    params = {**fixed, **row, "out": str(row_dir)}
    params.setdefault("threads", threads)
    return params


def _row_finished(row_dir: Path, case: str, params: dict[str, Any]) -> bool:
    run_file = row_dir / "run.toml"
    if not (row_dir / "summary.json").exists() or not run_file.exists():
        return False
    try:
        with open(run_file, "rb") as f:
            old = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError):
        return False
    return old.get("case") == case and old.get("params") == json.loads(json.dumps(params))


#: Run before the case, in a fresh interpreter (no threads): asks Linux to SIGKILL this
#: process when the worker thread that started it dies (PR_SET_PDEATHSIG, kept across exec),
#: then becomes the case. A killed Dask worker so leaves no orphan writing into the row's
#: folder while Dask runs the row again elsewhere. (A preexec_fn would run in the forked
#: child of a threaded worker, which is not safe.)
_DIE_WITH_PARENT = ("import ctypes, os, signal, sys\n"
                    "try:\n"
                    "    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))\n"
                    "except Exception:\n"
                    "    pass\n"
                    "os.execv(sys.argv[1], sys.argv[1:])\n")


def _run_row(command: list[str], argv: list[str], env: dict[str, str]) -> dict[str, Any]:
    """One row, on a Dask worker: the case in its own interpreter. A row run again after a
    killed worker starts from an empty folder (the lost attempt's files are removed)."""
    dest = out_of(argv)
    if dest is not None and dest.exists():
        shutil.rmtree(dest, ignore_errors=True)
    t0 = time.perf_counter()
    wrap = [sys.executable, "-c", _DIE_WITH_PARENT] if sys.platform.startswith("linux") else []
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


@main.command("sweep")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--workers", type=int, default=2, show_default=True,
              help="processes of the local Dask cluster")
@click.option("--scheduler", default=None,
              help="a running Dask scheduler: its address or its scheduler file")
@click.option("--threads", type=int, default=1, show_default=True,
              help="OpenMP threads per row (0 = all cores)")
@click.option("--max-rows", type=int, default=MAX_ROWS, show_default=True,
              help="the largest table run; a larger one is refused with its size")
def sweep_cmd(file: Path, workers: int, scheduler: str | None, threads: int,
              max_rows: int) -> None:
    """Runs a sweep file's rows on Dask, skipping finished rows; gathers OUT/results.csv.
    Every row is checked against the case's flags before Dask starts."""
    from geogrid_dem import rundir

    data = load_toml(file, "sweep")
    case = data["case"]
    if "out" not in data:
        raise RunFileError(f"{file}: field 'out' is missing: the sweep's results folder")
    if workers < 1:
        raise click.BadParameter(f"--workers={workers}: must be >= 1")
    if threads < 0:
        raise click.BadParameter(f"--threads={threads}: must be >= 0 (0 = all cores)")
    if max_rows < 1:
        raise click.BadParameter(f"--max-rows={max_rows}: must be >= 1")
    if not isinstance(data["out"], str) or not data["out"]:
        raise RunFileError(f"{file}: field 'out'={data['out']!r}: must be a folder's path")
    out = Path(data["out"])
    why = rundir._writable_or_error(out)
    if why:
        raise RunFileError(f"{file}: field 'out'={data['out']!r}: {why}")
    fixed = dict(data.get("params", {}))
    for k in ("out",):
        if k in fixed:
            raise RunFileError(f"{file}: field 'params.{k}': set the sweep's folder with the "
                               "top-level field 'out' (each row writes in OUT/row_NNN)")
    rows = sweep_rows(data, str(file), max_rows)
    script = case_command(case)
    if threads == 0 and case in _THREADS_ZERO_IS_ONE:
        threads = os.cpu_count() or 1
    # every row is parsed by the case's parser (about 5 ms a row); above MAX_ROWS (a lifted
    # cap) one row per distinct value of each field, so the check stays within a minute
    if len(rows) <= MAX_ROWS:
        parse = set(range(len(rows)))
    else:
        first: dict[tuple, int] = {}
        for i, row in enumerate(rows):
            for k, v in row.items():
                first.setdefault((k, json.dumps(v)), i)
        parse = set(first.values())
        click.echo(f"[sweep] {len(rows)} rows: checking one row per distinct value of each "
                   f"field ({len(parse)} rows)")
    checked: list[tuple[int, Path, dict, list[str]]] = []
    for i, row in enumerate(rows):
        row_dir = out / f"row_{i:03d}"
        params = _row_params(fixed, row, row_dir, threads)
        src = f"{file}: row {i} ({', '.join(f'{k}={v!r}' for k, v in row.items())})"
        argv = params_to_argv(params, source=src)
        if i in parse:
            check_params(case, params, source=src)
            check_argv(case, argv, source=src)
        checked.append((i, row_dir, params, argv))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RunFileError(f"{file}: field 'out'={data['out']!r}: cannot be created: "
                           f"{e.strerror}") from None
    todo, results = [], [None] * len(rows)
    for i, row_dir, params, argv in checked:
        row = rows[i]
        base = {"row": i, **{f"param.{k}": v for k, v in row.items()}}
        if _row_finished(row_dir, case, params):
            results[i] = {**base, "status": "done (earlier run)", **_summary_of(row_dir)}
        else:
            todo.append((i, row_dir, params, argv, base))
    click.echo(f"[sweep] {case}: {len(rows)} rows, {len(rows) - len(todo)} finished before, "
               f"{len(todo)} to run on "
               + (f"the scheduler at {scheduler}" if scheduler else f"{workers} local workers"))
    interrupted = False
    if todo:
        try:
            _run_on_dask(todo, results, script, case, scheduler, workers, threads, out)
        except KeyboardInterrupt:
            interrupted = True
    done = [r for r in results if r is not None]
    path = write_results(out, done)
    try:
        import pyarrow  # noqa: F401
        import pyarrow.csv as pacsv
        import pyarrow.parquet as pq

        pq.write_table(pacsv.read_csv(path), out / "results.parquet")
    except ImportError:
        pass
    failed = [r for r in done if r["status"] == "failed"]
    if interrupted:
        click.echo(f"[sweep] interrupted: {len(done)} of {len(rows)} rows finished, their "
                   f"results in {path}; the same command again runs the rest (finished rows "
                   "are skipped)", err=True)
        sys.exit(rundir.EXIT_INTERRUPTED)
    click.echo(f"[sweep] results: {path} ({len(done)} rows, {len(failed)} failed)")
    if failed:
        sys.exit(1)


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
        raise click.BadParameter(str(e), param_hint="--scheduler") from None
    except Exception as e:  # noqa: BLE001  (unreachable, refused, a bad scheduler file ...)
        if not scheduler:
            raise click.ClickException(f"--workers={workers}: the local Dask cluster did not "
                                       f"start: {type(e).__name__}: {e}") from None
        raise click.BadParameter(
            f"{scheduler!r}: could not connect to a Dask scheduler there "
            f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else 'no detail'}); is "
            "it running, and is the address (tcp://host:port) or the scheduler file right?",
            param_hint="--scheduler") from None


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
            if row_dir.exists():
                # An unfinished row of an earlier run: its files are incomplete.
                shutil.rmtree(row_dir)
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
            ok = r["returncode"] == 0
            if ok:
                write_run_file(row_dir, case, params)
            results[i] = {**base, "status": "ok" if ok else "failed",
                          "wall_s": round(r["wall_s"], 3),
                          **(_summary_of(row_dir) if ok else {"error": r["stderr_tail"]})}
            write_results(out, [x for x in results if x is not None])
            el = time.perf_counter() - t0
            eta = el / n_done * (len(todo) - n_done)
            click.echo(f"[sweep] row {i:03d} {'ok' if ok else 'FAILED'} in {r['wall_s']:.1f} s "
                       f"({n_done}/{len(todo)}, elapsed {el:.0f} s, ETA {eta:.0f} s)")
            if not ok:
                click.echo(f"[sweep] row {i:03d}: {r['stderr_tail']}", err=True)
    finally:
        if box:
            _close_client(*box)


@main.command("calibrate")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="results folder (default: the file's field 'out')")
@click.option("--workers", type=int, default=2, show_default=True,
              help="processes of the local Dask cluster (0: run in this process)")
@click.option("--scheduler", default=None,
              help="a running Dask scheduler: its address or its scheduler file")
@click.option("--threads", type=int, default=1, show_default=True,
              help="OpenMP threads per triaxial run (fixed: the results do not depend on the "
                   "number of workers)")
def calibrate_cmd(file: Path, out: Path | None, workers: int, scheduler: str | None,
                  threads: int) -> None:
    """Fits E, nu and phi of the triaxial case to a reference curve (001 §6.1, Table 6.1):
    a grid on Dask, then Nelder-Mead; writes OUT/grid.csv, best.json, misfit.png/.pdf."""
    from geogrid_dem import calibrate as cal

    try:
        cfg = cal.Config.load(file)
    except FileNotFoundError:
        raise RunFileError(f"calibration file {file}: not found") from None
    except (ValueError, tomllib.TOMLDecodeError) as e:
        raise RunFileError(str(e)) from None
    if out is not None:
        cfg.out = out
    if workers < 0 or threads < 0:
        raise click.BadParameter("--workers and --threads must be >= 0")
    # every triaxial run's flags checked before any work: the fixed ones, the reference's
    # and the grid's corners
    src = f"calibration file {file}"
    check_params("triaxial", cfg.fixed, source=f"{src}: [params]")
    ref_extra = {k: v for k, v in cfg.reference.items() if k not in (*cal.KEYS, "csv")}
    check_params("triaxial", ref_extra, source=f"{src}: [reference]")
    corners = [[min(cfg.grid[k]) for k in cal.KEYS], [max(cfg.grid[k]) for k in cal.KEYS]]
    for where, extra, pts in (("[params]/[grid]", {}, corners),
                              ("[reference]", ref_extra,
                               [[cfg.reference[k] for k in cal.KEYS]]
                               if all(k in cfg.reference for k in cal.KEYS) else [])):
        for pt in pts:
            runner = cal.Runner(cfg.out, {**cfg.fixed, **extra}, threads=threads)
            check_argv("triaxial", params_to_argv(runner.params(pt), source=src),
                       source=f"{src}: {where} at young={pt[0]:g}, poisson={pt[1]:g}, "
                              f"phi={pt[2]:g}")
    why = __import__("geogrid_dem.rundir", fromlist=["x"])._writable_or_error(Path(cfg.out))
    if not why:
        try:
            Path(cfg.out).mkdir(parents=True, exist_ok=True)
        except OSError as e:
            why = f"cannot be created: {e.strerror}"
    if why:
        raise RunFileError(f"{src}: out={str(cfg.out)!r}: {why}")
    box: list = []
    try:
        if (scheduler or workers > 0) and _started_client(scheduler, workers, box):
            raise KeyboardInterrupt
        cal.calibrate(cfg, client=box[0] if box else None, threads=threads, log=click.echo)
    except RuntimeError as e:
        raise click.ClickException(str(e)) from None
    except KeyboardInterrupt:
        click.echo(f"[calibrate] interrupted: the points finished so far are in "
                   f"{cfg.out / 'runs'} and are reused when the same command runs again",
                   err=True)
        sys.exit(130)
    finally:
        if box:
            _close_client(*box)


if __name__ == "__main__":
    main()
