"""gmsh geometry of a reinforced soil body (plane strain 2D or 3D) with tagged regions.

Coordinates (SI, m). The body is the half (2D) or quarter/slab (3D) next to a symmetry plane
x = 0 under a footing:

- **2D (plane strain)**: ``[0, width_m] x [0, height_m]`` in (x, z); z is vertical (up),
  y is the out-of-plane direction. Stresses reported as 3x3 tensors are ordered (x, y, z).
- **3D**: ``[0, width_m] x [0, length_m] x [0, height_m]`` in (x, y, z), z up; the footing is
  a strip ``[0, footing_half_width_m] x [0, length_m]`` on the top (y = 0 and y = length_m
  are rollers, i.e. a slab of a plane-strain strip), or with ``footing_length_m`` the
  rectangle ``[0, footing_half_width_m] x [0, footing_length_m]``: a quarter of a footing
  2 b x 2 l, x = 0 and y = 0 its planes of symmetry.

Physical groups (cell tags and facet tags are separate namespaces):

=============== ====================================================================
cell tag 1      soil
cell tag 100+i  geogrid layer i (a thin band ``thickness_m`` thick, ``x_min_m..x_max_m``)
cell tag 200+j  DEM element region j (square/cube of edge ``size_m``), soil cells only:
                where a geogrid layer crosses a region its cells keep the layer tag
facet 1         bottom z = 0            facet 2  top, free surface (outside the footing)
facet 3         x = 0 (symmetry)        facet 4  x = width_m
facet 5         footing (top, x <= footing_half_width_m)
facet 6, 7      y = 0, y = length_m (3D only)
=============== ====================================================================

Only :func:`build_mesh` touches gmsh and dolfinx (lazily); the specification dataclasses are
plain Python so that they can be pickled and validated without the FEM stack.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from femcoupling import _dolfinx
from femcoupling._checks import (_CELLS_PER_SIZE, FemInputError, _check_cells, _choice, _pos,
                                 _real)
from femcoupling.fem.gmsh_mesh import gmsh_mesh_on_root

__all__ = [
    "SOIL_TAG", "LAYER_TAG0", "REGION_TAG0", "BOTTOM", "TOP", "X_MIN", "X_MAX", "FOOTING",
    "Y_MIN", "Y_MAX", "FemInputError", "GeogridLayer", "ElementRegion", "ReinforcedSoilBody",
    "MeshBundle", "build_mesh",
]

SOIL_TAG = 1
"""Cell tag of the soil."""
LAYER_TAG0 = 100
"""Cell tag of geogrid layer i is LAYER_TAG0 + i."""
REGION_TAG0 = 200
"""Cell tag of DEM element region j is REGION_TAG0 + j."""
BOTTOM, TOP, X_MIN, X_MAX, FOOTING, Y_MIN, Y_MAX = 1, 2, 3, 4, 5, 6, 7
"""Facet tags (see the module doc)."""

_counter = itertools.count()


@dataclasses.dataclass(frozen=True)
class GeogridLayer:
    """A geogrid layer: a thin horizontal band of cells.

    Attributes:
        z_m: elevation of the layer's mid-plane, m (0 < z_m < height).
        x_min_m, x_max_m: horizontal extent, m.
        thickness_m: band thickness t, m; the layer's cells get Young's modulus J / t
            (J the geogrid's axial stiffness, N/m) in :mod:`femcoupling.fem.soil_body`.
        name: label used in reports and outputs.
    """

    z_m: float
    x_min_m: float
    x_max_m: float
    thickness_m: float = 0.01
    name: str = ""

    def __post_init__(self) -> None:
        _real("GeogridLayer.z_m", self.z_m)
        _real("GeogridLayer.x_min_m", self.x_min_m)
        _pos("GeogridLayer.thickness_m", self.thickness_m)
        if _real("GeogridLayer.x_max_m", self.x_max_m) <= self.x_min_m:
            raise FemInputError(f"GeogridLayer.x_max_m={self.x_max_m!r}: must be > x_min_m="
                                f"{self.x_min_m!r}")


@dataclasses.dataclass(frozen=True)
class ElementRegion:
    """A DEM element region: an axis-aligned square (2D) or cube (3D) of edge ``size_m``.

    Attributes:
        name: label (the key of the handover).
        center_m: centre (x, z) in 2D or (x, y, z) in 3D, m.
        size_m: edge length, m (002: a 0.1 m cube).
    """

    name: str
    center_m: tuple[float, ...]
    size_m: float = 0.1

    def __post_init__(self) -> None:
        if not self.name:
            raise FemInputError("ElementRegion.name='': must be a non-empty string")
        for k, c in enumerate(self.center_m):
            _real(f"ElementRegion.center_m[{k}]", c)
        _pos("ElementRegion.size_m", self.size_m)


@dataclasses.dataclass(frozen=True)
class ReinforcedSoilBody:
    """A reinforced soil body with a footing on its top, geogrid layers and element regions.

    Attributes:
        width_m: extent in x from the symmetry plane x = 0, m.
        height_m: extent in z (vertical), m.
        footing_half_width_m: half width b of the (strip) footing, m (<= width_m; = width_m
            loads the whole top: a uniform surcharge, e.g. an oedometric homogeneous field).
        layers: geogrid layers.
        regions: DEM element regions (each must lie inside the body).
        dim: 2 (plane strain) or 3.
        length_m: extent in y for dim = 3, m (ignored in 2D).
        footing_length_m: dim = 3 only: the footing's extent in y from the symmetry plane
            y = 0, m (< length_m: a rectangular footing, a quarter of it; ``footing_half_width_m``
            for a square one). None (the default): the whole length, a strip.
        mesh_size_m: element size far from the footing, m.
        fine_size_m: element size at the footing edge, in the element regions and along the
            layers, m.
        fine_radius_m: distance from the footing edge within which ``fine_size_m`` applies;
            the size grows linearly to ``mesh_size_m`` over 4 x this distance, m. Default
            (0) means 2 b.
        max_cells: the most cells the mesh may have (estimated before gmsh meshes:
            :meth:`estimated_cells`); a body above it is refused. None (the default) is
            900 000 in 2D and 150 000 in 3D: about 12 GiB each for a Drucker-Prager
            :class:`~femcoupling.fem.model.FemModel` with P2 elements (13 KiB per
            triangle, 79 KiB per tetrahedron measured, docs/fem.md), half of a 24 GiB
            machine; raise it to mesh more on a bigger one.

    Geogrid layers must not overlap (nor coincide), nor element regions: each cell carries
    one layer's or one region's tag.
    """

    width_m: float
    height_m: float
    footing_half_width_m: float
    layers: tuple[GeogridLayer, ...] = ()
    regions: tuple[ElementRegion, ...] = ()
    dim: int = 2
    length_m: float = 1.0
    mesh_size_m: float = 0.5
    fine_size_m: float = 0.05
    fine_radius_m: float = 0.0
    max_cells: int | None = None
    footing_length_m: float | None = None

    def __post_init__(self) -> None:
        w = _pos("width_m", self.width_m)
        h = _pos("height_m", self.height_m)
        b = _pos("footing_half_width_m", self.footing_half_width_m)
        if b > w:
            raise FemInputError(f"footing_half_width_m={b!r}: must be <= width_m={w!r} "
                                "(= width_m: a uniform surcharge on the whole top)")
        _choice("dim", self.dim, (2, 3), "2 or 3")
        _pos("length_m", self.length_m)
        if self.footing_length_m is not None:
            if self.dim != 3:
                raise FemInputError(f"footing_length_m={self.footing_length_m!r}: only for "
                                    "dim = 3 (in 2D the footing is a plane-strain strip)")
            if _pos("footing_length_m", self.footing_length_m) > self.length_m:
                raise FemInputError(f"footing_length_m={self.footing_length_m!r}: must be <= "
                                    f"length_m={self.length_m!r} (= length_m: a strip)")
        _pos("mesh_size_m", self.mesh_size_m)
        _pos("fine_size_m", self.fine_size_m)
        if self.fine_size_m > self.mesh_size_m:
            raise FemInputError(f"fine_size_m={self.fine_size_m!r}: must be <= mesh_size_m="
                                f"{self.mesh_size_m!r} (the fine size refines the mesh)")
        if _real("fine_radius_m", self.fine_radius_m) < 0:
            raise FemInputError(f"fine_radius_m={self.fine_radius_m!r}: must be >= 0")
        object.__setattr__(self, "layers", tuple(self.layers))
        object.__setattr__(self, "regions", tuple(self.regions))
        for i, lay in enumerate(self.layers):
            if not isinstance(lay, GeogridLayer):
                raise FemInputError(f"layers[{i}]={lay!r}: must be a GeogridLayer")
            if not (0 < lay.z_m - lay.thickness_m / 2 and lay.z_m + lay.thickness_m / 2 < h):
                raise FemInputError(f"layers[{i}].z_m={lay.z_m!r}: the band must lie inside "
                                    f"(0, height_m={h!r})")
            if lay.x_min_m < 0 or lay.x_max_m > w:
                raise FemInputError(f"layers[{i}]: x range [{lay.x_min_m}, {lay.x_max_m}] "
                                    f"must lie inside [0, width_m={w}]")
        names = set()
        for j, reg in enumerate(self.regions):
            if not isinstance(reg, ElementRegion):
                raise FemInputError(f"regions[{j}]={reg!r}: must be an ElementRegion")
            if reg.name in names:
                raise FemInputError(f"regions[{j}].name={reg.name!r}: duplicate region name")
            names.add(reg.name)
            if len(reg.center_m) != self.dim:
                raise FemInputError(f"regions[{j}].center_m={reg.center_m!r}: needs {self.dim} "
                                    "coordinates")
            extent = (w, h) if self.dim == 2 else (w, self.length_m, h)
            for k, (c, e) in enumerate(zip(reg.center_m, extent)):
                if c - reg.size_m / 2 < 0 or c + reg.size_m / 2 > e:
                    raise FemInputError(f"regions[{j}].center_m[{k}]={c!r}: the region "
                                        f"(size {reg.size_m}) must lie inside [0, {e}]")
        self._check_overlaps()
        _check_cells(f"mesh_size_m={self.mesh_size_m!r}, fine_size_m={self.fine_size_m!r}",
                     self.estimated_cells(), self.max_cells, self.dim)

    def _check_overlaps(self) -> None:
        """Refuses geogrid layers that overlap (or coincide) and element regions that
        overlap, naming both and their extents."""
        def span(lay):
            return (lay.z_m - lay.thickness_m / 2, lay.z_m + lay.thickness_m / 2)

        tol = 1e-9 * max(self.width_m, self.height_m)  # touching by construction is allowed
        for i, a in enumerate(self.layers):
            for k in range(i):
                b = self.layers[k]
                (a0, a1), (b0, b1) = span(a), span(b)
                if (a0 < b1 - tol and b0 < a1 - tol and a.x_min_m < b.x_max_m - tol
                        and b.x_min_m < a.x_max_m - tol):
                    raise FemInputError(
                        f"layers[{i}] (z {a0:g}..{a1:g} m, x {a.x_min_m:g}..{a.x_max_m:g} m) "
                        f"overlaps layers[{k}] (z {b0:g}..{b1:g} m, x {b.x_min_m:g}.."
                        f"{b.x_max_m:g} m): geogrid layers must not overlap or coincide (a "
                        "cell carries one layer); merge them into one, or move one")
        for j, a in enumerate(self.regions):
            for k in range(j):
                b = self.regions[k]
                if all(abs(ca - cb) < (a.size_m + b.size_m) / 2 - tol
                       for ca, cb in zip(a.center_m, b.center_m)):
                    raise FemInputError(
                        f"regions[{j}] {a.name!r} ({_box_text(a)}) overlaps regions[{k}] "
                        f"{b.name!r} ({_box_text(b)}): element regions must not overlap (a "
                        "cell belongs to one region)")

    def estimated_cells(self) -> float:
        """The number of cells gmsh will make, estimated from the body's size and the mesh
        size field (coarse everywhere, fine in the regions and along the layers with their
        transition, graded about the footing edge), without meshing. Overlapping refinements
        are counted twice, so it errs high; measured against gmsh within a factor of 2
        (docs/fem.md)."""
        d = self.dim
        w, h, b, ly = self.width_m, self.height_m, self.footing_half_width_m, self.length_m
        fine, coarse = self.fine_size_m, self.mesh_size_m
        per = _CELLS_PER_SIZE[d]  # cells per h^d of volume at a uniform size h
        depth = 1.0 if d == 2 else ly  # the 2D figures times the extent in y

        def extra(size):  # cells per m^d at `size`, above the coarse background
            return per * (size ** -d - coarse ** -d)

        n = per * w * h * depth / coarse ** d
        # The element regions and the layers: fine inside, through half of the 4 x fine
        # transition about them.
        boxes = [(reg.size_m, reg.size_m, reg.size_m if d == 3 else 1.0)
                 for reg in self.regions]
        boxes += [(lay.x_max_m - lay.x_min_m, lay.thickness_m, ly if d == 3 else 1.0)
                  for lay in self.layers]
        for bx in boxes:
            vol = (bx[0] + 4 * fine) * (bx[1] + 4 * fine)
            vol *= (min(bx[2] + 4 * fine, ly) if d == 3 else 1.0)
            n += vol * extra(fine)
        # The footing edge: fine within R of it, graded to coarse over R..5R (integrated on a
        # grid of the cross-section (x, z) near it; in 3D along the edge's length).
        r = self.fine_radius_m or 2.0 * b
        x0, x1 = max(0.0, b - 5 * r), min(w, b + 5 * r)
        z0 = max(0.0, h - 5 * r)
        m = 200
        hx, hz = (x1 - x0) / m, (h - z0) / m
        x = x0 + (np.arange(m) + 0.5) * hx
        z = z0 + (np.arange(m) + 0.5) * hz
        dist = np.hypot(x[:, None] - b, z[None, :] - h)
        size = fine + (coarse - fine) * np.clip((dist - r) / (4 * r), 0.0, 1.0)
        total = float(extra(size).sum())
        # (a rectangular footing: its two edges, x = b and y = its length, on the top)
        edge = depth if d == 2 else self.footing_y_m + (b if self.footing_y_m < ly else 0.0)
        n += total * hx * hz * edge
        return n

    @property
    def footing_y_m(self) -> float:
        """The footing's extent in y, m (3D; the whole length for a strip)."""
        return self.length_m if self.footing_length_m is None else self.footing_length_m

    def region_tag(self, name: str) -> int:
        """Cell tag of the element region called ``name``."""
        for j, reg in enumerate(self.regions):
            if reg.name == name:
                return REGION_TAG0 + j
        raise FemInputError(f"region={name!r}: no such region (have "
                            f"{[r.name for r in self.regions]})")

    def region(self, name: str) -> ElementRegion:
        """The element region called ``name``."""
        return self.regions[self.region_tag(name) - REGION_TAG0]

    def region_layers(self, name: str) -> list[int]:
        """Indices of the geogrid layers that cross the element region ``name``: their
        mid-plane lies within its height and their x range overlaps its x range."""
        reg = self.region(name)
        h = reg.size_m / 2
        x, z = reg.center_m[0], reg.center_m[-1]
        return [i for i, lay in enumerate(self.layers)
                if abs(lay.z_m - z) < h and lay.x_min_m < x + h and lay.x_max_m > x - h]

    def layer_tags(self) -> list[int]:
        """Cell tags of the geogrid layers."""
        return [LAYER_TAG0 + i for i in range(len(self.layers))]


def _box_text(reg: ElementRegion) -> str:
    s = reg.size_m / 2
    return ", ".join(f"{'xyz'[k] if len(reg.center_m) == 3 else 'xz'[k]} {c - s:g}..{c + s:g} m"
                     for k, c in enumerate(reg.center_m))


@dataclasses.dataclass
class MeshBundle:
    """The dolfinx mesh and its tags (the only dolfinx-typed object of the package's API)."""

    mesh: Any
    cell_tags: Any
    facet_tags: Any
    body: ReinforcedSoilBody


def _inside(p: Sequence[float], lo: Sequence[float], hi: Sequence[float], tol: float) -> bool:
    return all(lo[k] - tol <= p[k] <= hi[k] + tol for k in range(len(lo)))


def _build(gmsh: Any, body: ReinforcedSoilBody) -> None:
    occ = gmsh.model.occ
    dim = body.dim
    w, h, b, ly = body.width_m, body.height_m, body.footing_half_width_m, body.length_m
    tol = 1e-7 * max(w, h)
    pieces = []
    if dim == 2:
        pieces.append((2, occ.addRectangle(0, 0, 0, b, h)))
        if b < w:
            pieces.append((2, occ.addRectangle(b, 0, 0, w - b, h)))
    else:
        lf = body.footing_y_m
        pieces.append((3, occ.addBox(0, 0, 0, b, lf, h)))
        if lf < ly:  # (a rectangular footing: the soil beside it along y)
            pieces.append((3, occ.addBox(0, lf, 0, b, ly - lf, h)))
        if b < w:
            pieces.append((3, occ.addBox(b, 0, 0, w - b, ly, h)))
    layer_boxes = []
    for lay in body.layers:
        z0 = lay.z_m - lay.thickness_m / 2
        if dim == 2:
            pieces.append((2, occ.addRectangle(lay.x_min_m, z0, 0, lay.x_max_m - lay.x_min_m,
                                               lay.thickness_m)))
            layer_boxes.append(((lay.x_min_m, z0), (lay.x_max_m, z0 + lay.thickness_m)))
        else:
            pieces.append((3, occ.addBox(lay.x_min_m, 0, z0, lay.x_max_m - lay.x_min_m, ly,
                                         lay.thickness_m)))
            layer_boxes.append(((lay.x_min_m, 0, z0), (lay.x_max_m, ly, z0 + lay.thickness_m)))
    region_boxes = []
    for reg in body.regions:
        s = reg.size_m
        lo = tuple(c - s / 2 for c in reg.center_m)
        if dim == 2:
            pieces.append((2, occ.addRectangle(lo[0], lo[1], 0, s, s)))
        else:
            pieces.append((3, occ.addBox(lo[0], lo[1], lo[2], s, s, s)))
        region_boxes.append((lo, tuple(c + s / 2 for c in reg.center_m)))
    if len(pieces) > 1:
        occ.fragment(pieces[:1], pieces[1:])
    occ.synchronize()

    # Classify cells by their centres of mass: layer first (a layer crossing a region keeps
    # the layer tag), then region, else soil.
    groups: dict[int, list[int]] = {}
    for _, ent in gmsh.model.getEntities(dim):
        com = occ.getCenterOfMass(dim, ent)
        p = (com[0], com[1]) if dim == 2 else com
        tag = SOIL_TAG
        for i, (lo, hi) in enumerate(layer_boxes):
            if _inside(p, lo, hi, tol):
                tag = LAYER_TAG0 + i
                break
        else:
            for j, (lo, hi) in enumerate(region_boxes):
                if _inside(p, lo, hi, tol):
                    tag = REGION_TAG0 + j
                    break
        groups.setdefault(tag, []).append(ent)
    names = {SOIL_TAG: "soil"}
    names.update({LAYER_TAG0 + i: l.name or f"layer{i}" for i, l in enumerate(body.layers)})
    names.update({REGION_TAG0 + j: r.name for j, r in enumerate(body.regions)})
    for tag, ents in sorted(groups.items()):
        gmsh.model.addPhysicalGroup(dim, ents, tag, name=names[tag])

    # Boundary facets by centre of mass.
    zc = 1 if dim == 2 else 2
    fgroups: dict[int, list[int]] = {}
    for _, f in gmsh.model.getBoundary(gmsh.model.getEntities(dim), combined=True,
                                       oriented=False):
        c = occ.getCenterOfMass(dim - 1, f)
        if abs(c[zc]) < tol:
            t = BOTTOM
        elif abs(c[zc] - h) < tol:
            on = c[0] < b + tol and (dim == 2 or c[1] < body.footing_y_m + tol)
            t = FOOTING if on else TOP
        elif abs(c[0]) < tol:
            t = X_MIN
        elif abs(c[0] - w) < tol:
            t = X_MAX
        elif dim == 3 and abs(c[1]) < tol:
            t = Y_MIN
        elif dim == 3 and abs(c[1] - ly) < tol:
            t = Y_MAX
        else:
            raise RuntimeError(f"gmsh: unclassified boundary facet at {c}")
        fgroups.setdefault(t, []).append(f)
    fnames = {BOTTOM: "bottom", TOP: "top", X_MIN: "x_min", X_MAX: "x_max", FOOTING: "footing",
              Y_MIN: "y_min", Y_MAX: "y_max"}
    for t, ents in sorted(fgroups.items()):
        gmsh.model.addPhysicalGroup(dim - 1, ents, t, name=fnames[t])

    # Mesh size: fine at the footing edge (graded away from it), in the regions and layers.
    fine, coarse = body.fine_size_m, body.mesh_size_m
    radius = body.fine_radius_m or 2.0 * b
    f = gmsh.model.mesh.field
    e = 1e-6 * max(w, h)
    edge_dim = 0 if dim == 2 else 1
    hi_y = 0.0 if dim == 2 else body.footing_y_m
    zlo = (b - e, -e, h - e) if dim == 3 else (b - e, h - e, -e)
    zhi = (b + e, hi_y + e, h + e) if dim == 3 else (b + e, h + e, e)
    edge = [t for _, t in gmsh.model.getEntitiesInBoundingBox(*zlo, *zhi, dim=edge_dim)]
    if dim == 3 and hi_y < ly:  # (a rectangular footing: and its edge y = hi_y, x <= b)
        edge += [t for _, t in gmsh.model.getEntitiesInBoundingBox(
            -e, hi_y - e, h - e, b + e, hi_y + e, h + e, dim=edge_dim) if t not in edge]
    if not edge:
        raise RuntimeError("gmsh: footing edge not found")
    dist = f.add("Distance")
    f.setNumbers(dist, "PointsList" if dim == 2 else "CurvesList", edge)
    if dim == 3:
        f.setNumber(dist, "Sampling", 50)
    thr = f.add("Threshold")
    f.setNumber(thr, "InField", dist)
    f.setNumber(thr, "SizeMin", fine)
    f.setNumber(thr, "SizeMax", coarse)
    f.setNumber(thr, "DistMin", radius)
    f.setNumber(thr, "DistMax", 5.0 * radius)
    fields = [thr]
    for lo, hi in region_boxes + layer_boxes:
        bx = f.add("Box")
        f.setNumber(bx, "VIn", fine)
        f.setNumber(bx, "VOut", coarse)
        keys = ("XMin", "YMin", "ZMin") if dim == 3 else ("XMin", "YMin")
        for k, key in enumerate(keys):
            f.setNumber(bx, key, lo[k])
            f.setNumber(bx, key.replace("Min", "Max"), hi[k])
        f.setNumber(bx, "Thickness", 4 * fine)
        fields.append(bx)
    mn = f.add("Min")
    f.setNumbers(mn, "FieldsList", fields)
    f.setAsBackgroundMesh(mn)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    gmsh.model.mesh.generate(dim)


def build_mesh(body: ReinforcedSoilBody, *, comm: Any = None) -> MeshBundle:
    """Build the body in gmsh (rank 0) and distribute it with ``model_to_mesh``. Collective."""
    fx = _dolfinx.load()
    if comm is None:
        comm = fx.MPI.COMM_WORLD
    if not isinstance(body, ReinforcedSoilBody):
        raise FemInputError(f"body={body!r}: must be a ReinforcedSoilBody")
    data = gmsh_mesh_on_root(comm, f"femcoupling_body_{next(_counter)}",
                             lambda gmsh: _build(gmsh, body), gdim=body.dim,
                             what="build the body")
    return MeshBundle(mesh=data.mesh, cell_tags=data.cell_tags, facet_tags=data.facet_tags,
                      body=body)
