#!/usr/bin/env python3
"""How rough a band RVE's answer is (docs/studies/footing_multiscale.md, "How rough a band
RVE's answer is"): the reinforced-soil RVE of a footing's band cell
(``femcoupling.materials.dem_elements.ReinforcedBandElement`` with the footing's grains,
``footing_multiscale.band_options``)
takes one strain increment, and again with a probe of ``--probe`` more in zz, each relaxed
to each unbalanced force of ``--unbalanced``. The difference of the two stresses, over the
stress, is split into the grains' part and the sheet's bonds' part
(``periodic.bond_stress``). A difference that falls as the relaxation is tightened is a
vibration left in the sheet; one that does not is a different end state.

The measure's check: the increment run again gives the same stress bitwise
(``repeat_bitwise_equal``), so a difference is the probe's.

Prints one JSON line at the end. SI units; stresses of the cell (not the band's scale).

    OMP_NUM_THREADS=1 .venv/bin/python bench/band_rve_roughness.py            # about 25 s
    OMP_NUM_THREADS=1 .venv/bin/python bench/band_rve_roughness.py --smoke    # about 10 s
    OMP_NUM_THREADS=1 .venv/bin/python bench/band_rve_roughness.py --loose    # as before
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import sys
from pathlib import Path
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def roughness(*, grains: int, seed: int, pressure_pa: float, tension_n_per_m: float,
              increment, probe: float, unbalanced: list, loose: bool = False) -> dict:
    """The band RVE's answers to ``increment`` (3 x 3, -) and to it plus ``probe`` in zz,
    at each relaxation level: relative differences (total, grains', bonds')."""
    from cpp_dem import DemElement
    from cpp_dem.protocols import periodic
    from femcoupling.materials.dem_elements import ReinforcedBandElement
    from geogrid_dem.studies import footing_multiscale as fm

    t0 = time.perf_counter()
    options = fm.band_options(fm.FootingParams())
    if loose:  # (grown at the grains' friction, as the band RVEs were before)
        options.pop("prep_friction_deg")
    el = ReinforcedBandElement(n=grains, seed=seed, options=options).element(
        pressure_pa, tension_n_per_m)
    el.set_band_thickness(None)  # (the cell's own stress)
    blob = el.to_bytes()
    prep_s = time.perf_counter() - t0
    de = np.asarray(increment, float)
    pr = np.zeros((3, 3))
    pr[2, 2] = -probe
    rows = []
    for ub in unbalanced:
        out = []
        for d in (de, de + pr):
            e = DemElement.from_bytes(blob)
            s = e.apply_strain(d, unbalanced=ub, max_relax_steps=400_000)
            out.append((s, -periodic.bond_stress(e.scene), e.last_report.relax_steps))
        (sa, ba, na), (sb, bb, _) = out
        again = DemElement.from_bytes(blob).apply_strain(de, unbalanced=ub,
                                                         max_relax_steps=400_000)
        size = float(np.linalg.norm(sa))
        rows.append({"unbalanced": ub, "relax_steps": int(na),
                     "total": float(np.linalg.norm(sb - sa)) / size,
                     "bonds": float(np.linalg.norm(bb - ba)) / size,
                     "grains": float(np.linalg.norm((sb - bb) - (sa - ba))) / size,
                     "bitwise_equal": bool(np.array_equal(sa, sb)),
                     "repeat_bitwise_equal": bool(np.array_equal(sa, again)),
                     "stress_norm_pa": size})
    return {"grains": grains, "seed": seed, "loose": loose, "pressure_pa": pressure_pa,
            "tension_n_per_m": tension_n_per_m, "probe": probe, "preparation_s": prep_s,
            "rows": rows}


def main(argv=None) -> dict:
    ap = _cli.BenchParser(zero_ok=("probe",), description=__doc__.split("\n\n")[0])
    ap.add_argument("--smoke", action="store_true", help="the first relaxation level only")
    ap.add_argument("--grains", type=int, default=80)
    ap.add_argument("--seed", type=int, default=1501, help="packing seed (the footing's "
                    "first band element of seed 1)")
    ap.add_argument("--pressure", type=float, default=10e3, help="the grains' pressure, Pa")
    ap.add_argument("--tension", type=float, default=1900.0, help="the sheet's tension, N/m")
    ap.add_argument("--probe", type=float, default=1e-9, help="more zz compression, -")
    ap.add_argument("--loose", action="store_true",
                    help="grow the grains at their friction (loose), as the footing's band "
                         "RVEs were before; default: frictionless first, dense")
    ap.add_argument("--unbalanced", default="1e-3,1e-4,1e-5,1e-6",
                    help="comma-separated relaxation levels (unbalanced force)")
    a = ap.parse_args(argv)
    if a.probe < 0:
        ap.error(f"--probe={a.probe}: must be >= 0")
    try:
        levels = [float(x) for x in a.unbalanced.split(",")]
    except ValueError:
        ap.error(f"--unbalanced={a.unbalanced!r}: comma-separated numbers")
    if not levels or any(not (x > 0 and math.isfinite(x)) for x in levels):
        ap.error(f"--unbalanced={a.unbalanced!r}: numbers > 0, finite")
    if a.grains < 80:
        ap.error(f"--grains={a.grains}: at least 80 (fewer of the footing's 3 mm grains do "
                 "not fit beside the sheet)")
    if a.smoke:
        levels = levels[:1]
    de = np.zeros((3, 3))
    de[0, 0], de[2, 2] = 1e-4, -3e-4
    de[0, 2] = de[2, 0] = 2.5e-5
    r = roughness(grains=a.grains, seed=a.seed, pressure_pa=a.pressure,
                  tension_n_per_m=a.tension, increment=de, probe=a.probe, unbalanced=levels,
                  loose=a.loose)
    for row in r["rows"]:
        print(f"unbalanced {row['unbalanced']:g}: |ds| / |s| {row['total']:.2e} (grains "
              f"{row['grains']:.2e}, bonds {row['bonds']:.2e}), {row['relax_steps']} "
              "relaxation steps", flush=True)
    print(json.dumps(r), flush=True)
    return r


if __name__ == "__main__":
    sys.exit(_cli.run(main))
