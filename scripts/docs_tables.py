#!/usr/bin/env python
"""Tables in the docs come from committed data (shared/DESIGN.md, "Tables come from data").

A results table in a docs page sits between two HTML comments, which name its data file
(relative to the page) and its kind::

    <!-- table: data/prs_element_002_full.json findings grid=detailed -->

    | grid | finding | ... |
    ...

    <!-- /table -->

Kinds (options are ``key=value`` words after the kind; a value lists items with commas):

- ``findings``: grid | finding | RE mean ± sd | PRS mean ± sd | PRS − RE ± se | n | t crit |
  002 | verdict, and a last column "pairs left out" when a row has any. Options: ``grid=G,...``
  (those grid forms' rows only), ``from=KEY`` (the data's list of rows, default ``findings``).
- ``measures``: the same without 002 and verdict (t crit only when a row has
  ``t_critical``). Options as ``findings`` (``from`` defaults to ``measures``).
- ``elements``: one row per element: grains, porosity and coordination number at the end,
  rest status, the loading's largest inertial number over a record and the last hold's,
  loading strain z, strain ratio to the FEM (x, y, z). Options:
  ``grid=G,...``, ``labels=L,...`` (those elements, in that order).
- ``provenance``: one line, "Command: `...` at commit abc1234 on DATE (machine)."
- ``rve_size``: ``bench/rve_size.py``'s statistics, a row per element size: grains, seeds,
  E, ν, φ and ψ mean ± sd with E's, ν's and φ's coefficients of variation, the wall time
  of one fit, one element's state (kB), and whether its means lie within the next size's
  budget.
- ``differences``: ``footing-multiscale``'s ``differences``, a row per difference: mean,
  se and n, each part of its error budget, the total and whether it is resolved (mm).
- ``band_meshes``: ``bench/shear_band.py --compare``'s ``mesh_study.json``, a row per mesh:
  elements, runs (seeds), cell size, nonlocal length, axial strain, localization index, the
  band's angle ± its error and width ± se, the width over the cell, and the angle's move
  from the coarser mesh ± its error and whether it exceeds it.

  These three are followed by their source line, as a study page's table is
  (docs/studies/): "Command: `...` · commit `abc1234` (DATE) · data: FILE."

Numbers have 4 significant digits; a missing key, None or NaN is ``-`` (older data files).

Commands::

    python scripts/docs_tables.py capture RUN/summary.json docs/data/NAME.json --command "..."
    python scripts/docs_tables.py render docs/PAGE.md [...]   # rewrite the marked blocks
    python scripts/docs_tables.py check docs/ [...]           # non-zero if a table differs

``capture`` copies a case's ``summary.json`` trimmed to its scalars (findings, measures,
params, the elements' scalars) and adds ``provenance``: the command, the commit
(``git rev-parse HEAD``, and whether tracked files differed), the date (the run folder's
manifest's end time when there is one, else now) and the machine. Standard library only.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import platform
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

START = re.compile(r"^<!--\s*table:\s*(?P<data>\S+)\s+(?P<kind>[A-Za-z_]+)(?P<opts>(?:\s+\S+)*?)"
                   r"\s*-->\s*$")
END = re.compile(r"^<!--\s*/table\s*-->\s*$")
FENCE = re.compile(r"^\s*(```|~~~)")

#: the options each kind accepts
OPTIONS = {"findings": {"grid", "from"}, "measures": {"grid", "from"},
           "elements": {"grid", "labels"}, "provenance": set(), "rve_size": set(),
           "differences": set(), "band_meshes": set()}

#: lists longer than this are dropped by capture (histories, not scalars)
MAX_LIST = 12


class TableError(Exception):
    """A marked block that cannot be rendered (bad marker, missing data, unknown kind)."""


# ---- formatting --------------------------------------------------------------------------------

def fmt(x) -> str:
    """A cell: 4 significant digits for a float, an int as is, ``-`` for None, NaN or inf."""
    if x is None:
        return "-"
    if isinstance(x, bool):
        return str(x).lower()
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return f"{x:.4g}" if math.isfinite(x) else "-"
    return cell(str(x))


def cell(text: str) -> str:
    """Text made safe for a table cell (a ``|`` would end the cell)."""
    return text.replace("\\|", "|").replace("|", "\\|").replace("\n", " ")


def pm(row: dict, mean: str, spread: str) -> str:
    return f"{fmt(row.get(mean))} ± {fmt(row.get(spread))}"


def sign(s) -> str:
    if not isinstance(s, (int, float)) or isinstance(s, bool) or not s or s != s:
        return "-"
    return "+" if s > 0 else "−"


def _vec(v, i=None) -> str:
    if not isinstance(v, (list, tuple)):
        return "-"
    if i is not None:
        return fmt(v[i]) if len(v) > i else "-"
    return ", ".join(fmt(x) for x in v) if v else "-"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return (["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
            + ["| " + " | ".join(r) + " |" for r in rows])


# ---- the kinds ---------------------------------------------------------------------------------

def _rows(data: dict, opts: dict, default_key: str) -> list[dict]:
    key = opts.get("from", default_key)
    if key not in data:
        raise TableError(f"the data file has no {key!r}")
    rows = data[key]
    if not isinstance(rows, list):
        raise TableError(f"the data file's {key!r} is not a list of rows")
    if "grid" in opts:
        grids = opts["grid"].split(",")
        rows = [r for r in rows if r.get("grid") in grids]
    return rows


def _left_out(r: dict) -> str:
    v = r.get("pairs_left_out")
    if v is None:
        return "-"
    if isinstance(v, (list, tuple)):
        return cell(", ".join(str(x) for x in v)) if v else "-"
    return fmt(v)


def findings_table(data: dict, opts: dict, *, verdict: bool = True) -> list[str]:
    rows = _rows(data, opts, "findings" if verdict else "measures")
    with_t = verdict or any("t_critical" in r for r in rows)
    with_left = any(r.get("pairs_left_out") for r in rows)
    head = ["grid", "finding" if verdict else "measure", "RE mean ± sd", "PRS mean ± sd",
            "PRS − RE ± se", "n"] + (["t crit"] if with_t else [])
    head += ["002", "verdict"] if verdict else []
    head += ["pairs left out"] if with_left else []
    out = []
    for r in rows:
        line = [fmt(r.get("grid")), fmt(r.get("name")), pm(r, "re_mean", "re_sd"),
                pm(r, "prs_mean", "prs_sd"),
                # (a finding about PRS alone holds PRS's own mean and se there)
                ("PRS alone: " if r.get("compare") == "PRS" else "")
                + pm(r, "diff_mean", "diff_se"),
                fmt(r.get("n"))]
        line += [fmt(r.get("t_critical"))] if with_t else []
        line += [sign(r.get("expected_sign")), fmt(r.get("verdict"))] if verdict else []
        line += [_left_out(r)] if with_left else []
        out.append(line)
    return _table(head, out)


def elements_table(data: dict, opts: dict) -> list[str]:
    el = data.get("elements")
    if not isinstance(el, dict):
        raise TableError("the data file has no 'elements'")
    labels = list(el)
    if "labels" in opts:
        labels = opts["labels"].split(",")
        missing = [x for x in labels if x not in el]
        if missing:
            raise TableError(f"no element {', '.join(missing)} in the data file")
    if "grid" in opts:
        grids = opts["grid"].split(",")
        labels = [x for x in labels if any(x.startswith(g + "_") for g in grids)]
    head = ["element", "grains", "porosity", "coordination", "rest", "I loading (max)",
            "I hold (end)", "loading strain z", "strain / FEM (x, y, z)"]
    rows = []
    for x in labels:
        e = el[x]
        rest = e.get("rest") if isinstance(e.get("rest"), dict) else {}
        rows.append([cell(x), fmt(e.get("num_grains")), fmt(e.get("porosity_final")),
                     fmt(e.get("coordination_final")), fmt(rest.get("status")),
                     fmt(rest.get("loading_inertial_number_max")),
                     fmt(rest.get("inertial_number_end")), _vec(e.get("loading_strain"), 2),
                     _vec(e.get("strain_ratio_to_fem"))])
    return _table(head, rows)


def _command_and_commit(p: dict) -> tuple[str, str]:
    """A provenance's command as inline code (double backticks around one that has a
    backtick) and its commit, a full hash shortened to 7 characters."""
    cmd = str(p["command"])
    cmd = f"`` {cmd} ``" if "`" in cmd else f"`{cmd}`"
    commit = str(p.get("commit") or "unknown")
    return cmd, commit[:7] if re.fullmatch(r"[0-9a-f]{40}", commit) else commit


def provenance_line(data: dict, opts: dict) -> list[str]:
    p = data.get("provenance")
    if not isinstance(p, dict) or not p.get("command"):
        raise TableError("the data file has no provenance (make it with `capture`)")
    cmd, commit = _command_and_commit(p)
    dirty = " (with uncommitted changes)" if p.get("dirty") else ""
    date = str(p.get("date") or "-")[:10]
    machine = f" ({p['machine']})" if p.get("machine") else ""
    return [f"Command: {cmd} at commit {commit}{dirty} on {date}{machine}."]


def _stat(st: dict, key: str, scale: float = 1.0) -> str:
    x = st.get(key) if isinstance(st.get(key), dict) else {}
    mean, sd = x.get("mean"), x.get("sd")
    f = (lambda v: None if not isinstance(v, (int, float)) else v * scale)  # noqa: E731
    return f"{fmt(f(mean))} ± {fmt(f(sd))}"


def _cv(st: dict, key: str) -> str:
    x = st.get(key) if isinstance(st.get(key), dict) else {}
    cv = x.get("cv")
    return f"{100 * cv:.1f} %" if isinstance(cv, (int, float)) and math.isfinite(cv) else "-"


def rve_size_table(data: dict, opts: dict) -> list[str]:
    """bench/rve_size.py's rve_size.json: a row per element size."""
    sizes = data.get("sizes")
    if not isinstance(sizes, dict) or not sizes:
        raise TableError("the data file has no 'sizes' (bench/rve_size.py's rve_size.json)")
    within = {str(c.get("grains")): c.get("within") for c in data.get("comparisons") or []}
    head = ["grains", "seeds", "E (MPa) mean ± sd", "E cv", "ν mean ± sd", "ν cv",
            "φ (°) mean ± sd", "φ cv", "ψ (°) mean ± sd", "fit (s)", "state (kB)",
            "within the next size's budget"]
    rows = []
    for n in sorted(sizes, key=int):
        st = sizes[n].get("params") or {}
        seeds = (st.get("young_pa") or {}).get("n")
        kb = sizes[n].get("state_bytes")
        rows.append([n, fmt(seeds), _stat(st, "young_pa", 1e-6), _cv(st, "young_pa"),
                     _stat(st, "poisson"), _cv(st, "poisson"), _stat(st, "friction_deg"),
                     _cv(st, "friction_deg"), _stat(st, "dilatancy_deg"),
                     fmt(sizes[n].get("fit_wall_s")),
                     fmt(kb / 1e3 if isinstance(kb, (int, float)) else None),
                     "-" if n not in within else ("yes" if within[n] else "no")])
    return _table(head, rows)


