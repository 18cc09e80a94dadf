#!/usr/bin/env python3
"""A/B of two builds of the DEM core on one case's whole run: the same command, each build in
turn, its results compared field by field.

``bench/ab_build.py`` times scenes a step at a time; a case's run also prepares, servoes,
holds and measures, with the Python around the steps. This bench runs a case of
``geogrid_dem.cases`` (the name ``geogrid-dem run`` takes, or its module's) with the given
arguments on the *old* build (``--ref``, built and cached by ``ab_build.build_ref`` in
``build/ab/<sha>/``, with that revision's own Python sources) and on the *new* one (the
installed build of the working tree, or ``--new-ref``), alternating old | new, new | old,
... round by round, each run a fresh process with one OpenMP thread.

Each run writes its own folder; the bench reads its ``summary.json`` and compares every field
with the first old run's, except the wall times (any key with ``wall_time`` in its name). The
case's results are *identical* when every run's summary is: the same findings, numbers and
hashes from both builds, to the bit. The timing is each run's wall time (the process's, its
imports included) and CPU time; the ratio is old/new (> 1: the new build is faster), median
over the rounds, with its spread.

One JSON line on stdout (``case``, ``args``, ``old_s``, ``new_s``, ``old_cpu_s``,
``new_cpu_s``, ``ratio_old_over_new``, ``ratio_min``, ``ratio_max``, ``identical``,
``differences``: the first 20 fields that differ, as ``path: old -> new``), a table on
stderr; ``--out FILE`` appends the line.

    .venv/bin/python bench/ab_case.py --ref de87073 --rounds 3 -- prs-element-002 --smoke --soil given --seeds 1
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

ROOT = Path(__file__).resolve().parents[1]
#: A summary's field whose key matches this is a timing, not a result.
TIMING_KEY = re.compile(r"wall_time")


def log(msg: str) -> None:
    print(f"[ab_case] {msg}", file=sys.stderr, flush=True)


def case_module(name: str) -> str:
    """The module of case ``name`` (as ``geogrid-dem run`` names it, "prs-element-002", or
    its module's name, "prs_element_002"); refuses an unknown one, listing the cases."""
    from geogrid_dem.cases import CASES

    for command, case in CASES.items():
        if name in (command, case.module):
            return f"geogrid_dem.cases.{case.module}"
    raise _cli.BenchInputError(f"case={name!r}: not a case; one of {', '.join(CASES)}")


def differences(old, new, path: str = "", limit: int = 20) -> list[str]:
    """The fields of two summaries that differ (NaN equals NaN; timings skipped), as
    ``path: old -> new``, at most ``limit``."""
    out: list[str] = []

    def walk(a, b, p):
        if len(out) >= limit:
            return
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if TIMING_KEY.search(k):
                    continue
                if k not in a or k not in b:
                    out.append(f"{p}.{k}: {'missing' if k not in a else 'present'} -> "
                               f"{'missing' if k not in b else 'present'}")
                    continue
                walk(a[k], b[k], f"{p}.{k}")
        elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
            for i, (u, v) in enumerate(zip(a, b)):
                walk(u, v, f"{p}[{i}]")
        elif isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
            return
        elif a != b or type(a) is not type(b):
            out.append(f"{p}: {a!r} -> {b!r}")

    walk(old, new, path)
    return out


def worker(cfg: dict) -> None:
    """One run: the case's module as ``__main__`` with the build of ``cfg['overlay']`` (the
    installed one where it is empty)."""
    import runpy

    if cfg["overlay"]:
        from ab_build import use_overlay

        use_overlay(Path(cfg["overlay"]))
    import cpp_dem

    where = Path(cpp_dem.__file__).resolve()
    if cfg["overlay"] and Path(cfg["overlay"]).resolve() not in where.parents:
        raise SystemExit(f"the old build was not loaded: cpp_dem from {where}")
    sys.argv = [cfg["module"].rsplit(".", 1)[1], *cfg["args"], "--out", cfg["out"]]
    runpy.run_module(cfg["module"], run_name="__main__", alter_sys=True)


def run_once(variant: str, overlay: str, module: str, args: list[str], out: Path) -> dict:
    cfg = {"overlay": overlay, "module": module, "args": args, "out": str(out)}
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker",
                           json.dumps(cfg)], cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"the {variant} build's run failed (exit {proc.returncode}):\n"
                         f"{proc.stderr[-3000:]}")
    summary = out / "summary.json"
    if not summary.is_file():
        raise SystemExit(f"the {variant} build's run wrote no {summary}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    log(f"{variant}: {wall:.1f} s wall, {cpu:.1f} s CPU")
    return {"wall_s": wall, "cpu_s": cpu, "summary": json.loads(summary.read_text())}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--worker"]:
        worker(json.loads(argv[1]))
        return 0
    ap = _cli.BenchParser(description=__doc__, out="append",
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ref", default="HEAD", help="git revision of the old build (HEAD)")
    ap.add_argument("--new-ref", default="",
                    help="git revision of the new build, built like the old one (default: the "
                         "installed build of the working tree)")
    ap.add_argument("--rounds", type=int, default=2,
                    help="rounds of one run on each build (alternating their order)")
    ap.add_argument("--jobs", type=int, default=2, help="compile jobs for the old build")
    ap.add_argument("--out", default=None, help="a JSON-lines file to append the line to")
    ap.add_argument("case", help="the case (as `geogrid-dem run` names it)")
    ap.add_argument("case_args", nargs=argparse.REMAINDER,
                    help="the case's arguments, after `--` (not --out: each run has its own)")
    args = ap.parse_args(argv)
    case_args = [a for a in args.case_args if a != "--"]
    if any(a == "--out" or a.startswith("--out=") for a in case_args):
        raise _cli.BenchInputError("--out among the case's arguments: each run writes its own "
                                   "folder; give --out before the case for the JSON line")
    module = case_module(args.case)
    from ab_build import build_ref

    overlays = {"old": str(build_ref(args.ref, args.jobs)),
                "new": str(build_ref(args.new_ref, args.jobs)) if args.new_ref else ""}
    runs: dict[str, list[dict]] = {"old": [], "new": []}
    with tempfile.TemporaryDirectory(prefix="ab_case_") as tmp:
        for r in range(args.rounds):
            order = ("old", "new") if r % 2 == 0 else ("new", "old")
            for variant in order:
                log(f"round {r + 1}/{args.rounds}, {variant} build")
                runs[variant].append(run_once(variant, overlays[variant], module, case_args,
                                              Path(tmp) / f"{variant}_{r}"))
    reference = runs["old"][0]["summary"]
    diffs: list[str] = []
    for variant in ("old", "new"):
        for k, run in enumerate(runs[variant]):
            for d in differences(reference, run["summary"]):
                diffs.append(f"{variant} run {k + 1}: {d}")
    ratios = [o["wall_s"] / n["wall_s"] for o, n in zip(runs["old"], runs["new"])]
    line = {"case": args.case, "args": case_args, "ref": args.ref,
            "new_ref": args.new_ref or "working tree", "rounds": args.rounds,
            "old_s": [round(x["wall_s"], 2) for x in runs["old"]],
            "new_s": [round(x["wall_s"], 2) for x in runs["new"]],
            "old_cpu_s": [round(x["cpu_s"], 2) for x in runs["old"]],
            "new_cpu_s": [round(x["cpu_s"], 2) for x in runs["new"]],
            "ratio_old_over_new": statistics.median(ratios), "ratio_min": min(ratios),
            "ratio_max": max(ratios), "identical": not diffs, "differences": diffs[:20]}
    text = json.dumps(line)
    print(text, flush=True)
    if args.out:
        with open(args.out, "a") as f:
            f.write(text + "\n")
    print(f"\n| case | old s | new s | old/new (min-max) | results |\n|---|---|---|---|---|\n"
          f"| {args.case} {' '.join(case_args)} | {', '.join(map(str, line['old_s']))} | "
          f"{', '.join(map(str, line['new_s']))} | {line['ratio_old_over_new']:.3f} "
          f"({line['ratio_min']:.3f}-{line['ratio_max']:.3f}) | "
          f"{'identical' if not diffs else f'{len(diffs)} differences'} |", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
