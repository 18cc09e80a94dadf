#!/usr/bin/env python3
"""A shear band in a plane-strain biaxial test by hierarchical FEM x DEM (issue 38): the field's
standard demonstration (Guo & Zhao, IJNME 2014; Shahin et al., IJNME 2016), with a periodic
DEM element (RVE) at every quadrature point, held on Dask workers.

- Elements that do not lock: quadratic triangles (``--degree 2``, P2, three points and three
  RVEs per cell). Constant-strain P1 triangles lock under the isochoric or dilatant flow of a
  band; P2's strain varies linearly in a cell, so a band can cross it.
- Rough platens: the bottom is held, the top moves down without sliding, both sides carry the
  confining pressure (``Rectangle(platens="rough")`` of ``femcoupling.fem.bodies``).
- An imperfection: the RVEs within ``--weak-radius`` of ``--weak-at`` are grown loose (at the
  material's friction, ``WeakZoneFactory``), the others dense; every RVE has its own seed.

At the end, the equivalent shear strain eps_q = sqrt(2/3 e:e) (e the deviatoric part of the
total strain, plane strain) at every point gives the localization index (its largest over its
mean). The band: the points above the 85th percentile of eps_q, their principal direction
(weighted by eps_q above that percentile), as an angle from the horizontal (the minor
principal stress's direction). Beside it, the band angles the RVEs predict: Mohr-Coulomb
45 + phi/2, Roscoe 45 + psi/2 and Arthur 45 + (phi + psi)/4, with phi the peak friction angle
and psi the dilatancy angle at the peak of two RVEs run alone in the same plane-strain path
(``geogrid_dem.studies.biaxial.direct_biaxial``).

Writes in --out: ``strain.xdmf`` (eps_q per cell, the cell's mean, and the displacement; open
in ParaView), ``shear_band.png`` (eps_q at the points, the band's line, the load curve),
``shear_band.json``, and the model's records (``records/``: elements.h5, fem.xdmf, steps.csv).
Prints progress with an ETA, and a final JSON line with "elements", "localization_index" and
the angles. SI units; compression positive in the printed stresses.

The band is also fitted to every point (``band_profile``): eps_q = b + A exp(-s^2 / 2 w^2), s
the distance across the band, gives its angle and width (the full width at half its rise)
with their standard errors; the angle's error (``band_error``) is the larger of the fit's 95 %
interval and half the range of its estimators (the fit, the principal direction above the
80th, 85th and 90th percentiles). ``--nonlocal-length L`` strains each element by a mean of
the strain increments within about L (m; ``femcoupling.fem.nonlocal_strain``): the band's
regularisation. ``--compare A.json B.json ...`` runs nothing: it measures the band of each
run's ``shear_band.json`` (coarse to fine) and says, for successive meshes, whether the angle
moves more than its error (``mesh_study.json``). ``--pool STUDY.json`` adds the runs of an
earlier study (its ``mesh_study.json``, or the copy in docs/data) to those files: new seeds
pool with runs whose files are gone.

    .venv/bin/python bench/shear_band.py --nx 4 --ny 9 --grains 80 --out DIR   # 216 RVEs
    .venv/bin/python bench/shear_band.py --nx 3 --ny 6 --grains 80 --out DIR2  # the coarser mesh
    .venv/bin/python bench/shear_band.py --nx 5 --ny 11 --nonlocal-length 0.006 --out DIR3
    .venv/bin/python bench/shear_band.py --compare DIR/shear_band.json DIR3/shear_band.json \
        --out DIR4
    .venv/bin/python bench/shear_band.py --compare DIR5/shear_band.json --pool \
        DIR4/mesh_study.json --out DIR6   # DIR5: another --seed
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import t as student_t

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))
sys.path.insert(0, str(HERE.parent))

from _report import write_json  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def equivalent_shear_strain(grad: np.ndarray) -> np.ndarray:
    """eps_q = sqrt(2/3 e:e) of plane-strain displacement gradients (n, 2, 2), -: e the
    deviatoric part of the small strain, the out-of-plane strain zero."""
    g = np.asarray(grad, float)
    eps = np.zeros((len(g), 3, 3))
    eps[:, :2, :2] = 0.5 * (g + np.transpose(g, (0, 2, 1)))
    tr = np.trace(eps, axis1=1, axis2=2)
    dev = eps - tr[:, None, None] / 3.0 * np.eye(3)
    return np.sqrt(2.0 / 3.0 * np.einsum("nij,nij->n", dev, dev))


def band_direction(points: np.ndarray, eq: np.ndarray, percentile: float = 85.0) -> dict:
    """The band as the principal direction of the points whose eps_q is above its
    ``percentile``, each weighted by its excess: its angle from the horizontal (deg, in
    [0, 90]: the band's inclination, whichever way it leans), its centre (m), the points used
    and how elongated they are (the ratio of the two principal spreads, 1 for a round
    cloud: no band)."""
    thr = float(np.percentile(eq, percentile))
    sel = eq > thr
    w = eq[sel] - thr
    if sel.sum() < 3 or w.sum() <= 0:
        return {"angle_deg": float("nan"), "elongation": float("nan"), "points": int(sel.sum())}
    p = points[sel]
    c = (w[:, None] * p).sum(0) / w.sum()
    cov = (w[:, None, None] * np.einsum("ni,nj->nij", p - c, p - c)).sum(0) / w.sum()
    val, vec = np.linalg.eigh(cov)
    d = vec[:, 1]
    angle = math.degrees(math.atan2(abs(d[1]), abs(d[0])))
    return {"angle_deg": angle, "elongation": float(math.sqrt(val[1] / max(val[0], 1e-300))),
            "centre_m": c.tolist(), "points": int(sel.sum()), "threshold": thr,
            "leans": "right" if d[0] * d[1] > 0 else "left"}


def band_profile(points: np.ndarray, eq: np.ndarray, first: dict) -> dict:
    """The band fitted to every point: eps_q = b + A exp(-s^2 / (2 w^2)), s the distance from
    the band's line across it, by least squares from ``first`` (``band_direction``'s). Its
    angle from the horizontal (deg, in [0, 90], and which way it leans), its width (the full
    width at half the rise above the background, m) and their standard errors (from the
    fit's Jacobian and residual; the residual's spatial correlation makes them a lower
    bound: ``band_error`` adds the estimators' spread). NaN where no band fits."""
    from scipy.optimize import least_squares

    nan = {"angle_deg": float("nan"), "angle_se_deg": float("nan"), "width_m": float("nan"),
           "width_se_m": float("nan"), "leans": None}
    if not math.isfinite(first.get("angle_deg", float("nan"))):
        return nan
    x = np.asarray(points, float)
    y = np.asarray(eq, float)
    c = np.asarray(first["centre_m"], float)
    t0 = math.radians(first["angle_deg"]) * (1 if first["leans"] == "right" else -1)
    span = float(np.ptp(x, axis=0).max())
    lo = float(np.percentile(y, 25))

    def model(q):
        b, a, t, off, lw = q
        s = (x - c) @ np.array([-math.sin(t), math.cos(t)]) - off
        return b + a * np.exp(-0.5 * s * s / math.exp(2 * lw))

    q0 = [lo, float(y.max() - lo), t0, 0.0, math.log(max(span / 20, 1e-12))]
    try:
        fit = least_squares(lambda q: model(q) - y, q0, method="lm", x_scale="jac")
    except (ValueError, np.linalg.LinAlgError):
        return nan
    b, a, t, off, lw = fit.x
    w = math.exp(lw)
    dof = max(len(y) - 5, 1)
    try:
        cov = np.linalg.inv(fit.jac.T @ fit.jac) * float(fit.fun @ fit.fun) / dof
    except np.linalg.LinAlgError:
        return nan
    if not (fit.success and a > 0 and w < span and np.all(np.diag(cov) >= 0)):
        return nan
    d = np.array([math.cos(t), math.sin(t)])
    fwhm = 2 * math.sqrt(2 * math.log(2))
    return {"angle_deg": math.degrees(math.atan2(abs(d[1]), abs(d[0]))),
            "angle_se_deg": math.degrees(math.sqrt(cov[2, 2])),
            "width_m": fwhm * w, "width_se_m": fwhm * w * math.sqrt(cov[4, 4]),
            "leans": "right" if d[0] * d[1] > 0 else "left",
            "background": float(b), "rise": float(a),
            "rise_se": float(math.sqrt(cov[1, 1]))}


def band_error(points: np.ndarray, eq: np.ndarray, fit: dict) -> float:
    """The band angle's error, deg: the larger of the fit's 95 % interval (1.96 standard
    errors) and half the range of its estimators (the fit; the principal direction above
    the 80th, 85th and 90th percentiles of eps_q)."""
    est = [fit["angle_deg"]] + [band_direction(points, eq, q)["angle_deg"]
                                for q in (80.0, 85.0, 90.0)]
    if not all(math.isfinite(a) for a in est):
        return float("nan")
    return max(1.96 * fit["angle_se_deg"], 0.5 * (max(est) - min(est)))


def band_measures(points: np.ndarray, eq: np.ndarray) -> tuple[dict, dict, float]:
    """The band of a field eps_q at the points: its principal direction
    (``band_direction``), its fit (``band_profile``) and the angle's error (``band_error``)."""
    band = band_direction(points, eq)
    fit = band_profile(points, eq, band)
    return band, fit, band_error(points, eq, fit)


def mesh_study(rows: list[dict]) -> dict:
    """The band on successive meshes (rows of ``shear_band.json``, coarse to fine; a mesh
    may have several runs, each another ``seed``): per mesh the mean angle and width over
    its runs, and for each pair of successive meshes whether the angle moves more than its
    error and the width's ratio. A run's angle error is its fit's (``band_error``, a 95 %
    half-width) and, where some mesh has two runs or more, the seeds' scatter: Student's
    t (0.975, ``seed_dof``; ``seed_t975``) x their pooled standard deviation
    (``seed_sd_deg``, with ``seed_dof`` degrees of freedom), added in quadrature; a mesh's
    error is its runs' over the square root of their number, and a move's the two meshes'
    in quadrature. Without a second seed the seeds' part is not
    measured (``seed_sd_deg`` None) and the errors are the fits' alone."""
    groups: dict = {}
    for r in rows:
        groups.setdefault(r["mesh"], []).append(r)
    # each run's angle, its fit's error and width, by mesh
    angles = {k: [float(r["band_fit"]["angle_deg"]) for r in v] for k, v in groups.items()}
    dev, dof = 0.0, 0
    for a in map(np.asarray, angles.values()):
        if len(a) > 1:
            dev += float(((a - a.mean()) ** 2).sum())
            dof += len(a) - 1
    seed_sd = math.sqrt(dev / dof) if dof else None
    seed_t975 = float(student_t.ppf(0.975, dof)) if dof else None
    meshes = []
    for name, runs in groups.items():
        r0, n = runs[0], len(runs)
        errors = [float(r["angle_error_deg"]) for r in runs]
        widths = [float(r["band_fit"]["width_m"]) for r in runs]
        fit_err = math.sqrt(np.mean([e ** 2 for e in errors]))
        per_run = (math.hypot(fit_err, seed_t975 * seed_sd) if seed_sd is not None
                   else fit_err)
        meshes.append({
            "mesh": name, "elements": r0["elements"], "cell_m": r0["cell_m"], "runs": n,
            "seeds": [r.get("seed", 1) for r in runs],
            # (each run's own: another study can pool them without the runs' files)
            "angles_deg": angles[name], "angle_fit_errors_deg": errors, "widths_m": widths,
            "nonlocal_length_m": r0.get("nonlocal_length_m"),
            "angle_deg": float(np.mean(angles[name])),
            "angle_error_deg": per_run / math.sqrt(n),
            "width_m": float(np.mean(widths)),
            "width_se_m": math.sqrt(np.mean([r["band_fit"]["width_se_m"] ** 2
                                             for r in runs]) / n),
            "localization_index": float(np.mean([r["localization_index"] for r in runs])),
            "axial_strain": float(min(r["axial_strain_reached"] for r in runs))})
    pairs = []
    for a, b in zip(meshes, meshes[1:]):
        err = math.hypot(a["angle_error_deg"], b["angle_error_deg"])
        move = b["angle_deg"] - a["angle_deg"]
        pairs.append({"from": a["mesh"], "to": b["mesh"], "angle_move_deg": move,
                      "angle_error_deg": err,
                      "angle_moves": bool(abs(move) > err) if math.isfinite(err) else None,
                      "width_ratio": b["width_m"] / a["width_m"],
                      "cell_ratio": b["cell_m"] / a["cell_m"]})
    return {"meshes": meshes, "pairs": pairs, "seed_sd_deg": seed_sd, "seed_dof": dof,
            "seed_t975": seed_t975}


def elements_strain(json_path: Path, r: dict) -> np.ndarray:
    """eps_q of the strain the elements took (the sum of their accepted increments, the
    run's ``records/elements.h5``), (n,): with a nonlocal strain the averaged field, which
    the displacement's may not be; without one the same as ``eps_q``."""
    if not r.get("nonlocal_length_m") and not r["args"].get("nonlocal_length"):
        return np.asarray(r["eps_q"], float)
    if "eps_q_elements" in r:
        return np.asarray(r["eps_q_elements"], float)
    h5 = Path(json_path).parent / "records" / "elements.h5"
    if not h5.is_file():
        raise _cli.BenchInputError(f"--field elements: {json_path} has no eps_q_elements and "
                                   f"{h5} is missing")
    import h5py

    with h5py.File(h5, "r") as f:
        el, inc = f["element"][:], f["increment"][:]
    g = np.zeros((len(r["points"]), 3, 3))
    np.add.at(g, el, inc)  # (plane strain: the FEM's x, y are the element's x, z)
    return equivalent_shear_strain(g[:, [0, 2]][:, :, [0, 2]])


def write_strain_xdmf(model, eq: np.ndarray, path: Path) -> None:
    """eps_q per cell (the mean of its points) and the displacement, in one XDMF file."""
    fx = model._fx
    V0 = fx.fem.functionspace(model.mesh, ("DG", 0))
    f = fx.fem.Function(V0, name="eps_q")
    f.x.array[:] = eq.reshape(model.n_cells, model.nq).mean(axis=1)
    # (the displacement at the vertices: XDMF holds the mesh's degree, P1)
    u1 = fx.fem.Function(fx.fem.functionspace(model.mesh, ("Lagrange", 1, (2,))),
                         name="displacement_m")
    u1.interpolate(model.u)
    import dolfinx.io

    with dolfinx.io.XDMFFile(model.mesh.comm, str(path), "w") as xf:
        xf.write_mesh(model.mesh)
        xf.write_function(f)
        xf.write_function(u1)


def plot(points, eq, band, fd, lx, ly, png: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpp_dem.io.figures import save_figure

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 5.5), gridspec_kw={"width_ratios": [1, 1.3]})
    sc = a.scatter(points[:, 0], points[:, 1], c=eq, s=30, cmap="viridis")
    fig.colorbar(sc, ax=a, label="equivalent shear strain eps_q (-)")
    if math.isfinite(band["angle_deg"]):
        c = np.asarray(band["centre_m"])
        t = math.radians(band["angle_deg"]) * (1 if band["leans"] == "right" else -1)
        s = np.linspace(-2, 2, 2) * max(lx, ly)
        a.plot(c[0] + s * math.cos(t), c[1] + s * math.sin(t), "r--",
               label=f"band {band['angle_deg']:.0f} deg")
        a.legend(loc="upper right", fontsize=8)
    a.set_xlim(0, lx)
    a.set_ylim(0, ly)
    a.set_aspect("equal")
    a.set_xlabel("x (m)")
    a.set_ylabel("y (m)")
    b.plot(100 * fd["axial_strain"], np.asarray(fd["sigma_axial"]) / 1e3, "o-",
           label="sigma_axial")
    b.plot(100 * fd["axial_strain"], np.asarray(fd["sigma_lateral"]) / 1e3, "s-",
           label="sigma_lateral")
    b.set_xlabel("axial strain (%)")
    b.set_ylabel("mean element stress (kPa, compression positive)")
    b.grid(alpha=0.3)
    b.legend()
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, png)
    plt.close(fig)


