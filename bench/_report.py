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
