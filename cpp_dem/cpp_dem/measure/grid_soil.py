"""002's soil–geogrid interaction measures for woven grids of bonded spheres (cpp_dem.build.woven).

002 §6 names three effects. Each is compared between the reinforced (RE) and the prestressed
(PRS) element.

- **Interlocking**: grains enter the apertures, and the members are pushed sideways.
  - :func:`grains_in_apertures`: grains whose centre lies over an aperture and whose body
    reaches the grid's plane.
  - :func:`member_waviness`: the in-plane ("sideways") deviation of each member's strings from
    the straight line between its ends.
- **Single-string interaction**: grains enter between the strings of a member.
  - :func:`grains_between_strings`: grains touching two strings of one member, and grain
    spheres whose centre lies in the gap between two strings.
- **Alignment**: the grid wraps around the grains.
  - :func:`grid_contacts_per_metre`: grain–geogrid contacts per metre of member.
  - :func:`member_waviness`: the out-of-plane deviation of the strings from the straight line
    between their ends.

Beside them:
- :func:`member_force_profiles`: the tensile force along every member. Its coefficient of
  variation is 002's "more uniform along prestressed members".
- :func:`displacement_above_below`: the grains' mean displacement above against below the grid.
- :func:`write_vtk_woven` and :func:`plot_views`: the contact force network and the grid's
  tensile forces, as VTK and as figures in plan, side and front view (002 Figs 3–4).

SI units. Positions and displacements are in m, forces in N.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cpp_dem import measure
from cpp_dem.build.geogrid import JUNCTION, LONGITUDINAL, TRANSVERSE


def _bond_tension(scene) -> np.ndarray:
    """Per bond: its tensile force along its axis, N (tension positive)."""
    st = scene.bond_state()
    return -np.einsum("ij,ij->i", st["force"], st["normal"])


def _strings_of_member(grid, scene, m: int) -> list[np.ndarray]:
    """The spheres of each string of member m, ordered along the member (ends included)."""
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
        out.append(ids[np.argsort(pos[ids - first, ax])])
    return out


def member_waviness(scene, grid) -> dict:
    """For each member, the RMS deviation of its strings' spheres from the straight line
    between each string's two ends, m: out of plane (z) and in plane (sideways). Returns
    per-direction means and the per-member arrays."""
    pos = np.asarray(scene.positions)
    out_of_plane = np.zeros(grid.n_members)
    sideways = np.zeros(grid.n_members)
    for m in range(grid.n_members):
        ax = int(np.argmax(np.abs(grid.member_axis[m])))
        cross = 1 - ax
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
    for d in (LONGITUDINAL, TRANSVERSE):
        sel = grid.member_direction == d
        res[f"out_of_plane_{d}_mean_m"] = float(out_of_plane[sel].mean())
        res[f"sideways_{d}_mean_m"] = float(sideways[sel].mean())
    return res


def _grid_contacts(scene, grid):
    """Active pair contacts between a grain body and a grid sphere: (grain body, grid sphere,
    |force|)."""
    c = scene.contacts()
    ids = np.asarray(c["ids"])
    if len(ids) == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    is_grid = np.zeros(scene.num_bodies, bool)
    is_grid[grid.spheres] = True
    pair = ids[:, 1] >= 0
    a, b = ids[:, 0], ids[:, 1]
    ga = pair & is_grid[a] & ~is_grid[np.where(pair, b, 0)]
    gb = pair & is_grid[np.where(pair, b, 0)] & ~is_grid[a]
    grain = np.concatenate([b[ga], a[gb]])
    sphere = np.concatenate([a[ga], b[gb]])
    f = np.linalg.norm(c["force"], axis=1)
    return grain, sphere, np.concatenate([f[ga], f[gb]])


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


def member_lengths(grid) -> dict:
    """Total clear length of the members of each direction, m (between junctions)."""
    return {d: float(np.sum(grid.member_direction == d)) * (grid.pitch[0 if d == LONGITUDINAL
                                                                    else 1] - grid.member_width)
            for d in (LONGITUDINAL, TRANSVERSE)}


def grid_contacts_per_metre(scene, grid) -> dict:
    """Grain–geogrid contacts per metre of member (alignment), by member direction, and the
    number of distinct grains touching the grid."""
    grain, sphere, _ = _grid_contacts(scene, grid)
    first = int(grid.spheres[0])
    sm = _sphere_member(scene, grid)
    member = sm[sphere - first]
    lengths = member_lengths(grid)
    g_of_b, _ = measure.grain_of_body(scene)
    res = {"contacts": int(len(grain)), "grains_touching": int(len(np.unique(g_of_b[grain]))),
           "junction_contacts": int(np.sum(member < 0))}
    for d in (LONGITUDINAL, TRANSVERSE):
        on = (member >= 0) & (grid.member_direction[np.maximum(member, 0)] == d)
        res[f"{d}_per_m"] = float(np.sum(on) / lengths[d])
    return res


def grains_between_strings(scene, grid, *, z_grid: float | None = None) -> dict:
    """Single-string interaction: grains touching two or more strings of one member, and
    grain spheres whose centre lies between two strings of a member (in the member's span,
    within a grain radius of the grid's plane)."""
    grain, sphere, _ = _grid_contacts(scene, grid)
    first = int(grid.spheres[0])
    sm = _sphere_member(scene, grid)
    strand = grid.sphere_strand
    g_of_b, _ = measure.grain_of_body(scene)
    touching: dict[tuple, set] = {}
    for gb, s in zip(g_of_b[grain], sphere - first):
        if sm[s] >= 0:
            touching.setdefault((int(gb), int(sm[s])), set()).add(int(strand[s]))
    two = {g for (g, m), ss in touching.items() if len(ss) >= 2}
    # Geometry: centres in the gaps between adjacent strings.
    pos = np.asarray(scene.positions)
    rad = np.asarray(scene.radii)
    gmask = measure.sphere_mask(scene)
    zg = float(np.mean(pos[grid.spheres, 2])) if z_grid is None else z_grid
    near = gmask & (np.abs(pos[:, 2] - zg) < rad)
    inside = 0
    grains_inside = set()
    for m in range(grid.n_members):
        strings = _strings_of_member(grid, scene, m)
        if len(strings) < 2:
            continue
        ax = int(np.argmax(np.abs(grid.member_axis[m])))
        cross = 1 - ax
        lo_ax = max(pos[s[0], ax] for s in strings)
        hi_ax = min(pos[s[-1], ax] for s in strings)
        cs = sorted(float(np.mean(pos[s, cross])) for s in strings)
        x = pos[:, ax]
        y = pos[:, cross]
        for c0, c1 in zip(cs[:-1], cs[1:]):
            sel = near & (x > lo_ax) & (x < hi_ax) & (y > c0) & (y < c1)
            inside += int(np.sum(sel))
            grains_inside.update(int(g) for g in g_of_b[sel])
    return {"grains_touching_two_strings": len(two), "grain_spheres_between_strings": inside,
            "grains_between_strings": len(grains_inside)}


def grains_in_apertures(scene, grid, *, z_grid: float | None = None) -> dict:
    """Interlocking: grains whose reference point (centre, or clump centre of mass) lies over
    an aperture and whose spheres reach the grid's plane; the count and per aperture."""
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
    o = np.asarray(grid.reference_positions)[0, :2]  # a corner junction sphere
    x0 = np.min(np.asarray(grid.reference_positions)[:, 0])
    y0 = np.min(np.asarray(grid.reference_positions)[:, 1])
    del o
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


def member_force_profiles(scene, grid) -> dict:
    """The tensile force along each member, N: at every position along it, the sum of its
    strings' bond tensions. Returns the profiles and, per direction, the mean coefficient of
    variation along the members (std / |mean|) and the mean force."""
    tension = _bond_tension(scene)
    ab = np.asarray(scene.bond_spheres)
    pos = np.asarray(grid.reference_positions)
    first = int(grid.spheres[0])
    profiles = []
    cov = np.zeros(grid.n_members)
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
        prof = prof[n_str == n_str.max()]  # positions crossed by every string
        profiles.append(prof)
        cov[m] = float(np.std(prof) / max(abs(np.mean(prof)), 1e-12))
    res = {"profiles_n": profiles, "cov": cov}
    for d in (LONGITUDINAL, TRANSVERSE):
        sel = grid.member_direction == d
        res[f"{d}_cov_mean"] = float(cov[sel].mean())
        res[f"{d}_force_mean_n"] = float(np.mean([profiles[m].mean() for m in np.flatnonzero(sel)]))
    return res


def displacement_above_below(scene, reference_positions, z_grid: float) -> dict:
    """Mean displacement magnitude and mean vertical displacement of the grain bodies whose
    reference position is above against below the grid's plane, m."""
    pos = np.asarray(scene.positions)
    ref = np.asarray(reference_positions)
    g = measure.sphere_mask(scene)
    d = pos - ref
    above, below = g & (ref[:, 2] > z_grid), g & (ref[:, 2] < z_grid)
    return {"above_mean_m": float(np.linalg.norm(d[above], axis=1).mean()),
            "below_mean_m": float(np.linalg.norm(d[below], axis=1).mean()),
            "above_z_mean_m": float(d[above, 2].mean()),
            "below_z_mean_m": float(d[below, 2].mean())}


def summary(scene, grid, *, z_grid: float, reference_positions=None) -> dict:
    """All the measures above as plain numbers (the per-member arrays left out)."""
    w = member_waviness(scene, grid)
    f = member_force_profiles(scene, grid)
    out = {"contacts": grid_contacts_per_metre(scene, grid),
           "between_strings": grains_between_strings(scene, grid, z_grid=z_grid),
           "apertures": grains_in_apertures(scene, grid, z_grid=z_grid),
           "waviness": {k: v for k, v in w.items() if k.endswith("_m") and "mean" in k},
           "force": {k: v for k, v in f.items() if k.endswith(("_mean", "_n"))
                     and not isinstance(v, list)}}
    if reference_positions is not None:
        out["displacement"] = displacement_above_below(scene, reference_positions, z_grid)
    return out


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
