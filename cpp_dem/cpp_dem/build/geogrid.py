"""Geogrid builders and member measurements (000 §2.2, 001 §4.1, App. A, §5.2).

A geogrid is made of grid nodes (6-DOF bodies), cohesive links between them (each also a
Minkowski-sum cylinder grains can touch) and, for flat ribs, PFacets (triangles of three
nodes and their three links). Builders return a :class:`Geogrid` that knows its members:

- a *member* is a rib between two junctions (or, for cylinder grids, one link), labelled by
  direction (``longitudinal`` along the pull direction x, ``transverse`` along y,
  ``diagonal`` for triangular grids), by aperture cell ``(i, j)`` and by its side in that cell;
- sides follow 000 Fig. 6 in this convention: for cell (i, j) (x between junction columns i and
  i + 1, y between rows j and j + 1), **A** is the longitudinal member on its low-y edge, **D**
  the longitudinal member on its high-y edge, **C** the transverse member on its low-x edge and
  **B** the transverse member on its high-x edge. Each member is stored once, labelled as the A
  (longitudinal) or C (transverse) member of the cell it borders on its low side;
  :meth:`Geogrid.cell_members` returns all four sides of a cell.

Mass comes from the unit weight (000 Table 1: 981 N/m^3) and is lumped at the nodes: each link
contributes rho pi R_c^2 L (half to each end) unless it belongs to a PFacet, whose slab
(area x thickness 2 R_c) contributes a third to each node. ``node_density_scale`` multiplies
the node masses and inertias: it raises the critical time step of the stiff grid (which
dominates it with 000's 4 GPa grid in 1 MPa grains) at the price of the grid's inertia; it
changes nothing in a quasi-static equilibrium but slows the grid's dynamic response.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Sequence

import numpy as np

from cpp_dem._checks import positive
from cpp_dem._core import BeamParams, ParameterError
from cpp_dem.fixedorder import norm, unit

G_STANDARD = 9.81  # m/s^2, to turn unit weights into densities

LONGITUDINAL, TRANSVERSE, DIAGONAL, JUNCTION = "longitudinal", "transverse", "diagonal", "junction"


@dataclasses.dataclass
class Geogrid:
    """A geogrid in a scene: node and link ids and the member labels.

    Attributes (arrays over members unless said otherwise)
    ------------------------------------------------------
    nodes : body ids of the grid nodes.
    links : link ids of the grid (indices into scene.grid_link_*).
    pfacets : PFacet ids.
    member_direction : 'longitudinal', 'transverse' or 'diagonal'.
    member_cell : (n_members, 2) aperture cell (i, j); -1 where a member borders no cell.
    member_side : 'A' (longitudinal) or 'C' (transverse) in member_cell; '' otherwise.
    member_axis : (n_members, 3) unit vector along the member.
    member_section_links : list of arrays of link ids cut by the member's mid-section.
    member_links : list of arrays of all link ids of the member.
    area : cross-section area of each member, m^2 (for stresses).
    reference_positions : (n_nodes, 3) node positions when the grid was built, m (the
        reference of the node displacements written by write_vtk_geogrid).
    """

    nodes: np.ndarray
    links: np.ndarray
    pfacets: np.ndarray
    member_direction: np.ndarray
    member_cell: np.ndarray
    member_side: np.ndarray
    member_axis: np.ndarray
    member_section_links: list
    member_links: list
    area: np.ndarray
    n_cells: tuple[int, int] = (0, 0)
    reference_positions: np.ndarray | None = None

    @property
    def n_members(self) -> int:
        return len(self.member_direction)

    def member_axial_forces(self, scene) -> np.ndarray:
        """Axial force of every member, N, tension positive: the sum over the links cut by the
        member's mid-section of the link axial force projected on the member axis (each
        member's links summed in their order: :func:`section_sums`)."""
        links, member, starts = self._section_index
        nodes = np.asarray(scene.grid_link_nodes)[links]
        pos = np.asarray(scene.positions)
        d = pos[nodes[:, 1]] - pos[nodes[:, 0]]
        d /= np.linalg.norm(d, axis=1)[:, None]
        # (each row's d @ axis as a stack of 1 x 3 by 3 x 1 products: the loop's d @ axis,
        # bitwise, also for axes off x and y)
        proj = np.abs(np.matmul(d[:, None, :], self.member_axis[member][:, :, None])[:, 0, 0])
        terms = np.asarray(scene.grid_link_axial_forces)[links] * proj
        return section_sums(terms, starts, self.n_members)

    @functools.cached_property
    def _section_index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The members' section links flattened, computed once (a grid's sections do not
        change after it is built): (the links in member order, each one's member, where each
        member's run starts)."""
        lens = [len(sec) for sec in self.member_section_links]
        flat = (np.concatenate([np.asarray(sec, dtype=np.int64)
                                for sec in self.member_section_links])
                if sum(lens) else np.zeros(0, dtype=np.int64))
        member = np.repeat(np.arange(len(lens)), lens)
        starts = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)
        return flat, member, starts

    def member_axial_stresses(self, scene) -> np.ndarray:
        """Axial stress of every member, Pa, tension positive (force / cross-section area)."""
        return self.member_axial_forces(scene) / self.area

    def cell_members(self, i: int, j: int) -> dict[str, int]:
        """Member indices on the sides A, B, C, D of aperture cell (i, j) (see module doc)."""
        out = {}
        for side, (ci, cj, s) in {"A": (i, j, "A"), "D": (i, j + 1, "A"),
                                  "C": (i, j, "C"), "B": (i + 1, j, "C")}.items():
            hit = np.flatnonzero((self.member_cell[:, 0] == ci) & (self.member_cell[:, 1] == cj)
                                 & (self.member_side == s))
            if len(hit):
                out[side] = int(hit[0])
        return out

    def grouped_forces(self, scene) -> dict:
        """Member axial forces (N) grouped by (cell i, cell j, direction)."""
        f = self.member_axial_forces(scene)
        groups: dict = {}
        for m in range(self.n_members):
            key = (int(self.member_cell[m, 0]), int(self.member_cell[m, 1]),
                   str(self.member_direction[m]))
            groups.setdefault(key, []).append(float(f[m]))
        return groups

    def node_displacements(self, scene, reference: np.ndarray) -> np.ndarray:
        """Displacements of the grid nodes from reference positions (n_nodes, 3), m."""
        return scene.positions[self.nodes] - reference

    def link_member(self) -> np.ndarray:
        """For every link of the grid, the member it belongs to (-1 for junction links)."""
        lm = -np.ones(int(self.links.max()) + 1 if len(self.links) else 0, dtype=int)
        for m, ls in enumerate(self.member_links):
            lm[ls] = m
        return lm[self.links]


