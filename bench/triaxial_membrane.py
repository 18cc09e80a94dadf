"""The cylindrical triaxial test in a membrane beside the cubical one (issue 65 item 4). Not a
test: prints JSON lines and writes one JSON file.

For each seed the same grains (--grains radii uniform in [0.8, 1] x 2 mm, drawn from the
seed), the same linear law (E 50 MPa, k_s/k_n 0.3, friction --friction deg), the same cell
pressure and axial strain rate, in two specimens of the same initial volume and height:
- ``cylinder``: ``cpp_dem.protocols.cylinder_triaxial`` (made in a frictionless mould of
  radius --radius-m, then held by a rubber membrane, 1 MPa and 0.3 mm; frictionless
  platens);
- ``box``: ``cpp_dem.protocols.triaxial`` (six frictionless servo walls, square in plan,
  the mould's cross-section).
Both are sheared to --stop-strain. Each shape's deviator q (Pa, the cylinder's on its
corrected cross-section) and volumetric strain (the cylinder's from the membrane's volume)
are read at the --at axial strains (linear between rows), with the cylinder's measured
membrane correction. Then, over the seeds, the paired difference cylinder - box of each,
with its standard error and Student's t.

    .venv/bin/python bench/triaxial_membrane.py --seeds 1,2,3 --out docs/data/triaxial_membrane.json
    .venv/bin/python bench/triaxial_membrane.py --smoke --out /tmp/tm.json
    .venv/bin/python bench/triaxial_membrane.py --table docs/data/triaxial_membrane.json
"""

from __future__ import annotations

import json
import math
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols import cylinder_triaxial as ct
from cpp_dem.protocols import triaxial as tx

sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)
from geogrid_dem.stats import paired_difference, resolved  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
YOUNG, POISSON, DENSITY = 5e7, 0.3, 2650.0


def _radii(n: int, seed: int) -> np.ndarray:
    return 0.002 * np.random.default_rng(seed).uniform(0.8, 1.0, n)


def _at(rows: list[dict], key: str, strains: list[float], name: str = "axial_strain") -> list:
    e = np.array([r[name] for r in rows])
    v = np.array([r[key] for r in rows])
    return [float(np.interp(s, e, v)) if s <= e[-1] else None for s in strains]


def cylinder(a, seed: int) -> dict:
    mat = dem.linear_material(density=DENSITY, young=YOUNG, poisson=POISSON,
                              friction_angle_deg=a.friction)
    spec = ct.prepare(_radii(a.grains, seed), radius_m=a.radius_m, height_m=a.height_m,
                      pressure_pa=a.pressure, material=mat, seed=seed)
    rows = ct.shear(spec, strain_rate=a.rate, stop_strain=a.stop_strain,
                    record_every=a.record_every)
    solid = float(np.sum(4.0 / 3.0 * np.pi * np.asarray(spec.scene.radii)[
        np.asarray(spec.scene.body_kinds) == 0] ** 3))
    return {"shape": "cylinder", "seed": seed, "prepared": spec.prepared,
            "porosity": 1.0 - solid / spec.volume0_m3,
            "q_pa": _at(rows, "deviatoric_stress_pa", a.at),
            "volumetric_strain": _at(rows, "volumetric_strain", a.at),
            "membrane_correction_pa": _at(rows, "membrane_correction_pa", a.at),
            "grains_outside": max(r["grains_outside"] for r in rows)}


def box(a, seed: int) -> dict:
    side = math.sqrt(math.pi) * a.radius_m  # (the mould's cross-section, square)
    lo, hi = np.zeros(3), np.array([side, side, a.height_m])
    c, r = loose_cloud(_radii(a.grains, seed), lo, hi, seed=seed)
    sample = tx.build_box_sample(c, r, lo, hi, young=YOUNG, poisson=POISSON,
                                 friction_deg=a.friction, density=DENSITY, local_damping=0.3)
    iso = tx.isotropic_stage(sample, a.pressure)
    arrays = tx.deviatoric_stage(sample, a.pressure, a.rate, a.stop_strain,
                                 record_every=a.record_every)
    rows = [dict(zip(arrays, values)) for values in zip(*arrays.values())]
    return {"shape": "box", "seed": seed, "isotropic_reached": bool(iso.converged),
            "porosity": float(iso.porosity),
            "q_pa": _at(rows, "deviatoric_stress", a.at),
            "volumetric_strain": _at(rows, "volumetric_strain", a.at)}


def paired(runs: list[dict], strains: list[float]) -> list[dict]:
    """cylinder - box per seed, at each strain: mean, standard error, t, n."""
    out = []
    seeds = sorted({r["seed"] for r in runs})
    by = {(r["shape"], r["seed"]): r for r in runs}
    for key in ("q_pa", "volumetric_strain"):
        for i, s in enumerate(strains):
            d = [by["cylinder", k][key][i] - by["box", k][key][i] for k in seeds
                 if by["cylinder", k][key][i] is not None and by["box", k][key][i] is not None]
            out.append({"measure": key, "axial_strain": s, **paired_difference(d)})
    return out


