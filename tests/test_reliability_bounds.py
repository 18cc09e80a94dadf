"""Requests without bounds are refused up front with an estimate, or done within bounded
memory; FEM geometry that overlaps is refused; elements lost with a Dask worker are not
silently restarted from their build state; a tensile footing load on a cohesionless soil says
why it cannot be carried (docs/reliability.md, "Requests without bounds, and the FEM side")."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import clumps
from cpp_dem.clumps import ClumpTemplate


# ---- clumps ----------------------------------------------------------------------------------

def test_members_touching_by_construction_are_summed_exactly():
    # Ten members 2r apart (r = 0.1 m): the rounding of k * 2r leaves neighbours 5.6e-16 r
    # closer than 2r, which sent the template to the approximate grid integration (stated
    # accuracy 2e-4). Within the touch tolerance they are disjoint: exact volume and inertia.
    r = 0.1
    c = np.array([[k * 2 * r, 0.0, 0.0] for k in range(10)])
    assert np.min(np.linalg.norm(c[1:] - c[:-1], axis=1)) < 2 * r  # overlap by rounding
    t = ClumpTemplate.from_spheres(c, np.full(10, r))
    assert t.fill_accuracy == 0
    v = 4.0 / 3.0 * math.pi * r ** 3
    assert abs(t.volume / (10 * v) - 1) < 1e-14
    ix = 10 * 0.4 * v * r * r
    assert abs(t.props.principal[0] / ix - 1) < 1e-13
    # A real overlap (1e-9 of the radii) still goes to the union integration.
    t = ClumpTemplate.from_spheres([[0, 0, 0], [1.999999999, 0, 0]], [1, 1])
    assert t.fill_accuracy > 0


def test_a_20000_member_clump_takes_bounded_memory():
    # _disjoint built all k^2 pair distances (8.9 GiB for 20 000 members) and the union
    # integration all line-member pairs (25 600 x 20 000 per array): both are bounded now.
    rng = np.random.default_rng(1)
    n = 20_000
    c = rng.random((n, 3)) * 0.2
    r = 0.002 + 0.004 * rng.random(n)
    g = np.arange(28) * 2 * 0.001
    lattice = np.array(np.meshgrid(g, g, g[:26], indexing="ij")).reshape(3, -1).T[:n]
    tracemalloc.start()
    try:
        overlapping = ClumpTemplate.from_spheres(c, r)
        touching = ClumpTemplate.from_spheres(lattice, np.full(n, 0.001))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 512 * 2 ** 20, f"peak {peak / 2 ** 20:.0f} MiB"
    assert overlapping.fill_accuracy > 0 and 0 < overlapping.volume < 0.2 ** 3 * 1.1
    assert touching.fill_accuracy == 0
    assert abs(touching.volume / (n * 4.0 / 3.0 * math.pi * 1e-9) - 1) < 1e-13


def test_the_union_integration_in_chunks_is_the_integration_at_once():
    # Chunks of lines with only the members that reach them give every line the same sums as
    # all members on all lines at once, bitwise.
    rng = np.random.default_rng(3)
    c = rng.random((400, 3)) * 0.05
    r = 0.002 + 0.004 * rng.random(400)
    cells = 160
    p = clumps.union_mass_properties(c, r, cells)
    lo = (c - r[:, None]).min(axis=0)
    hi = (c + r[:, None]).max(axis=0)
    hy, hz = (hi[1] - lo[1]) / cells, (hi[2] - lo[2]) / cells
    Y, Z = np.meshgrid(lo[1] + (np.arange(cells) + 0.5) * hy,
                       lo[2] + (np.arange(cells) + 0.5) * hz, indexing="ij")
    m0, _, _ = clumps._chord_moments(Y.ravel(), Z.ravel(), c, r)
    assert p.volume == hy * hz * m0.sum()


# ---- elements on Dask ------------------------------------------------------------------------

def _pool_increments(n):
    base = np.array([[0, 0, 2e-4], [0, 0, 0], [0, 0, -1e-4]])
    return [base * (1 + 0.1 * k) for k in range(n)]


def _kill_one_worker(pool):
    import os
    import signal
    import time

    pids = pool.client.run(os.getpid)
    addr, pid = sorted(pids.items())[0]
    os.kill(pid, signal.SIGKILL)
    time.sleep(0.5)
    return addr


def test_elements_lost_without_copies_are_named_not_restarted_from_their_build_state():
    # keep_copies=False: after accept() the accepted state lives on the workers only. A lost
    # worker's elements were restarted from their build state (sigma_zz 132 kPa against
    # 228 kPa), flagged only in PoolStep.recovered; now that is an error naming them.
    from cpp_dem.element_pool import ElementLostError, ElementPool, PeriodicFactory

    fac = PeriodicFactory(n=120)
    with ElementPool.build(4, fac, workers=2, keep_copies=False) as pool:
        pool.apply_strain(_pool_increments(4))
        pool.accept()
        addr = _kill_one_worker(pool)
        lost = sorted(k for k, a in pool._where.items() if a == addr)
        with pytest.raises(ElementLostError, match=r"keep_copies=True") as e:
            pool.apply_strain(_pool_increments(4))
        assert f"elements {lost}" in str(e.value) and addr in str(e.value)


def test_elements_without_copies_give_their_accepted_states_and_recover_before_any_accept():
    from cpp_dem.dem_element import DemElement
    from cpp_dem.element_pool import ElementPool, PeriodicFactory

    fac = PeriodicFactory(n=120)
    serial = []
    for k in range(2):
        el = fac(k)
        el.apply_strain(_pool_increments(2)[k])
        serial.append(el)
    with ElementPool.build(2, fac, workers=2, keep_copies=False) as pool:
        # lost before any accept: the client's copies are the accepted states, so the
        # elements restart right
        _kill_one_worker(pool)
        st = pool.apply_strain(_pool_increments(2))
        assert st.recovered
        assert all(np.array_equal(a, el.stress()) for a, el in zip(st.stresses, serial))
        pool.accept()
        # states() are the accepted states (fetched from the workers), not the built ones
        got = [DemElement.from_bytes(b).stress() for b in pool.states()]
        assert all(np.array_equal(a, el.stress()) for a, el in zip(got, serial))
