"""The RE-against-PRS figures of cpp_dem.measure.grid_figures (002 Figs 3–4) on two small
hand-built elements: a one-aperture woven grid with grains pressed onto three of its members,
each grain with two neighbours above it at +-45 deg in the x-z plane."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import cpp_dem as cd  # noqa: E402
from cpp_dem import measure  # noqa: E402
from cpp_dem.build import woven  # noqa: E402
from cpp_dem.measure import grid_figures as gf  # noqa: E402

R = 2e-3  # grain radius, m


def _element(*, prestrain, sag, overlap):
    """A grid stretched along x by ``prestrain`` and pushed down by up to ``sag`` (m) around
    the middle of its first longitudinal member, with 9 grains (grain–grid and grain–grain
    overlaps ``overlap``, m) and a box. One step of 1 ns computes the forces."""
    s = cd.Scene()
    m = s.add_material(woven.woven_material("detailed"))
    g = woven.woven_geogrid(s, origin=(0, 0, 0), apertures_x=1, apertures_y=1, material=m)
    grain = s.add_material(cd.linear_material(density=2600, young=1e7, poisson=0.3,
                                              friction_angle_deg=30))
    woven.set_grid_laws(s, m, grain)
    pos = np.asarray(g.reference_positions).copy()
    pos[:, 0] *= 1 + prestrain
    pos[:, 2] -= sag * np.exp(-((pos[:, 0] - 0.0135) ** 2 + pos[:, 1] ** 2) / 2e-5)
    p = s.positions
    p[g.spheres] = pos
    s.positions = p
    rg = float(s.radii[0])
    cs = []
    for q in ([0.0135, 0, 0], [0, 0.0135, 0], [0.0135, 0.027, 0]):
        k = int(np.argmin(np.linalg.norm(pos - q, axis=1)))
        c = pos[k] + [0, 0, rg + R - overlap]
        cs += [c, c + (2 * R - overlap) * np.array([1, 0, 1]) / np.sqrt(2),
               c + (2 * R - overlap) * np.array([-1, 0, 1]) / np.sqrt(2)]
    s.add_spheres(cs, [R] * len(cs), material=grain)
    s.add_box((-0.01, -0.01, -0.01), (0.04, 0.04, 0.02), material=grain)
    s.dt = 1e-9
    s.run(1)
    return s, g


@pytest.fixture(scope="module")
def elements():
    """RE: a sagging grid under large grain forces; PRS: a pre-strained grid (the larger
    tensions) under small grain forces."""
    out = {}
    for name, kw in (("RE", dict(prestrain=0.0, sag=3e-4, overlap=3e-4)),
                     ("PRS", dict(prestrain=2e-3, sag=0.0, overlap=1e-4))):
        s, g = _element(**kw)
        out[name] = (s, g, gf.figure_data(s, g))
    return out


@pytest.fixture(scope="module")
def datas(elements):
    return {k: v[2] for k, v in elements.items()}


@pytest.fixture(scope="module")
def views(datas, tmp_path_factory):
    return gf.plot_views(datas, tmp_path_factory.mktemp("views") / "el_views.png",
                         title="RE against PRS")


def test_figure_data_holds_the_contacts_and_bonds(elements):
    s, g, d = elements["RE"]
    assert len(d["grain_force_n"]) == 6 and len(d["grid_contact_force_n"]) == 3
    assert np.all(d["grain_force_n"] > 0) and np.all(d["grid_contact_force_n"] > 0)
    assert np.allclose(np.linalg.norm(d["grain_normal"], axis=1), 1)
    # Grain–grain normals at +-45 deg in x-z, grain–grid normals vertical.
    assert np.allclose(np.abs(d["grain_normal"][:, [0, 2]]), np.sqrt(0.5))
    assert np.allclose(np.abs(d["grid_contact_normal"][:, 2]), 1)
    ref = measure.reference_points(s)
    grains = ref[len(g.spheres):]
    ends = d["grain_segments"].reshape(-1, 3)
    assert all(np.min(np.linalg.norm(grains - e, axis=1)) < 1e-15 for e in ends)
    assert len(d["bond_tension_n"]) == len(g.bonds) == len(d["bond_segments"])
    assert np.array_equal(d["grid_reference_positions"], g.reference_positions)
    assert np.array_equal(d["box_lo"], [-0.01, -0.01, -0.01])
    assert np.array_equal(d["box_hi"], [0.04, 0.04, 0.02])
    assert set(np.unique(d["bond_direction"])) == {0, 1, 2}


def test_figure_data_round_trips_bitwise(datas, tmp_path):
    for name, d in datas.items():
        p = gf.save_figure_data(tmp_path / name, d)
        assert p.suffix == ".npz"
        back = gf.load_figure_data(p)
        assert set(back) == set(d)
        for k, v in d.items():
            assert back[k].dtype == v.dtype and back[k].shape == v.shape, k
            assert back[k].tobytes() == v.tobytes(), k


def test_views_share_one_tension_scale_and_one_force_scale(datas, views):
    t = {k: float(np.max(np.abs(d["bond_tension_n"]))) for k, d in datas.items()}
    f = {k: float(max(d["grain_force_n"].max(), d["grid_contact_force_n"].max()))
         for k, d in datas.items()}
    # The elements were built so that the maxima come from different elements.
    assert t["PRS"] > t["RE"] and f["RE"] > f["PRS"]
    assert views["tension_limit_n"] == max(t.values())
    assert views["force_scale_n"] == max(f.values())
    assert len(views["reference_forces_n"]) == 3
    assert views["reference_forces_n"][-1] == pytest.approx(max(f.values()), rel=0.05)


def test_every_panel_draws_on_the_shared_scales(datas):
    fig, sc = gf._views_figure(datas)
    try:
        axes = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
        assert len(axes) == 6
        tl, fs = sc["tension_limit_n"], sc["force_scale_n"]
        for ax, name in zip(axes, ["RE"] * 3 + ["PRS"] * 3):
            tension = [c for c in ax.collections if c.get_array() is not None]
            assert len(tension) == 1
            assert (tension[0].norm.vmin, tension[0].norm.vmax) == (-tl, tl)
            widths = np.concatenate([c.get_linewidths() for c in ax.collections
                                     if c.get_array() is None and len(c.get_linewidths()) > 1])
            d = datas[name]
            fmax = max(d["grain_force_n"].max(), d["grid_contact_force_n"].max())
            assert widths.max() == pytest.approx(gf._line_width(fmax, fs))
        cbars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
        assert len(cbars) == 1 and "N" in cbars[0].get_ylabel()
    finally:
        plt.close(fig)


def test_views_are_saved_without_overlapping_labels(views):
    png, pdf = views["files"]
    assert png.suffix == ".png" and pdf.suffix == ".pdf"
    assert png.stat().st_size > 10_000 and pdf.stat().st_size > 1_000
    assert views["overlaps"] == []


def test_label_overlaps_finds_colliding_titles():
    fig, (a, b) = plt.subplots(1, 2, figsize=(4, 2))
    a.set_title("a long title that reaches into the next panel")
    b.set_title("another long title reaching back into the first")
    try:
        assert len(gf.label_overlaps(fig)) > 0
    finally:
        plt.close(fig)


def test_magnification_scales_the_displayed_displacement(datas):
    shown = {}
    for mag in (1.0, 10.0):
        fig, out = gf._grid_figure(datas, magnify=mag)
        plt.close(fig)
        assert out["magnify"] == mag
        shown[mag] = out["segments"]
    for name, d in datas.items():
        ab = d["bond_spheres"]
        ref = np.stack([d["grid_reference_positions"][ab[:, 0]],
                        d["grid_reference_positions"][ab[:, 1]]], axis=1)
        assert np.allclose(shown[1.0][name], d["bond_segments"], rtol=0, atol=1e-15)
        assert np.allclose(shown[10.0][name] - ref, 10 * (d["bond_segments"] - ref),
                           rtol=1e-9, atol=1e-15)
    # The automatic factor shows the largest displacement as the fraction of the pitch.
    fig, out = gf._grid_figure(datas, fraction=0.2)
    plt.close(fig)
    pitch = min(float(d["pitch"].min()) for d in datas.values())
    assert out["magnify"] * out["max_displacement_m"] == pytest.approx(0.2 * pitch)
    assert out["magnify"] > 1


def test_plot_grid_deformed_saves_png_and_pdf(datas, tmp_path):
    out = gf.plot_grid_deformed(datas, tmp_path / "el_grid.png")
    assert [p.name for p in out["files"]] == ["el_grid.png", "el_grid.pdf"]
    assert all(p.stat().st_size > 1_000 for p in out["files"])
    assert out["overlaps"] == []
    assert out["tension_limit_n"] == max(float(np.abs(d["bond_tension_n"]).max())
                                         for d in datas.values())


def _cluster(rng, angles_deg, n, spread_deg=4.0, plane=(0, 2)):
    """Unit normals in a plane (axes ``plane``) around the given angles, random signs."""
    a = np.deg2rad(rng.choice(angles_deg, n) + rng.normal(0, spread_deg, n))
    v = np.zeros((n, 3))
    v[:, plane[0]], v[:, plane[1]] = np.cos(a), np.sin(a)
    v += rng.normal(0, 0.05, (n, 3))  # a little out of the plane
    v *= rng.choice([-1, 1], n)[:, None]
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_two_inclined_directions_are_found():
    rng = np.random.default_rng(1)
    n = _cluster(rng, [45, -45], 2000)
    w = rng.uniform(0.5, 2.0, len(n))
    a = gf.principal_directions(n, w, "xz")
    assert len(a) == 2 and a[0] == pytest.approx(-45, abs=3) and a[1] == pytest.approx(45, abs=3)
    assert gf.is_inclined_pair(a)
    # The fabric tensor alone cannot see them: it is isotropic in the plane.
    f = gf.fabric_tensor(n, w, "xz")
    assert abs(f[0, 0] - f[1, 1]) < 0.05 and abs(f[0, 1]) < 0.05
    # The same in the y-z plane, and at other inclinations.
    n2 = _cluster(rng, [30, 120], 2000, plane=(1, 2))
    a2 = gf.principal_directions(n2, np.ones(len(n2)), "yz")
    assert a2 == [pytest.approx(-60, abs=3), pytest.approx(30, abs=3)]
    assert gf.is_inclined_pair(a2)
    assert gf.principal_directions(n2, np.ones(len(n2)), "xz") == [pytest.approx(90, abs=3)]


def test_axis_aligned_or_isotropic_normals_give_no_inclined_pair():
    rng = np.random.default_rng(2)
    n = _cluster(rng, [0, 90], 2000)
    a = gf.principal_directions(n, np.ones(len(n)), "xz")
    assert len(a) == 2 and a[0] == pytest.approx(0, abs=3) and a[1] == pytest.approx(90, abs=3)
    assert not gf.is_inclined_pair(a)
    u = rng.normal(size=(5000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    w = rng.uniform(0.5, 2.0, len(u))
    for plane in gf.PLANES:
        assert gf.principal_directions(u, w, plane) == []
    one = _cluster(rng, [30], 1000)
    a1 = gf.principal_directions(one, np.ones(len(one)), "xz")
    assert a1 == [pytest.approx(30, abs=3)] and not gf.is_inclined_pair(a1)
    # Weights decide: the +45 deg normals weigh nothing, only -45 is left.
    n2 = _cluster(rng, [45, -45], 2000)
    w2 = np.where(n2[:, 0] * n2[:, 2] > 0, 0.0, 1.0)
    assert gf.principal_directions(n2, w2, "xz") == [pytest.approx(-45, abs=3)]


def test_rose_reports_the_main_directions_per_element(datas, tmp_path):
    out = gf.plot_contact_rose(datas, tmp_path / "el_rose.png")
    for name in datas:  # grain–grain normals at +-45 deg in x-z, nothing in y-z
        assert out["directions_deg"][name]["xz"] == [pytest.approx(-45, abs=1),
                                                     pytest.approx(45, abs=1)]
        # Six contacts are too few to stand out of an isotropic fabric's noise at 1e-3
        # (main_directions: p = 2 exp(-6) = 0.005): the peaks are drawn, not called a pair.
        assert not out["inclined_pair"][name]["xz"]
        assert out["directions_deg"][name]["yz"] == [pytest.approx(90, abs=1)]
    assert out["overlaps"] == []
    assert all(p.stat().st_size > 1_000 for p in out["files"])
    th, h = gf.rose_histogram(datas["RE"]["grain_normal"], datas["RE"]["grain_force_n"], "xz")
    assert h.sum() == pytest.approx(100) and out["radial_max_percent"] >= h.max()
    assert np.allclose(h, np.roll(h, len(h) // 2))  # n and -n


def test_draw_all_writes_the_three_figures(datas, tmp_path):
    files = gf.draw_all(datas, tmp_path / "figs", "el")
    assert sorted(p.name for p in files) == sorted(
        f"el_{k}.{e}" for k in ("views", "grid", "rose") for e in ("png", "pdf"))
    assert all(p.stat().st_size > 0 for p in files)
