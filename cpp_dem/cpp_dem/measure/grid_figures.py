"""Paper figures of the reinforced (RE) against the prestressed (PRS) element (002 Figs 3–4).

Each element may run in its own process, so the figures are drawn afterwards from saved data:

1. :func:`figure_data` takes what the figures need from a scene and its woven grid
   (cpp_dem.build.woven) as plain arrays. :func:`save_figure_data` and :func:`load_figure_data`
   keep it in an .npz file.
2. The figures take ``datas``, a dict from the element's name ("RE", "PRS", ...) to such data
   (or to the path of its .npz file). Every figure shares its scales over all elements:
   - :func:`plot_views` (002 Fig. 3): the contact force network and the grid's bond tensions in
     plan (x-y), side (x-z) and front (y-z) view, one row per element;
   - :func:`plot_grid_deformed` (002 Fig. 4): the grid alone, its displacement from the built
     positions magnified, in plan and in 3D;
   - :func:`plot_contact_rose`: roses of the contact normals weighted by force, in the planes
     x-z, y-z and x-y, with the main directions of load transfer
     (:func:`principal_directions`; 002 §5's "two main directions ... inclined with regard to
     the longitudinal and transverse members"; :func:`main_directions` adds whether they
     stand out of an isotropic fabric's noise).
   :func:`draw_all` draws all three.

Every figure is saved as a 300 dpi PNG and a PDF (cpp_dem.io.figures.save_figure).
:func:`label_overlaps` lists the texts of a drawn figure that collide with another panel.

SI units: positions in m (the figures' axes in mm), forces in N, angles in degrees.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cpp_dem.build.geogrid import LONGITUDINAL, TRANSVERSE

#: Per bond, the code of its member's direction in the data ("bond_direction").
DIRECTION_CODES = {"junction": 0, LONGITUDINAL: 1, TRANSVERSE: 2}

#: The planes of the roses and of :func:`principal_directions`: the axes (first, second); an
#: angle is measured from the first axis towards the second.
PLANES = {"xz": (0, 2), "yz": (1, 2), "xy": (0, 1)}

_PLANE_LABEL = {"xz": "x-z", "yz": "y-z", "xy": "x-y (plan)"}
_VIEWS = ((0, 1, "plan (x-y)"), (0, 2, "side (x-z)"), (1, 2, "front (y-z)"))
_LW_MIN, _LW_MAX = 0.15, 2.5  # contact line widths, pt, at zero force and at the force scale
_MM = 1e3


# ---------------------------------------------------------------------------------------------
# Data
# ---------------------------------------------------------------------------------------------

def _box_bounds(scene, walls) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the box of six walls (x-, x+, y-, y+, z-, z+), m; NaN when there is none.
    ``walls`` None: the scene's walls if they are exactly one box."""
    nan = np.full(3, np.nan)
    if walls is None:
        if scene.num_walls != 6:
            return nan, nan.copy()
        walls = list(range(6))
    walls = list(walls)
    if len(walls) != 6:
        return nan, nan.copy()
    pos = np.asarray(scene.wall_positions, float)[walls]
    axes = np.asarray(scene.wall_axes)[walls]
    if list(axes) != [0, 0, 1, 1, 2, 2]:
        return nan, nan.copy()
    return pos[0::2].copy(), pos[1::2].copy()


