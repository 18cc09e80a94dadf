"""The C++ kernel tests (tests/cpp/test_kernels.cpp): the contact-law parts, the registry and
the shape-pair units on plain values, compiled here against the core's headers (header-only
kernels, plus the materials unit) with the system compiler and Eigen 3.4."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EIGEN = Path("/usr/include/eigen3")


@pytest.mark.skipif(shutil.which("c++") is None or not EIGEN.exists(),
                    reason="needs a C++ compiler and Eigen (scripts/setup.sh installs them)")
def test_kernels(tmp_path):
    exe = tmp_path / "test_kernels"
    cmd = ["c++", "-std=c++17", "-O1", "-Wall", "-Wextra", "-Werror", "-Wno-psabi",
           f"-I{ROOT / 'cpp_dem' / 'include'}", f"-I{EIGEN}",
           str(ROOT / "tests" / "cpp" / "test_kernels.cpp"),
           str(ROOT / "cpp_dem" / "src" / "laws" / "material.cpp"), "-o", str(exe)]
    build = subprocess.run(cmd, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    run = subprocess.run([str(exe)], capture_output=True, text=True,
                         env=dict(os.environ, OMP_NUM_THREADS="1"))
    print(run.stdout)
    assert run.returncode == 0, run.stdout + run.stderr
    assert " 0 failed" in run.stdout.splitlines()[-1]