def differences_table(data: dict, opts: dict) -> list[str]:
    """footing-multiscale's summary.json ``differences``: each difference with its budget,
    in mm."""
    rows = data.get("differences")
    if not isinstance(rows, list):
        raise TableError("the data file has no 'differences' (footing-multiscale's summary)")
    parts = ("ceiling", "calibration", "rve", "mesh", "seeds")
    mm = (lambda v: None if not isinstance(v, (int, float)) else 1e3 * v)  # noqa: E731
    head = ["difference", "mean (mm)", "se (mm)", "n"] + [f"{p} (mm)" for p in parts] + [
        "total (mm)", "resolved"]
    out = []
    for r in rows:
        b = r.get("budget") if isinstance(r.get("budget"), dict) else {}
        out.append([fmt(r.get("name")), fmt(mm(r.get("mean"))), fmt(mm(r.get("se"))),
                    fmt(r.get("n"))] + [fmt(mm(b.get(p))) for p in parts]
                   + [fmt(mm(r.get("total"))), "yes" if r.get("resolved") else "no"])
    return _table(head, out)


def _signed(x) -> str:
    """A difference with its sign (4 significant digits), ``-`` when missing."""
    return f"{x:+.4g}" if isinstance(x, (int, float)) and math.isfinite(x) else "-"


