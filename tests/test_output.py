"""Result files of cpp_dem.io: VTK PolyData / PVD well-formed, HDF5 and CSV recorders
append, flush, survive a crash and never replace a file silently."""

from __future__ import annotations

import base64
import hashlib
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.io import (CsvRecorder, H5Recorder, PvdWriter, read_csv_series,
                            read_h5_series, read_h5_snapshot, standard_series, write_vtk_box,
                            write_vtk_contacts, write_vtk_spheres, write_vtp)

h5py = pytest.importorskip("h5py")

PYTHON = sys.executable
BOX = (0.04, 0.04, 0.04)


# ---- a small scene and a VTK XML reader written from the file-format spec -------------------


def small_scene(steps: int = 1500) -> dem.Scene:
    """27 spheres dropped in a box: sphere–sphere and sphere–wall contacts after `steps`."""
    s = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.3)
    m = s.add_material(dem.Material(model="linear", density=2600, young=1e6, poisson=0.3,
                                    friction_angle_deg=30))
    s.add_box((0, 0, 0), BOX, material=m)
    g = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(3)
    s.add_spheres(0.008 + 0.0121 * g + rng.uniform(-5e-4, 5e-4, (27, 3)),
                  rng.uniform(0.005, 0.006, 27), material=m)
    s.set_auto_timestep(safety=0.3, period=100)
    s.track_energy = True
    s.run(steps)
    return s


@pytest.fixture(scope="module")
def scene():
    s = small_scene()
    c = s.contacts()
    assert (c["ids"][:, 1] >= 0).sum() > 0 and (c["ids"][:, 1] < 0).sum() > 0, \
        "the fixture should have both sphere-sphere and sphere-wall contacts"
    return s


_NP = {"Float64": "<f8", "Float32": "<f4", "Int64": "<i8", "Int32": "<i4", "UInt8": "u1",
       "UInt64": "<u8"}


def _array(el: ET.Element) -> np.ndarray:
    dtype = np.dtype(_NP[el.get("type")])
    ncomp = int(el.get("NumberOfComponents", "1"))
    text = (el.text or "").strip()
    if el.get("format") == "ascii":
        a = np.array(text.split(), dtype=float).astype(dtype) if text else np.zeros(0, dtype)
    else:
        assert el.get("format") == "binary"
        raw = base64.b64decode(text)
        nbytes = int(np.frombuffer(raw[:8], "<u8")[0])  # header_type UInt64
        assert nbytes == len(raw) - 8, "size header does not match the payload"
        a = np.frombuffer(raw[8:], dtype=dtype)
    return a.reshape(-1, ncomp) if ncomp > 1 else a


def read_vtp(path) -> dict:
    """Parses a VTK XML PolyData file (inline ascii/binary) and checks its structure."""
    root = ET.parse(path).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "PolyData"
    assert root.get("header_type") == "UInt64" and root.get("byte_order") == "LittleEndian"
    poly = root.find("PolyData")
    pieces = poly.findall("Piece")
    assert len(pieces) == 1
    piece = pieces[0]
    counts = {k: int(piece.get(f"NumberOf{k}")) for k in
              ("Points", "Verts", "Lines", "Strips", "Polys")}
    out = {"counts": counts, "point_data": {}, "cell_data": {}, "field_data": {}, "cells": {}}
    pts = piece.find("Points/DataArray")
    out["points"] = _array(pts)
    assert out["points"].shape == (counts["Points"], 3)
    for tag, key, n in (("PointData", "point_data", counts["Points"]),
                        ("CellData", "cell_data",
                         counts["Verts"] + counts["Lines"] + counts["Polys"])):
        block = piece.find(tag)
        for el in (block if block is not None else []):
            a = _array(el)
            assert len(a) == n, f"{tag}/{el.get('Name')}: {len(a)} tuples, expected {n}"
            out[key][el.get("Name")] = a
    for kind in ("Verts", "Lines", "Polys"):
        el = piece.find(kind)
        if counts[kind] == 0:
            assert el is None or len(el) == 0
            continue
        conn = _array(el.find("DataArray[@Name='connectivity']"))
        offs = _array(el.find("DataArray[@Name='offsets']"))
        assert len(offs) == counts[kind] and offs[-1] == len(conn)
        assert conn.min() >= 0 and conn.max() < counts["Points"]
        out["cells"][kind] = np.split(conn, offs[:-1])
    fd = poly.find("FieldData")
    for el in (fd if fd is not None else []):
        out["field_data"][el.get("Name")] = _array(el)
    return out


