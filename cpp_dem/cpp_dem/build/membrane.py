"""A flexible membrane around a cylindrical specimen, as in the laboratory's triaxial cell.

:func:`cylindrical_membrane` wraps a cylinder in a triangulated surface of grid nodes, cohesive
links (the beam law, ``laws/beam.hpp``) and PFacets, which the grains touch as they touch a
geogrid's (000 eqs 13-19). A :class:`cpp_dem.MembranePressure` loads it with the cell
pressure, as forces on its nodes from each triangle's current area and normal; two
:class:`cpp_dem.PlatenClamp` hold its end rings to the platens (planar walls).

**Stiffness in a rubber membrane's units.** The surface is a lattice of near-equilateral
triangles of side ``L``. A lattice of axial springs ``k_n`` with transverse springs
``k_s = beta k_n`` (the links' shear stiffness, ``beta = 12 I / (A L^2) = 3 (R_c / L)^2`` for
a link of circular section ``R_c``) is, in the plane, an isotropic sheet of

    E t = 2 sqrt(3) k_n (1 + beta) / (3 + beta),   nu = (1 - beta) / (3 + beta)

(the strain energy of the three link directions under a uniform strain). So a membrane of
modulus ``young_pa`` and thickness ``thickness_m`` takes ``k_n = young_pa thickness_m
(3 + beta) / (2 sqrt(3) (1 + beta))``, which the links' Young's modulus gives
(``k_n = E_link pi R_c^2 / L``). Its Poisson's ratio is the lattice's, at most 1/3 (rubber's
is 0.5): it matters only where the membrane stretches along the axis and around it at once.
``tests/test_membrane.py`` inflates one and finds the radius the formula gives.

The nodes carry the membrane's mass (``density_kg_m3`` times ``thickness_m`` times their
share of the area) times ``mass_scale``: a rubber membrane is light beside the grains, and a
heavier one lets the time step stay that of the grains (a quasi-static test does not see the
membrane's inertia).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from cpp_dem import _core
from cpp_dem._checks import positive
from cpp_dem.build.clump_mesh import _ray_triangle
from cpp_dem.build.geogrid import _Builder

__all__ = ["Membrane", "cylindrical_membrane", "lattice_link_young", "lattice_sides"]


def lattice_link_young(young_pa: float, thickness_m: float, link_length_m: float,
                       node_radius_m: float) -> float:
    """The links' Young's modulus, Pa, that makes a lattice of near-equilateral triangles of
    side ``link_length_m`` (m) with links of radius ``node_radius_m`` (m) a sheet of
    ``young_pa`` (Pa) times ``thickness_m`` (m) in its plane (the module doc)."""
    beta = 3.0 * (node_radius_m / link_length_m) ** 2
    kn = young_pa * thickness_m * (3.0 + beta) / (2.0 * math.sqrt(3.0) * (1.0 + beta))
    return kn * link_length_m / (math.pi * node_radius_m**2)


def lattice_sides(radius_m: float, height_m: float, segments: int) -> tuple[float, float, int]:
    """The triangles of :func:`cylindrical_membrane` with ``segments`` nodes around rings of
    radius ``radius_m`` over ``height_m`` (m): their side around the ring (the chord, m),
    their side between rings (m) and the number of rings."""
    n = int(segments)
    chord = 2.0 * radius_m * math.sin(math.pi / n)
    n_rings = max(2, int(round(height_m / (chord * math.sqrt(3.0) / 2.0))) + 1)
    spacing = height_m / (n_rings - 1)
    return chord, math.hypot(spacing, 2.0 * radius_m * math.sin(math.pi / (2 * n))), n_rings


@dataclasses.dataclass
class Membrane:
    """A membrane made by :func:`cylindrical_membrane` (ids are the scene's body, link and
    PFacet ids)."""

    centre: np.ndarray  #: the axis's point at the bottom ring, m
    radius_m: float  #: the rings' radius as built (the nodes' mid-surface), m
    height_m: float  #: from the bottom ring to the top ring, m
    node_radius_m: float  #: R_c, the surface's half thickness for the grains, m
    young_pa: float  #: the rubber's modulus, Pa
    thickness_m: float  #: the rubber's thickness, m
    link_young_pa: float  #: the links' Young's modulus that gives it, Pa
    sheet_poisson: float  #: the lattice's in-plane Poisson's ratio, -
    rings: list  #: node ids per ring, bottom to top (each ring around the axis)
    nodes: np.ndarray  #: every node id
    links: np.ndarray  #: every link id
    facets: np.ndarray  #: PFacet ids
    triangles: np.ndarray  #: (m, 3) node ids per facet, anticlockwise seen from outside
    link_length_m: float  #: the mean link length, m

    @property
    def sheet_stiffness_n_m(self) -> float:
        """E t of the rubber, N/m: the membrane's in-plane modulus times its thickness."""
        return self.young_pa * self.thickness_m

    def pressure(self, pressure_pa: float) -> "_core.MembranePressure":
        """A :class:`cpp_dem.MembranePressure` that gives the grains the cell pressure
        ``pressure_pa`` (Pa, compressive positive), to add to the scene
        (``scene.add_controller``). It loads the nodes' mid-surface (radius R) with
        ``pressure_pa`` times :attr:`thickness_factor`, (R - R_c) / R, so that its force over
        the surface the grains touch (radius R - R_c) is the cell pressure: the correction
        for the membrane's thickness for the grains, 2 R_c, far thicker than a rubber one
        (without it the grains take R / (R - R_c) of the pressure: 5 % more in
        ``tests/test_membrane.py``)."""
        return _core.MembranePressure(triangles=[tuple(int(x) for x in t)
                                                 for t in self.triangles],
                                      pressure_pa=pressure_pa * self.thickness_factor)

    @property
    def thickness_factor(self) -> float:
        """(R - R_c) / R with the radius as built: the share of the cell pressure that loads
        the mid-surface, so that the grains' side takes the cell pressure, -."""
        return (self.radius_m - self.node_radius_m) / self.radius_m

    def _ring_heights(self, x: np.ndarray) -> np.ndarray:
        """Each ring's mean height, m, bottom to top, from the positions ``x`` (m)."""
        return np.array([float(np.mean(x[r, 2])) for r in self.rings])

    @staticmethod
    def _area_vectors(p: np.ndarray) -> np.ndarray:
        """The area vectors (m^2, (m, 3)) of the triangles whose corners are ``p`` (m, 3, 3)."""
        return 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])

    def _contacts_in_band(self, scene, z0: float, z1: float) -> tuple[np.ndarray, np.ndarray]:
        """The grains' contacts with the membrane whose contact point lies in [z0, z1): the
        radial unit vectors there and the forces on the grains (N). The point is on the
        grain's surface towards the membrane (its centre plus (r - overlap) along the
        contact normal, turned to face the membrane): the radial direction there, not at the
        grain's centre, is the membrane's normal where the membrane lies in the dents
        between grains (at the centres the radial push was 4 % less)."""
        c = scene.grid_contacts()
        if len(c["sphere"]) == 0:
            return np.zeros((0, 2)), np.zeros((0, 3))
        ids = np.asarray(c["sphere"])
        f = np.asarray(c["force"])
        n = np.asarray(c["normal"])
        face = -np.sign(np.einsum("ki,ki->k", f, n))[:, None] * n  # grain -> membrane
        reach = (np.asarray(scene.radii)[ids] - np.asarray(c["overlap"]))[:, None]
        point = np.asarray(scene.positions)[ids] + reach * face
        keep = (point[:, 2] >= z0) & (point[:, 2] < z1)
        e = point[keep, :2] - self.centre[:2]
        e /= np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
        return e, f[keep]

    def radial_forces_n(self, scene, pressure_pa: float,
                        band: tuple[float, float] = (1 / 3, 2 / 3)) -> tuple[float, float]:
        """In a band of the height between the end rings (fractions; the middle third by
        default): the grains' outward radial push on the membrane (their contact forces
        whose contact point lies in it, N) and the pressure's inward radial force on the
        triangles whose centroid lies in it (N). Where the membrane's tension carries
        nothing (away from the platens, at small strain) they are equal: the membrane hands
        its load to the grains. ``pressure_pa``: the pressure on the mid-surface (a
        :meth:`pressure` controller's ``pressure_pa``)."""
        x = np.asarray(scene.positions)
        zr = self._ring_heights(x)
        z0, z1 = (zr[0] + f * (zr[-1] - zr[0]) for f in band)
        e, f = self._contacts_in_band(scene, z0, z1)
        push = float(-np.einsum("ki,ki->k", f[:, :2], e).sum())
        p = x[self.triangles]
        area = self._area_vectors(p)
        cen = p.mean(axis=1)
        keep = (cen[:, 2] >= z0) & (cen[:, 2] < z1)
        e = cen[keep, :2] - self.centre[:2]
        e /= np.maximum(np.linalg.norm(e, axis=1), 1e-300)[:, None]
        load = float(pressure_pa * np.einsum("ki,ki->k", area[keep, :2], e).sum())
        return push, load

    def clamps(self, bottom_wall: int, top_wall: int) -> tuple:
        """Two :class:`cpp_dem.PlatenClamp` holding the bottom ring to ``bottom_wall`` and the
        top ring to ``top_wall`` (planar walls across the axis), to add to the scene after
        the walls' servos."""
        return (_core.PlatenClamp(wall=int(bottom_wall), bodies=[int(i) for i in self.rings[0]]),
                _core.PlatenClamp(wall=int(top_wall), bodies=[int(i) for i in self.rings[-1]]))

    def volume_m3(self, scene) -> float:
        """The volume the membrane's mid-surface encloses between its end rings' planes, m^3:
        by the divergence theorem with the field (x, y, 0) / 2 (div 1), which the end caps
        (across the axis) do not see, 1/2 sum over the triangles of the centroid's radial
        vector dotted with the area vector. Exact for the polyhedral surface. The specimen
        inside it is this less about the lateral area times R_c."""
        x = np.asarray(scene.positions)
        p = x[self.triangles] - self.centre  # (m, 3 nodes, 3)
        area = self._area_vectors(p)
        c = p.mean(axis=1)
        return float(0.5 * np.sum(c[:, 0] * area[:, 0] + c[:, 1] * area[:, 1]))

    def ring_radii_m(self, scene) -> np.ndarray:
        """Each ring's mean distance from the axis, m, bottom to top."""
        x = np.asarray(scene.positions)
        return np.array([float(np.mean(np.linalg.norm(x[r, :2] - self.centre[:2], axis=1)))
                         for r in self.rings])

    def grains_outside(self, scene) -> np.ndarray:
        """Ids of the spheres whose centre lies outside the membrane, or above or below its
        end rings: none, for a membrane that holds its specimen. Outside is beyond the
        membrane's mid-surface where the horizontal ray from the axis through the centre
        crosses it (:meth:`surface_radius_m`): the membrane wraps coarse grains, and the
        centres of those it wraps lie beyond its rings' mean radius."""
        x = np.asarray(scene.positions)
        grains = np.flatnonzero(np.asarray(scene.body_kinds) == 0)
        zr = self._ring_heights(x)
        g = x[grains]
        ends = (g[:, 2] < zr[0]) | (g[:, 2] > zr[-1])
        r = np.linalg.norm(g[:, :2] - self.centre[:2], axis=1)
        # (only a centre beyond the innermost node can be outside: the surface is there or
        # farther out)
        near = ~ends & (r > float(np.min(np.linalg.norm(x[self.nodes, :2] - self.centre[:2],
                                                         axis=1))))
        out = ends.copy()
        bound = self.surface_radius_m(scene, g[near])
        miss = np.isnan(bound)  # (no crossing found: the rings' radius there)
        bound[miss] = np.interp(g[near][miss, 2], zr, self.ring_radii_m(scene))
        out[near] = r[near] > bound
        return grains[out]

    def surface_radius_m(self, scene, points) -> np.ndarray:
        """The membrane's mid-surface radius, m, along the horizontal ray from the axis
        through each of ``points`` ((k, 3), m): the farthest crossing of that ray with its
        triangles (Moller-Trumbore; a ray on a shared edge or vertex crosses both
        triangles alike). NaN where the ray crosses none (a point above or below the
        end rings)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3) - self.centre
        out = np.full(len(pts), np.nan)
        if not len(pts):
            return out
        tri = np.asarray(scene.positions)[self.triangles] - self.centre  # (m, 3, 3)
        zlo, zhi = tri[:, :, 2].min(axis=1), tri[:, :, 2].max(axis=1)
        order = np.argsort(zlo, kind="stable")
        zlo_s = zlo[order]
        reach = float(np.max(zhi - zlo))
        # each point against the triangles whose height range holds it: those with
        # zlo in [z - reach, z], then zhi >= z
        lo = np.searchsorted(zlo_s, pts[:, 2] - reach, side="left")
        hi = np.searchsorted(zlo_s, pts[:, 2], side="right")
        counts = hi - lo
        pi = np.repeat(np.arange(len(pts)), counts)
        ti = order[np.repeat(lo, counts) + (np.arange(counts.sum())
                                            - np.repeat(np.cumsum(counts) - counts, counts))]
        keep = zhi[ti] >= pts[pi, 2]
        pi, ti = pi[keep], ti[keep]
        d = pts[pi].copy()
        d[:, 2] = 0.0
        d /= np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
        o = np.zeros_like(d)
        o[:, 2] = pts[pi, 2]
        ok, u, v, t = _ray_triangle(o, d, tri[ti])
        eps = 1e-9
        hit = ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0)
        np.fmax.at(out, pi[hit], t[hit])
        return out

    def inner_volume_m3(self, scene) -> float:
        """The specimen's volume, m^3: :meth:`volume_m3` less the triangles' area times R_c
        (the surface the grains touch lies R_c inside the nodes')."""
        area = np.linalg.norm(self._area_vectors(np.asarray(scene.positions)[self.triangles]),
                              axis=1)
        return self.volume_m3(scene) - float(area.sum()) * self.node_radius_m

    def specimen_radius_m(self, scene) -> float:
        """The radius of the cylinder of the specimen's volume and height (between the end
        rings), m: its cross-section for stresses, as a laboratory's corrected area."""
        zr = self._ring_heights(np.asarray(scene.positions))
        return math.sqrt(self.inner_volume_m3(scene) / (math.pi * (zr[-1] - zr[0])))

    def radial_stress_pa(self, scene, band: tuple[float, float] = (1 / 3, 2 / 3)) -> float:
        """The grains' radial stress on the membrane in a band of its height, Pa, compressive
        positive: the outward radial components of the contact forces of the grains whose
        contact point lies in ``band`` (fractions of the height between the end rings; the
        middle third by default, away from the platens) over the band's lateral area at
        :meth:`specimen_radius_m`."""
        zr = self._ring_heights(np.asarray(scene.positions))
        z0, z1 = (zr[0] + f * (zr[-1] - zr[0]) for f in band)
        e, f = self._contacts_in_band(scene, z0, z1)
        push = -np.einsum("ki,ki->k", f[:, :2], e)
        return float(push.sum() / (2.0 * math.pi * self.specimen_radius_m(scene) * (z1 - z0)))


def cylindrical_membrane(scene, *, centre: Sequence[float], radius_m: float, height_m: float,
                         young_pa: float, thickness_m: float, node_radius_m: float,
                         material: int, segments: int, density_kg_m3: float = 1100.0,
                         mass_scale: float = 1.0, poisson: float = 0.3) -> Membrane:
    """Adds a membrane around the axis z through ``centre`` (m, the bottom ring's centre):
    ``segments`` nodes around each ring of radius ``radius_m`` (m), rings from ``centre``'s z
    to ``height_m`` (m) above it, every other ring turned by half a segment, so that the
    triangles are near-equilateral (the rings' spacing is the one closest to sqrt(3) / 2 of
    the chord that divides the height evenly). Its stiffness is a rubber membrane's of
    ``young_pa`` (Pa) and ``thickness_m`` (m) (the module doc); the grains meet its surface
    ``node_radius_m`` (m) from the nodes (the PFacets' R_c) with ``material``'s contact law.
    ``density_kg_m3`` (rubber: 1100) and ``mass_scale`` give the nodes' mass; ``poisson`` is
    the links' own (their twist), not the sheet's. Returns the :class:`Membrane`.

    Refused by name: a triangle larger than the grains already in the scene (its side above
    the smallest grain's diameter: the pressure would act on a few grains through a facet
    wider than them), R_c not below half a side (the links would overlap), fewer than 6
    segments, and non-positive sizes."""
    c0 = np.asarray(centre, dtype=float).reshape(-1)
    if c0.shape != (3,) or not np.all(np.isfinite(c0)):
        raise _core.ParameterError(f"centre={centre!r}: three finite coordinates, m")
    radius_m = positive("radius_m", radius_m)
    height_m = positive("height_m", height_m)
    young_pa = positive("young_pa", young_pa)
    thickness_m = positive("thickness_m", thickness_m)
    node_radius_m = positive("node_radius_m", node_radius_m)
    density_kg_m3 = positive("density_kg_m3", density_kg_m3)
    mass_scale = positive("mass_scale", mass_scale)
    if int(segments) != segments or segments < 6:
        raise _core.ParameterError(f"segments={segments!r}: an integer >= 6 (nodes around a "
                                   "ring)")
    n = int(segments)
    chord, diagonal, n_rings = lattice_sides(radius_m, height_m, n)
    spacing = height_m / (n_rings - 1)
    longest = max(chord, diagonal)
    if node_radius_m >= 0.5 * min(chord, diagonal):
        raise _core.ParameterError(
            f"node_radius_m={node_radius_m!r}: must be below half the shortest link "
            f"({0.5 * min(chord, diagonal):.4g} m with {n} segments on radius {radius_m} m), "
            "or the links overlap")
    radii = np.asarray(scene.radii, dtype=float)
    if scene.num_bodies:
        grains = radii[np.asarray(scene.body_kinds) == 0]
        if len(grains) and longest > 2.0 * grains.min():
            raise _core.ParameterError(
                f"segments={n}: the membrane's triangles ({longest:.4g} m a side) are larger "
                f"than the smallest grain ({2.0 * grains.min():.4g} m across); the pressure "
                f"would act through facets wider than the grains. Give at least "
                f"{math.ceil(math.pi / math.asin(min(1.0, grains.min() / radius_m)))} "
                "segments, or a smaller radius")
    mean_len = (n * chord + 2 * n * diagonal) / (3 * n)
    link_young = lattice_link_young(young_pa, thickness_m, mean_len, node_radius_m)
    beta = 3.0 * (node_radius_m / mean_len) ** 2
    params = _core.BeamParams(young=link_young, poisson=poisson, radius=node_radius_m)
    # (_Builder's nodes take density x area x 2 R_c / 3 of each facet)
    b = _Builder(params, density_kg_m3 * thickness_m / (2.0 * node_radius_m))
    for k in range(n_rings):
        turn = math.pi / n if k % 2 else 0.0
        for j in range(n):
            t = 2.0 * math.pi * j / n + turn
            b.node((k, j), c0 + [radius_m * math.cos(t), radius_m * math.sin(t), k * spacing])
    for k in range(n_rings - 1):
        for j in range(n):
            a, a1 = b.key_to_node[(k, j)], b.key_to_node[(k, (j + 1) % n)]
            if k % 2 == 0:  # ring k+1 is turned: its node j sits between j and j+1 of ring k
                u, u1 = b.key_to_node[(k + 1, j)], b.key_to_node[(k + 1, (j + 1) % n)]
                b.facet(a, a1, u)
                b.facet(a1, u1, u)
            else:  # ring k is turned: ring k+1's node j+1 sits between its j and j+1
                u, u1 = b.key_to_node[(k + 1, j)], b.key_to_node[(k + 1, (j + 1) % n)]
                b.facet(a, a1, u1)
                b.facet(a, u1, u)
    pts = np.array(b.points)
    tri = np.array(b.facets, dtype=int)
    for i, (p, q, r) in enumerate(tri):  # anticlockwise seen from outside
        normal = np.cross(pts[q] - pts[p], pts[r] - pts[p])
        out = pts[[p, q, r]].mean(axis=0) - c0
        out[2] = 0.0
        if normal @ out < 0:
            tri[i] = (p, r, q)
    b.facets = [tuple(int(v) for v in t) for t in tri]
    node_ids, link_ids, facet_ids = b.build(scene, material, mass_scale)
    rings = [np.array([node_ids[b.key_to_node[(k, j)]] for j in range(n)], dtype=int)
             for k in range(n_rings)]
    return Membrane(centre=c0, radius_m=radius_m, height_m=height_m,
                    node_radius_m=node_radius_m, young_pa=young_pa, thickness_m=thickness_m,
                    link_young_pa=link_young, sheet_poisson=(1.0 - beta) / (3.0 + beta),
                    rings=rings, nodes=np.asarray(node_ids, dtype=int),
                    links=np.asarray(link_ids, dtype=int), facets=facet_ids,
                    triangles=np.asarray(node_ids)[tri], link_length_m=mean_len)
