"""bench/step_budget.py: a step's bytes from the core's arrays and their traffic counts, over
its time and the measured bandwidth (the bench itself is not run by CI at full size)."""

import json
import subprocess
import sys

from conftest import ROOT


def test_the_budget_is_the_fields_times_their_traffic_over_the_time(tmp_path):
    proc = subprocess.run([sys.executable, str(ROOT / "bench" / "step_budget.py"), "--sizes",
                           "300", "--steps", "20", "--warmup", "5", "--bandwidth-mib", "8"],
                          capture_output=True, text=True, timeout=600, cwd=ROOT,
                          env={"OMP_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    bw, row = [json.loads(line) for line in proc.stdout.splitlines()]
    assert bw["copy_bytes_per_s"] > 1e8 and bw["read_bytes_per_s"] > 1e8
    sys.path.insert(0, str(ROOT / "bench"))
    from step_budget import TRAFFIC

    assert set(row["moved_by_field"]) <= set(TRAFFIC)
    assert row["bytes_per_step"] == sum(row["moved_by_field"].values())
    # every sphere-sphere contact's record crosses the pair pass: at least 2 x 96 B each, and
    # every candidate's 4 B are read; on one thread the shares go into the bodies' force and
    # torque (2 reads and 3 writes of 24 B a body, each), not into pair_out, pair_fi or pair_ti
    assert 0 < row["pair_contacts"] <= row["contacts"]
    assert row["moved_by_field"]["contacts.pairs"] >= 2 * 96 * row["pair_contacts"]
    assert row["moved_by_field"]["broadphase.candidates"] >= 4 * row["pair_contacts"]
    for name in ("contacts.pair_out", "scratch.pair_fi", "scratch.pair_ti"):
        assert name not in row["moved_by_field"], name
    assert row["moved_by_field"]["bodies.force"] == 5 * 24 * row["n"]
    assert row["moved_by_field"]["bodies.torque"] == 5 * 24 * row["n"]
    assert row["needed_bytes_per_s"] == row["bytes_per_step"] / row["s_per_step"]
    assert abs(row["share_of_copy_bandwidth"]
               - row["needed_bytes_per_s"] / bw["copy_bytes_per_s"]) < 1e-12
    assert "ms/step" in proc.stderr and "of the copy bandwidth" in proc.stderr