# ---- VTK ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_vtk_spheres_counts_arrays_and_values(tmp_path, scene, encoding):
    f = write_vtk_spheres(tmp_path / "spheres.vtp", scene, encoding=encoding,
                          extra_point_data={"coordination": np.arange(scene.num_bodies) % 5})
    d = read_vtp(f)
    n = scene.num_bodies
    assert d["counts"]["Points"] == n and d["counts"]["Verts"] == n
    assert set(d["point_data"]) == {"radius", "velocity", "angular_velocity", "force",
                                    "orientation", "id", "kind", "coordination"}
    np.testing.assert_array_equal(d["point_data"]["kind"], np.zeros(n))  # all grain spheres
    # Binary is bitwise; ASCII uses %.17g, which round-trips doubles exactly as well.
    np.testing.assert_array_equal(d["points"], scene.positions)
    np.testing.assert_array_equal(d["point_data"]["radius"], scene.radii)
    np.testing.assert_array_equal(d["point_data"]["velocity"], scene.velocities)
    np.testing.assert_array_equal(d["point_data"]["force"], scene.forces)
    np.testing.assert_array_equal(d["point_data"]["orientation"], scene.orientations)
    np.testing.assert_array_equal(d["point_data"]["id"], np.arange(n))
    assert d["point_data"]["velocity"].shape == (n, 3)
    assert d["field_data"]["TimeValue"][0] == scene.time
    assert [c.tolist() for c in d["cells"]["Verts"]] == [[i] for i in range(n)]


@pytest.mark.parametrize("include_walls", [False, True])
def test_vtk_contacts_is_the_force_network(tmp_path, scene, include_walls):
    f = write_vtk_contacts(tmp_path / "contacts.vtp", scene, include_walls=include_walls)
    d = read_vtp(f)
    c = scene.contacts()
    pair = c["ids"][:, 1] >= 0
    n_pair, n_wall = int(pair.sum()), int((~pair).sum())
    n_lines = n_pair + (n_wall if include_walls else 0)
    assert d["counts"]["Lines"] == n_lines
    assert d["counts"]["Points"] == scene.num_bodies + (n_wall if include_walls else 0)
    assert set(d["cell_data"]) == {"normal_force", "force", "normal", "overlap", "kind"}
    lines = np.array([ln.tolist() for ln in d["cells"]["Lines"]])
    np.testing.assert_array_equal(lines[:n_pair], c["ids"][pair])
    np.testing.assert_array_equal(d["cell_data"]["normal_force"][:n_pair],
                                  c["normal_force"][pair])
    np.testing.assert_array_equal(d["cell_data"]["force"][:n_pair], c["force"][pair])
    np.testing.assert_array_equal(d["cell_data"]["kind"],
                                  [0] * n_pair + [1] * (n_lines - n_pair))
    # Each pair line joins the two centres, whose distance is r_i + r_j - overlap (the
    # overlap is from the force evaluation at the start of the last step: the centres have
    # moved by v dt since).
    p, r = d["points"], scene.radii
    moved = 2 * np.abs(scene.velocities).max() * scene.dt * np.sqrt(3) + 1e-15
    ij = lines[:n_pair]
    length = np.linalg.norm(p[ij[:, 1]] - p[ij[:, 0]], axis=1)
    np.testing.assert_allclose(length, r[ij[:, 0]] + r[ij[:, 1]] - c["overlap"][pair],
                               rtol=0, atol=moved)
    if include_walls:
        # A wall line ends on the wall plane, at R - overlap/2 from the centre.
        wl = lines[n_pair:]
        seg = np.linalg.norm(p[wl[:, 1]] - p[wl[:, 0]], axis=1)
        np.testing.assert_allclose(seg, r[wl[:, 0]] - 0.5 * c["overlap"][~pair], rtol=1e-12)
        ends = p[wl[:, 1]]  # on the wall plane, within half the overlap and the motion
        tol = 0.5 * c["overlap"][~pair].max() + moved
        on_a_wall = np.isclose(ends, 0.0, atol=tol) | np.isclose(ends, BOX, atol=tol)
        assert on_a_wall.any(axis=1).all()