def figure_data(scene, grid, *, reference_positions=None, walls=None) -> dict[str, np.ndarray]:
    """What the figures need, as plain arrays (SI).

    scene, grid : a scene and its woven grid (cpp_dem.build.woven.WovenGeogrid).
    reference_positions : the grid's positions to measure its displacement from, m: (n_grid, 3)
        for the grid's spheres, or (num_bodies, 3) for all bodies (the grid's rows are taken);
        None is the grid as built (grid.reference_positions).
    walls : the six box walls (x-, x+, y-, y+, z-, z+) for the box bounds; None takes the
        scene's walls if they are exactly one box. Without a box the bounds are NaN.

    Keys (n grain–grain contacts, k grain–grid contacts, b bonds, s grid spheres):
    - grain_segments (n, 2, 3), grain_force_n (n,), grain_normal (n, 3): grain–grain contacts,
      each a segment between the two bodies' reference points (cpp_dem.measure.reference_points:
      a sphere's centre, a clump's centre of mass), |force| N, unit contact normal;
    - grid_contact_segments (k, 2, 3), grid_contact_force_n (k,), grid_contact_normal (k, 3):
      grain–grid contacts, from the grain's reference point to the grid sphere's centre;
    - bond_segments (b, 2, 3): the grid's bonds between its spheres' current centres;
      bond_spheres (b, 2): the bonds' spheres as indices into the grid's spheres;
      bond_tension_n (b,): tension positive, N; bond_member (b,): member index, -1 inside a
      junction; bond_direction (b,): DIRECTION_CODES of the bond's member;
    - grid_positions (s, 3), grid_reference_positions (s, 3), grid_radii (s,): m;
    - pitch (2,), member_width (): m; box_lo (3,), box_hi (3,): m (NaN without a box);
    - time (): the scene's time, s.
    """
    from cpp_dem import measure
    from cpp_dem.measure.grid_soil import _bond_tension

    pos = np.asarray(scene.positions, float)
    gids = np.asarray(grid.spheres, int)
    first = int(gids[0])
    gpos = pos[gids]
    if reference_positions is None:
        gref = np.asarray(grid.reference_positions, float)
    else:
        r = np.asarray(reference_positions, float)
        gref = r[gids] if len(r) == scene.num_bodies and len(r) != len(gids) else r
        if gref.shape != gpos.shape:
            raise ValueError(f"reference_positions: shape {r.shape}, expected ({len(gids)}, 3) "
                             f"or ({scene.num_bodies}, 3)")
        gref = gref.copy()

    # Contacts.
    c = scene.contacts()
    ids = np.asarray(c["ids"], int).reshape(-1, 2)
    force = np.linalg.norm(np.asarray(c["force"], float).reshape(-1, 3), axis=1)
    normal = np.asarray(c["normal"], float).reshape(-1, 3)
    ref = measure.reference_points(scene)
    is_grid = np.zeros(scene.num_bodies, bool)
    is_grid[gids] = True
    a, b = ids[:, 0], ids[:, 1]
    pair = b >= 0
    bb = np.where(pair, b, 0)
    grain_grain = pair & ~is_grid[a] & ~is_grid[bb]
    ga = pair & is_grid[a] & ~is_grid[bb]   # a the grid sphere
    gb = pair & ~is_grid[a] & is_grid[bb]   # b the grid sphere
    grain = np.concatenate([b[ga], a[gb]])
    sphere = np.concatenate([a[ga], b[gb]])

    # Bonds.
    ab = np.asarray(scene.bond_spheres, int)[np.asarray(grid.bonds, int)] - first
    tension = _bond_tension(scene)[np.asarray(grid.bonds, int)]
    member = np.asarray(grid.bond_member, int)
    mdir = np.asarray(grid.member_direction)
    direction = np.array([0 if m < 0 else DIRECTION_CODES[str(mdir[m])] for m in member],
                         dtype=np.int64)
    lo, hi = _box_bounds(scene, walls)
    return {
        "grain_segments": np.stack([ref[a[grain_grain]], ref[b[grain_grain]]], axis=1)
        .reshape(-1, 2, 3),
        "grain_force_n": force[grain_grain],
        "grain_normal": normal[grain_grain],
        "grid_contact_segments": np.stack([ref[grain], pos[sphere]], axis=1).reshape(-1, 2, 3),
        "grid_contact_force_n": np.concatenate([force[ga], force[gb]]),
        "grid_contact_normal": np.concatenate([normal[ga], normal[gb]]).reshape(-1, 3),
        "bond_segments": np.stack([gpos[ab[:, 0]], gpos[ab[:, 1]]], axis=1),
        "bond_spheres": ab.astype(np.int64),
        "bond_tension_n": np.asarray(tension, float),
        "bond_member": member.astype(np.int64),
        "bond_direction": direction,
        "grid_positions": gpos,
        "grid_reference_positions": gref,
        "grid_radii": np.asarray(scene.radii, float)[gids],
        "pitch": np.asarray(grid.pitch, float),
        "member_width": np.asarray(float(grid.member_width)),
        "box_lo": lo,
        "box_hi": hi,
        "time": np.asarray(float(scene.time)),
    }


def save_figure_data(path, data: dict) -> Path:
    """Saves figure data (:func:`figure_data`) as an .npz file; returns its path."""
    p = Path(path)
    if p.suffix != ".npz":
        p = p.with_name(p.name + ".npz")
    p.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(p, **{k: np.asarray(v) for k, v in data.items()})
    return p