# ---- helpers -------------------------------------------------------------------------------


def section_sums(terms: np.ndarray, starts: np.ndarray, n: int) -> np.ndarray:
    """Each member's terms summed, (n,): the contiguous run of ``terms`` from each of
    ``starts`` (``Geogrid._section_index``), added one after the other from 0 as ``np.sum``
    adds a short run (so bitwise its sum; ``np.add.reduceat`` adds in another order); 0 for
    a member without any."""
    out = np.zeros(n)
    lens = np.diff(np.append(starts, len(terms)))
    for k in range(int(lens.max()) if n else 0):  # (a section has a few links at most)
        has = lens > k
        out[has] += terms[starts[has] + k]
    return out


def _check_count(name: str, value, least: int) -> int:
    """A whole number >= least, or ParameterError naming the field."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ParameterError(f"{name}={value!r}: must be a whole number >= {least}")
    if value < least:
        raise ParameterError(f"{name}={value}: must be >= {least}")
    return int(value)


def _check_origin(origin) -> np.ndarray:
    try:
        o = np.asarray(origin, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"origin={origin!r}: must be 3 numbers (m)") from None
    if o.shape != (3,) or not np.all(np.isfinite(o)):
        raise ParameterError(f"origin={origin!r}: must be 3 finite numbers (m)")
    return o


#: The default ``max_nodes`` of the grid builders: a square grid takes about 2.6 kB and 0.11 ms
#: of building per node (nodes, two links each, the builder's tables; measured from 10 000 to
#: 90 000 nodes: 23 to 229 MiB, 0.9 to 10 s), so 2 000 000 nodes are about 5 GiB and 4 min.
MAX_GRID_NODES = 2_000_000
_GRID_BYTES_PER_NODE = 2600
_GRID_S_PER_NODE = 1.1e-4


def _check_grid_size(what: str, nodes: float, max_nodes) -> None:
    """Refuses a grid of ``nodes`` nodes (counted before anything is built) above
    ``max_nodes`` (None: MAX_GRID_NODES); the message names ``what`` (the arguments that set
    the size) and the estimate."""
    cap = MAX_GRID_NODES if max_nodes is None else _check_count("max_nodes", max_nodes, 1)
    if nodes > cap:
        raise ParameterError(
            f"{what}: {nodes:.3g} grid nodes (about {nodes * _GRID_BYTES_PER_NODE / 2**30:.3g} "
            f"GiB and {nodes * _GRID_S_PER_NODE / 60:.3g} min to build), above max_nodes={cap}"
            f"{' (the default)' if max_nodes is None else ''}; use fewer nodes, or raise "
            "max_nodes if the machine has the memory")


def _check_members_apart(spacing: float, radius: float, what: str) -> None:
    """Cylinders of radius R_c whose axes are `spacing` apart must not overlap (2 R_c <)."""
    if not 2 * radius < spacing:
        raise ParameterError(f"params.radius={radius}: the members would overlap; 2 x radius "
                             f"must be < the {what} {spacing:g} m")


class _Builder:
    """Accumulates nodes, links, facets and lumped masses, then adds them to the scene."""

    def __init__(self, params: BeamParams, density: float):
        self.params = params
        self.density = density
        self.points: list[np.ndarray] = []
        self.key_to_node: dict = {}
        self.links: dict[tuple[int, int], int] = {}
        self.link_list: list[tuple[int, int]] = []
        self.facets: list[tuple[int, int, int]] = []

    def node(self, key, xyz) -> int:
        if key not in self.key_to_node:
            self.key_to_node[key] = len(self.points)
            self.points.append(np.asarray(xyz, dtype=float))
        return self.key_to_node[key]

    def link(self, a: int, b: int) -> int:
        k = (min(a, b), max(a, b))
        if k not in self.links:
            self.links[k] = len(self.link_list)
            self.link_list.append((a, b))
        return self.links[k]

    def facet(self, a: int, b: int, c: int) -> None:
        self.link(a, b)
        self.link(b, c)
        self.link(c, a)
        self.facets.append((a, b, c))

    def build(self, scene, material: int, node_density_scale: float):
        pts = np.array(self.points)
        rc = self.params.radius
        mass = np.zeros(len(pts))
        in_facet = set()
        for a, b, c in self.facets:
            area = 0.5 * norm(np.cross(pts[b] - pts[a], pts[c] - pts[a]))
            for n in (a, b, c):
                mass[n] += self.density * area * 2 * rc / 3
            in_facet.update({(min(a, b), max(a, b)), (min(b, c), max(b, c)),
                             (min(a, c), max(a, c))})
        for a, b in self.link_list:
            if (min(a, b), max(a, b)) in in_facet:
                continue
            m = self.density * math.pi * rc**2 * norm(pts[b] - pts[a])
            mass[a] += m / 2
            mass[b] += m / 2
        mass = np.maximum(mass, 1e-12) * node_density_scale
        inertia = 0.4 * mass * rc**2
        first = scene._add_grid_nodes(pts, rc, mass, inertia, material)
        node_ids = first + np.arange(len(pts))
        link_ids = np.array([scene.add_grid_link(int(node_ids[a]), int(node_ids[b]), self.params,
                                                 material) for a, b in self.link_list], dtype=int)
        facet_ids = []
        for a, b, c in self.facets:
            l01 = link_ids[self.links[(min(a, b), max(a, b))]]
            l12 = link_ids[self.links[(min(b, c), max(b, c))]]
            l20 = link_ids[self.links[(min(a, c), max(a, c))]]
            facet_ids.append(scene.add_pfacet(int(node_ids[a]), int(node_ids[b]), int(node_ids[c]),
                                              int(l01), int(l12), int(l20), material))
        return node_ids, link_ids, np.array(facet_ids, dtype=int)


def _density(unit_weight: float | None, density: float | None) -> float:
    if (unit_weight is None) == (density is None):
        raise ParameterError("unit_weight, density: give exactly one (N/m^3 or kg/m^3)")
    if unit_weight is not None:
        positive("unit_weight", unit_weight)
        return unit_weight / G_STANDARD
    positive("density", density)
    return float(density)


def _one_link_members(b: "_Builder", scene, material: int, node_density_scale: float,
                      links_of, direction, cell, side, axis, radius: float,
                      n_cells=(0, 0)) -> Geogrid:
    """Adds the built grid to the scene; every member is a single link (cylinder grids)."""
    nodes, links, facets = b.build(scene, material, node_density_scale)
    member_links = [np.array([links[k]]) for k in links_of]
    n = len(links_of)
    return Geogrid(nodes=nodes, links=links, pfacets=facets,
                   member_direction=np.array(direction), member_cell=np.array(cell).reshape(n, 2),
                   member_side=np.array(side), member_axis=np.array(axis, dtype=float),
                   member_section_links=member_links, member_links=member_links,
                   area=np.full(n, math.pi * radius**2), n_cells=n_cells,
                   reference_positions=np.asarray(scene.positions)[nodes].copy())


# ---- generators ----------------------------------------------------------------------------


def square_grid(scene, *, origin: Sequence[float], length: float, width: float, nodes_x: int,
                nodes_y: int, params: BeamParams, material: int,
                unit_weight: float | None = None, density: float | None = None,
                node_density_scale: float = 1.0, max_nodes: int | None = None) -> Geogrid:
    """Square grid of cylinders in the plane z = origin[2] (001 App. A).

    length (x, the pull direction) and width (y) in m; nodes_x x nodes_y nodes (at most
    ``max_nodes``; None: MAX_GRID_NODES, refused before anything is built); cylinder radius
    from ``params.radius``; mass from unit_weight (N/m^3) or density (kg/m^3).
    """
    positive("length", length)
    positive("width", width)
    positive("node_density_scale", node_density_scale)
    nodes_x = _check_count("nodes_x", nodes_x, 2)
    nodes_y = _check_count("nodes_y", nodes_y, 2)
    _check_grid_size(f"nodes_x={nodes_x}, nodes_y={nodes_y}", nodes_x * nodes_y, max_nodes)
    o = _check_origin(origin)
    b = _Builder(params, _density(unit_weight, density))
    dx, dy = length / (nodes_x - 1), width / (nodes_y - 1)
    _check_members_apart(min(dx, dy), params.radius, "node spacing")
    ids = {}
    for i in range(nodes_x):
        for j in range(nodes_y):
            ids[i, j] = b.node((i, j), o + [i * dx, j * dy, 0.0])
    direction, cell, side, axis, links_of = [], [], [], [], []
    for j in range(nodes_y):
        for i in range(nodes_x - 1):
            links_of.append(b.link(ids[i, j], ids[i + 1, j]))
            direction.append(LONGITUDINAL)
            cell.append((i, j))
            side.append("A")
            axis.append((1.0, 0, 0))
    for i in range(nodes_x):
        for j in range(nodes_y - 1):
            links_of.append(b.link(ids[i, j], ids[i, j + 1]))
            direction.append(TRANSVERSE)
            cell.append((i, j))
            side.append("C")
            axis.append((0, 1.0, 0))
    return _one_link_members(b, scene, material, node_density_scale, links_of, direction, cell,
                             side, axis, params.radius, (nodes_x - 1, nodes_y - 1))


def triangular_grid(scene, *, origin: Sequence[float], length: float, width: float,
                    side: float, params: BeamParams, material: int,
                    unit_weight: float | None = None, density: float | None = None,
                    node_density_scale: float = 1.0, max_nodes: int | None = None) -> Geogrid:
    """Grid of equilateral triangles of edge ``side`` (m) in the plane z = origin[2]
    (001 §5.2: 1.43 cm). Rows along x (longitudinal members), diagonals at +-60 degrees.
    Fills [0, length] x [0, width] with whole triangles. A grid of more than ``max_nodes``
    nodes (None: MAX_GRID_NODES) is refused before it is built; so are biaxial grids."""
    positive("length", length)
    positive("width", width)
    positive("side", side)
    h = side * math.sqrt(3) / 2
    _check_grid_size(f"side={side} on {length} x {width} m",
                     (length / side + 1) * (width / h + 1), max_nodes)
    nx = int(math.floor(length / side + 1e-9)) + 1
    ny = int(math.floor(width / h + 1e-9)) + 1
    if nx < 2 or ny < 2:
        raise ParameterError(f"side={side}: too large for a {length} x {width} m grid")
    o = _check_origin(origin)
    b = _Builder(params, _density(unit_weight, density))
    ids = {}
    for j in range(ny):
        shift = 0.5 * side if j % 2 else 0.0
        for i in range(nx - (1 if j % 2 else 0)):
            ids[i, j] = b.node((i, j), o + [shift + i * side, j * h, 0.0])
    direction, cell, sides, axis, links_of = [], [], [], [], []

    def add(a, c, kind, cij, sd):
        links_of.append(b.link(ids[a], ids[c]))
        direction.append(kind)
        cell.append(cij)
        sides.append(sd)
        p, q = b.points[ids[a]], b.points[ids[c]]
        axis.append(unit(q - p))

    for (i, j) in list(ids):
        if (i + 1, j) in ids:
            add((i, j), (i + 1, j), LONGITUDINAL, (i, j), "A")
        if j + 1 < ny:
            # Neighbours in the next row: even rows connect to (i-1, j+1) and (i, j+1).
            up = [(i - 1, j + 1), (i, j + 1)] if j % 2 == 0 else [(i, j + 1), (i + 1, j + 1)]
            for k, nb in enumerate(up):
                if nb in ids:
                    add((i, j), nb, DIAGONAL, (i, j), "")
    return _one_link_members(b, scene, material, node_density_scale, links_of, direction, cell,
                             sides, axis, params.radius, (nx - 1, ny - 1))


def disc_grid(scene, *, centre: Sequence[float], radius: float, spacing: float,
              pattern: str = "square", params: BeamParams, material: int,
              unit_weight: float | None = None, density: float | None = None,
              node_density_scale: float = 1.0, max_nodes: int | None = None) -> Geogrid:
    """A round geogrid of cylinders in the plane z = centre[2]: the square grid of node
    spacing ``spacing`` (m), or the grid of equilateral triangles of edge ``spacing``
    (``pattern="triangular"``), centred on ``centre`` (a node there), cut to the disc of
    ``radius`` (m): the nodes within it, and the members whose two ends are both kept (a node
    left with no member is dropped). For a cylindrical specimen; ``member_cell`` counts the
    lattice's cells from the disc's lowest row and column, so it is >= 0. The rest as
    :func:`square_grid` (mass from unit_weight or density, ``max_nodes`` counted first)."""
    positive("radius", radius)
    positive("spacing", spacing)
    positive("node_density_scale", node_density_scale)
    if pattern not in ("square", "triangular"):
        raise ParameterError(f"pattern={pattern!r}: must be 'square' or 'triangular'")
    c = _check_origin(centre)
    row = spacing if pattern == "square" else spacing * math.sqrt(3) / 2
    _check_grid_size(f"radius={radius}, spacing={spacing}", math.pi * radius**2
                     / (spacing * row), max_nodes)
    _check_members_apart(spacing, params.radius, "node spacing")
    nj = int(math.floor(radius / row + 1e-9))
    ni = int(math.floor(radius / spacing + 1e-9)) + 1

    def at(i: int, j: int) -> tuple[float, float]:
        shift = 0.5 * spacing if (pattern == "triangular" and j % 2) else 0.0
        return i * spacing + shift, j * row

    kept = {}
    for j in range(-nj, nj + 1):
        for i in range(-ni, ni + 1):
            x, y = at(i, j)
            if x * x + y * y <= radius * radius * (1 + 1e-12):
                kept[i, j] = (x, y)
    if pattern == "square":
        def neighbours(i, j):
            return [((i + 1, j), LONGITUDINAL, "A", (1.0, 0, 0)),
                    ((i, j + 1), TRANSVERSE, "C", (0, 1.0, 0))]
    else:
        def neighbours(i, j):
            up = [(i - 1, j + 1), (i, j + 1)] if j % 2 == 0 else [(i, j + 1), (i + 1, j + 1)]
            return [((i + 1, j), LONGITUDINAL, "A", None)] + [(u, DIAGONAL, "", None)
                                                                for u in up]
    pairs = [((i, j), nb, kind, sd, ax) for (i, j) in sorted(kept, key=lambda k: (k[1], k[0]))
             for nb, kind, sd, ax in neighbours(i, j) if nb in kept]
    if not pairs:
        raise ParameterError(f"radius={radius}, spacing={spacing}: the disc holds no member "
                             "(the radius must be at least one spacing)")
    used = {k for a, b, *_ in pairs for k in (a, b)}
    i0 = min(k[0] for k in used)
    j0 = min(k[1] for k in used)
    b = _Builder(params, _density(unit_weight, density))
    ids = {}
    for k in sorted(used, key=lambda k: (k[1], k[0])):
        x, y = kept[k]
        ids[k] = b.node(k, c + [x, y, 0.0])
    direction, cell, sides, axis, links_of = [], [], [], [], []
    for a, nb, kind, sd, ax in pairs:
        links_of.append(b.link(ids[a], ids[nb]))
        direction.append(kind)
        cell.append((a[0] - i0, a[1] - j0))
        sides.append(sd)
        if ax is None:
            p, q = b.points[ids[a]], b.points[ids[nb]]
            ax = unit(q - p)
        axis.append(ax)
    span = (max(k[0] for k in used) - i0, max(k[1] for k in used) - j0)
    return _one_link_members(b, scene, material, node_density_scale, links_of, direction, cell,
                             sides, axis, params.radius, span)


def biaxial_geogrid(scene, *, origin: Sequence[float], apertures_x: int, apertures_y: int,
                    aperture_area: float = 6.4e-3, rib_width: float = 0.01,
                    params: BeamParams, material: int, unit_weight: float | None = None,
                    density: float | None = None, segments_per_rib: int = 2,
                    node_density_scale: float = 1.0, max_nodes: int | None = None) -> Geogrid:
    """Flat-ribbed biaxial geogrid of PFacets and cylinders (000 §2.2, Fig. 3).

    Square apertures of clear area ``aperture_area`` (m^2; 000 Table 1: 6.4e-3) between flat
    ribs of width ``rib_width`` (m) and thickness 2 R_c (``params.radius``; 000: 2 mm). Each rib
    between two junctions is a strip of ``segments_per_rib`` rectangles, each rectangle two
    PFacets; junctions are square patches of two PFacets. Junction columns are at
    x = origin + i * pitch, pitch = sqrt(aperture_area) + rib_width; the grid spans
    apertures_x x apertures_y cells.
    """
    positive("aperture_area", aperture_area)
    positive("rib_width", rib_width)
    apertures_x = _check_count("apertures_x", apertures_x, 1)
    apertures_y = _check_count("apertures_y", apertures_y, 1)
    segments_per_rib = _check_count("segments_per_rib", segments_per_rib, 1)
    # node lines per axis: two per junction line, segments_per_rib - 1 inside each rib
    _check_grid_size(f"apertures_x={apertures_x}, apertures_y={apertures_y}, segments_per_rib="
                     f"{segments_per_rib}",
                     float(math.prod(2 * (n + 1) + n * (segments_per_rib - 1)
                                     for n in (apertures_x, apertures_y))), max_nodes)
    o = _check_origin(origin)
    clear = math.sqrt(aperture_area)
    if not rib_width < clear:
        raise ParameterError(f"rib_width={rib_width}: must be < the aperture's side "
                             f"sqrt(aperture_area) = {clear:g} m (a biaxial geogrid is mostly "
                             "aperture; 000: 10 mm ribs, 80 mm apertures)")
    pitch = clear + rib_width
    hw = rib_width / 2
    b = _Builder(params, _density(unit_weight, density))
    # Node coordinates along one axis: junction edges and rib subdivisions.
    def coords(n_ap):
        xs = []
        for i in range(n_ap + 1):
            c = i * pitch
            xs += [c - hw, c + hw]
            if i < n_ap:
                for s in range(1, segments_per_rib):
                    xs.append(c + hw + clear * s / segments_per_rib)
        return np.array(sorted(xs))

    xs, ys = coords(apertures_x), coords(apertures_y)

    def on_rib(v, n_ap):
        """Index of the junction line whose rib band contains v, or -1."""
        for i in range(n_ap + 1):
            if abs(v - i * pitch) <= hw + 1e-12:
                return i
        return -1

    def nid(ix, iy):
        return b.node((ix, iy), o + [xs[ix], ys[iy], 0.0])

    direction, cell, sides, axis, mem_links, mem_section = [], [], [], [], [], []
    # Rectangles [xs[a], xs[a+1]] x [ys[c], ys[c+1]] that lie on a rib or a junction.
    rect_member = {}
    for a in range(len(xs) - 1):
        xm = 0.5 * (xs[a] + xs[a + 1])
        jx = on_rib(xm, apertures_x)
        for c in range(len(ys) - 1):
            ym = 0.5 * (ys[c] + ys[c + 1])
            jy = on_rib(ym, apertures_y)
            if jx < 0 and jy < 0:
                continue  # aperture
            n00, n10, n11, n01 = nid(a, c), nid(a + 1, c), nid(a + 1, c + 1), nid(a, c + 1)
            b.facet(n00, n10, n11)
            b.facet(n00, n11, n01)
            if jx >= 0 and jy >= 0:
                continue  # junction
            if jy >= 0:  # longitudinal rib along x on junction row jy, between columns
                key = (LONGITUDINAL, int(math.floor(xm / pitch)), jy)
            else:
                key = (TRANSVERSE, jx, int(math.floor(ym / pitch)))
            rect_member.setdefault(key, []).append((a, c, (n00, n10, n11, n01)))
    for (kind, i, j), rects in sorted(rect_member.items()):
        links_all = set()
        for a, c, (n00, n10, n11, n01) in rects:
            for p, q in ((n00, n10), (n10, n11), (n11, n01), (n01, n00), (n00, n11)):
                links_all.add(b.link(p, q))
        # Mid-section: the middle rectangle's links that run along the member.
        rects.sort(key=lambda r: (r[0], r[1]))
        a, c, (n00, n10, n11, n01) = rects[len(rects) // 2]
        if kind == LONGITUDINAL:
            sec = [b.link(n00, n10), b.link(n01, n11), b.link(n00, n11)]
            ax = (1.0, 0, 0)
        else:
            sec = [b.link(n00, n01), b.link(n10, n11), b.link(n00, n11)]
            ax = (0, 1.0, 0)
        direction.append(kind)
        cell.append((i, j))
        sides.append("A" if kind == LONGITUDINAL else "C")
        axis.append(ax)
        mem_links.append(sorted(links_all))
        mem_section.append(sec)
    nodes, links, facets = b.build(scene, material, node_density_scale)
    return Geogrid(nodes=nodes, links=links, pfacets=facets,
                   member_direction=np.array(direction), member_cell=np.array(cell),
                   member_side=np.array(sides), member_axis=np.array(axis),
                   member_section_links=[links[np.array(s)] for s in mem_section],
                   member_links=[links[np.array(s)] for s in mem_links],
                   area=np.full(len(direction), rib_width * 2 * params.radius),
                   n_cells=(apertures_x, apertures_y),
                   reference_positions=np.asarray(scene.positions)[nodes].copy())


def polyline(scene, points, *, params: BeamParams, material: int,
             unit_weight: float | None = None, density: float | None = None,
             node_density_scale: float = 1.0) -> Geogrid:
    """A chain of grid nodes at ``points`` (n, 3), m, joined by cohesive links (a beam, a
    cable, a single rib). Every link is a member of its own, direction 'longitudinal'."""
    try:
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
    except (TypeError, ValueError):
        raise ParameterError(f"points={points!r}: must be (n, 3) numbers (m)") from None
    if len(pts) < 2:
        raise ParameterError(f"points: need at least 2, got {len(pts)}")
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        raise ParameterError(f"points[{k}]={pts[k].tolist()}: must be 3 finite numbers (m)")
    positive("node_density_scale", node_density_scale)
    b = _Builder(params, _density(unit_weight, density))
    ids = [b.node(k, p) for k, p in enumerate(pts)]
    order = [b.link(ids[k], ids[k + 1]) for k in range(len(ids) - 1)]
    axis = np.diff(pts, axis=0)
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    n = len(order)
    return _one_link_members(b, scene, material, node_density_scale, order, [LONGITUDINAL] * n,
                             -np.ones((n, 2), dtype=int), [""] * n, axis, params.radius)


def write_vtk_geogrid(path, scene, grid: Geogrid, *, reference_positions=None):
    """Writes the geogrid as a .vtp file for ParaView: links as lines and PFacets as triangles
    at the nodes' current positions, with the scene's time (``TimeValue``, s) and

    - cell data (links; zero on PFacets): ``axial_force`` (N, tension positive),
      ``shear_force`` (|F_s| on node b, N), ``bending_moment`` (|M_b|, N m),
      ``twisting_moment`` (N m), ``member`` (index, -1 for junction links), ``broken``,
      ``kind`` (0 link, 1 pfacet);
    - point data: ``node_id`` and ``displacement`` (m) from ``reference_positions`` (default:
      the positions when the grid was built, ``grid.reference_positions``).

    The nodes are also points of the spheres file (:func:`cpp_dem.io.write_vtk_spheres`), with
    ``kind`` 2 there. Returns the path written (a ``pathlib.Path``)."""
    from cpp_dem.io.vtk import _time_field
    from cpp_dem.io import write_vtp

    pos = scene.positions
    nodes = grid.nodes
    local = {int(n): k for k, n in enumerate(nodes)}
    ln = scene.grid_link_nodes[grid.links]
    lines = np.array([[local[int(a)], local[int(b)]] for a, b in ln], dtype=np.int64).reshape(-1, 2)
    tri = scene.pfacet_nodes[grid.pfacets] if len(grid.pfacets) else np.zeros((0, 3), int)
    polys = np.array([[local[int(n)] for n in t] for t in tri], dtype=np.int64).reshape(-1, 3)
    f = scene.grid_link_axial_forces[grid.links]
    shear = np.linalg.norm(np.asarray(scene.grid_link_shear_forces)[grid.links], axis=1)
    bend = np.linalg.norm(np.asarray(scene.grid_link_bending_moments)[grid.links], axis=1)
    twist = np.asarray(scene.grid_link_twisting_moments)[grid.links]
    broken = np.asarray(scene.grid_link_broken, dtype=float)[grid.links]
    member = grid.link_member().astype(float)
    zeros = np.zeros(len(polys))
    cell_data = {
        "axial_force": np.concatenate([f, zeros]),
        "shear_force": np.concatenate([shear, zeros]),
        "bending_moment": np.concatenate([bend, zeros]),
        "twisting_moment": np.concatenate([twist, zeros]),
        "member": np.concatenate([member, -np.ones(len(polys))]),
        "broken": np.concatenate([broken, zeros]),
        "kind": np.concatenate([np.zeros(len(lines)), np.ones(len(polys))]),
    }
    ref = reference_positions if reference_positions is not None else grid.reference_positions
    point_data = {"node_id": nodes.astype(float)}
    if ref is not None:
        point_data["displacement"] = np.asarray(pos)[nodes] - np.asarray(ref, dtype=float)
    return write_vtp(path, points=pos[nodes], lines=lines, polys=polys, point_data=point_data,
                     cell_data=cell_data, field_data=_time_field(scene))