def test_vtk_contacts_without_contacts_is_valid(tmp_path):
    s = dem.Scene()
    m = s.add_material(dem.Material(model="linear", density=2600, young=1e7, poisson=0.3,
                                    friction_angle_deg=30))
    s.add_spheres([[0, 0, 0], [1, 0, 0]], [0.1, 0.1], material=m)
    d = read_vtp(write_vtk_contacts(tmp_path / "c.vtp", s, encoding="ascii"))
    assert d["counts"]["Lines"] == 0 and d["counts"]["Points"] == 2
    assert all(len(v) == 0 for v in d["cell_data"].values())


def test_vtk_box_faces_follow_the_wall_order(tmp_path):
    lo, hi = (0.0, -1.0, 2.0), (1.0, 1.0, 5.0)
    forces = np.arange(18, dtype=float).reshape(6, 3)
    d = read_vtp(write_vtk_box(tmp_path / "box.vtp", lo, hi, wall_forces=forces, time=0.5))
    assert d["counts"]["Points"] == 8 and d["counts"]["Polys"] == 6
    np.testing.assert_array_equal(d["cell_data"]["wall"], np.arange(6))
    np.testing.assert_array_equal(d["cell_data"]["force"], forces)
    for w, quad in enumerate(d["cells"]["Polys"]):  # x-, x+, y-, y+, z-, z+
        axis, side = divmod(w, 2)
        assert len(quad) == 4
        np.testing.assert_array_equal(d["points"][quad, axis], (hi if side else lo)[axis])
    assert d["field_data"]["TimeValue"][0] == 0.5


def test_write_vtp_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match="vtp"):
        write_vtp(tmp_path / "x.vtk", np.zeros((1, 3)))
    with pytest.raises(ValueError, match="out of range"):
        write_vtp(tmp_path / "x.vtp", np.zeros((2, 3)), lines=[[0, 2]])
    with pytest.raises(ValueError, match="radius"):
        write_vtp(tmp_path / "x.vtp", np.zeros((2, 3)), point_data={"radius": [1.0]})


def test_vtk_files_open_with_vtk_if_installed(tmp_path, scene):
    vtk = pytest.importorskip("vtk")
    files = [write_vtk_spheres(tmp_path / "s.vtp", scene),
             write_vtk_contacts(tmp_path / "c.vtp", scene, encoding="ascii"),
             write_vtk_box(tmp_path / "b.vtp", (0, 0, 0), BOX)]
    for f, npts in zip(files, (scene.num_bodies, scene.num_bodies, 8)):
        r = vtk.vtkXMLPolyDataReader()
        r.SetFileName(str(f))
        r.Update()
        assert r.GetOutput().GetNumberOfPoints() == npts


def test_pvd_is_valid_after_every_entry_and_not_replaced_silently(tmp_path):
    path = tmp_path / "series.pvd"
    pvd = PvdWriter(path)
    for k in range(3):
        pvd.add(0.1 * k, f"vtk/spheres_{k:04d}.vtp")
        entries = ET.parse(path).getroot().findall("Collection/DataSet")
        assert [e.get("file") for e in entries] == [f"vtk/spheres_{i:04d}.vtp"
                                                    for i in range(k + 1)]
        assert float(entries[-1].get("timestep")) == pytest.approx(0.1 * k)
    pvd.add(0.3, tmp_path / "vtk" / "abs.vtp", part=1)  # absolute -> relative to the .pvd
    assert ET.parse(path).getroot().findall("Collection/DataSet")[-1].get("file") == \
        "vtk/abs.vtp"
    with pytest.raises(FileExistsError, match="overwrite=True"):
        PvdWriter(path)
    again = PvdWriter(path, append=True)
    again.add(0.4, "vtk/spheres_0004.vtp")
    assert len(ET.parse(path).getroot().findall("Collection/DataSet")) == 5
    PvdWriter(path, overwrite=True)
    assert len(ET.parse(path).getroot().findall("Collection/DataSet")) == 0


# ---- HDF5 recorder ----------------------------------------------------------------------------


