"""Clump templates from closed triangle surface meshes (STL, OBJ, PLY).

A grain given as a closed, consistently oriented triangle surface (vertices in m) becomes a
:class:`~cpp_dem.build.clumps.ClumpTemplate` of overlapping spheres:

- :func:`read_surface_mesh` reads STL (ascii and binary), OBJ and PLY with ``meshio`` and checks
  that the surface is closed and consistently oriented (outward normals; a globally inverted
  mesh is flipped by the sign of its volume).
- :func:`mesh_mass_properties` gives the exact volume, centroid and inertia of the polyhedron.
- :func:`fill_mesh` fills it with overlapping spheres (medial spheres, greedy coverage).
- :func:`fill_report` measures the trade between the sphere count, the volume error and the
  surface deviation of the filled template.
- :func:`shipped_templates` / :func:`shipped_template` load the angular gravel grains shipped in
  ``cpp_dem/build/data/grains`` (made by ``scripts/make_gravel_meshes.py``).
- :func:`shipped_fill` fills the same shipped meshes with another number of spheres (the
  cases' ``--grains clumps:gravel@N``, :func:`templates_from_spec`).

Mass properties of a polyhedron
-------------------------------
By the divergence theorem the volume integrals of 1, x and x x^T over a closed polyhedron are
sums over signed tetrahedra (reference point, triangle). For a tetrahedron with vertices 0, a,
b, c (relative to the reference point) the volume is V = det[a, b, c] / 6, the first moment
V (a + b + c) / 4 and the second moment V / 20 (a a^T + b b^T + c c^T + s s^T) with
s = a + b + c (Tonon, F. 2004, "Explicit exact formulas for the 3-D tetrahedron inertia tensor
in terms of its vertex coordinates", J. Math. Stat. 1(1):8-11; Eberly, D. 2002, "Polyhedral
mass properties (revisited)", Geometric Tools). These are exact up to rounding (the cube test
holds to 1e-12); a triangulated curved surface (an ellipsoid) differs from the smooth body by
its own O(h^2) discretisation error.

Filling: medial spheres chosen by greedy volume coverage
--------------------------------------------------------
:func:`fill_mesh` approximates the grain by a union of internal medial spheres chosen to cover
its volume, after Stolpner, S., Kry, P. and Siddiqi, K. (2012), "Medial spheres for shape
approximation", IEEE Trans. Pattern Anal. Mach. Intell. 34(6):1234-1240 (spheres inside the
solid and tangent to its boundary, selected greedily by the volume they cover), on a sampled
distance field:

1. A regular grid of sample points, spacing h = shortest bounding-box edge / ``grid``, is
   classified inside/outside by the parity of ray crossings along x (a ray that grazes an
   edge or vertex is moved by 1e-6 of the mesh size and cast again).
2. For each inside point p the exact distance d(p) to the surface (point-triangle distances,
   pruned by bounding spheres) is the radius of the largest ball centred at p inside the grain.
   On the ridges of d (the medial axis) these are the medial balls. Every sample point with
   d >= ``min_radius_ratio`` * max(d) gives a candidate ball (p, d(p)).
3. Greedy maximum coverage: add the candidate that covers the most not-yet-covered sample
   points (the uncovered volume it adds, in cells of h^3); ties go to the larger ball, then to
   a seeded random choice. Repeat until ``max_spheres`` spheres, until the covered fraction of
   the sample points reaches ``target_fill``, or until no candidate adds volume. The greedy
   choice is within 1 - 1/e of the best n-subset of the candidates for the covered volume
   (Nemhauser, G.L., Wolsey, L.A. and Fisher, M.L. 1978, "An analysis of approximations for
   maximizing submodular set functions I", Math. Program. 14:265-294).

``min_radius_ratio`` plays the part of the ``ratio`` (r_min / r_max) of PFC's bubble pack
(Taghavi, R. 2011, "Automatic clump generation based on mid-surface", Proc. 2nd Int.
FLAC/DEM Symposium, Melbourne, 791-797); there is no counterpart of its ``distance`` (a
smoothness angle): the sphere count and the coverage target control the smoothness here.

Every sphere lies inside the mesh (its radius is the exact distance from its centre to the
surface), so the template's volume is *smaller* than the mesh's: corners and edges are never
filled, and the fill error of a box stays large (about -16 % volume at 32 spheres, -11 % at
64). The spheres come out in the order chosen, so the first n spheres of a fill are the fill
with ``max_spheres = n``. Centres lie on the sample grid (radii are exact at those points);
going from grid = 20 to 30 changes the volume errors by at most 0.012 (cube and ellipsoid, 8 to
64 spheres) at about 8 times the cost. ``seed`` only
breaks ties (symmetric shapes) and draws the surface samples of :func:`fill_report`; the result
is deterministic for a given seed.

The "Euclidean map" generator of CLUMP (Angelidakis, V., Nadimi, S., Otsubo, M. and Utili, S.
2021, "CLUMP: A Code Library to generate Universal Multi-sphere Particles", SoftwareX 15,
100735) is the other distance-field method: it takes the largest ball inscribed in the region
not yet covered (sphere cores shrunk by an ``overlap`` factor). Tried here on the same kind of
grid (grid = 30), it left -25 % (cube) and -19 % (ellipsoid 1 : 0.75 : 0.5) of the volume at
32 spheres with overlap 0.6 (-21 % and -13 % with 0.9), against -16 % and -5 % for greedy
coverage, so it is not used.

Measured trade (``python -m cpp_dem.build.clump_mesh report cube`` etc.; the tables are in
docs/clump_templates.md).
"""

from __future__ import annotations

import functools
import math
import os
import re
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from cpp_dem._core import ParameterError
from cpp_dem.build.clumps import ClumpTemplate, MassProperties, _principal

__all__ = [
    "templates_from_spec",
    "read_surface_mesh",
    "read_triangle_mesh",
    "check_closed_mesh",
    "mesh_mass_properties",
    "fill_mesh",
    "fill_report",
    "format_report",
    "FillRow",
    "box_mesh",
    "ellipsoid_mesh",
    "convex_hull_mesh",
    "write_stl",
    "shipped_templates",
    "shipped_template",
    "shipped_mesh",
    "shipped_fill",
    "GRAIN_DIR",
    "SHIPPED_FILL",
    "SHIPPED_SPHERES",
    "MAX_SPHERES",
]

