"""The VTK files a ParaView user gets, read back with the official VTK reader (the `vtk` wheel):
point counts, the `kind` legend against the scene, radii, the .pvd series (files, times, the
prepared state first) and the Python snippet of docs/output.md, run as it is written there."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

vtk_numpy = pytest.importorskip("vtkmodules.util.numpy_support")
vtk_xml = pytest.importorskip("vtkmodules.vtkIOXML")

import cpp_dem as dem  # noqa: E402
from cpp_dem.build import geogrid  # noqa: E402
from cpp_dem.build.clumps import ClumpTemplate  # noqa: E402
from cpp_dem.io import (SPHERE_KINDS, PvdWriter, sphere_kinds, write_vtk_box,  # noqa: E402
                        write_vtk_spheres)

ROOT = Path(__file__).resolve().parents[1]
SNIPPET_HEADING = "### Reading the files in Python"


def read(path: Path) -> dict:
    """Everything of a .vtp through vtkXMLPolyDataReader, as NumPy arrays."""
    r = vtk_xml.vtkXMLPolyDataReader()
    r.SetFileName(str(path))
    r.Update()
    assert r.GetErrorCode() == 0, path
    poly = r.GetOutput()
    pd, cd, fd = poly.GetPointData(), poly.GetCellData(), poly.GetFieldData()
    return {
        "n_points": poly.GetNumberOfPoints(), "n_verts": poly.GetNumberOfVerts(),
        "n_polys": poly.GetNumberOfPolys(), "n_lines": poly.GetNumberOfLines(),
        "points": vtk_numpy.vtk_to_numpy(poly.GetPoints().GetData()),
        "point": {pd.GetArrayName(i): vtk_numpy.vtk_to_numpy(pd.GetArray(i))
                  for i in range(pd.GetNumberOfArrays())},
        "cell": {cd.GetArrayName(i): vtk_numpy.vtk_to_numpy(cd.GetArray(i))
                 for i in range(cd.GetNumberOfArrays())},
        "time": fd.GetArray("TimeValue").GetValue(0) if fd.GetArray("TimeValue") else None,
    }


def pvd_entries(path: Path) -> list[tuple[float, Path]]:
    root = ET.parse(path).getroot()  # raises on a file that does not parse
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    return [(float(e.get("timestep")), path.parent / e.get("file")) for e in root.iter("DataSet")]


def mixed_scene():
    """Free spheres, a clump, a 3 x 3 beam geogrid and a bonded pair: every kind once."""
    s = dem.Scene(gravity=(0, 0, -9.81))
    m = s.add_material(dem.linear_material(density=2000, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    free = s.add_spheres([[0.01, 0.01, 0.03], [0.03, 0.01, 0.03], [0.05, 0.01, 0.03]],
                         [0.004, 0.005, 0.006], material=m)
    t = ClumpTemplate.from_spheres([[-0.004, 0, 0], [0.004, 0, 0], [0, 0.005, 0]],
                                   [0.003, 0.003, 0.0025])
    c = s.add_clumps(t, [[0.03, 0.04, 0.03]], material=m)
    g = geogrid.square_grid(s, origin=(0, 0, 0), length=0.04, width=0.04, nodes_x=3, nodes_y=3,
                            params=dem.BeamParams(young=1e8, poisson=0.3, radius=0.001),
                            material=m, density=1000)
    bonded = s.add_spheres([[0.07, 0.07, 0.03], [0.0795, 0.07, 0.03]], [0.005, 0.005],
                           material=m)
    s.add_bond(int(bonded[0]), int(bonded[1]), dem.BondParams(kn=1e5, ks=1e5, friction=0.5))
    s.add_box((-0.01, -0.01, -0.01), (0.1, 0.1, 0.08), material=m)
    s.dt = 1e-6
    s.run(5)  # a time that is not 0, velocities and forces that are not all 0
    members = np.concatenate([s.clump_members(int(k)) for k in c])
    return s, {0: np.asarray(free), 1: members, 2: np.asarray(g.nodes), 3: np.asarray(bonded)}


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_spheres_file_kind_counts_and_radii(tmp_path, encoding):
    s, by_kind = mixed_scene()
    f = write_vtk_spheres(tmp_path / "spheres.vtp", s, encoding=encoding)
    d = read(f)
    n = s.num_bodies
    assert n == sum(len(v) for v in by_kind.values()) == 3 + 3 + 9 + 2
    assert d["n_points"] == n and d["n_verts"] == n
    expect = np.full(n, 99)
    for k, ids in by_kind.items():
        expect[ids] = k
    kind = d["point"]["kind"]
    assert kind.dtype == np.int64
    np.testing.assert_array_equal(kind, expect)
    np.testing.assert_array_equal(kind, sphere_kinds(s))
    assert set(np.unique(kind)) <= set(SPHERE_KINDS)
    # The arrays that were there before keep their values bit for bit.
    np.testing.assert_array_equal(d["points"], s.positions)
    np.testing.assert_array_equal(d["point"]["radius"], s.radii)
    np.testing.assert_array_equal(d["point"]["velocity"], s.velocities)
    np.testing.assert_array_equal(d["point"]["force"], s.forces)
    np.testing.assert_array_equal(d["point"]["id"], np.arange(n))
    np.testing.assert_array_equal(d["point"]["clump_id"], s.clump_ids)
    np.testing.assert_array_equal(d["point"]["radius"][by_kind[2]], 0.001)  # the cylinders'
    assert d["time"] == s.time > 0


def test_kind_adds_one_array_and_leaves_the_others_bitwise(tmp_path):
    # The same file without `kind` (written through write_vtp with the other arrays) has
    # the same bytes for every other array.
    from cpp_dem.io.vtk import write_vtp

    s, _ = mixed_scene()
    d = read(write_vtk_spheres(tmp_path / "a.vtp", s))
    assert set(d["point"]) == {"radius", "velocity", "angular_velocity", "force", "orientation",
                               "id", "kind", "clump_id", "clump_orientation"}
    text = (tmp_path / "a.vtp").read_text()
    arrays = dict(re.findall(r'<DataArray type="\w+" Name="(\w+)"[^>]*>([^<]*)</DataArray>',
                             text))
    ref = write_vtp(tmp_path / "b.vtp", s.positions, verts=True, point_data={
        "radius": s.radii, "velocity": s.velocities, "angular_velocity": s.angular_velocities,
        "force": s.forces, "orientation": s.orientations, "id": np.arange(s.num_bodies)})
    ref_arrays = dict(re.findall(r'<DataArray type="\w+" Name="(\w+)"[^>]*>([^<]*)</DataArray>',
                                 ref.read_text()))
    for name in ("radius", "velocity", "angular_velocity", "force", "orientation", "id"):
        assert arrays[name] == ref_arrays[name], name


def test_kind_of_an_unknown_body_kind_is_minus_one():
    class Fake:
        num_bodies = 3
        body_kinds = [0, 1, 7]
        num_clumps = 0
        num_bonds = 0

    np.testing.assert_array_equal(sphere_kinds(Fake()), [0, 2, -1])


@pytest.fixture(scope="module")
def pullout_run(tmp_path_factory):
    """The pull-out cases' VTK writer on a small clump sample with its geogrid (built, not
    prepared: 40 clumps, ~0.5 s): the prepared state and two later states in the series."""
    from geogrid_dem.cases import pullout_000
    from geogrid_dem.cases.pullout_common import write_vtk_state

    out = tmp_path_factory.mktemp("pullout")
    vtk = out / "vtk"
    vtk.mkdir()
    sample = pullout_000.build(pullout_000.Params(spheres=40, box=(0.3, 0.15, 0.15),
                                                  grains="clumps:gravel_a"))
    sc = sample.scene
    pvds = {k: PvdWriter(vtk / f"{k}.pvd", overwrite=True)
            for k in ("spheres", "contacts", "geogrid", "box")}
    states = []
    for name in ("prepared", "d000.50mm", "d001.00mm"):
        if states:
            sc.run(20)
        write_vtk_state(sample, vtk, name, pvds)
        states.append({"name": name, "time": sc.time, "kind": sphere_kinds(sc),
                       "radii": sc.radii.copy(), "lo_hi": sample.box_lo_hi(),
                       "nodes": sc.positions[sample.grid.nodes].copy()})
    return out, sample, states


def test_pullout_series_list_every_file_at_its_time_prepared_first(pullout_run):
    out, sample, states = pullout_run
    for key in ("spheres", "contacts", "geogrid", "box"):
        entries = pvd_entries(out / "vtk" / f"{key}.pvd")
        assert [f.name for _, f in entries] == [f"{key}_{st['name']}.vtp" for st in states]
        assert [t for t, _ in entries] == [st["time"] for st in states]
        assert all(np.diff([t for t, _ in entries]) > 0)
        for t, f in entries:
            assert f.is_file()
            assert read(f)["time"] == t  # the file's TimeValue is the series' time


def test_pullout_spheres_kind_radii_and_box_against_the_scene(pullout_run):
    out, sample, states = pullout_run
    sc = sample.scene
    nodes = np.asarray(sample.grid.nodes)
    assert geogrid.write_vtk_geogrid(out / "g.vtp", sc, sample.grid) == out / "g.vtp"
    for st in states:
        d = read(out / "vtk" / f"spheres_{st['name']}.vtp")
        assert d["n_points"] == sc.num_bodies == d["n_verts"]
        kind = d["point"]["kind"]
        np.testing.assert_array_equal(kind, st["kind"])
        assert np.count_nonzero(kind == 2) == len(nodes) and (kind[nodes] == 2).all()
        members = np.asarray(sc.clump_ids) >= 0
        assert (kind[members] == 1).all() and members.sum() == 40 * 24
        assert set(np.unique(kind)) == {1, 2}
        np.testing.assert_array_equal(d["point"]["radius"], st["radii"])
        # The geogrid file draws the same nodes (kind 2) at the same positions.
        g = read(out / "vtk" / f"geogrid_{st['name']}.vtp")
        np.testing.assert_array_equal(g["points"], d["points"][kind == 2])
        np.testing.assert_array_equal(g["points"], st["nodes"])
        b = read(out / "vtk" / f"box_{st['name']}.vtp")
        assert b["n_points"] == 8 and b["n_polys"] == 6
        lo, hi = (np.asarray(v, float) for v in st["lo_hi"])
        np.testing.assert_array_equal(b["points"].min(axis=0), lo)
        np.testing.assert_array_equal(b["points"].max(axis=0), hi)
        np.testing.assert_array_equal(b["cell"]["wall"], np.arange(6))


def docs_snippet() -> str:
    text = (ROOT / "docs" / "output.md").read_text()
    k = text.index(SNIPPET_HEADING + "\n")
    m = re.search(r"```python\n(.*?)```", text[k:], re.S)
    assert m, f"no ```python block under {SNIPPET_HEADING!r} in docs/output.md"
    return m.group(1)


def test_the_reading_snippet_of_the_docs_runs_on_a_pullout_folder(pullout_run, capsys):
    out, sample, states = pullout_run
    ns = {"run_dir": str(out)}
    exec(compile(docs_snippet(), "docs/output.md", "exec"), ns)
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == len(states)
    assert printed[0].startswith("spheres_prepared.vtp at ")
    n_nodes = len(sample.grid.nodes)
    assert all(f": {40 * 24} grain spheres, {n_nodes} geogrid nodes," in line for line in printed)
    # Its helpers give what the scene had.
    points, arrays, t = ns["read_vtp"](out / "vtk" / "spheres_prepared.vtp")
    assert t == states[0]["time"] and points.shape == (sample.scene.num_bodies, 3)
    np.testing.assert_array_equal(arrays["kind"], states[0]["kind"])
    assert [f.name for _, f in ns["read_pvd"](out / "vtk" / "box.pvd")] == [
        f"box_{st['name']}.vtp" for st in states]


def test_box_file_and_series_of_a_moving_box(tmp_path):
    pvd = PvdWriter(tmp_path / "box.pvd")
    for k, top in enumerate((0.10, 0.09, 0.08)):
        pvd.add(0.5 * k, write_vtk_box(tmp_path / f"box_{k}.vtp", (0, 0, 0), (0.2, 0.1, top),
                                       time=0.5 * k).name)
    entries = pvd_entries(tmp_path / "box.pvd")
    assert [t for t, _ in entries] == [0.0, 0.5, 1.0]
    tops = [read(f)["points"][:, 2].max() for _, f in entries]
    assert tops == [0.10, 0.09, 0.08]


def test_deposition_smoke_run_reads_back(tmp_path):
    # The deposition case at smoke size over 0.1 s (~4 s): every .pvd parses, lists files
    # that exist at increasing times, from the initial state on; every point is a grain sphere.
    from geogrid_dem.cases import deposition

    out = tmp_path / "dep"
    deposition.main(["--smoke", "--duration", "0.1", "--out", str(out)])
    spheres = pvd_entries(out / "deposition.pvd")
    contacts = pvd_entries(out / "contacts.pvd")
    box = pvd_entries(out / "box.pvd")
    assert len(spheres) >= 2 and [t for t, _ in spheres] == [t for t, _ in contacts]
    assert spheres[0][0] == 0.0 and all(np.diff([t for t, _ in spheres]) > 0)
    assert [(t, f.name) for t, f in box] == [(0.0, "box.vtp")]
    n = deposition.SMOKE["n"]
    for t, f in spheres:
        d = read(f)
        assert d["time"] == t and d["n_points"] == n
        np.testing.assert_array_equal(d["point"]["kind"], np.zeros(n))
    last = read(spheres[-1][1])
    packing = np.loadtxt(out / "packing.csv", delimiter=",", skiprows=1, ndmin=2)
    np.testing.assert_allclose(np.sort(last["point"]["radius"]), np.sort(packing[:, 3]),
                               rtol=1e-12)
    b = read(box[0][1])
    np.testing.assert_array_equal(b["points"].max(axis=0), deposition.SMOKE["box"])


def test_cylinder_and_mesh_walls_read_back(tmp_path):
    from cpp_dem.io import write_vtk_walls

    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=2000, young=1e7, poisson=0.3,
                                            friction_angle_deg=30))
    sc.add_cylinder_wall(centre=[0, 0, 0], axis=[0, 0, 1], radius=0.05, inside=True,
                         material=m, lo=0.0, hi=0.1)
    sc.add_cylinder_wall(centre=[1, 0, 0], axis=[1, 1, 0], radius=0.01, inside=False,
                         material=m)  # infinite: drawn 1 m long
    v = np.array([[0, 0, -0.1], [0.2, 0, -0.1], [0.2, 0.2, -0.1], [0, 0.2, -0.1]])
    sc.add_mesh_wall(v, [[0, 1, 2], [0, 2, 3]], material=m)
    d = read(write_vtk_walls(tmp_path / "walls.vtp", sc, segments=12))
    assert d["n_polys"] == 2 * 12 * 2 + 2
    assert list(d["cell"]["kind"]) == [0] * 48 + [1, 1]
    assert list(d["cell"]["wall"]) == [0] * 24 + [1] * 24 + [0, 0]
    rho = np.hypot(d["points"][:24, 0], d["points"][:24, 1])
    assert np.allclose(rho, 0.05) and set(np.round(d["points"][:24, 2], 12)) == {0.0, 0.1}
    assert np.allclose(d["points"][-4:], v)
