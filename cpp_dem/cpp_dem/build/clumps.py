"""Clumps: rigid grains made of overlapping spheres (Yade's Clump, PFC's clump).

A :class:`ClumpTemplate` is a grain shape: member spheres (centres, m; radii, m) in the
template's own frame. Its mass properties are those of the *union* of the members, overlaps
counted once (:func:`union_mass_properties`). ``scene.add_clumps(template, positions,
orientations, material)`` places copies; each becomes one rigid body in the core (integrated in
its principal axes), and its members are spheres to the contact detection that carry the
clump's id and never touch each other.

Mass properties of a union of spheres
-------------------------------------
The union is cut into chords parallel to x on a regular (y, z) grid of ``cells`` x ``cells``
midpoints over its bounding box. Along one chord the union is a union of intervals (one per
sphere the line crosses), merged exactly, so the x-integrals of 1, x and x^2 over it are exact;
only the (y, z) quadrature (midpoint rule) approximates. For one sphere the volume error of the
midpoint rule on the chord-area function is about 0.3 (h / r)^1.5 (h the cell size), and for
unions it is of the same order: with the default 160 cells across the grain, volume and inertia
are within 2e-4 (measured against exact sphere and two-sphere lens values in
tests/test_clumps.py; stated per template as ``fill_accuracy``). Members that do not overlap
(one sphere among them) are summed exactly instead (analytic spheres, parallel axes), as Yade
and PFC do for any clump, so a one-sphere clump is the sphere itself.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from cpp_dem import fixedorder
from cpp_dem._core import ParameterError
from cpp_dem.build.packing import loose_cloud

__all__ = ["ClumpTemplate", "ClumpCloud", "MassProperties", "clump_cloud", "union_mass_properties",
           "random_orientations"]


@dataclass(frozen=True)
class MassProperties:
    """Mass properties of a solid of unit density.

    volume: m^3; centroid: (3,), m; inertia: (3, 3) tensor about the centroid per unit density,
    m^5 (multiply by the density, kg/m^3, for kg m^2); principal: (3,) principal moments per
    unit density, m^5, ascending; axes: (3, 3) rotation whose columns are the principal axes
    (right-handed), in the frame the centres were given in.
    """

    volume: float
    centroid: np.ndarray
    inertia: np.ndarray
    principal: np.ndarray
    axes: np.ndarray


def _as_spheres(centres, radii):
    c = np.asarray(centres, dtype=float)
    r = np.asarray(radii, dtype=float).ravel()
    if c.ndim != 2 or c.shape[1] != 3:
        raise ParameterError(f"centres: shape {c.shape}; must be (k, 3) member centres, m")
    if len(r) != len(c):
        raise ParameterError(f"radii: {len(r)} values for {len(c)} centres; one radius (m) per member")
    if len(r) == 0:
        raise ParameterError("centres: empty; a clump needs at least one member sphere")
    if not np.all(np.isfinite(c)):
        raise ParameterError("centres: must be finite (m)")
    bad = ~(np.isfinite(r) & (r > 0))
    if bad.any():
        raise ParameterError(f"radii[{int(np.argmax(bad))}]={r[bad][0]!r}: must be > 0 (m)")
    return c, r


def _principal(inertia: np.ndarray):
    """Principal moments (ascending) and axes (columns, a right-handed frame) of ``inertia``,
    the same bits on every CPU and BLAS (:func:`cpp_dem.fixedorder.eigh`)."""
    w, v = fixedorder.eigh(0.5 * (inertia + inertia.T))
    det = (v[0, 0] * (v[1, 1] * v[2, 2] - v[1, 2] * v[2, 1])
           - v[0, 1] * (v[1, 0] * v[2, 2] - v[1, 2] * v[2, 0])
           + v[0, 2] * (v[1, 0] * v[2, 1] - v[1, 1] * v[2, 0]))
    if det < 0:
        v[:, 2] = -v[:, 2]
    return w, v


#: Two members closer than the sum of their radii by at most this fraction of that sum count as
#: touching, not overlapping (members placed 2r apart by construction are apart by 2r to
#: rounding, 1e-15 r; the lens such an overlap leaves out of the exact sum is (1e-12)^2 of a
#: member's volume, far below the rounding of the sum itself).
TOUCH_TOLERANCE = 1e-12


def _disjoint(c: np.ndarray, r: np.ndarray) -> bool:
    """No two of the spheres (centres c, radii r) overlap (touching, to TOUCH_TOLERANCE of the
    sum of their radii, is allowed). A neighbour search (k-d tree) per chunk of members: the
    memory is that of the candidate pairs, not of all k^2 distances."""
    if len(r) < 2:
        return True
    from scipy.spatial import cKDTree

    tree = cKDTree(c)
    rmax = float(r.max())
    for i0 in range(0, len(r), 1024):
        sel = range(i0, min(i0 + 1024, len(r)))
        near = tree.query_ball_point(c[i0:sel.stop], r[i0:sel.stop] + rmax)
        for i, js in zip(sel, near):
            j = np.asarray(js, dtype=np.intp)
            j = j[j > i]
            if len(j) and np.any(np.linalg.norm(c[i] - c[j], axis=1)
                                 < (r[i] + r[j]) * (1.0 - TOUCH_TOLERANCE)):
                return False
    return True


def _chord_moments(Y: np.ndarray, Z: np.ndarray, c: np.ndarray, r: np.ndarray):
    """Per line (y, z) parallel to x: the integrals of 1, x and x^2 over its intersection with
    the union of the spheres (c, r), exact (the chords merged)."""
    m0 = np.zeros(len(Y))
    m1 = np.zeros(len(Y))
    m2 = np.zeros(len(Y))
    if len(r) == 0:
        return m0, m1, m2
    # Chord of sphere k on line (y, z): [x_k - s, x_k + s], s^2 = r^2 - (y-y_k)^2 - (z-z_k)^2.
    s2 = r[None, :] ** 2 - (Y[:, None] - c[None, :, 1]) ** 2 - (Z[:, None] - c[None, :, 2]) ** 2
    hit = s2 > 0
    s = np.sqrt(np.where(hit, s2, 0.0))
    a = np.where(hit, c[None, :, 0] - s, np.inf)
    b = np.where(hit, c[None, :, 0] + s, -np.inf)
    order = np.argsort(a, axis=1, kind="stable")
    a = np.take_along_axis(a, order, axis=1)
    b = np.take_along_axis(b, order, axis=1)
    # Merge the sorted intervals line by line (vectorised across lines). The chords a line
    # crosses come first in its sorted row; past the most any line crosses nothing changes.
    cur_a = a[:, 0].copy()
    cur_b = b[:, 0].copy()

    def close(mask):
        lo_, hi_ = cur_a[mask], cur_b[mask]
        ok = np.isfinite(lo_) & (hi_ > lo_)
        lo_ = np.where(ok, lo_, 0.0)
        hi_ = np.where(ok, hi_, 0.0)
        m0[mask] += hi_ - lo_
        m1[mask] += 0.5 * (hi_ ** 2 - lo_ ** 2)
        m2[mask] += (fixedorder.powers(hi_, 3) - fixedorder.powers(lo_, 3)) / 3.0

    for k in range(1, int(hit.sum(axis=1).max())):
        ak, bk = a[:, k], b[:, k]
        gap = np.isfinite(ak) & (ak > cur_b)
        close(gap)
        cur_a = np.where(gap, ak, cur_a)
        cur_b = np.where(gap, bk, np.where(np.isfinite(ak), np.maximum(cur_b, bk), cur_b))
    close(np.ones(len(Y), dtype=bool))
    return m0, m1, m2


def union_mass_properties(centres, radii, cells: int = 160) -> MassProperties:
    """Volume, centroid and inertia of the union of spheres (unit density; see the module
    docstring for the method and its accuracy). cells: (y, z) grid points across the bounding
    box per axis, >= 8."""
    c, r = _as_spheres(centres, radii)
    if not (isinstance(cells, (int, np.integer)) and cells >= 8):
        raise ParameterError(f"cells={cells!r}: must be an integer >= 8")
    m = _memo(c.tobytes(), r.tobytes(), int(cells))
    return MassProperties(m.volume, m.centroid.copy(), m.inertia.copy(), m.principal.copy(),
                          m.axes.copy())


@functools.lru_cache(maxsize=64)
def _memo(centres: bytes, radii: bytes, cells: int) -> MassProperties:
    """union_mass_properties's results by their exact input (the members' bytes and the
    grid): a case loads the same shipped templates several times (about 0.3 s each), and the
    same input gives the same output, so a repeat is answered from here (the caller hands
    out copies) bit for bit."""
    return _union_mass_properties(np.frombuffer(centres).reshape(-1, 3), np.frombuffer(radii),
                                  cells)


def _union_mass_properties(c: np.ndarray, r: np.ndarray, cells: int) -> MassProperties:
    """union_mass_properties's computation, on checked members."""
    if len(r) == 1:
        # Exact; the same arithmetic as the core's sphere mass (density 4/3 pi r^3).
        vol = 4.0 / 3.0 * math.pi * r[0] * r[0] * r[0]
        i = 0.4 * vol * r[0] * r[0]
        return MassProperties(vol, c[0].copy(), np.eye(3) * i, np.full(3, i), np.eye(3))
    if _disjoint(c, r):
        # No two members overlap: the sum of the spheres is exact (parallel axes).
        v = 4.0 / 3.0 * math.pi * fixedorder.powers(r, 3)
        vol = float(v.sum())
        cen = (v[:, None] * c).sum(axis=0) / vol
        x = c - cen
        inertia = np.zeros((3, 3))
        for k in range(len(r)):
            xx = x[k, 0] * x[k, 0] + x[k, 1] * x[k, 1] + x[k, 2] * x[k, 2]  # (not BLAS's dot)
            inertia += np.eye(3) * (0.4 * v[k] * r[k] ** 2 + v[k] * xx) - v[k] * np.outer(x[k], x[k])
        pm, axes = _principal(inertia)
        return MassProperties(vol, cen, inertia, pm, axes)
    lo = (c - r[:, None]).min(axis=0)
    hi = (c + r[:, None]).max(axis=0)
    hy = (hi[1] - lo[1]) / cells
    hz = (hi[2] - lo[2]) / cells
    y = lo[1] + (np.arange(cells) + 0.5) * hy
    z = lo[2] + (np.arange(cells) + 0.5) * hz
    Y, Z = np.meshgrid(y, z, indexing="ij")
    Y = Y.ravel()
    Z = Z.ravel()
    # The lines in chunks of whole y rows, each with only the members whose y range meets
    # its rows (a member outside has (y - y_k)^2 >= r_k^2 on every line of the chunk, so it
    # hits none): the memory is bounded (about 2^22 line-member pairs per array) for any
    # number of members, and every line's sums are the same as over all members at once.
    m0 = np.empty(len(Y))
    m1 = np.empty(len(Y))
    m2 = np.empty(len(Y))
    rows = max(1, min(cells, (1 << 22) // (cells * len(r))))
    for i0 in range(0, cells, rows):
        sl = slice(i0 * cells, min(i0 + rows, cells) * cells)
        ylo, yhi = Y[sl][0], Y[sl][-1]
        k = np.flatnonzero((c[:, 1] + r >= ylo) & (c[:, 1] - r <= yhi))
        m0[sl], m1[sl], m2[sl] = _chord_moments(Y[sl], Z[sl], c[k], r[k])
    w = hy * hz
    vol = w * m0.sum()
    sx, sy, sz = w * m1.sum(), w * (Y * m0).sum(), w * (Z * m0).sum()
    cen = np.array([sx, sy, sz]) / vol
    xx = w * m2.sum()
    yy = w * (Y * Y * m0).sum()
    zz = w * (Z * Z * m0).sum()
    xy = w * (Y * m1).sum()
    xz = w * (Z * m1).sum()
    yz = w * (Y * Z * m0).sum()
    # Second moments about the centroid, then the inertia tensor.
    S = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) - vol * np.outer(cen, cen)
    inertia = np.trace(S) * np.eye(3) - S
    pm, axes = _principal(inertia)
    return MassProperties(vol, cen, inertia, pm, axes)


@dataclass(frozen=True)
class ClumpTemplate:
    """A grain shape: member spheres in the template frame.

    centres: (k, 3), m; radii: (k,), m; name: for output and run files; cells: the (y, z) grid
    of the mass-property integration. The derived fields: ``props`` (unit density, template
    frame), ``local_centres`` (members in the principal frame about the centroid, m) and
    ``fill_accuracy`` (the stated relative accuracy of volume and inertia).
    """

    centres: np.ndarray
    radii: np.ndarray
    name: str = "clump"
    cells: int = 160
    props: MassProperties = field(init=False, repr=False)

    def __post_init__(self) -> None:
        c, r = _as_spheres(self.centres, self.radii)
        object.__setattr__(self, "centres", c)
        object.__setattr__(self, "radii", r)
        object.__setattr__(self, "props", union_mass_properties(c, r, self.cells))

    @classmethod
    def from_spheres(cls, centres, radii, name: str = "clump", cells: int = 160) -> "ClumpTemplate":
        """A template from a list of (centre, radius), m."""
        return cls(np.asarray(centres, dtype=float), np.asarray(radii, dtype=float), name, cells)

    @property
    def num_members(self) -> int:
        return len(self.radii)

    @property
    def volume(self) -> float:
        """Volume of the union, m^3."""
        return self.props.volume

    @property
    def equivalent_diameter(self) -> float:
        """Diameter of the sphere of the same volume, m."""
        return (6.0 * self.volume / math.pi) ** (1.0 / 3.0)

    @property
    def local_centres(self) -> np.ndarray:
        """Member centres in the principal frame about the centroid, m (k, 3)."""
        # (summed in a fixed order, not by BLAS: the same bits on every CPU and BLAS kernel)
        x, a = self.centres - self.props.centroid, self.props.axes
        return x[:, 0:1] * a[0] + x[:, 1:2] * a[1] + x[:, 2:3] * a[2]

    @property
    def bounding_radius(self) -> float:
        """Radius of the sphere about the centre of mass that holds every member, m."""
        return float(np.max(np.linalg.norm(self.local_centres, axis=1) + self.radii))

    @property
    def fill_accuracy(self) -> float:
        """Stated relative accuracy of volume and inertia (0 for one sphere: exact)."""
        if _disjoint(self.centres, self.radii):
            return 0.0  # summed exactly
        return 2e-4 * (160.0 / self.cells) ** 1.5

    def scaled(self, factor: float) -> "ClumpTemplate":
        """The same shape scaled about the template origin by `factor` (> 0)."""
        if not (math.isfinite(factor) and factor > 0):
            raise ParameterError(f"factor={factor!r}: must be > 0")
        return ClumpTemplate(self.centres * factor, self.radii * factor, self.name, self.cells)

    def save(self, path) -> None:
        """Writes the members as CSV: x, y, z, r (m), with a header."""
        np.savetxt(path, np.column_stack([self.centres, self.radii]), delimiter=",",
                   header=f"clump template {self.name}: x_m,y_m,z_m,r_m", comments="# ")

    @classmethod
    def load(cls, path, name: str | None = None, cells: int = 160) -> "ClumpTemplate":
        """Reads a template written by :meth:`save` (or any CSV of x, y, z, r in m, with or
        without one header line)."""
        try:
            a = np.loadtxt(path, delimiter=",", ndmin=2)
        except ValueError:  # a header line such as "x,y,z,r"
            a = np.loadtxt(path, delimiter=",", ndmin=2, skiprows=1)
        if a.shape[1] != 4:
            raise ParameterError(f"{path}: has {a.shape[1]} columns; a template CSV has 4 (x, y, z, r in m)")
        import os
        return cls(a[:, :3], a[:, 3], name or os.path.splitext(os.path.basename(str(path)))[0], cells)


def random_orientations(n: int, seed: int = 0) -> np.ndarray:
    """n uniformly random rotations as unit quaternions (w, x, y, z), seeded (Shoemake's
    method)."""
    rng = np.random.default_rng(seed)
    u1, u2, u3 = rng.random((3, n))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    return np.column_stack([b * np.cos(2 * math.pi * u3), a * np.sin(2 * math.pi * u2),
                            a * np.cos(2 * math.pi * u2), b * np.sin(2 * math.pi * u3)])


@dataclass(frozen=True)
class ClumpCloud:
    """A loose cloud of clumps: per clump the template index (into the templates given to
    :func:`clump_cloud`), centre of mass (m), orientation (w, x, y, z) and scale factor."""

    template: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray
    scales: np.ndarray

    def __len__(self) -> int:
        return len(self.template)

    def add_to(self, scene, templates, *, material: int, stiffness: str = "member") -> np.ndarray:
        """Adds the clumps to ``scene`` (stiffness: see Scene.add_clumps); returns their clump
        indices in cloud order."""
        templates = _templates(templates)
        out = np.empty(len(self), dtype=int)
        for k, t in enumerate(templates):
            sel = np.flatnonzero(self.template == k)
            if len(sel):
                out[sel] = scene.add_clumps(t, self.positions[sel], self.orientations[sel],
                                            material=material, scale=self.scales[sel],
                                            stiffness=stiffness)
        return out


def _templates(templates) -> list:
    ts = [templates] if isinstance(templates, ClumpTemplate) else list(templates)
    if not ts or not all(isinstance(t, ClumpTemplate) for t in ts):
        raise ParameterError("templates: must be a ClumpTemplate or a non-empty list of them")
    return ts


def clump_cloud(templates, diameters, lo, hi, *, seed: int = 0, max_tries: int = 2000) -> ClumpCloud:
    """Clumps placed at random, without overlap, in the box [lo, hi] (m): one per entry of
    ``diameters`` (equivalent-volume diameters, m, e.g. from cpp_dem.build.psd.radii_from_psd
    times 2), each a copy of one of ``templates`` (chosen at random, seeded) scaled to that
    diameter, at a uniformly random orientation (seeded). Placement is random sequential
    addition of the clumps' bounding spheres (cpp_dem.build.packing.loose_cloud), so the cloud is
    loose (compact it with radius growth or the servo walls)."""
    ts = _templates(templates)
    d = np.asarray(diameters, dtype=float).ravel()
    if len(d) == 0 or not np.all(np.isfinite(d) & (d > 0)):
        raise ParameterError("diameters: must be a non-empty list of equivalent diameters > 0 (m)")
    rng = np.random.default_rng(seed)
    which = rng.integers(0, len(ts), len(d)) if len(ts) > 1 else np.zeros(len(d), dtype=int)
    scale = d / np.array([ts[k].equivalent_diameter for k in which])
    rb = scale * np.array([ts[k].bounding_radius for k in which])
    # Tiny distinct offsets keep the bounding radii unique, so each placed sphere maps back
    # to its clump (loose_cloud returns the spheres in space order).
    rb_key = rb * (1 + 1e-12 * np.arange(len(rb)))
    pos, rr = loose_cloud(rb_key, lo, hi, seed=seed, max_tries=max_tries)
    order = np.argsort(rb_key, kind="stable")
    idx = order[np.searchsorted(rb_key[order], rr)]
    return ClumpCloud(which[idx], pos, random_orientations(len(d), seed + 1), scale[idx])


def bounding_volume_factor(templates) -> float:
    """Mean (bounding radius / equivalent radius)^3 of the templates: how much more room a
    clump's bounding sphere takes than its volume, for sizing loose clouds."""
    return float(np.mean([(t.bounding_radius / (0.5 * t.equivalent_diameter)) ** 3
                          for t in _templates(templates)]))