#: Folder of the shipped grain meshes (STL) and their templates (CSV).
GRAIN_DIR = Path(__file__).resolve().parent / "data" / "grains"


# --------------------------------------------------------------------------------------------
# Reading and checking meshes
# --------------------------------------------------------------------------------------------

def read_surface_mesh(path, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Reads a closed triangle surface from an STL (ascii or binary), OBJ or PLY file.

    scale: multiplies the file's coordinates to give m (1e-3 for a file in mm).
    Returns (vertices (n, 3) float, m; triangles (m, 3) int) as :func:`read_triangle_mesh`,
    checked by :func:`check_closed_mesh` (closed, consistently oriented, outward normals: a
    globally inverted mesh is flipped). Needs ``meshio`` (>= 5.3).
    """
    return check_closed_mesh(*read_triangle_mesh(path, scale))


def read_triangle_mesh(path, scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Reads a triangle surface, closed or open, from an STL (ascii or binary), OBJ or PLY file
    (a wall: ``Scene.add_mesh_wall``).

    scale: multiplies the file's coordinates to give m (1e-3 for a file in mm).
    Returns (vertices (n, 3) float, m; triangles (m, 3) int), duplicate vertices merged (exact
    coordinate matches: neighbouring triangles share their edges), unused vertices dropped,
    quads split into two triangles. Needs ``meshio`` (>= 5.3).
    """
    try:
        import meshio  # lazy: only needed to read files
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("reading a mesh file needs meshio (pip install 'meshio>=5.3')") from e
    path = os.fspath(path)
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ParameterError(f"scale={scale!r}: must be > 0 (file unit in m, e.g. 1e-3 for mm)")
    if not os.path.isfile(path):
        raise ParameterError(f"path={path!r}: no such file (an STL, OBJ or PLY surface)")
    try:
        with warnings.catch_warnings():  # meshio's binary-STL size probe can overflow (harmless)
            warnings.simplefilter("ignore", RuntimeWarning)
            m = meshio.read(path)
    except Exception as e:  # meshio raises several types for unreadable files
        raise ParameterError(f"path={path!r}: could not be read as a surface mesh "
                             f"(STL, OBJ or PLY): {type(e).__name__}: {e}") from e
    pts = np.asarray(m.points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ParameterError(f"path={path!r}: points of shape {pts.shape}; need (n, 3)")
    if pts.shape[1] == 2:
        raise ParameterError(f"path={path!r}: 2-D points; a surface mesh needs x, y, z")
    tris = []
    for block in m.cells:
        data = np.asarray(block.data)
        if block.type == "triangle":
            tris.append(data)
        elif block.type == "quad":
            tris.append(data[:, [0, 1, 2]])
            tris.append(data[:, [0, 2, 3]])
        elif block.type in ("vertex", "line"):
            continue
        else:
            raise ParameterError(f"path={path!r}: cells of type {block.type!r}; a surface mesh "
                                 "has triangles (or quads)")
    if not tris:
        raise ParameterError(f"path={path!r}: no triangles")
    tri = np.concatenate(tris).astype(np.int64)
    # Merge duplicate vertices (STL stores each triangle's corners separately).
    uniq, inv = np.unique(pts, axis=0, return_inverse=True)
    tri = inv.ravel()[tri]
    used, tri_new = np.unique(tri, return_inverse=True)
    return uniq[used] * float(scale), tri_new.reshape(-1, 3)


def _as_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=float)
    t = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ParameterError(f"vertices: shape {v.shape}; must be (n, 3), m")
    if not np.all(np.isfinite(v)):
        raise ParameterError("vertices: must be finite (m)")
    if t.ndim != 2 or t.shape[1] != 3 or len(t) < 4:
        raise ParameterError(f"triangles: shape {t.shape}; must be (m, 3) vertex indices, "
                             "m >= 4 for a closed surface")
    if not np.issubdtype(t.dtype, np.integer):
        if not np.all(np.mod(t, 1) == 0):
            raise ParameterError("triangles: must be integer vertex indices")
    t = t.astype(np.int64)
    if t.min() < 0 or t.max() >= len(v):
        raise ParameterError(f"triangles: indices in [{t.min()}, {t.max()}]; must be in "
                             f"[0, {len(v) - 1}] (the vertex count is {len(v)})")
    return v, t


def check_closed_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    """Checks that a triangle surface is closed and consistently oriented; returns (vertices,
    triangles) with outward normals (flipped if the signed volume is negative).

    Closed: every edge is shared by exactly two triangles. Consistently oriented: the two
    triangles traverse their shared edge in opposite directions. Not crossing itself: no two
    triangles that share no vertex meet (:func:`self_intersections`). Triangles with a
    repeated vertex index are dropped first. Raises :class:`ParameterError` naming the first
    bad edge or crossing pair.
    """
    v, t = _as_mesh(vertices, triangles)
    deg = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    t = t[~deg]
    if len(t) < 4:
        raise ParameterError(f"triangles: {len(t)} non-degenerate triangles; a closed surface "
                             "needs at least 4")
    d = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])  # directed edges
    und = np.sort(d, axis=1)
    ue, counts = np.unique(und, axis=0, return_counts=True)
    bad = counts != 2
    if bad.any():
        i = int(np.argmax(bad))
        a, b = ue[i]
        what = "an open boundary (hole)" if counts[i] == 1 else "a non-manifold edge"
        raise ParameterError(
            f"triangles: edge ({a}, {b}) belongs to {counts[i]} triangle(s), {what}; a closed "
            f"surface needs exactly 2 per edge ({int(bad.sum())} bad edges of {len(ue)})")
    de, dcounts = np.unique(d, axis=0, return_counts=True)
    if (dcounts > 1).any():
        a, b = de[int(np.argmax(dcounts > 1))]
        raise ParameterError(
            f"triangles: edge ({a}, {b}) is traversed in the same direction by both of its "
            "triangles; the surface is not consistently oriented (fix the winding of the "
            "triangles so that all normals point outward)")
    crossing = self_intersections(v, t)
    if len(crossing):
        i, j = crossing[0]
        raise ParameterError(
            f"triangles: triangles {i} {t[i].tolist()} and {j} {t[j].tolist()} cross (they "
            f"share no vertex; {len(crossing)} crossing pair(s)); a closed surface must not "
            "cross itself: the volume and inertia it encloses would be wrong")
    vol = _signed_volume(v, t)
    scale = float(np.ptp(v, axis=0).max()) ** 3
    if not abs(vol) > 1e-12 * scale:
        raise ParameterError(f"vertices: the surface encloses volume {vol!r} m^3; must be > 0")
    if vol < 0:
        t = t[:, ::-1].copy()
    return v, t


