"""Result files: VTK PolyData for ParaView, a PVD time-series index, and HDF5 / CSV recorders.

Everything is plain NumPy and text/HDF5 writing (no ``vtk`` package needed). SI units
throughout: m, s, kg, N, J, rad.

VTK (XML PolyData, ``.vtp``; open in ParaView, see ``docs/output.md``):

- :func:`write_vtk_spheres` — one point per sphere (centre, m) with point data ``radius`` (m),
  ``velocity`` (m/s), ``angular_velocity`` (rad/s), ``force`` (N), ``orientation`` (quaternion
  w, x, y, z) and ``id``; render with the Glyph filter (sphere glyph, scale by ``radius``,
  scale factor 2 since a glyph of size 1 has diameter 1).
- :func:`write_vtk_contacts` — the contact force network: one line per active sphere–sphere
  contact (between the two centres), cell data ``normal_force`` (N), ``force`` (N, on the
  second sphere), ``normal``, ``overlap`` (m).
- :func:`write_vtk_box` — the six faces of an axis-aligned box (walls), optionally with the
  wall forces (N) as cell data.
- :class:`PvdWriter` — a ``.pvd`` collection (time → file) rewritten atomically after every
  entry, so a crashed run leaves a valid index of the files written so far.

Recorders (append as the run goes, flush after every record):

- :class:`H5Recorder` — extendable HDF5 datasets of scalar or fixed-shape series under
  ``/series/<name>`` (``units`` attribute on each), snapshots of per-body arrays under
  ``/snapshots/NNNNNN``, run parameters as root attributes.
- :class:`CsvRecorder` — the same series as CSV rows.
- :func:`standard_series` — the usual scene series (time, step, energies, unbalanced force,
  wall forces) with their units; :func:`read_h5_series`, :func:`read_h5_snapshot`,
  :func:`read_csv_series` read the files back.
"""

from __future__ import annotations

import base64
import datetime as _dt
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence
from xml.sax.saxutils import quoteattr as _xml_quoteattr

import numpy as np

__all__ = [
    "SNAPSHOT_FIELDS",
    "CsvRecorder",
    "H5Recorder",
    "PvdWriter",
    "read_csv_series",
    "read_h5_series",
    "read_h5_snapshot",
    "standard_series",
    "write_vtk_box",
    "write_vtk_contacts",
    "write_vtk_spheres",
    "write_vtp",
]

PathLike = str | os.PathLike

# ---------------------------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------------------------


def _current_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _current_umask()


