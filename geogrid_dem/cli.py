"""The ``geogrid-dem`` command: run a case, a run file, or a sweep of runs on Dask.

    geogrid-dem cases                                  # the cases and what they are
    geogrid-dem run triaxial --smoke --out results/t   # a case, with its own flags after it
    geogrid-dem run my_run.toml                        # a run file (TOML)
    geogrid-dem sweep my_sweep.toml --workers 2        # a parameter table, on Dask
    geogrid-dem calibrate cases/calibrate_triaxial.toml  # fit E, nu, phi of the triaxial
    geogrid-dem continue results/p detailed_RE_s1 --steps 20000  # cycle an element on

Every case parses its flags with one parser (geogrid_dem.options): the shared ones have the
same names, units and meaning everywhere (``--smoke``, ``--out DIR``, ``--overwrite``,
``--seed N``, ``--threads N`` with 0 = automatic threads (``cpp_dem.apply_threads``), and
``--preset fast|balanced|accurate`` where the case has presets). Everything after the case
name goes to that parser (``geogrid-dem run triaxial --help`` lists the case's flags).

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
last ``--out`` wins, as for the case itself, and the run file goes where the results go). It
keeps ``out`` as given (a relative one stays relative to where the command runs); without
``--out`` every run gets a new folder ``results/<case>/run_NNN``, which the run file leaves
out, so that it reruns into a new folder of its own. A folder that holds
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
a killed worker is run again by Dask. A sweep writes a row's ``run.toml`` before the row runs
and removes only what its rows' runs recorded (a row run again replaces its earlier attempt's
recorded files); before anything is written it refuses, naming the row, a row folder that is
a symbolic link or holds one, another sweep's row (another case or other parameters), or
files no run of the row recorded (yours). ``OUT/results.csv`` (and ``results.parquet`` where
pyarrow is installed) gathers one line per row: its parameters, status, wall time and the
scalar numbers of its ``summary.json``; the CSV is rewritten after every finished row.
Every row's parameters are checked against the case's flags before Dask starts; a sweep of
more than ``--max-rows`` rows (10 000 by default) is refused with its size.
"""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path

from geogrid_dem import rundir
from geogrid_dem.cases import CASES
from geogrid_dem.options import HelpFormatter, add_allow_large
from geogrid_dem.provenance import version
from geogrid_dem.runs import (MAX_ROWS, RunFileError, UsageError, _close_client, _row_finished,
                              _row_params, _run_on_dask, _started_client, _summary_of,
                              argv_to_params, case_command, check_argv, check_params,
                              check_row_folder, check_same_parameter, param_action,
                              load_toml, out_of, params_to_argv, run_case, sweep_rows,
                              write_results, write_run_file)


def _echo(msg: str) -> None:
    print(msg, flush=True)


def columns(rows: list[tuple[str, ...]], gap: int = 2) -> list[str]:
    """The rows as lines of aligned columns: each column but the last padded to its widest
    cell plus ``gap`` spaces, so that every cell of a column starts in one place."""
    widths = [max(len(r[k]) for r in rows) + gap for k in range(len(rows[0]) - 1)]
    return ["".join(c.ljust(w) for c, w in zip(r, widths)) + r[-1] for r in rows]


def cases_table() -> list[str]:
    """The lines of `geogrid-dem cases`: a table of the cases (name, the study it rebuilds by
    its short name, what it runs), then the studies' short names with their codes (the
    aliases in case names and equation citations) and titles."""
    from geogrid_dem.cases import SOURCE_STUDIES

    lines = columns([("case", "study", "what it runs"),
                     *((name, case.study_name or "-", case.summary)
                       for name, case in CASES.items())])
    lines += ["", "The studies (docs/studies.md; the code is their alias in case names and "
              "equation citations):"]
    lines += columns([(f"  {s.name} ({s.code})", f'"{s.title}"') for s in SOURCE_STUDIES])
    return lines


def list_cases() -> None:
    """Lists the cases, each with the study it comes from, then the studies."""
    print("\n".join(cases_table()))