def self_intersections(vertices, triangles, *, block: int = 512) -> np.ndarray:
    """The pairs (i, j), i < j, of triangles that share no vertex and cross or touch: an
    edge of one meets the other (Moller-Trumbore, touching included to 1e-12 of the mesh's
    size), shape (k, 2), in order. Candidates are the pairs whose bounding boxes overlap,
    ``block`` triangles at a time. Coplanar overlaps of triangles that share no vertex are not
    found (no edge crosses the other's plane)."""
    v = np.asarray(vertices, float)
    t = np.asarray(triangles, np.int64)
    eps = 1e-12 * float(np.ptp(v, axis=0).max() or 1.0)
    order = np.argsort(v[t][:, :, 0].min(axis=1), kind="stable")  # (swept along x)
    t = t[order]
    p = v[t]  # (n, 3, 3)
    lo, hi = p.min(axis=1), p.max(axis=1)
    pairs = []
    for s0 in range(0, len(t), block):
        rows = np.arange(s0, min(s0 + block, len(t)))
        # (the columns whose x-range can reach the block's: sorted by their lower x)
        end = int(np.searchsorted(lo[:, 0], hi[rows, 0].max() + eps, side="right"))
        cols = np.arange(s0, max(end, s0))
        over = np.all((lo[rows, None, :] <= hi[None, cols, :] + eps)
                      & (lo[None, cols, :] <= hi[rows, None, :] + eps), axis=2)
        i, j = np.nonzero(over)
        a_, b_ = rows[i], cols[j]
        keep = a_ < b_
        a_, b_ = a_[keep], b_[keep]
        shared = (t[a_][:, :, None] == t[b_][:, None, :]).any(axis=(1, 2))
        pairs.append(np.stack([a_[~shared], b_[~shared]], axis=1))
    cand = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
    if not len(cand):
        return cand
    hit = np.zeros(len(cand), bool)
    for a, b in ((0, 1), (1, 0)):
        tri = p[cand[:, b]]
        for e in range(3):
            q0, q1 = p[cand[:, a], e], p[cand[:, a], (e + 1) % 3]
            hit |= _segment_meets_triangle(q0, q1, tri, eps)
    found = np.sort(order[cand[hit]], axis=1)  # (the given triangles' indices)
    return found[np.lexsort((found[:, 1], found[:, 0]))]


def _ray_triangle(o, d, tri):
    """Moller-Trumbore for each row: the ray o + t d (o, d: (k, 3)) against its triangle
    (tri: (k, 3 corners, 3)). Returns (ok, u, v, t): ok False where the ray is parallel to the
    triangle's plane; u, v the crossing's barycentric coordinates on the edges from corner 0
    to corners 1 and 2; t its parameter along d (0 where not ok)."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - tri[:, 0]
    u = inv * np.einsum("ij,ij->i", s, h)
    qv = np.cross(s, e1)
    v = inv * np.einsum("ij,ij->i", d, qv)
    t = inv * np.einsum("ij,ij->i", e2, qv)
    return ok, u, v, t


def _segment_meets_triangle(q0, q1, tri, eps: float) -> np.ndarray:
    """Whether each segment q0-q1 meets its triangle (rows), touching included."""
    d = q1 - q0
    ok, u, w, tt = _ray_triangle(q0, d, tri)
    size = np.linalg.norm(d, axis=1) + 1e-300
    tol = eps / size
    return ok & (u >= -tol) & (w >= -tol) & (u + w <= 1 + tol) & (tt >= -tol) & (tt <= 1 + tol)


def _signed_volume(v, t) -> float:
    ref = v.mean(axis=0)
    a, b, c = v[t[:, 0]] - ref, v[t[:, 1]] - ref, v[t[:, 2]] - ref
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def mesh_mass_properties(vertices, triangles) -> MassProperties:
    """Exact volume (m^3), centroid (m) and inertia tensor about the centroid per unit density
    (m^5) of the closed polyhedron, by signed tetrahedra (divergence theorem; Tonon 2004, Eberly
    2002; see the module docstring). The mesh is checked by :func:`check_closed_mesh`."""
    v, t = check_closed_mesh(vertices, triangles)
    ref = v.mean(axis=0)
    a, b, c = v[t[:, 0]] - ref, v[t[:, 1]] - ref, v[t[:, 2]] - ref
    vt = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    vol = vt.sum()
    s = a + b + c
    m1 = (vt[:, None] * s).sum(axis=0) / 4.0
    S = (np.einsum("t,ti,tj->ij", vt, a, a) + np.einsum("t,ti,tj->ij", vt, b, b)
         + np.einsum("t,ti,tj->ij", vt, c, c) + np.einsum("t,ti,tj->ij", vt, s, s)) / 20.0
    d = m1 / vol
    S = S - vol * np.outer(d, d)
    inertia = np.trace(S) * np.eye(3) - S
    pm, axes = _principal(inertia)
    return MassProperties(float(vol), ref + d, inertia, pm, axes)


# --------------------------------------------------------------------------------------------
# Simple meshes
# --------------------------------------------------------------------------------------------

def box_mesh(a: float, b: float | None = None, c: float | None = None,
             centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """A box with edges a, b, c (m; b and c default to a: a cube) centred at `centre`, as 8
    vertices and 12 outward triangles."""
    b = a if b is None else b
    c = a if c is None else c
    for nm, x in (("a", a), ("b", b), ("c", c)):
        if not (math.isfinite(x) and x > 0):
            raise ParameterError(f"{nm}={x!r}: must be > 0 (edge length, m)")
    v = np.array([[i, j, k] for i in (-0.5, 0.5) for j in (-0.5, 0.5) for k in (-0.5, 0.5)])
    v = v * [a, b, c] + np.asarray(centre, dtype=float)
    # Vertex index = 4 i + 2 j + k.
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    t = []
    for q in quads:
        t += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
    return check_closed_mesh(v, np.array(t))


def ellipsoid_mesh(a: float, b: float, c: float, subdivisions: int = 4,
                   centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid with semi-axes a, b, c (m) along x, y, z: an icosahedron subdivided
    `subdivisions` times (20 * 4^s triangles), vertices projected to the unit sphere and
    stretched. All vertices lie on the ellipsoid, so the polyhedron is inscribed and its volume
    falls short by O(h^2); measured for semi-axes 1, 0.75, 0.5: volume -8.6e-3, -2.2e-3, -5.4e-4
    and inertia -1.4e-2, -3.6e-3, -9.0e-4 at s = 3, 4, 5."""
    for nm, x in (("a", a), ("b", b), ("c", c)):
        if not (math.isfinite(x) and x > 0):
            raise ParameterError(f"{nm}={x!r}: must be > 0 (semi-axis, m)")
    if not (isinstance(subdivisions, (int, np.integer)) and 0 <= subdivisions <= 7):
        raise ParameterError(f"subdivisions={subdivisions!r}: must be an integer in [0, 7]")
    p = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p],
                  [0, -1, -p], [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]],
                 dtype=float)
    t = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    v /= np.linalg.norm(v, axis=1)[:, None]
    for _ in range(subdivisions):
        e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        e.sort(axis=1)
        ue, inv = np.unique(e, axis=0, return_inverse=True)
        inv = inv.ravel()
        mid = v[ue[:, 0]] + v[ue[:, 1]]
        mid /= np.linalg.norm(mid, axis=1)[:, None]
        m = len(t)
        i01, i12, i20 = (len(v) + inv[:m], len(v) + inv[m:2 * m], len(v) + inv[2 * m:])
        v = np.vstack([v, mid])
        t = np.concatenate([np.column_stack([t[:, 0], i01, i20]),
                            np.column_stack([t[:, 1], i12, i01]),
                            np.column_stack([t[:, 2], i20, i12]),
                            np.column_stack([i01, i12, i20])])
    v = v * [a, b, c] + np.asarray(centre, dtype=float)
    return check_closed_mesh(v, t)