def _atomic_write_bytes(path: PathLike, data: bytes) -> None:
    """Writes ``data`` to ``path`` through a temporary file in the same directory and
    ``os.replace``, so readers never see a half-written file."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)  # as open() would (mkstemp makes it 0600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


_VTK_TYPES = {
    np.dtype(np.float64): "Float64",
    np.dtype(np.float32): "Float32",
    np.dtype(np.int64): "Int64",
    np.dtype(np.int32): "Int32",
    np.dtype(np.uint8): "UInt8",
}


def _as_vtk_array(values, name: str, n_tuples: int | None) -> np.ndarray:
    """Checks and converts one data array: 1-D (n,) or 2-D (n, k), a supported dtype."""
    a = np.asarray(values)
    if a.dtype.kind == "b":
        a = a.astype(np.uint8)
    elif a.dtype.kind in "iu":
        a = a.astype(np.int64)
    elif a.dtype.kind == "f":
        a = a.astype(np.float64)
    else:
        raise TypeError(f"{name}: dtype {a.dtype} cannot be written to VTK (numbers only)")
    if a.ndim not in (1, 2):
        raise ValueError(f"{name}: expected shape (n,) or (n, k), got {a.shape}")
    if n_tuples is not None and a.shape[0] != n_tuples:
        raise ValueError(f"{name}: has {a.shape[0]} rows, expected {n_tuples}")
    return np.ascontiguousarray(a)


def _data_array_xml(a: np.ndarray, name: str | None, encoding: str) -> str:
    """One ``<DataArray>`` element, ASCII or inline base64 binary (UInt64 size header)."""
    ncomp = 1 if a.ndim == 1 else a.shape[1]
    vtk_type = _VTK_TYPES[a.dtype]
    attrs = f'type="{vtk_type}"'
    if name is not None:
        attrs += f" Name={_xml_quoteattr(name)}"
    if ncomp != 1:
        attrs += f' NumberOfComponents="{ncomp}"'
    if encoding == "ascii":
        if a.dtype.kind == "f":
            body = " ".join(np.char.mod("%.17g", a.reshape(-1)))
        else:
            body = " ".join(str(int(v)) for v in a.reshape(-1))
        return f'<DataArray {attrs} format="ascii">{body}</DataArray>'
    raw = a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes()
    payload = base64.b64encode(np.uint64(len(raw)).astype("<u8").tobytes() + raw).decode()
    return f'<DataArray {attrs} format="binary">{payload}</DataArray>'


def _data_block_xml(tag: str, data: Mapping[str, np.ndarray], encoding: str) -> str:
    if not data:
        return f"<{tag}/>"
    parts = [_data_array_xml(a, name, encoding) for name, a in data.items()]
    return f"<{tag}>\n" + "\n".join(parts) + f"\n</{tag}>"


def write_vtp(path: PathLike, points, *, verts: bool = False, lines=None, polys=None,
              point_data: Mapping[str, Any] | None = None,
              cell_data: Mapping[str, Any] | None = None,
              field_data: Mapping[str, Any] | None = None,
              encoding: str = "binary") -> Path:
    """Writes a VTK XML PolyData file (``.vtp``); the building block of the writers here.

    Parameters
    ----------
    path : output file; must end in ``.vtp``. Written atomically.
    points : point coordinates (n, 3), m.
    verts : if True, one vertex cell per point (so ParaView shows the points as they are).
    lines : (k, 2) point indices of line cells, or None.
    polys : (k, m) point indices of polygon cells (all with m corners), or None.
    point_data : name -> (n,) or (n, c) array.
    cell_data : name -> array with one row per cell, cells ordered verts, lines, polys.
    field_data : name -> 1-D array of whole-dataset values (e.g. ``TimeValue``, s).
    encoding : ``"binary"`` (inline base64, compact and lossless) or ``"ascii"``.

    Returns the path written.
    """
    path = Path(path)
    if path.suffix != ".vtp":
        raise ValueError(f"path={str(path)!r}: a VTK XML PolyData file must end in '.vtp'")
    if encoding not in ("binary", "ascii"):
        raise ValueError(f"encoding={encoding!r}: must be 'binary' or 'ascii'")
    pts = _as_vtk_array(np.asarray(points, dtype=float).reshape(-1, 3), "points", None)
    n = len(pts)
    n_verts = n if verts else 0
    line_conn = (np.zeros((0, 2), dtype=np.int64) if lines is None
                 else np.asarray(lines, dtype=np.int64).reshape(-1, 2))
    poly_conn = (np.zeros((0, 3), dtype=np.int64) if polys is None
                 else np.atleast_2d(np.asarray(polys, dtype=np.int64)))
    for name, conn in (("lines", line_conn), ("polys", poly_conn)):
        if conn.size and (conn.min() < 0 or conn.max() >= n):
            raise ValueError(f"{name}: point index out of range [0, {n})")
    n_cells = n_verts + len(line_conn) + len(poly_conn)
    pd = {k: _as_vtk_array(v, f"point_data[{k!r}]", n) for k, v in (point_data or {}).items()}
    cd = {k: _as_vtk_array(v, f"cell_data[{k!r}]", n_cells) for k, v in (cell_data or {}).items()}
    fd = {k: _as_vtk_array(np.atleast_1d(v), f"field_data[{k!r}]", None)
          for k, v in (field_data or {}).items()}

    def cells(tag: str, conn: np.ndarray) -> str:
        if len(conn) == 0:
            return ""
        offsets = np.arange(1, len(conn) + 1, dtype=np.int64) * conn.shape[1]
        return (f"<{tag}>\n"
                + _data_array_xml(conn.reshape(-1), "connectivity", encoding) + "\n"
                + _data_array_xml(offsets, "offsets", encoding) + f"\n</{tag}>\n")

    out = ['<?xml version="1.0"?>',
           '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" '
           'header_type="UInt64">',
           "<PolyData>"]
    if fd:
        fields = []
        for k, a in fd.items():
            fields.append(_data_array_xml(a, k, encoding).replace(
                "<DataArray ", f'<DataArray NumberOfTuples="{len(a)}" ', 1))
        out.append("<FieldData>\n" + "\n".join(fields) + "\n</FieldData>")
    out.append(f'<Piece NumberOfPoints="{n}" NumberOfVerts="{n_verts}" '
               f'NumberOfLines="{len(line_conn)}" NumberOfStrips="0" '
               f'NumberOfPolys="{len(poly_conn)}">')
    out.append(_data_block_xml("PointData", pd, encoding))
    out.append(_data_block_xml("CellData", cd, encoding))
    out.append("<Points>\n" + _data_array_xml(pts, "Points", encoding) + "\n</Points>")
    body = cells("Verts", np.arange(n_verts, dtype=np.int64).reshape(-1, 1))
    body += cells("Lines", line_conn) + cells("Polys", poly_conn)
    if body:
        out.append(body.rstrip("\n"))
    out += ["</Piece>", "</PolyData>", "</VTKFile>", ""]
    _atomic_write_bytes(path, "\n".join(out).encode("utf-8"))
    return path


def _time_field(scene) -> dict[str, np.ndarray]:
    return {"TimeValue": np.array([float(scene.time)])} if scene is not None else {}


# ---------------------------------------------------------------------------------------------
# VTK writers
# ---------------------------------------------------------------------------------------------


def write_vtk_spheres(path: PathLike, scene, *, extra_point_data: Mapping[str, Any] | None = None,
                      encoding: str = "binary") -> Path:
    """Writes the spheres of ``scene`` as a ``.vtp`` point cloud (one vertex per sphere).

    Points are the centres (m). Point data: ``radius`` (m), ``velocity`` (m/s),
    ``angular_velocity`` (rad/s), ``force`` (resultant at the last step, N), ``orientation``
    (unit quaternion w, x, y, z, -), ``id`` (body index, -), plus ``extra_point_data``
    (name -> (n,) or (n, k) array). Field data ``TimeValue`` holds the scene time (s).

    In ParaView: Glyph filter, glyph type Sphere, Scale Array ``radius``, Scale Factor 2
    (ParaView's unit sphere glyph has diameter 1), Glyph Mode "All Points".
    """
    n = int(scene.num_bodies)
    pd: dict[str, Any] = {
        "radius": scene.radii,
        "velocity": scene.velocities,
        "angular_velocity": scene.angular_velocities,
        "force": scene.forces,
        "orientation": scene.orientations,
        "id": np.arange(n, dtype=np.int64),
    }
    if extra_point_data:
        for k, v in extra_point_data.items():
            if k in pd:
                raise ValueError(f"extra_point_data[{k!r}]: clashes with a standard array")
            pd[k] = v
    return write_vtp(path, scene.positions, verts=True, point_data=pd,
                     field_data=_time_field(scene), encoding=encoding)


def write_vtk_contacts(path: PathLike, scene, *, include_walls: bool = False,
                       encoding: str = "binary") -> Path:
    """Writes the contact force network of ``scene`` as ``.vtp`` lines.

    Points are all sphere centres (m) — point data ``radius`` (m) — so point indices equal
    body ids. One line per active sphere–sphere contact, between the two centres, with cell
    data ``normal_force`` (N, > 0 in compression, includes the viscous part), ``force``
    (total contact force on the second sphere, N), ``normal`` (unit, from the first to the
    second sphere), ``overlap`` (m) and ``kind`` (0: sphere–sphere, 1: sphere–wall).

    With ``include_walls`` the sphere–wall contacts are added as lines from the centre to the
    contact point on the wall (extra points appended after the centres).

    In ParaView: Tube filter, Vary Radius "By Scalar" with ``normal_force``, colour by
    ``normal_force``.
    """
    c = scene.contacts()
    ids = np.asarray(c["ids"], dtype=np.int64).reshape(-1, 2)
    pair = ids[:, 1] >= 0
    wall = ~pair if include_walls else np.zeros(len(ids), dtype=bool)
    pos = np.asarray(scene.positions, dtype=float).reshape(-1, 3)
    radii = np.asarray(scene.radii, dtype=float).reshape(-1)
    n = len(pos)
    points = [pos]
    lines = [ids[pair]]
    if wall.any():
        b = ids[wall, 0]
        nrm = np.asarray(c["normal"], dtype=float)[wall]
        ov = np.asarray(c["overlap"], dtype=float)[wall]
        # The wall normal points from the wall to the sphere: the contact point is
        # centre - (R - overlap/2) n (as in the core's contact geometry).
        points.append(pos[b] - (radii[b] - 0.5 * ov)[:, None] * nrm)
        lines.append(np.column_stack([b, n + np.arange(len(b))]))
    order = np.concatenate([np.flatnonzero(pair), np.flatnonzero(wall)])
    extra = len(points[1]) if len(points) > 1 else 0
    cd = {
        "normal_force": np.asarray(c["normal_force"], dtype=float)[order],
        "force": np.asarray(c["force"], dtype=float).reshape(-1, 3)[order],
        "normal": np.asarray(c["normal"], dtype=float).reshape(-1, 3)[order],
        "overlap": np.asarray(c["overlap"], dtype=float)[order],
        "kind": np.concatenate([np.zeros(int(pair.sum()), np.int64),
                                np.ones(int(wall.sum()), np.int64)]),
    }
    return write_vtp(path, np.vstack(points), lines=np.vstack(lines),
                     point_data={"radius": np.concatenate([radii, np.zeros(extra)])},
                     cell_data=cd, field_data=_time_field(scene), encoding=encoding)


def write_vtk_box(path: PathLike, lo: Sequence[float], hi: Sequence[float], *,
                  wall_forces=None, time: float | None = None,
                  encoding: str = "binary") -> Path:
    """Writes the six faces of the box [lo, hi] (m) as ``.vtp`` quads, in the wall order of
    :meth:`cpp_dem.Scene.add_box` (x-, x+, y-, y+, z-, z+), cell data ``wall`` (index) and,
    if given, ``force`` = ``wall_forces`` (6, 3) in N (e.g. ``scene.wall_forces[:6]``).
    ``time`` (s) goes to field data ``TimeValue``. Show it with Opacity < 1 or as Wireframe.
    """
    lo_a = np.asarray(lo, dtype=float).reshape(3)
    hi_a = np.asarray(hi, dtype=float).reshape(3)
    corners = np.array([[(hi_a if (k >> a) & 1 else lo_a)[a] for a in range(3)]
                        for k in range(8)])  # corner k: bit a set -> hi along axis a
    faces = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        for side in (0, 1):
            quad = []
            for u, v in ((0, 0), (1, 0), (1, 1), (0, 1)):
                k = (side << axis) | (u << others[0]) | (v << others[1])
                quad.append(k)
            faces.append(quad)
    cd: dict[str, Any] = {"wall": np.arange(6, dtype=np.int64)}
    if wall_forces is not None:
        cd["force"] = np.asarray(wall_forces, dtype=float).reshape(6, 3)
    fd = {"TimeValue": np.array([float(time)])} if time is not None else None
    return write_vtp(path, corners, polys=np.array(faces), cell_data=cd, field_data=fd,
                     encoding=encoding)


class _ClosesOnExit:
    """Context-manager protocol for the writers here: ``with`` closes, and so (best effort)
    does garbage collection. Subclasses define an idempotent ``close()``."""

    def close(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass


class PvdWriter(_ClosesOnExit):
    """A ParaView ``.pvd`` collection: a list of (time, file) entries for a time series.

    Every :meth:`add` rewrites the (small) ``.pvd`` file atomically, so after a crash it is a
    valid index of the files written so far. File names are stored relative to the ``.pvd``
    file's directory. Open the ``.pvd`` in ParaView to get the time series.

    Parameters
    ----------
    path : the ``.pvd`` file.
    overwrite : if the file exists, start a new collection (True) instead of raising
        ``FileExistsError``. ``append=True`` continues an existing collection.
    """

    def __init__(self, path: PathLike, *, overwrite: bool = False, append: bool = False) -> None:
        self.path = Path(path)
        if self.path.suffix != ".pvd":
            raise ValueError(f"path={str(self.path)!r}: must end in '.pvd'")
        if overwrite and append:
            raise ValueError("overwrite and append: choose one")
        self.entries: list[tuple[float, str, int]] = []
        if self.path.exists():
            if append:
                self.entries = self._read_entries(self.path)
            elif not overwrite:
                raise FileExistsError(
                    f"{self.path}: exists; pass overwrite=True to replace it or append=True "
                    "to continue it")
        self._write()

    @staticmethod
    def _read_entries(path: Path) -> list[tuple[float, str, int]]:
        import xml.etree.ElementTree as ET

        root = ET.parse(path).getroot()
        return [(float(e.get("timestep", "0")), e.get("file", ""), int(e.get("part", "0")))
                for e in root.iter("DataSet")]

    def add(self, time: float, file: PathLike, *, part: int = 0) -> None:
        """Adds the data file ``file`` at simulated ``time`` (s) and rewrites the ``.pvd``.

        A relative ``file`` is relative to the ``.pvd`` file's directory (as ParaView reads
        it); an absolute one is converted to that. ``part`` distinguishes several files at the same time (e.g. spheres 0, contacts 1).
        """
        f = Path(file)
        if f.is_absolute():
            try:
                f = Path(os.path.relpath(f, self.path.parent.resolve()))
            except ValueError:  # another drive (Windows): keep it absolute
                pass
        self.entries.append((float(time), f.as_posix(), int(part)))
        self._write()

    def _write(self) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
                 "<Collection>"]
        for t, f, p in self.entries:
            lines.append(f'  <DataSet timestep="{t!r}" group="" part="{p}" '
                         f"file={_xml_quoteattr(f)}/>")
        lines += ["</Collection>", "</VTKFile>", ""]
        _atomic_write_bytes(self.path, "\n".join(lines).encode("utf-8"))

    def close(self) -> None:
        """Nothing to release (the file is complete after every :meth:`add`); for symmetry."""


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
}

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
      wall index for further walls.
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
# HDF5 recorder
# ---------------------------------------------------------------------------------------------


class H5Recorder(_ClosesOnExit):
    """Appends time series and snapshots to an HDF5 file as a run goes.

    Layout::

        /                      attrs: run parameters (``metadata``), ``parameters_json``,
                               ``format``, ``created_utc``
        /series                attrs: ``num_records`` (rows that are complete),
                               ``units_json`` (the declared series and their units)
        /series/<name>         dataset (num_records, *shape), maxshape (None, *shape),
                               attrs ``units``; float series are filled with NaN
        /snapshots/NNNNNN      group per snapshot (NNNNNN = snapshot index, 0, 1, ...),
                               attrs ``time`` (s), ``step``, ``complete``; one dataset per
                               field (e.g. ``positions`` (n, 3), m) with attr ``units``

    The file is flushed after every :meth:`record` and :meth:`snapshot`, so a crash loses at
    most the record being written. ``/series`` attribute ``num_records`` is updated last:
    readers (and :func:`read_h5_series`) trust only that many rows.

    Parameters
    ----------
    path : HDF5 file.
    scene : the scene the series callables are evaluated on, or None (then pass ``scene=``
        or the values themselves to :meth:`record`).
    series : name -> callable(scene) or (callable | None, units). A callable returns a scalar
        or a fixed-shape array (e.g. a (3,) wall force); the shape is fixed by the first
        record. Default: :func:`standard_series` of ``scene``.
    snapshot_fields : per-body scene attributes stored by :meth:`snapshot`
        (see ``SNAPSHOT_FIELDS`` for names and units).
    metadata : run parameters, stored as root attributes (nested values as JSON text) and
        all together as ``parameters_json``.
    overwrite : replace an existing file. Without it (and without ``append``) an existing
        file raises ``FileExistsError``: results are never destroyed silently.
    append : continue an existing file: the series must match the stored ones; rows past
        ``num_records`` (a crashed record) are dropped; snapshot numbering continues.
    compression : HDF5 compression for snapshot arrays (e.g. ``"gzip"``) or None.
    """

    FORMAT = "cpp_dem.H5Recorder/1"

    def __init__(self, path: PathLike, scene=None, *, series: Series | None = None,
                 snapshot_fields: Sequence[str] = ("positions", "velocities", "radii"),
                 metadata: Mapping[str, Any] | None = None, overwrite: bool = False,
                 append: bool = False, compression: str | None = None,
                 chunk_rows: int = 256) -> None:
        import h5py

        self.path = Path(path)
        self.scene = scene
        if series is None:
            if scene is None:
                raise ValueError("series: required when no scene is given")
            series = standard_series(scene)
        self.series = _normalise_series(series)
        for f in snapshot_fields:
            if f not in SNAPSHOT_FIELDS:
                raise ValueError(f"snapshot_fields: unknown field {f!r}; known: "
                                 f"{list(SNAPSHOT_FIELDS)}")
        self.snapshot_fields = tuple(snapshot_fields)
        self.compression = compression
        self.chunk_rows = int(chunk_rows)
        mode = _check_overwrite(self.path, overwrite, append, "H5Recorder")
        self._file = h5py.File(self.path, mode)
        try:
            self._open(mode, metadata or {})
        except BaseException:
            self._file.close()
            raise

    def _open(self, mode: str, metadata: Mapping[str, Any]) -> None:
        f = self._file
        if mode == "a":
            if f.attrs.get("format") != self.FORMAT or "series" not in f:
                raise ValueError(f"{self.path}: not a {self.FORMAT} file; cannot append")
            g = f["series"]
            stored = set(json.loads(g.attrs.get("units_json", "{}"))) | set(g.keys())
            if stored != set(self.series):
                raise ValueError(f"{self.path}: stored series {sorted(stored)} differ from "
                                 f"the requested {sorted(self.series)}; cannot append")
            self.num_records = int(g.attrs.get("num_records", 0))
            for name, (_fn, units) in self.series.items():
                if name not in g:  # declared, never recorded
                    continue
                ds = g[name]
                if units and ds.attrs.get("units", "") != units:
                    raise ValueError(f"{self.path}: series {name!r} stored in "
                                     f"{ds.attrs.get('units')!r}, requested {units!r}")
                if ds.shape[0] != self.num_records:  # a crash inside record(): drop the row
                    ds.resize(self.num_records, axis=0)
            snaps = f.require_group("snapshots")
            done = [int(k) for k in snaps.keys() if k.isdigit()]
            self.num_snapshots = max(done) + 1 if done else 0
            old = json.loads(f.attrs.get("parameters_json", "{}"))
            for k, v in metadata.items():
                new = json.loads(json.dumps(v, default=str))
                if k in old and old[k] != new:
                    raise ValueError(f"{self.path}: metadata {k!r}={new!r} differs from the "
                                     f"stored {old[k]!r}; cannot append")
            merged = {**old, **json.loads(json.dumps(dict(metadata), default=str))}
            self._write_metadata(merged)
        else:
            f.attrs["format"] = self.FORMAT
            f.attrs["created_utc"] = _dt.datetime.now(_dt.timezone.utc).isoformat()
            self._write_metadata(json.loads(json.dumps(dict(metadata), default=str)))
            g = f.create_group("series")
            g.attrs["num_records"] = 0
            g.attrs["units_json"] = json.dumps({k: u for k, (_f, u) in self.series.items()})
            f.create_group("snapshots")
            self.num_records = 0
            self.num_snapshots = 0
        f.flush()

    def _write_metadata(self, metadata: Mapping[str, Any]) -> None:
        f = self._file
        for k, v in metadata.items():
            if k in ("format", "created_utc", "parameters_json"):
                raise ValueError(f"metadata key {k!r} is reserved")
            f.attrs[k] = _metadata_attr(v)
        f.attrs["parameters_json"] = json.dumps(dict(metadata), default=str, sort_keys=True)

    # -- writing -------------------------------------------------------------------------------
    def record(self, scene=None, **values: Any) -> None:
        """Appends one row to every series and flushes the file.

        Each series is evaluated as ``callable(scene)`` (``scene`` defaults to the recorder's
        scene) unless its value is given by keyword, e.g. ``record(time=0.1, kinetic=2e-3)``.
        """
        if self._file is None:
            raise ValueError(f"{self.path}: recorder is closed")
        sc = scene if scene is not None else self.scene
        row = _evaluate(self.series, sc, values)
        g = self._file["series"]
        k = self.num_records
        for name, a in row.items():
            if name not in g:
                dtype = np.float64 if a.dtype.kind == "f" else np.int64
                if a.dtype.kind == "b":
                    dtype = np.int8
                ds = g.create_dataset(
                    name, shape=(0,) + a.shape, maxshape=(None,) + a.shape, dtype=dtype,
                    chunks=(self.chunk_rows,) + a.shape,
                    fillvalue=np.nan if dtype == np.float64 else 0)
                ds.attrs["units"] = self.series[name][1]
            ds = g[name]
            if ds.shape[1:] != a.shape:
                raise ValueError(f"series {name!r}: value of shape {a.shape}, the stored "
                                 f"rows have shape {ds.shape[1:]}")
            ds.resize(k + 1, axis=0)
            ds[k] = a
        g.attrs["num_records"] = k + 1
        self.num_records = k + 1
        self._file.flush()

    def snapshot(self, scene=None, *, fields: Sequence[str] | None = None,
                 extra: Mapping[str, tuple[Any, str]] | None = None) -> str:
        """Stores per-body arrays in a new group ``/snapshots/NNNNNN``; returns its name.

        ``fields`` defaults to the recorder's ``snapshot_fields``; ``extra`` adds arrays as
        name -> (array, units). The group's attrs hold ``time`` (s) and ``step`` of the scene
        and ``complete`` = True once every array is written. Flushes the file.
        """
        if self._file is None:
            raise ValueError(f"{self.path}: recorder is closed")
        sc = scene if scene is not None else self.scene
        if sc is None and fields:
            raise ValueError("snapshot: no scene to read the fields from")
        fields = self.snapshot_fields if fields is None else tuple(fields)
        name = f"{self.num_snapshots:06d}"
        g = self._file["snapshots"].create_group(name)
        g.attrs["complete"] = False
        if sc is not None:
            g.attrs["time"] = float(sc.time)
            g.attrs["step"] = int(sc.step_count)
        items: list[tuple[str, Any, str]] = []
        for fld in fields if sc is not None else ():
            if fld not in SNAPSHOT_FIELDS:
                raise ValueError(f"fields: unknown field {fld!r}; known: {list(SNAPSHOT_FIELDS)}")
            items.append((fld, getattr(sc, fld), SNAPSHOT_FIELDS[fld]))
        for k, (arr, units) in (extra or {}).items():
            items.append((k, arr, units))
        for k, arr, units in items:
            ds = g.create_dataset(k, data=np.asarray(arr), compression=self.compression)
            ds.attrs["units"] = units
        g.attrs["complete"] = True
        self.num_snapshots += 1
        self._file.flush()
        return name

    def flush(self) -> None:
        """Flushes the HDF5 file (done after every record and snapshot anyway)."""
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        """Flushes and closes the file. Idempotent."""
        if self._file is not None:
            self._file.flush()
            self._file.close()
            self._file = None

    @property
    def closed(self) -> bool:
        return self._file is None


def _open_h5_for_reading(path: PathLike):
    """Opens an HDF5 file read-only. If another process holds it open for writing (a live
    recorder: HDF5 file locking refuses the open), opens it again without locking; that is
    safe for the recorder's files, which are flushed after every record."""
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError as exc:
        if "lock" not in str(exc).lower():
            raise
        return h5py.File(path, "r", locking=False)


