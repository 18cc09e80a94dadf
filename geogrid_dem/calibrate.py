"""Calibration of the triaxial case's E, nu and phi to a reference curve (the thesis §6.1,
Table 6.1).

001 §6.1 picks Young's modulus E, Poisson's ratio nu (here k_s / k_n of the linear law) and the
contact friction angle phi by running the grid of Table 6.1 and comparing the q-eps_a and
eps_v-eps_a curves with a laboratory test at 75 kPa; it keeps E = 4500 kPa, nu = 0.33,
phi = 32 deg. The laboratory curve is not given as data in 001, so the reference here is either
a triaxial.csv given by the user or a run of our own triaxial case at known parameters (a
*synthetic truth*): recovering those parameters is an identifiability check of the procedure.

**Misfit.** With eps_a the axial strain, q the deviatoric stress and eps_v the volumetric
strain of a run (r) and the reference (ref), both interpolated linearly on the common grid
eps_k = eps_max k / (K - 1), k = 0 .. K-1, eps_max = min(max eps_a^r, max eps_a^ref)::

    M = sqrt( w_q * mean_k (q^r_k - q^ref_k)^2 / S_q^2 + w_v * mean_k (ev^r_k - ev^ref_k)^2 / S_v^2 )

with S_q = max_k |q^ref_k|, S_v = max_k |ev^ref_k| (floored at 1e-12) and w_q + w_v = 1
(0.5 each by default): a normalised RMS difference, 0 for identical curves.

**Grid.** The product of the lists of E, nu and phi (Table 6.1 or a subset; nu <= 0.5 for our
linear law) runs on ``dask.distributed`` workers, each point a separate process of the
triaxial case with a fixed seed and a fixed thread count (1 by default), so the numbers do not
depend on how many workers there are or in which order the points finish. A point's folder
``OUT/runs/E..._nu..._phi...`` that holds ``triaxial.csv``, ``summary.json`` and a
``point.json`` with the same parameters is finished and reused (resume).

**Optimiser.** The Nelder-Mead of ``scipy.optimize.minimize`` (deterministic: no random
numbers; standard coefficients 1, 2, 1/2, 1/2) on u = the bounded parameters (log10 E, nu, phi)
scaled to [0, 1] by the grid's bounds (``bounds``: SciPy clips every trial point into the box),
starting from the best grid point with the initial simplex u0, u0 + ``step`` e_i (toward the
inside of the box), whose points run at once. Evaluated parameters are rounded (E to 100 Pa, nu
to 1e-4, phi to 1e-3 deg) so that a point is one folder, and a point's misfit is computed once
(a point already run, in this call or an earlier one, is read from its folder). It stops after
``maxfev`` evaluations beyond the initial simplex or when every vertex is within ``xatol`` of
the best in u and every misfit within ``fatol`` of the best.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Hashable, Sequence

import numpy as np

from cpp_dem.io import read_csv_series
from geogrid_dem.runs import _run_row, case_command, params_to_argv

#: Table 6.1 of 001 (E in Pa, nu, phi in deg).
TABLE_6_1 = {
    "young": [2500e3, 3000e3, 3500e3, 4000e3, 4500e3, 4700e3, 4750e3, 4800e3, 5000e3],
    "poisson": [0.25, 0.30, 0.33, 0.35, 0.40, 0.45, 0.50, 0.55, 0.60],
    "phi": [28.0, 29.0, 30.0, 31.0, 32.0, 33.0, 34.0],
}
KEYS = ("young", "poisson", "phi")


# ---- the misfit -------------------------------------------------------------------------------

def misfit(run: dict[str, np.ndarray], ref: dict[str, np.ndarray], *, points: int = 50,
           w_q: float = 0.5) -> float:
    """Normalised RMS difference of q(eps_a) and eps_v(eps_a) between `run` and `ref` (dicts
    with axial_strain, deviatoric_stress, volumetric_strain); the formula is in the module's
    docstring. inf when the curves have no strain range in common."""
    def curve(d):
        ea = np.asarray(d["axial_strain"], float)
        order = np.argsort(ea, kind="stable")
        return (ea[order], np.asarray(d["deviatoric_stress"], float)[order],
                np.asarray(d["volumetric_strain"], float)[order])

    ea_r, q_r, v_r = curve(run)
    ea_f, q_f, v_f = curve(ref)
    if len(ea_r) < 2 or len(ea_f) < 2:
        return math.inf
    e_max = min(ea_r[-1], ea_f[-1])
    e_min = max(ea_r[0], ea_f[0], 0.0)
    if not e_max > e_min:
        return math.inf
    e = np.linspace(e_min, e_max, points)
    qr, qf = np.interp(e, ea_r, q_r), np.interp(e, ea_f, q_f)
    vr, vf = np.interp(e, ea_r, v_r), np.interp(e, ea_f, v_f)
    s_q = max(float(np.max(np.abs(qf))), 1e-12)
    s_v = max(float(np.max(np.abs(vf))), 1e-12)
    m2 = (w_q * np.mean((qr - qf) ** 2) / s_q ** 2
          + (1.0 - w_q) * np.mean((vr - vf) ** 2) / s_v ** 2)
    return float(math.sqrt(m2))


def read_curve(path: Path) -> dict[str, np.ndarray]:
    """axial_strain, deviatoric_stress, volumetric_strain of a triaxial.csv."""
    d = read_csv_series(path)
    missing = [k for k in ("axial_strain", "deviatoric_stress", "volumetric_strain")
               if k not in d]
    if missing:
        raise ValueError(f"{path}: columns {missing} are missing")
    return {k: d[k] for k in ("axial_strain", "deviatoric_stress", "volumetric_strain")}


# ---- running points ---------------------------------------------------------------------------

def rounded(p: Sequence[float]) -> tuple[float, float, float]:
    """(E, nu, phi) rounded to 100 Pa, 1e-4 and 1e-3 deg: one point, one folder."""
    return (round(float(p[0]) / 100.0) * 100.0, round(float(p[1]), 4), round(float(p[2]), 3))


def point_name(p: Sequence[float]) -> str:
    e, nu, phi = rounded(p)
    return f"E{e / 1e3:.1f}k_nu{nu:.4f}_phi{phi:.3f}"


@dataclass
class Runner:
    """Runs triaxial points (E, nu, phi) into ``out/runs/NAME`` on Dask (or in this process
    when ``client`` is None) and caches their curves; ``fixed`` are the other flags of the
    case (keys without dashes, as in a run file)."""

    out: Path
    fixed: dict[str, Any]
    client: Any = None
    threads: int = 1
    log: Callable[[str], None] = print
    curves: dict[tuple, dict[str, np.ndarray]] = field(default_factory=dict)
    wall: dict[tuple, float] = field(default_factory=dict)

    def folder(self, p) -> Path:
        return self.out / "runs" / point_name(p)

    def params(self, p) -> dict[str, Any]:
        e, nu, phi = rounded(p)
        params = {**self.fixed, "young": e, "poisson": nu, "phi": phi,
                  "out": str(self.folder(p))}
        params.setdefault("threads", self.threads)
        return params

    def _finished(self, p) -> bool:
        d = self.folder(p)
        try:
            old = json.loads((d / "point.json").read_text())
        except (OSError, json.JSONDecodeError):
            return False
        return ((d / "summary.json").exists() and (d / "triaxial.csv").exists()
                and old == json.loads(json.dumps(self.params(p))))

    def run(self, points: Sequence[Sequence[float]], *, label: str = "runs") -> list[float]:
        """Runs the points not run before (in parallel on the client); returns the wall time
        of each point (0 for a reused one). Raises RuntimeError naming a failed point."""
        pts = [rounded(p) for p in points]
        todo = [p for p in dict.fromkeys(pts) if p not in self.curves and not self._finished(p)]
        for p in dict.fromkeys(pts):
            if p not in todo and p not in self.curves:
                self.curves[p] = read_curve(self.folder(p) / "triaxial.csv")
                self.wall.setdefault(p, 0.0)
        if todo:
            cmd = case_command("triaxial")
            env = {"OMP_NUM_THREADS": str(self.threads or (os.cpu_count() or 1))}
            t0 = time.perf_counter()
            jobs = []
            for p in todo:
                argv = params_to_argv(self.params(p), source="calibrate")
                if self.client is None:
                    jobs.append((p, _run_row(cmd, argv, env)))
                    self._done(p, jobs[-1][1], len(jobs), len(todo), t0, label)
                else:
                    jobs.append((p, self.client.submit(_run_row, cmd, argv, env, pure=False,
                                                       retries=2)))
            if self.client is not None:
                from dask.distributed import as_completed

                by_future = {f: p for p, f in jobs}
                for n, fut in enumerate(as_completed(list(by_future)), start=1):
                    self._done(by_future[fut], fut.result(), n, len(todo), t0, label)
        return [self.wall.get(p, 0.0) for p in pts]

    def _done(self, p, r: dict, n: int, total: int, t0: float, label: str) -> None:
        if r["returncode"] != 0:
            raise RuntimeError(f"triaxial at E={p[0]:g} Pa, nu={p[1]:g}, phi={p[2]:g} deg "
                               f"failed (folder {self.folder(p)}): {r['stderr_tail']}")
        (self.folder(p) / "point.json").write_text(json.dumps(self.params(p), indent=1))
        self.curves[p] = read_curve(self.folder(p) / "triaxial.csv")
        self.wall[p] = float(r["wall_s"])
        el = time.perf_counter() - t0
        self.log(f"[calibrate] {label}: {point_name(p)} in {r['wall_s']:.1f} s ({n}/{total}, "
                 f"elapsed {el:.0f} s, ETA {el / n * (total - n):.0f} s)")


# ---- the optimiser ----------------------------------------------------------------------------

def nelder_mead(f: Callable[[np.ndarray], float] | None, x0: Sequence[float], *,
                step: float = 0.15, maxfev: int = 20, xatol: float = 0.01,
                fatol: float = 1e-4,
                batch: Callable[[list[np.ndarray]], list[float]] | None = None,
                key: Callable[[np.ndarray], Hashable] | None = None,
                cache: dict | None = None, lo: float = 0.0,
                hi: float = 1.0) -> dict[str, Any]:
    """Nelder-Mead of ``scipy.optimize.minimize`` in the box [lo, hi]^n (SciPy clips every
    trial point into it), deterministic: no random numbers, standard coefficients.

    The initial simplex is x0 and x0 + step e_i, or x0 - step e_i where + would leave the
    box. ``maxfev`` counts the evaluations after the initial simplex (SciPy's own limit is
    maxfev + n + 1, never exceeded); the search stops earlier when every vertex is within
    ``xatol`` of the best (max norm) and every misfit within ``fatol`` of the best.

    ``f`` evaluates one point, ``batch`` a list of points at once (given alone, it serves for
    single points too); the initial simplex goes to ``batch`` in one call (in parallel on
    Dask). Values are memoised by ``key(x)`` (default: the exact coordinates) in ``cache``
    (a dict, also passed back), so a point SciPy asks for again, or one that ``key`` maps to
    a point already evaluated, is not evaluated again. Returns x and fun (the best point
    evaluated), nfev (SciPy's evaluations, cached or not), new (the evaluations that called
    f or batch), history (list of (x, f) in SciPy's order) and the stop reason ("converged"
    or "maxfev")."""
    from scipy.optimize import Bounds, minimize

    if f is None and batch is None:
        raise ValueError("nelder_mead: give f or batch")
    if f is None:
        f = lambda x: batch([x])[0]  # noqa: E731
    keyf = key if key is not None else (lambda x: tuple(float(v) for v in x))
    cache = {} if cache is None else cache
    x0 = np.clip(np.asarray(x0, float), lo, hi)
    n = len(x0)
    simplex = [x0]
    for i in range(n):
        x = x0.copy()
        x[i] += step if x0[i] + step <= hi else -step
        simplex.append(np.clip(x, lo, hi))
    history: list[tuple[np.ndarray, float]] = []
    new = [0]

    todo = list({keyf(x): x for x in simplex if keyf(x) not in cache}.items())
    if todo and batch is not None:
        for (k, _), v in zip(todo, batch([x for _, x in todo])):
            cache[k] = float(v)
        new[0] += len(todo)

    def fun(x: np.ndarray) -> float:
        k = keyf(x)
        if k not in cache:
            cache[k] = float(f(x))
            new[0] += 1
        history.append((np.array(x, float), cache[k]))
        return cache[k]

    res = minimize(fun, x0, method="Nelder-Mead", bounds=Bounds(np.full(n, lo), np.full(n, hi)),
                   options={"initial_simplex": np.array(simplex), "maxfev": maxfev + n + 1,
                            "xatol": xatol, "fatol": fatol, "adaptive": False})
    # SciPy's x is the best vertex of the last simplex; a point evaluated in an iteration that
    # maxfev cut short is not in it, so the best is taken over every evaluation (first wins).
    best = min(range(len(history)), key=lambda j: (history[j][1], j))
    return {"x": history[best][0], "fun": history[best][1], "nfev": int(res.nfev),
            "new": new[0], "history": history,
            "reason": "converged" if res.status == 0 else "maxfev"}


def scaling(grid: dict[str, list[float]]) -> tuple[Callable, Callable]:
    """(to_p, to_u) for the optimiser's box: u = (log10 E, nu, phi) scaled to [0, 1] by the
    smallest and largest value of each of the grid's lists (E in Pa, phi in deg); to_p(u)
    gives the rounded point (E, nu, phi) (one folder), to_u(p) its u."""
    lo = np.array([math.log10(min(grid["young"])), min(grid["poisson"]), min(grid["phi"])])
    hi = np.array([math.log10(max(grid["young"])), max(grid["poisson"]), max(grid["phi"])])
    span = np.where(hi > lo, hi - lo, 1.0)

    def to_p(u) -> tuple[float, float, float]:
        x = lo + np.asarray(u, float) * span
        return rounded((10.0 ** x[0], x[1], x[2]))

    def to_u(p) -> np.ndarray:
        return (np.array([math.log10(p[0]), p[1], p[2]]) - lo) / span

    return to_p, to_u


# ---- the whole calibration ---------------------------------------------------------------------

@dataclass
class Config:
    """A calibration file (TOML), see cases/calibrate_triaxial.toml."""

    out: Path
    fixed: dict[str, Any]
    grid: dict[str, list[float]]
    reference: dict[str, Any]
    points: int = 50
    w_q: float = 0.5
    maxfev: int = 20
    step: float = 0.15
    xatol: float = 0.01
    fatol: float = 1e-4

    @classmethod
    def load(cls, path: Path, *, allow_large: bool = False) -> "Config":
        """Reads and checks a calibration file: every bad field is a ValueError of one line
        naming the file, the field, its value and what is allowed (FileNotFoundError when
        there is no such file). A grid of more than ``CAPS["grid points"]`` points
        (geogrid_dem.options) is refused unless ``allow_large`` (--allow-large)."""
        import tomllib

        from geogrid_dem.options import ALLOW_LARGE, CAPS

        src = str(path)
        try:
            with open(path, "rb") as f:
                d = tomllib.load(f)
        except FileNotFoundError:
            raise
        except IsADirectoryError:
            raise ValueError(f"{src}: is a folder, not a calibration file (TOML)") from None
        except OSError as e:
            raise ValueError(f"{src}: cannot be read: {e.strerror}") from None
        except UnicodeDecodeError as e:
            raise ValueError(f"{src}: not UTF-8 text (byte {e.start}); a calibration file is "
                             "TOML") from None
        except tomllib.TOMLDecodeError as e:
            raise ValueError(f"{src}: not valid TOML: {e}") from None
        known = {"out", "params", "grid", "reference", "misfit", "optimiser"}
        for k in d:
            if k not in known:
                raise ValueError(f"{src}: field {k!r} is not known; allowed: "
                                 f"{', '.join(sorted(known))}")
        if "out" not in d:
            raise ValueError(f"{src}: field 'out' is missing: the calibration's folder")
        if not isinstance(d["out"], str) or not d["out"].strip():
            raise ValueError(f"{src}: field 'out'={d['out']!r}: must be a folder name (a "
                             "non-empty string)")
        for name in ("params", "grid", "reference"):
            if not isinstance(d.get(name, {}), dict):
                raise ValueError(f"{src}: field {name!r}={d[name]!r}: must be a table "
                                 f"[{name}]")
        grid = d.get("grid", {})
        for k in grid:
            if k not in KEYS:
                raise ValueError(f"{src}: field 'grid.{k}': not known; allowed: "
                                 f"{', '.join(KEYS)}")
        for k in KEYS:
            v = grid.get(k)
            if v is None:
                raise ValueError(f"{src}: field 'grid.{k}' is missing: a non-empty list of "
                                 f"{_ALLOWED[k]}")
            if not isinstance(v, list) or not v:
                raise ValueError(f"{src}: field 'grid.{k}'={v!r}: must be a non-empty list of "
                                 f"{_ALLOWED[k]}")
            seen: set = set()
            for x in v:
                if not _ok(k, x):
                    raise ValueError(f"{src}: field 'grid.{k}' has {x!r}: each must be "
                                     f"{_ONE[k]}")
                if float(x) in seen:
                    raise ValueError(f"{src}: field 'grid.{k}' lists {x!r} twice: list each "
                                     "value once")
                seen.add(float(x))
        n_points = math.prod(len(grid[k]) for k in KEYS)
        if n_points > CAPS["grid points"] and not allow_large:
            raise ValueError(
                f"{src}: field 'grid': {' x '.join(str(len(grid[k])) for k in KEYS)} = "
                f"{n_points} points (a triaxial run each), more than the cap of "
                f"{CAPS['grid points']} grid points; add {ALLOW_LARGE} to run it")
        ref = d.get("reference", {})
        if "csv" in ref:
            extra = [k for k in ref if k != "csv"]
            if extra:
                raise ValueError(f"{src}: field 'reference.{extra[0]}': has no effect with "
                                 "reference.csv (the curve is given, nothing is run); leave "
                                 "it out, or drop csv for a synthetic truth")
            c = ref["csv"]
            if not isinstance(c, str) or not c:
                raise ValueError(f"{src}: field 'reference.csv'={c!r}: must be the path of a "
                                 "triaxial.csv (a string)")
            try:
                read_curve(Path(c))
            except FileNotFoundError:
                raise ValueError(f"{src}: field 'reference.csv'={c!r}: no such file") from None
            except (OSError, ValueError, KeyError, IndexError) as e:
                why = (str(e).splitlines() or [type(e).__name__])[0]
                raise ValueError(f"{src}: field 'reference.csv'={c!r}: cannot be read as a "
                                 "triaxial curve (columns axial_strain, deviatoric_stress, "
                                 f"volumetric_strain): {why}") from None
        elif not all(k in ref for k in KEYS):
            raise ValueError(f"{src}: field 'reference': give csv = 'triaxial.csv' or the "
                             "synthetic truth young, poisson, phi")
        else:
            for k in KEYS:
                if not _ok(k, ref[k]):
                    raise ValueError(f"{src}: field 'reference.{k}'={ref[k]!r}: must be "
                                     f"{_ONE[k]}")
        fixed = dict(d.get("params", {}))
        from geogrid_dem.runs import param_action

        for k in fixed:
            act = param_action("triaxial", k)
            dest = act.dest if act is not None else k
            if dest in ("out", *KEYS):
                alias = f" (the triaxial's {'/'.join(act.option_strings)})" \
                    if act is not None and k != dest else ""
                raise ValueError(f"{src}: field 'params.{k}'{alias}: set by the calibration")
        for k in ref:
            act = param_action("triaxial", k)
            if act is not None and k not in KEYS and act.dest in KEYS:
                raise ValueError(f"{src}: field 'reference.{k}' (the triaxial's "
                                 f"{'/'.join(act.option_strings)}): give the truth's "
                                 f"{act.dest} as 'reference.{act.dest}'")
        mis = _section(d, "misfit", src, {"points": (int, 2, 100_000, "a whole number in "
                                                            "[2, 100000]"),
                                          "w_q": (float, 0.0, 1.0, "in [0, 1] (the weight of q; "
                                                  "1 - w_q is eps_v's)")})
        opt = _section(d, "optimiser", src, {
            "maxfev": (int, 0, 100_000, "a whole number in [0, 100000] (0: the grid only)"),
            "step": (float, 1e-6, 1.0, "in (0, 1] (in the box scaled to [0, 1])"),
            "xatol": (float, 0.0, 1.0, "in [0, 1]"),
            "fatol": (float, 0.0, math.inf, "a finite number >= 0")})
        return cls(out=Path(d["out"]), fixed=fixed,
                   grid={k: [float(x) for x in grid[k]] for k in KEYS}, reference=dict(ref),
                   points=mis.get("points", 50), w_q=mis.get("w_q", 0.5),
                   maxfev=opt.get("maxfev", 20), step=opt.get("step", 0.15),
                   xatol=opt.get("xatol", 0.01), fatol=opt.get("fatol", 1e-4))


#: What the grid's values (_ALLOWED) and each of them (_ONE) may be, per key.
_ALLOWED = {"young": "finite numbers > 0 (Pa)",
            "poisson": "numbers in (0, 0.5] (k_s/k_n of the linear law)",
            "phi": "numbers in (0, 90) (deg)"}
_ONE = {"young": "a finite number > 0 (Pa)",
        "poisson": "a number in (0, 0.5] (k_s/k_n of the linear law)",
        "phi": "a number in (0, 90) (deg)"}


def _ok(key: str, x) -> bool:
    """Whether ``x`` may be a value of ``key`` (young, poisson, phi) of a grid or reference."""
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        return False
    return {"young": x > 0, "poisson": 0 < x <= 0.5, "phi": 0 < x < 90}[key]


def _section(d: dict, name: str, src: str, spec: dict) -> dict:
    """The table ``name`` of a calibration file, each key checked against ``spec`` (key ->
    (type, lo, hi, what is allowed)): an unknown key is refused with a did-you-mean, a value
    of the wrong type or out of range names the field, the value and the range."""
    import difflib

    sec = d.get(name, {})
    if not isinstance(sec, dict):
        raise ValueError(f"{src}: field {name!r}={sec!r}: must be a table [{name}]")
    out: dict[str, Any] = {}
    for k, v in sec.items():
        if k not in spec:
            near = difflib.get_close_matches(k, list(spec), n=1)
            hint = f" (did you mean {near[0]}?)" if near else ""
            raise ValueError(f"{src}: field '{name}.{k}': not known{hint}; allowed: "
                             f"{', '.join(spec)}")
        typ, lo, hi, allowed = spec[k]
        ok_type = isinstance(v, (int, float)) and not isinstance(v, bool) and (
            typ is float or float(v).is_integer())
        if not ok_type or not math.isfinite(float(v)) or not lo <= float(v) <= hi \
                or (k == "step" and not float(v) > 0):
            raise ValueError(f"{src}: field '{name}.{k}'={v!r}: must be {allowed}")
        out[k] = typ(v)
    return out


def calibrate(cfg: Config, *, client=None, threads: int = 1,
              log: Callable[[str], None] = print) -> dict[str, Any]:
    """Grid, then Nelder-Mead from the best grid point; writes OUT/grid.csv, optimiser.csv,
    best.json, misfit.png/.pdf and curves.png/.pdf. Returns best.json's content."""
    t_start = time.perf_counter()
    out = cfg.out
    out.mkdir(parents=True, exist_ok=True)
    runner = Runner(out, cfg.fixed, client=client, threads=threads, log=log)
    truth = None
    if "csv" in cfg.reference:
        ref = read_curve(Path(cfg.reference["csv"]))
        ref_src = str(cfg.reference["csv"])
    else:
        truth = rounded([cfg.reference[k] for k in KEYS])
        ref_fixed = {**cfg.fixed, **{k: v for k, v in cfg.reference.items() if k not in KEYS}}
        ref_runner = Runner(out / "reference", ref_fixed, threads=threads, log=log,
                            client=client)
        ref_runner.run([truth], label="reference (synthetic truth)")
        ref = ref_runner.curves[truth]
        ref_src = f"synthetic truth {point_name(truth)} ({ref_runner.folder(truth)})"
    log(f"[calibrate] reference: {ref_src}")

    def M(p) -> float:
        return misfit(runner.curves[rounded(p)], ref, points=cfg.points, w_q=cfg.w_q)

    # -- grid
    grid = list(itertools.product(*(cfg.grid[k] for k in KEYS)))
    log(f"[calibrate] grid: {len(grid)} points "
        f"({' x '.join(str(len(cfg.grid[k])) for k in KEYS)})")
    t0 = time.perf_counter()
    walls = runner.run(grid, label="grid")
    t_grid = time.perf_counter() - t0
    rows = [{"young_Pa": p[0], "poisson": p[1], "phi_deg": p[2], "misfit": M(p),
             "wall_s": round(w, 3), "folder": str(runner.folder(p))}
            for p, w in zip(grid, walls)]
    _write_csv(out / "grid.csv", rows)
    gbest = min(rows, key=lambda r: (r["misfit"], r["young_Pa"], r["poisson"], r["phi_deg"]))
    gbest_p = (gbest["young_Pa"], gbest["poisson"], gbest["phi_deg"])
    log(f"[calibrate] best grid point: E = {gbest_p[0] / 1e3:g} kPa, nu = {gbest_p[1]:g}, "
        f"phi = {gbest_p[2]:g} deg, misfit {gbest['misfit']:.4g}")

    # -- optimiser in u = (log10 E, nu, phi) scaled by the grid's bounds
    to_p, to_u = scaling(cfg.grid)

    def batch(us):
        ps = [to_p(u) for u in us]
        runner.run(ps, label="optimiser")
        return [M(p) for p in ps]

    t0 = time.perf_counter()
    res = nelder_mead(None, to_u(gbest_p), step=cfg.step, maxfev=cfg.maxfev, xatol=cfg.xatol,
                      fatol=cfg.fatol, batch=batch, key=to_p) if cfg.maxfev > 0 else None
    t_opt = time.perf_counter() - t0
    opt_rows = []
    if res is not None:
        for k, (u, fval) in enumerate(res["history"]):
            p = to_p(u)
            opt_rows.append({"eval": k, "young_Pa": p[0], "poisson": p[1], "phi_deg": p[2],
                             "misfit": fval})
        _write_csv(out / "optimiser.csv", opt_rows)
        best_p, best_f = to_p(res["x"]), res["fun"]
    else:
        best_p, best_f = gbest_p, gbest["misfit"]
    if best_f > gbest["misfit"]:
        best_p, best_f = gbest_p, gbest["misfit"]
    best = {
        "best": {"young_Pa": best_p[0], "poisson": best_p[1], "phi_deg": best_p[2],
                 "misfit": best_f},
        "best_grid": {"young_Pa": gbest_p[0], "poisson": gbest_p[1], "phi_deg": gbest_p[2],
                      "misfit": gbest["misfit"]},
        "reference": ref_src,
        "truth": (None if truth is None else
                  {"young_Pa": truth[0], "poisson": truth[1], "phi_deg": truth[2]}),
        "grid": {k: cfg.grid[k] for k in KEYS}, "grid_points": len(grid),
        "optimiser": None if res is None else {
            "method": "Nelder-Mead of scipy.optimize.minimize on (log10 E, nu, phi) scaled "
                      "to [0, 1]",
            "evaluations": res["nfev"], "distinct_points": res["new"], "stop": res["reason"],
            "maxfev": cfg.maxfev, "step": cfg.step, "xatol": cfg.xatol, "fatol": cfg.fatol},
        "misfit_definition": "sqrt(w_q mean((q-q_ref)^2)/max|q_ref|^2 + (1-w_q) "
                             "mean((ev-ev_ref)^2)/max|ev_ref|^2) on a common eps_a grid",
        "misfit_points": cfg.points, "w_q": cfg.w_q, "fixed": cfg.fixed, "threads": threads,
        "wall_time_s": {"grid": round(t_grid, 2), "optimiser": round(t_opt, 2),
                        "total": round(time.perf_counter() - t_start, 2)},
    }
    (out / "best.json").write_text(json.dumps(best, indent=1))
    plot_surface(out / "misfit.png", rows, best, opt_rows)
    plot_curves(out / "curves.png", ref, runner.curves[rounded(gbest_p)],
                runner.curves[rounded(best_p)], best)
    log(f"[calibrate] best: E = {best_p[0] / 1e3:g} kPa, nu = {best_p[1]:g}, "
        f"phi = {best_p[2]:g} deg, misfit {best_f:.4g} "
        f"(total {time.perf_counter() - t_start:.0f} s); {out / 'best.json'}")
    return best


