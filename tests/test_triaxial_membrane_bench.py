"""bench/triaxial_membrane.py (the cylindrical triaxial in a membrane beside the cubical one):
its smoke runs both shapes on one seed and writes the paired differences; the table in
docs/studies/triaxial_membrane.md is the bench's rendering of the committed data file."""

import json
import os
import subprocess
import sys
from pathlib import Path

from conftest import load_bench

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench" / "triaxial_membrane.py"


def _bench_module():
    return load_bench("triaxial_membrane")


def test_the_smoke_runs_both_shapes_and_pairs_them(tmp_path):
    out = tmp_path / "tm.json"
    p = subprocess.run([sys.executable, str(BENCH), "--smoke", "--out", str(out)],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr[-2000:]
    data = json.loads(out.read_text())
    shapes = {r["shape"] for r in data["runs"]}
    assert shapes == {"cylinder", "box"}
    cyl = next(r for r in data["runs"] if r["shape"] == "cylinder")
    box = next(r for r in data["runs"] if r["shape"] == "box")
    assert cyl["prepared"]["reached"] and box["isotropic_reached"]
    assert cyl["grains_outside"] == 0
    assert all(q > 0 for q in cyl["q_pa"] + box["q_pa"])
    # The paired difference is the cylinder's less the box's, per strain.
    d = next(x for x in data["paired"] if x["measure"] == "q_pa" and x["axial_strain"] == 0.01)
    assert d["mean"] == cyl["q_pa"][1] - box["q_pa"][1] and d["n"] == 1
    assert 0.2 < cyl["porosity"] < 0.6 and 0.2 < box["porosity"] < 0.6
    assert len(_bench_module().table(data)) == 3 + 3 * len(data["params"]["at"])


def test_the_docs_table_is_the_committed_data_s():
    mod = _bench_module()
    data = json.loads((ROOT / "docs" / "data" / "triaxial_membrane.json").read_text())
    text = (ROOT / "docs" / "studies" / "triaxial_membrane.md").read_text()
    for line in mod.table(data):
        assert line in text, line
