"""``geogrid-dem watch RUN_DIR``: a running case's main curve, redrawn as it grows.

A case appends its records to CSV files as it goes (flushed at every record). ``watch`` reads
the run folder's series, picks the one written last (or the ``--csv`` asked), and every
``--every`` seconds redraws its curve into a PNG beside the folder (``RUN_DIR_watch.png``:
nothing is written into the run folder, so a ``--resume`` finds only the run's own files)
and prints one line: the run's status, the file, its rows and the last point. It stops once
the run is no longer running (completed, failed, interrupted, or killed: the lock's process
is gone), after a last drawing; ``--once`` draws once. Open the PNG in an image viewer that
reloads a changed file (most do) for a live plot.

The curve of a series is chosen by its columns (:data:`CURVES`, the first whose columns the
file has): pull-out force against displacement, a triaxial deviator against axial strain, a
footing's pressure against settlement, an element's vertical stress against its steps, a
deposition's kinetic energy against time; ``--x`` and ``--y`` name others."""

from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

__all__ = ["CURVES", "WatchError", "main_watch", "pick_series", "read_curve", "run_state"]


class WatchError(ValueError):
    """A watch that cannot start (no run folder, no series, a column not in it)."""


#: (columns the file must have, x, y, x label, y label, y scale): the first that fits a file
CURVES: tuple[tuple[frozenset, str, str, str, str, float], ...] = (
    (frozenset({"displacement", "pull_force"}), "displacement", "pull_force",
     "pull-out displacement (mm)", "pull-out force (kN)", 1e-3),
    (frozenset({"axial_strain", "deviatoric_stress"}), "axial_strain", "deviatoric_stress",
     "axial strain (-)", "deviatoric stress (kPa)", 1e-3),
    (frozenset({"settlement_m", "pressure_pa"}), "settlement_m", "pressure_pa",
     "settlement (mm)", "footing pressure (kPa)", 1e-3),
    (frozenset({"step", "sigma_z", "lz"}), "step", "sigma_z",
     "step (-)", "vertical wall stress (kPa)", 1e-3),
    (frozenset({"step", "wall_stress_pa", "coordination"}), "step", "wall_stress_pa",
     "step (-)", "walls' mean stress (kPa)", 1e-3),
    (frozenset({"time", "kinetic"}), "time", "kinetic", "time (s)", "kinetic energy (J)", 1.0),
)
#: the x axes drawn in mm (m in the file)
_MM = {"displacement", "settlement_m"}


@dataclass
class Series:
    path: Path
    x: str
    y: str
    x_label: str
    y_label: str
    y_scale: float


def _header(path: Path) -> list[str]:
    try:
        with open(path, newline="") as fh:
            return next(csv.reader(fh), [])
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


def run_state(run_dir: Path) -> str:
    """The run's status (``geogrid_dem.rundir.live_status``): "running", "complete",
    "interrupted", "failed", "killed", or "unknown" without a manifest."""
    from geogrid_dem import rundir

    return rundir.live_status(run_dir)


def pick_series(run_dir: Path, csv_glob: str | None = None, x: str | None = None,
                y: str | None = None) -> Series:
    """The series to watch: of the run folder's CSV files (sub-folders too; ``csv_glob``
    narrows them) whose columns fit a curve of :data:`CURVES` (or hold ``x`` and ``y``), the
    one written last. Raises WatchError naming what is missing."""
    files = sorted(run_dir.rglob(csv_glob or "*.csv"))
    if not files:
        raise WatchError(f"RUN_DIR={run_dir}: no CSV file"
                         + (f" matches --csv={csv_glob!r}" if csv_glob else "")
                         + " (yet): a case writes its records as it goes; wait for its first "
                           "record, or name the folder a case writes into")
    fits = []
    for f in files:
        cols = set(_header(f))
        if x or y:
            xx, yy = x or "step", y or ""
            if {xx, yy} <= cols:
                fits.append(Series(f, xx, yy, xx, yy, 1.0))
            continue
        for need, cx, cy, lx, ly, s in CURVES:
            if need <= cols:
                fits.append(Series(f, cx, cy, lx, ly, s))
                break
    if not fits:
        names = ", ".join(str(f.relative_to(run_dir)) for f in files[:5])
        what = (f"holds columns --x={x!r} and --y={y!r}" if (x or y)
                else "has the columns of a known curve")
        raise WatchError(f"RUN_DIR={run_dir}: no CSV file {what} (files: {names}"
                         f"{', ...' if len(files) > 5 else ''}); give --x and --y, the columns "
                         "to draw")
    return max(fits, key=lambda s: (s.path.stat().st_mtime_ns, str(s.path)))


