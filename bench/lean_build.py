#!/usr/bin/env python3
"""Lean-build benchmark (issue 7, "Model only what a scene requires").

Does a sphere-only scene pay for the geogrid code compiled into the step loop? In one run:

1. **Lean build.** Configures and builds the extension module `_core` with
   ``-DCPP_DEM_GEOGRID=OFF`` into ``build/lean/`` (CMake, Release, the venv's pybind11, at
   most ``--jobs`` compile jobs). The build is cached: CMake/Ninja recompile only what changed
   since the last run, and configure only when there is no cache yet. The lean module is put
   in an overlay package ``build/lean/overlay/cpp_dem/`` (links to the Python sources of
   ``cpp_dem`` plus the lean ``_core``), so both builds are driven by the same Python code.
2. **Same scene, both builds, A/B blocks.** A dense, confined packing of N spheres (cached by
   bench/throughput.py; radii 2 mm +- 20 %), linear law (E = 1e7 Pa, k_s/k_n = 0.3, friction
   30 deg, density 2600 kg/m^3), six fixed walls, gravity 9.81 m/s^2 along -z, local damping
   0.2, fixed dt = 0.5 x the p-wave step. Each *block* is a fresh subprocess that builds the
   scene, runs ``--warmup`` untimed steps, then times ``--steps`` steps with
   ``time.process_time`` (CPU of that process) and ``time.perf_counter`` (wall). Blocks
   alternate between the builds for ``--rounds`` rounds (full lean | lean full | full lean
   ...: the first of a round alternates too, so a drift of the load cancels); round k gives
   the ratio full_k / lean_k of the CPU time per step, and the spread of that ratio over the
   rounds is the noise of the measurement. Every block hashes the final positions (and the
   whole state: velocities, angular velocities, orientations, wall forces): both builds must
   give bitwise identical results.
   On a shared machine CPU time still varies by a few per cent (caches and memory bandwidth
   are shared), so the same scene is also run under ``valgrind --tool=callgrind`` (1 thread,
   if valgrind is installed): the instructions executed per step by each build, an exact
   count that other jobs cannot disturb (two runs per build that differ only in the number
   of steps; the difference of their whole-process counts over the step difference;
   PYTHONHASHSEED=0 so that the interpreter's start-up work is the same in both).
3. **DEM-only never imports dolfinx.** A short DEM-only case (``cases/prs_element.py --smoke
   --stresses 20e3,20e3,40e3``: a geogrid element driven by given stresses, no FEM) runs in
   a subprocess; at its end the script lists which of dolfinx / petsc4py / ufl (and basix,
   ffcx, gmsh, mpi4py for information) are in ``sys.modules``. Every timed block reports the
   same for the sphere scene, in both builds. Import times (fresh interpreter each, median of
   ``--import-repeats``) of ``cpp_dem``, of ``femcoupling`` (which defers dolfinx too) and of
   the FEM stack (``femcoupling._dolfinx.load()``), which DEM-only runs do not pay.

Output: one JSON line per measurement on stdout (``kind`` = build | block | ratio |
instructions | import_time | dem_only), progress and closing Markdown tables on stderr.

Timing runs on ``--threads`` OpenMP threads (default 1) so that other jobs on a shared
machine disturb it as little as possible; CPU time of the measured process is the primary
figure, wall time and the CPU other processes used during each block (``other_load_cores``,
from /proc/stat) are reported with it.

Usage (repository root, project venv; ``bash scripts/setup.sh`` first):
    .venv/bin/python bench/lean_build.py                     # N = 2000, 10000; ~4 min
    .venv/bin/python bench/lean_build.py --quick --no-callgrind   # N = 2000, 2 rounds; ~30 s
    .venv/bin/python bench/lean_build.py --sizes 10000 --rounds 8 --out runs.jsonl
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import sysconfig  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from _machine import busy_cpu_seconds, own_cpu_seconds  # noqa: E402  (bench/ is on sys.path)
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

ROOT = Path(__file__).resolve().parents[1]
PKG_SRC = ROOT / "cpp_dem" / "cpp_dem"
DEFAULT_BUILD = ROOT / "build" / "lean"
DEFAULT_CACHE = ROOT / "results" / "bench_cache"
#: FEM modules that a DEM-only run must not import (the brief), and more for information.
FEM_MODULES = ("dolfinx", "petsc4py", "ufl")
FEM_MODULES_INFO = ("basix", "ffcx", "gmsh", "mpi4py")
DEM_ONLY_CASE = ["cases/prs_element.py", "--smoke", "--stresses", "20e3,20e3,40e3"]
GRAVITY_M_S2 = 9.81


def log(msg: str) -> None:
    print(f"[lean_build] {msg}", file=sys.stderr, flush=True)


def emit(record: dict, out: Path | None) -> None:
    line = json.dumps(record, sort_keys=False)
    print(line, flush=True)
    if out is not None:
        with open(out, "a", encoding="utf-8") as fh:
            fh.write(line + "\n")


def fem_modules_loaded() -> dict:
    """Top-level FEM packages present in sys.modules (required ones and informative ones)."""
    tops = {name.split(".")[0] for name in list(sys.modules)}
    return {"fem_modules": sorted(m for m in FEM_MODULES if m in tops),
            "fem_related_modules": sorted(m for m in FEM_MODULES_INFO if m in tops)}


# ---- worker: one timed block in a fresh process -----------------------------------------------

def use_overlay(overlay: Path) -> None:
    """Makes `import cpp_dem` load the overlay package (lean `_core`): drops the editable
    install's redirecting finder (which would serve the full build) and puts the overlay
    first on sys.path."""
    sys.meta_path[:] = [f for f in sys.meta_path
                        if type(f).__name__ != "ScikitBuildRedirectingFinder"]
    sys.path.insert(0, str(overlay))


def worker(cfg: dict) -> dict:
    if cfg["overlay"]:
        use_overlay(Path(cfg["overlay"]))
    import numpy as np

    import cpp_dem as dem

    core = dem._core
    geogrid = getattr(core, "GEOGRID", None)
    if geogrid is None:
        raise SystemExit(f"{core.__file__}: has no GEOGRID flag; the build is older than the "
                         "CPP_DEM_GEOGRID option: run scripts/setup.sh")
    if geogrid != cfg["expect_geogrid"]:
        raise SystemExit(f"{core.__file__}: GEOGRID={geogrid}, expected {cfg['expect_geogrid']}")
    dem.set_num_threads(cfg["threads"])

    centers, radii = dem.read_packing_csv(cfg["csv"])
    meta = json.loads(Path(cfg["csv"]).with_suffix(".json").read_text())
    lo, hi = np.asarray(meta["box_lo"], float), np.asarray(meta["box_hi"], float)
    density, young = 2600.0, 1e7
    scene = dem.Scene(gravity=(0.0, 0.0, -GRAVITY_M_S2), local_damping=0.2)
    mat = scene.add_material(dem.Material(model="linear", density=density, young=young,
                                          poisson=0.3, friction_angle_deg=30.0))
    scene.add_box(lo, hi, material=mat)
    scene.add_spheres(centers, radii, material=mat)
    scene.verlet_margin = 0.2 * float(radii.mean())
    scene.dt = 0.5 * float(radii.min()) * math.sqrt(density / young)

    scene.run(cfg["warmup"])
    builds0 = scene.collider_stats()["builds"]
    busy0, own0 = busy_cpu_seconds(), own_cpu_seconds()
    c0, w0 = time.process_time(), time.perf_counter()
    scene.run(cfg["steps"])
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    other = max(0.0, busy_cpu_seconds() - busy0 - (own_cpu_seconds() - own0))

    pos = np.ascontiguousarray(scene.positions, dtype=np.float64)
    state = hashlib.sha256(pos.tobytes())
    for arr in (scene.velocities, scene.angular_velocities, scene.orientations,
                scene.wall_forces):
        state.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    return {
        "core": core.__file__,
        "geogrid": bool(geogrid),
        "cpu_s": cpu,
        "wall_s": wall,
        "other_load_cores": other / wall if wall > 0 else 0.0,
        "collider_builds_timed": scene.collider_stats()["builds"] - builds0,
        "active_contacts": scene.num_active_contacts,
        "dt_s": scene.dt,
        "positions_sha256": hashlib.sha256(pos.tobytes()).hexdigest()[:16],
        "state_sha256": state.hexdigest()[:16],
        "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        **fem_modules_loaded(),
    }


def run_worker(cfg: dict, threads: int, prefix: list[str] | None = None) -> dict:
    """Runs one block in a fresh interpreter (under `prefix`, e.g. valgrind, if given)."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS="1")
    if prefix:
        # A fixed hash seed makes the interpreter's own work repeatable: whole-process counts
        # then vary by ~1e4 instructions between identical runs instead of ~3e5.
        env["PYTHONHASHSEED"] = "0"
    proc = subprocess.run([*(prefix or []), sys.executable, str(Path(__file__).resolve()),
                           "--worker", json.dumps(cfg)], cwd=ROOT, env=env, capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise SystemExit(f"worker failed ({cfg['variant']}):\n{proc.stderr}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if prefix:
        hits = re.findall(r"Collected\s*:\s*(\d+)", proc.stderr)
        if not hits:
            raise SystemExit(f"no instruction count in the valgrind output:\n{proc.stderr}")
        out["instructions"] = int(hits[-1])
    return out


def count_instructions(n: int, csv: Path, args, overlay: Path, out: Path | None) -> dict:
    """Instructions executed per step by each build (callgrind, exact and independent of the
    machine's load): whole-process counts of two runs that differ only in the number of timed
    steps; their difference / the step difference is the count of those steps alone."""
    lo = 20
    hi = lo + (args.callgrind_steps or max(20, math.ceil(4e5 / n)))
    valgrind = [shutil.which("valgrind"), "--tool=callgrind", "--callgrind-out-file=/dev/null"]
    counts: dict[str, dict[int, dict]] = {"full": {}, "lean": {}}
    for variant in ("full", "lean"):
        for steps in (lo, hi):
            cfg = {"variant": variant, "csv": str(csv), "steps": steps, "warmup": args.warmup,
                   "threads": 1, "expect_geogrid": variant == "full",
                   "overlay": str(overlay) if variant == "lean" else ""}
            counts[variant][steps] = run_worker(cfg, 1, prefix=valgrind)
            log(f"N={n} callgrind {variant:4s} {steps:4d} steps: "
                f"{counts[variant][steps]['instructions']:,} instructions")
    per_step = {v: (c[hi]["instructions"] - c[lo]["instructions"]) / (hi - lo)
                for v, c in counts.items()}
    rec = {
        "kind": "instructions", "n_particles": n, "tool": "valgrind --tool=callgrind",
        "warmup_steps": args.warmup, "steps_counted": hi - lo, "threads": 1,
        "full_instructions_per_step": per_step["full"],
        "lean_instructions_per_step": per_step["lean"],
        "ratio_full_over_lean": per_step["full"] / per_step["lean"],
        "full_instructions_total": [counts["full"][s]["instructions"] for s in (lo, hi)],
        "lean_instructions_total": [counts["lean"][s]["instructions"] for s in (lo, hi)],
        "bitwise_equal_positions": all(
            counts["full"][s]["positions_sha256"] == counts["lean"][s]["positions_sha256"]
            for s in (lo, hi)),
    }
    emit(rec, out)
    return rec


# ---- the lean build -----------------------------------------------------------------------------

def full_build_cache() -> dict:
    """CMake cache entries of the installed (scikit-build-core) build, if it is on disk."""
    entries: dict = {}
    for cache in sorted((ROOT / "build").glob("cp*/CMakeCache.txt")):
        for line in cache.read_text(errors="replace").splitlines():
            if ":" in line and "=" in line and not line.startswith(("//", "#")):
                key, val = line.split("=", 1)
                entries[key.split(":")[0]] = val
        entries["_dir"] = str(cache.parent)
        break
    return entries


def build_lean(build_dir: Path, jobs: int) -> dict:
    """Configures (once) and builds the lean `_core`; returns where it is and what it cost."""
    full = full_build_cache()
    cmake = shutil.which("cmake")
    if cmake is None:
        raise SystemExit("cmake not found (scripts/setup.sh installs it)")
    pybind11_dir = subprocess.run([sys.executable, "-m", "pybind11", "--cmakedir"],
                                  capture_output=True, text=True, check=True).stdout.strip()
    t0, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    configured = False
    if not (build_dir / "CMakeCache.txt").exists():
        args = [cmake, "-S", str(ROOT), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
                "-DCPP_DEM_GEOGRID=OFF", f"-Dpybind11_DIR={pybind11_dir}",
                f"-DPython_EXECUTABLE={sys.executable}", "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"]
        # The same compiler and generator as the installed full build, when known.
        if full.get("CMAKE_CXX_COMPILER"):
            args.append(f"-DCMAKE_CXX_COMPILER={full['CMAKE_CXX_COMPILER']}")
        if shutil.which("ninja"):
            args += ["-G", "Ninja"]
        log("configuring the lean build: " + " ".join(args[1:]))
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
        configured = True
    ext = sysconfig.get_config_var("EXT_SUFFIX")
    so = build_dir / f"_core{ext}"
    before = so.stat().st_mtime_ns if so.exists() else None
    log(f"building the lean _core in {build_dir} (-j{jobs}; no-op when up to date)")
    proc = subprocess.run([cmake, "--build", str(build_dir), "--target", "_core", "-j",
                           str(jobs)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"lean build failed:\n{proc.stdout}\n{proc.stderr}")
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    rebuilt = before is None or so.stat().st_mtime_ns != before
    # The overlay package: the Python sources of cpp_dem (links) + the lean _core.
    overlay = build_dir / "overlay" / "cpp_dem"
    if overlay.exists():
        shutil.rmtree(overlay)
    overlay.mkdir(parents=True)
    for src in PKG_SRC.glob("*.py"):
        (overlay / src.name).symlink_to(src)
    (overlay / so.name).symlink_to(so)
    lean = {}
    for line in (build_dir / "CMakeCache.txt").read_text(errors="replace").splitlines():
        if line.startswith(("CMAKE_CXX_COMPILER:", "CMAKE_CXX_FLAGS_RELEASE:",
                            "CMAKE_BUILD_TYPE:", "CPP_DEM_GEOGRID:")):
            key, val = line.split("=", 1)
            lean[key.split(":")[0]] = val
    return {
        "kind": "build", "variant": "lean", "build_dir": str(build_dir), "module": str(so),
        "configured_now": configured, "rebuilt": rebuilt,
        "build_wall_s": round(time.perf_counter() - t0, 2),
        "build_cpu_s": round((r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime), 2),
        "jobs": jobs, "overlay": str(overlay.parent),
        "lean_cmake": lean,
        "full_cmake": {k: full.get(k) for k in ("CMAKE_CXX_COMPILER", "CMAKE_CXX_FLAGS_RELEASE",
                                                 "CMAKE_BUILD_TYPE", "_dir")},
        "same_flags": all(lean.get(k) == full.get(k) for k in
                          ("CMAKE_CXX_COMPILER", "CMAKE_CXX_FLAGS_RELEASE", "CMAKE_BUILD_TYPE")),
    }


# ---- import checks ------------------------------------------------------------------------------

_IMPORT_SNIPPET = """
import json, sys, time
c0, w0 = time.process_time(), time.perf_counter()
{statement}
c1, w1 = time.process_time(), time.perf_counter()
tops = {{m.split('.')[0] for m in sys.modules}}
print(json.dumps({{"cpu_s": c1 - c0, "wall_s": w1 - w0,
                  "fem_modules": sorted(m for m in {fem} if m in tops),
                  "fem_related_modules": sorted(m for m in {info} if m in tops)}}))
"""

_CASE_SNIPPET = """
import json, runpy, sys, time
sys.argv = {argv}
c0, w0 = time.process_time(), time.perf_counter()
status = 0
try:
    runpy.run_path(sys.argv[0], run_name="__main__")
except SystemExit as e:
    status = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
c1, w1 = time.process_time(), time.perf_counter()
tops = {{m.split('.')[0] for m in sys.modules}}
print(json.dumps({{"status": status, "cpu_s": c1 - c0, "wall_s": w1 - w0,
                  "fem_modules": sorted(m for m in {fem} if m in tops),
                  "fem_related_modules": sorted(m for m in {info} if m in tops)}}))
"""


def _py(snippet: str, threads: int) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, "-c", snippet], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"subprocess failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


#: What the import timings run (label -> statement), each in a fresh interpreter. The FEM
#: stack is loaded the way femcoupling does it (dolfinx_solver must come before dolfinx).
IMPORTS = {
    "import numpy": "import numpy",  # the baseline: cpp_dem and femcoupling import it
    "import cpp_dem": "import cpp_dem",
    "import femcoupling": "import femcoupling",
    "FEM stack (femcoupling._dolfinx.load())": "import femcoupling._dolfinx as f; f.load()",
}


def import_time(label: str, repeats: int, threads: int) -> dict:
    snippet = _IMPORT_SNIPPET.format(statement=IMPORTS[label], fem=FEM_MODULES,
                                     info=FEM_MODULES_INFO)
    runs = [_py(snippet, threads) for _ in range(repeats)]
    return {
        "kind": "import_time", "what": label, "repeats": repeats,
        "cpu_s_median": statistics.median(r["cpu_s"] for r in runs),
        "wall_s_median": statistics.median(r["wall_s"] for r in runs),
        "cpu_s_all": [round(r["cpu_s"], 4) for r in runs],
        "fem_modules": runs[0]["fem_modules"],
        "fem_related_modules": runs[0]["fem_related_modules"],
    }


def dem_only_case(case: list[str], threads: int) -> dict:
    out = Path(tempfile.mkdtemp(prefix="lean_build_case_"))
    argv = [str(ROOT / case[0]), *case[1:], "--out", str(out)]
    r = _py(_CASE_SNIPPET.format(argv=repr(argv), fem=FEM_MODULES, info=FEM_MODULES_INFO),
            threads)
    shutil.rmtree(out, ignore_errors=True)
    return {"kind": "dem_only", "command": " ".join(case), **r,
            "imports_dolfinx": bool(r["fem_modules"])}


# ---- the A/B comparison -------------------------------------------------------------------------

def default_steps(n: int) -> int:
    """About 6e6 particle-steps per block (2-3 s of one core at the measured 2-3e6 p-steps/s)."""
    return max(50, math.ceil(6e6 / n))


def compare(n: int, csv: Path, args, overlay: Path, out: Path | None) -> dict:
    steps = args.steps or (max(50, default_steps(n) // 3) if args.quick else default_steps(n))
    warmup = args.warmup
    blocks: dict[str, list[dict]] = {"full": [], "lean": []}
    for k in range(args.rounds):
        # The builds alternate block by block, and the first of each round alternates too
        # (full lean | lean full | ...): a drift of the machine's load or an effect of running
        # first or second in a round cancels in the ratios.
        for variant in (("full", "lean") if k % 2 == 0 else ("lean", "full")):
            if args.wait_idle > 0:
                wait_idle(args.wait_idle)
            cfg = {"variant": variant, "csv": str(csv), "steps": steps, "warmup": warmup,
                   "threads": args.threads, "expect_geogrid": variant == "full",
                   "overlay": str(overlay) if variant == "lean" else ""}
            r = run_worker(cfg, args.threads)
            rec = {"kind": "block", "n_particles": n, "variant": variant, "round": k,
                   "steps": steps, "warmup_steps": warmup, "threads": args.threads,
                   "cpu_us_per_step": 1e6 * r["cpu_s"] / steps,
                   "wall_us_per_step": 1e6 * r["wall_s"] / steps, **r}
            blocks[variant].append(rec)
            emit(rec, out)
            log(f"N={n} round {k} {variant:4s}: {rec['cpu_us_per_step']:9.1f} us/step CPU, "
                f"{rec['wall_us_per_step']:9.1f} wall, other load "
                f"{rec['other_load_cores']:.2f} cores, positions {rec['positions_sha256']}")
    cpu = {v: [b["cpu_us_per_step"] for b in bl] for v, bl in blocks.items()}
    ratios = [f / lean for f, lean in zip(cpu["full"], cpu["lean"])]
    pos_hashes = {b["positions_sha256"] for bl in blocks.values() for b in bl}
    state_hashes = {b["state_sha256"] for bl in blocks.values() for b in bl}

    def cv(v):
        return statistics.stdev(v) / statistics.fmean(v) if len(v) > 1 else float("nan")

    rec = {
        "kind": "ratio", "n_particles": n, "rounds": args.rounds, "steps": steps,
        "warmup_steps": warmup, "threads": args.threads,
        "full_cpu_us_per_step_median": statistics.median(cpu["full"]),
        "lean_cpu_us_per_step_median": statistics.median(cpu["lean"]),
        "full_cpu_cv": cv(cpu["full"]), "lean_cpu_cv": cv(cpu["lean"]),
        "ratio_full_over_lean_median": statistics.median(ratios),
        "ratio_min": min(ratios), "ratio_max": max(ratios),
        "ratio_stdev": statistics.stdev(ratios) if len(ratios) > 1 else float("nan"),
        "ratios": [round(r, 4) for r in ratios],
        "ratio_of_medians": statistics.median(cpu["full"]) / statistics.median(cpu["lean"]),
        "full_wall_us_per_step_median": statistics.median(b["wall_us_per_step"]
                                                          for b in blocks["full"]),
        "lean_wall_us_per_step_median": statistics.median(b["wall_us_per_step"]
                                                          for b in blocks["lean"]),
        "max_other_load_cores": max(b["other_load_cores"] for bl in blocks.values() for b in bl),
        "bitwise_equal_positions": len(pos_hashes) == 1,
        "bitwise_equal_state": len(state_hashes) == 1,
        "positions_sha256": sorted(pos_hashes),
        "active_contacts": blocks["full"][0]["active_contacts"],
        "collider_builds_timed": blocks["full"][0]["collider_builds_timed"],
        "fem_modules_in_blocks": sorted({m for bl in blocks.values() for b in bl
                                         for m in b["fem_modules"]}),
    }
    emit(rec, out)
    return rec


def wait_idle(max_wait_s: float, threshold: float = 0.1) -> float:
    """Waits until other processes use < threshold cores (or max_wait_s); returns their load."""
    t0 = time.perf_counter()
    while True:
        b0, o0 = busy_cpu_seconds(), own_cpu_seconds()
        time.sleep(1.0)
        load = max(0.0, (busy_cpu_seconds() - b0) - (own_cpu_seconds() - o0))
        if load < threshold or time.perf_counter() - t0 > max_wait_s:
            return load


# ---- tables -------------------------------------------------------------------------------------

def print_tables(ratios: list[dict], counted: list[dict], imports: list[dict],
                 cases: list[dict]) -> None:
    p = lambda *a: print(*a, file=sys.stderr)  # noqa: E731
    if ratios:
        p("\n| N | steps x rounds | full CPU µs/step | lean CPU µs/step | full/lean (median) "
          "| min–max | stdev | bitwise equal | max other load |")
        p("|---|---|---|---|---|---|---|---|---|")
        for r in ratios:
            p(f"| {r['n_particles']} | {r['steps']} x {r['rounds']} "
              f"| {r['full_cpu_us_per_step_median']:.1f} | {r['lean_cpu_us_per_step_median']:.1f} "
              f"| {r['ratio_full_over_lean_median']:.4f} "
              f"| {r['ratio_min']:.4f}–{r['ratio_max']:.4f} | {r['ratio_stdev']:.4f} "
              f"| {'yes' if r['bitwise_equal_positions'] and r['bitwise_equal_state'] else 'NO'} "
              f"| {r['max_other_load_cores']:.2f} cores |")
    if counted:
        p("\n| N | steps counted | full instructions/step | lean instructions/step | full/lean |")
        p("|---|---|---|---|---|")
        for r in counted:
            p(f"| {r['n_particles']} | {r['steps_counted']} "
              f"| {r['full_instructions_per_step']:,.0f} | {r['lean_instructions_per_step']:,.0f} "
              f"| {r['ratio_full_over_lean']:.5f} |")
    if imports or cases:
        p("\n| what | CPU s | wall s | dolfinx/petsc4py/ufl imported | other FEM-side modules |")
        p("|---|---|---|---|---|")
        for r in imports:
            p(f"| `{r['what']}` (median of {r['repeats']}) | {r['cpu_s_median']:.3f} "
              f"| {r['wall_s_median']:.3f} | {', '.join(r['fem_modules']) or 'none'} "
              f"| {', '.join(r['fem_related_modules']) or 'none'} |")
        for r in cases:
            p(f"| `{r['command']}` (exit {r['status']}) | {r['cpu_s']:.1f} | {r['wall_s']:.1f} "
              f"| {', '.join(r['fem_modules']) or 'none'} "
              f"| {', '.join(r['fem_related_modules']) or 'none'} |")


# ---- main ---------------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    ap = _cli.BenchParser(out="append",
        description="Full vs lean (-DCPP_DEM_GEOGRID=OFF) build on the same sphere-only scene, "
                    "and a check that DEM-only runs never import dolfinx. One JSON line per "
                    "measurement on stdout, Markdown tables on stderr.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Times are CPU time of the measured process (time.process_time) unless named "
               "wall; per step = the block's time / --steps. The ratio full/lean is taken per "
               "round (one full and one lean block); its min-max over the rounds is the "
               "noise.")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, metavar="N",
                    help="numbers of spheres of the packings (default 2000 10000; --quick: 2000)")
    ap.add_argument("--rounds", type=int, default=None,
                    help="A/B rounds; each runs one full and one lean block, the full one "
                         "first in even rounds, second in odd ones (default 6; --quick: 2)")
    ap.add_argument("--steps", type=int, default=0,
                    help="timed steps per block (default ceil(6e6 / N): 3000 at N=2000, 600 at "
                         "N=10000; --quick: a third)")
    ap.add_argument("--warmup", type=int, default=100,
                    help="untimed steps before the timed ones in each block (default 100)")
    ap.add_argument("--threads", type=int, default=1,
                    help="OpenMP threads of the timed runs (default 1)")
    ap.add_argument("--seed", type=int, default=1, help="packing seed (default 1)")
    ap.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE,
                    help="where bench/throughput.py keeps (and, if missing, generates) the "
                         f"packings (default {DEFAULT_CACHE.relative_to(ROOT)})")
    ap.add_argument("--build-dir", type=Path, default=DEFAULT_BUILD,
                    help=f"lean build directory (default {DEFAULT_BUILD.relative_to(ROOT)})")
    ap.add_argument("--jobs", type=int, default=2, help="compile jobs of the lean build "
                    "(default 2)")
    ap.add_argument("--wait-idle", type=float, default=0.0, metavar="SECONDS",
                    help="before each block wait up to SECONDS until other processes use < 0.1 "
                         "core (default 0: do not wait)")
    ap.add_argument("--import-repeats", type=int, default=5,
                    help="fresh interpreters timing each of `import cpp_dem`, `import "
                         "femcoupling` and the FEM stack; the median counts (default 5)")
    ap.add_argument("--no-callgrind", action="store_true",
                    help="skip the instruction counts (valgrind --tool=callgrind, 1 thread; "
                         "about 1 min per N)")
    ap.add_argument("--callgrind-steps", type=int, default=0,
                    help="steps whose instructions are counted (default max(20, ceil(4e5 / N)):"
                         " 200 at N=2000, 40 at N=10000)")
    ap.add_argument("--no-ab", action="store_true",
                    help="skip the lean build and the full/lean comparison")
    ap.add_argument("--no-dem-only", action="store_true",
                    help="skip the DEM-only case and the import timings")
    ap.add_argument("--quick", action="store_true", help="N = 2000, 2 rounds, 1/3 of the steps")
    ap.add_argument("--out", type=Path, default=None, help="also append the JSON lines to FILE")
    ap.add_argument("--worker", type=str, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker is not None:
        print(json.dumps(worker(json.loads(args.worker))))
        return 0

    sizes = args.sizes or ([2000] if args.quick else [2000, 10000])
    args.rounds = args.rounds or (2 if args.quick else 6)
    if args.rounds < 1 or args.threads < 1 or args.jobs < 1 or args.warmup < 0:
        ap.error("--rounds, --threads, --jobs must be >= 1 and --warmup >= 0")
    sys.path.insert(0, str(ROOT / "bench"))
    import throughput  # noqa: E402  (packing generation and cache, provenance)

    # git commit, C++ source hash, and whether the installed (full) build matches the sources
    prov = throughput.provenance()
    if prov.get("build_matches_sources") is False:
        log("warning: the installed full build does not match the C++ sources: run "
            "scripts/setup.sh first")
    ratios, counted, imports, cases = [], [], [], []
    use_callgrind = not args.no_callgrind and shutil.which("valgrind") is not None
    if not args.no_callgrind and not use_callgrind:
        log("valgrind not found: no instruction counts")

    if not args.no_ab:
        build = build_lean(args.build_dir.resolve(), args.jobs)
        emit({**build, **prov}, args.out)
        if not build["same_flags"]:
            log("warning: the lean and full builds differ in compiler or flags: "
                f"{build['lean_cmake']} vs {build['full_cmake']}")
        for n in sizes:
            packing = throughput.get_packing(n, args.seed, args.cache_dir,
                                             throughput.BenchScene())
            ratios.append(compare(n, packing.csv, args, Path(build["overlay"]), args.out))
            if use_callgrind:
                counted.append(count_instructions(n, packing.csv, args, Path(build["overlay"]),
                                                  args.out))

    if not args.no_dem_only:
        log("timing imports in fresh interpreters: " + ", ".join(IMPORTS))
        for label in IMPORTS:
            imports.append(import_time(label, args.import_repeats, args.threads))
            emit(imports[-1], args.out)
        log("running the DEM-only case: " + " ".join(DEM_ONLY_CASE))
        cases.append(dem_only_case(DEM_ONLY_CASE, args.threads))
        emit(cases[-1], args.out)

    print_tables(ratios, counted, imports, cases)
    bad = [r for r in ratios if not (r["bitwise_equal_positions"] and r["bitwise_equal_state"])]
    bad += [r for r in counted if not r["bitwise_equal_positions"]]
    bad += [r for r in cases if r["imports_dolfinx"] or r["status"] != 0]
    bad += [r for r in imports if not r["what"].startswith("FEM") and r["fem_modules"]]
    if bad:
        log(f"{len(bad)} check(s) failed (results differ between builds, or dolfinx imported)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
