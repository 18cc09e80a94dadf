"""ElementPool (cpp_dem.elements.pool): DEM elements held on Dask workers across increments.
Results are bitwise those of the serial elements for 1, 2 and 4 workers; a rejected increment
restores every element; a killed worker's elements are rebuilt from their accepted bytes (its
spill files) and the run ends as an undisturbed one. Late workers, the bytes through the client
and recovery without copies: test_pool_scaling.py."""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

from cpp_dem.elements.pool import ElementPool, PeriodicFactory

FACTORY = PeriodicFactory(n=120)
N = 4


def _increments(scale=1.0):
    base = np.array([[0, 0, 2e-4], [0, 0, 0], [0, 0, -1e-4]])
    return [scale * base * (1 + 0.1 * k) for k in range(N)]


@pytest.fixture(scope="module")
def serial():
    """Two increments on each element, in this process."""
    out = []
    for k in range(N):
        el = FACTORY(k)
        el.apply_strain(_increments()[k])
        out.append(el.apply_strain(_increments()[k]))
    return out


@pytest.mark.parametrize("workers", [1, 2, 4])
def test_pool_gives_the_serial_result_bitwise(serial, workers):
    with ElementPool.build(N, FACTORY, workers=workers) as pool:
        assert len(pool.workers()) == workers
        pool.apply_strain(_increments())
        pool.accept()
        st = pool.apply_strain(_increments(), tangent="network")
        assert all(np.array_equal(a, b) for a, b in zip(serial, st.stresses))
        assert all(t.shape == (6, 6) for t in st.tangents)
        # a rejected iteration: back to the accepted state, and the same again
        pool.reject()
        again = pool.apply_strain(_increments(), tangent="network")
        assert all(np.array_equal(a, b) for a, b in zip(st.stresses, again.stresses))


def test_a_killed_worker_does_not_change_the_result(serial):
    with ElementPool.build(N, FACTORY, workers=2) as pool:
        pool.apply_strain(_increments())
        pool.accept()
        pids = pool.client.run(os.getpid)
        os.kill(sorted(pids.items())[0][1], signal.SIGKILL)
        time.sleep(0.5)
        st = pool.apply_strain(_increments())
        # that worker's elements were rebuilt elsewhere, from the spill files it wrote in
        # this machine's temporary directory (the client keeps no copy by default)
        assert st.recovered
        assert all(np.array_equal(a, b) for a, b in zip(serial, st.stresses))


def test_an_element_failure_is_named_and_the_pool_goes_on(serial):
    from cpp_dem.elements.pool import ElementError

    with ElementPool.build(N, FACTORY, workers=2) as pool:
        bad = _increments()
        bad[1] = -2.0 * np.eye(3)  # I + de turns the cell inside out
        with pytest.raises(ElementError, match=r"element 1: .*positive determinant"):
            pool.apply_strain(bad)
        pool.reject()  # back to the accepted state; the pool is usable
        pool.apply_strain(_increments())
        st = pool.apply_strain(_increments())
        assert all(np.array_equal(a, b) for a, b in zip(serial, st.stresses))


def _never(lock, k):
    return None


def _fails(k):
    raise RuntimeError(f"element {k} cannot be made")


def test_a_pool_that_cannot_start_says_so_and_stops_its_cluster(monkeypatch):
    # A factory Dask cannot send (it holds a lock) is refused before any cluster starts (the
    # actor call waited forever before); one that fails on its worker stops the pool's own
    # LocalCluster (its processes kept the interpreter alive before).
    import functools
    import threading

    from cpp_dem import ParameterError
    from cpp_dem.elements import pool as ep

    made = []

    def spy(workers):
        made.append(real(workers))
        return made[-1]

    real = ep.local_client
    monkeypatch.setattr(ep, "local_client", spy)
    with pytest.raises(ParameterError, match="factory=.*cannot be sent to the Dask workers"):
        ElementPool.build(2, functools.partial(_never, threading.Lock()), workers=1)
    assert made == []
    with pytest.raises(RuntimeError, match="cannot be made"):
        ElementPool.build(2, _fails, workers=1)
    client, cluster = made[0]
    assert client.status == "closed" and cluster.status.name == "closed"