def band_meshes_table(data: dict, opts: dict) -> list[str]:
    """bench/shear_band.py --compare's mesh_study.json: a row per mesh, coarse to fine."""
    meshes = data.get("meshes")
    if not isinstance(meshes, list) or not meshes:
        raise TableError("the data file has no 'meshes' (bench/shear_band.py --compare's "
                         "mesh_study.json)")
    pairs = {p.get("to"): p for p in data.get("pairs") or []}
    mm = (lambda v: None if not isinstance(v, (int, float)) else 1e3 * v)  # noqa: E731
    head = ["mesh", "elements", "runs", "cell (mm)", "nonlocal length (mm)", "axial strain (%)",
            "localization index", "band angle (°) ± error", "width (mm) ± se", "width / cell",
            "angle's move from the coarser mesh (°) ± error", "moves"]
    rows = []
    for m in meshes:
        p = pairs.get(m.get("mesh"))
        length = m.get("nonlocal_length_m")
        w, c = m.get("width_m"), m.get("cell_m")
        rows.append([
            fmt(m.get("mesh")), fmt(m.get("elements")), fmt(m.get("runs", 1)), fmt(mm(c)),
            "local" if not length else fmt(mm(length)),
            fmt(100 * m["axial_strain"] if isinstance(m.get("axial_strain"), (int, float))
                else None),
            fmt(m.get("localization_index")),
            f"{fmt(m.get('angle_deg'))} ± {fmt(m.get('angle_error_deg'))}",
            f"{fmt(mm(w))} ± {fmt(mm(m.get('width_se_m')))}",
            fmt(w / c if isinstance(w, (int, float)) and isinstance(c, (int, float)) and c
                else None),
            "-" if p is None else
            f"{_signed(p.get('angle_move_deg'))} ± {fmt(p.get('angle_error_deg'))}",
            "-" if p is None or p.get("angle_moves") is None else
            ("yes" if p["angle_moves"] else "no")])
    return _table(head, rows)