def load_figure_data(path) -> dict[str, np.ndarray]:
    """The figure data saved by :func:`save_figure_data`."""
    with np.load(Path(path), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _as_datas(datas) -> dict[str, dict]:
    """``datas`` with the paths among its values loaded."""
    out = {}
    for name, d in datas.items():
        out[str(name)] = load_figure_data(d) if isinstance(d, (str, Path)) else d
    if not out:
        raise ValueError("datas: no element given")
    return out


# ---------------------------------------------------------------------------------------------
# Shared scales and helpers
# ---------------------------------------------------------------------------------------------

def _round_sig(x: float, sig: int = 2) -> float:
    if x <= 0 or not math.isfinite(x):
        return 0.0
    return round(x, sig - 1 - int(math.floor(math.log10(x))))


def tension_limit(datas) -> float:
    """The shared colour limit of the bond tension, N: the largest |tension| of all elements."""
    datas = _as_datas(datas)
    return max(float(np.max(np.abs(d["bond_tension_n"]), initial=0.0)) for d in datas.values())


def force_scale(datas) -> float:
    """The shared line-width scale of the contact forces, N: the largest contact force
    (grain–grain and grain–grid) of all elements."""
    datas = _as_datas(datas)
    return max(max(float(np.max(d["grain_force_n"], initial=0.0)),
                   float(np.max(d["grid_contact_force_n"], initial=0.0)))
               for d in datas.values())


def _line_width(f, scale: float) -> np.ndarray:
    return _LW_MIN + (_LW_MAX - _LW_MIN) * np.asarray(f, float) / max(scale, 1e-300)


def _extent(datas, *, reference=False) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) over all elements, m: the box if every element has one, else the data."""
    los, his = [], []
    for d in datas.values():
        if np.all(np.isfinite(d["box_lo"])) and np.all(np.isfinite(d["box_hi"])):
            los.append(d["box_lo"])
            his.append(d["box_hi"])
            continue
        pts = [d["bond_segments"].reshape(-1, 3), d["grain_segments"].reshape(-1, 3),
               d["grid_contact_segments"].reshape(-1, 3)]
        if reference:
            pts.append(d["grid_reference_positions"])
        p = np.concatenate(pts)
        r = float(np.max(d["grid_radii"], initial=0.0))
        los.append(p.min(axis=0) - r)
        his.append(p.max(axis=0) + r)
    return np.min(los, axis=0), np.max(his, axis=0)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _drawn_tick_labels(axis) -> list:
    """The tick labels of ``axis`` that are drawn (inside the view limits, switched on)."""
    try:
        ticks = axis._update_ticks()  # the ticks that are drawn (private, matplotlib >= 3.1)
    except AttributeError:
        lo, hi = sorted(axis.get_view_interval())
        ticks = [t for t in axis.get_major_ticks() if lo <= t.get_loc() <= hi]
    out = []
    for t in ticks:
        for lab in (t.label1, t.label2):
            if lab.get_visible() and lab.get_text().strip():
                out.append(lab)
    return out


def label_overlaps(fig, *, pad_px: float = 0.5) -> list[tuple[str, str]]:
    """Draws ``fig`` and returns the pairs of texts that overlap between different panels:
    each panel's title, axis labels and tick labels against the other panels' texts and
    frames, and the figure's legends and suptitle against all. Empty: no collision."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    items = []  # (owner, description, bbox)

    def add(owner, what, artist):
        if artist is None or not artist.get_visible():
            return
        if hasattr(artist, "get_text") and not artist.get_text().strip():
            return
        bb = artist.get_window_extent(renderer)
        if bb.width > 0 and bb.height > 0:
            items.append((owner, what, bb.expanded(1, 1).padded(-pad_px)))

    frames = []
    for k, ax in enumerate(fig.axes):
        name = f"axes {k} ({ax.get_title() or ax.get_label()})"
        add(k, f"{name} title", ax.title)
        add(k, f"{name} x label", ax.xaxis.label)
        add(k, f"{name} y label", ax.yaxis.label)
        for axis in (ax.xaxis, ax.yaxis):
            for t in _drawn_tick_labels(axis):
                add(k, f"{name} tick label {t.get_text()!r}", t)
        frames.append((k, f"{name} frame", ax.get_window_extent(renderer).padded(-pad_px)))
    for n, lg in enumerate(fig.legends):
        items.append((f"legend {n}", f"legend {n}", lg.get_window_extent(renderer)))
    if getattr(fig, "_suptitle", None) is not None:
        add("suptitle", "suptitle", fig._suptitle)
    out = []
    for i, (oa, wa, ba) in enumerate(items):
        for ob, wb, bb in items[i + 1:] + frames:
            if oa != ob and ba.overlaps(bb):
                out.append((wa, wb))
    return out


def _save(fig, png) -> list[Path]:
    from cpp_dem.io.figures import save_figure

    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    return list(save_figure(fig, png))


def _tension_mappable(limit: float):
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    sm = ScalarMappable(norm=Normalize(-limit, limit), cmap="coolwarm")
    sm.set_array([])
    return sm


# ---------------------------------------------------------------------------------------------
# 002 Fig. 3: the views
# ---------------------------------------------------------------------------------------------

