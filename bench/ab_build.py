#!/usr/bin/env python3
"""A/B of two builds of the DEM core on the same scenes, in one run (issue 14: "no slower").

The *new* build is the installed one (the working tree, after ``make setup``), or with
``--new-ref`` one built from that revision like the old; the *old* one
is built here from a git revision (``--ref``, default ``HEAD``) into ``build/ab/<sha>/``
(CMake, Release, the same compiler as the installed build; cached), with an overlay package
made of that revision's own Python sources and its ``_core``, so each build runs with the
Python layer it was written for.

Scenes (SI units; the same input for both builds):
- ``spheres``: the benchmark packing of bench/throughput.py (N spheres, linear law with
  friction, six walls, local damping 0.2, fixed dt = 0.5 x the p-wave step);
- ``general``: the same packing with viscous damping and rolling resistance on every contact
  (the composed law, not the short kernel);
- ``hertz``: the same packing with Hertz–Mindlin grains;
- ``geogrid``: a square geogrid (cohesive beams, grain–cylinder and grain–PFacet contacts)
  between two layers of grains (bench/geogrid_cost.py's scene, small);
- ``clumps``: the same packing with each sphere replaced by a clump of three members inside
  its ball (bench/clump_cost.py's template, random seeded orientations), settling under
  gravity (N clumps, 3 N spheres);
- ``bonds``: the ``spheres`` packing with every pair closer than 0.2 of the smaller radius
  bonded (contact and parallel bonds, unbreakable; dt at most 0.5 x the critical step);
- ``pullout``: the geogrid pull-out of ``cases/pullout_000.py --smoke`` (N is ignored: 375
  grains and a flat-ribbed biaxial grid of PFacets), prepared untimed (REFD, gravity, top servo)
  and timed while the clamp pulls the grid;
- ``membrane``: the cylindrical triaxial specimen of ``triaxial --specimen cylinder`` (N
  grains of its sieve curve, the seed 1, a membrane of PFacets under the cell pressure),
  prepared untimed (``cylinder_triaxial.prepare``, the hold's steps capped at 20 000) and
  timed while the lid moves down at 0.1 /s;
- ``meshbox``: ``bench/mesh_wall_cost.py``'s scene, N grains at rest under gravity in a box
  whose six faces are one mesh wall of 10 092 triangles (settled once, by the first block's
  build, and kept in results/bench_cache: both builds start from that state).

Each *block* is a fresh subprocess that builds the scene, runs ``--warmup`` untimed steps and
times ``--steps`` steps (CPU time of that process). Blocks alternate old | new, new | old, ...
round by round, so a drift of the machine's load cancels in the ratios. Every block hashes
the final state (positions, velocities, spins, orientations, wall forces, a mesh wall's force
and moment): the closing table
says whether the two builds gave bitwise equal results, and if not the largest position
difference (m) beside the chaos floor: the same largest difference between the old build's
run and that run again with its first body moved by one ulp in x (one more block, not
timed; ``floor_max_position_diff_m`` in the JSON line). A change of the arithmetic made on
purpose is within the floor when the two are of one size.

The ratio reported is new/old in particle-steps per second (> 1: the new build is faster),
median over the rounds, with its spread, and the ratio of each build's fastest block
(``ratio_fastest``): a disturbance of the host only ever slows a block, so on a noisy host
the fastest blocks are the least disturbed, and this ratio holds where the rounds' ratios
scatter (it needs one undisturbed block of each build).

On a loaded machine timings drift by several per cent; ``--instructions`` counts instead the
instructions each build executes per step under ``valgrind --tool=callgrind`` (1 thread; two
runs per build that differ only in the number of timed steps, whose difference is the cost of
those steps alone): exact and repeatable whatever else runs, though not a time.

    .venv/bin/python bench/ab_build.py --ref 1f3da9b                    # the issue's set
    .venv/bin/python bench/ab_build.py --ref HEAD --scenes spheres:1000 --rounds 2
    .venv/bin/python bench/ab_build.py --ref 1f3da9b --instructions
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import sysconfig  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
DEFAULT_SCENES = ("spheres:1000", "spheres:10000", "general:1000", "hertz:1000", "geogrid:2000",
                  "pullout:0")


def log(msg: str) -> None:
    print(f"[ab] {msg}", file=sys.stderr, flush=True)


# ---- the old build ------------------------------------------------------------------------------

def installed_cmake_cache() -> dict:
    entries: dict = {}
    for cache in sorted((ROOT / "build").glob("cp*/CMakeCache.txt")):
        for line in cache.read_text(errors="replace").splitlines():
            if ":" in line and "=" in line and not line.startswith(("//", "#")):
                key, val = line.split("=", 1)
                entries[key.split(":")[0]] = val
        break
    return entries


def build_ref(ref: str, jobs: int) -> Path:
    """Builds `_core` of revision `ref`; returns the overlay directory to put on sys.path."""
    sha = subprocess.run(["git", "rev-parse", "--short=10", ref], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout.strip()
    base = ROOT / "build" / "ab" / sha
    src, bld, overlay = base / "src", base / "build", base / "overlay"
    if not (src / "CMakeLists.txt").exists():
        src.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", sha], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    if not (bld / "CMakeCache.txt").exists():
        pybind11_dir = subprocess.run([sys.executable, "-m", "pybind11", "--cmakedir"],
                                      capture_output=True, text=True, check=True).stdout.strip()
        args = ["cmake", "-S", str(src), "-B", str(bld), "-DCMAKE_BUILD_TYPE=Release",
                f"-Dpybind11_DIR={pybind11_dir}", f"-DPython_EXECUTABLE={sys.executable}"]
        compiler = installed_cmake_cache().get("CMAKE_CXX_COMPILER")
        if compiler:
            args.append(f"-DCMAKE_CXX_COMPILER={compiler}")
        if shutil.which("ninja"):
            args += ["-G", "Ninja"]
        log(f"configuring the old build ({sha})")
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    log(f"building the old _core ({sha}, -j{jobs}; no-op when up to date)")
    proc = subprocess.run(["cmake", "--build", str(bld), "--target", "_core", "-j", str(jobs)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"old build failed:\n{proc.stdout}\n{proc.stderr}")
    so = bld / f"_core{sysconfig.get_config_var('EXT_SUFFIX')}"
    pkg = overlay / "cpp_dem"
    if pkg.exists():
        shutil.rmtree(pkg)
    shutil.copytree(src / "cpp_dem" / "cpp_dem", pkg, symlinks=True)
    (pkg / so.name).symlink_to(so)
    # the revision's other packages (the cases import them), where it has them
    for other in ("geogrid_dem", "femcoupling"):
        if (overlay / other).exists():
            shutil.rmtree(overlay / other)
        if (src / other).is_dir():
            shutil.copytree(src / other, overlay / other, symlinks=True)
    return overlay


def use_overlay(overlay: Path) -> None:
    """`import cpp_dem` then loads the overlay package, not the editable install."""
    sys.meta_path[:] = [f for f in sys.meta_path
                        if type(f).__name__ != "ScikitBuildRedirectingFinder"]
    sys.path.insert(0, str(overlay))


# ---- one block -----------------------------------------------------------------------------------

def make_scene(kind: str, n: int):
    import numpy as np

    import cpp_dem as dem

    if kind == "geogrid":
        sys.path.insert(0, str(BENCH))
        from geogrid_cost import build

        scene, _ = build(n, 15, True)
        scene.dt = 0.5 * scene.critical_dt()
        return scene
    sys.path.insert(0, str(BENCH))
    from throughput import BenchScene, DEFAULT_CACHE, bench_dt, get_packing

    cfg = BenchScene()
    p = get_packing(n, 1, DEFAULT_CACHE, cfg)
    scene = dem.Scene(gravity=cfg.gravity, local_damping=cfg.local_damping)
    if kind == "hertz":
        mat = dem.hertz_mindlin_material(density=cfg.density, shear_modulus=4e6, poisson=0.25,
                                         friction_coefficient=0.5)
    else:
        parts = ({"damping_normal": 0.2, "damping_shear": 0.1, "rolling_stiffness": 0.5,
                  "rolling_friction": 0.1} if kind == "general" else {})
        mat = dem.linear_material(density=cfg.density, young=cfg.young, poisson=cfg.poisson,
                                  friction_angle_deg=cfg.friction_angle_deg, **parts)
    m = scene.add_material(mat)
    scene.add_box(p.lo, p.hi, material=m)
    if kind == "clumps":
        # Each sphere of the packing replaced by a three-member clump (bench/clump_cost.py's
        # template) inside its ball, random seeded orientations; they settle under gravity.
        from clump_cost import template

        try:  # the layout of the revision under test
            from cpp_dem.build.clumps import random_orientations
        except ImportError:  # revisions before the build/protocols/... layout
            from cpp_dem.clumps import random_orientations

        tpl = template()
        scene.add_clumps(tpl, p.centers, random_orientations(len(p.radii), 1), material=m,
                         scale=np.asarray(p.radii) / tpl.bounding_radius)
    else:
        ids = scene.add_spheres(p.centers, p.radii, material=m)
    if kind == "bonds":
        # Every pair of the packing closer than 0.2 of the smaller radius, bonded (contact
        # and parallel bonds, unbreakable): the bond pass's load, beside the pair pass's.
        x, r = np.asarray(p.centers), np.asarray(p.radii)
        bp = dem.BondParams(kn=1e5, ks=1e5, friction=0.5, contact_bond=True, pb_kn=1e10,
                            pb_ks=1e10)
        for i in range(len(r)):
            gap = np.linalg.norm(x[i + 1:] - x[i], axis=1) - r[i + 1:] - r[i]
            for j in np.nonzero(gap < 0.2 * np.minimum(r[i + 1:], r[i]))[0]:
                scene.add_bond(int(ids[i]), int(ids[i + 1 + j]), bp)
    scene.verlet_margin = cfg.margin_factor * float(np.mean(p.radii))
    scene.dt = bench_dt(p, cfg)
    if kind == "bonds":
        scene.dt = min(scene.dt, 0.5 * scene.critical_dt())
    return scene


def pullout_scene(root: Path = ROOT):
    """The smoke pull-out of `root`/cases/pullout_000.py (each build runs its own revision's
    case), prepared; returns (scene, pull)."""
    import importlib.util

    try:  # the layout of the revision under test
        from cpp_dem.protocols import pullout
    except ImportError:  # revisions before the build/protocols/... layout
        from cpp_dem import pullout

    spec = importlib.util.spec_from_file_location("pullout_000", root / "cases" / "pullout_000.py")
    case = importlib.util.module_from_spec(spec)
    sys.modules["pullout_000"] = case  # (its dataclasses look their module up)
    sys.path.insert(0, str(root / "cases"))
    spec.loader.exec_module(case)
    p, _, _ = case.parse_args(["--smoke"])
    sample = case.build(p)
    pullout.prepare(sample, stress=p.pressure, porosity=p.porosity, node_density_scale="auto")

    def pull(steps: int) -> None:
        pullout.pull(sample, velocity=p.velocity, distance=p.velocity * sample.scene.dt * steps,
                     record_every=50)
    return sample.scene, pull


def membrane_scene(n: int, max_steps: int = 20_000):
    """The cylindrical specimen of the triaxial case (the overlay's revision, or the working
    tree's), ``n`` grains, held in its membrane (at most ``max_steps`` steps a stage of the
    preparation); returns (scene, advance) with the lid moving down at 0.1 /s."""
    from cpp_dem.protocols import cylinder_triaxial as cyl
    from geogrid_dem.cases import triaxial as case
    from geogrid_dem.cases import triaxial_cylinder as tc

    import cpp_dem as dem

    p = case.Params(n=n, seed=1)
    p.box = case.smoke_box(p)
    r_m, h_m = tc.geometry(p.box)
    rad, _ = tc.radii(p, lambda msg: None)
    mat = dem.linear_material(density=p.density, young=p.young, poisson=p.poisson,
                              friction_angle_deg=p.phi)
    grow = (p.solid_fraction / p.cloud_fraction) ** (1.0 / 3.0)
    spec = cyl.prepare(rad, radius_m=grow * r_m, height_m=grow * h_m,
                       pressure_pa=p.cell_pressure, material=mat, seed=1, damping=p.damping,
                       max_steps=max_steps)
    spec.lid_servo.enabled = False
    spec.scene.set_wall_velocity(spec.lid, [0.0, 0.0, -0.1 * spec.height0_m])
    return spec.scene, spec.scene.run


def meshbox_scene(n: int, cells: int = 29, cache_dir: Path | None = None):
    """bench/mesh_wall_cost.py's scene B: ``n`` grains at rest under gravity in a box whose six
    faces are one mesh wall of 12 cells^2 triangles (10 092). The settled state is computed
    once (by the first block's build) and kept in ``cache_dir`` (default results/bench_cache),
    so both builds start from the same grains, velocities and dt."""
    import numpy as np

    sys.path.insert(0, str(BENCH))
    import mesh_wall_cost as mwc
    from throughput import DEFAULT_CACHE

    cache = Path(cache_dir or DEFAULT_CACHE) / f"meshbox_{n}.npz"
    if not cache.is_file():
        cache.parent.mkdir(parents=True, exist_ok=True)
        lo, hi, x, r, v, dt = mwc.settled(n, 1)
        tmp = cache.with_suffix(".tmp.npz")
        np.savez(tmp, lo=lo, hi=hi, x=x, r=r, v=v, dt=dt)
        tmp.replace(cache)
    z = np.load(cache)
    state = (z["lo"], z["hi"], z["x"], z["r"], z["v"], float(z["dt"]))
    return mwc.scene("mesh", state, cells)


def worker(cfg: dict) -> dict:
    if cfg["overlay"]:
        use_overlay(Path(cfg["overlay"]))
    import numpy as np

    import cpp_dem as dem

    dem.set_num_threads(cfg["threads"])
    if cfg["scene"] == "pullout":
        root = Path(cfg["overlay"]).parent / "src" if cfg["overlay"] else ROOT
        scene, advance = pullout_scene(root)
    elif cfg["scene"] == "membrane":
        scene, advance = membrane_scene(cfg["n"])
    elif cfg["scene"] == "meshbox":
        scene = meshbox_scene(cfg["n"])
        advance = scene.run
    else:
        scene = make_scene(cfg["scene"], cfg["n"])
        advance = scene.run
    if cfg.get("perturb"):
        # (the chaos floor's run: the first body moved by one ulp in x, through
        # Scene.positions, before the warm-up)
        x = np.array(scene.positions, dtype=np.float64)
        x[0, 0] = np.nextafter(x[0, 0], np.inf)
        scene.positions = x
    advance(cfg["warmup"])
    c0, w0 = time.process_time(), time.perf_counter()
    step0 = scene.step_count
    advance(cfg["steps"])
    steps_done = scene.step_count - step0
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in
              (scene.positions, scene.velocities, scene.angular_velocities, scene.orientations,
               scene.wall_forces)]
    for m in range(getattr(scene, "num_mesh_walls", 0)):  # (a mesh wall's force and moment)
        w = scene.mesh_wall(m)
        arrays.append(np.concatenate([w["force"], w["moment"]]).astype(np.float64))
    state = hashlib.sha256()
    for a in arrays:
        state.update(a.tobytes())
    tmp = Path(cfg["dump"])
    np.save(tmp, arrays[0])
    return {"core": dem._core.__file__, "cpu_s": cpu, "wall_s": wall, "steps_done": steps_done,
            "bodies": int(scene.num_bodies), "state_sha256": state.hexdigest()[:16]}


def run_block(cfg: dict, prefix: list[str] | None = None, env_add: dict | None = None) -> dict:
    """One block in a fresh process (``env_add``: more environment variables, such as
    ``CPP_DEM_NARROW``)."""
    env = dict(os.environ, OMP_NUM_THREADS=str(cfg["threads"]), OPENBLAS_NUM_THREADS="1",
               **(env_add or {}))
    if prefix:
        env["PYTHONHASHSEED"] = "0"  # the interpreter's own work repeats exactly
    proc = subprocess.run([*(prefix or []), sys.executable, str(Path(__file__).resolve()),
                           "--worker", json.dumps(cfg)], cwd=ROOT, env=env, capture_output=True,
                          text=True)
    if proc.returncode != 0:
        raise SystemExit(f"block failed ({cfg['variant']} {cfg['scene']}):\n{proc.stderr}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    if prefix:
        hits = re.findall(r"Collected\s*:\s*(\d+)", proc.stderr)
        if not hits:
            raise SystemExit(f"no instruction count in the valgrind output:\n{proc.stderr}")
        out["instructions"] = int(hits[-1])
    return out


def count_instructions(scene: str, n: int, args, overlays: dict, tmp: Path) -> dict:
    """Instructions per step of each build, 1 thread, from two callgrind runs per build."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        raise SystemExit("--instructions needs valgrind (apt-get install valgrind)")
    prefix = [valgrind, "--tool=callgrind", "--callgrind-out-file=/dev/null"]
    lo = 20
    hi = lo + (args.steps or max(20, math.ceil(4e5 / (n or 500))))  # (pullout: N is 0, 501 bodies)
    per_step = {}
    for variant in ("old", "new"):
        counts, done = {}, {}
        for steps in (lo, hi):
            cfg = {"variant": variant, "scene": scene, "n": n, "threads": 1, "steps": steps,
                   "warmup": 50, "dump": str(tmp / f"cg_{variant}.npy"),
                   "overlay": str(overlays[variant])}
            r = run_block(cfg, prefix)
            counts[steps], done[steps] = r["instructions"], r["steps_done"]
        per_step[variant] = (counts[hi] - counts[lo]) / (done[hi] - done[lo])
        log(f"{scene} N={n} {variant}: {per_step[variant]:.4g} instructions per step")
    rec = {"scene": scene, "n": n, "old_instructions_per_step": per_step["old"],
           "new_instructions_per_step": per_step["new"],
           "ratio_old_over_new": per_step["old"] / per_step["new"]}
    print(json.dumps(rec), flush=True)
    return rec


def speed_ratios(old_s: list[float], new_s: list[float]) -> dict:
    """new/old in speed from the two builds' times per step (s), block by block in round
    order: the median of the rounds' ratios, their range, and the ratio of the fastest blocks
    (module doc)."""
    ratios = [o / nw for o, nw in zip(old_s, new_s)]
    return {"ratio_new_over_old": statistics.median(ratios),
            "ratio_min": min(ratios), "ratio_max": max(ratios),
            "ratio_fastest": min(old_s) / min(new_s)}


def compare(scene: str, n: int, threads: int, args, overlays: dict, tmp: Path) -> dict:
    import numpy as np

    # (the pull-out ignores N: its smoke's 375 grains set its share of --particle-steps)
    steps = args.steps or max(100, math.ceil(args.particle_steps / (n or 375)))
    cpu: dict[str, list[float]] = {"old": [], "new": []}
    hashes: dict[str, set] = {"old": set(), "new": set()}
    dumps = {}
    for k in range(args.rounds):
        for variant in (("old", "new") if k % 2 == 0 else ("new", "old")):
            dump = tmp / f"{scene}_{n}_{threads}_{variant}.npy"
            cfg = {"variant": variant, "scene": scene, "n": n, "threads": threads,
                   "steps": steps, "warmup": args.warmup, "dump": str(dump),
                   "overlay": str(overlays[variant])}
            r = run_block(cfg)
            cpu[variant].append(r["cpu_s"] / r["steps_done"])
            hashes[variant].add(r["state_sha256"])
            dumps[variant] = dump
            log(f"{scene} N={n} threads={threads} round {k} {variant}: "
                f"{1e6 * r['cpu_s'] / steps:9.1f} us/step CPU, state {r['state_sha256']}")
    a, b = np.load(dumps["old"]), np.load(dumps["new"])
    bitwise = hashes["old"] == hashes["new"] and len(hashes["old"]) == 1
    floor = None
    if not bitwise and a.shape == b.shape:
        # Not the same bits: the chaos floor beside it, the old build's run again with one
        # body moved by one ulp (how far a rounding-level change alone takes this run).
        dump = tmp / f"{scene}_{n}_{threads}_floor.npy"
        run_block({"variant": "old", "scene": scene, "n": n, "threads": threads,
                   "steps": steps, "warmup": args.warmup, "dump": str(dump),
                   "overlay": str(overlays["old"]), "perturb": True})
        floor = float(np.max(np.abs(a - np.load(dump))))
    rec = {"scene": scene, "n": n, "bodies": int(len(a)), "threads": threads, "steps": steps,
           "rounds": args.rounds,
           "old_us_per_step": 1e6 * statistics.median(cpu["old"]),
           "new_us_per_step": 1e6 * statistics.median(cpu["new"]),
           **speed_ratios(cpu["old"], cpu["new"]),
           "bitwise_equal": bitwise,
           "max_position_diff_m": float(np.max(np.abs(a - b))) if a.shape == b.shape else None,
           "floor_max_position_diff_m": floor}
    print(json.dumps(rec), flush=True)
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = _cli.BenchParser(description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--ref", default="HEAD", help="git revision of the old build (HEAD)")
    ap.add_argument("--new-ref", default="",
                    help="git revision of the new build, built like the old one (default: the "
                         "installed build of the working tree); for an A/B of one commit "
                         "while the working tree holds other, unfinished changes")
    ap.add_argument("--scenes", nargs="+", default=list(DEFAULT_SCENES),
                    help="KIND:N, KIND one of spheres, general, hertz, geogrid, pullout, "
                         "clumps, bonds, membrane, meshbox")
    ap.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--steps", type=int, default=0, help="timed steps (0: from --particle-steps)")
    ap.add_argument("--particle-steps", type=float, default=4e6,
                    help="particle-steps per block when --steps is 0")
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--jobs", type=int, default=2, help="compile jobs for the old build")
    ap.add_argument("--instructions", action="store_true",
                    help="count instructions per step under callgrind instead of timing")
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(json.loads(args.worker))))
        return 0
    for spec in args.scenes:
        kind, _, n = spec.partition(":")
        if kind not in ("spheres", "general", "hertz", "geogrid", "pullout",
                        "clumps", "bonds", "membrane", "meshbox") or not n.isdigit():
            raise SystemExit(f"--scenes {spec}: must be KIND:N with KIND spheres, general, "
                             "hertz, geogrid, pullout, clumps, bonds, membrane or meshbox and "
                             "N a whole number")
    overlays = {"old": build_ref(args.ref, args.jobs),
                "new": build_ref(args.new_ref, args.jobs) if args.new_ref else ""}
    rows = []
    if args.instructions:
        with tempfile.TemporaryDirectory() as tmp:
            for spec in args.scenes:
                kind, _, n = spec.partition(":")
                rows.append(count_instructions(kind, int(n), args, overlays, Path(tmp)))
        print("\n| scene | N | old instr./step | new instr./step | old/new |", file=sys.stderr)
        print("|---|---|---|---|---|", file=sys.stderr)
        for r in rows:
            print(f"| {r['scene']} | {r['n']} | {r['old_instructions_per_step']:.4g} | "
                  f"{r['new_instructions_per_step']:.4g} | {r['ratio_old_over_new']:.4f} |",
                  file=sys.stderr)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.scenes:
            kind, _, n = spec.partition(":")
            for t in args.threads:
                rows.append(compare(kind, int(n), t, args, overlays, Path(tmp)))
    print("\n| scene | bodies | threads | old us/step | new us/step | new/old p-steps/s (min-max)"
          " | fastest block's | bitwise |", file=sys.stderr)
    print("|---|---|---|---|---|---|---|---|", file=sys.stderr)
    for r in rows:
        bit = "yes" if r["bitwise_equal"] else (
            f"no (max dx {r['max_position_diff_m']:.1e} m; one ulp moved: "
            f"{r['floor_max_position_diff_m']:.1e} m)" if r["floor_max_position_diff_m"] is not None
            else "no (the body counts differ)")
        print(f"| {r['scene']} | {r['bodies']} | {r['threads']} | {r['old_us_per_step']:.1f} | "
              f"{r['new_us_per_step']:.1f} | {r['ratio_new_over_old']:.3f} "
              f"({r['ratio_min']:.3f}-{r['ratio_max']:.3f}) | {r['ratio_fastest']:.3f} | {bit} |",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