def source_line(data: dict, path: str) -> str:
    """The line under a study page's table: "Command: `...` · commit `abc1234` (DATE) ·
    data: PATH." (docs/studies/: tests/test_docs_text.py)."""
    p = data["provenance"]
    cmd, commit = _command_and_commit(p)
    dirty = " with uncommitted changes" if p.get("dirty") else ""
    return (f"Command: {cmd} · commit `{commit}`{dirty} "
            f"({str(p.get('date') or '-')[:10]}) · data: {path}.")


KINDS = {"findings": findings_table,
         "measures": lambda d, o: findings_table(d, o, verdict=False),
         "elements": elements_table, "provenance": provenance_line,
         "rve_size": rve_size_table, "differences": differences_table,
         "band_meshes": band_meshes_table}
#: the kinds whose table is followed by its source line (:func:`source_line`)
SOURCED = {"rve_size", "differences", "band_meshes"}


# ---- pages -------------------------------------------------------------------------------------

def parse_options(text: str, kind: str) -> dict:
    opts = {}
    for word in text.split():
        key, eq, value = word.partition("=")
        if not eq or not value:
            raise TableError(f"option {word!r} is not key=value")
        if key not in OPTIONS[kind]:
            allowed = ", ".join(sorted(OPTIONS[kind])) or "none"
            raise TableError(f"{kind} takes no option {key!r} (allowed: {allowed})")
        opts[key] = value
    return opts


