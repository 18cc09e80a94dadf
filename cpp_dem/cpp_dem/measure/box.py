"""Measurements on a confined sample: wall stresses, Love–Weber average stress, porosity,
coordination number, unbalanced force, energies; and on a deposited packing (from its
arrays): the solid volume in a horizontal slab, the interior porosity, the free-surface
height. SI units; stresses compressive positive.

``walls`` is always the list of the six box walls in the order of ``Scene.add_box``
(x-, x+, y-, y+, z-, z+). In a periodic cell (``Scene.set_periodic_cell``) pass no walls
(``()``): the box is then the cell, and the "wall" stresses are the cell's normal stresses
(Love–Weber over the cell, ``Scene.cell_stress``), so the preparation stages of ``prep`` run
unchanged in a cell.
"""

from __future__ import annotations

import math

import numpy as np

from cpp_dem import _core, fixedorder


def _cell(scene, walls) -> bool:
    """True when the measures are of the periodic cell (no walls given, a periodic scene)."""
    if len(walls):
        return False
    if not scene.is_periodic:
        raise _core.ParameterError("walls=(): no walls given and the scene has no periodic "
                                   "cell; pass the six box walls (Scene.add_box)")
    return True


def box_size(scene, walls) -> np.ndarray:
    """Current box dimensions (x, y, z) from the wall positions, m; in a periodic cell the
    cell's thicknesses across its faces (its edge lengths when it is a box)."""
    if _cell(scene, walls):
        h = np.asarray(scene.cell_matrix)
        v = abs(np.linalg.det(h))
        return np.array([v / np.linalg.norm(np.cross(h[:, (a + 1) % 3], h[:, (a + 2) % 3]))
                         for a in range(3)])
    return np.asarray(_core.TriaxialController.box_size(scene, list(walls)))


def box_volume(scene, walls) -> float:
    """Current box (or periodic cell) volume, m^3."""
    if _cell(scene, walls):
        return float(scene.cell_volume)
    return float(np.prod(box_size(scene, walls)))


def wall_stresses(scene, walls) -> np.ndarray:
    """Normal stress on each of the six walls, Pa (compressive positive): force the spheres
    exert on the wall (last step) over the current face area. In a periodic cell: the cell's
    normal stresses, each twice (x, x, y, y, z, z)."""
    if _cell(scene, walls):
        return np.repeat(np.diag(np.asarray(scene.cell_stress())), 2)
    return np.asarray(_core.TriaxialController.wall_stresses(scene, list(walls)))


def axis_stresses(scene, walls) -> np.ndarray:
    """Per-axis boundary stress (mean of the two opposite walls), Pa, shape (3,); in a
    periodic cell the diagonal of the cell stress."""
    if _cell(scene, walls):
        return np.diag(np.asarray(scene.cell_stress())).copy()
    return np.asarray(_core.TriaxialController.axis_stresses(scene, list(walls)))


def sphere_mask(scene) -> np.ndarray:
    """True for the bodies that are grains (spheres), (n,). False for geogrid nodes and for
    bonded spheres: the spheres of a bonded structure (a woven geogrid, cpp_dem.build.woven) are
    not grains."""
    m = np.asarray(scene.body_kinds) == 0
    if scene.num_bonds:
        m[np.asarray(scene.bond_spheres).ravel()] = False
    return m


def grain_of_body(scene) -> tuple[np.ndarray, int]:
    """Per body, the index of the grain it belongs to, and the number of grains: a free
    sphere is a grain, a clump (all its members) is one grain; geogrid nodes get -1."""
    n = int(scene.num_bodies)
    sph = sphere_mask(scene)
    cl = np.asarray(scene.clump_ids) if scene.num_clumps else np.full(n, -1)
    free = sph & (cl < 0)
    g = np.full(n, -1)
    g[free] = np.arange(int(free.sum()))
    nfree = int(free.sum())
    g[cl >= 0] = nfree + cl[cl >= 0]
    return g, nfree + int(scene.num_clumps)


