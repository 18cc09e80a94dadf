"""``geogrid-dem continue RUN_DIR LABEL --steps N``: cycle a finished element on.

A PFC user "cycles on" to check that an element is at equilibrium. Each element of the case
prs_element_002 saves its final state as ``RUN_DIR/<label>_final.h5``
(cpp_dem.elements.box.save_final_state: the scene's checkpoint, and as its extra JSON the
element's parameters, targets, the servo's set points and axis modes, and the grid's end
conditions). This module restores that element and runs it on:

1. **The skeleton.** The scene is rebuilt from the saved parameters without a step
   (``prepare_woven_element(..., build_only=True)``: the same bodies, materials, laws, walls
   and controllers in the same order), and the checkpoint is loaded into it
   (cpp_dem.checkpoint.load_checkpoint, which refuses another scene).
2. **The end conditions.** PRS's Prestress (``load_variant(..., build_only=True)``) and the
   grid's EndTension are re-created on the restored positions (they find the grid's ends
   there), and the checkpoint is loaded again: the grips' held DOFs and the end forces are
   then the run's own, bit for bit (the EndTension knows its saved N/m).
3. **The servo.** The walls servo at the final set points: the stress axes at their goals,
   the strain-rate axes at rate 0 (held where they are).
4. **N steps**, then one JSON line (:func:`continue_element`'s result): ``label``, ``steps``,
   ``added_strain`` [x, y, z] (the box's engineering strain over the N steps, compression
   positive), ``stress_pa`` [x, y, z] (the stresses held at the end:
   cpp_dem.elements.box.held_stresses) and ``inertial_number`` (the box's largest axis strain
   rate over the N steps times the grains' mean diameter over sqrt(p / rho_eff):
   cpp_dem.elements.box._Rate).

RUN_DIR is only read. With ``out`` the continued state goes there as ``<label>_final.h5`` (the
same format: it can be continued in turn) with ``<label>_continue.json`` (the result and
where it came from). SI units; stresses compression positive.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import time
from dataclasses import fields
from pathlib import Path
from typing import Callable

import numpy as np

from geogrid_dem.rundir import write_atomic
from geogrid_dem.runs import RunFileError, UsageError

#: The most steps one call runs (continue again from its --out to go farther).
MAX_STEPS = 10_000_000
#: The final states' files in a run's folder: <label>_final.h5.
FINAL_SUFFIX = "_final.h5"
#: The ``kind`` of a prs_element_002 element's final state (box.save_final_state).
KIND = "prs_element_002 element"
#: Steps run between progress checks (a fixed chunking: the result does not depend on time).
CHUNK = 1000
#: Seconds between progress lines (stderr).
PROGRESS_S = 5.0


def _log(msg: str) -> None:
    print(f"[continue] {msg}", file=sys.stderr, flush=True)


def final_states(run_dir: Path) -> dict[str, Path]:
    """The elements whose final state ``run_dir`` holds: {label: its <label>_final.h5}."""
    return {f.name[: -len(FINAL_SUFFIX)]: f
            for f in sorted(Path(run_dir).glob(f"*{FINAL_SUFFIX}")) if f.is_file()}


def check_steps(steps, *, least: int = 1) -> int:
    """``steps`` as an integer in [least, MAX_STEPS]; UsageError naming --steps otherwise
    (the command asks for at least 1; :func:`continue_element` takes 0: restore only)."""
    try:
        n = int(str(steps).strip()) if not isinstance(steps, bool) else None
    except ValueError:
        n = None
    if n is None or not (least <= n <= MAX_STEPS):
        raise UsageError(f"--steps={steps!r}: must be an integer from {least} to {MAX_STEPS} "
                         "(steps to run; to go farther, continue again from --out)")
    return n


def find_state(run_dir, label: str) -> Path:
    """The final state of ``label`` in ``run_dir``; UsageError naming RUN_DIR or LABEL (and
    the labels there) when there is none."""
    d = Path(run_dir)
    if not d.is_dir():
        raise UsageError(f"RUN_DIR={str(run_dir)!r}: "
                         + ("not a folder" if d.exists() else "no such folder")
                         + " (the --out of a prs-element-002 run)")
    states = final_states(d)
    if not states:
        raise UsageError(f"RUN_DIR={str(run_dir)!r}: holds no element's final state "
                         f"(*{FINAL_SUFFIX}); give the --out of a prs-element-002 run")
    if label not in states:
        raise UsageError(f"LABEL={label!r}: no element of that name in {str(run_dir)!r}; its "
                         f"elements: {', '.join(states)}")
    return states[label]


def check_out(out, run_dir, label: str, overwrite: bool) -> Path | None:
    """``out`` as a folder to write the continued state to (None: write nothing); UsageError
    naming --out for RUN_DIR itself (its final state would be replaced), a file, or earlier
    results of ``label`` there without ``overwrite``."""
    if out is None:
        return None
    o = Path(out)
    if o.resolve() == Path(run_dir).resolve():
        raise UsageError(f"--out={str(out)!r}: is RUN_DIR itself, whose final state it would "
                         "replace; give another folder")
    if o.exists() and not o.is_dir():
        raise UsageError(f"--out={str(out)!r}: is a file; give a folder")
    earlier = [f.name for f in (o / f"{label}{FINAL_SUFFIX}", o / f"{label}_continue.json")
               if f.exists()]
    if earlier and not overwrite:
        raise UsageError(f"--out={str(out)!r}: holds an earlier continuation of {label} "
                         f"({', '.join(earlier)}); add --overwrite to replace it")
    return o


def read_extra(path: Path) -> dict:
    """The final state's extra JSON (checked against its checksum when the state loads)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            extra = json.loads(f.attrs["extra_json"])
    except (OSError, KeyError, TypeError, ValueError) as e:
        raise RunFileError(f"{path}: not a readable final state (a checkpoint written by "
                           f"cpp_dem.elements.box.save_final_state): {e}") from None
    missing = [k for k in ("kind", "label", "prestressed", "params", "targets_pa", "set_points",
                           "modes", "grid_end_tension_n_per_m", "prestress_locked")
               if k not in extra] if isinstance(extra, dict) else ["(all)"]
    if missing:
        raise RunFileError(f"{path}: the final state's extra JSON lacks {', '.join(missing)}; "
                           "it was not written by cpp_dem.elements.box.save_final_state")
    if extra["kind"] != KIND:
        raise RunFileError(f"{path}: kind={extra['kind']!r}: this command continues a "
                           f"{KIND!r}")
    return extra


