"""Checkpoints (docs/reliability.md, "Checkpoints"): the state carries checksums checked on
load, two identical runs write byte-identical files, and a damaged or incomplete file is
refused with an error naming the file and what is wrong, leaving the scene as it was."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core
from cpp_dem.build import geogrid
from cpp_dem.protocols import periodic
from cpp_dem.build import psd
from cpp_dem.checkpoint import FORMAT, load_checkpoint, save_checkpoint
from cpp_dem.build.packing import loose_cloud
from cpp_dem.protocols.triaxial import build_box_sample

ROOT = Path(__file__).resolve().parents[1]


def box_scene():
    """Spheres in a servo-controlled box growing their radii: materials, walls, sphere and
    wall contacts, two stateful controllers."""
    r = psd.radii_uniform(0.005, 0.001, 150, seed=3)
    c, r = loose_cloud(r * 0.8, (0, 0, 0), (0.06, 0.06, 0.06), seed=3)
    smp = build_box_sample(c, r, (0, 0, 0), (0.06, 0.06, 0.06), young=1e7, poisson=0.3,
                           friction_deg=30, density=2650, local_damping=0.2)
    smp.scene.add_controller(_core.RadiusGrowth(walls=smp.walls, target_stress=3e4,
                                                max_strain=5e-4))
    smp.scene.track_energy = True
    for a in range(3):
        smp.controller.set_stress(a, 3e4)
    smp.controller.enabled = True
    return smp.scene


def grid_scene():
    """Grains on a held geogrid in a box, a pair law, and a bonded pair: grid nodes, links,
    grid contacts, sphere and wall contacts, bonds."""
    s = dem.Scene(gravity=(0, 0, -9.81), local_damping=0.5)
    m = s.add_material(dem.linear_material(density=1000, young=1e8, poisson=0.3,
                                           friction_angle_deg=20))
    p = dem.BeamParams(young=1e8, poisson=0.3, radius=1e-3)
    g = geogrid.square_grid(s, origin=(0, 0, 0.0105), length=0.04, width=0.04, nodes_x=5,
                            nodes_y=5, params=p, material=m, density=1000,
                            node_density_scale=10.0)
    s.block_dofs(g.nodes, "all")
    sand = s.add_material(dem.linear_material(density=2600, young=1e7, poisson=0.3,
                                              friction_angle_deg=30, rolling_stiffness=1.0,
                                              rolling_friction=0.1))
    s.set_pair_law(m, sand, friction=0.4)
    walls = s.add_box((-0.004, -0.004, 0), (0.044, 0.044, 0.04), material=sand)
    # A grain on every node (0.1 mm overlap), and one more on each of those.
    lay = np.stack(np.meshgrid(np.arange(5), np.arange(5), indexing="ij"), -1).reshape(-1, 2)
    on = np.column_stack([lay * 0.01, np.full(len(lay), 0.0149)])
    s.add_spheres(np.vstack([on, on + [0, 0, 0.0069]]), np.full(2 * len(on), 0.0035),
                  material=sand)
    ids = s.add_spheres([[0.015, 0.015, 0.032], [0.0215, 0.015, 0.032]], [0.00325, 0.00325],
                        material=sand)
    s.add_bond(int(ids[0]), int(ids[1]), dem.BondParams(kn=1e5, ks=1e5, friction=0.5,
                                                        pb_kn=1e12, pb_ks=1e12))
    s.set_auto_timestep(safety=0.3, period=20)
    s.set_wall_velocity(walls[5], [0, 0, -0.02])
    return s


def cell_scene():
    """A few grains in a periodic cell under a velocity gradient."""
    s = dem.Scene(dt=1e-5)
    m = s.add_material(dem.linear_material(density=2650, young=1e8, poisson=0.3,
                                           friction_angle_deg=30))
    # Two pairs in contact, one of them across the cell's face z = 0.
    x = np.array([[1e-3, 2e-3, 3e-3], [7e-3, 5e-3, 1e-3], [4e-3, 8e-3, 6e-3],
                  [4e-3, 8e-3, 8.4e-3], [4e-3, 8e-3, 0.9e-3]])
    s.add_spheres(x, [1.3e-3] * 5, material=m)
    s.set_periodic_cell(periodic.cube_cell(10e-3))
    s.velocity_gradient = np.array([[-20.0, 1.0, 0.0], [0.0, -20.0, 0.5], [0.0, 0.0, -20.0]])
    return s


SCENES = {"box": (box_scene, 400), "grid": (grid_scene, 250), "cell": (cell_scene, 350)}


def fresh(kind, steps):
    s = SCENES[kind][0]()
    s.run(steps)
    return s


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """One checkpoint of the box scene after 400 steps (read-only; tests copy it)."""
    path = tmp_path_factory.mktemp("ck") / "ck.h5"
    save_checkpoint(path, fresh("box", 400), extra={"walls": [0, 1, 2, 3, 4, 5]})
    return path


def copy(saved, tmp_path):
    p = tmp_path / "ck.h5"
    shutil.copyfile(saved, p)
    return p


def flip_byte(path, dataset, at):
    """Flips the bits of byte `at` of `dataset`'s data in the file, as a damaged disk would."""
    with h5py.File(path, "r") as f:
        off = f[dataset].id.get_offset()
        assert off is not None  # contiguous, uncompressed
    with open(path, "r+b") as fh:
        fh.seek(off + at)
        b = fh.read(1)
        fh.seek(off + at)
        fh.write(bytes([b[0] ^ 0xFF]))


