"""The pair contacts' cold part (PairContactCold: the law's full parameters, the rolling moment,
the viscous dissipation) is kept only by a scene one of whose material pairs takes a kernel
that reads it (dashpots, rolling resistance, the composed law); with the short kernels alone
the hot record holds all the law's parameters (docs/core.md, "Contact storage"). Nothing but
the memory changes: the same bits with the cold part or without it, and a checkpoint of the
format before (14, the cold part in every scene, the friction dissipation in it) continues as
the build that wrote it did."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core

REG = Path(__file__).resolve().parent / "regression"


def _scene(kind: str, extra_damped_material: bool = False) -> dem.Scene:
    """tests/regression/make_checkpoints_v14.py's scene: 80 spheres dropped into a box."""
    sys.path.insert(0, str(REG))
    from make_checkpoints_v14 import scene

    return scene(kind, extra_damped_material)


@pytest.mark.parametrize("kind", ["linear", "hertz_short"])
def test_the_short_kernels_give_the_same_bits_with_or_without_the_cold_part(kind):
    a, b = _scene(kind), _scene(kind, extra_damped_material=True)
    a.run(6000)
    b.run(6000)
    fa, fb = a.memory_by_field(), b.memory_by_field()
    assert fa["contacts.pair_cold"] == 0  # (short kernels only)
    assert fb["contacts.pair_cold"] >= 104 * a.num_active_contacts > 0
    assert a.num_active_contacts == b.num_active_contacts > 20
    for name in ("positions", "velocities", "angular_velocities"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    ea, eb = a.energies(), b.energies()
    assert ea["friction"] == eb["friction"] > 0  # (slip happened: its dissipation is kept)
    ca, cb = a.contacts(), b.contacts()
    for key in ("kn", "ks", "tan_phi", "force"):
        assert np.array_equal(ca[key], cb[key]), key
    # a checkpoint without the cold part restores it as it was
    c = dem.Scene()
    _core._checkpoint_load(c, _core._checkpoint_save(a), replace=True)
    assert c.memory_by_field()["contacts.pair_cold"] == 0
    a.run(200)
    c.run(200)
    assert np.array_equal(a.positions, c.positions)


def test_a_damped_material_given_during_a_run_brings_the_cold_part():
    """A scene that starts with the short kernel and is given dashpots later keeps the cold
    part from then on, and runs as a scene that had it from the start."""
    a, b = _scene("linear"), _scene("linear", extra_damped_material=True)
    a.run(1000)
    b.run(1000)
    damped = dem.linear_material(density=2650, young=5e6, poisson=0.3, friction_angle_deg=25,
                                 damping_normal=0.3)
    for s in (a, b):
        m = s.add_material(damped)
        for body in range(s.num_bodies):
            s.set_body_material(body, m)
    assert a.memory_by_field()["contacts.pair_cold"] == 0  # (not until the next step)
    a.run(500)
    b.run(500)
    assert a.memory_by_field()["contacts.pair_cold"] > 0
    assert np.array_equal(a.positions, b.positions)
    assert a.energies()["viscous"] == b.energies()["viscous"]


@pytest.mark.parametrize("kind", ["linear", "hertz"])
def test_a_format_14_checkpoint_continues_as_the_build_that_wrote_it(kind):
    """tests/regression/make_checkpoints_v14.py, run by the build before this format: its
    checkpoint after 3000 steps and its state 300 steps later (the hertz scene has dashpots
    and rolling resistance: the composed law, with the cold part)."""
    ref = np.load(REG / f"pair_cold_{kind}_v14.npz")
    s = dem.Scene()
    _core._checkpoint_load(s, ref["blob"].tobytes(), replace=True)
    s.run(300)
    assert s.num_active_contacts == int(ref["active"])
    for name, key in (("positions", "positions"), ("velocities", "velocities"),
                      ("angular_velocities", "angvel")):
        assert np.array_equal(getattr(s, name), ref[key]), name
    e = s.energies()
    assert e["friction"] == float(ref["friction"]) and e["viscous"] == float(ref["viscous"])


def _pile(kind: str) -> dem.Scene:
    """384 spheres dropped into a box (about 1 000 candidate pairs: the pass runs threaded
    on two threads), two of them pushed by an external force."""
    sys.path.insert(0, str(REG))
    from make_checkpoints_v14 import scene

    s = scene(kind, nx=8, nz=6)
    f = np.zeros((s.num_bodies, 3))
    f[[5, 200]] = [[1e-3, 0, 0], [0, -2e-3, 1e-3]]
    s.external_forces = f
    return s


_KEPT = ("contacts.pair_out", "contacts.pair_jslot", "contacts.pair_jadj_off",
         "scratch.pair_fi", "scratch.pair_ti")
_CROSS = ("scratch.pair_cross", "scratch.pair_cross_k", "scratch.pair_cross_j")


def _kept(s) -> dict:
    """Bytes of the arrays that only a pass keeping its outputs (the cold part) has, and of
    a threaded direct pass's cross pairs."""
    f = s.memory_by_field()
    return {k: f[k] for k in _KEPT + _CROSS}


@pytest.mark.parametrize("kind", ["linear", "hertz_short", "hertz"])
def test_one_two_and_three_threads_give_the_same_bits(kind):
    """With the short kernels alone the pair pass adds each contact's share to its bodies'
    sums (starting from the external force and the weight) and keeps no outputs, on one
    thread and on more: there each thread sums its own bodies, and the contacts whose second
    body another thread sums (cross pairs) have their shares computed first and added in
    their place. With the composed law ("hertz": dashpots, rolling) the pass keeps its
    outputs and the reduction sums them. The same bits either way, the same contact forces,
    the same checkpoint bytes."""
    before = dem.get_num_threads()
    runs = []
    try:
        for t in (1, 2, 3):
            dem.set_num_threads(t)
            s = _pile(kind)
            s.run(3000)
            runs.append((s, _kept(s), _core._checkpoint_save(s)))
    finally:
        dem.set_num_threads(before)
    (a, kept_a, blob_a) = runs[0]
    # (one thread keeps neither the outputs nor their slots nor the bodies' scratch sums,
    # without the cold part)
    if kind != "hertz":
        assert kept_a == dict.fromkeys(_KEPT + _CROSS, 0), kept_a
    assert len(a.contacts()["force"]) > 200
    for b, kept_b, blob_b in runs[1:]:
        if kind == "hertz":
            assert all(kept_b[k] > 0 for k in _KEPT) and not any(kept_b[k] for k in _CROSS)
        else:
            assert not any(kept_b[k] for k in _KEPT), kept_b
            assert all(kept_b[k] > 0 for k in _CROSS), kept_b  # (cross pairs exist)
        for name in ("positions", "velocities", "angular_velocities", "forces", "torques"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        ca, cb = a.contacts(), b.contacts()
        assert np.array_equal(ca["force"], cb["force"]) and np.array_equal(ca["ids"], cb["ids"])
        assert blob_a == blob_b


def test_the_cross_pairs_shares_in_another_order_would_change_the_bits():
    """The threaded direct pass is bitwise the one-thread pass because each cross pair's
    share enters its bodies' sums where the one-thread pass adds it. The measure can fail:
    the same forces summed with the cross shares last, not first, differ in the last bits
    (numpy, on the run's own contact forces)."""
    dem.set_num_threads(1)
    s = _pile("linear")
    s.run(3000)
    c = s.contacts()
    ids, f = np.asarray(c["ids"]), np.asarray(c["force"])
    pairs = [(k, int(a), int(b)) for k, (a, b) in enumerate(ids) if b >= 0]
    # body j's sum of its shares in contact order, and with a "cross" half (even k) moved last
    differs = 0
    for j in range(s.num_bodies):
        mine = [k for k, a, b in pairs if b == j]
        if len(mine) < 3:
            continue
        x = 0.0
        for k in mine:
            x = x + f[k]
        y = 0.0
        for k in [k for k in mine if k % 2] + [k for k in mine if not k % 2]:
            y = y + f[k]
        differs += int(not np.array_equal(x, y))
    assert differs > 0


@pytest.mark.parametrize("kind", ["linear", "hertz"])
def test_a_blob_rewritten_as_format_14_runs_on_to_the_same_bits(kind):
    """tests/test_yade_kinematics.py's rewriting of a format-15 blob as format 14 (every
    contact with the cold part, the dissipation in it, the outputs kept) loads and runs on as
    the blob itself: the short kernels without the cold part, the composed law with it."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_yade_kinematics import _format_14

    s = _scene(kind)
    s.run(3000)
    blob = bytes(_core._checkpoint_save(s))
    a, b = dem.Scene(), dem.Scene()
    _core._checkpoint_load(a, blob, replace=True)
    _core._checkpoint_load(b, _format_14(blob), replace=True)
    assert b.memory_by_field()["contacts.pair_cold"] > 0  # (format 14: every scene had it)
    a.run(300)
    b.run(300)
    assert np.array_equal(a.positions, b.positions)
    assert a.energies()["friction"] == b.energies()["friction"]


def test_threads_changed_between_steps_give_the_one_thread_bits():
    """A run that goes from one thread to two and back (the pass making the cross pairs'
    index for two threads, with a rebuild of the contacts in each part) ends on the bits of
    a run on one thread."""
    before = dem.get_num_threads()
    try:
        dem.set_num_threads(1)
        ref = _pile("linear")
        ref.run(3000)
        s = _pile("linear")
        builds = []
        for t, n in ((1, 800), (2, 1200), (1, 1000)):
            dem.set_num_threads(t)
            b0 = s.collider_stats()["builds"]
            s.run(n)
            builds.append(s.collider_stats()["builds"] - b0)
            # (two threads: the cross pairs' index, made again after each build)
            assert (_kept(s)["scratch.pair_cross"] > 0) == (t == 2)
            assert _kept(s)["contacts.pair_jslot"] == 0
    finally:
        dem.set_num_threads(before)
    assert all(b > 0 for b in builds), builds
    for name in ("positions", "velocities", "angular_velocities", "forces", "torques"):
        assert np.array_equal(getattr(ref, name), getattr(s, name)), name
