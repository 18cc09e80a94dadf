"""Checks shared by the cases' command lines: the output folder and the thread count."""

from __future__ import annotations

import argparse


def check_common_args(ap: argparse.ArgumentParser, a: argparse.Namespace) -> None:
    """Refuses (through ``ap.error``, naming the flag and the value) a ``--threads`` below 0 and
    an ``--out`` that exists and is not a folder."""
    threads = getattr(a, "threads", None)
    if threads is not None and threads < 0:
        ap.error(f"--threads={threads}: must be >= 0 (0 = the default)")
    out = getattr(a, "out", None)
    if out is not None and out.exists() and not out.is_dir():
        ap.error(f"--out={out}: exists and is not a directory; name a folder (created if "
                 "missing)")


MANIFEST = ".geogrid-dem-run.json"
#: Files a results folder may hold without being an earlier run's: the command's run file.
_FREE = {"run.toml", MANIFEST}


def begin_run(out, case: str, log=print) -> None:
    """Prepares the results folder ``out`` of a case run, so that no earlier run's file is
    left in it without a word: a folder written by a completed run (its manifest lists the
    files) has those files removed, with a message; a folder holding other files (an
    interrupted run, or files of the user's) is refused, naming it. Creates ``out``."""
    import json
    from pathlib import Path

    out = Path(out)
    if out.is_dir():
        files = [p for p in out.rglob("*") if p.is_file() and p.name not in _FREE]
        manifest = out / MANIFEST
        if manifest.exists():
            try:
                listed = json.loads(manifest.read_text()).get("files", [])
            except (OSError, ValueError):
                listed = []
            removed = 0
            for rel in listed:
                p = out / rel
                if p.is_file():
                    p.unlink()
                    removed += 1
            manifest.unlink()
            log(f"[{case}] --out {out}: removed {removed} files of the earlier run there")
            files = [p for p in out.rglob("*") if p.is_file() and p.name not in _FREE]
        if files:
            raise SystemExit(
                f"error: --out={out}: holds {len(files)} files that no completed run recorded "
                f"(e.g. {files[0].relative_to(out)}): an interrupted run or files of yours; "
                "name a new or empty folder, or empty this one")
    out.mkdir(parents=True, exist_ok=True)


def end_run(out) -> None:
    """Records the files of the completed run in ``out`` (the manifest begin_run reads)."""
    import json
    from pathlib import Path

    out = Path(out)
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*")
                   if p.is_file() and p.name not in _FREE)
    tmp = out / (MANIFEST + ".tmp")
    tmp.write_text(json.dumps({"files": files}, indent=0) + "\n")
    tmp.replace(out / MANIFEST)
