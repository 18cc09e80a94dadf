#!/usr/bin/env python3
"""A/B of the loose-cloud placement (``cpp_dem.build.packing.loose_cloud``, random
sequential addition) of two revisions: the same clouds, each revision in turn, their spheres
compared to the bit.

The placement is Python (numpy), so the old revision needs no build: its
``cpp_dem/cpp_dem/build/packing.py`` (``git show <ref>:...``) is loaded beside the installed
one. Each size is a cloud of ``n`` radii (uniform in 0.8-1.2, seeded) in a cube that they fill
to the given solid fraction; the two revisions place it in alternating order, round by round
(old | new, new | old, ...). The ratio is old/new (> 1: the new one is faster), the median
over the rounds, with its spread. A cloud is *identical* when both place every sphere at the
same centre, to the bit.

One JSON line on stdout per size (``n``, ``solid_fraction``, ``old_s``, ``new_s``,
``ratio_old_over_new``, ``ratio_min``, ``ratio_max``, ``identical``), a table on stderr;
``--out FILE`` appends the lines.

    .venv/bin/python bench/ab_placement.py --ref <before> --rounds 3
"""

from __future__ import annotations

import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

ROOT = Path(__file__).resolve().parents[1]
SOURCE = "cpp_dem/cpp_dem/build/packing.py"
#: (grains, solid fraction): a periodic element's cloud, clumps' bounding spheres, a dense
#: box that needs many tries, a large sparse one.
SIZES = "60:0.2,100:0.25,500:0.15,2000:0.1,5000:0.3,20000:0.05"


def log(msg: str) -> None:
    print(f"[ab_placement] {msg}", file=sys.stderr, flush=True)


def load_revision(ref: str, folder: Path):
    """The packing module of revision ``ref`` (its source from git), loaded as a module of
    its own."""
    try:
        text = subprocess.run(["git", "show", f"{ref}:{SOURCE}"], cwd=ROOT, check=True,
                              capture_output=True, text=True).stdout
    except subprocess.CalledProcessError as e:
        raise _cli.BenchInputError(f"--ref={ref!r}: no {SOURCE} there ({e.stderr.strip()})")
    path = folder / "packing_ref.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("packing_ref", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def parse_sizes(text: str) -> list[tuple[int, float]]:
    out = []
    for item in text.split(","):
        try:
            n, frac = item.split(":")
            n, frac = int(n), float(frac)
        except ValueError:
            raise _cli.BenchInputError(f"--sizes={text!r}: expected N:FRACTION,... "
                                       "(e.g. 100:0.2)") from None
        if n < 1 or not 0 < frac < 0.4:
            raise _cli.BenchInputError(f"--sizes={text!r}: N >= 1 and a solid fraction in "
                                       f"(0, 0.4) (got {item})")
        out.append((n, frac))
    return out


def main() -> None:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0], out="append")
    ap.add_argument("--ref", required=True, help="the old revision (a commit, tag or branch)")
    ap.add_argument("--sizes", default=SIZES, help=f"N:SOLID_FRACTION,... (default {SIZES})")
    ap.add_argument("--rounds", type=int, default=3, help="rounds of old and new (default 3)")
    ap.add_argument("--seed", type=int, default=3, help="the clouds' seed (default 3)")
    ap.add_argument("--out", type=Path, help="append the JSON lines to this file")
    a = ap.parse_args()
    if a.rounds < 1:
        raise _cli.BenchInputError(f"--rounds={a.rounds}: must be >= 1")
    import numpy as np

    from cpp_dem.build import packing as new

    with tempfile.TemporaryDirectory() as tmp:
        old = load_revision(a.ref, Path(tmp))
        rows = []
        for n, frac in parse_sizes(a.sizes):
            radii = np.random.default_rng(a.seed).uniform(0.8, 1.2, n)
            edge = (np.sum(4.0 / 3.0 * np.pi * radii**3) / frac) ** (1.0 / 3.0)
            times = {"old": [], "new": []}
            clouds, same = {}, True
            for k in range(a.rounds):
                for name in (("old", "new") if k % 2 == 0 else ("new", "old")):
                    mod = old if name == "old" else new
                    t = time.perf_counter()
                    clouds[name] = mod.loose_cloud(radii, (0, 0, 0), (edge,) * 3, seed=a.seed)
                    times[name].append(time.perf_counter() - t)
                # (every round's pair: identical only if both agree in each round)
                same &= all(np.array_equal(u, v) for u, v in zip(clouds["old"], clouds["new"]))
            ratios = [o / w for o, w in zip(times["old"], times["new"])]
            row = {"n": n, "solid_fraction": frac, "ref": a.ref,
                   "old_s": statistics.median(times["old"]),
                   "new_s": statistics.median(times["new"]),
                   "ratio_old_over_new": statistics.median(ratios),
                   "ratio_min": min(ratios), "ratio_max": max(ratios), "identical": same}
            rows.append(row)
            line = json.dumps(row)
            print(line, flush=True)
            if a.out is not None:
                with open(a.out, "a") as f:
                    f.write(line + "\n")
        log(f"{'grains':>7} {'solid':>6} {'old s':>8} {'new s':>8} {'old/new':>8}  identical")
        for r in rows:
            log(f"{r['n']:>7} {r['solid_fraction']:>6.2f} {r['old_s']:>8.3f} {r['new_s']:>8.3f}"
                f" {r['ratio_old_over_new']:>8.2f}  {r['identical']}")


if __name__ == "__main__":
    sys.exit(_cli.run(main))