def reference_points(scene) -> np.ndarray:
    """Per body, the point that stands for its grain, m (n, 3): a free sphere's centre, a
    clump member's clump centre of mass (the branch vectors of Love–Weber join these)."""
    pos = np.asarray(scene.positions).copy()
    if scene.num_clumps:
        cl = np.asarray(scene.clump_ids)
        m = cl >= 0
        pos[m] = np.asarray(scene.clump_positions)[cl[m]]
    return pos


def _free_radii_and_clump_volumes(scene) -> tuple[np.ndarray, np.ndarray]:
    """Radii of the free spheres (m, by id; no geogrid nodes) and the volume of each clump's
    union of members (m^3: its mass over its members' density)."""
    sph = sphere_mask(scene)
    r = np.asarray(scene.radii)
    if not scene.num_clumps:
        return r[sph], np.zeros(0)
    cl = np.asarray(scene.clump_ids)
    mats = np.asarray(scene.material_ids)
    first = np.array([scene.clump_members(c)[0] for c in range(scene.num_clumps)])
    rho = np.array([scene.material(int(m)).density for m in mats[first]])
    return r[sph & (cl < 0)], np.asarray(scene.clump_masses) / rho


def grain_diameters(scene) -> np.ndarray:
    """Equivalent-volume diameters of the grains, m: free spheres 2 r, clumps (6 V / pi)^(1/3)
    with V the union's volume (order: the free spheres by id, then the clumps)."""
    r, v = _free_radii_and_clump_volumes(scene)
    return np.concatenate([2.0 * r, fixedorder.powers(6.0 * v / np.pi, 1.0 / 3.0)])


def solid_volume(scene) -> float:
    """Volume of the grains, m^3: free spheres 4/3 pi r^3 (overlaps between grains counted
    twice; see porosity), clumps the volume of the union of their members (mass / density:
    overlaps inside a clump count once). Geogrid nodes are not grains and are left out."""
    r, v = _free_radii_and_clump_volumes(scene)
    return float(np.sum(4.0 / 3.0 * np.pi * fixedorder.powers(r, 3))) + float(np.sum(v))


def porosity(scene, walls) -> float:
    """Porosity n = 1 - sum(4/3 pi r^3) / V_box, -.

    Approximation: the sphere volumes are summed whole, so the lens-shaped overlaps between
    spheres and the caps that cross a wall plane are counted as solid (twice for a
    sphere–sphere lens). The error is of order (overlap / radius) times the solid fraction:
    at 75 kPa with E = 4.5 MPa grains (overlaps ~1 % of the radius) it is a few 1e-3.
    """
    return 1.0 - solid_volume(scene) / box_volume(scene, walls)


def void_ratio(scene, walls) -> float:
    """Void ratio e = n / (1 - n), -."""
    n = porosity(scene, walls)
    return n / (1.0 - n)


def love_weber_stress(scene, volume: float) -> np.ndarray:
    """Average stress tensor of the assembly (Love–Weber), Pa, compressive positive, (3, 3):

        sigma = (1/V) [ sum_pairs f_c (x) l_c + sum_wall-contacts f_c (x) (x_p - x_c) ]

    with f_c the force on the second sphere of a pair, l_c = x_j - x_i the branch vector, and
    for a sphere–wall contact f_c the force on the sphere and x_p - x_c the vector from the
    contact point (on the wall plane) to the sphere's centre. For clumps the branch vectors
    join the clumps' centres of mass (exact for rigid grains in equilibrium; see
    reference_points). V is the volume the stress is averaged over (m^3):
    the box volume for a confined sample. For a sample in equilibrium it equals the average
    boundary traction; the tensor is symmetrised.
    """
    if not volume > 0:
        raise _core.ParameterError(f"volume={volume}: must be > 0 (m^3)")
    s = _love_weber_terms(scene).sum(axis=0) / volume
    return 0.5 * (s + s.T)


