"""bench/memory.py (issue 63's bench): the marginal resident memory per grain between two
packings and each field's share, one JSON line; a bad pair of packings refused in one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import memory  # noqa: E402


def test_the_slope_is_per_grain_between_the_sizes():
    small = {"grains": 100, "contacts": 300, "rss_bytes": 1_000_000,
             "fields": {"a": 10_000, "b": 5_000}}
    large = {"grains": 1100, "contacts": 3600, "rss_bytes": 2_500_000,
             "fields": {"a": 110_000, "b": 55_000, "c": 1000}}
    m = memory.marginal(small, large)
    assert m["bytes_per_grain"] == 1500.0
    assert m["fields"] == {"a": 100.0, "b": 50.0, "c": 1.0}
    assert list(m["fields"]) == ["a", "b", "c"]  # largest first
    assert m["core_bytes_per_grain"] == 151.0
    assert sum(m["field_shares"].values()) == pytest.approx(1.0)
    assert m["grains"] == [100, 1100] and m["contacts_per_grain"] == pytest.approx(3600 / 1100)
    with pytest.raises(memory._cli.BenchInputError, match="the second must have more"):
        memory.marginal(large, small)


def _lattice(path: Path, k: int) -> Path:
    h = 0.01
    g = np.arange(k) * h
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    r = np.full(len(pos), 0.505 * h)
    path.write_text("x,y,z,r\n" + "\n".join(f"{x:.17g},{y:.17g},{z:.17g},{q:.17g}"
                                             for (x, y, z), q in zip(pos, r)) + "\n")
    return path


def _run(args, cwd):
    return subprocess.run([sys.executable, str(ROOT / "bench" / "memory.py"), *args],
                          capture_output=True, text=True, cwd=cwd, timeout=300,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})


def test_the_bench_prints_one_line_for_two_packings(tmp_path):
    a, b = _lattice(tmp_path / "a.csv", 6), _lattice(tmp_path / "b.csv", 12)
    p = _run(["--packing", str(a), str(b), "--steps", "5"], tmp_path)
    assert p.returncode == 0, p.stderr[-2000:]
    lines = p.stdout.strip().splitlines()
    assert len(lines) == 1
    m = json.loads(lines[0])
    assert m["grains"] == [216, 1728]
    # each inner grain touches six neighbours: about three pair contacts a grain, and the
    # faces' grains their walls
    assert 2.5 < m["contacts_per_grain"] < 3.5
    assert sum(m["fields"].values()) == pytest.approx(m["core_bytes_per_grain"])
    assert m["fields"]["contacts.pairs"] > 0 and m["fields"]["bodies.pos"] == 24.0
    assert m["bytes_per_grain"] > 0
    bad = _run(["--packing", str(b), str(a)], tmp_path)
    assert bad.returncode == 2 and "the second must have more" in bad.stderr
    assert "Traceback" not in bad.stderr