def read_h5_series(path: PathLike) -> dict[str, np.ndarray]:
    """Reads the series of an :class:`H5Recorder` file: name -> array (num_records, ...).

    Only the complete rows (``/series`` attr ``num_records``) are returned; a declared series
    without records comes back empty. Works on a file
    that a live recorder is still writing (from another process the file is opened with HDF5
    file locking off) and on the file of a crashed run. Units: ``h5py.File(path)["series"][name].attrs["units"]``.
    """
    with _open_h5_for_reading(path) as f:
        g = f["series"]
        n = int(g.attrs.get("num_records", 0))
        out = {k: np.zeros(0) for k in json.loads(g.attrs.get("units_json", "{}"))}
        out.update({k: g[k][:n] for k in g.keys()})
        return out


def read_h5_snapshot(path: PathLike, index: int = -1) -> dict[str, Any]:
    """Reads snapshot ``index`` (negative counts from the last complete one) of an
    :class:`H5Recorder` file: field -> array, plus ``time`` (s) and ``step``."""
    with _open_h5_for_reading(path) as f:
        g = f["snapshots"]
        names = sorted(k for k in g.keys() if g[k].attrs.get("complete", False))
        if not names:
            raise KeyError(f"{path}: no complete snapshot")
        s = g[names[index]]
        out: dict[str, Any] = {k: s[k][()] for k in s.keys()}
        out["time"] = float(s.attrs.get("time", math.nan))
        out["step"] = int(s.attrs.get("step", -1))
        out["name"] = names[index]
        return out