def params_from(extra: dict, path: Path):
    """The element's parameters (prs_element_002's Params) from the final state's JSON: lists
    back to tuples where the field's default is one; a field this version lacks is refused."""
    from geogrid_dem.cases.prs_element_002 import Params

    known = {f.name: f for f in fields(Params)}
    saved = extra["params"]
    unknown = sorted(set(saved) - set(known))
    if unknown:
        raise RunFileError(f"{path}: params field {unknown[0]!r} is not a parameter of this "
                           "version's prs_element_002 (a final state of another version)")
    defaults = Params()
    kw = {k: (tuple(v) if isinstance(getattr(defaults, k), tuple) and isinstance(v, list)
              else v) for k, v in saved.items()}
    return Params(**kw)


def _ends_as_pulled(ends) -> None:
    """The restored EndTension's end bodies: those the run pulled (their restored external
    forces along the members, - at the low end, + at the high end), each on its nearest line.
    GridEnds finds the ends by position, and the grid has deformed since the run's EndTension
    found them: at 150 clumps the final positions gave 200 end bodies where the run pulled
    231. Without a pull (0 N/m) they stay as found."""
    e = ends.ends
    sc = ends.scene
    f = np.asarray(sc.external_forces)[:, e.axis]
    low, high = np.flatnonzero(f < 0), np.flatnonzero(f > 0)
    if len(low) == 0 or len(high) == 0:
        return
    pos = np.asarray(sc.positions)[:, 1 - e.axis]
    e.low, e.high = low, high
    e.low_line = np.argmin(np.abs(pos[low][:, None] - e.line_coord[None, :]), axis=1)
    e.high_line = np.argmin(np.abs(pos[high][:, None] - e.line_coord[None, :]), axis=1)


