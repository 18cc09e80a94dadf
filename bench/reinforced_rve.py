#!/usr/bin/env python3
"""The reinforced-soil RVE (issue 38; docs/periodic.md "A reinforced-soil RVE"): what its
preparation costs, and what the sheet adds to the cell's stiffness along x.

- **growth**: ``--n`` grains around a detailed sheet (seed 1), grown in the fixed cell to
  ``--stress``, with RadiusGrowth counting every contact and the bonds (the default) and
  counting the grains' contacts only (``grown_only``): steps, seconds, the grains' and the
  cell's mean stress and the sheet's tension when the growth stops (or gives up at
  ``--max-steps``);
- **element**: ``reinforced_element`` (RE and PRS at ``--prestress``) for each seed: its
  preparation's steps and seconds, the sheet's tension, and the stiffness along x, D_xxxx,
  by a central finite difference of ``--h`` (``DemElement.fd_tangent``), split into the
  bonds' part (times the height, against the sheet's series stiffness per metre J) and the
  grains'; the soil element (``DemElement.periodic``, as many grains, the same stress) the
  same way. The difference of the means, reinforced minus soil, against J / height;
- **release**: the PRS cell taken to the isotropic stress (``apply_stress``): the prestress
  passes to the grains and the sheet keeps part of it.

Prints one JSON line at the end. SI units, tension positive from the elements.

    OMP_NUM_THREADS=1 .venv/bin/python bench/reinforced_rve.py              # about 2 min
    OMP_NUM_THREADS=1 .venv/bin/python bench/reinforced_rve.py --seeds 1 2 3 --n 150
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))

from cpp_dem import DemElement, _core  # noqa: E402
from cpp_dem.build import woven  # noqa: E402
from cpp_dem.elements import reinforced  # noqa: E402
from cpp_dem.elements.periodic import default_material  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def log(msg: str) -> None:
    print(f"[reinforced] {msg}", flush=True)


def growth(n: int, stress: float, grown_only: bool, max_steps: int) -> dict:
    s, _, _, ms, _ = reinforced.sheet_cell(preset="detailed", grain_material=default_material())
    c, r = reinforced._grains_beside_sheet(s, n, woven.PRESETS["detailed"]["sphere_radius"],
                                           None, 0.2, 1)
    ids = s.add_spheres(c, r, material=ms)
    s.set_auto_timestep(0.5, 500)
    g = _core.RadiusGrowth(walls=[], bodies=[int(b) for b in ids], target_stress=stress,
                           grown_only=grown_only)
    s.add_controller(g)
    t0 = time.process_time()
    done = False
    while s.step_count < max_steps and not done:
        s.run(200)
        done = abs(g.measured_stress - stress) <= 0.01 * stress and s.unbalanced_force() < 0.01
    cell = -np.asarray(s.cell_stress())
    grains = np.asarray(s.cell_stress()) - reinforced.bond_stress(s)
    return {"grown_only": grown_only, "reached": done, "steps": s.step_count,
            "cpu_s": time.process_time() - t0,
            "grains_mean_pa": float(np.trace(grains)) / 3,
            "cell_mean_pa": -float(np.trace(cell)) / 3,
            "sheet_tension_n_per_m": reinforced.sheet_tension_per_metre(s)}


def stiffness_xx(el: DemElement, h: float) -> tuple[float, float]:
    """D_xxxx of the whole cell and of its bonds alone, Pa (central difference of h)."""
    out = []
    for sign in (1.0, -1.0):
        c = el.clone()
        de = np.zeros((3, 3))
        de[0, 0] = sign * h
        total = c.apply_strain(de)[0, 0]
        out.append((total, -reinforced.bond_stress(c.scene)[0, 0]))
    return ((out[0][0] - out[1][0]) / (2 * h), (out[0][1] - out[1][1]) / (2 * h))


def main(argv=None) -> int:
    ap = _cli.BenchParser(description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=150, help="grains (default 150)")
    ap.add_argument("--stress", type=float, default=50e3, help="Pa (default 50e3)")
    ap.add_argument("--prestress", type=float, default=2000.0, help="N/m (default 2000)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--h", type=float, default=1e-5, help="finite-difference strain")
    ap.add_argument("--max-steps", type=int, default=100_000,
                    help="the growth comparison gives up here (default 1e5)")
    a = ap.parse_args(argv)
    out: dict = {"n": a.n, "stress_pa": a.stress, "prestress_n_per_m": a.prestress}
    out["growth"] = [growth(a.n, a.stress, g, a.max_steps) for g in (False, True)]
    for row in out["growth"]:
        log(f"growth grown_only={row['grown_only']}: {row['steps']} steps, "
            f"{row['cpu_s']:.1f} s, reached {row['reached']}, grains {row['grains_mean_pa']:.0f}"
            f" Pa, cell {row['cell_mean_pa']:.0f} Pa, sheet {row['sheet_tension_n_per_m']}")
    j = woven.series_stiffness_per_metre("detailed")
    rows = []
    for seed in a.seeds:
        for kind, tp in (("RE", 0.0), ("PRS", a.prestress), ("soil", None)):
            t0 = time.process_time()
            if kind == "soil":
                el = DemElement.periodic(a.n, stress=a.stress, seed=seed)
            else:
                el = reinforced.reinforced_element(a.n, stress=a.stress, prestress=tp, seed=seed)
            prep_s = time.process_time() - t0
            steps = el.scene.step_count
            lz = float(np.asarray(el.scene.cell_matrix)[2, 2])
            d_total, d_bonds = stiffness_xx(el, a.h)
            row = {"seed": seed, "kind": kind, "prep_steps": steps, "prep_cpu_s": prep_s,
                   "height_m": lz, "d_xx_pa": d_total, "d_xx_bonds_pa": d_bonds,
                   "bonds_j_ratio": d_bonds * lz / j if kind != "soil" else None}
            if kind != "soil":
                row["sheet_tension_n_per_m"] = reinforced.sheet_tension_per_metre(el.scene)
                g = -el.stress() - reinforced.bond_stress(el.scene)
                row["grains_normal_pa"] = np.diag(g).tolist()  # compression positive
            if kind == "PRS":
                el.apply_stress(-a.stress * np.eye(3), components=((0, 0), (1, 1), (2, 2)))
                row["released_sheet_tension_n_per_m"] = reinforced.sheet_tension_per_metre(
                    el.scene)
            log(json.dumps(row))
            rows.append(row)
    out["elements"] = rows
    mean = {k: float(np.mean([r["d_xx_pa"] for r in rows if r["kind"] == k]))
            for k in ("RE", "PRS", "soil")}
    sd_soil = float(np.std([r["d_xx_pa"] for r in rows if r["kind"] == "soil"], ddof=1)) \
        if len(a.seeds) > 1 else float("nan")
    lz = float(np.mean([r["height_m"] for r in rows if r["kind"] == "RE"]))
    out["summary"] = {"d_xx_mean_pa": mean, "d_xx_soil_sd_pa": sd_soil,
                      "j_over_height_pa": j / lz,
                      "re_minus_soil_over_j_h": (mean["RE"] - mean["soil"]) / (j / lz),
                      "bonds_over_j": float(np.mean([r["bonds_j_ratio"] for r in rows
                                                     if r["kind"] == "RE"]))}
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
