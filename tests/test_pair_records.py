"""Pair contact records only for the candidates that carry history (docs/core.md, "Contact
storage"): a candidate pair that does not touch is its entry in the broad phase's rows, and
takes a record the step it first touches. Nothing but the memory changes: the states of
scenes where contacts form and open between builds are those of the build before, to the
bit; the records are in candidate order whatever the threads; a checkpoint still holds a
record for every candidate."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import _core

REG = Path(__file__).resolve().parent / "regression"
sys.path.insert(0, str(REG))
from make_pair_records_ref import STEPS, scene, state  # noqa: E402


def _lattice(gap: float) -> dem.Scene:
    """4 x 4 x 4 spheres (R 1 mm), touching their neighbours along x (overlap 2 um) and
    `gap` apart along y and z (within the broad phase's margin, 0.2 R: candidates)."""
    s = dem.Scene(dt=1e-6)
    m = s.add_material(dem.linear_material(density=2650, young=1e8, poisson=0.3,
                                           friction_angle_deg=30))
    r = 1e-3
    ax = np.arange(4)
    x, y, z = np.meshgrid(ax * (2 * r - 2e-6), ax * (2 * r + gap), ax * (2 * r + gap),
                          indexing="ij")
    s.add_spheres(np.column_stack([x.ravel(), y.ravel(), z.ravel()]), np.full(64, r),
                  material=m)
    return s


def test_a_candidate_that_does_not_touch_has_no_record():
    s = _lattice(gap=0.1e-3)
    s.run(1)
    st = s.collider_stats()
    # 3 x 16 touching pairs along x; 2 x 48 candidates along y and z (and the diagonals
    # within reach) that do not touch
    assert s.num_active_contacts == 48
    assert st["pair_candidates"] >= 48 + 96
    assert st["pair_records"] == 48
    f = s.memory_by_field()
    assert f["contacts.pairs"] < 104 * st["pair_candidates"]
    assert "contacts.pair_slot" not in f  # (a candidate: 4 B, its record slot or its j)
    # (the active contacts' arrays: the 48 along x)
    c = s.contacts()
    assert len(c["force"]) == 48


def test_a_contact_formed_between_builds_takes_its_record_and_the_law_s_force():
    """Two spheres approaching along x (a candidate at the build, not touching) touch some
    steps later without a new build: the pass makes the record, and the force is the linear
    law's k_n delta."""
    s = dem.Scene(dt=1e-7)
    m = s.add_material(dem.linear_material(density=2650, young=1e8, poisson=0.3,
                                           friction_angle_deg=30))
    r = 1e-3
    ids = s.add_spheres([[0, 0, 0], [2 * r + 0.05e-3, 0, 0]], [r, r], material=m)
    v = s.velocities
    v[int(ids[0])] = [0.5, 0, 0]
    s.velocities = v
    s.run(1)
    st0 = s.collider_stats()
    assert st0["pair_candidates"] == 1 and st0["pair_records"] == 0
    s.run(200)  # (0.5 m/s x 2e-5 s = 10 um: about 40 um gap still open)
    assert s.collider_stats()["pair_records"] == 0
    s.run(805)  # (40.25 um more: touching for a few steps)
    st = s.collider_stats()
    assert st["builds"] == st0["builds"]  # (no build: the pass made the record)
    assert st["pair_records"] == 1 and s.num_active_contacts == 1
    c = s.contacts()
    overlap, kn = float(c["overlap"][0]), float(c["kn"][0])
    assert 0 < overlap < 1e-6
    # the law's force on the overlap of the step (x: the normal, from 0 to 1)
    assert kn == pytest.approx(1e5, rel=1e-12)  # (2 E r1 r2 / (r1 + r2) = E r)
    assert np.allclose(c["force"][0], [kn * overlap, 0, 0], rtol=0, atol=1e-12 * kn * overlap)
    assert np.array_equal(c["shear_force"][0], [0, 0, 0])


@pytest.mark.parametrize("kind", list(STEPS))
def test_the_states_are_the_build_before_s_to_the_bit(kind):
    """tests/regression/make_pair_records_ref.py, run by the build that kept a record for
    every candidate: 80 grains dropped into a box (linear law, Hertz's short kernel) and a
    periodic cell of 343 grains compressed and sheared; contacts form and open between
    builds in all three."""
    ref = np.load(REG / f"pair_records_{kind}.npz")
    s = scene(kind)
    s.run(STEPS[kind])
    got = state(s)
    assert got["builds"] == ref["builds"]
    assert got["active"] == ref["active"] > 30
    for key in ("positions", "velocities", "angvel", "contact_force"):
        assert np.array_equal(got[key], ref[key]), key
    assert got["friction"] == ref["friction"] > 0
    st = s.collider_stats()
    assert st["pair_records"] < st["pair_candidates"]


def test_the_measure_can_fail():
    """The comparison above sees a change of one ulp in one grain's position."""
    ref = np.load(REG / "pair_records_drop_linear.npz")
    s = scene("drop_linear")
    x = s.positions
    x[3, 0] = np.nextafter(x[3, 0], 1.0)
    s.positions = x
    s.run(STEPS["drop_linear"])
    assert not np.array_equal(state(s)["positions"], ref["positions"])


def test_new_records_are_in_candidate_order_whatever_the_threads():
    """The cell, on one and on two threads: the same bits, the same records and the same
    checkpoint bytes (a checkpoint holds every candidate's record in candidate order)."""
    out = []
    for nt in (1, 2):
        prev = dem.get_num_threads()
        dem.set_num_threads(nt)
        try:
            s = scene("cell")
            s.run(3700)
            out.append((s.positions.copy(), s.collider_stats(), _core._checkpoint_save(s),
                        s.memory_by_field()["contacts.pairs"]))
        finally:
            dem.set_num_threads(prev)
    (xa, sa, ba, pa), (xb, sb, bb, pb) = out
    assert np.array_equal(xa, xb)
    assert sa == sb and sa["pair_records"] > 100
    assert ba == bb
    assert pa == pb


def test_a_checkpoint_round_trip_keeps_its_bytes_and_the_run():
    """Saved while records of contacts that opened since the build exist, loaded (which
    keeps only the records that carry history) and saved again: the same bytes; both copies
    run on to the same bits."""
    a = scene("drop_linear")
    for _ in range(4):
        a.run(700)
        blob = _core._checkpoint_save(a)
        b = dem.Scene()
        _core._checkpoint_load(b, blob, replace=True)
        assert _core._checkpoint_save(b) == blob
        assert b.collider_stats()["pair_records"] <= a.collider_stats()["pair_records"]
        a.run(300)
        b.run(300)
        assert np.array_equal(a.positions, b.positions)
        assert a.energies()["friction"] == b.energies()["friction"]


def test_a_change_of_materials_reaches_every_active_contact_at_the_next_step():
    """The parameters of every active contact are made again at the first step after the
    materials change (one phys version for the scene, not one per record), and a checkpoint
    saved between the change and that step continues as the run that was not saved."""
    a = scene("drop_linear")
    a.run(STEPS["drop_linear"])
    stiff = dem.linear_material(density=2650, young=2e7, poisson=0.3, friction_angle_deg=25)
    m = a.add_material(stiff)
    for body in range(a.num_bodies):
        a.set_body_material(body, m)
    before = a.contacts()
    blob = _core._checkpoint_save(a)
    b = dem.Scene()
    _core._checkpoint_load(b, blob, replace=True)
    a.run(1)
    b.run(1)
    after = a.contacts()
    # sphere-sphere contacts (the second id a body's, not a wall's): kn = 2 E r1 r2 / (r1 + r2)
    # = E r, four times the old at the first step with the new modulus
    pairs_before = before["ids"][:, 1] >= 0
    pairs_after = after["ids"][:, 1] >= 0
    assert pairs_before.sum() > 10 and pairs_after.sum() > 10
    assert np.allclose(before["kn"][pairs_before], 5e6 * 0.005, rtol=1e-12)
    assert np.allclose(after["kn"][pairs_after], 2e7 * 0.005, rtol=1e-12)
    assert np.array_equal(b.contacts()["kn"], after["kn"])
    a.run(300)
    b.run(300)
    assert np.array_equal(a.positions, b.positions)