def blocks(lines: list[str]) -> list[dict]:
    """The marked blocks of a page (markers inside fenced code are text): for each, the line
    indices of its two markers, its data path, kind and options text."""
    out, fence, cur = [], None, None
    for i, line in enumerate(lines):
        m = FENCE.match(line)
        if m and cur is None:
            fence = None if fence == m.group(1) else (fence or m.group(1))
            continue
        if fence:
            continue
        s = START.match(line.rstrip())
        if s:
            if cur is not None:
                raise TableError(f"line {i + 1}: a table marker inside the table of line "
                                 f"{cur['start'] + 1}")
            cur = {"start": i, "data": s.group("data"), "kind": s.group("kind"),
                   "opts": s.group("opts").strip()}
        elif END.match(line.rstrip()):
            if cur is None:
                raise TableError(f"line {i + 1}: <!-- /table --> without its start")
            cur["end"] = i
            out.append(cur)
            cur = None
        elif re.match(r"<!--\s*(table\s*:|/\s*table)", line.rstrip()):
            raise TableError(f"line {i + 1}: not a table marker: {line.strip()} (expected "
                             "<!-- table: data/FILE.json KIND [key=value ...] -->)")
    if cur is not None:
        raise TableError(f"line {cur['start'] + 1}: no <!-- /table --> after this marker")
    return out


def generated_lines(text: str) -> set[int]:
    """The 1-based numbers of the lines a marked block's data writes (between its markers):
    text checks of the docs (work-log words, commit ids) can skip them, since the provenance
    line names a commit on purpose. Empty when the page's markers do not parse."""
    try:
        found = blocks(text.split("\n"))
    except TableError:
        return set()
    return {k + 1 for b in found for k in range(b["start"] + 1, b["end"])}


def _load(path: Path, cache: dict) -> dict:
    if path not in cache:
        if not path.is_file():
            raise TableError(f"data file {path} is missing")
        try:
            cache[path] = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise TableError(f"data file {path} is not JSON: {exc}") from exc
    return cache[path]


def body(page: Path, block: dict, cache: dict | None = None) -> list[str]:
    """The lines between a block's markers, from its data."""
    kind = block["kind"]
    if kind not in KINDS:
        raise TableError(f"unknown kind {kind!r} (kinds: {', '.join(KINDS)})")
    opts = parse_options(block["opts"], kind)
    data = _load(page.parent / block["data"], {} if cache is None else cache)
    prov = data.get("provenance")
    if not isinstance(prov, dict) or not prov.get("command") or not prov.get("commit"):
        raise TableError(f"data file {block['data']} has no provenance with its command and "
                         "commit (make it with `capture`)")
    lines = KINDS[kind](data, opts)
    if kind in SOURCED:  # (a study page's table carries its source line: docs/studies/)
        lines += ["", source_line(data, block["data"])]
    return [""] + lines + [""]


def process(page: Path, *, write: bool) -> list[str]:
    """Compares (and with ``write`` rewrites) every marked block of ``page``; returns one
    problem line per block that differs from its data or cannot be rendered."""
    page = Path(page)
    if not page.is_file():
        return [f"{page}: no such page"]
    text = page.read_text(encoding="utf-8")
    lines = text.split("\n")
    try:
        found = blocks(lines)
    except TableError as exc:
        return [f"{page}: {exc}"]
    problems, cache, new = [], {}, list(lines)
    for n, b in reversed(list(enumerate(found, 1))):
        where = f"{page}: table {n} (line {b['start'] + 1}: {b['data']} {b['kind']})"
        try:
            want = body(page, b, cache)
        except TableError as exc:
            problems.append(f"{where}: {exc}")
            continue
        have = lines[b["start"] + 1:b["end"]]
        if have != want:
            if not write:
                i = next((k for k, (a, c) in enumerate(zip(have, want)) if a != c),
                         min(len(have), len(want)))
                got = (have[i] or "(a blank line)") if i < len(have) else "(the end marker)"
                exp = (want[i] or "(a blank line)") if i < len(want) else "(the end marker)"
                problems.append(f"{where}: differs from its data; line {b['start'] + 2 + i} "
                                f"is\n    {got}\n  the data gives\n    {exp}")
            new[b["start"] + 1:b["end"]] = want
    problems.reverse()
    if write and new != lines:
        page.write_text("\n".join(new), encoding="utf-8")
    return problems


def pages(paths: list[str]) -> list[Path]:
    out = []
    for p in map(Path, paths):
        out += sorted(p.rglob("*.md")) if p.is_dir() else [p]
    return out


