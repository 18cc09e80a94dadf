"""The core's memory by field (Scene.memory_by_field; issue 63 item 3): every array counted
once, by its capacity, and together they are what a grain costs the process."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

import cpp_dem as dem
from cpp_dem import _core

ROOT = Path(__file__).resolve().parents[1]


def _scene() -> tuple[dem.Scene, int]:
    """A scene with the tests' one material (linear, sand-like): the scene and the material."""
    s = dem.Scene()
    return s, s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                                 friction_angle_deg=30))


def _lattice(k: int) -> dem.Scene:
    s, m = _scene()
    g = np.arange(k) * 0.01
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    s.add_spheres(pos, np.full(len(pos), 0.0051), material=m)
    s.dt = 1e-7
    s.run(2)
    return s


def test_every_field_is_counted_by_its_capacity():
    s = _lattice(8)
    n, c = s.num_bodies, s.num_active_contacts
    f = s.memory_by_field()
    assert c == 3 * 8 * 8 * 7  # (every sphere touches its six neighbours)
    assert all(isinstance(v, int) and v >= 0 for v in f.values())
    for name, size in (("bodies.pos", 24), ("bodies.ori", 32), ("bodies.radius", 8),
                       ("bodies.force", 24)):
        assert f[name] >= n * size, name
    assert f["contacts.pairs"] >= c * 8
    # (one thread, the short kernel: the pass sums into the bodies' forces and keeps no
    # outputs, no slots for them and no scratch sums; the integration's accelerations are a
    # block's, on the stack)
    for name in ("contacts.pair_out", "contacts.pair_cold", "contacts.pair_jslot",
                 "contacts.pair_jadj_off", "scratch.pair_fi", "scratch.pair_ti"):
        assert f[name] == 0, name
    assert not any(k.startswith("scratch.acc") for k in f)
    assert f["bonds.bonds"] == 0 and f["geogrid.links"] == 0  # (none in this scene)
    assert len({k.split(".")[0] for k in f}) >= 8


def test_the_fields_add_up_to_what_a_grain_costs_the_process():
    """bench/memory_per_grain.py on two lattices: the marginal resident memory per grain is
    the fields' sum to within 10 % (measured: 1 283 against 1 250 B/grain between 2.7e4 and
    2.16e5 grains); a field left uncounted, or counted twice, would show here."""
    import json

    out = subprocess.run([sys.executable, str(ROOT / "bench" / "memory_per_grain.py"),
                          "--k", "16", "32"], capture_output=True, text=True, check=True)
    slope = json.loads(out.stdout.strip().splitlines()[-1])
    assert slope["between"] == [16**3, 32**3]
    rss, core = slope["marginal_rss_bytes_per_grain"], slope["marginal_core_bytes_per_grain"]
    assert abs(rss - core) < 0.1 * core, slope


def _pair(gap_over_r: float) -> dem.Scene:
    """Two resting spheres of radius 1 mm, gap_over_r radii apart, in zero gravity."""
    s, m = _scene()
    r = 1e-3
    s.add_spheres(np.array([[0.0, 0, 0], [2 * r + gap_over_r * r, 0, 0]]), np.full(2, r),
                  material=m)
    s.gravity = (0.0, 0.0, 0.0)
    s.dt = 1e-7
    return s


def _field(s: dem.Scene, name: str) -> int:
    return s.memory_by_field()[name]


def test_radii_at_the_build_are_kept_from_the_first_change_and_growth_is_seen():
    """The radii at the last build exist only once one changes (set through radii): two
    spheres a skin's worth apart (0.1 radius, the margin 0.2 radius covers it) that grow by
    a tenth of a radius each touch, and repel, without moving first: the broad phase saw the
    growth. A checkpoint taken after the growth continues to the same bits."""
    s = _pair(0.3)  # (0.3 r apart: beyond the margin, no candidate pair at the build)
    s.run(5)
    assert _field(s, "broadphase.radius_at_build") == 0
    assert s.collider_stats()["pair_candidates"] == 0
    s.radii = s.radii * 1.2  # (now 0.1 r overlapping)
    assert _field(s, "broadphase.radius_at_build") == 2 * 8
    blob = bytes(_core._checkpoint_save(s))
    s.run(5)
    assert s.num_active_contacts == 1
    assert s.velocities[0, 0] < 0 < s.velocities[1, 0]
    assert _field(s, "broadphase.radius_at_build") == 0  # (the rebuild the growth called)
    c = dem.Scene()
    _core._checkpoint_load(c, blob, replace=True)
    assert _field(c, "broadphase.radius_at_build") == 2 * 8
    c.run(5)
    assert np.array_equal(c.positions, s.positions) and np.array_equal(c.velocities, s.velocities)