def test_h5_recorder_series_snapshots_units_metadata(tmp_path, scene):
    path = tmp_path / "run.h5"
    meta = {"n": 27, "young_Pa": 1e6, "box": [0.04, 0.04, 0.04], "label": "test",
            "nested": {"a": 1}, "none": None}
    with H5Recorder(path, scene, metadata=meta,
                    snapshot_fields=("positions", "velocities", "radii")) as rec:
        for _ in range(4):
            rec.record()
            scene.run(10)
        assert rec.snapshot() == "000000"
        scene.run(10)
        assert rec.snapshot() == "000001"
    with h5py.File(path, "r") as f:
        assert f.attrs["n"] == 27 and f.attrs["label"] == "test"
        np.testing.assert_array_equal(f.attrs["box"], meta["box"])
        assert f.attrs["parameters_json"].startswith("{")
        g = f["series"]
        assert g.attrs["num_records"] == 4
        assert g["time"].maxshape == (None,) and g["time"].attrs["units"] == "s"
        assert g["kinetic"].attrs["units"] == "J"
        assert g["wall_force_zmin"].shape == (4, 3) and g["wall_force_zmin"].attrs["units"] == "N"
        assert g["wall_force_zmin"].maxshape == (None, 3)
        assert g["step"].dtype.kind == "i"
        snap = f["snapshots/000001"]
        assert snap.attrs["complete"] and snap.attrs["step"] == scene.step_count
        assert snap["positions"].attrs["units"] == "m" and snap["positions"].shape == (27, 3)
        np.testing.assert_array_equal(snap["positions"][()], scene.positions)
    s = read_h5_series(path)
    assert np.all(np.diff(s["time"]) > 0) and np.all(np.diff(s["step"]) == 10)
    last = read_h5_snapshot(path)
    assert last["name"] == "000001" and last["time"] == scene.time


def test_h5_recorder_refuses_to_replace_and_appends(tmp_path, scene):
    path = tmp_path / "run.h5"
    series = {"time": (lambda s: s.time, "s"), "ke": (lambda s: s.energies()["kinetic"], "J")}
    with H5Recorder(path, scene, series=series, metadata={"seed": 1}) as rec:
        rec.record()
        rec.snapshot()
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(FileExistsError, match="overwrite=True"):
        H5Recorder(path, scene, series=series)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest, "file was modified"
    # Append: rows and snapshot numbering continue; conflicting metadata or series refused.
    with H5Recorder(path, scene, series=series, append=True, metadata={"seed": 1}) as rec:
        assert rec.num_records == 1 and rec.num_snapshots == 1
        rec.record()
        assert rec.snapshot() == "000001"
    assert len(read_h5_series(path)["time"]) == 2
    with pytest.raises(ValueError, match="seed"):
        H5Recorder(path, scene, series=series, append=True, metadata={"seed": 2})
    with pytest.raises(ValueError, match="series"):
        H5Recorder(path, scene, series={"time": (lambda s: s.time, "s")}, append=True)
    with H5Recorder(path, scene, series=series, overwrite=True) as rec:
        assert rec.num_records == 0
    assert {k: len(v) for k, v in read_h5_series(path).items()} == {"time": 0, "ke": 0}


def test_h5_recorder_without_scene_takes_values(tmp_path):
    path = tmp_path / "free.h5"
    with H5Recorder(path, None, series={"t": (None, "s"), "f": (None, "N")}) as rec:
        rec.record(t=0.0, f=[1.0, 2.0, 3.0])
        rec.record(t=0.5, f=[4.0, 5.0, 6.0])
        with pytest.raises(ValueError, match="no callable"):
            rec.record(t=1.0)
        with pytest.raises(KeyError, match="undeclared"):
            rec.record(t=1.0, f=[0, 0, 0], g=1.0)
        with pytest.raises(ValueError, match="shape"):
            rec.record(t=1.0, f=[0.0, 0.0])
    s = read_h5_series(path)
    np.testing.assert_array_equal(s["t"], [0.0, 0.5])
    np.testing.assert_array_equal(s["f"], [[1, 2, 3], [4, 5, 6]])


