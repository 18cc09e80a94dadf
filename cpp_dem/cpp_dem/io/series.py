"""The series a recorder samples: definitions, evaluation, checks (cpp_dem.io)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np



# ---------------------------------------------------------------------------------------------
# Series definitions
# ---------------------------------------------------------------------------------------------

#: Per-body arrays a snapshot can hold: scene attribute -> units.
SNAPSHOT_FIELDS: dict[str, str] = {
    "positions": "m",
    "velocities": "m/s",
    "angular_velocities": "rad/s",
    "radii": "m",
    "masses": "kg",
    "forces": "N",
    "torques": "N m",
    "orientations": "-",
    "clump_ids": "-",
    "clump_positions": "m",
    "clump_velocities": "m/s",
    "clump_angular_velocities": "rad/s",
    "clump_orientations": "-",
    "clump_masses": "kg",
}

#: Stored with every snapshot of a scene that has clumps (per body: its clump, -1 free; per
#: clump: centre of mass, orientation of the principal frame (w, x, y, z)).
CLUMP_SNAPSHOT_FIELDS = ("clump_ids", "clump_positions", "clump_orientations")

Series = Mapping[str, Any]  # name -> callable(scene) | (callable | None, units)

#: Names of the six walls of a box in series names (order of ``cpp_dem.BOX_WALLS``).
_BOX_WALL_TAGS = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


def standard_series(scene=None, *, energies: bool = True, walls: bool = True
                    ) -> dict[str, tuple[Callable | None, str]]:
    """The usual series of a scene, name -> (callable(scene), units).

    - ``time`` (s), ``step`` (-), ``dt`` (s), ``num_contacts`` (-), ``unbalanced_force`` (-;
      NaN without contacts), ``max_speed`` (m/s);
    - with ``energies`` (needs ``scene.track_energy = True``): ``kinetic``, ``elastic``,
      ``gravity_potential``, ``friction``, ``viscous``, ``local_damping``, ``wall_work``,
      ``external_work``, ``balance_error`` (J) and ``balance_error_relative`` (-);
    - with ``walls`` and a ``scene`` that has walls: ``wall_force_<k>`` for every wall k
      (force the spheres exert on it, (3,) vector, N) and ``wall_position_<k>`` (m), with
      k = ``xmin, xmax, ymin, ymax, zmin, zmax`` for the first six walls (the order of
      ``cpp_dem.BOX_WALLS``: x-, x+, y-, y+, z-, z+; the floor of a box is ``zmin``) and the
      wall index for further walls; for every cylindrical wall k, ``cylinder_radius_<k>`` (m)
      and ``cylinder_normal_force_<k>`` (N, compressive positive: its pressure times its
      lateral area).
    """
    s: dict[str, tuple[Callable | None, str]] = {
        "time": (lambda sc: float(sc.time), "s"),
        "step": (lambda sc: int(sc.step_count), "-"),
        "dt": (lambda sc: float(sc.dt), "s"),
        "num_contacts": (lambda sc: int(sc.num_active_contacts), "-"),
        "unbalanced_force": (lambda sc: float(sc.unbalanced_force()), "-"),
        "max_speed": (lambda sc: float(np.sqrt((np.asarray(sc.velocities) ** 2).sum(1).max()))
                      if sc.num_bodies else 0.0, "m/s"),
    }
    if energies:
        for key in ("kinetic", "elastic", "gravity_potential", "friction", "viscous",
                    "local_damping", "wall_work", "external_work", "balance_error"):
            s[key] = (lambda sc, k=key: float(sc.energies()[k]), "J")
        s["balance_error_relative"] = (lambda sc: float(sc.energies()["balance_error_relative"]),
                                       "-")
    if walls and scene is not None and getattr(scene, "num_walls", 0):
        for w in range(int(scene.num_walls)):
            tag = _BOX_WALL_TAGS[w] if w < len(_BOX_WALL_TAGS) else str(w)
            s[f"wall_force_{tag}"] = (lambda sc, w=w: np.asarray(sc.wall_forces)[w].copy(), "N")
            s[f"wall_position_{tag}"] = (lambda sc, w=w: float(np.asarray(sc.wall_positions)[w]),
                                         "m")
    if walls and scene is not None and getattr(scene, "num_cylinder_walls", 0):
        for w in range(int(scene.num_cylinder_walls)):
            s[f"cylinder_radius_{w}"] = (lambda sc, w=w: float(sc.cylinder_wall(w)["radius"]),
                                         "m")
            s[f"cylinder_normal_force_{w}"] = (
                lambda sc, w=w: float(sc.cylinder_wall(w)["normal_force"]), "N")
    return s


def _normalise_series(series: Series) -> dict[str, tuple[Callable | None, str]]:
    out: dict[str, tuple[Callable | None, str]] = {}
    for name, spec in series.items():
        if not isinstance(name, str) or not name or "/" in name:
            raise ValueError(f"series name {name!r}: must be a non-empty string without '/'")
        if callable(spec) or spec is None:
            fn, units = spec, ""
        else:
            try:
                fn, units = spec
            except (TypeError, ValueError):
                raise TypeError(f"series[{name!r}]: expected a callable or (callable, units), "
                                f"got {spec!r}") from None
            if fn is not None and not callable(fn):
                raise TypeError(f"series[{name!r}]: {fn!r} is not callable")
        out[name] = (fn, str(units))
    if not out:
        raise ValueError("series: at least one series is needed")
    return out


#: Series whose NaN is a documented value ("undefined"), not a failure: the unbalanced force of
#: a scene without contacts.
NAN_MEANS_UNDEFINED = frozenset({"unbalanced_force"})


class NonFiniteValueError(ValueError):
    """A recorder was handed an inf or NaN: it writes no such value (issue: no silent wrong
    results). The message names the series, the value and the step."""


def _series_for(series: Series | None, scene) -> dict[str, tuple[Callable | None, str]]:
    """A recorder's series: the given ones, or the scene's standard_series."""
    if series is None:
        if scene is None:
            raise ValueError("series: required when no scene is given")
        series = standard_series(scene)
    return _normalise_series(series)


def _evaluate(series: dict[str, tuple[Callable | None, str]], scene,
              values: Mapping[str, Any]) -> dict[str, np.ndarray]:
    unknown = set(values) - set(series)
    if unknown:
        raise KeyError(f"values for undeclared series {sorted(unknown)}; declared: "
                       f"{list(series)}")
    row: dict[str, np.ndarray] = {}
    for name, (fn, _units) in series.items():
        if name in values:
            v = values[name]
        elif fn is None:
            raise ValueError(f"series {name!r} has no callable: pass its value to record()")
        else:
            v = fn(scene)
        a = np.asarray(v)
        if a.dtype.kind not in "biuf":
            raise TypeError(f"series {name!r}: value {v!r} is not numeric")
        if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
            bad = ~np.isfinite(a)
            if not (name in NAN_MEANS_UNDEFINED and np.all(np.isnan(a[bad]))):
                step = getattr(scene, "step_count", None)
                raise NonFiniteValueError(
                    f"series {name!r}: value {v!r} is not finite"
                    + (f" at step {step}" if step is not None else "")
                    + "; the recorder writes no inf or NaN (the scene's state is not physical:"
                    " see cpp_dem.BlowUpError and the tunnelling check, docs/core.md)")
        row[name] = a
    return row


def _check_overwrite(path: Path, overwrite: bool, append: bool, what: str) -> str:
    """Returns the open mode ('x', 'w' or 'a') or raises FileExistsError."""
    if overwrite and append:
        raise ValueError("overwrite and append: choose one")
    if path.exists():
        if append:
            return "a"
        if overwrite:
            return "w"
        raise FileExistsError(
            f"{path}: exists; the {what} does not replace files silently. Pass overwrite=True "
            "to replace it, append=True to continue it, or choose another path.")
    return "x"


def _metadata_attr(value: Any) -> Any:
    """An HDF5-storable version of a metadata value (JSON text for anything nested)."""
    if isinstance(value, (bool, np.bool_)):
        return np.bool_(value)
    if isinstance(value, (int, float, np.integer, np.floating, str)):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        a = np.asarray(value)
        if a.dtype.kind in "biuf" and a.size > 0:
            return a
    return json.dumps(value, default=str)


# ---------------------------------------------------------------------------------------------
