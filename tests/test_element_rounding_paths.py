"""002's element, DEM only, gives the same bits on the DEM core's two forms, with NumPy's
baseline loops and under another BLAS kernel (docs/core.md, "The same bits on every x86-64
CPU"): its clumps of gravel built (principal frames, members, quaternions), its woven grid,
the growth, the servo stages, the rest hold and the measures. Before, each was another
chaotic sample: 002's smoke read another soil and another verdict on each path
(docs/prs_element_002.md, "Smoke size")."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARGS = ["--smoke", "--stresses", "20000,20000,40000", "--n", "250", "--grids", "standard",
        "--seeds", "1"]
#: summary.json keys that are the run's own (times, the process's dispatch), not its result
OWN = ("wall_time", "time_s", "wall_s", "provenance")


def _strip(x):
    if isinstance(x, dict):
        return {k: _strip(v) for k, v in x.items() if not any(w in k for w in OWN)}
    if isinstance(x, list):
        return [_strip(v) for v in x]
    return x


def _run(out: Path, env: dict) -> tuple[dict, dict]:
    r = subprocess.run([sys.executable, str(ROOT / "cases" / "prs_element_002.py"), *ARGS,
                        "--out", str(out)], capture_output=True, text=True, cwd=ROOT,
                       env={**os.environ, "OMP_NUM_THREADS": "1", **env}, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    csvs = {p.name: p.read_bytes() for p in sorted(out.glob("*.csv"))}
    return _strip({k: summary[k] for k in ("elements", "findings", "measures")}), csvs


def test_the_element_is_the_same_bits_on_the_narrow_form_and_another_blas_kernel(tmp_path):
    # (the narrow form with this CPU's BLAS kernel, against the wide form with Haswell's: a
    # run equal to both paths' changes at once)
    # (the narrow side also with NumPy's baseline loops: a CPU without AVX2 has neither)
    a = _run(tmp_path / "narrow", {"CPP_DEM_NARROW": "1",
                                   "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"})
    b = _run(tmp_path / "haswell", {"OPENBLAS_CORETYPE": "Haswell", "CPP_DEM_NARROW": "0"})
    assert len(a[1]) >= 4 and a[1].keys() == b[1].keys()
    for name in a[1]:
        assert a[1][name] == b[1][name], name
    assert a[0] == b[0]
