"""Woven biaxial geogrids of bonded spheres (002 §4, Table 2).

002 builds its woven PET geogrid in PFC3D from single spheres bonded side by side. Here a
member (a rib between two junctions) is made of ``strands`` single strings of spheres. The
strings are parallel and ``strand_spacing`` apart (centre to centre), and free of each other
between junctions, so a grain can enter between them (002's "single string interaction").

- **Strings.** Each string is a chain of touching spheres. Each sphere is bonded to the next
  with the contact bond and the parallel bond of the preset (docs/bonds.md).
- **Junctions.** Where a longitudinal and a transverse string cross there is one sphere, shared
  by both. A junction is the patch of ``strands x strands`` crossings. Its spheres are bonded
  along both directions, so the strings are tied together there and only there.
- **Coordinates.** Longitudinal members run along x (the pull direction), transverse ones
  along y. All spheres lie in the plane z = origin z. The over-and-under of a real weave is
  not modelled.
- **Labels.** Members follow the cylinder grids' convention (cpp_dem.build.geogrid): cell (i, j) has
  its longitudinal member 'A' on junction row j and its transverse member 'C' on junction
  column i.
- **Member force.** A member's tensile force is the sum, over its strings, of the force of the
  bond that the member's mid-section cuts.
- **Tails** (``tails``): each string may go on past its end junctions by a number of touching
  spheres, bonded like the strings, so that a grid cut from a larger sheet reaches towards the
  faces of its box (the element's grid is pulled at its tails' tips: the layer's tension
  enters at the faces, not at an end rib inside the soil). Tail spheres are of their string's
  kind; tail bonds belong to no member (``bond_member`` -1, as inside a junction).

**Presets** (:data:`PRESETS`):
- 002 Table 2 gives the "detailed" and "standard" sets, with their densities: contact bonds,
  parallel bonds, and the linear contact between geogrid spheres.
- 002 gives no dimensions of the grid. The presets choose them, as parameters:
  - detailed: spheres of radius 1 mm, three strings per member, 4.5 mm apart centre to
    centre (a 2.5 mm clear gap between adjacent strings), 16 mm clear apertures;
  - standard: one string of 1.5 mm spheres per member, 20 mm clear apertures.
  The pitch (aperture + (strands - 1) x strand_spacing + 2 x sphere_radius) is 27 mm
  (detailed) and 23 mm (standard), so the element's 3 x 3 apertures fit its 0.1 m box
  (cpp_dem.elements.box), which gives the standard grid tails to reach towards its faces.

**Why 4.5 mm between the detailed strings.** 002 sees grains enter between the single
strings of the detailed grid (its Fig. 4b). With 1 mm spheres 2.5 mm apart (the earlier
preset) the clear gap was 0.5 mm and no grain sphere could enter. The grains' member spheres:
in the element (cpp_dem.elements.box.make_woven_element) the grains have the mean diameter
d = (0.6 x 0.1^3 / (n pi / 6))^(1/3) = 8.3 mm at n = 2000 (full size) and 19.7 mm at n = 150
(smoke), spread +-20 %; the gravel clump templates ("clumps:gravel") have member spheres of
0.125-0.41 x the clump's equivalent diameter. So at full size the member-sphere radii run from
0.83 mm (median about 2 mm), at smoke size from 2.0 mm. The spacing 4.5 mm:
- leaves a 2.5 mm gap: about 7 % of the full-size grains' member spheres (radius < 1.25 mm)
  pass into it freely, and larger ones enter by spreading the strings, which are free of
  each other between junctions (at smoke size no member sphere fits without spreading them);
- keeps the 27 mm pitch with a 16 mm aperture (about 2 grain diameters at full size, so the
  grains still enter the apertures) and an 11 mm member width, which leaves the element's walls
  4 mm of room (box.py asks 3 % of the 0.1 m edge, 3 mm; 5.5 mm spacing would leave exactly
  3 mm);
- makes the member's strings exact chains of touching spheres (the 18 mm between the
  junctions' outer strings is 9 x 2 mm), and keeps every span/2r away from a rounding tie
  (inside a junction the 4.5 mm is 2 bonds of 2.25 mm, a 0.25 mm reference gap).

**Stiffness convention.** 002 gives k_n, k_s (Table 2, and Table 1's grain values) as PFC 4
*ball* properties. PFC 4's linear contact model combines the two balls' values in series,
k = k1 k2 / (k1 + k2). So a contact between two detailed grid balls (k_n = 4e6 N/m each) had
k_n = 2e6 N/m in 002, and a clump-grid contact had k_n = 3.9e6 x 4e6 / 7.9e6 = 1.97e6 N/m and
k_s = 9e5 x 8.5e5 / 1.75e6 = 4.37e5 N/m. The ``convention`` parameter of :func:`contact_stiffness`,
:func:`preset_bond`, :func:`woven_geogrid`, :func:`set_grid_laws`,
:func:`series_stiffness_per_metre` and :func:`tensile_test` says how the Table values are read:
- "series" (the default): they are ball properties, combined in series as PFC 4 did. This is
  what 002's grid was calibrated with (its tensile tests were back-analysed in PFC 4 with
  these numbers), so it is the default;
- "contact": they are the contacts' own stiffnesses (the behaviour before this parameter).
The contact bond's k_n, k_s (the linear contact's springs that the contact bond holds in
tension) follow the convention. The parallel bonds' k_bar_n, k_bar_s (Pa/m) are bond
properties, not ball ones, and are used as given in both conventions.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from cpp_dem._core import BondParams, ParameterError
from cpp_dem.build.geogrid import JUNCTION, LONGITUDINAL, TRANSVERSE

#: 002 Table 2 (the bond and contact parameters, density) and the dimensions chosen here.
PRESETS = {
    "detailed": dict(
        density=1030.0,          # kg/m^3 (002 Table 2)
        kn=4.0e6, ks=8.5e5,      # linear contact, N/m
        cb_tensile=5.0e5, cb_shear=5.0e5,  # contact bond strengths, N
        pb_radius_factor=0.29,   # lambda_bar, -
        pb_kn=2.8e12, pb_ks=1.8e12,        # parallel bond stiffness, Pa/m
        pb_tensile=8.0e14, pb_shear=8.0e14,  # parallel bond strengths, Pa
        friction=0.5,            # mu, -
        # Dimensions (not in 002; chosen here).
        # 27 mm pitch: 16 + 2 x 4.5 + 2 x 1 mm; a 2.5 mm clear gap between the strings
        # (module docstring: why).
        sphere_radius=1.0e-3, strands=3, strand_spacing=4.5e-3, aperture=16e-3,
    ),
    "standard": dict(
        density=2060.0,
        kn=1.3e7, ks=6.0e4,
        cb_tensile=5.0e5, cb_shear=5.0e5,
        pb_radius_factor=0.15,
        pb_kn=1.25e13, pb_ks=3.0e11,
        pb_tensile=8.0e14, pb_shear=8.0e14,
        friction=0.5,
        sphere_radius=1.5e-3, strands=1, strand_spacing=3.0e-3, aperture=20e-3,
    ),
}

_BOND_KEYS = ("kn", "ks", "friction", "cb_tensile", "cb_shear", "pb_kn", "pb_ks",
              "pb_radius_factor", "pb_tensile", "pb_shear")
_GEOMETRY_KEYS = ("sphere_radius", "strands", "strand_spacing", "aperture")


#: How 002's k_n, k_s are read (module docstring): 'series' (ball properties combined in
#: series, as PFC 4 did; the default) or 'contact' (the contacts' own stiffnesses).
CONVENTIONS = ("series", "contact")


def _convention(convention: str) -> str:
    if convention not in CONVENTIONS:
        raise ParameterError(f"convention={convention!r}: must be one of "
                             f"{', '.join(map(repr, CONVENTIONS))}")
    return convention


def contact_stiffness(preset: str = "detailed", other_kn: float | None = None,
                      other_ks: float | None = None, convention: str = "series") -> tuple:
    """(k_n, k_s), N/m, of a linear contact between a grid sphere of ``preset`` and another
    body whose 002 values are ``other_kn``, ``other_ks`` (N/m; None: another sphere of the
    same grid, i.e. the preset's Table 2 values).

    - convention 'series' (default): the values are ball properties, combined in series as
      PFC 4's linear model did: k = k_grid k_other / (k_grid + k_other). Grid-grid (detailed):
      (2e6, 4.25e5); grid-grain with 002 Table 1's 3.9e6, 9e5: (1.975e6, 4.371e5).
    - convention 'contact': the other body's values are the contact's own: (other_kn,
      other_ks), or the preset's (k_n, k_s) when the other is a grid sphere.
    """
    p = _preset(preset)
    _convention(convention)
    okn = p["kn"] if other_kn is None else float(other_kn)
    oks = p["ks"] if other_ks is None else float(other_ks)
    for name, v in (("other_kn", okn), ("other_ks", oks)):
        if not (math.isfinite(v) and v > 0):
            raise ParameterError(f"{name}={v}: must be > 0 (N/m)")
    if convention == "contact":
        return okn, oks
    return p["kn"] * okn / (p["kn"] + okn), p["ks"] * oks / (p["ks"] + oks)


def preset_bond(name: str, convention: str = "series") -> BondParams:
    """The bond of preset ``name`` (contact bond and parallel bond, 002 Table 2). The contact
    bond's k_n, k_s are those of a grid-grid contact under ``convention``
    (:func:`contact_stiffness`); the parallel bond's values are used as given."""
    p = _preset(name)
    kw = {k: p[k] for k in _BOND_KEYS}
    kw["kn"], kw["ks"] = contact_stiffness(name, None, None, convention)
    return BondParams(contact_bond=True, **kw)


def _preset(name: str) -> dict:
    if name not in PRESETS:
        raise ParameterError(f"preset={name!r}: must be one of {', '.join(map(repr, PRESETS))}")
    return PRESETS[name]


@dataclasses.dataclass
class WovenGeogrid:
    """A woven geogrid of bonded spheres in a scene.

    Attributes
    ----------
    spheres : body ids of the grid's spheres.
    bonds : bond indices of the grid.
    sphere_kind : per sphere, 'junction', 'longitudinal' or 'transverse'.
    sphere_strand : per sphere, its string (index into strand_direction); -1 at junctions.
    strand_direction : per string, 'longitudinal' or 'transverse'.
    strand_member_line : per string, its junction row (longitudinal) or column (transverse).
    bond_member : per bond, the member it belongs to (-1 inside a junction or in a tail).
    member_direction, member_cell, member_side, member_axis : as cpp_dem.build.geogrid.Geogrid.
    member_section_bonds : per member, the bonds its mid-section cuts (one per string).
    member_bonds : per member, all its bonds.
    member_width : width of a member, m (from the outer strings' edges).
    pitch : centre distance of the members, m (x, y).
    reference_positions : (n, 3) sphere positions when built, m.
    tails : spheres per string past each end junction (x strings, y strings).
    """

    spheres: np.ndarray
    bonds: np.ndarray
    sphere_kind: np.ndarray
    sphere_strand: np.ndarray
    strand_direction: np.ndarray
    strand_member_line: np.ndarray
    bond_member: np.ndarray
    member_direction: np.ndarray
    member_cell: np.ndarray
    member_side: np.ndarray
    member_axis: np.ndarray
    member_section_bonds: list
    member_bonds: list
    member_width: float
    pitch: tuple
    n_cells: tuple
    reference_positions: np.ndarray
    tails: tuple = (0, 0)

    @property
    def n_members(self) -> int:
        return len(self.member_direction)

    def member_axial_forces(self, scene) -> np.ndarray:
        """Tensile force of every member, N, tension positive: the sum over the bonds cut by
        its mid-section of each bond's force along the member axis."""
        st = scene.bond_state()
        normal = np.asarray(st["normal"])  # (a -> b: also across a periodic cell's faces)
        out = np.zeros(self.n_members)
        for m, sec in enumerate(self.member_section_bonds):
            ax = self.member_axis[m]
            d = normal[sec]
            # The force on b pulls it back towards a in tension.
            out[m] = -np.sum(np.sign(d @ ax) * (st["force"][sec] @ ax))
        return out

    def members(self, direction: str) -> np.ndarray:
        """Indices of the members of one direction ('longitudinal' or 'transverse')."""
        return np.flatnonzero(self.member_direction == direction)


#: The default ``max_spheres`` of :func:`woven_geogrid`. Building takes about 1.5 kB per sphere
#: and a time that grows with the square of the count (the bonds are added one by one):
#: measured 0.8 s for 2 124 spheres, 42 s for 16 704, so about 20 min for 100 000.
MAX_WOVEN_SPHERES = 100_000
_WOVEN_BYTES_PER_SPHERE = 1500
_WOVEN_S_AT_16704 = 42.0


def woven_geogrid(scene, *, origin: Sequence[float], apertures_x: int, apertures_y: int,
                  material: int, preset: str = "detailed", bond: BondParams | None = None,
                  sphere_radius: float | None = None, strands: int | None = None,
                  strand_spacing: float | None = None,
                  aperture: float | Sequence[float] | None = None,
                  max_spheres: int | None = None, convention: str = "series",
                  periodic: bool = False, tails: int | Sequence[int] = 0) -> WovenGeogrid:
    """Builds a woven biaxial geogrid of bonded spheres (module docstring) in ``scene``.

    origin : centre of the first junction (m; the grid spans apertures_x x apertures_y cells
        towards +x and +y).
    material : the spheres' material (its density is the grid's; see :func:`woven_material`).
    preset : 'detailed' or 'standard' (002 Table 2); ``bond`` and the geometry arguments
        override it. sphere_radius (m), strands (per member), strand_spacing (centre to
        centre, m, >= 2 sphere_radius), aperture (clear opening, m, one value or (x, y)).
    max_spheres : the most spheres the grid may have, counted before anything is built; None
        is MAX_WOVEN_SPHERES.
    convention : how the preset's k_n, k_s make the contact bonds' stiffness, 'series'
        (default) or 'contact' (module docstring); ignored when ``bond`` is given.
    periodic : an endless sheet in the scene's periodic cell (Scene.set_periodic_cell first,
        periodic along x and y, its x and y cell vectors apertures_x x pitch_x and
        apertures_y x pitch_y along the axes): the last junction column and row are the
        first ones' images, and the strings close through the cell's faces (bonds in a
        periodic cell: docs/bonds.md). A reinforced-soil RVE's sheet.
    tails : touching spheres that each string goes on by past its end junctions (module
        docstring), one count or (longitudinal strings, transverse strings); 0 (the default)
        ends the strings at the end junctions. Not with ``periodic``.
    """
    p = _preset(preset)
    r = float(p["sphere_radius"] if sphere_radius is None else sphere_radius)
    ns = p["strands"] if strands is None else strands
    sp = float(p["strand_spacing"] if strand_spacing is None else strand_spacing)
    ap = p["aperture"] if aperture is None else aperture
    ap = np.broadcast_to(np.asarray(ap, dtype=float), (2,)).copy()
    bond = preset_bond(preset, convention) if bond is None else bond
    if not (math.isfinite(r) and r > 0):
        raise ParameterError(f"sphere_radius={r}: must be > 0 (m)")
    if not (isinstance(ns, (int, np.integer)) and ns >= 1):
        raise ParameterError(f"strands={ns!r}: must be an integer >= 1")
    if ns > 1 and not (math.isfinite(sp) and sp >= 2 * r * (1 - 1e-12)):
        raise ParameterError(f"strand_spacing={sp}: must be >= 2 x sphere_radius = {2 * r:g} m "
                             "(strings side by side must not overlap)")
    for name, v in (("apertures_x", apertures_x), ("apertures_y", apertures_y)):
        if not (isinstance(v, (int, np.integer)) and v >= 1):
            raise ParameterError(f"{name}={v!r}: must be an integer >= 1")
    width = (ns - 1) * sp + 2 * r
    if not np.all(ap >= 2 * r):
        raise ParameterError(f"aperture={tuple(ap)}: must be >= 2 x sphere_radius (m)")
    tl = (tails, tails) if np.ndim(tails) == 0 else tuple(tails)
    if len(tl) != 2 or not all(isinstance(t, (int, np.integer)) and not isinstance(t, bool)
                               and t >= 0 for t in tl):
        raise ParameterError(f"tails={tails!r}: must be a whole number >= 0 of spheres, or two "
                             "(longitudinal strings, transverse strings)")
    tl = (int(tl[0]), int(tl[1]))
    if periodic and any(tl):
        raise ParameterError(f"tails={tails!r}: a periodic sheet has no ends; use 0")
    o = np.asarray(origin, dtype=float).reshape(3)
    pitch = ap + width
    if periodic:
        _check_periodic_sheet(scene, apertures_x * pitch[0], apertures_y * pitch[1])
    # Spheres: the crossings, and the strings filled with touching spheres between them.
    n_lines = (float(apertures_x) + 1) * ns, (float(apertures_y) + 1) * ns

    def fill(n_ap, p):  # spheres between the crossings along one string
        inner = max(1, round(sp / (2 * r))) - 1 if ns > 1 else 0
        return ((n_ap + 1.0) * (ns - 1) * inner
                + n_ap * (max(1, round((p - (ns - 1) * sp) / (2 * r))) - 1))

    spheres = (n_lines[0] * n_lines[1] + n_lines[1] * fill(apertures_x, pitch[0])
               + n_lines[0] * fill(apertures_y, pitch[1])
               + 2 * (n_lines[1] * tl[0] + n_lines[0] * tl[1]))
    cap = MAX_WOVEN_SPHERES if max_spheres is None else max_spheres
    if isinstance(cap, bool) or not isinstance(cap, (int, np.integer)) or cap < 1:
        raise ParameterError(f"max_spheres={max_spheres!r}: must be a whole number >= 1, or "
                             "None (the default)")
    if spheres > cap:
        raise ParameterError(
            f"apertures_x={apertures_x}, apertures_y={apertures_y}: about {spheres:.3g} "
            f"spheres (strands={ns}, sphere_radius={r:g} m), above max_spheres={cap}"
            f"{' (the default)' if max_spheres is None else ''}; about "
            f"{spheres * _WOVEN_BYTES_PER_SPHERE / 2**30:.3g} GiB, and the build time grows "
            f"with the square of the count ({_WOVEN_S_AT_16704:.0f} s for 16 704 spheres); "
            "use fewer apertures, or raise max_spheres")
    offs = (np.arange(ns) - (ns - 1) / 2) * sp
    # String lines: transverse strings at x = X, longitudinal ones at y = Y.
    xs = np.array([o[0] + i * pitch[0] + s for i in range(apertures_x + 1) for s in offs])
    ys = np.array([o[1] + j * pitch[1] + s for j in range(apertures_y + 1) for s in offs])
    x_line = np.repeat(np.arange(apertures_x + 1), ns)  # column of each transverse string
    y_line = np.repeat(np.arange(apertures_y + 1), ns)  # row of each longitudinal string

    pts, kind, strand = [], [], []
    index = {}
    # (periodic: the last junction column and row are the first ones', one cell on)
    n_x, n_y = ns * apertures_x, ns * apertures_y

    def jkey(a, b):
        return ("J", a % n_x, b % n_y) if periodic else ("J", a, b)

    def sphere(key, xyz, k, s):
        if key[0] == "J":
            key = jkey(key[1], key[2])
        if key not in index:
            index[key] = len(pts)
            pts.append(xyz)
            kind.append(k)
            strand.append(s)
        return index[key]

    for a, x in enumerate(xs):
        for b, y in enumerate(ys):
            sphere(("J", a, b), (x, y, o[2]), JUNCTION, -1)
    pairs, pair_member = [], []  # bonds (local sphere indices) and their member keys
    pair_along = []  # per bond, its two ends' coordinates along its string (unwrapped), m
    n_long = len(ys)
    strand_dir = [LONGITUDINAL] * n_long + [TRANSVERSE] * len(xs)
    strand_line = list(y_line) + list(x_line)

    def string(sid, along, lines, line_of, fixed, direction):
        """One string: crossing spheres at `along`, filled with touching spheres between."""
        prev = None
        n_along = n_x if direction == LONGITUDINAL else n_y
        for k in range(len(along)):
            cur = (index[jkey(k, sid)] if direction == LONGITUDINAL
                   else index[jkey(sid - n_long, k)])
            # (periodic: the last junction is the first's image; the string inside it is
            # the first junction's, built already)
            if prev is not None and not (periodic and k - 1 >= n_along):
                g = along[k] - along[k - 1]
                m = max(1, int(round(g / (2 * r))))
                same_line = lines[k] == lines[k - 1]
                key = (None if same_line else
                       (direction, int(lines[k - 1]), int(line_of)))
                last, t_last = prev, along[k - 1]
                for q in range(1, m):
                    t = along[k - 1] + g * q / m
                    xyz = (t, fixed, o[2]) if direction == LONGITUDINAL else (fixed, t, o[2])
                    nxt = sphere(("S", sid, k, q), xyz, direction, sid)
                    pairs.append((last, nxt))
                    pair_member.append(key)
                    pair_along.append((t_last, t))
                    last, t_last = nxt, t
                pairs.append((last, cur))
                pair_member.append(key)
                pair_along.append((t_last, along[k]))
            prev = cur

    def tail(sid, end_sphere, start, step, fixed, direction, count):
        """``count`` touching spheres from ``end_sphere`` (at ``start`` along the string)
        outwards by ``step`` (+-2r), bonded in a chain, in no member."""
        last, t_last = end_sphere, start
        for q in range(1, count + 1):
            t = start + q * step
            xyz = (t, fixed, o[2]) if direction == LONGITUDINAL else (fixed, t, o[2])
            nxt = sphere(("T", sid, step > 0, q), xyz, direction, sid)
            pairs.append((last, nxt))
            pair_member.append(None)
            pair_along.append((t_last, t))
            last, t_last = nxt, t

    for b, y in enumerate(ys):
        if not (periodic and b >= n_y):  # (periodic: the last row is the first's image)
            string(b, xs, x_line, y_line[b], y, LONGITUDINAL)
            tail(b, index[jkey(0, b)], xs[0], -2 * r, y, LONGITUDINAL, tl[0])
            tail(b, index[jkey(len(xs) - 1, b)], xs[-1], 2 * r, y, LONGITUDINAL, tl[0])
    for a, x in enumerate(xs):
        if not (periodic and a >= n_x):
            string(n_long + a, ys, y_line, x_line[a], x, TRANSVERSE)
            tail(n_long + a, index[jkey(a, 0)], ys[0], -2 * r, x, TRANSVERSE, tl[1])
            tail(n_long + a, index[jkey(a, len(ys) - 1)], ys[-1], 2 * r, x, TRANSVERSE, tl[1])

    # Members: cell (i, j) has longitudinal member A on row j between columns i and i + 1,
    # and transverse member C on column i between rows j and j + 1.
    keys = sorted({k for k in pair_member if k is not None})
    member_of_key = {k: m for m, k in enumerate(keys)}
    direction = np.array([k[0] for k in keys])
    cell = np.array([(k[1], k[2]) if k[0] == LONGITUDINAL else (k[2], k[1]) for k in keys],
                    dtype=int).reshape(-1, 2)
    side = np.array(["A" if k[0] == LONGITUDINAL else "C" for k in keys])
    axis = np.array([(1.0, 0, 0) if k[0] == LONGITUDINAL else (0, 1.0, 0) for k in keys])
    bond_member = np.array([member_of_key[k] if k is not None else -1 for k in pair_member],
                           dtype=int)

    # Add to the scene.
    pts = np.array(pts, dtype=float)
    ids = np.asarray(scene.add_spheres(pts, np.full(len(pts), r), material=material))
    first_bond = scene.num_bonds
    for a, b in pairs:
        scene.add_bond(int(ids[a]), int(ids[b]), bond)
    bonds = np.arange(first_bond, first_bond + len(pairs))
    member_bonds, section = [], []
    for m, k in enumerate(keys):
        mb = np.flatnonzero(bond_member == m)
        member_bonds.append(bonds[mb])
        # Mid-section of the member: for each string, the bond whose span holds the middle.
        coord = 0 if k[0] == LONGITUDINAL else 1
        line = k[1]  # column (longitudinal) or row (transverse) before the member
        mid = o[coord] + (line + 0.5) * pitch[coord]
        cut = [bonds[q] for q in mb
               if min(pair_along[q]) <= mid < max(pair_along[q])]
        section.append(np.array(cut, dtype=int))
    return WovenGeogrid(
        spheres=ids, bonds=bonds, sphere_kind=np.array(kind), sphere_strand=np.array(strand),
        strand_direction=np.array(strand_dir), strand_member_line=np.array(strand_line),
        bond_member=bond_member, member_direction=direction, member_cell=cell,
        member_side=side, member_axis=axis, member_section_bonds=section,
        member_bonds=member_bonds, member_width=width, pitch=(float(pitch[0]), float(pitch[1])),
        n_cells=(apertures_x, apertures_y), reference_positions=pts.copy(), tails=tl)


def preset_pitch(preset: str = "detailed", **geometry) -> tuple[float, float]:
    """The centre distance of the preset's members, m (x, y): aperture + member width.
    ``geometry`` overrides the preset's sphere_radius, strands, strand_spacing, aperture."""
    p = dict(_preset(preset))
    p.update({k: v for k, v in geometry.items() if v is not None})
    ap = np.broadcast_to(np.asarray(p["aperture"], dtype=float), (2,))
    width = (p["strands"] - 1) * p["strand_spacing"] + 2 * p["sphere_radius"]
    return float(ap[0] + width), float(ap[1] + width)


def _check_periodic_sheet(scene, lx: float, ly: float) -> None:
    """A periodic sheet needs the scene's cell periodic along x and y with its x and y cell
    vectors (lx, 0, 0) and (0, ly, 0), m."""
    if not scene.is_periodic:
        raise ParameterError("periodic=True: the scene has no periodic cell; set it first "
                             f"(Scene.set_periodic_cell), with x and y cell vectors ({lx:.6g}, "
                             f"0, 0) and (0, {ly:.6g}, 0) m: apertures x pitch")
    h = np.asarray(scene.cell_matrix)
    per = scene.cell_periodic
    want = np.array([lx, ly])
    ok = (per[0] and per[1] and np.allclose(np.diag(h)[:2], want, rtol=1e-9, atol=0)
          and abs(h[1, 0]) + abs(h[2, 0]) + abs(h[0, 1]) + abs(h[2, 1]) <= 1e-12 * lx)
    if not ok:
        raise ParameterError(f"periodic=True: the cell's x and y vectors are "
                             f"{h[:, 0].tolist()} and {h[:, 1].tolist()} m (periodic "
                             f"{list(per)}); the sheet needs ({lx:.6g}, 0, 0) and (0, "
                             f"{ly:.6g}, 0), periodic along x and y: apertures x pitch")


def woven_material(preset: str = "detailed"):
    """The material of a woven grid's spheres: the preset's density and friction, linear.

    Its Young's modulus only matters where no pair law is set (:func:`set_grid_laws` sets
    them for 002)."""
    from cpp_dem.scene import linear_material

    p = _preset(preset)
    # The linear law's k_n = E R at contact (000 eq 4 for equal spheres): E = k_n / R.
    return linear_material(density=p["density"], young=p["kn"] / p["sphere_radius"],
                           poisson=min(0.5, p["ks"] / p["kn"]),
                           friction_angle_deg=math.degrees(math.atan(p["friction"])))


def set_grid_laws(scene, grid_material: int, grain_material: int | None = None, *,
                  preset: str = "detailed", grain_kn: float = 3.9e6, grain_ks: float = 9.0e5,
                  grain_friction: float = 0.5, convention: str = "series") -> None:
    """002's contact laws around a woven grid, linear, with the stiffnesses of
    :func:`contact_stiffness` under ``convention``:
    - between grid spheres that are not bonded: the preset's k_n, k_s (in series with
      themselves for 'series': half of them), and its mu;
    - between the grid and grains (if ``grain_material`` is given): 002 Table 1's grain
      k_n = 3.9e6 N/m, k_s = 9e5 N/m with the grid's (in series for 'series':
      1.975e6, 4.37e5 N/m with the detailed grid; as given for 'contact'), and mu = 0.5
      (the geogrid's)."""
    p = _preset(preset)
    kn, ks = contact_stiffness(preset, None, None, convention)
    scene.set_pair_law(grid_material, grid_material, model="linear", kn=kn, ks=ks,
                       friction=p["friction"])
    if grain_material is not None:
        kn, ks = contact_stiffness(preset, grain_kn, grain_ks, convention)
        scene.set_pair_law(grain_material, grid_material, model="linear", kn=kn, ks=ks,
                           friction=grain_friction)


def series_stiffness_per_metre(preset: str = "detailed", *, convention: str = "series",
                               **geometry) -> float:
    """The tensile stiffness per metre of width, N/m, of an endless woven grid of the preset
    pulled along its longitudinal members, from its bonds in series: every longitudinal
    string is a chain of bonds of stiffness k_n + k_bar_n A (the contact bond pulls, with the
    grid-grid k_n of ``convention``, :func:`contact_stiffness`: half the Table's for
    'series'; and the parallel bond's disc beside it), and a pitch holds the member's bonds
    and the junction's. ``geometry`` overrides the preset's sphere_radius, strands,
    strand_spacing, aperture."""
    kn, _ = contact_stiffness(preset, None, None, convention)
    p = dict(_preset(preset))
    p.update({k: v for k, v in geometry.items() if v is not None})
    p["kn"] = kn
    r, ns, sp = p["sphere_radius"], p["strands"], p["strand_spacing"]
    ap = np.broadcast_to(np.asarray(p["aperture"], dtype=float), (2,))
    width = (ns - 1) * sp + 2 * r
    pitch = ap + width
    k_bond = p["kn"] + p["pb_kn"] * math.pi * (p["pb_radius_factor"] * r) ** 2
    span = pitch[0] - (ns - 1) * sp  # from a junction's last string to the next one's first
    bonds_per_pitch = max(1, int(round(span / (2 * r)))) + (ns - 1) * max(
        1, int(round(sp / (2 * r))))
    return ns * k_bond * pitch[0] / bonds_per_pitch / pitch[1]


def tensile_test(preset: str = "detailed", *, apertures_x: int = 3, apertures_y: int = 1,
                 strain: float = 1e-3, load_steps: int = 4000, relax_steps: int = 20000,
                 convention: str = "series", **geometry) -> dict:
    """A quasi-static tensile test of a woven grid sample along its longitudinal members.

    The junction columns at both ends are gripped (all DOFs held). The right grip moves by
    ``strain`` times the free length in ``load_steps`` steps, then holds while the sample
    settles (local damping 0.7) for ``relax_steps`` steps. The grid's bonds follow
    ``convention`` (:func:`contact_stiffness`). Returns:
    - force_n: the right grip's reaction, N;
    - member_forces_n: the longitudinal members' forces at their mid-sections, N;
    - strain;
    - stiffness_per_metre: force / (strain x sample width), N/m, the width being a pitch per
      longitudinal member, (apertures_y + 1) x pitch_y;
    - series_per_metre: the endless grid's series value (series_stiffness_per_metre).
    """
    from cpp_dem.scene import Scene

    s = Scene(local_damping=0.7)
    m = s.add_material(woven_material(preset))
    g = woven_geogrid(s, origin=(0, 0, 0), apertures_x=apertures_x, apertures_y=apertures_y,
                      material=m, preset=preset, convention=convention, **geometry)
    r = float(s.radii[0])
    x = np.asarray(s.positions)[:, 0]
    lo, hi = g.member_width / 2 - r, apertures_x * g.pitch[0] - g.member_width / 2 + r
    left, right = np.flatnonzero(x <= lo + 1e-9), np.flatnonzero(x >= hi - 1e-9)
    s.block_dofs(np.concatenate([left, right]), "all")
    length = hi - lo
    s.dt = 0.5 * s.critical_dt()
    v = np.zeros((s.num_bodies, 3))
    v[right, 0] = strain * length / (load_steps * s.dt)
    s.velocities = v
    s.run(load_steps)
    s.velocities = np.zeros((s.num_bodies, 3))
    s.run(relax_steps)
    force = -float(np.asarray(s.forces)[right, 0].sum())
    done = float(np.asarray(s.positions)[right, 0].mean() - x[right].mean()) / length
    width = (apertures_y + 1) * g.pitch[1]
    return dict(force_n=force, member_forces_n=g.member_axial_forces(s)[g.members(LONGITUDINAL)],
                strain=done, stiffness_per_metre=force / (done * width),
                series_per_metre=series_stiffness_per_metre(preset, convention=convention,
                                                            **geometry))