def convex_hull_mesh(points) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull of points (k, 3), m, as (vertices, outward triangles); incremental
    construction (O(k^2), meant for the tens of points of a grain shape). Points inside the hull
    are dropped; coplanar faces stay triangulated."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 4:
        raise ParameterError(f"points: shape {p.shape}; must be (k, 3) with k >= 4, m")
    if not np.all(np.isfinite(p)):
        raise ParameterError("points: must be finite (m)")
    scale = float(np.ptp(p, axis=0).max())
    eps = 1e-10 * max(scale, 1e-300)
    # Initial tetrahedron: two far points, the farthest from their line, the farthest from
    # that plane.
    i0 = int(np.argmin(p[:, 0]))
    i1 = int(np.argmax(np.linalg.norm(p - p[i0], axis=1)))
    u = p[i1] - p[i0]
    i2 = int(np.argmax(np.linalg.norm(np.cross(p - p[i0], u), axis=1)))
    n = np.cross(u, p[i2] - p[i0])
    i3 = int(np.argmax(np.abs((p - p[i0]) @ n)))
    if abs((p[i3] - p[i0]) @ n) <= eps * np.linalg.norm(n):
        raise ParameterError("points: all coplanar; a convex hull needs volume")
    faces = [(i0, i1, i2), (i0, i3, i1), (i1, i3, i2), (i2, i3, i0)]
    if (p[i3] - p[i0]) @ n > 0:
        faces = [f[::-1] for f in faces]

    def plane(f):
        a, b, c = p[f[0]], p[f[1]], p[f[2]]
        nn = np.cross(b - a, c - a)
        nn /= np.linalg.norm(nn)
        return nn, nn @ a

    planes = [plane(f) for f in faces]
    for k in range(len(p)):
        if k in (i0, i1, i2, i3):
            continue
        vis = [i for i, (nn, off) in enumerate(planes) if nn @ p[k] - off > eps]
        if not vis:
            continue
        visset = set(vis)
        edges = {}
        for i in vis:
            a, b, c = faces[i]
            for e in ((a, b), (b, c), (c, a)):
                edges[e] = True
        horizon = [e for e in edges if (e[1], e[0]) not in edges]
        faces = [f for i, f in enumerate(faces) if i not in visset]
        planes = [q for i, q in enumerate(planes) if i not in visset]
        for a, b in horizon:
            faces.append((a, b, k))
            planes.append(plane((a, b, k)))
    t = np.array(faces, dtype=np.int64)
    used, inv = np.unique(t, return_inverse=True)
    return check_closed_mesh(p[used], inv.reshape(-1, 3))


def write_stl(path, vertices, triangles, name: str = "grain") -> None:
    """Writes a binary STL (float32 coordinates, m) without meshio."""
    v, t = _as_mesh(vertices, triangles)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    nrm = np.cross(b - a, c - a)
    ln = np.linalg.norm(nrm, axis=1)
    nrm = nrm / np.where(ln > 0, ln, 1.0)[:, None]
    rec = np.zeros(len(t), dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)),
                                           ("attr", "<u2")]))
    rec["n"] = nrm
    rec["v"] = np.stack([a, b, c], axis=1)
    header = f"binary STL {name} (m)".encode()[:80].ljust(80, b" ")
    with open(path, "wb") as f:
        f.write(header)
        f.write(np.uint32(len(t)).tobytes())
        f.write(rec.tobytes())


# --------------------------------------------------------------------------------------------
# Geometry kernels (vectorised)
# --------------------------------------------------------------------------------------------

