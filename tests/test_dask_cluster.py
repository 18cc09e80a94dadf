"""The elements on a Dask cluster started the way a cluster is: a ``dask scheduler`` writing
its scheduler file and ``dask worker`` processes started on their own (here on this machine;
on a cluster by SLURM/PBS jobs, SSH or ``dask-mpi``), reached with ``client=`` or
``--scheduler FILE`` (issue 18). The same code as the LocalCluster's, bitwise the serial
results; a worker lost for good (no nanny to restart it: a node gone) costs a rerun on the
other, not the run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cpp_dem._core import ParameterError
from cpp_dem.elements.pool import ElementPool
from cpp_dem.elements.cluster import dask_client
# the same elements and increments as the LocalCluster's tests, and their serial answers
from test_element_pool import FACTORY, N, _increments, serial  # noqa: F401 (a fixture)

DASK = str(Path(sys.executable).with_name("dask"))


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two single-threaded workers, each its own process (no nanny)."""
    sched = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    procs = [subprocess.Popen([DASK, "scheduler", "--scheduler-file", str(sched), "--port",
                               "0", "--no-dashboard"], env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)]
    for _ in range(50):
        if sched.exists():
            break
        time.sleep(0.1)
    workers = [subprocess.Popen([DASK, "worker", "--scheduler-file", str(sched), "--nthreads",
                                 "1", "--no-nanny", "--no-dashboard"], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
               for _ in range(2)]
    procs += workers
    try:
        client, _ = dask_client(str(sched), 0)
        client.wait_for_workers(2, timeout=60)
        yield client, workers, sched
        client.close()
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()


def test_the_pool_on_a_started_cluster_is_bitwise_serial_and_survives_a_lost_node(cluster,
                                                                                   serial):
    client, workers, _ = cluster
    pool = ElementPool.build(N, FACTORY, client=client)
    assert len(pool.workers()) == 2
    pool.apply_strain(_increments())
    pool.accept()
    workers[0].send_signal(signal.SIGKILL)  # a node gone, for good
    workers[0].wait(timeout=10)
    st = pool.apply_strain(_increments())
    assert st.recovered  # its elements rebuilt on the other worker
    assert len(pool.workers()) == 1
    assert all(np.array_equal(a, b) for a, b in zip(serial, st.stresses))
    pool.close()  # (its spill files; the cluster is the fixture's)


def test_two_way_runs_its_regions_on_a_started_cluster(cluster):
    from test_fem_handover import _footing, two_region_model
    from test_fem_runner_pool import CountingElement, _same

    from femcoupling.coupling.twoway import two_way

    client, _, _ = cluster
    kw = dict(regions=["a", "b"], load=_footing, tol=1e-6, max_iterations=4,
              relaxation="none")
    ser = two_way(two_region_model(), element_runner=CountingElement(), **kw)
    par = two_way(two_region_model(), element_runner=CountingElement(), client=client, **kw)
    _same(ser, par)
    assert par.responses["a"].info["pid"] != par.responses["b"].info["pid"]
    assert par.responses["a"].info["calls"] == par.iterations - 1
    assert client.status == "running"  # the loop leaves a given client open


def test_a_scheduler_that_is_neither_address_nor_file_is_refused(tmp_path):
    with pytest.raises(ParameterError, match="scheduler='nowhere'"):
        dask_client("nowhere", 1)
