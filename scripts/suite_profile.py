#!/usr/bin/env python3
"""Where a run's CPU goes, across all its processes, from py-spy's raw samples.

`--durations` gives each test's wall time, not what the cases, Dask workers and MPI ranks
that the tests start spend it on. py-spy samples every process of a tree; record the suite
with it (py-spy is not a dependency of the project: install it in a venv of its own) and
read its raw file here:

    python3 -m venv /tmp/spy && /tmp/spy/bin/pip install py-spy
    OMP_NUM_THREADS=1 OMP_WAIT_POLICY=passive /tmp/spy/bin/py-spy record --subprocesses -r 20 \\
        -f raw -o suite.raw -- .venv/bin/python -m pytest -q -n 2 --dist loadfile tests
    .venv/bin/python scripts/suite_profile.py suite.raw
    .venv/bin/python scripts/suite_profile.py suite.raw --where 'network_tangent \\('

Each line of the raw file is a stack (frames joined by ';', outermost first) and its count of
samples. The report gives each category's share of the samples: a stack counts in the first
category (in CATEGORIES' order) that one of its frames matches. py-spy counts threads that
wait in an event loop too, so the samples exceed the CPU time (about 1.6 x for `make test`):
read the shares, not the seconds. With ``--where REGEX``, the stacks that match are broken
down by their innermost three frames instead; ``--callers REGEX`` breaks them down by the two
frames that call the innermost frame matching REGEX (who runs the DEM's steps:
``--callers 'Scene\\.run \\('``).
"""

from __future__ import annotations

import argparse
import collections
import re
import sys
from pathlib import Path

#: (name, pattern): a stack counts in the first category one of whose frames matches.
CATEGORIES = (
    ("the DEM's steps (Scene.run)", r"Scene\.run \("),
    ("the FEM (femcoupling)", r"femcoupling/(fem|materials)/"),
    ("network tangents", r"network_tangent \("),
    ("figures (matplotlib, PIL)", r"matplotlib/|PIL/"),
    ("the loose-cloud placement", r"_sequential_addition \("),
    ("imports", r"_find_and_load"),
    ("HDF5 records (h5py)", r"h5py/|hdf5\.py"),
    ("Dask, Tornado, asyncio", r"distributed/|tornado/|asyncio/"),
    ("pytest", r"_pytest/|pluggy/|xdist/|execnet/"),
)


class ProfileError(ValueError):
    """A raw file that holds no samples."""


def read_raw(path: Path):
    """(frames, count) per stack of a py-spy raw file; lines that are not a stack and a count
    (a frame's text may hold spaces, not the count) are skipped."""
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            stack, _, n = line.rstrip("\n").rpartition(" ")
            if stack and n.isdigit():
                yield stack.split(";"), int(n)


def categories(path: Path) -> tuple[int, dict[str, int]]:
    """(all samples, samples per category: CATEGORIES' names and "other")."""
    rules = [(name, re.compile(pat)) for name, pat in CATEGORIES]
    out = collections.Counter()
    total = 0
    for frames, n in read_raw(path):
        total += n
        stack = ";".join(frames)
        out[next((name for name, pat in rules if pat.search(stack)), "other")] += n
    if total == 0:
        raise ProfileError(f"{path}: no samples (a py-spy file recorded with -f raw?)")
    return total, dict(out)


def _short(frame: str) -> str:
    """'function (file.py:line)' of a frame 'function (path/to/file.py:line)'."""
    m = re.match(r"(.*) \((.*)\)$", frame)
    return f"{m.group(1)} ({m.group(2).rsplit('/', 1)[-1]})" if m else frame


def breakdown(path: Path, *, where: str | None = None, callers: str | None = None
              ) -> tuple[int, int, collections.Counter]:
    """(all samples, matching samples, Counter of keys): the stacks that match ``where``
    by their innermost three frames, or those with a frame matching ``callers`` by the two
    frames that call its innermost such frame."""
    pat = re.compile(callers or where)
    keys = collections.Counter()
    total = matched = 0
    for frames, n in read_raw(path):
        total += n
        hits = [k for k, f in enumerate(frames) if pat.search(f)]
        if not hits:
            continue
        matched += n
        if callers:
            k = hits[-1]
            keys[" <- ".join(_short(f) for f in reversed(frames[max(0, k - 2):k]))] += n
        else:
            keys[" ; ".join(_short(f) for f in frames[-3:])] += n
    if total == 0:
        raise ProfileError(f"{path}: no samples (a py-spy file recorded with -f raw?)")
    return total, matched, keys


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("raw", type=Path, help="py-spy's raw file (record -f raw)")
    ap.add_argument("--where", help="break the stacks matching this regex down by their "
                                    "innermost frames")
    ap.add_argument("--callers", help="break the stacks with a frame matching this regex "
                                      "down by that frame's two callers")
    ap.add_argument("--top", type=int, default=25, help="rows of a breakdown (default 25)")
    a = ap.parse_args(argv)
    if not a.raw.is_file():
        ap.error(f"raw={str(a.raw)!r}: no such file")
    if a.top < 1:
        ap.error(f"--top={a.top}: must be >= 1")
    if a.where and a.callers:
        ap.error("--where and --callers: give one of them")
    try:
        if a.where or a.callers:
            total, matched, keys = breakdown(a.raw, where=a.where, callers=a.callers)
            print(f"{matched} of {total} samples ({100 * matched / total:.1f} %) match")
            for k, v in keys.most_common(a.top):
                print(f"{100 * v / total:6.2f} %  {k}")
        else:
            total, cats = categories(a.raw)
            print(f"{total} samples")
            for name, v in sorted(cats.items(), key=lambda kv: -kv[1]):
                print(f"{100 * v / total:6.2f} %  {name}")
    except (ProfileError, re.error) as e:
        print(f"suite_profile: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