def _line_hits(A, B, C, det, Y, Z):
    """x of the crossings of the lines {(x, Y_j, Z_j)} with the triangles (sorted per line),
    and per line whether it grazes an edge or vertex (a barycentric coordinate within 1e-9 of
    0 for a crossed triangle, where the parity count is not reliable)."""
    out, graze = [], np.zeros(len(Y), dtype=bool)
    chunk = max(1, 2_000_000 // max(len(A), 1))
    tol = 1e-9
    for s in range(0, len(Y), chunk):
        y = Y[s:s + chunk, None]
        z = Z[s:s + chunk, None]
        l1 = ((y - A[:, 1]) * (C[:, 2] - A[:, 2]) - (C[:, 1] - A[:, 1]) * (z - A[:, 2])) / det
        l2 = ((B[:, 1] - A[:, 1]) * (z - A[:, 2]) - (y - A[:, 1]) * (B[:, 2] - A[:, 2])) / det
        l0 = 1.0 - l1 - l2
        lmin = np.minimum(np.minimum(l0, l1), l2)
        hit = lmin >= 0
        graze[s:s + chunk] = (np.abs(lmin) <= tol).any(axis=1)
        xh = l0 * A[:, 0] + l1 * B[:, 0] + l2 * C[:, 0]
        out += [np.sort(xh[j][hit[j]]) for j in range(len(y))]
    return out, graze


def _inside_on_lines(v, t, ys, zs, xs) -> np.ndarray:
    """Inside flags (len(ys), len(zs), len(xs)) of the grid points, by the parity of the
    crossings of a ray along +x. A line that grazes an edge or a vertex is moved by about 1e-6
    of the mesh size (again, up to 8 times, if it still grazes) and tested again; a line that
    cannot be resolved counts as outside."""
    A, B, C = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    det = (B[:, 1] - A[:, 1]) * (C[:, 2] - A[:, 2]) - (C[:, 1] - A[:, 1]) * (B[:, 2] - A[:, 2])
    ok = det != 0  # triangles parallel to x are never crossed
    A, B, C, det = A[ok], B[ok], C[ok], det[ok]
    Y, Z = np.meshgrid(ys, zs, indexing="ij")
    Y, Z = Y.ravel(), Z.ravel()
    hits, bad = _line_hits(A, B, C, det, Y, Z)
    bad |= np.array([len(h) % 2 == 1 for h in hits], dtype=bool)
    size = float(np.ptp(v, axis=0).max())
    for k in range(1, 9):
        idx = np.flatnonzero(bad)
        if len(idx) == 0:
            break
        # Irrational-ratio offsets, different at each try.
        dy, dz = 1e-6 * size * math.sin(k * 2.399963), 1e-6 * size * math.cos(k * 2.399963)
        h2, g2 = _line_hits(A, B, C, det, Y[idx] + dy, Z[idx] + dz)
        for j, h, g in zip(idx, h2, g2):
            hits[j] = h
            bad[j] = g or len(h) % 2 == 1
    out = np.zeros((len(Y), len(xs)), dtype=bool)
    for j, h in enumerate(hits):
        if len(h) and not bad[j]:
            # Points between crossings 2i and 2i+1 are inside.
            out[j] = (len(h) - np.searchsorted(h, xs, side="right")) % 2 == 1
    return out.reshape(len(ys), len(zs), len(xs))


def _pair_distance2(p, A, B, C):
    """Squared distance from points p (k, 3) to triangles (A, B, C) (k, 3 each), pairwise."""
    AB, AC, BC = B - A, C - A, C - B
    N = np.cross(AB, AC)
    nn = np.einsum("ij,ij->i", N, N)
    ap, bp, cp = p - A, p - B, p - C

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)

    def seg(w, d):
        d2 = dot(d, d)
        s = np.clip(dot(w, d) / np.where(d2 > 0, d2, 1.0), 0.0, 1.0)
        r = w - s[:, None] * d
        return dot(r, r)

    # The projection falls inside the triangle iff p is on the inner side of all three edge
    # planes (edge normals N x edge point inward for a counter-clockwise triangle).
    inprism = ((dot(ap, np.cross(N, AB)) >= 0) & (dot(bp, np.cross(N, BC)) >= 0)
               & (dot(cp, np.cross(AC, N)) >= 0) & (nn > 0))
    dplane = dot(ap, N) ** 2 / np.where(nn > 0, nn, 1.0)
    dedge = np.minimum(np.minimum(seg(ap, AB), seg(bp, BC)), seg(ap, AC))
    return np.where(inprism, dplane, dedge)