class Restored:
    """An element restored from its final state: ``sample``, ``grid``, ``p`` (Params),
    ``extra`` (the state's JSON), ``prestress`` (PRS's Prestress, or None), ``ends``
    (the grid's EndTension, or None), ``path``."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def restore_element(path: Path, log: Callable[[str], None] = _log) -> Restored:
    """The element of the final state ``path``, restored with its walls servoing at their
    final set points and its grid's end conditions (module docstring, steps 1-3)."""
    from cpp_dem import ParameterError
    from cpp_dem.checkpoint import load_checkpoint
    from cpp_dem.elements.box import load_variant, prepare_woven_element
    from cpp_dem.protocols.prestress import EndTension
    from cpp_dem.scene import apply_threads

    path = Path(path)
    extra = read_extra(path)
    p = params_from(extra, path)
    apply_threads(p.threads)
    targets = np.asarray(extra["targets_pa"], float)
    quiet = lambda _m: None  # noqa: E731 (the skeleton's build says nothing worth saying)
    try:
        # (the grow stress only sets the disabled growth controller's target, which the
        # checkpoint replaces)
        sample, grid = prepare_woven_element(p, max(float(np.mean(targets)), 1.0), log=quiet,
                                             build_only=True)
        sc = sample.scene
        load_checkpoint(path, sc)
        ps = load_variant(sample, grid, p, bool(extra["prestressed"]), log=quiet,
                          build_only=True)
        t_ends = extra["grid_end_tension_n_per_m"]
        ends = EndTension(sc, grid) if t_ends is not None else None
        # Again: the grips' held DOFs, the velocities and the end forces as the run left them.
        load_checkpoint(path, sc)
    except ParameterError as e:
        raise RunFileError(f"{path}: the element cannot be restored: {e}") from None
    if ps is not None:
        ps.locked = bool(extra["prestress_locked"])
    if ends is not None:
        ends.tension_per_m = float(t_ends)  # (its forces: the checkpoint's)
        _ends_as_pulled(ends)
    ctl = sample.controller
    for a, (mode, goal) in enumerate(zip(extra["modes"], extra["set_points"])):
        if mode == "stress":
            ctl.set_stress(a, float(goal))
        elif mode == "strain_rate":
            ctl.set_strain_rate(a, 0.0)  # (held where it is)
        else:
            raise RunFileError(f"{path}: modes[{a}]={mode!r}: must be 'stress' or "
                               "'strain_rate'")
    ctl.enabled = True
    log(f"{extra['label']}: restored from {path} at step {sc.step_count} (t = {sc.time:.4g} s):"
        f" walls servoing at {np.round(np.array(extra['set_points']) / 1e3, 3).tolist()} kPa "
        f"({', '.join(extra['modes'])})"
        + ("" if ends is None else f", grid ends pulled by {float(t_ends):g} N/m")
        + ("" if ps is None else
           f", prestress grips {'locked' if ps.locked else 'released'}"))
    return Restored(sample=sample, grid=grid, p=p, extra=extra, prestress=ps, ends=ends,
                    path=path)