def test_wrap_counts_and_inertia_factors_exist_from_their_first_use():
    """A scene without a periodic cell has no wrap counts and one without density scaling
    no inertia factors (their absence reads as zeros and ones); a wrapped body makes the
    counts, density scaling the factors, and a checkpoint keeps them or their absence."""
    from cpp_dem import periodic

    s = _pair(-0.01)  # (pressed together: a contact for the scaling to see)
    s.run(2)
    assert _field(s, "bodies.image") == 0 and _field(s, "bodies.inertia_scale") == 0
    assert np.array_equal(s.images, np.zeros((2, 3)))
    s.set_density_scaling(target_dt=1e-3, safety=0.5, period=1)  # (beyond their own step)
    s.run(2)
    assert _field(s, "bodies.inertia_scale") >= 2 * 8
    assert max(s.inertia_scale(b) for b in range(2)) > 1
    s.clear_density_scaling()
    assert _field(s, "bodies.inertia_scale") == 0 and s.inertia_scale(0) == 1.0

    p = _pair(0.0)
    p.set_periodic_cell(periodic.cube_cell(10e-3))
    p.velocities = np.array([[-5.0, 0, 0], [5.0, 0, 0]])  # (the first leaves by x = 0)
    assert _field(p, "bodies.image") == 0
    p.run(3000)
    assert _field(p, "bodies.image") == 2 * 12
    im = p.images
    assert im[0].tolist() == [-1, 0, 0] and not im[1].any()
    q = dem.Scene()
    _core._checkpoint_load(q, bytes(_core._checkpoint_save(p)), replace=True)
    assert np.array_equal(q.images, im)
    # (a scene without the arrays writes the zeros and ones they stand for)
    blank = dem.Scene()
    _core._checkpoint_load(blank, bytes(_core._checkpoint_save(s)), replace=True)
    assert _field(blank, "bodies.image") == 0 and _field(blank, "bodies.inertia_scale") == 0
    assert bytes(_core._checkpoint_save(blank)) == bytes(_core._checkpoint_save(s))


def test_the_candidate_rows_are_the_same_on_one_thread_and_two():
    """The broad phase's candidates are rows by body (4 B a candidate and 4 B a body): on two
    threads each block of bodies fills its own buffer, joined in block order. A jittered
    lattice of 3 150 spheres thrown about (above the threads' threshold) gives the same
    candidates, the same contacts and, after steps with rebuilds, the same bits on one
    thread and two; a checkpoint writes them as the list of pairs they stand for."""
    before = dem.get_num_threads()
    runs = []
    try:
        for t in (1, 2):
            dem.set_num_threads(t)
            s, m = _scene()
            rng = np.random.default_rng(7)
            g = np.arange(15) * 0.0085  # (spheres of 4 mm, 0.5 mm apart, jittered)
            pos = np.stack(np.meshgrid(g, g, g[:14], indexing="ij"), -1).reshape(-1, 3)
            pos += rng.uniform(-2e-4, 2e-4, pos.shape)
            s.add_spheres(pos, np.full(len(pos), 0.004), material=m)
            s.velocities = rng.uniform(-0.5, 0.5, pos.shape)
            s.gravity = (0.0, 0.0, 0.0)
            s.dt = 2e-6
            s.run(1500)
            runs.append((s, s.collider_stats(), bytes(_core._checkpoint_save(s))))
    finally:
        dem.set_num_threads(before)
    (a, ca, blob_a), (b, cb, blob_b) = runs
    assert ca["builds"] >= 3 and ca == cb, (ca, cb)
    f = a.memory_by_field()
    # (the rows' offsets: the build's are kept as the contacts' rows, pair_ioff)
    assert f["broadphase.candidate_off"] == 0 and f["contacts.pair_ioff"] >= 4 * 3151
    assert 4 * ca["pair_candidates"] <= f["broadphase.candidates"] <= 6 * ca["pair_candidates"]
    assert np.array_equal(a.contacts()["ids"], b.contacts()["ids"])
    assert np.array_equal(a.positions, b.positions) and blob_a == blob_b