def _fmt(x, scale: float, digits: int) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x * scale:.{digits}f}"


def table(data: dict) -> list[str]:
    """The docs' table (docs/studies/triaxial_membrane.md) of a data file: the mean porosity
    of each shape at the start of shearing, then per axial strain,
    each shape's mean q (kPa) and volumetric strain (%) over the seeds, the cylinder's
    membrane correction (kPa), and the paired difference cylinder - box with its standard
    error, t and whether it is resolved at 95 % (|t| > t(0.975, n - 1))."""
    runs, strains = data["runs"], data["params"]["at"]
    head = ["axial strain, %", "measure", "cylinder", "box", "cylinder - box (+- SE)", "t",
            "resolved (95 %)"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    pairs = {(d["measure"], d["axial_strain"]): d for d in data["paired"]}
    for i, e in enumerate(strains):
        for key, name, scale, digits in (("q_pa", "q, kPa", 1e-3, 1),
                                         ("volumetric_strain", "volumetric strain, %", 100, 3)):
            mean = {}
            for shape in ("cylinder", "box"):
                v = [r[key][i] for r in runs if r["shape"] == shape and r[key][i] is not None]
                mean[shape] = float(np.mean(v)) if v else None
            d = pairs[key, e]
            res = "yes" if resolved(d["t"], d["n"]) else "no" if d["n"] > 1 else "-"
            out.append(f"| {100 * e:g} | {name} | {_fmt(mean['cylinder'], scale, digits)} | "
                       f"{_fmt(mean['box'], scale, digits)} | "
                       f"{_fmt(d['mean'], scale, digits)} +- {_fmt(d['se'], scale, digits)} | "
                       f"{_fmt(d['t'], 1, 1)} | {res} |")
        if i == 0:
            por = {shape: float(np.mean([r["porosity"] for r in runs if r["shape"] == shape]))
                   for shape in ("cylinder", "box")}
            out.insert(2, f"| 0 | porosity at the start of shearing | {por['cylinder']:.3f} | "
                          f"{por['box']:.3f} | {por['cylinder'] - por['box']:+.3f} | - | - |")
        corr = [r["membrane_correction_pa"][i] for r in runs
                if r["shape"] == "cylinder" and r["membrane_correction_pa"][i] is not None]
        out.append(f"| {100 * e:g} | membrane correction, kPa | "
                   f"{_fmt(float(np.mean(corr)) if corr else None, 1e-3, 2)} | - | - | - | - |")
    return out


def main() -> None:
    ap = _cli.study_parser("triaxial_membrane", __doc__)
    ap.add_argument("--grains", type=int, default=600, help="grains per specimen")
    ap.add_argument("--seeds", default="1,2,3", help="comma-separated seeds (one pair each)")
    ap.add_argument("--pressure", type=float, default=100e3, help="cell pressure, Pa")
    ap.add_argument("--friction", type=float, default=30.0, help="contact friction, deg")
    ap.add_argument("--radius-m", type=float, default=0.02, help="the mould's radius, m")
    ap.add_argument("--height-m", type=float, default=0.06, help="the mould's height, m")
    ap.add_argument("--rate", type=float, default=0.5, help="axial strain rate, 1/s")
    ap.add_argument("--stop-strain", type=float, default=0.06, help="axial strain to reach, -")
    ap.add_argument("--at", default="0.01,0.02,0.04,0.06",
                    help="axial strains to read q and the volumetric strain at")
    ap.add_argument("--record-every", type=int, default=500, help="steps between rows")
    ap.add_argument("--smoke", action="store_true", help="150 grains, one seed, to 1 %%")
    a = _cli.parse_study(ap, table)
    if a is None:
        return
    if a.smoke:
        a.grains, a.seeds, a.stop_strain, a.at = 150, a.seeds[:1], 0.01, [0.005, 0.01]
        a.radius_m, a.height_m = 0.014, 0.04
    dem.set_num_threads(1)
    runs = []
    for seed in a.seeds:
        for shape in (cylinder, box):
            r = shape(a, seed)
            print(json.dumps(r), flush=True)
            runs.append(r)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    data = {"command": "bench/triaxial_membrane.py " + " ".join(sys.argv[1:]),
            "machine": platform.processor() or platform.machine(),
            "commit": commit, "params": {k: v for k, v in vars(a).items() if k != "out"},
            "runs": runs, "paired": paired(runs, a.at)}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(data, indent=1, default=float) + "\n")
    for d in data["paired"]:
        print(json.dumps(d))


if __name__ == "__main__":
    sys.exit(_cli.run(main))