@pytest.mark.parametrize("kind", sorted(SCENES))
def test_two_identical_runs_write_byte_identical_checkpoints(kind, tmp_path):
    # The records are copied byte for byte: padding left uninitialised made 145 of 147 463
    # bytes of the box scene's state differ between two identical runs (walls, wall and pair
    # contacts, the cell); HDF5 object time stamps made the files differ too.
    a = fresh(kind, SCENES[kind][1])
    blob_a = bytes(_core._checkpoint_save(a))
    save_checkpoint(tmp_path / "a.h5", a, extra={"k": 1})
    time.sleep(1.1)  # HDF5 time stamps have a resolution of one second
    b = fresh(kind, SCENES[kind][1])
    assert np.array_equal(a.positions, b.positions)  # the same run
    assert bytes(_core._checkpoint_save(b)) == blob_a
    save_checkpoint(tmp_path / "b.h5", b, extra={"k": 1})
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()


@pytest.mark.parametrize("kind", sorted(SCENES))
def test_a_run_continued_from_a_checkpoint_equals_the_uninterrupted_run(kind, tmp_path):
    n = SCENES[kind][1]
    a = fresh(kind, n)
    save_checkpoint(tmp_path / "ck.h5", a)
    a.run(n)
    b = SCENES[kind][0]()
    load_checkpoint(tmp_path / "ck.h5", b)
    b.run(n)
    assert bytes(_core._checkpoint_save(a)) == bytes(_core._checkpoint_save(b))