def _write_csv(path: Path, rows: list[dict]) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    tmp.replace(path)


def plot_surface(path: Path, rows: list[dict], best: dict, opt_rows: list[dict]) -> None:
    """Small multiples: one panel per phi of the grid, misfit over (E, nu) (log colours); the
    best grid point (white star), the optimum (red circle, on the panel of the nearest phi),
    the truth (black cross, same), the optimiser's path (red line, same)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    from cpp_dem.io.figures import save_figure

    es = sorted({r["young_Pa"] for r in rows})
    nus = sorted({r["poisson"] for r in rows})
    phis = sorted({r["phi_deg"] for r in rows})
    table = {(r["young_Pa"], r["poisson"], r["phi_deg"]): r["misfit"] for r in rows}
    vals = np.array([v for v in table.values() if np.isfinite(v) and v > 0])
    norm = LogNorm(vmin=max(vals.min(), 1e-3), vmax=vals.max()) if len(vals) else None
    ncol = min(4, len(phis))
    nrow = math.ceil(len(phis) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 * ncol + 1.0, 2.8 * nrow),
                             squeeze=False, sharex=True, sharey=True)
    nearest = lambda phi: min(phis, key=lambda x: abs(x - phi))  # noqa: E731
    im = None
    for k, phi in enumerate(phis):
        ax = axes[k // ncol][k % ncol]
        z = np.array([[table[(e, nu, phi)] for e in es] for nu in nus])
        z = np.where(z > 0, z, norm.vmin if norm else 1e-3)
        im = ax.pcolormesh(np.arange(len(es) + 1) - 0.5, np.arange(len(nus) + 1) - 0.5, z,
                           norm=norm, cmap="viridis", shading="flat")
        for i, nu in enumerate(nus):
            for j, e in enumerate(es):
                ax.text(j, i, f"{table[(e, nu, phi)]:.2f}", ha="center", va="center",
                        fontsize=6, color="w")
        ax.set_title(f"phi = {phi:g} deg", fontsize=9)
        ax.set_xticks(range(len(es)), [f"{e / 1e3:g}" for e in es], fontsize=7, rotation=45)
        ax.set_yticks(range(len(nus)), [f"{nu:g}" for nu in nus], fontsize=7)
        bg = best["best_grid"]
        if bg["phi_deg"] == phi:
            ax.plot(es.index(bg["young_Pa"]), nus.index(bg["poisson"]), "*", color="w", ms=12,
                    mec="k")

        def where(p_e, p_nu):  # fractional index positions (log E, linear nu)
            fe = np.interp(math.log10(p_e), np.log10(es), range(len(es)))
            fn = np.interp(p_nu, nus, range(len(nus)))
            return fe, fn

        if opt_rows and nearest(best["best"]["phi_deg"]) == phi:
            path_xy = [where(r["young_Pa"], r["poisson"]) for r in opt_rows]
            ax.plot(*zip(*path_xy), "-", color="r", lw=0.8, alpha=0.7)
            ax.plot(*where(best["best"]["young_Pa"], best["best"]["poisson"]), "o",
                    color="r", mec="w", ms=7)
        if best.get("truth") and nearest(best["truth"]["phi_deg"]) == phi:
            ax.plot(*where(best["truth"]["young_Pa"], best["truth"]["poisson"]), "x",
                    color="k", ms=9, mew=2)
    for k in range(len(phis), nrow * ncol):
        axes[k // ncol][k % ncol].axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("E (kPa)")
    for row in axes:
        row[0].set_ylabel("nu = k_s/k_n")
    fig.suptitle("Misfit of q and eps_v vs eps_a (star: best grid point, o: optimum, "
                 "x: truth)", fontsize=9)
    fig.tight_layout()
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="misfit M")
    save_figure(fig, path)
    plt.close(fig)


def plot_curves(path: Path, ref, grid_best, opt_best, best: dict) -> None:
    """q-eps_a and eps_v-eps_a: the reference, the best grid point and the optimum."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cpp_dem.io.figures import save_figure

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    b, g = best["best"], best["best_grid"]
    for d, style, label in (
            (ref, "k-", "reference"),
            (grid_best, "b--", f"best grid: E={g['young_Pa'] / 1e3:g} kPa, nu={g['poisson']:g},"
                               f" phi={g['phi_deg']:g}"),
            (opt_best, "r:", f"optimum: E={b['young_Pa'] / 1e3:g} kPa, nu={b['poisson']:g}, "
                             f"phi={b['phi_deg']:g}")):
        a1.plot(d["axial_strain"] * 100, d["deviatoric_stress"] / 1e3, style, label=label)
        a2.plot(d["axial_strain"] * 100, d["volumetric_strain"] * 100, style, label=label)
    a1.set_xlabel("axial strain (%)")
    a1.set_ylabel("q (kPa)")
    a2.set_xlabel("axial strain (%)")
    a2.set_ylabel("volumetric strain (%, compression +)")
    a1.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