def _love_weber_terms(scene) -> np.ndarray:
    """Each contact's term f_c (x) l_c of ``love_weber_stress`` (m, 3, 3), N m, in the scene's
    contact order (the sum is taken in that fixed order)."""
    c = scene.contacts()
    ids, f, nrm, ov = c["ids"], c["force"], c["normal"], c["overlap"]
    pos = reference_points(scene)
    r = np.asarray(scene.radii)
    pair = ids[:, 1] >= 0
    terms = np.zeros((len(ids), 3, 3))
    if pair.any():
        # (In a periodic cell the branch runs to j's image: the contacts' own branch vectors.)
        l = (c["branch"][pair] if scene.is_periodic
             else pos[ids[pair, 1]] - pos[ids[pair, 0]])
        terms[pair] = np.einsum("ki,kj->kij", f[pair], l)
    wl = ~pair
    if wl.any():
        b = ids[wl, 0]
        # The wall is rigid: the contact point is on the wall plane, x_p - (r - delta) n
        # (n: the wall normal, towards the sphere), so the boundary term is exactly the
        # wall force times the wall-to-wall distance.
        arm = (r[b] - ov[wl])[:, None] * nrm[wl]
        if scene.num_clumps:
            arm += pos[b] - np.asarray(scene.positions)[b]  # member centre -> clump centre
        terms[wl] = np.einsum("ki,kj->kij", f[wl], arm)
    return terms


def stress_scatter(scene, volume: float, *, n_boot: int = 64, seed: int = 0) -> np.ndarray:
    """The scatter of the Love–Weber stress of a sample, Pa (3 x 3, symmetric): the standard
    deviation over ``n_boot`` bootstrap resamplings (with replacement, seeded) of its
    contacts' terms. It says how far the stress of a sample of this size is from the mean of
    samples like it (about the stress times the contact terms' coefficient of variation over
    sqrt(contacts)): the noise floor of a coupled loop (``femcoupling``). For a sample in
    equilibrium between walls the wall contacts are resampled too."""
    if int(n_boot) < 2:
        raise _core.ParameterError(f"n_boot={n_boot}: must be >= 2")
    if not volume > 0:
        raise _core.ParameterError(f"volume={volume}: must be > 0 (m^3)")
    t = _love_weber_terms(scene) / volume
    m = len(t)
    if m == 0:
        return np.zeros((3, 3))
    t = 0.5 * (t + t.transpose(0, 2, 1))
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, m, size=(int(n_boot), m))
    reps = np.array([t[p].sum(axis=0) for p in picks])
    return reps.std(axis=0, ddof=1)


def coordination_number(scene, *, mechanical: bool = False) -> float:
    """Mean number of grain–grain contacts per grain, -: 2 C / N (a clump is one grain; each
    member–member contact between two clumps counts, as in Yade and PFC).

    With ``mechanical``, rattlers are left out (Thornton's mechanical coordination number):
    grains with fewer than 2 contacts (walls included) are removed repeatedly, then
    Z = 2 C' / N' over the remaining grains and their grain–grain contacts.
    """
    c = scene.contacts()
    ids = c["ids"]
    g, n_grains = grain_of_body(scene)
    if n_grains == 0:
        return float("nan")
    pair = ids[:, 1] >= 0
    pi, pj = g[ids[pair, 0]], g[ids[pair, 1]]
    ok = (pi >= 0) & (pj >= 0)
    pi, pj = pi[ok], pj[ok]
    if not mechanical:
        return 2.0 * len(pi) / n_grains
    wb = g[ids[~pair, 0]]
    wall_count = np.bincount(wb[wb >= 0], minlength=n_grains)
    alive = np.ones(n_grains, dtype=bool)
    while True:
        keep = alive[pi] & alive[pj]
        cnt = (np.bincount(pi[keep], minlength=n_grains) +
               np.bincount(pj[keep], minlength=n_grains) + wall_count)
        drop = alive & (cnt < 2)
        if not drop.any():
            break
        alive &= ~drop
    keep = alive[pi] & alive[pj]
    m = int(alive.sum())
    return 2.0 * int(keep.sum()) / m if m else 0.0