#: columns that split a file's rows into curves (a footing's variants, models and seeds)
_GROUPS = ("variant", "model", "seed")


def read_curve(s: Series) -> list[tuple[str, list[float], list[float]]]:
    """The curves of the series' file so far: one (label, x, y) per group of rows (by its
    variant, model and seed columns where it has them; one curve, label "", otherwise). A
    last line still being written, or a value that is not a number, is left out."""
    curves: dict[str, tuple[list[float], list[float]]] = {}
    try:
        with open(s.path, newline="") as fh:
            for row in csv.DictReader(fh):
                try:
                    a, b = float(row[s.x]), float(row[s.y])
                except (KeyError, TypeError, ValueError):
                    continue
                if math.isfinite(a) and math.isfinite(b):
                    key = " ".join(f"{row[g]}" for g in _GROUPS if row.get(g))
                    xs, ys = curves.setdefault(key, ([], []))
                    xs.append(a)
                    ys.append(b)
    except OSError:
        pass
    return [(k, xs, ys) for k, (xs, ys) in curves.items()]


def _draw(s: Series, curves, png: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fx = 1e3 if s.x in _MM else 1.0
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, xs, ys in curves:
        ax.plot([v * fx for v in xs], [v * s.y_scale for v in ys], ".-" if label else "-",
                lw=1.2, label=label or None)
    if any(label for label, _x, _y in curves):
        ax.legend(fontsize=7)
    ax.set_xlabel(s.x_label)
    ax.set_ylabel(s.y_label)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    tmp = png.with_name(png.name + ".tmp.png")
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    os.replace(tmp, png)  # (a viewer never reads a half-written file)


def main_watch(run_dir: Path, *, csv_glob: str | None = None, x: str | None = None,
               y: str | None = None, every_s: float = 2.0, once: bool = False,
               png: Path | None = None, log: Callable[[str], None] = print,
               max_wait_s: float = 600.0) -> int:
    """The ``watch`` command (module doc); returns its exit status (0). Waits up to
    ``max_wait_s`` for a running case's first series file."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise WatchError(f"RUN_DIR={run_dir}: not a folder (the --out of a case run)")
    if not (every_s > 0 and math.isfinite(every_s)):
        raise WatchError(f"--every={every_s}: must be a number of seconds > 0")
    png = Path(png) if png is not None else run_dir.parent / f"{run_dir.name}_watch.png"
    t0 = time.monotonic()
    while True:
        state = run_state(run_dir)
        try:
            s = pick_series(run_dir, csv_glob, x, y)
            break
        except WatchError:
            if once or state != "running" or time.monotonic() - t0 > max_wait_s:
                raise
            time.sleep(every_s)
    while True:
        state = run_state(run_dir)  # (before the read: a run that ended is drawn whole)
        if not (csv_glob or x or y):
            s = pick_series(run_dir)  # (a case moves on to its next file)
        curves = read_curve(s)
        rows = sum(len(xs) for _k, xs, _y in curves)
        name = str(s.path.relative_to(run_dir))
        k, xs, ys = curves[-1] if curves else ("", [], [])
        last = (f"{s.y} {ys[-1]:.6g} at {s.x} {xs[-1]:.6g}" + (f" ({k})" if k else "")
                if xs else "no row yet")
        _draw(s, curves, png, f"{run_dir.name}/{name} ({state}, {rows} rows)")
        log(f"[watch] {state}: {name}: {rows} rows, {last}; drawn in {png}")
        if once or state != "running":
            return 0
        time.sleep(every_s)