def _views_figure(datas, *, title: str = ""):
    plt = _pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

    datas = _as_datas(datas)
    tlim = max(tension_limit(datas), 1e-30)
    fscale = force_scale(datas)
    lo, hi = _extent(datas)
    span = hi - lo
    # Panel widths in proportion to the views' horizontal extents, so that all share one
    # length scale per row.
    widths = [span[0], span[0], span[1]]
    n = len(datas)
    height = max(span[1], span[2])
    fig = plt.figure(figsize=(13.0, 0.9 + n * max(2.6, 10.0 * height / sum(widths) * 1.15)),
                     layout="constrained")
    axes = np.atleast_2d(fig.subplots(n, 3, width_ratios=widths, squeeze=False))
    sm = _tension_mappable(tlim)
    for r, (name, d) in enumerate(datas.items()):
        for cidx, (i, j, view) in enumerate(_VIEWS):
            ax = axes[r, cidx]
            gs, gf = d["grain_segments"], d["grain_force_n"]
            if len(gs):
                ax.add_collection(LineCollection(gs[:, :, [i, j]] * _MM,
                                                 linewidths=_line_width(gf, fscale),
                                                 colors="0.55", zorder=1))
            cs, cf = d["grid_contact_segments"], d["grid_contact_force_n"]
            if len(cs):
                ax.add_collection(LineCollection(cs[:, :, [i, j]] * _MM,
                                                 linewidths=_line_width(cf, fscale),
                                                 colors="tab:green", zorder=2))
            bs = d["bond_segments"][:, :, [i, j]] * _MM
            ax.add_collection(LineCollection(bs, linewidths=1.5, colors="0.25", zorder=3))
            lc = LineCollection(bs, linewidths=1.1, cmap=sm.cmap, norm=sm.norm, zorder=4)
            lc.set_array(d["bond_tension_n"])
            ax.add_collection(lc)
            ax.set_xlim(lo[i] * _MM, hi[i] * _MM)
            ax.set_ylim(lo[j] * _MM, hi[j] * _MM)
            ax.set_aspect("equal", adjustable="box")
            ax.set_title(f"{name}: {view}", fontsize=10)
            ax.set_xlabel(f"{'xyz'[i]} (mm)")
            ax.set_ylabel(f"{'xyz'[j]} (mm)")
            ax.tick_params(labelsize=8)
            ax.locator_params(nbins=5)
    fig.colorbar(sm, ax=axes, shrink=0.8, label="bond tension (N)")
    refs = sorted({_round_sig(fscale * q) for q in (0.25, 0.5, 1.0)} - {0.0})
    handles = [Line2D([], [], color="0.55", lw=float(_line_width(f, fscale)),
                      label=f"{f:g} N") for f in refs]
    handles += [Line2D([], [], color="0.55", lw=1.5, label="grain–grain contact"),
                Line2D([], [], color="tab:green", lw=1.5, label="grain–grid contact"),
                Line2D([], [], color="k", lw=1.5, label="geogrid bond (colour: tension)")]
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8,
               frameon=False, title="contact force (line width)", title_fontsize=8)
    if title:
        fig.suptitle(title)
    return fig, {"tension_limit_n": float(tlim), "force_scale_n": float(fscale),
                 "reference_forces_n": refs}


def plot_views(datas: dict, png, *, title: str = "") -> dict:
    """002 Fig. 3 for every element: one row per element ("RE", "PRS", ...), columns plan
    (x-y), side (x-z) and front (y-z) view. The contact forces are lines between the bodies'
    reference points (grain–grain grey, grain–grid green), their width by force on one scale
    for all elements (legend in N); the grid's bonds are coloured by tension on one symmetric
    scale for all elements (one colour bar, N). ``datas``: element name -> figure data or the
    path of its .npz. Saves png and pdf.

    Returns tension_limit_n (the largest |bond tension| of all elements, N), force_scale_n (the
    largest contact force of all elements, N: the widest line), reference_forces_n (the
    legend's), overlaps (:func:`label_overlaps`, empty when no labels collide) and files.
    """
    plt = _pyplot()
    fig, out = _views_figure(datas, title=title)
    out["overlaps"] = label_overlaps(fig)
    out["files"] = _save(fig, png)
    plt.close(fig)
    return out


# ---------------------------------------------------------------------------------------------
# 002 Fig. 4: the deformed grid
# ---------------------------------------------------------------------------------------------

def auto_magnification(datas, *, fraction: float = 0.25) -> float:
    """The displacement magnification for :func:`plot_grid_deformed`: the largest displacement
    of the grid from its reference positions over all elements is shown as ``fraction`` of
    the smaller aperture pitch. Never below 1 (a displacement is never shown shrunk)."""
    datas = _as_datas(datas)
    dmax = max(float(np.max(np.linalg.norm(d["grid_positions"] - d["grid_reference_positions"],
                                           axis=1), initial=0.0)) for d in datas.values())
    pitch = min(float(np.min(d["pitch"])) for d in datas.values())
    if dmax <= 0:
        return 1.0
    return max(1.0, fraction * pitch / dmax)


def magnified_positions(data: dict, magnify: float) -> np.ndarray:
    """The grid's spheres as drawn: reference + magnify x displacement, m (s, 3)."""
    ref = data["grid_reference_positions"]
    return ref + magnify * (data["grid_positions"] - ref)


