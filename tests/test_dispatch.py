"""The CPU dispatch a run records (cpp_dem.dispatch.cpu_dispatch; issue 62 item 3): the DEM
core's SIMD path and the BLAS kernels, as each rounding variant changes them, in the run
folder's manifest."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from cpp_dem.dispatch import cpu_dispatch


def _dispatch_in(env: dict) -> dict:
    """cpu_dispatch() of a fresh process with ``env`` added (numpy loaded: its BLAS)."""
    code = ("import json, numpy; from cpp_dem.dispatch import cpu_dispatch; "
            "print(json.dumps(cpu_dispatch()))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env={**os.environ, **env}, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def _flags() -> set[str]:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


def test_the_simd_path_follows_the_cpu_and_the_narrow_switch():
    d = cpu_dispatch()
    assert set(d) == {"dem_simd", "numpy_simd", "cpp_dem_narrow", "cpu", "openblas_coretype",
                      "blas"}
    simd = d["dem_simd"]
    flags = _flags()
    if simd["clones"]:
        want = ("x86-64-v4" if {"avx512f", "avx512bw", "avx512vl", "avx512dq"} <= flags
                else "x86-64-v3" if {"avx2", "fma", "bmi2"} <= flags else "baseline")
        assert simd["level"] == want, (simd, sorted(flags & {"avx2", "fma", "avx512f"}))
    narrow_env = os.environ.get("CPP_DEM_NARROW") == "1"
    assert simd["ops"] == ("narrow" if narrow_env or "avx2" not in flags else "wide")
    n = _dispatch_in({"CPP_DEM_NARROW": "1"})
    assert n["dem_simd"]["ops"] == "narrow" and n["cpp_dem_narrow"] == "1"
    assert n["dem_simd"]["level"] == simd["level"]  # (the loader's pick is the CPU's)
    # the linear contacts eight at a time: in the wide form, where the CPU has AVX-512
    if simd["clones"]:
        assert simd["linear_batch"] == (simd["ops"] == "wide" and simd["level"] == "x86-64-v4")
    assert n["dem_simd"]["linear_batch"] is False


def test_numpys_own_dispatch_is_recorded_as_npy_disable_cpu_features_sets_it():
    """NumPy's array exp, log, power, tan and arccos take another form on a CPU without
    AVX-512 and round otherwise: its targets are recorded, and a disabled one drops out."""
    d = _dispatch_in({})["numpy_simd"]
    assert d["version"] and d["disabled"] is None
    if not d["targets"]:
        pytest.skip("this CPU runs none of NumPy's dispatch targets")
    top = d["targets"][-1]
    less = _dispatch_in({"NPY_DISABLE_CPU_FEATURES": top})["numpy_simd"]
    assert less["disabled"] == top and top not in less["targets"]


def test_the_blas_kernel_is_recorded_as_openblas_coretype_sets_it():
    d = _dispatch_in({})
    libs = [b for b in d["blas"] if b.get("api") == "openblas"]
    assert libs and all(b["architecture"] and b["library"] for b in libs)  # numpy's at least
    h = _dispatch_in({"OPENBLAS_CORETYPE": "Haswell"})
    assert h["openblas_coretype"] == "Haswell"
    assert {b["architecture"] for b in h["blas"] if b.get("api") == "openblas"} == {"Haswell"}
    # another kernel set, where this CPU has one, is told apart
    s = _dispatch_in({"OPENBLAS_CORETYPE": "Sandybridge"})
    assert {b["architecture"] for b in s["blas"] if b.get("api") == "openblas"} == {
        "Sandybridge"}


def test_a_run_folder_records_its_dispatch(tmp_path):
    from geogrid_dem import rundir

    out = rundir.begin_run(tmp_path / "r", "triaxial", log=lambda *_: None,
                           params={"n": 10})
    rundir.end_run(out)
    code = json.loads((out / rundir.MANIFEST).read_text())["code"]
    assert code["cpu_dispatch"]["dem_simd"]["ops"] in ("wide", "narrow")
    assert code["cpu_dispatch"]["cpu"] and "commit" in code
