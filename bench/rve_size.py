#!/usr/bin/env python3
"""The RVE-size study of footing-multiscale's zone elements (issue 62 item 2;
docs/studies/footing_multiscale.md, "RVE size").

The zone's mean stress path is taken as the case's calibration takes it (a first FEM of the
unreinforced body with the starting soil, ``footing_multiscale.zone_path``: the case's full
parameters, or with ``--smoke`` its smoke's). Then, for each element size in ``--sizes``
(grains) and each of ``--seeds`` packing seeds from ``--seed``, an element of the zone's
grains is fitted as the calibration fits one (``footing_multiscale.fit_element``): E and nu
its secant along the path, phi and psi the peak of its plane-strain biaxial test at the
path's final mean pressure. Per size: each parameter's mean over the seeds, its sd, standard
error and coefficient of variation (the scatter one element of that size has, and so what a
calibration on it, or a CPU's rounding path, can move), the wall time of one element's fit
and the bytes of one prepared element's state (what a pool of them holds per element).

A size is **representative** when every parameter's mean lies within the budget of the next
size up: |mean(n) - mean(next)| <= t(0.975, k - 1) x se(next), k the next size's seeds. The
smallest such size is the study's answer (``representative``; None when none is, or only the
largest size is left, which has no next size to be judged against).

Writes in --out: ``rve_size.jsonl`` (a line per element fit, appended and flushed as each
ends), ``rve_size.json`` (the path, the statistics per size, the comparisons and the
answer, with the command's provenance) and ``rve_size.png``. Prints progress with an ETA.
SI units; stresses compression positive in the record.

    .venv/bin/python bench/rve_size.py --smoke --out DIR                   # about 20 s
    .venv/bin/python bench/rve_size.py --sizes 100,200,400,800 --seeds 16 --out DIR
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _cli  # noqa: E402

#: The fitted parameters compared between sizes, with their units for the table.
KEYS = {"young_pa": "Pa", "poisson": "-", "friction_deg": "deg", "dilatancy_deg": "deg"}
#: The smoke: two small sizes, two seeds, the case's smoke path.
SMOKE = {"sizes": (50, 80), "seeds": 2}


def size_statistics(fits: list) -> dict:
    """The statistics of one size's fits (``fit_element``'s dicts): per key of :data:`KEYS`
    ``{"mean", "sd", "se", "cv", "n"}`` (``footing_multiscale.seed_scatter``), the mean wall
    time of one fit (s) and the seeds whose biaxial test had no peak within 6 %."""
    from geogrid_dem.studies.footing_multiscale import seed_scatter

    return {"params": seed_scatter(fits, tuple(KEYS)),
            "fit_wall_s": float(np.mean([f["wall_s"] for f in fits])),
            "no_peak_seeds": [f["seed"] for f in fits if not f["peak_reached"]]}


def compare(smaller: dict, larger: dict) -> dict:
    """Per key: the smaller size's mean minus the larger's (``difference``, and relative to
    the larger's mean), the larger's budget t(0.975, k - 1) x se, and whether the difference
    lies within it (``within``; False when the larger size has one seed: no budget)."""
    from geogrid_dem.stats import t_critical

    out = {}
    for key in KEYS:
        a, b = smaller["params"][key], larger["params"][key]
        diff = a["mean"] - b["mean"]
        budget = t_critical(b["n"]) * b["se"] if b["se"] is not None else None
        out[key] = {"difference": diff,
                    "relative": diff / abs(b["mean"]) if b["mean"] else None,
                    "budget": budget,
                    "within": bool(budget is not None and abs(diff) <= budget)}
    return out


def representative(sizes: list, stats: dict) -> tuple[list, int | None]:
    """(the comparison of each size with the next one up, the smallest size whose every
    parameter lies within the next size's budget or None)."""
    rows, answer = [], None
    for n, m in zip(sizes, sizes[1:]):
        c = compare(stats[n], stats[m])
        ok = all(x["within"] for x in c.values())
        rows.append({"grains": n, "next": m, "params": c, "within": ok})
        if ok and answer is None:
            answer = n
    return rows, answer


def figure(summary: dict, png: Path) -> None:
    """Each parameter's mean against the grains, the bars t x se."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpp_dem.io.figures import save_figure
    from geogrid_dem.stats import t_critical

    sizes = [int(k) for k in summary["sizes"]]
    fig, axes = plt.subplots(1, len(KEYS), figsize=(12, 3.4))
    for ax, (key, unit) in zip(axes, KEYS.items()):
        scale = 1e-6 if key == "young_pa" else 1.0
        st = [summary["sizes"][str(n)]["params"][key] for n in sizes]
        mean = np.array([s["mean"] for s in st]) * scale
        bar = np.array([t_critical(s["n"]) * s["se"] if s["se"] is not None else 0.0
                        for s in st]) * scale
        ax.errorbar(sizes, mean, yerr=bar, marker="o", capsize=3)
        ax.set_xscale("log")
        ax.set_xlabel("grains an element")
        ax.set_ylabel({"young_pa": "E (MPa)", "poisson": "nu (-)", "friction_deg":
                       "phi (deg)", "dilatancy_deg": "psi (deg)"}[key])
    fig.suptitle("Zone element along the footing's path: mean over seeds (bars t x se)")
    fig.tight_layout()
    save_figure(fig, png)
    plt.close(fig)


def parse(argv):
    ap = _cli.BenchParser(description=__doc__.splitlines()[0], out="folder")
    ap.add_argument("--smoke", action="store_true",
                    help=f"sizes {SMOKE['sizes']}, {SMOKE['seeds']} seeds, the case's smoke path")
    ap.add_argument("--sizes", default=None,
                    help="comma-separated element sizes, grains, increasing (default "
                         "100,200,400,800; smoke 50,80)")
    ap.add_argument("--seeds", type=int, default=None,
                    help="packing seeds per size, from --seed (default 16; smoke 2)")
    ap.add_argument("--seed", type=int, default=1, help="the first packing seed")
    ap.add_argument("--workers", type=int, default=2,
                    help="Dask workers of the element fits (results do not depend on it)")
    ap.add_argument("--out", type=Path, default=Path("results/bench/rve_size"))
    a = ap.parse_args(argv)
    text = a.sizes or ",".join(map(str, SMOKE["sizes"] if a.smoke else (100, 200, 400, 800)))
    a.sizes = _cli.numbers(text, "--sizes", kind=int, minimum=50)
    if sorted(set(a.sizes)) != list(a.sizes) or len(a.sizes) < 2:
        ap.error(f"--sizes={text}: at least two distinct sizes, increasing")
    a.seeds = a.seeds if a.seeds is not None else (SMOKE["seeds"] if a.smoke else 16)
    if a.seeds < 2:
        ap.error(f"--seeds={a.seeds}: must be >= 2 (a size's scatter needs two seeds)")
    return a


def main(argv=None) -> int:
    from cpp_dem.elements.cluster import local_client
    from cpp_dem.elements.periodic import DemElement
    from cpp_dem.progress import Progress
    from geogrid_dem.cases.footing_multiscale import SMOKE as CASE_SMOKE
    from geogrid_dem.provenance import code_record
    from geogrid_dem.studies import footing_multiscale as fm

    a = parse(argv)
    out = a.out
    p0 = fm.FootingParams(**CASE_SMOKE) if a.smoke else fm.FootingParams()
    t0 = time.perf_counter()
    s0, s1, path = fm.zone_path(p0, lambda m: print(f"[rve_size] {m}", flush=True))
    pressure = float(-np.trace(s1) / 3)
    print(f"[rve_size] the zone's path: {np.round(path['path_initial_pa'], 0).tolist()} -> "
          f"{np.round(path['path_final_pa'], 0).tolist()} Pa", flush=True)
    seeds = list(range(a.seed, a.seed + a.seeds))
    lines = out / "rve_size.jsonl"
    lines.write_text("")
    bar = Progress("rve_size")
    work = sum(a.sizes) * len(seeds)
    done = 0
    fits: dict = {}
    states: dict = {}

    def written(f):  # (each fit appended and flushed as it ends, and the progress)
        nonlocal done
        with lines.open("a") as fh:
            fh.write(json.dumps(f) + "\n")
            fh.flush()
        done += f["grains"]
        bar.update(done / work, f"{f['grains']} grains seed {f['seed']}: E "
                                f"{f['young_pa'] / 1e6:.3g} MPa, phi {f['friction_deg']:.1f} deg")

    client, cluster = local_client(a.workers)
    try:
        for n in a.sizes:
            p = dataclasses.replace(p0, cell_grains=n)
            el = DemElement.periodic(n, stress=pressure, seed=seeds[0], prep_friction_deg=0.0,
                                     **fm.grain_options(p))
            states[n] = len(el.to_bytes())
            fits[n] = fm.fit_elements(p, s0, s1, seeds, client, on_fit=written)
    finally:
        client.close()
        cluster.close()
    stats = {n: {**size_statistics(fits[n]), "state_bytes": states[n]} for n in a.sizes}
    rows, answer = representative(a.sizes, stats)
    summary = {"bench": "rve_size", "sizes": {str(n): stats[n] for n in a.sizes},
               "comparisons": rows, "representative": answer, "seeds": seeds,
               "path": {**path, "biaxial_pressure_pa": pressure},
               "params": {k: (list(v) if isinstance(v, tuple) else v)
                          for k, v in dataclasses.asdict(p0).items()},
               "smoke": bool(a.smoke), "wall_time_s": time.perf_counter() - t0,
               "command": " ".join([".venv/bin/python bench/rve_size.py", *(
                   argv if argv is not None else sys.argv[1:])]),
               "provenance": code_record()}
    (out / "rve_size.json").write_text(json.dumps(summary, indent=1) + "\n")
    figure(summary, out / "rve_size.png")
    for n in a.sizes:
        st = stats[n]["params"]
        print(f"[rve_size] {n} grains: " + ", ".join(
            f"{k} {st[k]['mean']:.4g} (cv {100 * st[k]['cv']:.1f} %)" for k in KEYS)
            + f"; {stats[n]['fit_wall_s']:.1f} s a fit, {stats[n]['state_bytes']} B a state",
            flush=True)
    print("[rve_size] representative: " + (f"{answer} grains (within the next size's budget "
          "in every parameter)" if answer else "none of the sizes below the largest"),
          flush=True)
    print(json.dumps({"representative": answer, "sizes": a.sizes, "seeds": len(seeds)}))
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
