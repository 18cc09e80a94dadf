"""VTK XML PolyData (.vtp) for ParaView and the PVD time-series index (cpp_dem.io)."""

from __future__ import annotations

import base64
import os
from pathlib import Path
from typing import Any, Mapping, Sequence
from xml.sax.saxutils import quoteattr as _xml_quoteattr

import numpy as np

from ._files import PathLike, _ClosesOnExit, _atomic_write_bytes


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

    Returns
    -------
    Path
        The path written.
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

#: The legend of the ``kind`` point-data array of :func:`write_vtk_spheres` (value -> what the
#: point is). A body is counted in the first of these that applies: geogrid node, bonded
#: sphere, clump member, free sphere.
SPHERE_KINDS: dict[int, str] = {
    0: "grain sphere (a free sphere, not in a clump)",
    1: "clump member (a sphere of a clumped grain)",
    2: "geogrid node (a node of a beam/PFacet geogrid, cpp_dem.build.geogrid)",
    3: "bonded sphere (a sphere of a bonded structure such as a woven geogrid)",
    -1: "a body kind this writer does not know (a newer core)",
}


def sphere_kinds(scene) -> np.ndarray:
    """Per body, the code of :data:`SPHERE_KINDS` (int64, (n,)), from what the scene knows:
    ``body_kinds`` (1 = geogrid node), ``bond_spheres`` (the spheres of a bond) and
    ``clump_ids`` (>= 0 for a clump member)."""
    n = int(scene.num_bodies)
    bk = np.asarray(scene.body_kinds, dtype=np.int64).reshape(n)
    kind = np.zeros(n, dtype=np.int64)
    if getattr(scene, "num_clumps", 0):
        kind[np.asarray(scene.clump_ids, dtype=np.int64).reshape(n) >= 0] = 1
    if getattr(scene, "num_bonds", 0):
        kind[np.asarray(scene.bond_spheres, dtype=np.int64).ravel()] = 3
    kind[bk == 1] = 2
    kind[(bk != 0) & (bk != 1)] = -1
    return kind


def write_vtk_spheres(path: PathLike, scene, *, extra_point_data: Mapping[str, Any] | None = None,
                      encoding: str = "binary") -> Path:
    """Writes the spheres of ``scene`` as a ``.vtp`` point cloud (one vertex per sphere).

    Points are the centres (m). Point data: ``radius`` (m), ``velocity`` (m/s),
    ``angular_velocity`` (rad/s), ``force`` (resultant at the last step, N), ``orientation``
    (unit quaternion w, x, y, z, -), ``id`` (body index, -), plus ``extra_point_data``
    (name -> (n,) or (n, k) array). Field data ``TimeValue`` holds the scene time (s).
    ``kind`` (-) tells what each point is (:data:`SPHERE_KINDS`: 0 grain sphere, 1 clump
    member, 2 geogrid node, 3 bonded sphere): a Threshold on ``kind`` shows the grains alone
    (0-1) or hides the geogrid nodes, which are bodies too (so that ``id`` is the body index
    and the contact file's point indices match) but are drawn by the geogrid's own file.
    With clumps in the scene, the members are the points, with ``clump_id`` (the clump's
    index, -1 for a free sphere) and ``clump_orientation`` (its clump's principal frame,
    w, x, y, z; the free spheres' own orientation); colour by ``clump_id`` to see grains.

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
        "kind": sphere_kinds(scene),
    }
    if getattr(scene, "num_clumps", 0):
        cid = np.asarray(scene.clump_ids, dtype=np.int64)
        q = np.asarray(scene.orientations).copy()
        m = cid >= 0
        q[m] = np.asarray(scene.clump_orientations)[cid[m]]
        pd["clump_id"] = cid
        pd["clump_orientation"] = q
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


def write_vtk_walls(path: PathLike, scene, *, segments: int = 48, infinite_length: float = 1.0,
                    encoding: str = "binary") -> Path:
    """Writes the scene's cylindrical and mesh walls (``Scene.add_cylinder_wall``,
    ``add_mesh_wall``) at their current places as one ``.vtp`` of polygons: each cylinder's
    lateral surface as ``segments`` quads of two triangles (an infinite one drawn ``infinite_length`` m long
    about its centre), each mesh's triangles. Cell data: ``kind`` (0 cylinder, 1 mesh) and
    ``wall`` (its index among its kind). Field data ``TimeValue``. Show it with Opacity < 1.
    """
    if not (isinstance(segments, int) and segments >= 3):
        raise ValueError(f"segments={segments!r}: must be an integer >= 3")
    if not (np.isfinite(infinite_length) and infinite_length > 0):
        raise ValueError(f"infinite_length={infinite_length!r}: must be > 0 (m)")
    points, polys, kind, index = [], [], [], []
    for k in range(int(getattr(scene, "num_cylinder_walls", 0))):
        w = scene.cylinder_wall(k)
        a = np.asarray(w["axis"], float)
        ref = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
        e1 = ref - ref.dot(a) * a
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(a, e1)
        lo = w["lo"] if np.isfinite(w["lo"]) else -0.5 * infinite_length
        hi = w["hi"] if np.isfinite(w["hi"]) else 0.5 * infinite_length
        base = sum(len(p) for p in points)
        phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
        ring = w["radius"] * (np.outer(np.cos(phi), e1) + np.outer(np.sin(phi), e2))
        c = np.asarray(w["centre"], float)
        points.append(np.vstack([c + lo * a + ring, c + hi * a + ring]))
        for i in range(segments):
            j = (i + 1) % segments
            polys += [[base + i, base + j, base + segments + j],
                      [base + i, base + segments + j, base + segments + i]]
            kind += [0, 0]
            index += [k, k]
    tri_points = []
    for k in range(int(getattr(scene, "num_mesh_walls", 0))):
        w = scene.mesh_wall(k)
        v = np.asarray(w["vertices"], float)
        base = sum(len(p) for p in points) + sum(len(p) for p in tri_points)
        tri_points.append(v)
        for t in np.asarray(w["triangles"]):
            polys.append([base + int(t[0]), base + int(t[1]), base + int(t[2])])
            kind.append(1)
            index.append(k)
    pts = np.vstack(points + tri_points) if points or tri_points else np.zeros((0, 3))
    cd = {"kind": np.asarray(kind, np.int64), "wall": np.asarray(index, np.int64)}
    return write_vtp(path, pts, polys=polys, cell_data=cd, field_data=_time_field(scene),
                     encoding=encoding)


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
