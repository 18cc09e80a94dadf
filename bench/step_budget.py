#!/usr/bin/env python3
"""A step's memory traffic against the machine's memory bandwidth (issue 63 item 1).

For the throughput scene (bench/throughput.py's packings: linear law with friction, six
walls, one thread) at each size N it gives:

- the time per step (CPU time of ``--steps`` steps after ``--warmup``);
- the bytes a step must move, from the core's own arrays (``Scene.memory_by_field``) and how
  often a step reads and writes each (``TRAFFIC`` below: the pair pass reads the contacts and
  both bodies' state and writes the contacts' state and outputs; the reduction reads the
  outputs and writes the accelerations; the integration reads and writes the bodies' state).
  Each array counts once per read and once per write: the least a step moves when nothing
  stays in cache between the passes, a lower bound of the traffic once the arrays outgrow
  the caches;
- that traffic over the time: the bandwidth the step would need, and its share of the
  machine's, measured here (``--bandwidth-mib``: numpy copy and sum of arrays that big,
  best of five; the copy counted as STREAM counts it, read + write).

A share near 1 means the step is bound by memory: only fewer bytes make it faster. A small
share (the arrays fit in the caches) means it is bound by instructions. One JSON line per
size and one for the bandwidth on stdout; a table on stderr.

Usage (from the repository root, in the project venv; a quiet machine):
    OMP_NUM_THREADS=1 python bench/step_budget.py                      # N = 1e3, 1e4, 1e5
    OMP_NUM_THREADS=1 python bench/step_budget.py --sizes 1000 --steps 200 --bandwidth-mib 64
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import throughput  # noqa: E402  (its packings and scene)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

#: How many times a step reads and writes each of the core's arrays (the fields of
#: Scene.memory_by_field): (reads, writes). Arrays a step of the throughput scene does not
#: touch (energy tracking, external loads, clumps, the broad phase between its builds, the
#: friction dissipation, written only where a contact slips) are left out; a scene of the
#: short kernels has no cold contact record.
TRAFFIC = {
    "contacts.pairs": (1, 1),          # pair pass: geometry in, shear force and normal out
    "broadphase.candidates": (1, 0),   # pair pass: each candidate's record slot (or its j)
    # (one thread: the pair pass adds each contact's share to its bodies' force and torque
    # at once and keeps no pair_out; on more threads it writes pair_out, 64 B a contact, and
    # pair_fi and pair_ti, which the reduction reads back through pair_jslot and
    # pair_jadj_off: none of them is in the fields here)
    "contacts.pair_ioff": (1, 0),
    "contacts.wall_adj_off": (1, 0),
    "bodies.force": (2, 3),            # started, summed into by the pair pass, completed by
    "bodies.torque": (2, 3),           # the reduction (the accelerations: a block's, in cache)
    "bodies.pos": (2, 1),              # pair pass and integration read, integration writes
    "bodies.vel": (2, 1),
    "bodies.angvel": (2, 1),
    "bodies.ori": (1, 1),
    "bodies.radius": (1, 0),
    "bodies.mass": (1, 0),
    "bodies.inertia": (1, 0),
    "bodies.inertia_scale": (1, 0),
    "bodies.blocked": (1, 0),
    "bodies.kind": (1, 0),
    "broadphase.pos_at_build": (1, 0),  # integration: the displacement since the build
}


def bandwidth(mib: int) -> dict:
    """Copy (read + write, as STREAM counts it) and sum (read) bandwidth, bytes/s, best of
    five on arrays of ``mib`` MiB."""
    n = mib * 2**20 // 8
    a = np.random.default_rng(1).random(n)
    b = np.empty_like(a)
    copy, read = [], []
    for _ in range(5):
        t = time.perf_counter()
        np.copyto(b, a)
        copy.append(2 * a.nbytes / (time.perf_counter() - t))
        t = time.perf_counter()
        float(a.sum())
        read.append(a.nbytes / (time.perf_counter() - t))
    return {"array_mib": mib, "copy_bytes_per_s": max(copy), "read_bytes_per_s": max(read)}


def budget(n: int, steps: int, warmup: int, bw: dict) -> dict:
    cfg = throughput.BenchScene()
    p = throughput.get_packing(n, 1, throughput.DEFAULT_CACHE, cfg)
    scene, _ = throughput.make_scene(p, cfg)
    scene.run(warmup)
    t = time.process_time()
    scene.run(steps)
    s_per_step = (time.process_time() - t) / steps
    fields = scene.memory_by_field()
    moved = {k: fields.get(k, 0) * sum(rw) for k, rw in TRAFFIC.items()}
    total = sum(moved.values())
    c = scene.contacts()
    contacts = len(c["normal_force"])
    pair_contacts = int((np.asarray(c["ids"])[:, 1] >= 0).sum()) if contacts else 0
    return {"n": p.n, "contacts": contacts, "pair_contacts": pair_contacts,
            "s_per_step": s_per_step,
            "bytes_per_step": total, "bytes_per_grain_step": total / p.n,
            "needed_bytes_per_s": total / s_per_step,
            "share_of_copy_bandwidth": total / s_per_step / bw["copy_bytes_per_s"],
            "core_bytes": sum(fields.values()),
            "moved_by_field": {k: v for k, v in sorted(moved.items(), key=lambda kv: -kv[1])
                               if v}}


def main(argv=None) -> int:
    ap = _cli.BenchParser(description=__doc__.split("\n\n")[0],
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000, 100000],
                    help="packing sizes N (bench/throughput.py's packings; default 1e3 1e4 1e5)")
    ap.add_argument("--steps", type=int, default=0,
                    help="timed steps per size (default: about 2e7 particle-steps, 20 to 4000)")
    ap.add_argument("--warmup", type=int, default=20, help="untimed steps first (default 20)")
    ap.add_argument("--bandwidth-mib", type=int, default=1024,
                    help="array size of the bandwidth measure, MiB (default 1024: well above "
                         "the caches)")
    a = ap.parse_args(argv)
    for name in ("steps", "warmup"):
        if getattr(a, name) < 0:
            ap.error(f"--{name}={getattr(a, name)}: must be >= 0")
    if a.bandwidth_mib < 1 or any(n < 8 for n in a.sizes):
        ap.error("--bandwidth-mib must be >= 1 and every --sizes value >= 8")
    bw = bandwidth(a.bandwidth_mib)
    print(json.dumps(bw), flush=True)
    print(f"memory bandwidth: copy {bw['copy_bytes_per_s'] / 1e9:.1f} GB/s, read "
          f"{bw['read_bytes_per_s'] / 1e9:.1f} GB/s ({a.bandwidth_mib} MiB arrays)",
          file=sys.stderr)
    for n in a.sizes:
        steps = a.steps or max(20, min(4000, round(2e7 / n)))
        r = budget(n, steps, a.warmup, bw)
        print(json.dumps(r), flush=True)
        print(f"N {r['n']:>7}: {r['s_per_step'] * 1e3:8.3f} ms/step, "
              f"{r['bytes_per_grain_step']:6.0f} B per grain moved, needs "
              f"{r['needed_bytes_per_s'] / 1e9:5.2f} GB/s = "
              f"{r['share_of_copy_bandwidth']:.2f} of the copy bandwidth", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
