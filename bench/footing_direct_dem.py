#!/usr/bin/env python3
"""A small strip footing by hierarchical FEM x DEM against a direct DEM of the same grains
(issue 38, item 2; docs/studies/footing_direct_dem.md).

The body is plane strain, the half beside the footing's symmetry plane, small enough for a
direct DEM on this machine: ``--length`` by ``--depth`` (m), the footing's half width ``--b``
on the top, the surcharge ``--surcharge`` (Pa) beside it, smooth sides and bottom, no
gravity. For each seed s:

1. **Direct DEM** (``cpp_dem.protocols.footing``): a box of the grains between smooth walls,
   ``--thickness`` deep out of plane (``--out-of-plane periodic``: periodic along y instead,
   no y walls; ``both``: each box in turn, from the same seed), grown frictionless then at
   the grains' friction (dense) to the isotropic q (the periodic box's first growth at
   ``--periodic-prep-friction`` degrees: 1 puts it at the elements' porosity); the top
   wall is split into the footing and the surcharge, and the footing is pushed to each
   settlement and held until the grains are at rest.
2. **FEM x DEM** (``geogrid_dem.studies.footing_dem``): the same rectangle in ``--nx`` by ``--ny``
   cells of triangles (``--degree 2``: P2, three quadrature points each, which do not lock
   under dilatant flow; ``--degree 1``: P1, one), a periodic element of ``--cell-grains``
   of the same grains (material, radii, preparation) at each point, prepared at q (element
   k from packing seed 1000 s + k), on ``--workers`` Dask workers; the footing pushed to
   the same settlements.

The footing pressures are paired over the seeds at each settlement both reached: FEM x DEM
minus direct DEM, the mean and its standard error (``geogrid_dem.studies.footing_dem.
paired_pressures``); with ``both``, FEM x DEM minus each box, and the periodic box minus the
walled one. With ``--oedometer`` the walled box (prepared again: the same) and the first 8
elements of each seed also go through the same oedometric path from q, which compares the
material itself (``oedometric_moduli``).

Writes in --out: ``footing_direct_dem.json`` (every run, the porosities, the paired
differences, the cost), ``load_settlement.csv`` (a row per run and settlement, appended as
they are reached), ``load_settlement.png``, and each run's records (``dem_seed<s>/``,
``fem_dem_seed<s>/``). Prints progress with an ETA and a final JSON line. SI units;
pressures compression positive.

    .venv/bin/python bench/footing_direct_dem.py --smoke --out DIR          # about 30 s
    .venv/bin/python bench/footing_direct_dem.py --seeds 3 --out DIR        # the measured run
    .venv/bin/python bench/footing_direct_dem.py --oedometer --out DIR     # and the material
    .venv/bin/python bench/footing_direct_dem.py --out-of-plane both --out DIR  # and periodic
    .venv/bin/python bench/footing_direct_dem.py --out-of-plane both \
        --periodic-prep-friction 1 --out DIR   # the periodic box at the elements' porosity
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))

from _report import write_json  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)

#: The direct DEM's boxes of each --out-of-plane choice: (its key in the runs, periodic_y).
BOXES = {"walls": (("dem", False),), "periodic": (("dem_periodic", True),),
         "both": (("dem", False), ("dem_periodic", True))}
FULL = dict(length=0.15, depth=0.10, thickness=0.03, b=0.03, nx=5, ny=4, cell_grains=60,
            settlements=(0.05e-3, 0.1e-3, 0.2e-3, 0.3e-3, 0.45e-3, 0.6e-3, 0.8e-3, 1.0e-3,
                         1.25e-3, 1.5e-3))
SMOKE = dict(length=0.06, depth=0.04, thickness=0.03, b=0.03, nx=2, ny=2, cell_grains=50,
             settlements=(0.05e-3, 0.1e-3, 0.2e-3))


def parse(argv=None) -> argparse.Namespace:
    ap = _cli.BenchParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true",
                    help="test size: a box of about 390 grains, 24 elements of 50, 1 seed")
    ap.add_argument("--out", type=Path, default=Path("results/bench/footing_direct_dem"))
    ap.add_argument("--seeds", type=int, default=None, help="seeds 1..N (default 3; smoke 1)")
    ap.add_argument("--surcharge", type=float, default=20e3, help="surcharge q, Pa")
    ap.add_argument("--workers", type=int, default=2, help="Dask workers of the elements")
    ap.add_argument("--degree", type=int, choices=(1, 2), default=2,
                    help="the FEM's triangles: 2 (P2, three elements per triangle: no "
                         "volumetric locking; default) or 1 (P1, one: locks under dilatant "
                         "flow)")
    for k in ("length", "depth", "thickness", "b"):
        ap.add_argument(f"--{k}", type=float, default=None, help=f"m (default {FULL[k]})")
    for k in ("nx", "ny", "cell_grains"):
        ap.add_argument(f"--{k.replace('_', '-')}", dest=k, type=int, default=None,
                        help=f"default {FULL[k]}")
    ap.add_argument("--out-of-plane", choices=tuple(BOXES), default="walls",
                    help="the direct DEM's box out of plane (y): between two smooth walls, "
                         "periodic, or both in turn (default walls)")
    ap.add_argument("--periodic-prep-friction", type=float, default=0.0,
                    help="the periodic box's friction of its first growth, deg (default 0: "
                         "frictionless, as the walled box and the elements; a few degrees "
                         "grow it looser, to the elements' porosity)")
    ap.add_argument("--oedometer", action="store_true",
                    help="also take the box (prepared again, the same) and its first 8 "
                         "elements through the same oedometric path from q (z shortened, x "
                         "and y held): their constrained moduli, Pa")
    ap.add_argument("--settlements-mm", type=str, default=None,
                    help="comma-separated settlements, mm (default "
                         + ",".join(f"{1e3 * s:g}" for s in FULL["settlements"]) + ")")
    a = ap.parse_args(argv)
    base = SMOKE if a.smoke else FULL
    for k in ("length", "depth", "thickness", "b", "nx", "ny", "cell_grains"):
        if getattr(a, k) is None:
            setattr(a, k, base[k])
    try:
        a.settlements = (tuple(v * 1e-3 for v in _cli.numbers(a.settlements_mm,
                                                               "--settlements-mm"))
                         if a.settlements_mm else base["settlements"])
    except _cli.BenchInputError as e:
        ap.error(str(e))
    if a.seeds is None:
        a.seeds = 1 if a.smoke else 3
    if a.seeds < 1:
        ap.error(f"--seeds={a.seeds}: must be >= 1")
    from cpp_dem.protocols.footing import StripFootingBox

    phi = StripFootingBox.friction_deg  # (the grains' friction angle, deg: its default)
    if not 0.0 <= a.periodic_prep_friction < phi:
        ap.error(f"--periodic-prep-friction={a.periodic_prep_friction}: must be >= 0 and "
                 f"below the grains' friction angle, {phi:g} deg")
    if a.periodic_prep_friction and a.out_of_plane == "walls":
        ap.error("--periodic-prep-friction: the periodic box's growth; needs --out-of-plane "
                 "periodic or both")
    if a.oedometer and a.out_of_plane == "periodic":
        ap.error("--oedometer with --out-of-plane periodic: the oedometer takes the box between "
                 "its six walls; run it with --out-of-plane walls or both")
    return a


def _element_grains(pool) -> tuple[list[float], float]:
    """Each element's porosity (1 - the spheres' volume over the cell's, -) and the elements'
    mean grain radius, m."""
    from cpp_dem.elements.periodic import DemElement
    from cpp_dem.measure.box import solid_volume

    porosity, radii = [], []
    for data in pool.states():
        el = DemElement.from_bytes(data)
        porosity.append(1.0 - solid_volume(el.scene) / el.volume())
        radii.extend(np.asarray(el.scene.radii).tolist())
    return porosity, float(np.mean(radii))


def _interior_porosity(state, inset: float, spacing: float) -> float:
    """The box's porosity away from its walls, -: the share of a grid of points (``spacing``,
    m) ``inset`` (m) or more inside every wall that no sphere covers (sampled: unbiased by
    the layering of the grains along the walls, which a count of the centres in a region
    is not)."""
    from scipy.spatial import cKDTree

    from cpp_dem.protocols.footing import box_extents

    sc = state.scene
    w = np.asarray(sc.wall_positions)[state.walls]
    if len(w) == 6:
        lo, hi = w[[0, 2, 4]] + inset, w[[1, 3, 5]] - inset
    else:  # periodic along y: inset from the cell's faces too, where the KD-tree sees no image
        lo = np.array([w[0], 0.0, w[2]]) + inset
        hi = lo - 2 * inset + box_extents(sc, state.walls)
    ids = np.asarray(state.grain_ids)
    c, r = np.asarray(sc.positions)[ids], np.asarray(sc.radii)[ids]
    axes = [np.arange(lo[k] + 0.5 * spacing, hi[k], spacing) for k in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    d, j = cKDTree(c).query(pts, k=8, distance_upper_bound=float(r.max()))
    covered = np.zeros(len(pts), bool)
    for col in range(d.shape[1]):
        ok = np.isfinite(d[:, col])
        covered[ok] |= d[ok, col] < r[j[ok, col]]
    return 1.0 - float(covered.mean())


#: the oedometric path's axial strains (-, cumulative, shortening)
OEDOMETER_STRAINS = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3)


def oedometric_moduli(box, factory, n_elements: int = 8) -> dict:
    """The constrained modulus (Pa) of the footing's box (``prepare_footing_box(box)``, as a
    wall-bounded ``DemElement``: its Love-Weber stress over its volume) and of elements
    0..``n_elements`` - 1 of ``factory``, each shortened along z to each of
    OEDOMETER_STRAINS with x and y held and relaxed (unbalanced force 1e-4): the secant
    -(sigma_zz - sigma_zz0) / eps_zz at each. The like-for-like check of the material: the
    same grains, from the same q, along the same path."""
    from cpp_dem.elements.periodic import DemElement
    from cpp_dem.protocols.footing import prepare_footing_box

    def moduli(el) -> list[float]:
        s0, prev, out = float(el.stress()[2, 2]), 0.0, []
        for e in OEDOMETER_STRAINS:
            sig = el.apply_strain(np.diag([0.0, 0.0, -(e - prev)]), unbalanced=1e-4,
                                  max_relax_steps=200_000)
            out.append(-(float(sig[2, 2]) - s0) / e)
            prev = e
        return out

    state = prepare_footing_box(box)
    box_m = moduli(DemElement(state.scene, walls=state.walls))
    el_m = np.array([moduli(factory(k)) for k in range(n_elements)])
    return {"strain": list(OEDOMETER_STRAINS), "box_pa": box_m,
            "elements_pa": el_m.mean(axis=0).tolist(),
            "elements_sd_pa": el_m.std(axis=0, ddof=1).tolist(),
            "ratio": (el_m.mean(axis=0) / np.array(box_m)).tolist()}


def _append_csv(path: Path, model: str, seed: int, res: dict) -> None:
    new = not path.exists()
    with open(path, "a") as fh:
        if new:
            fh.write("model,seed,settlement_m,footing_pressure_pa\n")
        for s, p in zip(res["settlement_m"], res["footing_pressure_pa"]):
            fh.write(f"{model},{seed},{float(s)!r},{float(p)!r}\n")


def _figure(path: Path, runs: dict, b: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    for s, r in runs.items():
        for key, style, label in (("dem", "k-o", "direct DEM"),
                                  ("dem_periodic", "C1-^", "direct DEM, periodic in y"),
                                  ("fem_dem", "C0-s", "FEM x DEM")):
            if key not in r:
                continue
            x = 100 * np.asarray(r[key]["settlement_m"]) / b
            ax.plot(x, np.asarray(r[key]["footing_pressure_pa"]) / 1e3, style, ms=3,
                    label=f"{label}, seed {s}")
    ax.set(xlabel="settlement / half width b, %", ylabel="footing pressure, kPa",
           title="small strip footing: FEM x DEM against direct DEM")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _print_pairs(d: dict, first: str, second: str) -> None:
    """A line per settlement of a ``paired_pressures`` result: each side's mean pressure and
    their paired difference with its standard error."""
    for k, s in enumerate(d["settlement_m"]):
        print(f"[footing vs dem] settlement {1e3 * s:.3f} mm: {first} "
              f"{d['fem_dem_pa'][k] / 1e3:.1f} kPa, {second} {d['dem_pa'][k] / 1e3:.1f} kPa, "
              f"difference {d['difference_pa'][k] / 1e3:+.1f} +- {d['se_pa'][k] / 1e3:.1f} kPa "
              f"({d['seeds']} seeds)")


def walled_box(a: argparse.Namespace, seed: int):
    """Seed ``seed``'s box between six walls, grown frictionless first (dense): the direct DEM
    of ``--out-of-plane walls``, and the grains and preparation of the FEM x DEM's elements
    and of the oedometer, whatever the periodic box's ``--periodic-prep-friction``."""
    from cpp_dem.protocols.footing import StripFootingBox

    return StripFootingBox(footing_b=a.b, length=a.length, depth=a.depth,
                           thickness=a.thickness, surcharge_pa=a.surcharge, seed=seed)