def test_h5_recorder_is_readable_while_open(tmp_path, scene):
    """Flushed after every record: another process sees the rows while the recorder runs."""
    path = tmp_path / "live.h5"
    with H5Recorder(path, scene) as rec:
        for _ in range(3):
            rec.record()
        code = ("from cpp_dem.io import read_h5_series; "
                f"s = read_h5_series({str(path)!r}); print(len(s['time']), s['step'][-1])")
        out = subprocess.run([PYTHON, "-c", code], capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert out.stdout.split() == ["3", str(scene.step_count)]
        assert len(read_h5_series(path)["time"]) == 3  # same process, handle still open


def test_h5_recorder_survives_a_crash(tmp_path):
    """A process that records and is then killed (no close) leaves a readable file."""
    path = tmp_path / "crash.h5"
    code = textwrap.dedent(f"""
        import os, signal
        from cpp_dem.io import H5Recorder
        rec = H5Recorder({str(path)!r}, None, series={{"t": (None, "s"), "v": (None, "m/s")}},
                         metadata={{"case": "crash"}})
        for k in range(5):
            rec.record(t=0.1 * k, v=[k, 2 * k, 3 * k])
        rec.snapshot(extra={{"positions": ([[0.0, 0.0, float(k)]], "m")}})
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    out = subprocess.run([PYTHON, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == -9, (out.returncode, out.stderr)
    s = read_h5_series(path)
    np.testing.assert_allclose(s["t"], 0.1 * np.arange(5))
    np.testing.assert_array_equal(s["v"][-1], [4, 8, 12])
    snap = read_h5_snapshot(path, 0)
    np.testing.assert_array_equal(snap["positions"], [[0, 0, 4]])
    with h5py.File(path, "r") as f:
        assert f.attrs["case"] == "crash"
    with H5Recorder(path, None, series={"t": (None, "s"), "v": (None, "m/s")},
                    append=True) as rec:  # the crashed run can be continued
        rec.record(t=0.5, v=[5, 10, 15])
    assert len(read_h5_series(path)["t"]) == 6


# ---- CSV recorder ------------------------------------------------------------------------------


def test_csv_recorder_rows_units_flush_and_overwrite(tmp_path, scene):
    path = tmp_path / "run.csv"
    series = standard_series(scene)
    with CsvRecorder(path, scene, series=series) as rec:
        rec.record()
        scene.run(10)
        rec.record()
        lines = path.read_text().splitlines()  # flushed: visible before close
        assert len(lines) == 3
        assert rec.units["time"] == "s" and rec.units["wall_force_zmin"] == "N"
    header = lines[0].split(",")
    assert header[:2] == ["time", "step"]
    assert {"wall_force_zmin_x", "wall_force_zmin_y", "wall_force_zmin_z"} <= set(header)
    d = read_csv_series(path)
    assert d["step"][-1] == scene.step_count and d["time"][-1] == scene.time
    assert d["wall_force_zmin_z"][-1] == scene.wall_forces[4][2]
    h = np.genfromtxt(path, delimiter=",", names=True)  # a standard reader
    assert h["time"][-1] == scene.time
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(FileExistsError, match="overwrite=True"):
        CsvRecorder(path, scene, series=series)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    with CsvRecorder(path, scene, series=series, append=True) as rec:
        rec.record()
    assert len(read_csv_series(path)["time"]) == 3
    with pytest.raises(ValueError, match="cannot append"):
        with CsvRecorder(path, scene, series={"time": (lambda s: s.time, "s")},
                         append=True) as rec:
            rec.record()
    with CsvRecorder(path, None, series={"x": (None, "m")}, overwrite=True) as rec:
        rec.record(x=1.5)
    assert read_csv_series(path) == {"x": pytest.approx(np.array([1.5]))}


def test_standard_series_names_and_units(scene):
    s = standard_series(scene)
    for name, units in (("time", "s"), ("step", "-"), ("kinetic", "J"),
                        ("balance_error", "J"), ("unbalanced_force", "-"),
                        ("wall_force_zmin", "N"), ("wall_position_xmax", "m"),
                        ("max_speed", "m/s")):
        assert s[name][1] == units
    assert s["wall_position_xmax"][0](scene) == BOX[0]
    np.testing.assert_array_equal(s["wall_force_zmin"][0](scene), scene.wall_forces[4])
    assert "wall_force_zmin" not in standard_series(None)