def run_on(r: Restored, steps: int, log: Callable[[str], None] = _log) -> dict:
    """Runs the restored element ``steps`` steps; returns the result (the JSON line's keys)."""
    from cpp_dem import measure
    from cpp_dem.elements.box import _Rate, held_stresses

    sample = r.sample
    sc, walls = sample.scene, sample.walls
    rate = _Rate(sample)  # (marks the box's size and the time now)
    size0 = measure.box_size(sc, walls)
    t0 = last = time.perf_counter()
    done = 0
    while done < steps:
        k = min(CHUNK, steps - done)
        sc.run(k)
        done += k
        now = time.perf_counter()
        if now - last > PROGRESS_S and done < steps:
            last = now
            eta = (now - t0) / done * (steps - done)
            log(f"{r.extra['label']}: step {done}/{steps}, walls "
                f"{np.round(held_stresses(sample) / 1e3, 3).tolist()} kPa, about {eta:.0f} s "
                "left")
    stress = held_stresses(sample)
    added = (size0 - measure.box_size(sc, walls)) / size0
    pressure = float(np.mean(np.abs(stress)))
    inertial = rate.inertial(rate.strain_rate(size0), pressure)
    return {"label": r.extra["label"], "steps": int(steps),
            "added_strain": [float(x) for x in added],
            "stress_pa": [float(x) for x in stress],
            "inertial_number": float(inertial)}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def continue_element(run_dir, label: str, steps, *, out=None, overwrite: bool = False,
                     log: Callable[[str], None] = _log) -> dict:
    """Restores ``label`` of ``run_dir`` (its <label>_final.h5), runs ``steps`` steps (0:
    restore only) and returns the result {"label", "steps", "added_strain", "stress_pa",
    "inertial_number"}. Writes nothing into ``run_dir``; with ``out`` the continued state
    (<label>_final.h5) and <label>_continue.json go there. Bad arguments raise UsageError,
    a state that cannot be restored RunFileError, each naming the field."""
    from cpp_dem.elements.box import save_final_state

    n = check_steps(steps, least=0)
    path = find_state(run_dir, label)
    o = check_out(out, run_dir, label, overwrite)
    t_wall = time.perf_counter()
    r = restore_element(path, log=log)
    if r.extra["label"] != label:
        raise RunFileError(f"{path}: holds the element {r.extra['label']!r}, not {label!r} "
                           "(renamed?)")
    sc = r.sample.scene
    step0, time0 = int(sc.step_count), float(sc.time)
    res = run_on(r, n, log=log)
    log(f"{label}: {n} steps: added strain {np.round(res['added_strain'], 8).tolist()}, "
        f"inertial number {res['inertial_number']:.3g} ({time.perf_counter() - t_wall:.1f} s)")
    if o is not None:
        o.mkdir(parents=True, exist_ok=True)
        x = r.extra
        save_final_state(o / f"{label}{FINAL_SUFFIX}", r.sample, r.p, x["targets_pa"],
                         prestressed=bool(x["prestressed"]), label=label, ends=r.ends,
                         prestress=r.prestress)
        summary = {**res, "run_dir": str(run_dir), "source": str(path),
                   "source_sha256": _sha256(path), "step_start": step0,
                   "step_end": int(sc.step_count), "time_start_s": time0,
                   "time_end_s": float(sc.time), "targets_pa": x["targets_pa"],
                   "set_points": x["set_points"], "modes": x["modes"],
                   "grid_end_tension_n_per_m": x["grid_end_tension_n_per_m"],
                   "prestress_locked": x["prestress_locked"],
                   "unbalanced_force_end": float(sc.unbalanced_force()),
                   "state": f"{label}{FINAL_SUFFIX}",
                   "wall_time_s": time.perf_counter() - t_wall,
                   "units": "SI; stresses compression positive; strains compression positive"}
        write_atomic(o / f"{label}_continue.json", json.dumps(summary, indent=2) + "\n")
        log(f"{label}: the continued state in {o / (label + FINAL_SUFFIX)}")
    if not math.isfinite(res["inertial_number"]):
        log(f"WARNING: {label}: the inertial number is not finite")
    return res


def main_continue(run_dir: str, label: str, steps: str, out, overwrite: bool) -> None:
    """The ``continue`` subcommand: checks the arguments (--steps at least 1), runs, prints
    the result as one JSON line on stdout (everything else goes to stderr)."""
    import contextlib

    n = check_steps(steps, least=1)
    find_state(run_dir, label)
    check_out(out, run_dir, label, overwrite)
    with contextlib.redirect_stdout(sys.stderr):  # (stdout holds the one JSON line only)
        res = continue_element(run_dir, label, n, out=out, overwrite=overwrite)
    print(json.dumps(res), flush=True)
