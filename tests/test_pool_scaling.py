"""ElementPool at scale (issue 37, item 5), on tiny elements (30 grains, 2 workers):

- a worker that joins after the pool was built (``cluster.scale``, as a batch system's job
  starting late) receives elements, moved worker to worker, and the results stay bitwise
  those of the serial elements;
- the client receives digests, not states: the bytes it receives per accepted step and the
  element data it keeps are the same at every step and far below the elements' state (with
  ``keep_copies=True`` the states do come through, which shows the measures see them);
- ``keep_copies=False`` after a lost worker: the elements come back from their spill files
  (here in a shared ``state_dir``), the calls since the last accept redone, bitwise; with
  the spill files gone too, ``ElementLostError`` names them; ``keep_copies=True`` then
  restarts them from the client's copy.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from cpp_dem._core import ParameterError
from cpp_dem.elements.pool import ElementLostError, ElementPool, PeriodicFactory

FACTORY = PeriodicFactory(n=30)
N = 4
KW = {"steps": 100, "max_relax_steps": 0}  # a fixed, short DEM run per increment


def _increments(scale: float = 1.0) -> list:
    base = np.array([[0, 0, 2e-4], [0, 0, 0], [0, 0, -1e-4]])
    return [scale * base * (1 + 0.1 * k) for k in range(N)]


@pytest.fixture(scope="module")
def serial():
    """The stresses of each element after 1, 2 and 3 increments, in this process."""
    out = [[] for _ in range(3)]
    for k in range(N):
        el = FACTORY(k)
        for j in range(3):
            out[j].append(el.apply_strain(_increments()[k], **KW))
    return out


def _same(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(a, b))


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of two single-threaded worker processes (with nannies: a killed worker
    comes back under a new address) shared by the tests below."""
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


def _kill_worker_of(pool, k: int) -> str:
    """SIGKILLs the worker holding element k (a node gone); returns its address."""
    addr = pool._where[k]
    pid = pool.client.run(os.getpid, workers=[addr])[addr]
    os.kill(pid, signal.SIGKILL)
    for _ in range(100):
        if addr not in pool.client.nthreads():
            break
        time.sleep(0.1)
    return addr


def test_a_late_worker_receives_elements_and_the_results_stay_bitwise(serial):
    # The documented recipe: the pool is built on the workers there are, and the cluster
    # grows afterwards (cluster.scale, as SLURMCluster.scale does when its jobs start).
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        pool = ElementPool.build(N, FACTORY, client=client)
        try:
            assert len(pool.workers()) == 1
            pool.apply_strain(_increments(), **KW)
            pool.accept()
            cluster.scale(2)
            client.wait_for_workers(2, timeout=120)
            second = pool.apply_strain(_increments(), **KW)  # (moved first, at the boundary)
            assert len(pool.workers()) == 2
            assert len(pool.moves) == N // 2  # equal sizes: half of them
            moved = pool.received_bytes()["move"]
            assert moved < min(s.size_bytes for s in pool.saved_states())  # worker to worker
            pool.accept()
            third = pool.apply_strain(_increments(), **KW)
            assert _same(second.stresses, serial[1]) and _same(third.stresses, serial[2])
        finally:
            pool.close()


def test_the_client_receives_digests_not_states(client):
    with ElementPool.build(N, FACTORY, client=client) as pool:
        state = sum(s.size_bytes for s in pool.saved_states())
        per_step, held = [], []
        for _ in range(6):
            pool.apply_strain(_increments(), **KW)
            before = pool.received_bytes().get("accept", 0)
            pool.accept()
            per_step.append(pool.received_bytes()["accept"] - before)
            held.append(pool.held_bytes())
        assert len(set(per_step)) == 1 and len(set(held)) == 1  # the same at every step
        assert per_step[0] < state / 100 and held[0] < state / 100  # digests, not states
    # The measures see states when they come: keep_copies=True brings them at every accept.
    with ElementPool.build(N, FACTORY, client=client, keep_copies=True) as pool:
        state = sum(s.size_bytes for s in pool.saved_states())
        assert pool.received_bytes()["build"] >= state
        pool.apply_strain(_increments(), **KW)
        pool.accept()
        assert pool.received_bytes()["accept"] >= state and pool.held_bytes() >= state


def test_states_of_some_elements_fetch_only_those(client):
    """``states(indices)``: those elements' accepted bytes, in the order asked, and only
    their bytes through the client; an index outside the pool is refused."""
    with ElementPool.build(N, FACTORY, client=client) as pool:
        pool.apply_strain(_increments(), **KW)
        pool.accept()
        every = pool.states()
        before = pool.received_bytes()["states"]
        some = pool.states([3, 1])
        assert some == [every[3], every[1]]
        assert pool.received_bytes()["states"] - before < len(every[3]) + len(every[1]) + 1024
        with pytest.raises(ParameterError, match=r"indices: \[4\] outside"):
            pool.states([0, 4])
    with ElementPool.build(N, FACTORY, client=client, keep_copies=True) as pool:
        assert pool.states([2]) == [pool.states()[2]]


def test_a_lost_worker_without_copies_recovers_from_the_spill_or_refuses(client, serial,
                                                                          tmp_path):
    with ElementPool.build(N, FACTORY, client=client, state_dir=tmp_path) as pool:
        pool.apply_strain(_increments(), **KW)
        pool.accept()
        assert all(Path(s.spill).parent == tmp_path / f"pool-{pool.pool_id}"
                   for s in pool.saved_states())
        pool.apply_strain(_increments(), **KW)  # (not accepted: redone after the loss)
        lost = _kill_worker_of(pool, 0)
        third = pool.apply_strain(_increments(), **KW)
        assert third.recovered and all(pool._where[k] != lost for k in third.recovered)
        assert _same(third.stresses, serial[2])
        pool.accept()
        # The spill gone with the worker (a node's local disk): refused, by name.
        lost = _kill_worker_of(pool, 0)
        gone = sorted(k for k, a in pool._where.items() if a == lost)
        for k in gone:
            Path(pool.saved_states()[k].spill).unlink()
        with pytest.raises(ElementLostError, match=r"keep_copies=True") as e:
            pool.apply_strain(_increments(), **KW)
        assert f"elements {gone}" in str(e.value) and lost in str(e.value)
    assert not (tmp_path / f"pool-{pool.pool_id}").exists()  # close() removed the spill
    # keep_copies=True: the client's copy, when no spill file can be read.
    with ElementPool.build(N, FACTORY, client=client, keep_copies=True) as pool:
        pool.apply_strain(_increments(), **KW)
        pool.accept()
        lost = _kill_worker_of(pool, 1)
        for k, a in pool._where.items():
            if a == lost:
                Path(pool.saved_states()[k].spill).unlink()
        second = pool.apply_strain(_increments(), **KW)
        assert second.recovered and _same(second.stresses, serial[1])


@pytest.mark.parametrize("kw, message", [
    ({"keep_copies": "yes"}, "keep_copies='yes'"),
    ({"state_dir": 3}, "state_dir=3"),
    ({"min_workers": 3}, "min_workers=3 > workers=2"),
    ({"min_workers": 0}, "min_workers=0"),
    ({"timeout_s": -1.0}, "timeout_s=-1.0"),
])
def test_bad_options_are_refused_by_name_before_any_cluster_starts(kw, message):
    with pytest.raises(ParameterError, match=message):
        ElementPool.build(N, FACTORY, workers=2, **kw)
