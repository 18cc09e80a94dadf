"""Issue 60, items 3 and 7: a checkpoint loads only into the scene it came from (or a blank
one, or with ``replace=True``), its stored values pass the API's own checks, and a refused load
leaves the scene as it was; element states are a documented format that is parsed, never
unpickled."""

import hashlib
import os
import pickle
import struct

import h5py
import numpy as np
import pytest

import cpp_dem as cd
from cpp_dem import _core
from cpp_dem.checkpoint import _sha256, load_checkpoint, save_checkpoint

R = 0.004123  # a radius no other stored number equals (patched in the blobs below)


def _material(s):
    return s.add_material(cd.linear_material(density=2650, young=1e8, poisson=0.3,
                                             friction_angle_deg=30.0))


def box_scene(n=27, walls=((2, 0.0, 1),), controller=None):
    """n spheres on a grid above the walls."""
    s = cd.Scene(gravity=(0, 0, -9.81))
    m = _material(s)
    k = round(n ** (1 / 3)) + 1
    pos = [[0.01 * (i % k), 0.01 * ((i // k) % k), 0.006 + 0.01 * (i // (k * k))]
           for i in range(n)]
    s.add_spheres(pos, [R] * n, material=m)
    for axis, position, sense in walls:
        s.add_wall(axis=axis, position=position, sense=sense, material=m)
    if controller == "servo":
        s.add_controller(_core.ServoWall(wall=0, target_stress=1e3, area=1e-2, max_speed=0.1))
    elif controller == "cell":
        s.add_controller(_core.CellController(gain=0.1, max_rate=1.0))
    s.dt = 1e-6
    return s


def periodic_scene(n=27):
    s = cd.Scene()
    m = _material(s)
    k = round(n ** (1 / 3))
    pos = [[0.01 * (i % k) + 0.005, 0.01 * ((i // k) % k) + 0.005, 0.01 * (i // (k * k)) + 0.005]
           for i in range(n)]
    s.add_spheres(pos, [R] * n, material=m)
    s.set_periodic_cell(0.01 * k * np.eye(3), (True, True, True))
    s.dt = 1e-6
    return s


def state(s) -> bytes:
    return bytes(_core._checkpoint_save(s))


def rewrite_file(path, blob: bytes) -> None:
    """Puts ``blob`` into the checkpoint file at ``path`` with valid checksums (as an edit by
    someone who knows the format would): only the loader's own checks can refuse it."""
    with h5py.File(path, "r+") as f:
        del f["checkpoint/blob"]
        a = np.frombuffer(blob, dtype=np.uint8)
        d = f["checkpoint"].create_dataset("blob", data=a, track_times=False)
        d.attrs["sha256"] = _sha256(a)


# ---- 3. a checkpoint loads only into the scene it came from --------------------------------

def test_a_periodic_cells_checkpoint_does_not_turn_a_walled_box_into_a_cell(tmp_path):
    cell = periodic_scene()
    cell.run(3)
    save_checkpoint(tmp_path / "cell.h5", cell)
    box = box_scene(27, walls=((2, 0.0, 1),))
    before = state(box)
    with pytest.raises(cd.ParameterError, match=r"cell\.h5: checkpoint: the saved scene is a "
                       r"periodic cell \(periodic along xyz\), this scene is not periodic.*"
                       r"replace=True"):
        load_checkpoint(tmp_path / "cell.h5", box)
    assert state(box) == before and not box.is_periodic
    # Asked for, it replaces the scene.
    load_checkpoint(tmp_path / "cell.h5", box, replace=True)
    assert box.is_periodic and state(box) == state(cell)


def test_a_27_sphere_checkpoint_into_a_64_sphere_scene_is_refused_not_truncated(tmp_path):
    small = box_scene(27)
    small.run(2)
    save_checkpoint(tmp_path / "s.h5", small)
    big = box_scene(64)
    before = state(big)
    with pytest.raises(cd.ParameterError, match=r"the saved scene has 27 bodies, this scene "
                       r"has 64; load a checkpoint into the scene it came from"):
        load_checkpoint(tmp_path / "s.h5", big)
    assert state(big) == before and len(big.positions) == 64
    with pytest.raises(cd.ParameterError, match="27 bodies, this scene has 64"):
        _core._checkpoint_load(big, state(small))  # the bytes path too
    assert state(big) == before


def test_bodies_kinds_walls_and_controllers_must_match():
    # A clump's members against free spheres, body count equal.
    a = cd.Scene()
    m = _material(a)
    a._add_clump(np.array([[-0.004, 0, 0], [0.004, 0, 0]]), np.array([R, R]), material=m,
                 mass=1e-3, inertia=np.array([1e-9, 2e-9, 2e-9]), com=np.array([0, 0, 0.01]),
                 ori=np.array([1.0, 0, 0, 0]))
    b = cd.Scene()
    _material(b)
    b.add_spheres([[0, 0, 0.01], [0.02, 0, 0.01]], [R, R], material=0)
    with pytest.raises(cd.ParameterError, match=r"saved scene has 1 clumps, this scene has 0"):
        _core._checkpoint_load(b, state(a))
    # Walls: same count, another side.
    up, down = box_scene(8, walls=((2, 0.0, 1),)), box_scene(8, walls=((2, 0.1, -1),))
    with pytest.raises(cd.ParameterError, match=r"wall 0 faces \+z in the saved scene, -z in "
                       "this one"):
        _core._checkpoint_load(down, state(up))
    with pytest.raises(cd.ParameterError, match=r"saved scene has 1 walls, this scene has 2"):
        _core._checkpoint_load(box_scene(8, walls=((2, 0.0, 1), (0, 0.0, 1))), state(up))
    # Controllers of the same count, another kind (neither keeps state: passed before).
    servo, cell = box_scene(8, controller="servo"), box_scene(8, controller="cell")
    before = state(cell)
    with pytest.raises(cd.ParameterError, match=r"controller 0 is a CellController in this "
                       r"scene, a ServoWall in the saved one"):
        _core._checkpoint_load(cell, state(servo))
    with pytest.raises(cd.ParameterError, match=r"controller 0 is a CellController"):
        _core._checkpoint_load(cell, state(servo), replace=True)  # controllers are code
    assert state(cell) == before


def test_a_blank_scene_takes_any_checkpoint_and_the_same_scene_runs_on_bitwise(tmp_path):
    a = box_scene(27)
    a.run(5)
    save_checkpoint(tmp_path / "a.h5", a)
    blank = cd.Scene()
    load_checkpoint(tmp_path / "a.h5", blank)
    same = box_scene(27)
    load_checkpoint(tmp_path / "a.h5", same)
    a.run(20)
    blank.run(20)
    same.run(20)
    assert state(blank) == state(a) == state(same)
    with pytest.raises(cd.ParameterError, match=r"replace='yes': must be True or False"):
        load_checkpoint(tmp_path / "a.h5", cd.Scene(), replace="yes")


# ---- stored values pass the API's checks ----------------------------------------------------

def _patched(blob: bytes, old: bytes, new: bytes) -> bytes:
    assert old in blob
    return blob.replace(old, new)


def test_a_stored_wall_opening_the_api_refuses_is_refused(tmp_path):
    s = box_scene(8, walls=((2, 0.0, 1),))
    s.set_wall_opening(0, axis=0, lo=0.01, hi=0.03)
    with pytest.raises(cd.ParameterError, match="hi"):
        s.set_wall_opening(0, axis=0, lo=0.03, hi=0.01)  # what the API says
    save_checkpoint(tmp_path / "o.h5", s)
    bad = _patched(state(s), struct.pack("<iidd", 0, 0, 0.01, 0.03),
                   struct.pack("<iidd", 0, 0, 0.03, 0.01))
    rewrite_file(tmp_path / "o.h5", bad)
    t = box_scene(8, walls=((2, 0.0, 1),))
    before = state(t)
    with pytest.raises(cd.ParameterError, match=r"o\.h5: checkpoint: stored wall 0: hi=0\.01: "
                       r"must be finite and above lo=0\.03"):
        load_checkpoint(tmp_path / "o.h5", t)
    assert state(t) == before and t.wall_opening(0)[0] == -1


@pytest.mark.parametrize("what, old, new, message", [
    ("radius", struct.pack("<d", R), struct.pack("<d", -R), r"stored bodies: radius=-0\.004123"),
    ("dt", struct.pack("<d", 1.25e-6), struct.pack("<d", -1.25e-6),
     r"stored parameters: dt=-1\.25e-06: must be > 0"),
    ("mass", None, None, r"stored body 0: mass=-1: must be > 0 \(kg\)"),
    ("nan position", struct.pack("<d", 0.006), struct.pack("<d", float("nan")),
     r"stored bodies: position of sphere 0: must be finite"),
])
def test_stored_values_go_through_the_setters_checks(what, old, new, message):
    s = box_scene(8)
    s.dt = 1.25e-6
    if what == "mass":
        s.set_mass_inertia(0, 0.123456, 7.5e-9)
        old, new = struct.pack("<d", 0.123456), struct.pack("<d", -1.0)
    blob = _patched(state(s), old, new)
    t = box_scene(8)
    before = state(t)
    with pytest.raises(cd.ParameterError, match=message):
        _core._checkpoint_load(t, blob)
    assert state(t) == before
    with pytest.raises(cd.ParameterError, match=message):
        _core._checkpoint_load(cd.Scene(), blob, replace=True)  # with replace too


# ---- 7. element states: parsed, never executed ---------------------------------------------

class _Plant:
    """A pickle that creates a file when it is unpickled."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def _payloads(path):
    evil = pickle.dumps(_Plant(str(path)))
    assert pickle.loads(evil) and os.path.exists(path)  # the payload works ...
    os.unlink(path)
    return evil


def test_a_pickle_payload_is_refused_and_runs_nothing(tmp_path):
    from cpp_dem.elements.interface import RunnerElement
    from cpp_dem.elements.linear import LinearElement
    from cpp_dem.elements.periodic import DemElement
    from cpp_dem.elements.pool import ElementPool
    from femcoupling.materials.dem_elements import PeriodicRegionElement

    planted = tmp_path / "planted"
    evil = _payloads(planted)
    for load in (DemElement.from_bytes, LinearElement.from_bytes, RunnerElement.from_bytes,
                 PeriodicRegionElement(n=10).set_state):
        with pytest.raises(cd.ParameterError, match=r"data: not a saved .*magic.*never "
                           r"unpickled"):
            load(evil)
        assert not planted.exists(), load
    # A region's disk cache holding it: refused naming the file.
    import json
    from types import SimpleNamespace

    runner = PeriodicRegionElement(n=10, cache_dir=str(tmp_path / "cache"))
    s0 = -1e4 * np.eye(3)
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / "a_initial.bin").write_bytes(evil)
    (tmp_path / "cache" / "a_initial.key.json").write_text(json.dumps(
        {"stress_pa": s0.tolist(), "settings": runner._settings()}))
    with pytest.raises(cd.ParameterError, match=r"a_initial\.bin: data: not a saved DemElement"):
        runner.prepare("a", SimpleNamespace(fem_stress_pa=s0))
    assert not planted.exists()
    # The pool refuses it before a cluster starts, naming the element.
    with pytest.raises(cd.ParameterError, match=r"data\[1\]: not a saved LinearElement"):
        ElementPool([LinearElement(1e7, 0.3).to_bytes(), evil], element_type=LinearElement,
                    workers=1)
    assert not planted.exists()


def test_element_bytes_round_trip_and_refuse_a_wrong_magic_version_or_checksum():
    from cpp_dem.elements import state_format
    from cpp_dem.elements.linear import LinearElement
    from cpp_dem.elements.periodic import DemElement

    el = DemElement.periodic(30, stress=50e3, seed=3)
    data = el.to_bytes()
    assert data[:8] == state_format.MAGIC
    back = DemElement.from_bytes(data)
    assert back.to_bytes() == data
    de = np.diag([-2e-4, 1e-4, 0.0])
    assert np.array_equal(back.apply_strain(de), el.apply_strain(de))  # bitwise
    assert back.to_bytes() == el.to_bytes()
    lin = LinearElement(2e7, 0.25, -1e5 * np.eye(3)).to_bytes()
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 1
    with pytest.raises(cd.ParameterError, match=r"data: a saved DemElement whose SHA-256 "
                       "checksum does not match"):
        DemElement.from_bytes(bytes(flipped))
    with pytest.raises(cd.ParameterError, match="checksum does not match"):
        DemElement.from_bytes(data[:-1])
    v2 = bytearray(data)
    v2[8:12] = (2).to_bytes(4, "little")
    with pytest.raises(cd.ParameterError, match=r"data: element format version 2, this build "
                       "reads version 1"):
        DemElement.from_bytes(bytes(v2))
    with pytest.raises(cd.ParameterError, match=r"the bytes of 'cpp_dem.LinearElement', "
                       r"expected 'cpp_dem.DemElement'"):
        DemElement.from_bytes(lin)
    # A well-formed record whose values the element's setters refuse.
    fields, parts = state_format.unpack(data, "cpp_dem.DemElement")
    fields["kind"] = "sphere"
    with pytest.raises(cd.ParameterError, match=r"malformed field: kind='sphere'"):
        DemElement.from_bytes(state_format.pack("cpp_dem.DemElement", fields, parts))
    fields, parts = state_format.unpack(lin, "cpp_dem.LinearElement")
    fields["poisson"] = 0.7
    with pytest.raises(cd.ParameterError, match=r"poisson=0\.7: must be in"):
        LinearElement.from_bytes(state_format.pack("cpp_dem.LinearElement", fields, parts))


class _Echo:
    def __call__(self, name, initial, final):
        return name


def test_runner_element_bytes_restore_only_in_the_session_that_signed_them():
    from cpp_dem.elements.interface import RunnerElement, RunnerFactory

    el = RunnerFactory(_Echo(), ["a"])(0)
    assert RunnerElement.from_bytes(el.to_bytes()).name == "a"
    other = RunnerElement(_Echo(), "a", key=hashlib.sha256(b"another session").digest())
    with pytest.raises(cd.ParameterError, match=r"not signed in this session .* hold code"):
        RunnerElement.from_bytes(other.to_bytes())
