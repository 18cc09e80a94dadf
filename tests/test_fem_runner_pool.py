"""The two-way loop's elements on Dask workers (femcoupling.runner_pool; issue 18): each
region's runner is kept on one worker for the whole loop (what it keeps in memory reaches
every iteration), the results are bitwise the serial loop's, and a worker killed mid-loop
costs a rerun of its region, not the run."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

from test_fem_handover import _footing, two_region_model


class CountingElement:
    """A linear elastic stand-in (E 10 MPa, nu 0.25) that counts its calls per region in
    memory and says where it ran. With ``kill_flag``: the first time region b runs its second
    call, it kills its own worker process (once: the flag file)."""

    def __init__(self, kill_flag: str | None = None):
        self.calls: dict = {}
        self.kill_flag = kill_flag

    def __call__(self, name, initial, final):
        from femcoupling.twoway import ElementResponse

        self.calls[name] = self.calls.get(name, 0) + 1
        if (self.kill_flag and name == "b" and self.calls[name] == 2
                and not Path(self.kill_flag).exists()):
            Path(self.kill_flag).write_text("killed")
            os.kill(os.getpid(), signal.SIGKILL)
        E, nu = 10e6, 0.25
        ds = final.normal_pa - initial.normal_pa
        de = (ds - nu * (ds.sum() - ds)) / E
        return ElementResponse(stress_initial_pa=initial.normal_pa,
                               stress_final_pa=final.normal_pa, strain_increment=de,
                               info={"calls": self.calls[name], "pid": os.getpid()})


def _loop(runner, workers, log=None):
    from femcoupling.twoway import two_way

    return two_way(two_region_model(), regions=["a", "b"], load=_footing,
                   element_runner=runner, tol=1e-6, max_iterations=4, workers=workers,
                   relaxation="none", log=log)


def _same(r1, r2):
    assert r1.iterations == r2.iterations and r1.changes == r2.changes
    for r in ("a", "b"):
        assert r1.materials[r] == r2.materials[r]
        assert np.array_equal(r1.targets[r].fem_stress_pa, r2.targets[r].fem_stress_pa)
        assert np.array_equal(r1.responses[r].strain_increment,
                              r2.responses[r].strain_increment)


@pytest.fixture(scope="module")
def serial():
    return _loop(CountingElement(), 1)


def test_each_region_is_kept_on_its_worker_and_the_loop_is_bitwise_serial(serial):
    lines: list = []
    par = _loop(CountingElement(), 2, log=lines.append)
    _same(serial, par)
    assert par.iterations == 3  # (the elastic stand-in's secant is exact: settled at 3)
    pids = {r: par.responses[r].info["pid"] for r in ("a", "b")}
    assert os.getpid() not in pids.values() and pids["a"] != pids["b"]
    for r in ("a", "b"):
        # the runner on its worker ran every iteration: its in-memory count reached them all
        assert par.responses[r].info["calls"] == par.iterations - 1
    assert any("on Dask workers" in s for s in lines)


def test_a_killed_worker_costs_a_rerun_of_its_region_not_the_run(serial, tmp_path):
    lines: list = []
    flag = tmp_path / "killed"
    par = _loop(CountingElement(kill_flag=str(flag)), 2, log=lines.append)
    assert flag.exists()  # a worker was killed (SIGKILL) in iteration 2
    _same(serial, par)
    assert any("region b: its worker" in s and "was lost" in s for s in lines)
    # b's runner started again from the runner as sent: its count restarted
    assert par.responses["b"].info["calls"] < par.responses["a"].info["calls"]


def test_a_failing_element_names_its_region():
    from femcoupling.runner_pool import RunnerPool

    def bad(name, initial, final):
        raise ValueError("no packing")

    with RunnerPool(bad, ["a", "b"], workers=2) as pool:
        with pytest.raises(RuntimeError, match="region a: its DEM element failed.*no packing"):
            pool.run([("a", None, None), ("b", None, None)])


def test_periodic_elements_are_prepared_once_on_their_workers():
    """Real periodic elements (100 grains), no cache_dir: the last iteration starts from the
    element its worker kept in memory, and its answer is bitwise that of the same runner run
    here from the same targets."""
    from femcoupling.region import PeriodicRegionElement
    from femcoupling.twoway import two_way

    runner = PeriodicRegionElement(n=100, tol=0.01)
    res = two_way(two_region_model(), regions=["a", "b"], load=_footing,
                  element_runner=runner, tol=1e-3, max_iterations=3, workers=2)
    assert res.iterations == 3
    for r in ("a", "b"):
        got = res.responses[r]
        assert got.info["prepared_from_cache"]  # kept on its worker, not prepared again
    here = runner("b", res.initial_targets["b"], res.targets["b"])
    assert not here.info["prepared_from_cache"]  # (this process had not prepared it)
    assert np.array_equal(here.stress_final_pa, res.responses["b"].stress_final_pa)
    assert np.array_equal(here.strain_increment, res.responses["b"].strain_increment)


def test_a_runner_dask_cannot_send_is_refused_before_a_cluster_starts():
    import threading

    from cpp_dem import ParameterError
    from femcoupling.runner_pool import RunnerPool

    class Holds:  # a runner with a lock in it
        def __init__(self):
            self.lock = threading.Lock()

        def __call__(self, name, initial, final):
            return None

    with pytest.raises(ParameterError, match="element_runner=.*cannot be sent"):
        RunnerPool(Holds(), ["a"], workers=1)