# ---------------------------------------------------------------------------------------------
# CSV recorder
# ---------------------------------------------------------------------------------------------


class CsvRecorder(_ClosesOnExit):
    """Writes series as CSV rows, one per :meth:`record`, flushed per row (and fsync'ed with
    ``fsync=True``).

    A plain CSV: the first line is the header, then one row per record; any CSV reader opens
    it as it is. The units are those of the series (``units``, the same as the ``units``
    attributes of an :class:`H5Recorder` file with the same series; for
    :func:`standard_series` see its docstring). A series with vector values (e.g. a (3,) wall
    force) takes one column per
    component: ``<name>_x``, ``<name>_y``, ``<name>_z`` for a (3,) vector, else ``<name>_0``,
    ``<name>_1``, ... over the flattened value (the shape is fixed by the first record). Read
    back with :func:`read_csv_series` (or ``numpy.genfromtxt(path, delimiter=",",
    names=True)``, ``pandas.read_csv(path)``).

    Parameters are those of :class:`H5Recorder`: ``path``, ``scene``, ``series``,
    ``overwrite``, ``append`` (the header must match).
    """

    def __init__(self, path: PathLike, scene=None, *, series: Series | None = None,
                 overwrite: bool = False, append: bool = False, fsync: bool = False) -> None:
        self.path = Path(path)
        self.scene = scene
        if series is None:
            if scene is None:
                raise ValueError("series: required when no scene is given")
            series = standard_series(scene)
        self.series = _normalise_series(series)
        self.fsync = fsync
        #: series name -> units
        self.units = {k: u for k, (_f, u) in self.series.items()}
        mode = _check_overwrite(self.path, overwrite, append, "CsvRecorder")
        self._columns: list[str] | None = None
        self._stored_header: list[str] | None = None
        self.num_records = 0
        if mode == "a":
            with open(self.path, encoding="utf-8") as fh:
                header = [ln.rstrip("\n") for ln in fh if ln.strip()]
            if header:
                self._stored_header = header[0].split(",")
                self.num_records = len(header) - 1
            self._fh = open(self.path, "a", encoding="utf-8", newline="")
        else:
            self._fh = open(self.path, "w" if mode == "w" else "x", encoding="utf-8", newline="")

    def _flush(self) -> None:
        self._fh.flush()
        if self.fsync:
            os.fsync(self._fh.fileno())

    def record(self, scene=None, **values: Any) -> None:
        """Appends one row (series evaluated as in :meth:`H5Recorder.record`) and flushes."""
        if self._fh is None:
            raise ValueError(f"{self.path}: recorder is closed")
        sc = scene if scene is not None else self.scene
        row = _evaluate(self.series, sc, values)
        cols: list[str] = []
        cells: list[str] = []
        for name, a in row.items():
            flat = a.reshape(-1)
            if a.ndim == 0:
                cols.append(name)
            elif a.shape == (3,):
                cols += [f"{name}_{c}" for c in "xyz"]
            else:
                cols += [f"{name}_{i}" for i in range(flat.size)]
            for v in flat:
                cells.append(str(int(v)) if a.dtype.kind in "biu" else repr(float(v)))
        if self._columns is None:
            if self._stored_header is not None:
                if self._stored_header != cols:
                    raise ValueError(f"{self.path}: stored columns {self._stored_header} differ "
                                     f"from {cols}; cannot append")
            else:
                self._fh.write(",".join(cols) + "\n")
            self._columns = cols
        elif cols != self._columns:
            raise ValueError(f"{self.path}: columns changed from {self._columns} to {cols}")
        self._fh.write(",".join(cells) + "\n")
        self.num_records += 1
        self._flush()

    def close(self) -> None:
        """Flushes and closes the file. Idempotent."""
        if self._fh is not None:
            self._fh.flush()
            self._fh.close()
            self._fh = None


def read_csv_series(path: PathLike) -> dict[str, np.ndarray]:
    """Reads a :class:`CsvRecorder` file: column name -> 1-D float array. Vector series come
    back as one column per component (``<name>_x`` ... or ``<name>_0`` ...). Lines with the
    wrong number of fields or non-numbers (e.g. a line cut by a crash) are skipped."""
    with open(path, encoding="utf-8") as fh:
        lines = [ln.rstrip("\n") for ln in fh if ln.strip()]
    if not lines:
        return {}
    cols = lines[0].split(",")
    rows = []
    for ln in lines[1:]:
        parts = ln.split(",")
        if len(parts) != len(cols):
            continue
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            continue
    data = np.asarray(rows, dtype=float).reshape(-1, len(cols))
    return {c: data[:, i].copy() for i, c in enumerate(cols)}