def run_cmd(target: str, extra: list[str]) -> None:
    """Runs a case (TARGET = its name, then its own flags) or a run file (TARGET.toml)."""
    source = None
    if target.endswith(".toml"):
        path = Path(target)
        source = str(path)
        data = load_toml(path, "run")
        case = data["case"]
        if "sweep" in data:
            raise RunFileError(f"{source}: field 'sweep': a run file runs the case once; a "
                               f"[sweep] table is run by `geogrid-dem sweep {source}` (remove "
                               "the table to run the [params] once)")
        params = dict(data.get("params", {}))
        if "out" in data:
            clash = next((k for k in params if param_action(case, k) is not None
                          and param_action(case, k).dest == "out"), None)
            if clash is not None:
                raise RunFileError(f"{source}: fields 'out' and 'params.{clash}' both name the "
                                   "results folder; give it once")
            params["out"] = data["out"]
        check_params(case, params, source=source)
        argv = params_to_argv(params, source=source)
        argv += extra
        check_argv(case, argv, source=source)
    else:
        case = target
        case_command(case, field="case")
        argv = list(extra)
    helping = "--help" in argv or "-h" in argv
    valid = True
    if source is None and not helping:
        try:
            check_argv(case, argv, source=case)
        except RunFileError:
            valid = False  # the case itself says why (argparse, exit status 2)
    numbered = out_of(argv) is None and not helping and valid
    if numbered:
        # the case's default, made here so that run.toml goes into the same new folder
        argv += ["--out", str(rundir.numbered_run_dir(rundir.default_base(CASES[case].folder)))]
    status = run_case(case, argv, source=source)
    dest = out_of(argv)
    if dest is not None and not helping:
        state = (rundir.run_status(dest) or {}).get("status")
        # (a completed run that exits non-zero says how its coupling ended: its results and
        # run file are kept as a converged run's)
        if (status == 0 or state == "complete"
                or (status == rundir.EXIT_INTERRUPTED and state == "interrupted")):
            params = argv_to_params(argv, case)
            params.pop("overwrite", None)  # a run file never replaces a run by itself
            if numbered:  # (its copy reruns into a new numbered folder of its own)
                params.pop("out", None)
            write_run_file(dest, case, params)
        if status == rundir.EXIT_INTERRUPTED:
            again = f" --out {dest}" if numbered else ""
            print(f"[geogrid-dem] {case} interrupted: results so far in {dest}; run it "
                  f"again with geogrid-dem run {dest / 'run.toml'}{again} --overwrite",
                  file=sys.stderr, flush=True)
    if status != 0:
        sys.exit(status)


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
        raise UsageError(f"--workers={workers}: must be >= 1")
    if threads < 0:
        raise UsageError(f"--threads={threads}: must be >= 0 (0 = automatic)")
    _check_local_bounds(scheduler, workers, threads, low_workers=1)
    if max_rows < 1:
        raise UsageError(f"--max-rows={max_rows}: must be >= 1")
    if not isinstance(data["out"], str) or not data["out"]:
        raise RunFileError(f"{file}: field 'out'={data['out']!r}: must be a folder's path")
    out = Path(data["out"])
    why = rundir._writable_or_error(out) or _holds_a_run(out)
    if why:
        raise RunFileError(f"{file}: field 'out'={data['out']!r}: {why}")
    fixed = dict(data.get("params", {}))
    for k in fixed:
        if param_action(case, k) is not None and param_action(case, k).dest == "out":
            raise RunFileError(f"{file}: field 'params.{k}': set the sweep's folder with the "
                               "top-level field 'out' (each row writes in OUT/row_NNN)")
    if isinstance(data.get("sweep"), dict):
        check_same_parameter(case, [("params", fixed),
                                    ("sweep", {k: v for k, v in data["sweep"].items()
                                               if k != "mode"})], source=str(file))
    rows = sweep_rows(data, str(file), max_rows)
    script = case_command(case)
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
        print(f"[sweep] {len(rows)} rows: checking one row per distinct value of each "
                   f"field ({len(parse)} rows)")
    checked: list[tuple[int, Path, dict, list[str]]] = []
    for i, row in enumerate(rows):
        row_dir = out / f"row_{i:03d}"
        params = _row_params(fixed, row, row_dir, threads)
        src = f"{file}: row {i} ({', '.join(f'{k}={v!r}' for k, v in row.items())})"
        argv = params_to_argv(params, source=src)
        if i in parse:
            check_params(case, params, source=src)
            # (on a scheduler's workers a row's threads are bounded by the cores of the
            # machine that runs it, which its case checks there, not by this one's)
            check_argv(case, argv if not scheduler else params_to_argv(
                _threads_unbounded(case, params), source=src), source=src)
        checked.append((i, row_dir, params, argv))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RunFileError(f"{file}: field 'out'={data['out']!r}: cannot be created: "
                           f"{e.strerror}") from None
    # Every row folder is checked before anything is written or removed: a symbolic link
    # (a row, results.csv or .parquet) is refused, and so is a row folder the sweep did not
    # write (another sweep's row, files of yours); a row of this sweep that did not finish
    # is run again, its case replacing only the files it recorded.
    for name in ("results.csv", "results.parquet"):
        if (out / name).is_symlink():
            raise RunFileError(f"{file}: field 'out': {out / name} is a symbolic link; a sweep "
                               "follows no link in its results folder: remove it, or name "
                               "another 'out'")
    todo, results = [], [None] * len(rows)
    for i, row_dir, params, argv in checked:
        row = rows[i]
        src = f"{file}: row {i}"
        base = {"row": i, **{f"param.{k}": v for k, v in row.items()}}
        if row_dir.is_symlink():
            check_row_folder(row_dir, case, params, source=src)  # (refuses it, naming it)
        if _row_finished(row_dir, case, params):
            results[i] = {**base, "status": "done (earlier run)", **_summary_of(row_dir)}
        else:
            check_row_folder(row_dir, case, params, source=src)
            todo.append((i, row_dir, params, argv, base))
    print(f"[sweep] {case}: {len(rows)} rows, {len(rows) - len(todo)} finished before, "
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
        print(f"[sweep] interrupted: {len(done)} of {len(rows)} rows finished, their "
                   f"results in {path}; the same command again runs the rest (finished rows "
                   "are skipped)", file=sys.stderr, flush=True)
        sys.exit(rundir.EXIT_INTERRUPTED)
    print(f"[sweep] results: {path} ({len(done)} rows, {len(failed)} failed)")
    if failed:
        sys.exit(1)


def calibrate_cmd(file: Path, out: Path | None, workers: int, scheduler: str | None,
                  threads: int, allow_large: bool = False) -> None:
    """Fits E, nu and phi of the triaxial case to a reference curve (the thesis's §6.1,
    Table 6.1): a grid on Dask, then a local optimiser; writes OUT/grid.csv, best.json,
    misfit.png/.pdf."""
    from geogrid_dem import calibrate as cal

    try:
        cfg = cal.Config.load(file, allow_large=allow_large)
    except FileNotFoundError:
        raise RunFileError(f"calibration file {file}: not found") from None
    except (ValueError, tomllib.TOMLDecodeError) as e:
        raise RunFileError(str(e)) from None
    if out is not None:
        cfg.out = out
    if workers < 0 or threads < 0:
        raise UsageError("--workers and --threads must be >= 0")
    _check_local_bounds(scheduler, workers, threads, low_workers=0)
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
    why = rundir._writable_or_error(Path(cfg.out))
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
        cal.calibrate(cfg, client=box[0] if box else None, threads=threads, log=_echo)
    except RuntimeError as e:
        raise RunFileError(str(e)) from None
    except KeyboardInterrupt:
        print(f"[calibrate] interrupted: the points finished so far are in "
              f"{cfg.out / 'runs'} and are reused when the same command runs again",
              file=sys.stderr, flush=True)
        sys.exit(130)
    finally:
        if box:
            _close_client(*box)


def _check_local_bounds(scheduler: str | None, workers: int, threads: int, *,
                        low_workers: int) -> None:
    """Refuses (UsageError) ``--threads`` and, for a local cluster, ``--workers`` above
    ``rundir.local_bound()`` (4 x the cores of this machine; docs/cli.md). Rows run on a
    ``--scheduler``'s machines are checked there."""
    if scheduler:
        return
    why = (rundir.local_bound_error("--workers", workers, low_workers,
                                    "the local cluster's worker processes")
           or rundir.local_bound_error("--threads", threads, 0, "the threads of each run"))
    if why:
        raise UsageError(why)


def _holds_a_run(out: Path) -> str | None:
    """Why a sweep may not write into ``out``: it holds a case's run (its manifest, lock or
    run file: a sweep's results.csv and row folders would go in among that run's files)."""
    if not out.is_dir():
        return None
    manifest = rundir.run_status(out)
    if manifest is not None or (out / rundir.LOCK).exists() or (out / "run.toml").is_file():
        what = ""
        if isinstance(manifest, dict):
            what = (f" of {manifest.get('case', 'a case')!s} ({manifest.get('status', '?')}, "
                    f"started {manifest.get('started', '?')})")
        return (f"holds a run{what} (its {rundir.MANIFEST if manifest is not None else 'run.toml'}"
                "); a sweep writes results.csv and row_NNN/ into a folder of its own: name "
                "another 'out'")
    return None


def _threads_unbounded(case: str, params: dict) -> dict:
    """``params`` with a ``threads`` above this machine's bound set to 0 (for the check of a
    row that runs on another machine)."""
    key = next((k for k in params if param_action(case, k) is not None
                and param_action(case, k).dest == "threads"), None)
    if key is not None and isinstance(params[key], int) and params[key] > rundir.local_bound():
        return {**params, key: 0}
    return params


def _dask_options(p: argparse.ArgumentParser, *, workers: str, threads: str) -> None:
    """--workers, --scheduler and --threads of a command that runs cases on Dask."""
    p.add_argument("--workers", type=int, default=2, help=workers)
    p.add_argument("--scheduler", default=None,
                   help="a running Dask scheduler: its address or its scheduler file")
    p.add_argument("--threads", type=int, default=1, help=threads)


def _parser() -> tuple[argparse.ArgumentParser, argparse.ArgumentParser]:
    """The command's parser and its ``run`` subparser (whose help ``geogrid-dem run --help``
    prints: everything after ``run`` goes to the case's own parser)."""
    ap = argparse.ArgumentParser(
        prog="geogrid-dem", formatter_class=HelpFormatter, allow_abbrev=False,
        description="Coupled DEM-FEM for geogrid-reinforced soil: run the cases of the source "
                    "studies, run files and sweeps, calibrate a case's parameters, and "
                    "continue a finished element.",
        epilog="`geogrid-dem run NAME --help` lists a case's own flags; docs/cli.md has the "
               "run and sweep file formats.")
    ap.add_argument("--version", action="version", version=f"geogrid-dem, version {version()}")
    sub = ap.add_subparsers(dest="command", metavar="COMMAND", required=True)
    sub.add_parser("cases", help="list the cases and the studies they come from",
                   formatter_class=HelpFormatter, allow_abbrev=False)
    run = sub.add_parser("run", help="run a case (NAME, then its flags) or a run file (FILE.toml)",
                         formatter_class=HelpFormatter, allow_abbrev=False, add_help=False,
                         description="Runs a case, with its own flags after its name, or a run "
                                     "file (TOML) whose flags can be overridden after it "
                                     "(the last --out wins). Cases: " + ", ".join(CASES) + ".")
    run.add_argument("target", metavar="NAME|FILE.toml", nargs="?")
    run.add_argument("case_args", nargs=argparse.REMAINDER, help="the case's flags")
    sw = sub.add_parser("sweep", help="run a sweep file's rows on Dask; gather results.csv",
                        formatter_class=HelpFormatter, allow_abbrev=False,
                        description="Runs a sweep file's rows on Dask, skipping finished rows; "
                                    "gathers OUT/results.csv. Every row is checked against the "
                                    "case's flags before Dask starts.")
    sw.add_argument("file", type=Path, help="the sweep file (TOML)")
    _dask_options(sw, workers="processes of the local Dask cluster",
                  threads="OpenMP threads per row; 0: automatic (cpp_dem.apply_threads)")
    sw.add_argument("--max-rows", type=int, default=MAX_ROWS,
                    help="the largest table run; a larger one is refused with its size")
    cal = sub.add_parser("calibrate", help="fit the triaxial case's E, nu, phi to a curve",
                         formatter_class=HelpFormatter, allow_abbrev=False,
                         description="Fits E, nu and phi of the triaxial case to a reference "
                                     "curve: a grid on Dask, then a local optimiser; writes "
                                     "OUT/grid.csv, best.json, misfit.png/.pdf.")
    cal.add_argument("file", type=Path, help="the calibration file (TOML)")
    cal.add_argument("--out", type=Path, default=None,
                     help="results folder (default: the file's field 'out')")
    _dask_options(cal, workers="processes of the local Dask cluster (0: run in this process)",
                  threads="OpenMP threads per triaxial run; the results do not depend on it "
                          "or on the number of workers")
    add_allow_large(cal)
    from geogrid_dem.continue_run import MAX_STEPS

    co = sub.add_parser("continue", help="cycle a finished prs-element-002 element on: N steps "
                                         "at its final targets, one JSON line",
                        formatter_class=HelpFormatter, allow_abbrev=False,
                        description="Restores an element of a prs-element-002 run from its "
                                    "final state (RUN_DIR/LABEL_final.h5) with its walls "
                                    "servoing at their final set points and its grid's end "
                                    "conditions, runs N steps and prints one JSON line: "
                                    "label, steps, added_strain [x, y, z] (compression "
                                    "positive), stress_pa [x, y, z], inertial_number. Writes "
                                    "nothing into RUN_DIR (docs/prs_element_002.md, "
                                    "\"Continuing an element\").")
    co.add_argument("run_dir", metavar="RUN_DIR", help="the --out of a prs-element-002 run")
    co.add_argument("label", metavar="LABEL",
                    help="the element, e.g. detailed_RE_s1 (a LABEL_final.h5 in RUN_DIR)")
    co.add_argument("--steps", required=True, metavar="N",
                    help=f"steps to run, 1 to {MAX_STEPS}")
    co.add_argument("--out", type=Path, default=None,
                    help="a folder for the continued state (LABEL_final.h5, which can be "
                         "continued in turn) and LABEL_continue.json; default: write nothing")
    co.add_argument("--overwrite", action="store_true",
                    help="replace an earlier continuation of LABEL in --out")
    wa = sub.add_parser("watch", help="a running case's main curve, redrawn as it grows",
                        formatter_class=HelpFormatter, allow_abbrev=False,
                        description="Redraws the main curve of a case run (the series it "
                                    "wrote last: pull-out force, triaxial deviator, footing "
                                    "pressure, an element's vertical stress, ...) every "
                                    "--every seconds into RUN_DIR_watch.png beside the folder "
                                    "and prints its last point, until the run ends "
                                    "(docs/output.md, \"Watching a run\"). Writes nothing "
                                    "into RUN_DIR.")
    wa.add_argument("run_dir", metavar="RUN_DIR", type=Path, help="the --out of a case run")
    wa.add_argument("--every", type=float, default=2.0, metavar="S",
                    help="seconds between drawings (default 2)")
    wa.add_argument("--once", action="store_true", help="draw once and stop")
    wa.add_argument("--csv", default=None, metavar="GLOB",
                    help="the series file(s) to watch, e.g. 'detailed_PRS_s1.csv'")
    wa.add_argument("--x", default=None, help="the column along x (with --y)")
    wa.add_argument("--y", default=None, help="the column along y")
    wa.add_argument("--png", type=Path, default=None,
                    help="where to draw (default RUN_DIR_watch.png beside RUN_DIR)")
    return ap, run


def main(argv: list[str] | None = None) -> None:
    """The ``geogrid-dem`` command. Warnings are shown one line each, a repeated one once and
    then counted (geogrid_dem.warnings_display)."""
    from geogrid_dem.warnings_display import shown_once

    with shown_once():
        _main(argv)


def _main(argv: list[str] | None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    ap, run_parser = _parser()
    try:
        if argv[:1] == ["run"]:
            # everything after the target belongs to the case's own parser, --help included
            rest = argv[1:]
            if not rest or rest[0] in ("-h", "--help"):
                run_parser.print_help()
                return
            run_cmd(rest[0], rest[1:])
            return
        a = ap.parse_args(argv)
        if a.command == "cases":
            list_cases()
        elif a.command == "sweep":
            sweep_cmd(a.file, a.workers, a.scheduler, a.threads, a.max_rows)
        elif a.command == "calibrate":
            calibrate_cmd(a.file, a.out, a.workers, a.scheduler, a.threads, a.allow_large)
        elif a.command == "continue":
            from geogrid_dem.continue_run import main_continue

            main_continue(a.run_dir, a.label, a.steps, a.out, a.overwrite)
        elif a.command == "watch":
            from geogrid_dem.watch import WatchError, main_watch

            try:
                main_watch(a.run_dir, csv_glob=a.csv, x=a.x, y=a.y, every_s=a.every,
                           once=a.once, png=a.png)
            except WatchError as e:
                raise UsageError(str(e)) from None
    except UsageError as e:
        print(f"Error: {e}", file=sys.stderr)
        sys.exit(2)
    except RunFileError as e:
        print(f"Error: {e}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
