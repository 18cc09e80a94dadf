"""002's soil–geogrid interaction measures for woven grids of bonded spheres (cpp_dem.build.woven).

002 §5–§6 names three effects, compared between the reinforced (RE) and the prestressed
(PRS) element, and two observations beside them. Every measure below returns plain numbers
(per direction 'longitudinal' / 'transverse' where it applies) and has a test in
tests/test_grid_soil_measures.py or tests/test_grid_soil_new_measures.py with a scene where
its effect is present and one where it is absent. "Grain spheres" are the spheres of the grains (free spheres and clump members);
the grid's bonded spheres are never grains. SI units: m, N.

**Interior members.** The grid's longitudinal members are pulled at their ends (the end
junctions of the longitudinal lines; the prestress and the element's end pull), and the two
*end transverse members* (the transverse members on the first and the last junction column,
at the grid's longitudinal ends) bow in plane under that pull (issue 59: 1.2–1.3 mm sideways
under PRS against 0.16–0.34 mm for RE). So every measure of the transverse members (its
'transverse_*' values: sideways displacement, waviness and out-of-plane deflection, contacts
per metre, tension along and across, string gaps, single-string entries, interfriction,
gaps, member strain) is taken over the *interior* transverse members only
(:func:`end_members`, :func:`measured_members`); the keys keep their names. A periodic sheet
has no end members. A grid one aperture long has no interior transverse member: its
transverse values are NaN (entries: 0). Per-member arrays ('per_member_rms_m',
'out_of_plane_m', 'sideways_m', 'cov', 'profiles_n', 'per_member') still hold every member.
Longitudinal measures take all longitudinal members.

- **Interlocking** (grains enter the apertures and push the members sideways):
  - :func:`grains_in_apertures`: grains whose reference point (centre, or clump centre of
    mass) lies over a clear aperture (between the members' built edges) and one of whose
    spheres crosses the grid's plane z_grid (|z - z_grid| < its radius).
  - :func:`member_sideways_displacement`: the rms in-plane displacement of the members'
    string spheres perpendicular to their member's axis, from the grid as built, after
    subtracting the motion of the member's ends (the linear interpolation between the mean
    displacements of its strings' end crossings, which belong to the junctions): a rigid
    shift, a rotation or a stretch of the grid gives zero, a member bowed sideways does not.
- **Single-string interaction** (grains enter between the strings of a member):
  - :func:`single_string_entries` (:func:`grains_between_strings` is the same): grain spheres
    whose centre lies laterally between the axes of two adjacent strings of a member, within
    its clear span between the junctions, and whose lowest point (grain above the strings;
    highest point for a grain below) has gone past the strings' top (bottom) by more than a
    sphere of its radius resting on both strings at their as-built spacing can, plus
    0.1 string radius. A sphere resting on two strings does not count; one pushed into
    the gap, or small enough to pass into it, does.
  - :func:`string_gaps`: the clear gap between adjacent strings of each member (centre
    distance minus the two spheres' radii), as built and now: how far the strings stand
    apart and how they spread under load.
- **Alignment** (the grid wraps around the grains):
  - :func:`grid_contacts_per_metre`: active grain–grid-sphere contacts per metre of clear
    member length, per direction (contacts at junction spheres counted apart).
  - :func:`member_waviness`: the rms out-of-plane (z) deviation of each member's string
    spheres from the straight chord between each string's two ends, per direction (and
    the in-plane one).
- **Tensile force along the members** (002: "more uniform along prestressed members"):
  - :func:`member_force_profiles`: at every position along a member, the sum of its strings'
    bond tensions (N); its coefficient of variation along the members.
  - :func:`tension_variation`: the same profiles' variation in newtons: the std and the
    range (max - min) along each member, the std across the members of their means, and the
    mean above the locked-in force.
- **Displacement above and below the grid** (002: larger above):
  :func:`displacement_above_below`.
- **Interfriction** (002: alignment "resulted in a permanent interfriction effect"; PRS
  "results in lower interfriction"): :func:`interfriction`, the mobilised friction
  |F_t| / (mu F_n) of each grain–grid contact (mu: the contact's own friction coefficient,
  from the pair law of the grain's and the grid's materials), its mean and the share of
  contacts that slide (ratio >= 0.99), per direction.
- **Gaps between the reinforcement and the grains** (002: PRS "may result in gaps between
  the reinforcement and the surrounding particles"): :func:`grid_grain_gaps`, per grid sphere
  the clear distance to the nearest grain sphere above and below, and the share of grid
  spheres with no grain within one grid-sphere diameter (unsupported), above and below apart.
- **Member strain** (002 §6: under PRS "the transverse members have been strained in the
  longitudinal direction"): :func:`member_strain`, each member's axial strain from its
  bonds' lengths. (Read as the members' own strain; their in-plane bending along x, the
  other reading, is :func:`member_sideways_displacement`'s transverse value.)

:func:`summary` gathers them all; :func:`history_row` is a flat row of scalars cheap enough to
write every few thousand steps. :func:`write_vtk_woven` and :func:`plot_views` draw the grid
and the contact network (002 Figs 3–4).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cpp_dem import measure
from cpp_dem.build.geogrid import JUNCTION, LONGITUDINAL, TRANSVERSE

_DIRECTIONS = (LONGITUDINAL, TRANSVERSE)

#: Single-string interaction: the depth margin beyond the resting depth, in string radii.
ENTRY_MARGIN = 0.1

#: Interfriction: a grain–grid contact slides when |F_t| / (mu F_n) is at least this.
SLIDING_RATIO = 0.99


def _bond_tension(scene) -> np.ndarray:
    """Per bond: its tensile force along its axis, N (tension positive)."""
    st = scene.bond_state()
    return -np.einsum("ij,ij->i", st["force"], st["normal"])


def _strings_of_member(grid, scene, m: int) -> list[np.ndarray]:
    """The spheres of each string of member m, ordered along the member (ends included: the
    two end spheres are the crossings at the junctions' edges), the strings in order across
    the member (as built)."""
    ab = np.asarray(scene.bond_spheres)[grid.member_bonds[m]]
    ax = int(np.argmax(np.abs(grid.member_axis[m])))
    pos = np.asarray(grid.reference_positions)
    first = int(grid.spheres[0])
    strings: dict[int, set] = {}
    for a, b in ab:
        s = max(grid.sphere_strand[a - first], grid.sphere_strand[b - first])
        strings.setdefault(int(s), set()).update((int(a), int(b)))
    out = []
    for s in sorted(strings):
        ids = np.array(sorted(strings[s]))
        out.append(ids[np.argsort(pos[ids - first, ax], kind="stable")])
    cross = 1 - ax
    out.sort(key=lambda ids: float(np.mean(pos[ids - first, cross])))
    return out


def _axes(grid, m: int) -> tuple[int, int]:
    ax = int(np.argmax(np.abs(grid.member_axis[m])))
    return ax, 1 - ax


def end_members(grid) -> np.ndarray:
    """Per member, True for the two end transverse members: the transverse members on the
    grid's first and last junction column (member_cell[:, 0] == 0 or n_cells[0]), at its
    longitudinal ends, where the longitudinal lines are pulled. A periodic sheet (no last
    column: it is the first one's image) has none."""
    direction = np.asarray(grid.member_direction)
    col = np.asarray(grid.member_cell).reshape(-1, 2)[:, 0]
    tr = direction == TRANSVERSE
    last = int(grid.n_cells[0])
    if not np.any(tr & (col == last)):
        return np.zeros(len(direction), bool)
    return tr & ((col == 0) | (col == last))


def measured_members(grid, direction: str) -> np.ndarray:
    """The members of ``direction`` that the measures take: all longitudinal members; the
    interior transverse members (the end ones, :func:`end_members`, left out)."""
    sel = (np.asarray(grid.member_direction) == direction) & ~end_members(grid)
    return np.flatnonzero(sel)


def _measured_mask(grid) -> np.ndarray:
    """Per member, True when the measures take it (:func:`measured_members`)."""
    return ~end_members(grid)


def _mean(x) -> float:
    x = np.asarray(x, float)
    return float(x.mean()) if x.size else float("nan")


def _min_image(scene, d: np.ndarray) -> np.ndarray:
    """Vectors between bodies (n, 3), m, with the periodic cell's minimum image (as they
    are when the scene is not periodic)."""
    if not getattr(scene, "is_periodic", False):
        return d
    h = np.asarray(scene.cell_matrix, float)
    per = np.asarray(scene.cell_periodic, bool)
    f = d @ np.linalg.inv(h).T
    f[:, per] -= np.round(f[:, per])
    return f @ h.T


def member_waviness(scene, grid) -> dict:
    """For each member, the RMS deviation of its strings' spheres from the straight line
    between each string's two ends, m: out of plane (z; alignment) and in plane (sideways).

    Returns the per-member arrays 'out_of_plane_m', 'sideways_m' (every member) and, per
    direction d, 'out_of_plane_{d}_mean_m' and 'sideways_{d}_mean_m' (means over the
    direction's members, m; transverse: the interior members, the two end ones left out,
    :func:`measured_members`; NaN when there is none)."""
    pos = np.asarray(scene.positions)
    out_of_plane = np.zeros(grid.n_members)
    sideways = np.zeros(grid.n_members)
    for m in range(grid.n_members):
        ax, cross = _axes(grid, m)
        dz, dy = [], []
        for ids in _strings_of_member(grid, scene, m):
            p = pos[ids]
            t = (p[:, ax] - p[0, ax]) / (p[-1, ax] - p[0, ax])
            line = p[0] + np.outer(t, p[-1] - p[0])
            dz.append(p[:, 2] - line[:, 2])
            dy.append(p[:, cross] - line[:, cross])
        out_of_plane[m] = np.sqrt(np.mean(np.concatenate(dz) ** 2))
        sideways[m] = np.sqrt(np.mean(np.concatenate(dy) ** 2))
    res = {"out_of_plane_m": out_of_plane, "sideways_m": sideways}
    for d in _DIRECTIONS:
        sel = measured_members(grid, d)
        res[f"out_of_plane_{d}_mean_m"] = _mean(out_of_plane[sel])
        res[f"sideways_{d}_mean_m"] = _mean(sideways[sel])
    return res


def member_sideways_displacement(scene, grid) -> dict:
    """Interlocking: how far the members were pushed sideways, m.

    For every string sphere of a member (its end crossings, which belong to the junctions,
    left out): its displacement from the grid as built (grid.reference_positions), minus
    the motion of the member's ends there (the linear interpolation, along the member,
    between the mean displacements of the strings' two end crossings), and of that its
    in-plane component perpendicular to the member's axis. A rigid shift of the grid, a
    stretch along the member, or (to first order) a rotation gives zero; a member bowed
    sideways between its junctions does not.

    Returns per direction d: '{d}_rms_m' (rms over the direction's member spheres, m) and
    '{d}_max_m' (largest magnitude, m), transverse over the interior members only (the two
    end members, bowed by the pull at the end junctions, left out: :func:`measured_members`;
    NaN when there is none), and 'per_member_rms_m' (array, every member)."""
    pos = np.asarray(scene.positions)
    ref = np.asarray(grid.reference_positions)
    first = int(grid.spheres[0])
    per = np.zeros(grid.n_members)
    vals: dict[str, list] = {d: [] for d in _DIRECTIONS}
    measured = _measured_mask(grid)
    for m in range(grid.n_members):
        ax, cross = _axes(grid, m)
        strings = _strings_of_member(grid, scene, m)
        ends0 = np.array([s[0] for s in strings])
        ends1 = np.array([s[-1] for s in strings])
        u0 = (pos[ends0] - ref[ends0 - first]).mean(axis=0)
        u1 = (pos[ends1] - ref[ends1 - first]).mean(axis=0)
        a0 = ref[ends0 - first, ax].mean()
        a1 = ref[ends1 - first, ax].mean()
        inner = np.concatenate([s[1:-1] for s in strings])
        t = (ref[inner - first, ax] - a0) / (a1 - a0)
        u = pos[inner] - ref[inner - first] - (u0 + np.outer(t, u1 - u0))
        side = u[:, cross]
        per[m] = float(np.sqrt(np.mean(side ** 2))) if len(side) else 0.0
        if measured[m]:
            vals[grid.member_direction[m]].append(side)
    res = {"per_member_rms_m": per}
    for dname in _DIRECTIONS:
        v = np.concatenate(vals[dname]) if vals[dname] else np.zeros(0)
        none = 0.0 if len(measured_members(grid, dname)) else float("nan")
        res[f"{dname}_rms_m"] = float(np.sqrt(np.mean(v ** 2))) if len(v) else none
        res[f"{dname}_max_m"] = float(np.max(np.abs(v))) if len(v) else none
    return res


def _grid_contact_arrays(scene, grid) -> dict:
    """Active pair contacts between a grain body and a grid sphere (scene.contacts()), as
    arrays: 'grain' (grain body id), 'sphere' (grid sphere id), 'force' (|force|, N),
    'normal_force' (F_n, N, compression positive), 'shear_force' (|F_t|, N) and 'mu' (the
    contact's Coulomb coefficient tan(phi), from the pair law of the two materials)."""
    c = scene.contacts()
    ids = np.asarray(c["ids"]).reshape(-1, 2)
    keys = ("grain", "sphere", "force", "normal_force", "shear_force", "mu")
    if len(ids) == 0:
        return {k: np.zeros(0, int if k in ("grain", "sphere") else float) for k in keys}
    is_grid = np.zeros(scene.num_bodies, bool)
    is_grid[grid.spheres] = True
    pair = ids[:, 1] >= 0
    a, b = ids[:, 0], ids[:, 1]
    ga = pair & is_grid[a] & ~is_grid[np.where(pair, b, 0)]
    gb = pair & is_grid[np.where(pair, b, 0)] & ~is_grid[a]

    def both(x):
        x = np.asarray(x)
        return np.concatenate([x[ga], x[gb]])

    return {"grain": np.concatenate([b[ga], a[gb]]).astype(int),
            "sphere": np.concatenate([a[ga], b[gb]]).astype(int),
            "force": both(np.linalg.norm(np.asarray(c["force"]).reshape(-1, 3), axis=1)),
            "normal_force": both(np.asarray(c["normal_force"], float)),
            "shear_force": both(np.linalg.norm(np.asarray(c["shear_force"]).reshape(-1, 3),
                                               axis=1)),
            "mu": both(np.asarray(c["tan_phi"], float))}


def _grid_contacts(scene, grid):
    """Active pair contacts between a grain body and a grid sphere: (grain body, grid sphere,
    |force|)."""
    c = _grid_contact_arrays(scene, grid)
    return c["grain"], c["sphere"], c["force"]


def _sphere_member(scene, grid) -> np.ndarray:
    """Per grid sphere (local index), the member it belongs to (-1: junction)."""
    first = int(grid.spheres[0])
    out = np.full(len(grid.spheres), -1)
    ab = np.asarray(scene.bond_spheres)[grid.bonds] - first
    for k, m in enumerate(grid.bond_member):
        if m < 0:
            continue
        for s in ab[k]:
            if grid.sphere_kind[s] != JUNCTION:
                out[s] = m
    return out


def member_lengths(grid, *, interior: bool = True) -> dict:
    """Total clear length of the members of each direction, m (between junctions): with
    ``interior`` (the default) of the members the measures take (transverse: the interior
    ones, :func:`measured_members`), else of all of them."""
    def count(d):
        return (len(measured_members(grid, d)) if interior
                else int(np.sum(grid.member_direction == d)))

    return {d: float(count(d)) * (grid.pitch[0 if d == LONGITUDINAL else 1] - grid.member_width)
            for d in _DIRECTIONS}


def _sphere_direction(scene, grid) -> np.ndarray:
    """Per grid sphere (local index): 'longitudinal' or 'transverse' for the string spheres
    of a member the measures take (:func:`measured_members`), 'junction' for junction
    spheres, '' for the string spheres of an end transverse member."""
    sm = _sphere_member(scene, grid)
    measured = _measured_mask(grid)
    mdir = np.asarray(grid.member_direction)
    out = np.full(len(sm), "", dtype=object)
    out[sm < 0] = JUNCTION
    on = (sm >= 0) & measured[np.maximum(sm, 0)]
    out[on] = mdir[sm[on]]
    return out


def grid_contacts_per_metre(scene, grid) -> dict:
    """Alignment: active grain–grid-sphere contacts per metre of clear member length.

    Returns 'contacts' (all grain–grid contacts), 'grains_touching' (distinct grains touching
    the grid), 'junction_contacts' (contacts at junction spheres, not in the per-metre
    values) and per direction d '{d}_per_m' (contacts with the string spheres of the
    direction's members / their total clear length, 1/m; transverse: the interior members,
    their contacts over their length, the two end members left out; NaN when there is
    none)."""
    grain, sphere, _ = _grid_contacts(scene, grid)
    first = int(grid.spheres[0])
    sm = _sphere_member(scene, grid)
    member = sm[sphere - first]
    lengths = member_lengths(grid)
    g_of_b, _ = measure.grain_of_body(scene)
    res = {"contacts": int(len(grain)), "grains_touching": int(len(np.unique(g_of_b[grain]))),
           "junction_contacts": int(np.sum(member < 0))}
    measured = _measured_mask(grid)
    for d in _DIRECTIONS:
        on = ((member >= 0) & (grid.member_direction[np.maximum(member, 0)] == d)
              & measured[np.maximum(member, 0)])
        res[f"{d}_per_m"] = float(np.sum(on) / lengths[d]) if lengths[d] > 0 else float("nan")
    return res


def resting_depth(sphere_radius: float, string_radius: float, half_spacing) -> np.ndarray:
    """How far below the top of two parallel strings (spheres of ``string_radius``, centres
    2 ``half_spacing`` apart in one plane) the lowest point of a sphere of ``sphere_radius``
    resting on both (touching both, no overlap) lies, m: R + r - sqrt((R + r)^2 - s^2).
    A sphere with R + r <= s fits between the strings and cannot rest on both: 0 (any dip
    below their top is a way into the gap)."""
    rr = np.asarray(sphere_radius, float) + string_radius
    s = np.asarray(half_spacing, float)
    return np.where(rr > s, rr - np.sqrt(np.maximum(rr ** 2 - s ** 2, 0.0)), 0.0)


def single_string_entries(scene, grid, *, margin: float = ENTRY_MARGIN) -> dict:
    """Single-string interaction: the grain spheres that have entered between two adjacent
    strings of a member.

    A grain sphere (centre c, radius R) is tested against each pair of adjacent strings of
    each member, at its position along the member. The strings there: each string's centre
    line interpolated at c's coordinate along the member, now (their spacing 2 s_now, their
    mean height z_s); their spheres' radius r; their as-built half spacing s. It counts when
    - c lies laterally between the two strings' axes, and along the member within its clear
      span (between the end crossings, one string radius in from each), and
    - its lowest point (grain reference point above z_s; for a grain below, its highest
      point, mirrored) lies below the strings' top z_s + r by a depth
      depth > resting_depth(R, r, s) + margin x r.

    Why this depth: resting_depth(R, r, s) is exactly how deep a sphere of radius R dips
    between the strings while it rests on both at their as-built spacing (touching, no
    overlap), so a resting sphere never counts, whatever its size; a sphere gets deeper only
    by spreading the strings apart, or by being small enough to fit between them (R + r <=
    s: it cannot rest on both, and any dip below their top beyond the margin counts). The
    margin (0.1 r =
    0.1 mm for the detailed grid) stands above the contact overlaps (micrometres at 002's
    stiffnesses and the element's stresses) and the strings' own local sag. With the detailed
    grid (r = 1 mm, s = 2.25 mm), a 2 mm member sphere resting on two strings dips
    3 - sqrt(3^2 - 2.25^2) = 1.02 mm below their top; it counts beyond 1.12 mm. A member
    sphere of radius < 1.25 mm fits the 2.5 mm gap and counts once 0.1 mm below the top.

    The two end transverse members are left out (:func:`measured_members`).

    Returns per direction d: '{d}_grains' (distinct grains with an entered sphere),
    '{d}_spheres' (entered grain spheres, counted once per string pair), '{d}_depth_max_m'
    (the largest depth below the strings' top reached by an entered sphere, 0 if none), and
    in total 'grains_entered', 'spheres_entered'."""
    pos = np.asarray(scene.positions)
    ref_g = np.asarray(grid.reference_positions)
    first = int(grid.spheres[0])
    rad = np.asarray(scene.radii)
    gmask = measure.sphere_mask(scene)
    gidx = np.flatnonzero(gmask)
    gp, gr = pos[gidx], rad[gidx]
    gref = measure.reference_points(scene)[gidx]
    g_of_b, _ = measure.grain_of_body(scene)
    r_max = float(gr.max()) if len(gr) else 0.0
    grains: dict[str, set] = {d: set() for d in _DIRECTIONS}
    spheres = {d: 0 for d in _DIRECTIONS}
    depth_max = {d: 0.0 for d in _DIRECTIONS}
    measured = _measured_mask(grid)
    for m in range(grid.n_members):
        if not measured[m]:
            continue
        strings = _strings_of_member(grid, scene, m)
        if len(strings) < 2 or not len(gidx):
            continue
        d = grid.member_direction[m]
        ax, cross = _axes(grid, m)
        r = float(rad[strings[0][0]])
        lo = max(pos[s[0], ax] for s in strings) + r
        hi = min(pos[s[-1], ax] for s in strings) - r
        allp = pos[np.concatenate(strings)]
        c_lo, c_hi = allp[:, cross].min(), allp[:, cross].max()
        z_lo, z_hi = allp[:, 2].min() - r - 2 * r_max, allp[:, 2].max() + r + 2 * r_max
        near = ((gp[:, ax] > lo) & (gp[:, ax] < hi) & (gp[:, cross] > c_lo)
                & (gp[:, cross] < c_hi) & (gp[:, 2] > z_lo) & (gp[:, 2] < z_hi))
        if not near.any():
            continue
        k = np.flatnonzero(near)
        x = gp[k, ax]
        lines = []
        for s in strings:
            p = pos[s]
            o = np.argsort(p[:, ax], kind="stable")
            lines.append((np.interp(x, p[o, ax], p[o, cross]), np.interp(x, p[o, ax], p[o, 2])))
        for i in range(len(strings) - 1):
            (c0, z0), (c1, z1) = lines[i], lines[i + 1]
            between = (gp[k, cross] > np.minimum(c0, c1)) & (gp[k, cross] < np.maximum(c0, c1))
            zs = 0.5 * (z0 + z1)
            above = gref[k, 2] > zs
            depth = np.where(above, (zs + r) - (gp[k, 2] - gr[k]), (gp[k, 2] + gr[k]) - (zs - r))
            s_built = 0.5 * abs(float(np.mean(ref_g[strings[i + 1] - first, cross])
                                      - np.mean(ref_g[strings[i] - first, cross])))
            entered = between & (depth > resting_depth(gr[k], r, s_built) + margin * r)
            if entered.any():
                spheres[d] += int(entered.sum())
                grains[d].update(int(g) for g in g_of_b[gidx[k[entered]]])
                depth_max[d] = max(depth_max[d], float(depth[entered].max()))
    res = {}
    for d in _DIRECTIONS:
        res[f"{d}_grains"] = len(grains[d])
        res[f"{d}_spheres"] = spheres[d]
        res[f"{d}_depth_max_m"] = depth_max[d]
    res["grains_entered"] = len(grains[LONGITUDINAL] | grains[TRANSVERSE])
    res["spheres_entered"] = spheres[LONGITUDINAL] + spheres[TRANSVERSE]
    return res


def grains_between_strings(scene, grid, *, z_grid: float | None = None) -> dict:
    """Single-string interaction: :func:`single_string_entries` (``z_grid`` is not used: the
    strings' height is taken where each grain sphere is)."""
    del z_grid
    return single_string_entries(scene, grid)


def string_gaps(scene, grid) -> dict:
    """The clear gap between adjacent strings of each member, m: for each pair of adjacent
    strings and each position along the member (the k-th string sphere of one against the
    k-th of the other, end crossings left out), the centre distance minus the two spheres'
    radii. As built (grid.reference_positions) and now: how far the strings stand apart and
    how they spread under load.

    Returns per direction d: '{d}_built_mean_m', and now '{d}_now_mean_m', '{d}_now_min_m',
    '{d}_now_max_m' (over all positions of the direction's members), '{d}_spread_mean_m' (now - built,
    mean) and '{d}_spread_max_m' (largest widening). Transverse: the interior members (the
    two end members left out, :func:`measured_members`). NaN for single-string members and
    when the direction has no member measured."""
    pos = np.asarray(scene.positions)
    ref = np.asarray(grid.reference_positions)
    rad = np.asarray(scene.radii)
    first = int(grid.spheres[0])
    now: dict[str, list] = {d: [] for d in _DIRECTIONS}
    built: dict[str, list] = {d: [] for d in _DIRECTIONS}
    measured = _measured_mask(grid)
    for m in range(grid.n_members):
        if not measured[m]:
            continue
        strings = _strings_of_member(grid, scene, m)
        d = grid.member_direction[m]
        for a, b in zip(strings[:-1], strings[1:]):
            a, b = a[1:-1], b[1:-1]
            n = min(len(a), len(b))
            a, b = a[:n], b[:n]
            rr = rad[a] + rad[b]
            now[d].append(np.linalg.norm(pos[a] - pos[b], axis=1) - rr)
            built[d].append(np.linalg.norm(ref[a - first] - ref[b - first], axis=1) - rr)
    res = {}
    for d in _DIRECTIONS:
        if now[d]:
            g, g0 = np.concatenate(now[d]), np.concatenate(built[d])
            res.update({f"{d}_built_mean_m": float(g0.mean()),
                        f"{d}_now_mean_m": float(g.mean()),
                        f"{d}_now_min_m": float(g.min()), f"{d}_now_max_m": float(g.max()),
                        f"{d}_spread_mean_m": float((g - g0).mean()),
                        f"{d}_spread_max_m": float((g - g0).max())})
        else:
            res.update({f"{d}_{k}": float("nan") for k in ("built_mean_m", "now_mean_m",
                                                           "now_min_m", "now_max_m",
                                                           "spread_mean_m", "spread_max_m")})
    return res


def grains_in_apertures(scene, grid, *, z_grid: float | None = None) -> dict:
    """Interlocking: grains whose reference point (centre, or clump centre of mass) lies over
    a clear aperture (between the members' built edges) and one of whose spheres crosses the
    grid's plane (|z - z_grid| < its radius; z_grid: the grid spheres' mean height if None).
    Returns 'grains_in_apertures' (count) and 'per_aperture' (counts, cells x by y)."""
    pos = np.asarray(scene.positions)
    rad = np.asarray(scene.radii)
    gmask = measure.sphere_mask(scene)
    zg = float(np.mean(pos[grid.spheres, 2])) if z_grid is None else z_grid
    ref = measure.reference_points(scene)
    g_of_b, ng = measure.grain_of_body(scene)
    reach = np.zeros(ng, bool)
    crosses = gmask & (np.abs(pos[:, 2] - zg) < rad)
    reach[g_of_b[crosses]] = True
    # Aperture (i, j): between the members' edges.
    x0 = np.min(np.asarray(grid.reference_positions)[:, 0])
    y0 = np.min(np.asarray(grid.reference_positions)[:, 1])
    w = grid.member_width
    r_g = float(rad[grid.spheres[0]])
    per = np.zeros(grid.n_cells, int)
    gref = np.zeros((ng, 3))
    gref[g_of_b[gmask]] = ref[gmask]
    for i in range(grid.n_cells[0]):
        for j in range(grid.n_cells[1]):
            xl = x0 - r_g + i * grid.pitch[0] + w
            yl = y0 - r_g + j * grid.pitch[1] + w
            inside = ((gref[:, 0] > xl) & (gref[:, 0] < xl + grid.pitch[0] - w)
                      & (gref[:, 1] > yl) & (gref[:, 1] < yl + grid.pitch[1] - w) & reach)
            per[i, j] = int(np.sum(inside))
    return {"grains_in_apertures": int(per.sum()), "per_aperture": per.tolist()}


def _profiles(scene, grid) -> list[np.ndarray]:
    """Per member, its tensile force profile, N: at every position along it crossed by all its
    strings, the sum of the strings' bond tensions there."""
    tension = _bond_tension(scene)
    ab = np.asarray(scene.bond_spheres)
    pos = np.asarray(grid.reference_positions)
    first = int(grid.spheres[0])
    profiles = []
    for m in range(grid.n_members):
        bonds = np.asarray(grid.member_bonds[m])
        ax = int(np.argmax(np.abs(grid.member_axis[m])))
        mid = 0.5 * (pos[ab[bonds, 0] - first, ax] + pos[ab[bonds, 1] - first, ax])
        # Bonds at the same position along the member (one per string) are summed.
        key = np.round(mid / 1e-7).astype(np.int64)
        u, inv = np.unique(key, return_inverse=True)
        prof = np.zeros(len(u))
        np.add.at(prof, inv, tension[bonds])
        n_str = np.bincount(inv)
        profiles.append(prof[n_str == n_str.max()])  # positions crossed by every string
    return profiles


def member_force_profiles(scene, grid) -> dict:
    """The tensile force along each member, N: at every position along it, the sum of its
    strings' bond tensions. Returns the profiles ('profiles_n'), per member the coefficient
    of variation along it ('cov', std / |mean|; both for every member) and, per direction d,
    '{d}_cov_mean' (mean over the members) and '{d}_force_mean_n' (mean force, N);
    transverse over the interior members (:func:`measured_members`; NaN when there is
    none)."""
    profiles = _profiles(scene, grid)
    cov = np.array([float(np.std(p) / max(abs(np.mean(p)), 1e-12)) for p in profiles])
    res = {"profiles_n": profiles, "cov": cov}
    for d in _DIRECTIONS:
        sel = measured_members(grid, d)
        res[f"{d}_cov_mean"] = _mean(cov[sel])
        res[f"{d}_force_mean_n"] = _mean([profiles[m].mean() for m in sel])
    return res


def tension_variation(scene, grid, locked_n=None) -> dict:
    """How the tensile force varies along and across the members, N (not a ratio).

    The profiles are those of :func:`member_force_profiles` (at each position along a member,
    its strings' bond tensions summed). ``locked_n``: the locked-in force, N, one value or
    one per member (default 0). Returns per direction d:
    - '{d}_std_along_n': the mean over the members of the std of the force along each, N;
    - '{d}_range_along_n': the mean over the members of (max - min) along each, N;
    - '{d}_std_across_n': the std across the members of their mean forces, N;
    - '{d}_mean_above_locked_n': the mean over the members of (mean force - locked_n), N.
    Transverse: over the interior members (the two end ones left out,
    :func:`measured_members`; NaN when there is none)."""
    return _tension_variation(grid, _profiles(scene, grid), locked_n)


def _tension_variation(grid, profiles, locked_n) -> dict:
    locked = np.broadcast_to(np.asarray(0.0 if locked_n is None else locked_n, float),
                             (grid.n_members,))
    means = np.array([p.mean() for p in profiles])
    res = {}
    for d in _DIRECTIONS:
        sel = measured_members(grid, d)
        res[f"{d}_std_along_n"] = _mean([np.std(profiles[m]) for m in sel])
        res[f"{d}_range_along_n"] = _mean([np.ptp(profiles[m]) for m in sel])
        res[f"{d}_std_across_n"] = float(np.std(means[sel])) if len(sel) else float("nan")
        res[f"{d}_mean_above_locked_n"] = _mean(means[sel] - locked[sel])
    return res


def displacement_above_below(scene, reference_positions, z_grid: float) -> dict:
    """The grain spheres' displacement from ``reference_positions`` (all bodies, m), split by
    whether their reference position is above or below the grid's plane z_grid: mean
    magnitude ('above_mean_m', 'below_mean_m') and mean vertical component ('above_z_mean_m',
    'below_z_mean_m'), m. (Clump members count one by one.)"""
    pos = np.asarray(scene.positions)
    ref = np.asarray(reference_positions)
    g = measure.sphere_mask(scene)
    d = pos - ref
    above, below = g & (ref[:, 2] > z_grid), g & (ref[:, 2] < z_grid)

    def mean(x):
        return float(x.mean()) if len(x) else float("nan")

    return {"above_mean_m": mean(np.linalg.norm(d[above], axis=1)),
            "below_mean_m": mean(np.linalg.norm(d[below], axis=1)),
            "above_z_mean_m": mean(d[above, 2]),
            "below_z_mean_m": mean(d[below, 2])}


def interfriction(scene, grid, *, sliding: float = SLIDING_RATIO) -> dict:
    """Interfriction: how much of its friction each grain–grid contact mobilises.

    For every active contact between a grain sphere and a grid sphere (scene.contacts()):
    the ratio |F_t| / (mu F_n), with F_t its tangential (shear) force, F_n its normal force
    (compression positive) and mu its own Coulomb coefficient (the contact's tan(phi), set by
    the pair law of the grain's and the grid's materials, cpp_dem.build.woven.set_grid_laws).
    0: no tangential load; 1: sliding (the Coulomb limit). Contacts with F_n <= 0 or mu = 0
    (ratio undefined) are left out. A contact counts as sliding when its ratio >= ``sliding``
    (default 0.99).

    Returns, over all grain–grid contacts: 'contacts' (count), 'mean_ratio' (mean of the
    ratio, -) and 'sliding_fraction' (share of the contacts sliding, -); and the same per
    kind k of the grid sphere touched, '{k}_contacts', '{k}_mean_ratio',
    '{k}_sliding_fraction', for k = 'longitudinal', 'transverse' (the string spheres of the
    direction's members; transverse: the interior members only, :func:`measured_members`)
    and 'junction'. NaN where there is no contact."""
    c = _grid_contact_arrays(scene, grid)
    fn, ft, mu = c["normal_force"], c["shear_force"], c["mu"]
    ok = (fn > 0) & (mu > 0)
    ratio = ft[ok] / (mu[ok] * fn[ok])
    kind = _sphere_direction(scene, grid)[c["sphere"][ok] - int(grid.spheres[0])]

    def part(sel, prefix):
        r = ratio[sel]
        return {f"{prefix}contacts": int(len(r)),
                f"{prefix}mean_ratio": _mean(r),
                f"{prefix}sliding_fraction": _mean(r >= sliding)}

    res = part(np.ones(len(ratio), bool), "")
    for k in (*_DIRECTIONS, JUNCTION):
        res.update(part(kind == k, f"{k}_"))
    return res


def _grain_spheres(scene, grid) -> tuple[np.ndarray, np.ndarray]:
    """Centres (m) and radii (m) of the grain spheres (free spheres and clump members; never
    the grid's), with their periodic images across the periodic cell's faces (the 3^k - 1
    neighbouring cells) when the scene is periodic."""
    mask = measure.sphere_mask(scene)
    mask[np.asarray(grid.spheres)] = False
    c = np.asarray(scene.positions, float)[mask]
    r = np.asarray(scene.radii, float)[mask]
    if getattr(scene, "is_periodic", False) and len(c):
        h = np.asarray(scene.cell_matrix, float)
        per = [a for a in range(3) if scene.cell_periodic[a]]
        shifts = np.array(np.meshgrid(*[[-1, 0, 1]] * len(per), indexing="ij")).reshape(
            len(per), -1).T
        cs, rs = [], []
        for n in shifts:
            cs.append(c + (h[:, per] @ n))
            rs.append(r)
        c, r = np.concatenate(cs), np.concatenate(rs)
    return c, r


def _nearest_clearance(points, radii, centres, cradii, sign: int) -> np.ndarray:
    """Per point (a sphere of ``radii``), the clear distance to the nearest sphere of
    (``centres``, ``cradii``) whose centre lies above it (sign +1: higher z; -1: lower),
    |c - p| - R - r, floored at 0; inf when there is none. Exact: the k nearest centres
    (k growing fourfold) until no sphere further away can be nearer."""
    n = len(points)
    best = np.full(n, np.inf)
    if not len(centres) or not n:
        return best
    from scipy.spatial import cKDTree

    tree = cKDTree(centres)
    r_max = float(np.max(cradii))
    todo = np.arange(n)
    k = 16
    while todo.size:
        kk = min(k, len(centres))
        d, idx = tree.query(points[todo], kk)
        d, idx = d.reshape(len(todo), kk), idx.reshape(len(todo), kk)
        clear = d - cradii[idx] - radii[todo, None]
        side = sign * (centres[idx, 2] - points[todo, 2, None]) > 0
        b = np.where(side, clear, np.inf).min(axis=1)
        if kk == len(centres):
            best[todo] = b
            break
        ok = b <= d[:, -1] - r_max - radii[todo]
        best[todo[ok]] = b[ok]
        todo = todo[~ok]
        k *= 4
    return np.maximum(best, 0.0)


def grid_grain_gaps(scene, grid) -> dict:
    """Gaps between the reinforcement and the grains (002: under prestress the grid does not
    wrap around the grains, which "may result in gaps").

    For each grid sphere (centre p, radius r): its clear distance to the nearest grain sphere
    surface above (grain sphere centres c with c_z > p_z) and below (c_z < p_z),
    |c - p| - R - r (R the grain sphere's radius), 0 for a touching or overlapping grain, inf
    when no grain sphere lies on that side. It is *unsupported* on a side when no grain
    sphere lies within one grid-sphere diameter there (clear distance > 2 r). Grain spheres:
    free spheres and clump members (measure.sphere_mask), with their periodic images.

    Returns, over all the grid's spheres (junctions and every member): 'above_mean_m' and
    'below_mean_m' (the mean clear distance, m, over the spheres with a grain on that side;
    NaN if none has) and 'unsupported_above_fraction', 'unsupported_below_fraction' (share of
    the grid spheres, -); the same per direction d, '{d}_above_mean_m', ..., over the string
    spheres of the direction's members (transverse: interior members only,
    :func:`measured_members`); and the per-sphere arrays 'above_m', 'below_m' (grid order)."""
    gi = np.asarray(grid.spheres)
    gp = np.asarray(scene.positions, float)[gi]
    gr = np.asarray(scene.radii, float)[gi]
    cp, cr = _grain_spheres(scene, grid)
    above = _nearest_clearance(gp, gr, cp, cr, +1)
    below = _nearest_clearance(gp, gr, cp, cr, -1)
    kind = _sphere_direction(scene, grid)

    def part(sel, prefix):
        out = {}
        for side, g in (("above", above[sel]), ("below", below[sel])):
            out[f"{prefix}{side}_mean_m"] = _mean(g[np.isfinite(g)])
            out[f"{prefix}unsupported_{side}_fraction"] = _mean(g > 2 * gr[sel])
        return out

    res = part(np.ones(len(gi), bool), "")
    for d in _DIRECTIONS:
        res.update(part(kind == d, f"{d}_"))
    res["above_m"], res["below_m"] = above, below
    return res


def member_strain(scene, grid) -> dict:
    """The members' axial strain from their bonds' lengths (002 §6: under PRS the transverse
    members "have been strained in the longitudinal direction").

    For each member: (sum of its bonds' current lengths) / (sum of their initial lengths) - 1,
    over all its strings, the bonds from the end crossings included (a bond's current
    length: its spheres' centre distance, the periodic cell's minimum image; its initial
    length: its reference gap plus the two radii, the centre distance when it was made).
    So a homogeneous stretch eps along the member gives eps exactly; a string wrapped
    around a grain is longer. Returns 'per_member' (array, every member) and per direction d
    '{d}_mean', '{d}_min', '{d}_max' (-) over the direction's members (transverse: the
    interior ones, :func:`measured_members`; NaN when there is none)."""
    pos = np.asarray(scene.positions, float)
    rad = np.asarray(scene.radii, float)
    ab = np.asarray(scene.bond_spheres)
    gap0 = np.asarray(scene.bond_state()["reference_gap"], float)
    per = np.zeros(grid.n_members)
    for m in range(grid.n_members):
        b = np.asarray(grid.member_bonds[m])
        a0, a1 = ab[b, 0], ab[b, 1]
        length = np.linalg.norm(_min_image(scene, pos[a1] - pos[a0]), axis=1)
        length0 = gap0[b] + rad[a0] + rad[a1]
        per[m] = float(length.sum() / length0.sum() - 1.0)
    res = {"per_member": per}
    for d in _DIRECTIONS:
        sel = measured_members(grid, d)
        v = per[sel]
        res[f"{d}_mean"] = _mean(v)
        res[f"{d}_min"] = float(v.min()) if len(v) else float("nan")
        res[f"{d}_max"] = float(v.max()) if len(v) else float("nan")
    return res


def summary(scene, grid, *, z_grid: float, reference_positions=None, locked_n=None) -> dict:
    """All the measures above as plain numbers (the per-member and per-sphere arrays left
    out): 'contacts', 'between_strings' (:func:`single_string_entries`), 'apertures',
    'waviness', 'force', 'tension_variation', 'string_gaps', 'sideways_displacement',
    'interfriction' (:func:`interfriction`), 'gaps' (:func:`grid_grain_gaps`),
    'member_strain' (:func:`member_strain`), and 'displacement' when
    ``reference_positions`` (all bodies, m) is given. Transverse values are of the interior
    transverse members (module docstring)."""
    w = member_waviness(scene, grid)
    f = member_force_profiles(scene, grid)
    sd = member_sideways_displacement(scene, grid)
    out = {"contacts": grid_contacts_per_metre(scene, grid),
           "between_strings": single_string_entries(scene, grid),
           "apertures": grains_in_apertures(scene, grid, z_grid=z_grid),
           "waviness": {k: v for k, v in w.items() if k.endswith("_m") and "mean" in k},
           "force": {k: v for k, v in f.items() if k.endswith(("_mean", "_n"))
                     and not isinstance(v, list)},
           "tension_variation": tension_variation(scene, grid, locked_n),
           "string_gaps": string_gaps(scene, grid),
           "sideways_displacement": {k: v for k, v in sd.items() if not k.startswith("per_")},
           "interfriction": interfriction(scene, grid),
           "gaps": {k: v for k, v in grid_grain_gaps(scene, grid).items()
                    if k not in ("above_m", "below_m")},
           "member_strain": {k: v for k, v in member_strain(scene, grid).items()
                             if k != "per_member"}}
    if reference_positions is not None:
        out["displacement"] = displacement_above_below(scene, reference_positions, z_grid)
    return out


def history_row(scene, grid, *, z_grid: float, locked_n=None, reference_positions=None) -> dict:
    """A flat dict of the scalar measures (a CSV row over the loading); the suffix says the
    unit (_n N, _m m, _per_m 1/m; dimensionless: _ratio a force ratio, _fraction a share in
    [0, 1], _strain a strain; no suffix: a count). Transverse values are of the interior
    transverse members, the two end ones left out (module docstring). Keys, d in
    longitudinal/transverse:
    grid_contacts, grains_touching_grid, junction_contacts, {d}_contacts_per_m;
    {d}_entered_grains, {d}_entered_spheres, {d}_entry_depth_max_m; grains_in_apertures;
    {d}_out_of_plane_mean_m, {d}_sideways_chord_mean_m (waviness);
    {d}_sideways_displacement_rms_m, {d}_sideways_displacement_max_m;
    {d}_string_gap_mean_m, _min_m, _max_m, {d}_string_gap_spread_mean_m;
    {d}_force_mean_n, {d}_tension_std_along_n, {d}_tension_range_along_n,
    {d}_tension_std_across_n, {d}_tension_mean_above_locked_n;
    interfriction (:func:`interfriction`, all grain–grid contacts and per direction):
    interfriction_contacts, interfriction_mean_ratio, interfriction_sliding_fraction,
    {d}_interfriction_contacts, {d}_interfriction_mean_ratio,
    {d}_interfriction_sliding_fraction;
    gaps (:func:`grid_grain_gaps`, all grid spheres and per direction): gap_above_mean_m,
    gap_below_mean_m, unsupported_above_fraction, unsupported_below_fraction,
    {d}_gap_above_mean_m, {d}_gap_below_mean_m, {d}_unsupported_above_fraction,
    {d}_unsupported_below_fraction;
    member strain (:func:`member_strain`): {d}_mean_axial_strain;
    and with ``reference_positions``: disp_above_mean_m, disp_below_mean_m,
    disp_z_above_mean_m, disp_z_below_mean_m."""
    row: dict = {}
    c = grid_contacts_per_metre(scene, grid)
    row.update(grid_contacts=c["contacts"], grains_touching_grid=c["grains_touching"],
               junction_contacts=c["junction_contacts"])
    e = single_string_entries(scene, grid)
    a = grains_in_apertures(scene, grid, z_grid=z_grid)
    w = member_waviness(scene, grid)
    sd = member_sideways_displacement(scene, grid)
    g = string_gaps(scene, grid)
    profiles = _profiles(scene, grid)
    t = _tension_variation(grid, profiles, locked_n)
    for d in _DIRECTIONS:
        row[f"{d}_contacts_per_m"] = c[f"{d}_per_m"]
        row[f"{d}_entered_grains"] = e[f"{d}_grains"]
        row[f"{d}_entered_spheres"] = e[f"{d}_spheres"]
        row[f"{d}_entry_depth_max_m"] = e[f"{d}_depth_max_m"]
    row["grains_in_apertures"] = a["grains_in_apertures"]
    for d in _DIRECTIONS:
        row[f"{d}_out_of_plane_mean_m"] = w[f"out_of_plane_{d}_mean_m"]
        row[f"{d}_sideways_chord_mean_m"] = w[f"sideways_{d}_mean_m"]
        row[f"{d}_sideways_displacement_rms_m"] = sd[f"{d}_rms_m"]
        row[f"{d}_sideways_displacement_max_m"] = sd[f"{d}_max_m"]
        for k in ("now_mean", "now_min", "now_max", "spread_mean"):
            row[f"{d}_string_gap_{k.replace('now_', '')}_m"] = g[f"{d}_{k}_m"]
        sel = measured_members(grid, d)
        row[f"{d}_force_mean_n"] = _mean([profiles[m].mean() for m in sel])
        for k in ("std_along", "range_along", "std_across", "mean_above_locked"):
            row[f"{d}_tension_{k}_n"] = t[f"{d}_{k}_n"]
    fr = interfriction(scene, grid)
    gp = grid_grain_gaps(scene, grid)
    ms = member_strain(scene, grid)
    for pre, k in (("", ""), *((f"{d}_", f"{d}_") for d in _DIRECTIONS)):
        row[f"{pre}interfriction_contacts"] = fr[f"{k}contacts"]
        row[f"{pre}interfriction_mean_ratio"] = fr[f"{k}mean_ratio"]
        row[f"{pre}interfriction_sliding_fraction"] = fr[f"{k}sliding_fraction"]
    for pre in ("", *(f"{d}_" for d in _DIRECTIONS)):
        for side in ("above", "below"):
            row[f"{pre}gap_{side}_mean_m"] = gp[f"{pre}{side}_mean_m"]
            row[f"{pre}unsupported_{side}_fraction"] = gp[f"{pre}unsupported_{side}_fraction"]
    for d in _DIRECTIONS:
        row[f"{d}_mean_axial_strain"] = ms[f"{d}_mean"]
    if reference_positions is not None:
        dab = displacement_above_below(scene, reference_positions, z_grid)
        row.update(disp_above_mean_m=dab["above_mean_m"], disp_below_mean_m=dab["below_mean_m"],
                   disp_z_above_mean_m=dab["above_z_mean_m"],
                   disp_z_below_mean_m=dab["below_z_mean_m"])
    return row


def write_vtk_woven(path, scene, grid) -> Path:
    """The woven grid as a .vtp for ParaView: spheres as points (radius, kind, string,
    displacement from the built positions) and bonds as lines (tension N, parallel-bond
    sigma and tau Pa, member, the parts still intact)."""
    from cpp_dem.io.vtk import _time_field, write_vtp

    pos = np.asarray(scene.positions)[grid.spheres]
    first = int(grid.spheres[0])
    ab = np.asarray(scene.bond_spheres)[grid.bonds] - first
    st = scene.bond_state()
    t = _bond_tension(scene)[grid.bonds]
    kind = np.array([{JUNCTION: 0, LONGITUDINAL: 1, TRANSVERSE: 2}[k] for k in grid.sphere_kind])
    return write_vtp(path, pos, lines=ab,
                     point_data={"radius": np.asarray(scene.radii)[grid.spheres],
                                 "kind": kind.astype(float),
                                 "string": grid.sphere_strand.astype(float),
                                 "displacement": pos - grid.reference_positions},
                     cell_data={"tension": t,
                                "pb_sigma": st["pb_sigma"][grid.bonds],
                                "pb_tau": st["pb_tau"][grid.bonds],
                                "member": grid.bond_member.astype(float),
                                "contact_bond": np.asarray(st["contact_bond"], float)[grid.bonds],
                                "parallel_bond": np.asarray(st["parallel_bond"], float)[grid.bonds]},
                     field_data=_time_field(scene))


def plot_views(scene, grid, png, *, title: str = "") -> tuple:
    """002 Figs 3–4: the contact force network (lines between the contacting grains' centres,
    width by force) and the grid's bond tensions (colour), in plan (x-y), side (x-z) and front
    (y-z) view. Saves png and pdf; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from cpp_dem.io.figures import save_figure

    c = scene.contacts()
    ids = np.asarray(c["ids"])
    pair = ids[:, 1] >= 0 if len(ids) else np.zeros(0, bool)
    ref = measure.reference_points(scene)
    f = np.linalg.norm(c["force"], axis=1)[pair] if len(ids) else np.zeros(0)
    seg = (np.stack([ref[ids[pair, 0]], ref[ids[pair, 1]]], axis=1) if len(ids)
           else np.zeros((0, 2, 3)))
    pos = np.asarray(scene.positions)
    ab = np.asarray(scene.bond_spheres)[grid.bonds]
    gseg = np.stack([pos[ab[:, 0]], pos[ab[:, 1]]], axis=1)
    t = _bond_tension(scene)[grid.bonds]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    fmax = max(float(f.max()) if len(f) else 0.0, 1e-30)
    tmax = max(float(np.abs(t).max()), 1e-30)
    for ax, (i, j, name) in zip(axes, ((0, 1, "plan (x-y)"), (0, 2, "side (x-z)"),
                                       (1, 2, "front (y-z)"))):
        if len(seg):
            ax.add_collection(LineCollection(seg[:, :, [i, j]], linewidths=0.2 + 3 * f / fmax,
                                             colors="0.3"))
        lc = LineCollection(gseg[:, :, [i, j]], linewidths=1.5, cmap="coolwarm",
                            norm=plt.Normalize(-tmax, tmax))
        lc.set_array(t)
        ax.add_collection(lc)
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_title(name)
        ax.set_xlabel("xyz"[i] + " (m)")
        ax.set_ylabel("xyz"[j] + " (m)")
    fig.colorbar(lc, ax=axes, shrink=0.7, label="bond tension (N)")
    if title:
        fig.suptitle(title)
    out = save_figure(fig, png)
    plt.close(fig)
    return out