def _grid_figure(datas, *, magnify=None, fraction: float = 0.25, title: str = ""):
    plt = _pyplot()
    from matplotlib.collections import LineCollection
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    datas = _as_datas(datas)
    mag = auto_magnification(datas, fraction=fraction) if magnify is None else float(magnify)
    tlim = max(tension_limit(datas), 1e-30)
    sm = _tension_mappable(tlim)
    dmax = max(float(np.max(np.linalg.norm(d["grid_positions"] - d["grid_reference_positions"],
                                           axis=1), initial=0.0)) for d in datas.values())
    n = len(datas)
    fig = plt.figure(figsize=(11.0, 0.9 + 4.2 * n), layout="constrained")
    drawn = {}
    pts_all = np.concatenate([np.concatenate([magnified_positions(d, mag),
                                              d["grid_reference_positions"]])
                              for d in datas.values()])
    r = max(float(np.max(d["grid_radii"])) for d in datas.values())
    lo, hi = pts_all.min(axis=0) - r, pts_all.max(axis=0) + r
    axes = []
    for k, (name, d) in enumerate(datas.items()):
        p = magnified_positions(d, mag)
        ab = d["bond_spheres"]
        seg = np.stack([p[ab[:, 0]], p[ab[:, 1]]], axis=1)
        ref = d["grid_reference_positions"]
        rseg = np.stack([ref[ab[:, 0]], ref[ab[:, 1]]], axis=1)
        drawn[name] = seg
        ax = fig.add_subplot(n, 2, 2 * k + 1)
        ax.add_collection(LineCollection(rseg[:, :, :2] * _MM, linewidths=0.6, colors="0.8",
                                         zorder=1))
        ax.add_collection(LineCollection(seg[:, :, :2] * _MM, linewidths=1.9, colors="0.25",
                                         zorder=2))
        lc = LineCollection(seg[:, :, :2] * _MM, linewidths=1.4, cmap=sm.cmap, norm=sm.norm,
                            zorder=3)
        lc.set_array(d["bond_tension_n"])
        ax.add_collection(lc)
        ax.set_xlim(lo[0] * _MM, hi[0] * _MM)
        ax.set_ylim(lo[1] * _MM, hi[1] * _MM)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("y (mm)")
        ax.set_title(f"{name}: plan (x-y), grey: as built", fontsize=10)
        ax.tick_params(labelsize=8)
        ax3 = fig.add_subplot(n, 2, 2 * k + 2, projection="3d")
        l3 = Line3DCollection(seg * _MM, linewidths=1.4, cmap=sm.cmap, norm=sm.norm)
        l3.set_array(d["bond_tension_n"])
        ax3.add_collection3d(l3)
        # Equal scales on all three axes, the z range at least a tenth of the plan's.
        c = 0.5 * (lo + hi)
        half = 0.5 * (hi - lo)
        half[2] = max(half[2], 0.1 * max(half[0], half[1]))
        ax3.set_xlim((c[0] - half[0]) * _MM, (c[0] + half[0]) * _MM)
        ax3.set_ylim((c[1] - half[1]) * _MM, (c[1] + half[1]) * _MM)
        ax3.set_zlim((c[2] - half[2]) * _MM, (c[2] + half[2]) * _MM)
        ax3.set_box_aspect(tuple(half), zoom=0.9)  # room for the tick labels
        ax3.set_xlabel("x (mm)", fontsize=8)
        ax3.set_ylabel("y (mm)", fontsize=8)
        ax3.set_zlabel("z (mm)", fontsize=8)
        ax3.tick_params(labelsize=7)
        for axis in (ax3.xaxis, ax3.yaxis):
            axis.set_major_locator(plt.MaxNLocator(5))
        ax3.zaxis.set_major_locator(plt.MaxNLocator(3))
        ax3.set_title(f"{name}: 3D view", fontsize=10)
        ax3.view_init(elev=25, azim=-60)
        axes += [ax, ax3]
    fig.colorbar(sm, ax=axes, shrink=0.8, label="bond tension (N)")
    pitch = min(float(np.min(d["pitch"])) for d in datas.values())
    head = (f"Geogrid displacement magnified x{mag:.3g} (largest {dmax * _MM:.3g} mm, shown as "
            f"{mag * dmax / pitch:.2g} of the {pitch * _MM:.3g} mm pitch)")
    fig.suptitle(f"{title}\n{head}" if title else head, fontsize=11)
    return fig, {"magnify": mag, "max_displacement_m": dmax, "tension_limit_n": float(tlim),
                 "segments": drawn}