def main(argv=None) -> dict:
    a = parse(argv)
    from cpp_dem.elements.pool import ElementPool
    from cpp_dem.protocols.footing import (load_strip_footing,
                                           prepare_footing_box)
    from femcoupling.fem.bodies import quadrature_points
    from geogrid_dem.studies.footing_dem import element_factory, fem_dem_footing, paired_pressures

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "load_settlement.csv"
    if csv.exists():
        raise SystemExit(f"--out {out}: holds an earlier run ({csv.name}); give a new folder")
    t0 = time.perf_counter()
    runs: dict = {}
    seeds = list(range(1, a.seeds + 1))
    for i, s in enumerate(seeds):
        runs[s] = {}
        walled = walled_box(a, s)
        for key, periodic in BOXES[a.out_of_plane]:
            box = (replace(walled, periodic_y=True, prep_friction_deg=a.periodic_prep_friction)
                   if periodic else walled)
            box.check()
            t = time.perf_counter()
            state = prepare_footing_box(box, log=print)
            prep_s = time.perf_counter() - t
            inner = _interior_porosity(state, 2 * box.radius_mean, box.radius_mean / 6)
            print(f"[footing vs dem] seed {s}, {key}: the box's porosity {state.porosity:.4f}, "
                  f"{inner:.4f} two radii in from its walls", flush=True)
            sub = out / (f"dem_seed{s}" if key == "dem" else f"{key}_seed{s}")
            dem = load_strip_footing(state, box, a.settlements, log=print, out=sub)
            _append_csv(csv, key, s, dem)
            runs[s][key] = {**{k: np.asarray(v).tolist() if isinstance(v, (list, np.ndarray))
                               else v for k, v in dem.items()},
                            "grains": int(state.grains), "porosity": float(state.porosity),
                            "interior_porosity": float(inner),
                            "radius_mean_m": float(np.mean(np.asarray(state.scene.radii)[
                                np.asarray(state.grain_ids)])),
                            "preparation_s": prep_s, "wall_s": time.perf_counter() - t}
        t = time.perf_counter()
        n_el = len(quadrature_points(a.length, a.depth, a.nx, a.ny, a.degree))  # (the model's)
        fac = element_factory(walled, grains=a.cell_grains, seed=1000 * s)
        with ElementPool.build(n_el, fac, workers=a.workers) as pool:
            pool_s = time.perf_counter() - t
            porosities, r_el = _element_grains(pool)
            fd = fem_dem_footing(pool, length=a.length, depth=a.depth, nx=a.nx, ny=a.ny,
                                 footing_b=a.b, surcharge_pa=a.surcharge,
                                 settlements_m=a.settlements, log=print,
                                 out=out / f"fem_dem_seed{s}", degree=a.degree)
            model = fd.pop("model")
            fd["status_worst"] = model.status if fd["failed"] is None else "failed"
        _append_csv(csv, "fem_dem", s, fd)
        runs[s]["fem_dem"] = {**{k: np.asarray(v).tolist() if isinstance(v, np.ndarray)
                                  else v for k, v in fd.items()},
                               "elements": n_el, "grains": n_el * a.cell_grains,
                               "element_porosity_mean": float(np.mean(porosities)),
                               "element_porosity_sd": float(np.std(porosities, ddof=1)),
                               "radius_mean_m": r_el,
                               "preparation_s": pool_s,
                               "wall_s": time.perf_counter() - t}
        if a.oedometer:  # (the walled box)
            runs[s]["oedometer"] = o = oedometric_moduli(walled, fac)
            print(f"[footing vs dem] seed {s}: constrained modulus at eps_zz "
                  f"{o['strain'][-1]:g}: box {o['box_pa'][-1] / 1e6:.2f} MPa, elements "
                  f"{o['elements_pa'][-1] / 1e6:.2f} MPa", flush=True)
        done = time.perf_counter() - t0
        print(f"[footing vs dem] seed {s} ({i + 1}/{len(seeds)}) done, {done:.0f} s; ETA "
              f"{done / (i + 1) * (len(seeds) - i - 1):.0f} s", flush=True)
    keys = [k for k, _ in BOXES[a.out_of_plane]]
    fd_runs = [runs[s]["fem_dem"] for s in seeds]
    d = paired_pressures(fd_runs, [runs[s][keys[0]] for s in seeds])
    extra = {}
    if len(keys) == 2:  # (both: FEM x DEM - the periodic box, and periodic - walls)
        extra["paired_periodic"] = paired_pressures(fd_runs, [runs[s][keys[1]] for s in seeds])
        extra["periodic_minus_walls"] = paired_pressures([runs[s][keys[1]] for s in seeds],
                                                         [runs[s][keys[0]] for s in seeds])
    summary = {
        "geometry_m": {"length": a.length, "depth": a.depth, "thickness": a.thickness,
                       "footing_b": a.b},
        "surcharge_pa": a.surcharge, "mesh": {"nx": a.nx, "ny": a.ny, "degree": a.degree,
                                              "elements": n_el, "cell_grains": a.cell_grains},
        "seeds": seeds, "runs": {str(s): r for s, r in runs.items()},
        "direct_dem": keys, "periodic_prep_friction_deg": a.periodic_prep_friction,
        **{name: {k: np.asarray(v).tolist() if isinstance(v, np.ndarray) else v
                  for k, v in dd.items()} for name, dd in (("paired", d), *extra.items())},
        "wall_s": time.perf_counter() - t0,
    }
    if a.oedometer:
        r = np.array([runs[s]["oedometer"]["ratio"] for s in seeds])
        summary["oedometer_ratio"] = {
            "strain": list(OEDOMETER_STRAINS), "mean": r.mean(axis=0).tolist(),
            "se": (r.std(axis=0, ddof=1) / np.sqrt(len(r)) if len(r) > 1
                   else np.full(r.shape[1], np.nan)).tolist()}
    write_json(out / "footing_direct_dem.json", summary)
    _figure(out / "load_settlement.png", runs, a.b)
    _print_pairs(d, "FEM x DEM", f"direct DEM ({keys[0]})")
    if extra:
        _print_pairs(extra["periodic_minus_walls"], "periodic box", "walled box")
    last = {"settlement_m": float(d["settlement_m"][-1]),
            "fem_dem_pa": float(d["fem_dem_pa"][-1]), "dem_pa": float(d["dem_pa"][-1]),
            "difference_pa": float(d["difference_pa"][-1]), "se_pa": float(d["se_pa"][-1]),
            "seeds": d["seeds"], "wall_s": summary["wall_s"]}
    print(json.dumps(last))
    return summary


if __name__ == "__main__":  # (Dask spawns its workers: the guard is needed)
    sys.exit(_cli.run(main))
