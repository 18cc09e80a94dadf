#!/usr/bin/env python3
"""The DEM element's tangent two ways (issue 17): from the contact network
(``DemElement.network_tangent``, a Kruyt–Rothenburg type assembly) and by finite differences
of cloned states (``DemElement.fd_tangent``).

- **elastic**: the element at rest at its isotropic stress with the grains' friction raised to
  ``--elastic-friction`` (no contact slides), a central difference of ``--h``: the two must
  agree (the network tangent is then exact up to the geometric terms and the relaxation);
- **peak**: the element strained along a drained triaxial path (sigma_xx = sigma_yy held,
  compression along z at ``--rate``) to the peak of its stress ratio, relaxed there with the
  cell held, then both tangents at that state: the network with sliding contacts on the Coulomb cone, the finite difference
  one-sided in the loading direction (a sliding contact unloads elastically, so +h and -h
  differ: the tangent is not one matrix there). Reported, not asserted.

Both are 6 x 6 Voigt (xx, yy, zz, yz, xz, xy; engineering shear), Pa, tension positive.

    .venv/bin/python bench/element_tangent.py                   # n 400
    .venv/bin/python bench/element_tangent.py --n 1000 --out results/bench_runs/element_tangent.json
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from _report import write_json  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "cpp_dem"))

import cpp_dem as dem  # noqa: E402
from cpp_dem.protocols import periodic  # noqa: E402
from cpp_dem.protocols import prep
from cpp_dem.elements.periodic import DemElement  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))  # (bench/: the shared _cli)
import _cli  # noqa: E402  (one command-line style: bench/_cli.py)


def log(msg: str) -> None:
    print(f"[tangent] {msg}", flush=True)


def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    """|a - b| / |b| (Frobenius) over the finite entries."""
    m = np.isfinite(a) & np.isfinite(b)
    return float(np.linalg.norm((a - b)[m]) / np.linalg.norm(b[m]))


def elastic_element(base: DemElement, friction_deg: float) -> DemElement:
    el = base.clone()
    s = el.scene
    prep.set_friction(s, np.arange(s.num_bodies), s.material(0), friction_deg)
    el._relax(1e-6, 100_000)
    return el


def main(argv=None) -> int:
    ap = _cli.BenchParser(out="file", description=__doc__,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--stress", type=float, default=100e3, help="isotropic stress, Pa")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--h", type=float, default=1e-6, help="finite-difference strain, -")
    ap.add_argument("--elastic-friction", type=float, default=89.0, help="deg")
    ap.add_argument("--rate", type=float, default=2.0, help="axial strain rate to the peak, 1/s")
    ap.add_argument("--skip-peak", action="store_true")
    ap.add_argument("--out", default="results/bench_runs/element_tangent.json")
    args = ap.parse_args(argv)
    np.set_printoptions(precision=2, suppress=True, linewidth=140)
    t0 = time.perf_counter()
    base = DemElement.periodic(args.n, stress=args.stress, seed=args.seed)
    log(f"element: {args.n} grains, {base.contact_count()} contacts, "
        f"{time.perf_counter() - t0:.1f} s")
    out = {"args": vars(args)}

    el = elastic_element(base, args.elastic_friction)
    t = time.perf_counter()
    d_net, info = el.network_tangent()
    t_net = time.perf_counter() - t
    t = time.perf_counter()
    d_fd = el.fd_tangent(h=args.h, unbalanced=1e-7, max_relax_steps=200_000)
    t_fd = time.perf_counter() - t
    out["elastic"] = {"network": d_net.tolist(), "fd": d_fd.tolist(),
                      "rel_diff": rel_diff(d_net, d_fd), "network_s": t_net, "fd_s": t_fd,
                      "affine_over_network": float(np.trace(info["affine_voigt"]) / np.trace(d_net))
                      if "affine_voigt" in info else None,
                      "rattlers": info.get("n_rattlers"), "residual": info.get("residual")}
    log(f"elastic: network (MPa)\n{d_net / 1e6}\nfd (MPa)\n{d_fd / 1e6}")
    log(f"elastic: |network - fd| / |fd| = {out['elastic']['rel_diff']:.4f}; network "
        f"{t_net:.2f} s, fd {t_fd:.1f} s")

    if not args.skip_peak:
        el = base.clone()
        s = el.scene
        c = periodic.cell_controller(s, max_rate=20 * args.rate)
        c.set_stress(0, 0, args.stress)
        c.set_stress(1, 1, args.stress)
        c.set_rate(2, 2, -args.rate)
        c.enabled = True
        best, best_blob, q_prev = -1.0, None, []
        while True:
            s.run(500)
            st = np.asarray(s.cell_stress())
            ratio = (st[2, 2] - st[0, 0]) / (st[2, 2] + st[0, 0])
            q_prev.append(ratio)
            if ratio > best:
                best, best_blob = ratio, el.to_bytes()
            if len(q_prev) > 10 and ratio < best - 0.05:
                break
            if len(q_prev) > 400:
                break
        peak = DemElement.from_bytes(best_blob)
        peak.controller.enabled = False
        peak.scene.velocity_gradient = np.zeros((3, 3))
        # at rest at the peak strain first (the loading state is not in equilibrium: its
        # relaxation would swamp the difference)
        relax_steps, u, _ = peak._relax(1e-5, 200_000)
        log(f"peak state relaxed in {relax_steps} steps (unbalanced {u:.2g})")
        d_net_p, info_p = peak.network_tangent(sliding="plastic")
        d_fd_p = peak.fd_tangent(h=args.h, central=False, unbalanced=1e-5,
                                 max_relax_steps=50_000)
        out["peak"] = {"sin_phi_mobilised": best, "network": d_net_p.tolist(),
                       "fd_loading": d_fd_p.tolist(), "rel_diff": rel_diff(d_net_p, d_fd_p),
                       "sliding_contacts": info_p.get("n_sliding"),
                       "contacts": peak.contact_count()}
        log(f"peak (sin phi_mob {best:.3f}, {info_p.get('n_sliding')} of "
            f"{peak.contact_count()} contacts sliding): network (MPa)\n{d_net_p / 1e6}\n"
            f"fd, one-sided (MPa)\n{d_fd_p / 1e6}\n|network - fd| / |fd| = "
            f"{out['peak']['rel_diff']:.3f}")
    log(f"wrote {write_json(args.out, out)}")
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
