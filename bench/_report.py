"""Shared reporting of the benches: JSON lines (printed and appended to a file), one JSON
document per run, and a Markdown table on stderr."""

from __future__ import annotations

import json
import sys
from pathlib import Path


def emit(row: dict, out: Path | None) -> None:
    """Prints ``row`` as one JSON line and appends it to ``out`` (if given), flushed."""
    line = json.dumps(row, default=float)
    print(line, flush=True)
    if out is not None:
        with open(out, "a") as f:
            f.write(line + "\n")


def write_json(path: str | Path, obj) -> Path:
    """Writes ``obj`` as one indented JSON document to ``path`` (its folder made if needed);
    returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(obj, indent=1))
    return out


def markdown_table(rows: list, columns: list) -> None:
    """Writes ``rows`` to stderr as a Markdown table; ``columns`` is a list of (header,
    function of a row returning the cell text)."""
    print("\n| " + " | ".join(h for h, _ in columns) + " |", file=sys.stderr)
    print("|" + "---|" * len(columns), file=sys.stderr)
    for r in rows:
        print("| " + " | ".join(f(r) for _, f in columns) + " |", file=sys.stderr)


def pct(x: float) -> str:
    """A relative error as a signed percentage."""
    return f"{100 * x:+.1f} %"


def fmt(x, scale: float, digits: int) -> str:
    """``x`` times ``scale`` with ``digits`` decimals for a docs table, "-" for None or a
    value that is not finite."""
    import math

    return "-" if x is None or not math.isfinite(x) else f"{x * scale:.{digits}f}"


def run_jobs(run_one, jobs: list, workers: int, hide: tuple = ()) -> list:
    """``run_one(*job)`` for each job, ``workers`` at a time (threads: each job runs its own
    process), in the jobs' order; each result printed as one JSON line (without its keys in
    ``hide``) as it is taken."""
    from concurrent.futures import ThreadPoolExecutor

    out = []
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for r in pool.map(lambda j: run_one(*j), jobs):
            print(json.dumps({k: v for k, v in r.items() if k not in hide}), flush=True)
            out.append(r)
    return out


def write_study(script: str, args, runs: list, paired: list, out: str | Path) -> dict:
    """The data file of a study over seeds (its docs table is rendered from it): the command
    (``script`` and this process's arguments), the machine, the commit, the parameters
    (``args`` without ``out`` and ``table``), the runs and their paired differences, written
    to ``out`` (its folder made if needed), and each paired difference printed as a JSON
    line. Returns the data."""
    import platform
    import subprocess

    root = Path(__file__).resolve().parents[1]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root,
                            capture_output=True, text=True).stdout.strip()
    data = {"command": f"bench/{script} " + " ".join(sys.argv[1:]),
            "machine": platform.processor() or platform.machine(), "commit": commit,
            "params": {k: v for k, v in vars(args).items() if k not in ("out", "table")},
            "runs": runs, "paired": paired}
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(json.dumps(data, indent=1, default=float) + "\n")
    for d in paired:
        print(json.dumps(d))
    return data