def sample_state(scene, walls) -> dict:
    """The usual numbers of a confined sample, by key: ``wall_stresses`` (6, Pa),
    ``axis_stresses`` (3, Pa), ``mean_stress`` (p, Pa), ``deviator_stress``
    (q = sigma_z - (sigma_x + sigma_y) / 2, Pa), ``love_weber`` (3 x 3, Pa), ``porosity`` (-),
    ``coordination`` and ``coordination_mechanical`` (-), ``unbalanced_force`` (-),
    ``box_size`` (3, m). Stresses compression positive."""
    ax = axis_stresses(scene, walls)
    vol = box_volume(scene, walls)
    return {
        "wall_stresses": wall_stresses(scene, walls),
        "axis_stresses": ax,
        "mean_stress": float(ax.mean()),
        "deviator_stress": float(ax[2] - 0.5 * (ax[0] + ax[1])),
        "love_weber": love_weber_stress(scene, vol),
        "porosity": porosity(scene, walls),
        "coordination": coordination_number(scene),
        "coordination_mechanical": coordination_number(scene, mechanical=True),
        "unbalanced_force": float(scene.unbalanced_force()),
        "box_size": box_size(scene, walls),
    }


# ---- a deposited packing, from its arrays (centres pos (n, 3), m; radii (n,), m) ---------------

def slab_solid_volume(z: np.ndarray, r: np.ndarray, z0: float, z1: float) -> float:
    """Exact volume (m^3) of the spheres (centres z, radii r) inside the slab z0 <= z <= z1:
    the integral of pi (r^2 - (s - z)^2) ds over the part of [z - r, z + r] in the slab."""
    a = np.clip(z0 - z, -r, r)
    b = np.clip(z1 - z, -r, r)
    # integral of pi (r^2 - u^2) du from a to b
    return float(np.sum(np.pi * (r**2 * (b - a)
                                 - (fixedorder.powers(b, 3) - fixedorder.powers(a, 3)) / 3.0)))


def interior_porosity(pos: np.ndarray, radii: np.ndarray, box, inset: float,
                      z_top: float) -> float:
    """Porosity estimate away from the walls, -: the region inset by ``inset`` (m) from the
    side walls and the floor, up to ``z_top`` (m); solid volume = the volumes of the spheres
    whose centres lie in it (unbiased up to boundary noise of order inset / region size)."""
    lo = np.array([inset, inset, inset])
    hi = np.array([box[0] - inset, box[1] - inset, z_top])
    if np.any(hi - lo < 2 * inset):  # too thin for a meaningful count
        return float("nan")
    inside = np.all((pos >= lo) & (pos < hi), axis=1)
    solid = float(np.sum(4.0 / 3.0 * np.pi * fixedorder.powers(radii[inside], 3)))
    return 1.0 - solid / float(np.prod(hi - lo))


def surface_height(pos: np.ndarray, radii: np.ndarray, box, cells: int = 5) -> float:
    """Mean height of the free surface, m: the box footprint is cut into cells x cells
    columns; in each, the highest sphere top z + r; the mean over the columns."""
    ix = np.clip((pos[:, 0] / box[0] * cells).astype(int), 0, cells - 1)
    iy = np.clip((pos[:, 1] / box[1] * cells).astype(int), 0, cells - 1)
    top = np.full((cells, cells), np.nan)
    for i, j, h in zip(ix, iy, pos[:, 2] + radii):
        if not h <= top[i, j]:
            top[i, j] = h
    return float(np.nanmean(top))


__all__ = ["axis_stresses","box_size","box_volume","coordination_number","grain_diameters","grain_of_body","interior_porosity","love_weber_stress","porosity","reference_points","sample_state","slab_solid_volume","solid_volume","sphere_mask","stress_scatter","surface_height","void_ratio","wall_stresses"]
