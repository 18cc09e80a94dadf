#!/usr/bin/env python3
"""Marginal memory per grain of a dense packing (issue 63's bench): ONE JSON line.

Two sizes of the throughput bench's dense packing (bench/throughput.py: the same scene, six
walls, the linear law, the same dt and margin), each built and run for ``--steps`` steps in a
fresh process on one thread. Between the two:

- ``bytes_per_grain``: the process's resident memory (VmRSS after the run less VmRSS before
  the scene was made), its slope between the sizes: what one more grain costs, without the
  interpreter's and the libraries' fixed memory;
- ``core_bytes_per_grain``: the same slope of the core's own arrays
  (``Scene.memory_by_field``: capacity x element size);
- ``fields``: each array's slope, bytes per grain (largest first), and ``field_shares``:
  each over their sum;
- ``grains`` (the two sizes) and ``contacts_per_grain`` (active contacts, sphere-sphere and
  sphere-wall, over grains, of the larger).

The bench's packings are generated once and cached (bench/throughput.py's cache folder);
``--packing A.csv B.csv`` measures two given packings instead (CSV x,y,z,r with a JSON
sidecar holding the box, or the spheres' bounding box). A table of the largest fields goes to
stderr.

    .venv/bin/python bench/memory.py                      # 2 000 and 20 000 grains
    .venv/bin/python bench/memory.py --sizes 20000 200000  # generates 2e5 once (~1 h)
    .venv/bin/python bench/memory.py --packing small.csv large.csv
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402

HERE = Path(__file__).resolve().parent

_ONE = r"""
import json, sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
import throughput as T
from _machine import resident_bytes

p = T.load_packing(Path(sys.argv[2]))
cfg = T.BenchScene()
before = resident_bytes()
scene, _ = T.make_scene(p, cfg)
scene.run(int(sys.argv[3]))
after = resident_bytes()
print(json.dumps({"grains": p.n, "contacts": int(scene.num_active_contacts),
                  "rss_bytes": after - before, "fields": scene.memory_by_field()}))
"""


def one(csv: Path, steps: int) -> dict:
    """One packing in a fresh process on one thread: its grains, contacts, the resident
    memory the scene added (bytes) and the core's arrays by field (bytes)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", _ONE, str(HERE), str(csv), str(steps)],
                         capture_output=True, text=True, env=env)
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no message"])[-1]
        raise _cli.BenchInputError(f"--packing {csv}: the scene did not run ({last})")
    return json.loads(out.stdout.strip().splitlines()[-1])


def marginal(small: dict, large: dict) -> dict:
    """The slope between two measured sizes (the JSON line; module doc)."""
    dn = large["grains"] - small["grains"]
    if dn <= 0:
        raise _cli.BenchInputError(f"the two packings have {small['grains']} and "
                                   f"{large['grains']} grains: the second must have more")
    names = set(small["fields"]) | set(large["fields"])
    fields = {f: (large["fields"].get(f, 0) - small["fields"].get(f, 0)) / dn for f in names}
    fields = dict(sorted(((f, b) for f, b in fields.items() if b), key=lambda x: -x[1]))
    core = sum(fields.values())
    return {"bytes_per_grain": (large["rss_bytes"] - small["rss_bytes"]) / dn,
            "core_bytes_per_grain": core,
            "grains": [small["grains"], large["grains"]],
            "contacts_per_grain": large["contacts"] / large["grains"],
            "fields": fields,
            "field_shares": {f: b / core for f, b in fields.items()} if core else {}}


def main(argv=None) -> int:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0],
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs=2, default=[2000, 20000], metavar="N",
                    help="the two packing sizes (default 2000 20000)")
    ap.add_argument("--packing", type=Path, nargs=2, metavar="CSV",
                    help="measure these two packings instead (the second the larger)")
    ap.add_argument("--steps", type=int, default=100, help="steps run before measuring "
                    "(default 100)")
    ap.add_argument("--seed", type=int, default=1, help="packing seed")
    ap.add_argument("--top", type=int, default=12, help="fields in the stderr table")
    a = ap.parse_args(argv)
    if a.packing:
        csvs = list(a.packing)
        for c in csvs:
            if not c.is_file():
                raise _cli.BenchInputError(f"--packing {c}: no such file")
    else:
        if a.sizes[0] >= a.sizes[1]:
            ap.error(f"--sizes {a.sizes[0]} {a.sizes[1]}: the second must be larger")
        import throughput as T

        csvs = [T.get_packing(n, a.seed, T.DEFAULT_CACHE, T.BenchScene()).csv for n in a.sizes]
    small, large = (one(c, a.steps) for c in csvs)
    line = marginal(small, large)
    print(json.dumps(line), flush=True)
    print(f"marginal, {line['grains'][0]} -> {line['grains'][1]} grains "
          f"({line['contacts_per_grain']:.2f} contacts a grain): resident "
          f"{line['bytes_per_grain']:.0f} B/grain, core arrays "
          f"{line['core_bytes_per_grain']:.0f} B/grain", file=sys.stderr)
    for f, b in list(line["fields"].items())[:a.top]:
        print(f"  {f:32s} {b:8.1f} B/grain  {100 * line['field_shares'][f]:5.1f} %",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