def main(argv=None) -> int:

    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from femcoupling.fem.bodies import quadrature_points
    from geogrid_dem.studies import biaxial

    ap = _cli.BenchParser(out="folder", zero_ok=("weak_radius",), description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nx", type=int, default=4, help="cells across (x2 triangles)")
    ap.add_argument("--ny", type=int, default=9, help="cells up")
    ap.add_argument("--degree", type=int, default=2, choices=(1, 2),
                    help="2: P2 triangles, 3 RVEs each (no locking); 1: P1, 1 RVE each")
    ap.add_argument("--lx", type=float, default=0.05, help="width, m")
    ap.add_argument("--ly", type=float, default=0.10, help="height, m")
    ap.add_argument("--grains", type=int, default=80, help="grains per RVE")
    ap.add_argument("--pressure", type=float, default=100e3, help="confining, Pa")
    ap.add_argument("--strain", type=float, default=0.06, help="total axial strain, -")
    ap.add_argument("--steps", type=int, default=24)
    ap.add_argument("--weak-at", type=str, default="0.25,0.3",
                    help="the weak zone's centre as fractions of (lx, ly)")
    ap.add_argument("--weak-radius", type=float, default=0.12,
                    help="its radius as a fraction of lx; 0: no weak zone")
    ap.add_argument("--seed", type=int, default=1,
                    help="element k's packing seed is seed + k (another seed: another random "
                         "field of packings on the same mesh)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rtol", type=float, default=5e-3)
    ap.add_argument("--max-newton", type=int, default=12)
    ap.add_argument("--unbalanced", type=float, default=1e-4,
                    help="the RVEs relax to this unbalanced force after each increment")
    ap.add_argument("--rve-seeds", type=int, default=2,
                    help="RVEs run alone for phi and psi (0: skip)")
    ap.add_argument("--nonlocal-length", type=float, default=0.0,
                    help="the elements strained by a mean over this length, m "
                         "(femcoupling.fem.nonlocal_strain); 0: local")
    ap.add_argument("--nonlocal-weight", type=float, default=1.0,
                    help="the averaged strain's share, in (0, 1]")
    ap.add_argument("--compare", nargs="+", metavar="JSON",
                    help="no run: the band on the meshes of these shear_band.json files, "
                         "coarse to fine (angle, width, whether the angle moves more than "
                         "its error), printed and written to --out/mesh_study.json")
    ap.add_argument("--pool", type=Path, metavar="STUDY_JSON",
                    help="with --compare: also the runs of this earlier mesh_study.json (each "
                         "mesh's runs with their own angle, fit error and width)")
    ap.add_argument("--field", choices=("displacement", "elements"), default="displacement",
                    help="with --compare: the band of the displacement's strain, or of the "
                         "strain the elements took (with a nonlocal strain, the averaged one)")
    ap.add_argument("--out", default="results/bench_runs/shear_band")
    args = ap.parse_args(argv)
    if args.pool and not args.compare:
        ap.error("--pool: only with --compare (the new runs' shear_band.json files)")
    if args.compare:
        return _compare(args.compare, Path(args.out), args.field, args.pool)
    if not (args.nonlocal_length >= 0 and math.isfinite(args.nonlocal_length)):
        ap.error(f"--nonlocal-length={args.nonlocal_length}: a length >= 0, m (0: local)")
    if not (0 < args.nonlocal_weight <= 1):
        ap.error(f"--nonlocal-weight={args.nonlocal_weight}: must be in (0, 1]")
    for name in ("nx", "ny", "grains", "steps", "workers"):
        if getattr(args, name) < 1:
            ap.error(f"--{name}={getattr(args, name)}: must be >= 1")
    if not (0 <= args.weak_radius < 1):
        ap.error(f"--weak-radius={args.weak_radius}: must be in [0, 1) (a fraction of lx)")
    try:
        wx, wy = _cli.numbers(args.weak_at, "--weak-at", lo="nonneg")
    except (ValueError, _cli.BenchInputError):
        ap.error(f"--weak-at={args.weak_at!r}: two fractions in [0, 1], x,y")
    if not (wx <= 1 and wy <= 1):
        ap.error(f"--weak-at={args.weak_at!r}: two fractions in [0, 1], x,y")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    nq = 3 if args.degree == 2 else 1
    n = 2 * args.nx * args.ny * nq
    if args.seed < 0:
        ap.error(f"--seed={args.seed}: must be >= 0")
    base = PeriodicFactory(n=args.grains, stress=args.pressure, isotropic=True,
                           seed=args.seed, options={"prep_friction_deg": 0.0})
    pts = quadrature_points(args.lx, args.ly, args.nx, args.ny, args.degree)
    weak = () if args.weak_radius == 0 else biaxial.weak_zone(
        pts, (wx * args.lx, wy * args.ly), args.weak_radius * args.lx)
    factory = biaxial.WeakZoneFactory(base, weak, {"prep_friction_deg": None})
    print(f"[shear band] {n} RVEs of {args.grains} grains ({args.nx} x {args.ny} cells, "
          f"P{args.degree}), {len(weak)} weak; building them on {args.workers} workers",
          flush=True)
    with ElementPool.build(n, factory, workers=args.workers) as pool:
        t_build = time.perf_counter() - t0
        print(f"[shear band] built in {t_build:.0f} s", flush=True)
        fd = biaxial.fem_dem_biaxial(
            pool, lx=args.lx, ly=args.ly, nx=args.nx, ny=args.ny, pressure=args.pressure,
            strain=args.strain, steps=args.steps, newton_rtol=args.rtol,
            max_newton=args.max_newton, degree=args.degree, platens="rough",
            out=out / "records", overwrite=True, stop_on_failure=True,
            nonlocal_length=args.nonlocal_length or None,
            **({"nonlocal_weight": args.nonlocal_weight} if args.nonlocal_length else {}),
            strain_kw={"unbalanced": args.unbalanced, "max_relax_steps": 100_000})
        m = fd["model"]
        cells = np.arange(m.n_cells, dtype=np.int32)
        grad = m.expr_grad.eval(m.mesh, cells).reshape(-1, 2, 2)
        eq = equivalent_shear_strain(grad)
        # (the elements' own strain: with a nonlocal strain, the averaged field)
        eq_el = (eq if m.nonlocal_strain is None else
                 equivalent_shear_strain(m.nonlocal_strain.apply(grad)))
        write_strain_xdmf(m, eq, out / "strain.xdmf")
        statuses = {s: sum(h.status == s for h in m.history)
                    for s in sorted({h.status for h in m.history})}
        iterations = int(sum(h.newton_iterations for h in m.history))
        # the scale (issue 38 item 5): worker memory, what the client received per
        # accepted step, the time per Newton iteration
        mem = pool.memory()
        received = pool.received_bytes()
        scale = {
            "workers": len(mem),
            "worker_rss_bytes": int(sum(v["rss_bytes"] for v in mem.values())),
            "accepted_state_bytes": int(sum(v["accepted_bytes"] for v in mem.values())),
            "client_received_bytes": {k: int(v) for k, v in received.items()},
            "client_bytes_per_accepted_step": (
                sum(v for k, v in received.items() if k != "build") / max(len(m.history), 1)),
            "client_held_bytes": int(pool.held_bytes()),
            "newton_iteration_s": float(sum(h.wall_s for h in m.history) / max(iterations, 1)),
            "dem_s_per_element_evaluation": float(
                sum(h.dem_s for h in m.history) / max(iterations, 1) / n)}
    band, fit, angle_error = band_measures(pts, eq)
    li = float(eq.max() / eq.mean()) if eq.mean() > 0 else float("nan")
    _, fit_el, error_el = band_measures(pts, eq_el)
    elements_field = {"localization_index": float(eq_el.max() / eq_el.mean()),
                      "eps_q_max": float(eq_el.max()), "band_fit": fit_el,
                      "angle_error_deg": error_el}
    rves = []
    if args.rve_seeds:
        runs = biaxial.direct_biaxial(base, list(range(args.rve_seeds)),
                                      pressure=args.pressure, strain=args.strain,
                                      strain_per_step=1e-6, log=None)
        rves = [biaxial.rve_angles(r) for r in runs]
    phi = float(np.mean([r["phi_peak_deg"] for r in rves])) if rves else float("nan")
    psi = float(np.mean([r["psi_deg"] for r in rves])) if rves else float("nan")
    row = {"elements": n, "mesh": f"{args.nx}x{args.ny}", "degree": args.degree,
           "cell_m": args.lx / args.nx, "seed": args.seed,
           "nonlocal_length_m": args.nonlocal_length, "nonlocal_weight": args.nonlocal_weight,
           "grains_per_element": args.grains, "weak_elements": len(weak),
           "axial_strain_reached": float(fd["axial_strain"][-1]) if len(fd["axial_strain"])
           else 0.0, "failed": fd["failed"], "statuses": statuses,
           "newton_iterations": iterations,
           "localization_index": li, "eps_q_mean": float(eq.mean()), "eps_q_max": float(eq.max()),
           "band_angle_deg": band["angle_deg"], "band_elongation": band["elongation"],
           "band_leans": band.get("leans"), "band_fit": fit, "angle_error_deg": angle_error,
           "elements_field": elements_field,
           "phi_peak_deg": phi, "psi_deg": psi,
           "mohr_coulomb_deg": 45 + phi / 2, "roscoe_deg": 45 + psi / 2,
           "arthur_deg": 45 + (phi + psi) / 4, "rves": rves,
           "peak_sigma_axial_pa": float(fd["peak_sigma_axial"]) if len(fd["axial_strain"])
           else float("nan"),
           "scale": scale, "build_s": t_build, "wall_s": time.perf_counter() - t0}
    plot(pts, eq, band, fd, args.lx, args.ly, out / "shear_band.png",
         f"{n} RVEs, {args.nx} x {args.ny} P{args.degree}"
         + (f", nonlocal length {1e3 * args.nonlocal_length:g} mm" if args.nonlocal_length
            else "") + f"; localization index {li:.2f}; band {band['angle_deg']:.0f} deg"
         + (f" (Mohr-Coulomb {45 + phi / 2:.0f}, Roscoe {45 + psi / 2:.0f})" if rves else ""))
    write_json(out / "shear_band.json", {"args": vars(args), **row,
                                         "axial_strain": fd["axial_strain"].tolist(),
                                         "sigma_axial": np.asarray(fd["sigma_axial"]).tolist(),
                                         "eps_q": eq.tolist(),
                                         "eps_q_elements": eq_el.tolist(),
                                         "points": pts.tolist()})
    print(json.dumps(row, default=float), flush=True)
    return 0


def pooled_runs(path: Path, field: str = "displacement") -> list[dict]:
    """The runs of an earlier mesh study (``mesh_study.json``, or its copy in docs/data) as
    rows of :func:`mesh_study`: each mesh's runs with their own angle, fit error and width
    (``angles_deg``, ``angle_fit_errors_deg``, ``widths_m``); a mesh of one run in a study
    without a seeds' scatter is that run. Each run takes its mesh's localization index, axial
    strain and width error (the mesh's width error times the square root of its runs), so
    the study made again from these rows gives that mesh's numbers. Refused, by name: a
    file that is not a mesh study, a study of the other ``field``, and a mesh whose runs'
    own angles were not kept (a study of an older bench with several runs, or one whose
    errors hold a seeds' scatter)."""
    try:
        st = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise _cli.BenchInputError(f"--pool {path}: not a readable mesh_study.json ({e})")
    if not isinstance(st, dict) or not isinstance(st.get("meshes"), list):
        raise _cli.BenchInputError(f"--pool {path}: not a mesh_study.json (needs meshes)")
    if st.get("field", "displacement") != field:
        raise _cli.BenchInputError(f"--pool {path}: its band is of the field "
                                   f"{st.get('field')!r}; --field {field} asked")
    rows = []
    for m in st["meshes"]:
        n = int(m["runs"])
        if "angles_deg" in m:
            angles, errors = m["angles_deg"], m["angle_fit_errors_deg"]
            widths, seeds = m["widths_m"], m["seeds"]
        elif n == 1 and st.get("seed_sd_deg") is None:
            angles, errors = [m["angle_deg"]], [m["angle_error_deg"]]
            widths, seeds = [m["width_m"]], m.get("seeds", [1])
        else:
            raise _cli.BenchInputError(
                f"--pool {path}: mesh {m['mesh']} keeps no run's own angle ({n} runs; a study "
                "of an older bench): compare its runs' shear_band.json files instead")
        if not len(angles) == len(errors) == len(widths) == len(seeds) == n:
            raise _cli.BenchInputError(f"--pool {path}: mesh {m['mesh']}: {n} runs, but "
                                       f"{len(angles)} angles, {len(errors)} errors, "
                                       f"{len(widths)} widths and {len(seeds)} seeds")
        for a, e, w, seed in zip(angles, errors, widths, seeds):
            rows.append({"mesh": m["mesh"], "elements": m["elements"], "cell_m": m["cell_m"],
                         "seed": int(seed), "nonlocal_length_m": m.get("nonlocal_length_m"),
                         "band_fit": {"angle_deg": float(a), "width_m": float(w),
                                      "width_se_m": float(m["width_se_m"]) * math.sqrt(n)},
                         "angle_error_deg": float(e),
                         "localization_index": float(m["localization_index"]),
                         "axial_strain_reached": float(m["axial_strain"]),
                         "pooled_from": str(path)})
    return rows


def check_poolable(rows: list[dict]) -> list[dict]:
    """``rows`` (runs of one study) sorted coarse to fine (by cell), a mesh's by seed;
    refused, by name: two runs of one mesh and seed (a run counted twice), and runs of
    different nonlocal lengths (a local and a nonlocal band are not one study)."""
    seen: dict = {}
    for r in rows:
        key = (r["mesh"], int(r.get("seed", 1)))
        where = r.get("pooled_from") or r.get("file", "?")
        if key in seen:
            raise _cli.BenchInputError(f"mesh {key[0]} seed {key[1]}: twice ({seen[key]} and "
                                       f"{where}); a run counts once")
        seen[key] = where
    lengths = {float(r.get("nonlocal_length_m") or 0.0) for r in rows}
    if len(lengths) > 1:
        raise _cli.BenchInputError(f"nonlocal lengths {sorted(lengths)} m among the runs: one "
                                   "study compares runs of one regularisation (0: local)")
    return sorted(rows, key=lambda r: (-float(r["cell_m"]), int(r.get("seed", 1))))


def _compare(files: list[str], out: Path, field: str = "displacement",
             pool: Path | None = None) -> int:
    rows = []
    for f in files:
        try:
            rows.append(json.loads(Path(f).read_text()))
        except (OSError, ValueError) as e:
            raise _cli.BenchInputError(f"--compare {f}: not a readable shear_band.json ({e})")
        r = rows[-1]
        if not all(k in r for k in ("points", "eps_q", "args", "elements", "mesh")):
            raise _cli.BenchInputError(f"--compare {f}: not a shear_band.json (needs points, "
                                       "eps_q, args, elements, mesh)")
        # (measured again from the field: files of an older bench compare too)
        r.setdefault("nonlocal_length_m", r["args"].get("nonlocal_length", 0.0))
        pts = np.asarray(r["points"], float)
        eq = (np.asarray(r["eps_q"], float) if field == "displacement"
              else elements_strain(Path(f), r))
        r["localization_index"] = float(eq.max() / eq.mean())
        _, r["band_fit"], r["angle_error_deg"] = band_measures(pts, eq)
        r["cell_m"] = r["args"]["lx"] / r["args"]["nx"]
        r["file"] = str(f)
    if pool is not None:
        rows = pooled_runs(pool, field) + rows
    study = mesh_study(check_poolable(rows))
    study["field"] = field
    if pool is not None:
        study["pooled"] = str(pool)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "mesh_study.json", study)
    for m in study["meshes"]:
        print(f"[mesh] {m['mesh']} ({m['elements']} elements, cells "
              f"{m['cell_m'] * 1e3:.1f} mm, {m['runs']} run(s)): band {m['angle_deg']:.1f} +- "
              f"{m['angle_error_deg']:.1f} deg, width {m['width_m'] * 1e3:.1f} +- "
              f"{m['width_se_m'] * 1e3:.1f} mm, localization index "
              f"{m['localization_index']:.2f} at {100 * m['axial_strain']:.2f} %", flush=True)
    sd = study["seed_sd_deg"]
    print("[mesh] the band of " + {"displacement": "the displacement's strain",
                                   "elements": "the strain the elements took"}[field],
          flush=True)
    print("[mesh] the seeds' scatter of the angle: " + (
        "not measured (one run a mesh; --seed gives another)" if sd is None else
        f"sd {sd:.2f} deg ({study['seed_dof']} degrees of freedom; Student's t "
        f"{study['seed_t975']:.2f} x sd in every error)"),
        flush=True)
    print(json.dumps(study, default=float), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
