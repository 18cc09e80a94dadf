"""Clump templates from closed surface meshes (cpp_dem.build.clump_mesh).

Mass properties of meshes against analytic values; fills of a cube and an ellipsoid against the
analytic values within the stated fill errors (docs/clump_templates.md), decreasing with the
sphere count; closed-mesh checks; file round trips; the shipped gravel grains and their
generator (scripts/make_gravel_meshes.py).
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.build import clump_mesh as cm
from cpp_dem.build.clumps import ClumpTemplate

from conftest import ROOT


def _box(a, b, c):
    v = a * b * c
    return v, np.diag(v / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b]))


def _ellipsoid(a, b, c):
    v = 4.0 / 3.0 * math.pi * a * b * c
    return v, np.diag(v / 5.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b]))


def _rotation(seed):
    q = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))[0]
    return q * np.sign(np.linalg.det(q))


# ---------------------------------------------------------------- mass properties of meshes

def test_box_mesh_mass_properties_are_exact():
    v, t = cm.box_mesh(0.3, 0.5, 0.7, centre=(1.0, -2.0, 0.5))
    mp = cm.mesh_mass_properties(v, t)
    vol, inertia = _box(0.3, 0.5, 0.7)
    assert mp.volume == pytest.approx(vol, rel=1e-13)
    np.testing.assert_allclose(mp.centroid, [1.0, -2.0, 0.5], atol=1e-13)
    np.testing.assert_allclose(mp.inertia, inertia, atol=1e-13 * inertia.max())
    # Rotated and moved: the inertia tensor turns with the body.
    R = _rotation(3)
    mr = cm.mesh_mass_properties(v @ R.T + [5.0, 6.0, 7.0], t)
    assert mr.volume == pytest.approx(vol, rel=1e-12)
    np.testing.assert_allclose(mr.centroid, R @ [1.0, -2.0, 0.5] + [5.0, 6.0, 7.0], atol=1e-12)
    np.testing.assert_allclose(mr.inertia, R @ inertia @ R.T, atol=1e-12 * inertia.max())
    np.testing.assert_allclose(mr.principal, np.sort(np.diag(inertia)), rtol=1e-12)


# Stated O(h^2) error of the inscribed icosphere ellipsoid (semi-axes 1, 0.75, 0.5), relative,
# per subdivision level: measured -8.6e-3, -2.2e-3, -5.4e-4 (volume) and -1.4e-2, -3.6e-3,
# -9.0e-4 (inertia).
ELLIPSOID_MESH_ERROR = {3: (9e-3, 1.5e-2), 4: (2.3e-3, 3.8e-3), 5: (6e-4, 1e-3)}


def test_ellipsoid_mesh_mass_properties_converge_as_h_squared():
    vol, inertia = _ellipsoid(1.0, 0.75, 0.5)
    errs = []
    for s, (tol_v, tol_i) in ELLIPSOID_MESH_ERROR.items():
        v, t = cm.ellipsoid_mesh(1.0, 0.75, 0.5, subdivisions=s, centre=(0.2, 0.1, -0.3))
        mp = cm.mesh_mass_properties(v, t)
        ev = mp.volume / vol - 1.0
        ei = np.abs(mp.inertia - inertia).max() / inertia.max()
        assert -tol_v < ev < 0.0, (s, ev)     # inscribed: always smaller
        assert ei < tol_i, (s, ei)
        np.testing.assert_allclose(mp.centroid, [0.2, 0.1, -0.3], atol=1e-12)
        errs.append(ev)
    # Halving h divides the error by 4.
    for e0, e1 in zip(errs, errs[1:]):
        assert 3.7 < e0 / e1 < 4.3


def test_convex_hull_of_cube_corners_and_inner_points():
    rng = np.random.default_rng(1)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    pts = np.vstack([rng.uniform(0.1, 0.9, (30, 3)), corners])
    v, t = cm.convex_hull_mesh(pts)
    assert len(v) == 8
    mp = cm.mesh_mass_properties(v, t)
    assert mp.volume == pytest.approx(1.0, rel=1e-12)
    # A random hull contains all its points (outward normals: no point above a face).
    p = rng.normal(size=(40, 3))
    v, t = cm.convex_hull_mesh(p)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    assert (np.einsum("tk,ptk->pt", n, p[:, None] - a[None]) <= 1e-12).all()


# ---------------------------------------------------------------- checks

def test_open_nonmanifold_and_misoriented_meshes_are_refused():
    v, t = cm.box_mesh(1.0)
    with pytest.raises(dem.ParameterError, match=r"triangles: edge .* 1 triangle.*hole"):
        cm.check_closed_mesh(v, t[1:])
    with pytest.raises(dem.ParameterError, match=r"non-manifold"):
        cm.check_closed_mesh(v, np.vstack([t, t[:2]]))
    bad = t.copy()
    bad[0] = bad[0, ::-1]
    with pytest.raises(dem.ParameterError, match=r"not consistently oriented"):
        cm.mesh_mass_properties(v, bad)
    with pytest.raises(dem.ParameterError, match=r"triangles: indices"):
        cm.check_closed_mesh(v, t + 1)
    with pytest.raises(dem.ParameterError, match=r"vertices: shape"):
        cm.check_closed_mesh(v[:, :2], t)
    # A globally inverted mesh is turned outward.
    mp = cm.mesh_mass_properties(v, t[:, ::-1])
    assert mp.volume == pytest.approx(1.0)
    with pytest.raises(dem.ParameterError, match=r"max_spheres=0"):
        cm.fill_mesh(v, t, max_spheres=0)
    with pytest.raises(dem.ParameterError, match=r"min_radius_ratio=1.0"):
        cm.fill_mesh(v, t, min_radius_ratio=1.0)
    with pytest.raises(dem.ParameterError, match=r"grid=2"):
        cm.fill_mesh(v, t, grid=2)


# ---------------------------------------------------------------- fills vs analytic values

# Stated fill error (grid = 20, seed = 0) of the template against the analytic solid, per
# sphere count: (|volume error|, centroid offset / d_eq, inertia error (unit density, over the
# largest principal moment), gyration error (inertia / volume)). Measured values are in
# docs/clump_templates.md; these bounds are them rounded up.
CUBE_FILL = {8: (0.30, 0.02, 0.47, 0.25), 16: (0.23, 0.006, 0.36, 0.17),
             32: (0.165, 0.002, 0.27, 0.13)}
ELLIPSOID_FILL = {8: (0.235, 0.02, 0.39, 0.20), 16: (0.12, 0.003, 0.16, 0.05),
                  32: (0.07, 0.001, 0.10, 0.04)}


def _check_fill(v, t, vol, inertia, stated):
    tmpl = cm.fill_mesh(v, t, max_spheres=max(stated))
    assert tmpl.num_members == max(stated)
    # Every sphere lies inside the surface.
    dist = cm._point_triangle_distance(tmpl.centres, v, t)
    assert (tmpl.radii <= dist + 1e-12).all()
    d_eq = (6.0 * vol / math.pi) ** (1.0 / 3.0)
    prev = None
    for n, (tv, tc, ti, tg) in sorted(stated.items()):
        p = ClumpTemplate(tmpl.centres[:n], tmpl.radii[:n]).props
        ev = p.volume / vol - 1.0
        ec = np.linalg.norm(p.centroid - (v.max(0) + v.min(0)) / 2) / d_eq
        ei = np.abs(p.inertia - inertia).max() / inertia.max()
        eg = np.abs(p.inertia / p.volume - inertia / vol).max() / (inertia.max() / vol)
        assert -tv < ev < 0.0, (n, ev)
        assert ec < tc, (n, ec)
        assert ei < ti, (n, ei)
        assert eg < tg, (n, eg)
        if prev is not None:  # the errors fall as spheres are added
            assert abs(ev) < abs(prev[0]) and ei < prev[1] and eg < prev[2], (n, ev, ei, eg)
        prev = (ev, ei, eg)
    return tmpl


def test_a_surface_that_crosses_itself_is_refused():
    """Two cubes that interpenetrate make a closed, consistently oriented surface (every edge
    in two triangles, opposite ways) whose divergence-theorem volume counts their overlap
    twice: refused, naming two crossing triangles. Apart, the same two cubes are a closed
    surface of twice a cube's volume; a fine convex surface (13 920 triangles) has no
    crossing pair."""
    a_v, a_t = cm.box_mesh(1.0)
    b_v, b_t = cm.box_mesh(1.0, centre=(0.5, 0.3, 0.2))
    v, t = np.vstack([a_v, b_v]), np.vstack([a_t, b_t + len(a_v)])
    crossing = cm.self_intersections(v, t)
    assert len(crossing) == 12 and all(i < j for i, j in crossing)
    assert all(not set(t[i]) & set(t[j]) for i, j in crossing)  # (no shared vertex)
    with pytest.raises(dem.ParameterError, match=r"triangles: triangles \d+ .* and \d+ .* cross "
                                                 r"\(they share no vertex; 12 crossing"):
        cm.mesh_mass_properties(v, t)
    c_v, c_t = cm.box_mesh(1.0, centre=(3.0, 0.0, 0.0))
    apart = cm.mesh_mass_properties(np.vstack([a_v, c_v]), np.vstack([a_t, c_t + len(a_v)]))
    assert apart.volume == pytest.approx(2.0, rel=1e-12)
    from scipy.spatial import ConvexHull

    th, ph = np.linspace(0, math.pi, 60)[1:-1], np.linspace(0, 2 * math.pi, 120, endpoint=False)
    pts = np.array([[0, 0, 1.0], [0, 0, -1.0]] + [
        [math.sin(x) * math.cos(y), math.sin(x) * math.sin(y), math.cos(x)]
        for x in th for y in ph])
    hull = ConvexHull(pts).simplices
    assert len(hull) == 13920 and len(cm.self_intersections(pts, hull)) == 0


def test_cube_fill_matches_analytic_within_stated_error():
    v, t = cm.box_mesh(1.0)
    vol, inertia = _box(1.0, 1.0, 1.0)
    tmpl = _check_fill(v, t, vol, inertia, CUBE_FILL)
    # The first sphere is the inscribed one.
    np.testing.assert_allclose(tmpl.centres[0], 0.0, atol=1e-12)
    assert tmpl.radii[0] == pytest.approx(0.5, rel=1e-12)


def test_ellipsoid_fill_matches_analytic_within_stated_error():
    v, t = cm.ellipsoid_mesh(1.0, 0.75, 0.5, subdivisions=3)
    vol, inertia = _ellipsoid(1.0, 0.75, 0.5)
    _check_fill(v, t, vol, inertia, ELLIPSOID_FILL)


def test_fill_is_deterministic_and_stops_on_target_fill():
    v, t = cm.box_mesh(0.02, 0.012, 0.01)
    a = cm.fill_mesh(v, t, max_spheres=10, grid=12, seed=4)
    b = cm.fill_mesh(v, t, max_spheres=10, grid=12, seed=4)
    np.testing.assert_array_equal(a.centres, b.centres)
    np.testing.assert_array_equal(a.radii, b.radii)
    c = cm.fill_mesh(v, t, max_spheres=40, grid=12, target_fill=0.6)
    assert 1 < c.num_members < 40
    r = cm.fill_mesh(v, t, max_spheres=40, grid=12, min_radius_ratio=0.5)
    assert r.radii.min() >= 0.5 * r.radii.max() - 1e-15


def test_fill_report_trade():
    v, t = cm.ellipsoid_mesh(1.0, 0.75, 0.5, subdivisions=2)
    rows = cm.fill_report(v, t, counts=(2, 8, 32), samples=1000, grid=12)
    assert [r.count for r in rows] == [2, 8, 32]
    for r0, r1 in zip(rows, rows[1:]):
        assert r0.volume_error < r1.volume_error < 0.0
        assert r1.rms_deviation < r0.rms_deviation
        assert r1.max_deviation <= r0.max_deviation
    assert rows[-1].rms_deviation < 0.02 and rows[-1].max_deviation < 0.06
    assert "| 32 |" in cm.format_report(rows)


# ---------------------------------------------------------------- files

@pytest.mark.parametrize("fname,kw", [("m.stl", {"binary": False}), ("m.stl", {"binary": True}),
                                      ("m.obj", {}), ("m.ply", {"binary": True})])
def test_reader_round_trip(tmp_path, fname, kw):
    meshio = pytest.importorskip("meshio")
    v, t = cm.ellipsoid_mesh(0.01, 0.008, 0.006, subdivisions=2, centre=(0.1, 0.0, 0.0))
    meshio.write(tmp_path / fname, meshio.Mesh(v, [("triangle", t.astype(np.int32))]), **kw)
    v2, t2 = cm.read_surface_mesh(tmp_path / fname)
    assert v2.shape == v.shape and t2.shape == t.shape
    a, b = cm.mesh_mass_properties(v, t), cm.mesh_mass_properties(v2, t2)
    tol = 1e-6 if kw.get("binary") and fname.endswith(".stl") else 1e-12  # float32 STL
    assert b.volume == pytest.approx(a.volume, rel=tol)
    np.testing.assert_allclose(b.centroid, a.centroid, atol=tol * 0.01)


def test_reader_flips_inverted_and_refuses_bad_files(tmp_path):
    meshio = pytest.importorskip("meshio")
    v, t = cm.box_mesh(2.0)
    meshio.write(tmp_path / "inv.obj", meshio.Mesh(v, [("triangle", t[:, ::-1])]))
    v2, t2 = cm.read_surface_mesh(tmp_path / "inv.obj")
    assert cm.mesh_mass_properties(v2, t2).volume == pytest.approx(8.0)
    meshio.write(tmp_path / "open.stl", meshio.Mesh(v, [("triangle", t[2:])]), binary=True)
    with pytest.raises(dem.ParameterError, match="hole"):
        cm.read_surface_mesh(tmp_path / "open.stl")
    with pytest.raises(dem.ParameterError, match="no such file"):
        cm.read_surface_mesh(tmp_path / "missing.stl")
    v3, t3 = cm.read_surface_mesh(tmp_path / "inv.obj", scale=1e-3)  # a file in mm
    assert cm.mesh_mass_properties(v3, t3).volume == pytest.approx(8e-9)
    with pytest.raises(dem.ParameterError, match="scale=0"):
        cm.read_surface_mesh(tmp_path / "inv.obj", scale=0)
    (tmp_path / "junk.stl").write_text("not a mesh")
    with pytest.raises(dem.ParameterError, match="could not be read"):
        cm.read_surface_mesh(tmp_path / "junk.stl")


def test_write_stl_reads_back(tmp_path):
    pytest.importorskip("meshio")
    v, t = cm.box_mesh(0.5, 0.25, 0.125)
    cm.write_stl(tmp_path / "b.stl", v, t)
    v2, t2 = cm.read_surface_mesh(tmp_path / "b.stl")
    assert cm.mesh_mass_properties(v2, t2).volume == pytest.approx(0.5 * 0.25 * 0.125, rel=1e-12)


# ---------------------------------------------------------------- shipped grains

def _generator():
    spec = importlib.util.spec_from_file_location(
        "make_gravel_meshes", ROOT / "scripts" / "make_gravel_meshes.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_shipped_templates_load_and_are_sane():
    gen = _generator()
    tmpls = cm.shipped_templates()
    assert sorted(tmpls) == sorted(gen.GRAINS)
    for name, tmpl in tmpls.items():
        assert tmpl.name == name and 10 <= tmpl.num_members <= 30
        # The mesh has d_eq = 1 m and its centroid at the origin; the spheres fill 75-95 % of it
        # (measured 0.797-0.877) and sit about its centroid.
        assert 0.75 * math.pi / 6 < tmpl.volume < 0.95 * math.pi / 6
        assert np.linalg.norm(tmpl.props.centroid) < 0.03
        assert tmpl.radii.min() >= gen.FILL["min_radius_ratio"] * tmpl.radii.max()
    with pytest.raises(dem.ParameterError, match="available: gravel_a, gravel_b"):
        cm.shipped_template("granite")
    assert cm.shipped_template("gravel_b").num_members == tmpls["gravel_b"].num_members


def test_shipped_mesh_and_template_are_reproduced_by_the_generator():
    pytest.importorskip("meshio")
    gen = _generator()
    v, t = gen.make_grain("gravel_a")
    vs, ts = cm.shipped_mesh("gravel_a")
    a, b = cm.mesh_mass_properties(v, t), cm.mesh_mass_properties(vs, ts)
    assert a.volume == pytest.approx(math.pi / 6, rel=1e-6)   # d_eq = 1 m (float32 vertices)
    assert b.volume == pytest.approx(a.volume, rel=1e-14)
    np.testing.assert_allclose(b.inertia, a.inertia, atol=1e-14)
    tmpl = gen.make_template("gravel_a", v, t)
    shipped = cm.shipped_template("gravel_a")
    np.testing.assert_array_equal(tmpl.centres, shipped.centres)
    np.testing.assert_array_equal(tmpl.radii, shipped.radii)


def test_generator_is_deterministic():
    gen = _generator()
    for name in ("gravel_b", "gravel_d"):
        v1, t1 = gen.make_grain(name, seed=7)
        v2, t2 = gen.make_grain(name, seed=7)
        np.testing.assert_array_equal(v1, v2)
        np.testing.assert_array_equal(t1, t2)
        v3, _ = gen.make_grain(name, seed=8)
        assert v3.shape != v1.shape or not np.array_equal(v3, v1)
    for name in gen.GRAINS:  # the shipped seed: L/S 1.44-1.78
        ext = np.sort(np.ptp(gen.make_grain(name)[0], axis=0))
        assert 1.3 < ext[2] / ext[0] < 2.0