def plot_grid_deformed(datas: dict, png, *, magnify: float | None = None,
                       fraction: float = 0.25, title: str = "") -> dict:
    """002 Fig. 4: the grid alone, per element a plan view (x-y; the grid as built in light
    grey beneath) and a 3D view, its displacement from the reference positions magnified by
    ``magnify`` (None: :func:`auto_magnification`, the largest displacement of all elements
    shown as ``fraction`` of the aperture pitch; the factor is in the title). The bonds are
    coloured by tension on one symmetric scale for all elements. Saves png and pdf.

    Returns magnify, max_displacement_m (the largest true displacement, m), tension_limit_n,
    overlaps (:func:`label_overlaps`) and files."""
    plt = _pyplot()
    fig, out = _grid_figure(datas, magnify=magnify, fraction=fraction, title=title)
    out.pop("segments")
    out["overlaps"] = label_overlaps(fig)
    out["files"] = _save(fig, png)
    plt.close(fig)
    return out


# ---------------------------------------------------------------------------------------------
# Contact roses and the main directions of load transfer
# ---------------------------------------------------------------------------------------------

def _plane_angles(normals, weights, plane: str) -> tuple[np.ndarray, np.ndarray]:
    """The axial angles (rad, in [0, pi)) of the normals projected on ``plane`` and their
    weights times the squared length of the projection (a normal across the plane counts
    nothing: the weighted fabric tensor restricted to the plane)."""
    if plane not in PLANES:
        raise ValueError(f"plane={plane!r}: must be one of {', '.join(PLANES)}")
    i, j = PLANES[plane]
    n = np.asarray(normals, float).reshape(-1, 3)
    w = np.asarray(weights, float).reshape(-1)
    if len(w) != len(n):
        raise ValueError(f"weights: {len(w)} values for {len(n)} normals")
    l2 = n[:, i] ** 2 + n[:, j] ** 2
    keep = l2 > 1e-12
    phi = np.mod(np.arctan2(n[keep, j], n[keep, i]), np.pi)
    return phi, np.abs(w[keep]) * l2[keep]


def fabric_tensor(normals, weights, plane: str) -> np.ndarray:
    """The force-weighted fabric tensor of the normals projected on ``plane`` (2 x 2,
    trace 1): sum w n n^T / sum w."""
    phi, w = _plane_angles(normals, weights, plane)
    if w.sum() <= 0:
        return np.full((2, 2), np.nan)
    u = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    return np.einsum("k,ki,kj->ij", w, u, u) / w.sum()


