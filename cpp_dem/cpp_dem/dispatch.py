"""The CPU dispatch of this process: which code paths its arithmetic takes.

Two runs of the same input on the same build give the same bits; on another CPU, or with
another BLAS kernel, they may not: the step's hot loops are compiled for several instruction
sets and picked at load time, ``CPP_DEM_NARROW=1`` selects the narrow (scalar) form of the
pair pass, and OpenBLAS picks its kernels by CPU (``OPENBLAS_CORETYPE`` overrides it). A run
records what it took (``cpu_dispatch()``), so that two results can be told apart by their
rounding path (docs/cli.md, "Results folders")."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cpu_dispatch"]


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    import platform

    return platform.processor() or "unknown"


def _numpy_simd() -> dict:
    """NumPy's own dispatch: its version, the instruction-set targets its loops run at here
    (an array's exp, log, power, tan, arccos round otherwise on a CPU without AVX-512), and
    ``NPY_DISABLE_CPU_FEATURES``."""
    import numpy as np

    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
        targets = [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]
    except ImportError:  # (another NumPy layout)
        targets = None
    return {"version": np.__version__, "targets": targets,
            "disabled": os.environ.get("NPY_DISABLE_CPU_FEATURES")}


def cpu_dispatch() -> dict:
    """The rounding path of this process: ``dem_simd`` (the DEM core's: ``ops`` "wide" or
    "narrow", ``clones`` and the instruction-set ``level`` its hot loops run at),
    ``numpy_simd`` (NumPy's version, the targets its loops run at, and
    ``NPY_DISABLE_CPU_FEATURES``), ``cpp_dem_narrow`` (the variable's value or None), ``cpu`` (the CPU's model name),
    ``openblas_coretype`` (the variable's value or None) and ``blas``: one entry per BLAS
    library loaded in the process at the call ({"library": file name, "api", "version",
    "architecture": the kernel set it runs}; a library loaded later, such as dolfinx's on its
    first import, is not listed). Workers on other machines have their own."""
    from cpp_dem import _core

    blas = []
    try:
        from threadpoolctl import threadpool_info

        for lib in threadpool_info():
            if lib.get("user_api") == "blas":
                blas.append({"library": Path(lib.get("filepath") or "?").name,
                             "api": lib.get("internal_api"), "version": lib.get("version"),
                             "architecture": lib.get("architecture")})
    except Exception as e:  # noqa: BLE001  (threadpoolctl missing or a library it cannot read)
        blas.append({"error": f"{type(e).__name__}: {e}"})
    return {"dem_simd": dict(_core.simd_dispatch()),
            "numpy_simd": _numpy_simd(),
            "cpp_dem_narrow": os.environ.get("CPP_DEM_NARROW"),
            "cpu": _cpu_model(),
            "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE"),
            "blas": blas}