# ---- capture -----------------------------------------------------------------------------------

def trim(v):
    """``v`` without its long lists (histories): scalars, short lists of scalars, and dicts of
    those at any depth. Returns ``trim.DROP`` when nothing is left to keep."""
    if v is None or isinstance(v, (str, int, float, bool)):
        return v
    if isinstance(v, (list, tuple)):
        if len(v) > MAX_LIST:
            return trim.DROP
        items = [trim(x) for x in v]
        return trim.DROP if any(x is trim.DROP for x in items) else items
    if isinstance(v, dict):
        return {k: t for k, t in ((k, trim(x)) for k, x in v.items()) if t is not trim.DROP}
    return trim.DROP


trim.DROP = object()


def _git(*args: str) -> str | None:
    try:
        r = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True,
                           timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() if r.returncode == 0 else None


def machine() -> str:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = ", " + line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{platform.node()}: {platform.system()} {platform.machine()}, {n} cores{model}"


def _run_date(summary_path: Path) -> str | None:
    manifest = summary_path.parent / ".geogrid-dem-run.json"
    try:
        m = json.loads(manifest.read_text())
    except (OSError, ValueError):
        return None
    return m.get("finished") or m.get("started")


def capture(summary_path: Path, dest: Path, command: str, *, commit: str | None = None,
            date: str | None = None, machine_name: str | None = None) -> dict:
    """Writes ``dest``: ``summary_path``'s JSON trimmed to scalars, with its provenance."""
    summary = json.loads(Path(summary_path).read_text(encoding="utf-8"))
    out = {}
    for key, value in summary.items():
        if key in ("findings", "measures", "params", "provenance"):
            out[key] = value
        elif key in ("elements", "fem") and isinstance(value, dict):
            out[key] = {k: trim(v) for k, v in value.items() if trim(v) is not trim.DROP}
        else:
            t = trim(value)
            if t is not trim.DROP:
                out[key] = t
    if "provenance" in out:  # the case's own record (if it writes one) is kept under run
        out["run_provenance"] = out.pop("provenance")
    dirty = _git("status", "--porcelain", "--untracked-files=no")
    out["provenance"] = {
        "command": command,
        "commit": commit or _git("rev-parse", "HEAD") or "unknown",
        "dirty": None if commit else bool(dirty),  # None: unknown (a given commit)
        "date": date or _run_date(Path(summary_path))
        or _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "machine": machine_name or machine(),
        "captured_from": str(summary_path),
    }
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(out, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return out


# ---- the command line --------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("capture", help="a case's summary.json as a docs data file")
    c.add_argument("summary", type=Path)
    c.add_argument("dest", type=Path)
    c.add_argument("--command", required=True, help="the exact command line of the run")
    c.add_argument("--commit", help="the run's commit when it was not HEAD")
    c.add_argument("--date", help="the run's date (default: its folder's manifest, else now)")
    c.add_argument("--machine", help="the run's machine (default: this one)")
    r = sub.add_parser("render", help="rewrite the marked tables of pages from their data")
    r.add_argument("pages", nargs="+")
    k = sub.add_parser("check", help="non-zero when a marked table differs from its data")
    k.add_argument("pages", nargs="+", help="pages or folders (searched for *.md)")
    a = ap.parse_args(argv)

    if a.cmd == "capture":
        out = capture(a.summary, a.dest, a.command, commit=a.commit, date=a.date,
                      machine_name=a.machine)
        p = out["provenance"]
        print(f"{a.dest}: {len(out.get('findings', []))} findings, "
              f"{len(out.get('measures', []))} measures, {len(out.get('elements', {}))} "
              f"elements; commit {p['commit'][:12]}{' (dirty)' if p['dirty'] else ''}")
        return 0
    problems, n = [], 0
    for page in pages(a.pages):
        found = process(page, write=a.cmd == "render")
        problems += found
        n += 1
    for p in problems:
        print(p, file=sys.stderr)
    if a.cmd == "check" and not problems:
        print(f"{n} pages: every marked table matches its data")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