def test_a_flipped_byte_in_the_state_is_refused_naming_file_and_dataset(saved, tmp_path):
    p = copy(saved, tmp_path)
    with h5py.File(p, "r") as f:
        n = f["checkpoint/blob"].shape[0]
    flip_byte(p, "checkpoint/blob", n // 3)  # inside the body arrays: loads silently unchecked
    s = box_scene()
    s.run(3)
    before = bytes(_core._checkpoint_save(s))
    with pytest.raises(dem.ParameterError,
                       match=re.escape(str(p)) + r": dataset checkpoint/blob does not match "
                       r"its checksum"):
        load_checkpoint(p, s)
    assert bytes(_core._checkpoint_save(s)) == before  # the scene is left as it was


def test_a_changed_header_is_refused(saved, tmp_path):
    p = copy(saved, tmp_path)
    with h5py.File(p, "r+") as f:
        f.attrs["extra_json"] = json.dumps({"walls": [0, 1, 2, 3, 4, 9]})
    with pytest.raises(dem.ParameterError, match=r"ck\.h5: the header .*extra_json.* does not "
                       r"match its checksum"):
        load_checkpoint(p, box_scene())


def test_a_damaged_readable_copy_is_reported_and_the_state_still_loads(saved, tmp_path):
    p = copy(saved, tmp_path)
    flip_byte(p, "readable/positions", 5)
    s = box_scene()
    with pytest.warns(UserWarning, match=r"dataset readable/positions does not match its "
                      r"checksum.*the state is intact"):
        extra = load_checkpoint(p, s)
    assert extra == {"walls": [0, 1, 2, 3, 4, 5]}
    with h5py.File(saved, "r") as f:
        assert bytes(_core._checkpoint_save(s)) == f["checkpoint/blob"][()].tobytes()


def rewrite_header(path, extra_json):
    """Sets extra_json and a matching header checksum: a file whose writer stored bad JSON."""
    from cpp_dem.checkpoint import _header_sha256

    with h5py.File(path, "r+") as f:
        f.attrs["extra_json"] = extra_json
        f.attrs["header_sha256"] = _header_sha256(FORMAT, f.attrs["step"], f.attrs["time"],
                                                  extra_json)


@pytest.mark.parametrize("text, msg", [
    ("{walls: [0, 1]", r"attribute extra_json is not readable JSON \(Expecting property name"),
    ("[1, 2]", r"attribute extra_json holds a list, expected a JSON object"),
])
def test_unreadable_extra_json_names_the_file_and_the_attribute(saved, tmp_path, text, msg):
    p = copy(saved, tmp_path)
    rewrite_header(p, text)
    with pytest.raises(dem.ParameterError, match=re.escape(str(p)) + ": " + msg):
        load_checkpoint(p, box_scene())


@pytest.mark.parametrize("what, msg", [
    ("blob", r"no dataset checkpoint/blob \(the scene's state\); the file is not a complete "
             r"checkpoint"),
    ("group", r"no dataset checkpoint/blob"),
    ("checksum", r"dataset checkpoint/blob carries no checksum"),
    ("extra_json", r"attribute extra_json missing"),
    ("format", r"format None, expected 'cpp_dem.checkpoint/2'"),
])
def test_a_missing_part_names_the_file_and_the_part(saved, tmp_path, what, msg):
    p = copy(saved, tmp_path)
    with h5py.File(p, "r+") as f:
        if what == "blob":
            del f["checkpoint/blob"]
        elif what == "group":
            del f["checkpoint"]
        elif what == "checksum":
            del f["checkpoint/blob"].attrs["sha256"]
        else:
            del f.attrs[what]
    with pytest.raises(dem.ParameterError, match=re.escape(str(p)) + ": " + msg):
        load_checkpoint(p, box_scene())


def test_errors_of_the_state_name_the_file(saved):
    with pytest.raises(dem.ParameterError, match=re.escape(str(saved)) + r": checkpoint: the "
                       r"saved scene had 2 controllers, this scene has 0"):
        load_checkpoint(saved, dem.Scene())


def test_a_checkpoint_of_the_format_without_checksums_loads_with_a_warning(saved, tmp_path):
    p = tmp_path / "old.h5"
    with h5py.File(saved, "r") as f, h5py.File(p, "w") as g:
        g.attrs["format"] = "cpp_dem.checkpoint/1"
        for k in ("step", "time", "extra_json"):
            g.attrs[k] = f.attrs[k]
        for name in ("checkpoint/blob", "readable/positions", "readable/velocities",
                     "readable/radii", "readable/wall_positions", "readable/wall_velocities"):
            g.create_dataset(name, data=f[name][()])
        blob = f["checkpoint/blob"][()].tobytes()
    s = box_scene()
    with pytest.warns(UserWarning, match=r"old\.h5: a checkpoint of format 'cpp_dem.checkpoint/1'"
                      r", written before checkpoints carried checksums: it is loaded unverified"):
        load_checkpoint(p, s)
    assert bytes(_core._checkpoint_save(s)) == blob


def test_extra_that_is_not_json_is_refused_before_writing(tmp_path):
    with pytest.raises(dem.ParameterError, match=r"extra=\{'f': <built-in function print>\}: must be a dict of "
                       r"JSON values"):
        save_checkpoint(tmp_path / "x.h5", dem.Scene(), extra={"f": print})
    assert not list(tmp_path.iterdir())


def test_the_saved_records_have_no_implicit_padding():
    """Every record the checkpoint copies byte for byte (the sizes in its layout fingerprint)
    has its padding as explicit zero members: GCC's -Wpadded finds none. A record given a field
    that leaves a gap must fill it, or two identical runs write different checkpoints."""
    gxx = shutil.which("g++")
    eigen = Path("/usr/include/eigen3")
    if gxx is None or not eigen.is_dir():
        pytest.skip("needs g++ and Eigen (make setup installs both)")
    src = ROOT / "cpp_dem" / "src" / "checkpoint.cpp"
    body = src.read_text().split("std::vector<std::uint64_t> layout(")[1].split("\n}\n")[0]
    records = set(re.findall(r"sizeof\((\w+)\)", body)) - {"Real", "Vec3", "Quat"}
    assert {"Wall", "WallOpening", "PairContactDisk", "WallContact", "GridContact",
            "Bond"} <= records
    r = subprocess.run([gxx, "-std=c++17", "-fsyntax-only", "-fopenmp", "-Wpadded",
                        f"-I{ROOT / 'cpp_dem' / 'include'}", f"-I{eigen}",
                        "-DEIGEN_DONT_PARALLELIZE", str(src)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    found = []
    for line in r.stderr.splitlines():
        m = re.search(r"padding struct to align .cpp_dem::(\w+)::", line)
        if m and m.group(1) in records:
            found.append(line)
        m = re.match(r"(.*?):(\d+):\d+: warning: padding struct size to alignment", line)
        if m and "eigen3" not in m.group(1):
            decl = Path(m.group(1)).read_text().splitlines()[int(m.group(2)) - 1]
            name = re.search(r"struct\s+(\w+)", decl)
            if name and name.group(1) in records:
                found.append(line)
    assert not found, "\n".join(found)