def _point_triangle_distance(P, v, t, chunk_pairs: int = 2_000_000) -> np.ndarray:
    """Unsigned distance (m) from each point of P (n, 3) to the triangle surface (v, t).

    Exact; pruned by bounds: the nearest vertex distance U(p) bounds the answer from above, and
    a triangle with bounding sphere (centre m_t, radius R_t) can only be nearer if
    |p - m_t| - R_t <= U(p); only those pairs get the exact point-triangle distance."""
    A, B, C = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    M = (A + B + C) / 3.0
    R = np.sqrt(np.maximum.reduce([((X - M) ** 2).sum(axis=1) for X in (A, B, C)]))
    out = np.empty(len(P))
    step = max(1, chunk_pairs // max(len(t), len(v), 1))
    slack = 1e-9 * float(np.ptp(v, axis=0).max())
    for s0 in range(0, len(P), step):
        p = P[s0:s0 + step]
        pp = (p * p).sum(axis=1)[:, None]
        U2 = np.maximum(pp - 2.0 * p @ v.T + (v * v).sum(axis=1), 0.0).min(axis=1)
        U = np.sqrt(U2)
        dm = np.sqrt(np.maximum(pp - 2.0 * p @ M.T + (M * M).sum(axis=1), 0.0))
        pi, ti = np.nonzero(dm - R <= U[:, None] + slack)
        d2 = _pair_distance2(p[pi], A[ti], B[ti], C[ti])
        best = np.full(len(p), np.inf)
        np.minimum.at(best, pi, d2)
        out[s0:s0 + step] = np.sqrt(np.minimum(best, U2))
    return out


def _sample_grid(v, grid: int):
    """Grid spacing h (shortest bounding-box edge / grid) and the x, y, z sample coordinates:
    an odd number per axis, symmetric about the box centre (symmetric shapes get a centre
    point)."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    ext = hi - lo
    h = float(ext.min()) / grid
    mid = 0.5 * (lo + hi)
    axes = []
    for i in range(3):
        k = int(math.ceil(0.5 * ext[i] / h))
        axes.append(mid[i] + h * np.arange(-k, k + 1))
    return h, axes


def _surface_samples(v, t, n: int, rng) -> np.ndarray:
    A, B, C = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(B - A, C - A), axis=1)
    idx = rng.choice(len(t), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    sq = np.sqrt(r1)
    return ((1 - sq)[:, None] * A[idx] + (sq * (1 - r2))[:, None] * B[idx]
            + (sq * r2)[:, None] * C[idx])


# --------------------------------------------------------------------------------------------
# Filling
# --------------------------------------------------------------------------------------------

def _inside_points(v, t, grid: int):
    """The sample grid points strictly inside the mesh (k, 3), their distance to the surface
    (k,), m, and the grid spacing h, m."""
    h, (xs, ys, zs) = _sample_grid(v, grid)
    inside = _inside_on_lines(v, t, ys, zs, xs)          # (ny, nz, nx)
    jy, jz, jx = np.nonzero(inside)
    P = np.column_stack([xs[jx], ys[jy], zs[jz]])
    d = _point_triangle_distance(P, v, t)
    keep = d > 1e-9 * h                                   # points on the surface hold no volume
    if not keep.any():
        raise ParameterError(f"grid={grid}: no sample point falls inside the mesh; increase it")
    return P[keep], d[keep], h


def _count_in_balls(C, R, Q, chunk: int = 4_000_000) -> np.ndarray:
    """For balls (C (m, 3), R (m,)), the number of points of Q (q, 3) inside each."""
    out = np.zeros(len(C), dtype=np.int64)
    if len(Q) == 0 or len(C) == 0:
        return out
    qq = (Q * Q).sum(axis=1)
    step = max(1, chunk // len(Q))
    for s in range(0, len(C), step):
        c = C[s:s + step]
        d2 = (c * c).sum(axis=1)[:, None] - 2.0 * c @ Q.T + qq[None, :]
        out[s:s + step] = (d2 <= (R[s:s + step] ** 2)[:, None]).sum(axis=1)
    return out


def fill_mesh(vertices, triangles, max_spheres: int = 20, min_radius_ratio: float = 0.0,
              target_fill: float = 1.0, grid: int = 20, seed: int = 0, name: str = "mesh",
              cells: int = 160) -> ClumpTemplate:
    """Fills a closed triangle surface (m) with overlapping medial spheres, chosen greedily by
    the volume they add (see the module docstring for the method and its references).

    max_spheres: at most this many spheres (>= 1).
    min_radius_ratio: smallest allowed radius over the largest inscribed radius, in [0, 1)
    (PFC bubble-pack ``ratio`` r_min / r_max; 0: any size down to the grid spacing).
    target_fill: stop once this fraction of the interior sample points is covered, in (0, 1]
    (1: run to ``max_spheres`` or until no candidate adds volume).
    grid: sample points along the shortest bounding-box edge (>= 4); centres lie on this grid
    and the covered volume is counted on it. Cost grows as grid^6 (candidates x points): 20
    fills a grain in about a second.
    seed: breaks ties between equally good candidates (deterministic for a given seed).
    name, cells: passed to the :class:`ClumpTemplate` (cells: its mass-property grid).

    Returns the template in the mesh's frame, spheres in the order chosen.
    """
    v, t = check_closed_mesh(vertices, triangles)
    if not (isinstance(max_spheres, (int, np.integer)) and max_spheres >= 1):
        raise ParameterError(f"max_spheres={max_spheres!r}: must be an integer >= 1")
    if not (isinstance(min_radius_ratio, (int, float)) and 0.0 <= min_radius_ratio < 1.0):
        raise ParameterError(f"min_radius_ratio={min_radius_ratio!r}: must be in [0, 1) "
                             "(r_min / r_max; 0 switches the limit off)")
    if not (isinstance(target_fill, (int, float)) and 0.0 < target_fill <= 1.0):
        raise ParameterError(f"target_fill={target_fill!r}: must be in (0, 1] (covered "
                             "fraction of the interior sample points)")
    if not (isinstance(grid, (int, np.integer)) and 4 <= grid <= 200):
        raise ParameterError(f"grid={grid!r}: must be an integer in [4, 200] (sample points "
                             "along the shortest bounding-box edge)")
    P, d, h = _inside_points(v, t, grid)
    # Candidates: the maximal inscribed ball at each sample point (its medial ball if the point
    # lies on the medial axis), at least r_min = min_radius_ratio * r_max.
    cand = np.flatnonzero(d >= min_radius_ratio * d.max())
    Cc, Rc = P[cand], d[cand]
    gain = _count_in_balls(Cc, Rc, P)
    covered = np.zeros(len(P), dtype=bool)
    rng = np.random.default_rng(seed)
    centres, radii = [], []
    for _ in range(max_spheres):
        gmax = int(gain.max())
        if gmax <= 0 or covered.mean() >= target_fill:
            break
        best = np.flatnonzero(gain == gmax)
        best = best[Rc[best] >= Rc[best].max() - 1e-9 * h]   # prefer the larger ball
        i = int(best[0] if len(best) == 1 else rng.choice(best))
        c, r = Cc[i], Rc[i]
        centres.append(c.copy())
        radii.append(float(r))
        new = ~covered & (((P - c) ** 2).sum(axis=1) <= r * r)
        covered |= new
        # Only balls that reach the new sphere lose gain.
        near = np.flatnonzero(np.linalg.norm(Cc - c, axis=1) <= Rc + r + h)
        gain[near] -= _count_in_balls(Cc[near], Rc[near], P[new])
    return ClumpTemplate.from_spheres(np.array(centres), np.array(radii), name, cells)


class FillRow(NamedTuple):
    """One row of :func:`fill_report`.

    count: spheres. volume_error: (V_template - V_mesh) / V_mesh (negative: spheres never fill
    corners and edges). centroid_error_m: |c_template - c_mesh|, m. inertia_error: largest
    absolute difference of the inertia tensors per unit density (about each own centroid) over
    the mesh's largest principal moment; it contains the volume deficit. gyration_error: the
    same for inertia / volume (the error left when the clump's density is raised to give the
    grain's mass). rms_deviation_m, max_deviation_m: distance from points on the mesh surface
    to the union surface, |min_k(|p - c_k| - r_k)|, m (RMS over area-uniform random samples;
    max over those samples and the mesh vertices). d_eq_m: the mesh's volume-equivalent
    diameter, m. The properties centroid_error, rms_deviation and max_deviation are the
    lengths over d_eq.
    """

    count: int
    volume_error: float
    centroid_error_m: float
    inertia_error: float
    gyration_error: float
    rms_deviation_m: float
    max_deviation_m: float
    d_eq_m: float

    @property
    def centroid_error(self) -> float:
        return self.centroid_error_m / self.d_eq_m

    @property
    def rms_deviation(self) -> float:
        return self.rms_deviation_m / self.d_eq_m

    @property
    def max_deviation(self) -> float:
        return self.max_deviation_m / self.d_eq_m


def fill_report(vertices, triangles, counts=(1, 2, 4, 8, 16, 32), samples: int = 4000,
                seed: int = 0, **fill_kwargs) -> list[FillRow]:
    """Sphere count against volume error and surface deviation for :func:`fill_mesh` of a mesh.

    One fill with ``max_spheres = max(counts)`` (plus ``fill_kwargs``, e.g. ``grid``); the
    template of n spheres is its first n spheres (the greedy choice is sequential, so this is
    the fill with ``max_spheres = n``). Returns one :class:`FillRow` per count (fewer if the
    fill stopped early). Mass properties of the template: :func:`union_mass_properties`
    (accuracy ~2e-4, far below the fill errors).
    """
    v, t = check_closed_mesh(vertices, triangles)
    counts = sorted({int(n) for n in counts})
    if not counts or counts[0] < 1:
        raise ParameterError(f"counts={counts!r}: must be sphere counts >= 1")
    if not (isinstance(samples, (int, np.integer)) and samples >= 10):
        raise ParameterError(f"samples={samples!r}: must be an integer >= 10")
    mp = mesh_mass_properties(v, t)
    tmpl = fill_mesh(v, t, max_spheres=counts[-1], seed=seed, **fill_kwargs)
    d_eq = (6.0 * mp.volume / math.pi) ** (1.0 / 3.0)
    S = np.vstack([_surface_samples(v, t, samples, np.random.default_rng(seed + 1)), v])
    ref = mp.principal.max()
    rows = []
    for n in counts:
        if n > tmpl.num_members:
            break
        c, r = tmpl.centres[:n], tmpl.radii[:n]
        up = ClumpTemplate(c, r, tmpl.name, tmpl.cells).props
        gap = np.abs((np.linalg.norm(S[:, None] - c[None], axis=2) - r).min(axis=1))
        rows.append(FillRow(
            n, float(up.volume / mp.volume - 1.0),
            float(np.linalg.norm(up.centroid - mp.centroid)),
            float(np.abs(up.inertia - mp.inertia).max() / ref),
            float(np.abs(up.inertia / up.volume - mp.inertia / mp.volume).max()
                  / (ref / mp.volume)),
            float(np.sqrt(np.mean(gap[:samples] ** 2))), float(gap.max()), d_eq))
    return rows


def format_report(rows: list[FillRow], title: str = "") -> str:
    """The rows of :func:`fill_report` as a Markdown table."""
    lines = [f"{title}", ""] if title else []
    lines += ["| spheres | volume error | centroid error / d_eq | inertia error | "
              "gyration error | RMS deviation / d_eq | max deviation / d_eq |",
              "|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r.count} | {r.volume_error:+.4f} | {r.centroid_error:.1e} | "
                     f"{r.inertia_error:.4f} | {r.gyration_error:.4f} | {r.rms_deviation:.4f} | "
                     f"{r.max_deviation:.4f} |")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# Shipped grains
# --------------------------------------------------------------------------------------------

def _shipped_names() -> list[str]:
    if not GRAIN_DIR.is_dir():
        return []
    return sorted(p.stem for p in GRAIN_DIR.glob("*.csv"))


def shipped_templates() -> dict[str, ClumpTemplate]:
    """The shipped gravel-grain templates, name -> :class:`ClumpTemplate` (mesh normalised to a
    volume-equivalent diameter of 1 m about its centroid; scale with ``template.scaled(d)``)."""
    return {n: ClumpTemplate.load(GRAIN_DIR / f"{n}.csv", name=n) for n in _shipped_names()}


def shipped_template(name: str) -> ClumpTemplate:
    """One shipped template by name (e.g. ``"gravel_a"``)."""
    names = _shipped_names()
    if name not in names:
        raise ParameterError(f"name={name!r}: no shipped grain template of that name; "
                             f"available: {', '.join(names) or '(none)'}")
    return ClumpTemplate.load(GRAIN_DIR / f"{name}.csv", name=name)


def shipped_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The surface mesh (vertices m, triangles) a shipped template was filled from."""
    names = _shipped_names()
    if name not in names:
        raise ParameterError(f"name={name!r}: no shipped grain mesh of that name; "
                             f"available: {', '.join(names) or '(none)'}")
    return read_surface_mesh(GRAIN_DIR / f"{name}.stl")


# --------------------------------------------------------------------------------------------
# Command line: python -m cpp_dem.build.clump_mesh report cube|ellipsoid|<shipped name>|<mesh file>
# --------------------------------------------------------------------------------------------

def _main(argv=None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m cpp_dem.build.clump_mesh",
                                 description="Sphere-filling trade of a closed surface mesh.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    rp = sub.add_parser("report", help="print sphere count vs volume error and surface deviation")
    rp.add_argument("shape", help="cube, ellipsoid (semi-axes 1, 0.75, 0.5 m), a shipped grain "
                    "name, or a mesh file (STL/OBJ/PLY)")
    rp.add_argument("--counts", default="1,2,4,8,16,32")
    rp.add_argument("--grid", type=int, default=20)
    rp.add_argument("--min-radius-ratio", type=float, default=0.0)
    rp.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    if a.shape == "cube":
        v, t = box_mesh(1.0)
    elif a.shape == "ellipsoid":
        v, t = ellipsoid_mesh(1.0, 0.75, 0.5, subdivisions=4)
    elif a.shape in _shipped_names():
        v, t = shipped_mesh(a.shape)
    else:
        v, t = read_surface_mesh(a.shape)
    counts = [int(x) for x in a.counts.split(",") if x.strip()]
    rows = fill_report(v, t, counts, seed=a.seed, grid=a.grid,
                       min_radius_ratio=a.min_radius_ratio)
    d_eq = rows[0].d_eq_m if rows else float("nan")
    print(format_report(rows, f"{a.shape}: {len(t)} triangles, d_eq {d_eq:.4g} m, grid {a.grid}, "
                              f"min_radius_ratio {a.min_radius_ratio}, seed {a.seed}"))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())


#: The fill_mesh settings the shipped gravel templates were made with
#: (scripts/make_gravel_meshes.py: ``FILL`` and ``SEED``); filling a shipped mesh with these and
#: ``max_spheres = SHIPPED_SPHERES`` gives its CSV bit for bit (tests/test_clump_resolution.py).
SHIPPED_FILL = dict(min_radius_ratio=0.2, grid=24, seed=20240611)
#: Spheres per shipped template (``gravel_a.csv`` etc.).
SHIPPED_SPHERES = 24
#: The largest resolution ``clumps:NAME@N`` accepts. With SHIPPED_FILL every shipped grain gets
#: exactly N spheres for N up to this (the greedy fill runs out of candidates that add volume
#: at 296 to 337 spheres on the grid-24 sample, so no shipped grain is cut short below it).
MAX_SPHERES = 256


def shipped_fill(name: str, spheres: int) -> ClumpTemplate:
    """The shipped grain ``name`` (e.g. ``"gravel_a"``) filled with ``spheres`` spheres: its
    shipped surface mesh (:func:`shipped_mesh`: volume-equivalent diameter 1 m, centroid at the
    origin, principal axes along x, y, z) filled by :func:`fill_mesh` with the shipped
    settings (SHIPPED_FILL) and ``max_spheres = spheres``, named ``<name>_<spheres>``.
    ``spheres = SHIPPED_SPHERES`` (24) returns the shipped CSV itself (:func:`shipped_template`,
    named ``<name>``), which that fill reproduces bit for bit. The greedy fill is sequential,
    so the template of n spheres is the first n spheres of any larger one: the resolutions
    nest, and below 24 the fill is the shipped CSV's first n spheres, which are taken
    without filling again (the same template to the bit). Larger fills are cached in the
    process (about a second per grain).

    name: a shipped grain. spheres: an integer in [1, MAX_SPHERES]."""
    if not (isinstance(spheres, (int, np.integer)) and not isinstance(spheres, bool)
            and 1 <= spheres <= MAX_SPHERES):
        raise ParameterError(f"spheres={spheres!r}: must be an integer in [1, {MAX_SPHERES}]")
    if int(spheres) == SHIPPED_SPHERES:
        return shipped_template(name)
    return _shipped_fill(name, int(spheres))


@functools.lru_cache(maxsize=None)
def _shipped_fill(name: str, spheres: int) -> ClumpTemplate:
    if spheres < SHIPPED_SPHERES:
        # (the greedy fill's first spheres: its template with the fill's cells, 160)
        first = shipped_template(name)
        return ClumpTemplate.from_spheres(first.centres[:spheres], first.radii[:spheres],
                                          f"{name}_{spheres}")
    v, t = shipped_mesh(name)
    return fill_mesh(v, t, max_spheres=spheres, name=f"{name}_{spheres}", **SHIPPED_FILL)


def _resolution(spec: str, text: str) -> int:
    """The N of a ``@N`` suffix, checked (ParameterError naming grains, the value and what is
    allowed)."""
    if not (re.fullmatch(r"[0-9]+", text) and 1 <= int(text) <= MAX_SPHERES):
        raise ParameterError(f"grains={spec!r}: the resolution {text!r} after '@' must be an "
                             f"integer in [1, {MAX_SPHERES}] (spheres per grain, e.g. "
                             f"'clumps:gravel@12'; without '@N' the shipped "
                             f"{SHIPPED_SPHERES}-sphere templates)")
    return int(text)


def templates_from_spec(spec: str) -> list:
    """The clump templates a case's ``--grains clumps:NAME`` names: a shipped grain
    (shipped_templates: gravel_a .. gravel_d), ``gravel`` for all of them,
    or a template CSV (x, y, z, r in m; ClumpTemplate.load).

    ``clumps:NAME@N`` (NAME a shipped grain or ``gravel``; N an integer in [1, MAX_SPHERES]):
    the same grains filled with N spheres each (:func:`shipped_fill`: the same meshes and fill
    settings as the shipped 24-sphere CSVs; ``@24`` is the shipped CSV itself, bit for bit the
    spec without ``@N``). Raises ParameterError naming the value and what is allowed."""
    name = spec.split(":", 1)[1] if spec.startswith("clumps:") else ""
    if not name:
        raise ParameterError(f"grains={spec!r}: must be 'spheres' or 'clumps:NAME' (NAME: a "
                             f"shipped grain {sorted(shipped_templates())}, 'gravel', or a "
                             "template CSV; 'NAME@N' for a shipped grain filled with N spheres)")
    if name == "gravel":
        return list(shipped_templates().values())
    if os.path.isfile(name):
        return [ClumpTemplate.load(name)]
    base, at, res = name.rpartition("@")
    if at:
        n = _resolution(spec, res)
        if base == "gravel":
            return [shipped_fill(g, n) for g in _shipped_names()]
        if base not in _shipped_names():
            raise ParameterError(
                f"grains={spec!r}: '@N' needs a shipped grain before it "
                f"({', '.join(_shipped_names()) or '(none)'}) or 'gravel'; a template CSV "
                "keeps its own spheres")
        return [shipped_fill(base, n)]
    try:
        return [shipped_template(name)]
    except ParameterError as e:
        raise ParameterError(f"grains={spec!r}: {e} (or 'gravel' for all of them, or a "
                             "template CSV x,y,z,r; 'NAME@N' for N spheres per grain)") from None