def direction_density(normals, weights, plane: str, *, smoothing_deg: float = 10.0,
                      resolution_deg: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """The smoothed force-weighted density of the normals' directions in ``plane`` over
    [0, 180) deg (axial: n and -n are one direction), relative to its mean (1 everywhere for
    an isotropic fabric). Returns (angles deg, density). The kernel is a von Mises one on the
    doubled angle, of standard deviation about ``smoothing_deg``."""
    phi, w = _plane_angles(normals, weights, plane)
    theta = np.deg2rad(np.arange(0.0, 180.0, resolution_deg))
    if w.sum() <= 0:
        return np.rad2deg(theta), np.zeros_like(theta)
    kappa = 1.0 / (4.0 * np.deg2rad(smoothing_deg) ** 2)
    dens = np.zeros_like(theta)
    for start in range(0, len(phi), 4096):
        p, ww = phi[start:start + 4096], w[start:start + 4096]
        dens += np.exp(kappa * (np.cos(2.0 * (theta[:, None] - p[None, :])) - 1.0)) @ ww
    return np.rad2deg(theta), dens / dens.mean()


def principal_directions(normals, weights, plane: str, *, threshold: float = 1.5,
                         smoothing_deg: float = 10.0) -> list[float]:
    """The main directions of load transfer in ``plane`` ('xz', 'yz' or 'xy'): the peaks of
    the force-weighted density of the contact normals (:func:`direction_density`) that reach
    ``threshold`` times its mean. Angles in degrees in (-90, 90], measured from the plane's
    first axis towards its second (xz: from +x towards +z), ascending. Empty when no
    direction stands out (e.g. an isotropic fabric).

    The fabric tensor's eigenvectors would not do: two directions at +-45 deg of equal weight
    make it isotropic."""
    ang, dens = direction_density(normals, weights, plane, smoothing_deg=smoothing_deg)
    if not np.any(dens > 0):
        return []
    left, right = np.roll(dens, 1), np.roll(dens, -1)
    peaks = np.flatnonzero((dens > left) & (dens >= right) & (dens >= threshold))
    out = [float(a - 180.0 if a > 90.0 else a) for a in ang[peaks]]
    return sorted(out)


def is_inclined_pair(angles, *, min_inclination_deg: float = 15.0) -> bool:
    """True when ``angles`` (:func:`principal_directions`) are exactly two directions, each at
    least ``min_inclination_deg`` away from both axes of the plane (0 and 90 deg): 002's "two
    main directions ... inclined with regard to the longitudinal and transverse members"."""
    a = [abs(float(x)) for x in angles]
    return len(a) == 2 and all(min_inclination_deg <= x <= 90.0 - min_inclination_deg
                               for x in a)


#: :func:`main_directions`: the probability, under an isotropic fabric, below which the
#: anisotropy counts as significant.
ISOTROPY_ALPHA = 1e-3


def main_directions(normals, weights, plane: str, *, threshold: float = 1.5,
                    smoothing_deg: float = 10.0, alpha: float = ISOTROPY_ALPHA,
                    min_inclination_deg: float = 15.0) -> dict:
    """The main directions of load transfer in ``plane`` and whether they are significant,
    as a pure function of the normals (k, 3) and their weights (k,) (e.g. contact forces).

    The directions are :func:`principal_directions` (peaks of the smoothed force-weighted
    density at ``threshold`` times its mean). Their significance is a test against an
    isotropic fabric, on the plane's projected normals (angle phi, weight w_k times the
    squared length of the projection, as in :func:`fabric_tensor`):

    - the rose's anisotropy of order 2 and 4: a_m = |sum w e^{i m phi}| / sum w, m = 2, 4.
      a_2 is the fabric tensor's deviator (the difference of its eigenvalues, trace 1); a_4
      sees what a_2 cannot: two equal families at +-45 deg (a_2 = 0, a_4 = 1 for sharp ones).
      Any one direction or any pair of directions has a_2 > 0 or a_4 > 0.
    - n_eff = (sum w)^2 / sum w^2, the weights' effective number of normals. For an
      isotropic fabric (phi uniform, independent of w) n_eff a_m^2 is about exponential
      with mean 1 (Rayleigh's test), so P(a_m >= x) = exp(-n_eff x^2).
    - p_isotropic = min(1, 2 min_m exp(-n_eff a_m^2)) (both orders, Bonferroni): the
      probability that an isotropic fabric of n_eff normals is at least this anisotropic.
      'significant' when p_isotropic < ``alpha`` (default 1e-3, i.e. a_m above about
      sqrt(7.6 / n_eff)).

    Returns 'directions_deg' (:func:`principal_directions`), 'peak_density' (the density at
    each, relative to its mean), 'anisotropy_2', 'anisotropy_4', 'n_eff', 'p_isotropic',
    'significant' and 'inclined_pair' (:func:`is_inclined_pair` of the directions, and
    significant: 002's "two main directions" that an isotropic sample does not show)."""
    phi, w = _plane_angles(normals, weights, plane)
    total = float(w.sum())
    if total <= 0:
        return {"directions_deg": [], "peak_density": [], "anisotropy_2": float("nan"),
                "anisotropy_4": float("nan"), "n_eff": 0.0, "p_isotropic": 1.0,
                "significant": False, "inclined_pair": False}
    n_eff = total ** 2 / float(np.sum(w ** 2))
    a2 = float(abs(np.sum(w * np.exp(2j * phi))) / total)
    a4 = float(abs(np.sum(w * np.exp(4j * phi))) / total)
    p = min(1.0, 2.0 * math.exp(-n_eff * max(a2, a4) ** 2))
    dirs = principal_directions(normals, weights, plane, threshold=threshold,
                                smoothing_deg=smoothing_deg)
    ang, dens = direction_density(normals, weights, plane, smoothing_deg=smoothing_deg)
    peak = [float(np.interp(np.mod(a, 180.0), ang, dens)) for a in dirs]
    significant = bool(p < alpha)
    return {"directions_deg": dirs, "peak_density": peak, "anisotropy_2": a2,
            "anisotropy_4": a4, "n_eff": float(n_eff), "p_isotropic": float(p),
            "significant": significant,
            "inclined_pair": significant and is_inclined_pair(
                dirs, min_inclination_deg=min_inclination_deg)}


def _rose_source(d, contacts: str):
    if contacts == "grain":
        return d["grain_normal"], d["grain_force_n"]
    if contacts == "grid":
        return d["grid_contact_normal"], d["grid_contact_force_n"]
    if contacts == "all":
        return (np.concatenate([d["grain_normal"], d["grid_contact_normal"]]),
                np.concatenate([d["grain_force_n"], d["grid_contact_force_n"]]))
    raise ValueError(f"contacts={contacts!r}: must be 'grain', 'grid' or 'all'")


def rose_histogram(normals, weights, plane: str, *, bins: int = 36):
    """The rose of the normals in ``plane``: (bin centres rad over the full circle, share of
    the force-weighted normals per bin, %; the first bin centred on 0). Mirrored (n and -n),
    so opposite bins are equal and the shares sum to 100 %."""
    phi, w = _plane_angles(normals, weights, plane)
    width = 2 * np.pi / bins
    # Bins centred on 0, 360/bins, ... deg, so that the axes fall in a bin's middle.
    a = np.mod(np.concatenate([phi, phi + np.pi]) + 0.5 * width, 2 * np.pi)
    h, _ = np.histogram(a, bins=np.linspace(0.0, 2 * np.pi, bins + 1),
                        weights=np.concatenate([w, w]))
    total = h.sum()
    return np.arange(bins) * width, (100.0 * h / total if total > 0 else h * 0.0)


def plot_contact_rose(datas: dict, png, *, planes=("xz", "yz", "xy"), contacts: str = "grain",
                      bins: int = 36, threshold: float = 1.5, title: str = "") -> dict:
    """Roses of the contact normals weighted by force (the share of the force-weighted normals
    per bin, %), one row per element, one column per plane (x-z and y-z vertical, x-y plan),
    on one radial scale. The main directions (:func:`principal_directions`) are drawn as black
    lines and listed in each panel's title. ``contacts``: 'grain' (grain–grain), 'grid'
    (grain–grid) or 'all'. Saves png and pdf.

    Returns radial_max_percent, directions_deg ({element: {plane: angles}}), inclined_pair
    ({element: {plane: bool}}, :func:`main_directions`: significant against isotropy), overlaps (:func:`label_overlaps`) and
    files."""
    plt = _pyplot()
    datas = _as_datas(datas)
    hists, dirs, pairs = {}, {}, {}
    for name, d in datas.items():
        n, w = _rose_source(d, contacts)
        hists[name] = {p: rose_histogram(n, w, p, bins=bins) for p in planes}
        dirs[name] = {p: principal_directions(n, w, p, threshold=threshold) for p in planes}
        # (an inclined pair that an isotropic fabric of as many contacts would not show)
        pairs[name] = {p: main_directions(n, w, p, threshold=threshold)["inclined_pair"]
                       for p in planes}
    rmax = max(float(np.max(h[1], initial=0.0)) for hs in hists.values() for h in hs.values())
    rmax = rmax * 1.08 if rmax > 0 else 1.0
    nr, nc = len(datas), len(planes)
    fig = plt.figure(figsize=(3.6 * nc + 0.6, 0.9 + 3.7 * nr), layout="constrained")
    # The polar tick labels reach beyond what the layout reserves: more room between rows.
    fig.get_layout_engine().set(h_pad=0.25, w_pad=0.1)
    axes = np.atleast_2d(fig.subplots(nr, nc, subplot_kw={"projection": "polar"},
                                      squeeze=False))
    width = 2 * np.pi / bins
    for r, name in enumerate(datas):
        for c, p in enumerate(planes):
            ax = axes[r, c]
            th, h = hists[name][p]
            ax.bar(th, h, width=width, color="0.6", edgecolor="0.3", linewidth=0.4)
            for a in dirs[name][p]:
                t = np.deg2rad(a)
                ax.plot([t, t], [0, rmax], color="k", lw=1.2)
                ax.plot([t + np.pi, t + np.pi], [0, rmax], color="k", lw=1.2)
            ax.set_ylim(0, rmax)
            ax.set_theta_zero_location("E")
            ax.set_theta_direction(1)
            i, j = PLANES[p]
            ax.set_xticks(np.deg2rad([0, 90, 180, 270]),
                          [f"+{'xyz'[i]}", f"+{'xyz'[j]}", f"-{'xyz'[i]}", f"-{'xyz'[j]}"])
            ax.tick_params(labelsize=8)
            ax.yaxis.set_major_locator(plt.MaxNLocator(3))
            ax.set_rlabel_position(22.5)
            ds = ", ".join(f"{a:+.0f}°" for a in dirs[name][p]) or "none"
            ax.set_title(f"{name}: {_PLANE_LABEL[p]}\nmain directions: {ds}", fontsize=9,
                         pad=12)
    head = (f"Contact normals weighted by force ({contacts} contacts), % per "
            f"{360 / bins:g}° bin; angles from the first axis towards the second")
    fig.suptitle(f"{title}\n{head}" if title else head, fontsize=10)
    out = {"radial_max_percent": rmax, "directions_deg": dirs, "inclined_pair": pairs,
           "overlaps": label_overlaps(fig)}
    out["files"] = _save(fig, png)
    plt.close(fig)
    return out


# ---------------------------------------------------------------------------------------------

def draw_all(datas: dict, out_dir, stem: str, *, title: str = "") -> list[Path]:
    """Draws :func:`plot_views`, :func:`plot_grid_deformed` and :func:`plot_contact_rose` of
    ``datas`` into ``out_dir`` as <stem>_views, <stem>_grid and <stem>_rose (.png and .pdf);
    returns the six paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    datas = _as_datas(datas)
    files = []
    files += plot_views(datas, out / f"{stem}_views.png", title=title)["files"]
    files += plot_grid_deformed(datas, out / f"{stem}_grid.png", title=title)["files"]
    files += plot_contact_rose(datas, out / f"{stem}_rose.png", title=title)["files"]
    return files
