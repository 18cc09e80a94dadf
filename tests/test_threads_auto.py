"""Automatic threads (``--threads 0``, ``cpp_dem.apply_threads(0)``; issue 63 item 4): the
cores free of other work, one thread for a small scene, OMP_NUM_THREADS and an explicit
choice respected, and what it chose said."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from cpp_dem import scene as sc


def test_busy_cores_counts_the_cpus_busy_more_than_half_the_interval():
    before = {0: (100, 1000), 1: (100, 1000), 2: (0, 0)}
    after = {0: (190, 1100), 1: (140, 1100), 2: (0, 0)}  # 90 %, 40 %, no ticks
    assert sc.busy_cores(before, after) == 1
    assert sc.busy_cores(before, after, threshold=0.3) == 2
    assert sc.busy_cores({}, after) == 0  # (a CPU with no earlier sample: free)


def test_the_cgroup_quota_caps_the_cores(tmp_path):
    f = tmp_path / "cpu.max"
    f.write_text("150000 100000\n")
    assert sc._quota_cores(str(f)) == 1.5
    f.write_text("max 100000\n")
    assert sc._quota_cores(str(f)) is None
    assert sc._quota_cores(str(tmp_path / "none")) is None


_PROBE = textwrap.dedent("""
    import json, multiprocessing as mp, sys, time
    import cpp_dem as dem
    from cpp_dem import scene as sc

    def spin():
        while True:
            pass

    if __name__ == "__main__":
        hogs = [mp.Process(target=spin, daemon=True) for _ in range(int(sys.argv[1]))]
        for h in hogs:
            h.start()
        time.sleep(0.3)
        note = dem.apply_threads(int(sys.argv[2]))
        s = dem.Scene()
        m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                               friction_angle_deg=30))
        n = int(sys.argv[3])
        k = round(n ** (1 / 3)) + 1
        pos = [[0.01 * (i % k), 0.01 * ((i // k) % k), 0.01 * (i // (k * k))]
               for i in range(n)]
        s.add_spheres(pos, [0.004] * n, material=m)
        s.dt = 1e-6
        s.run(3)
        run = dem.get_num_threads()
        for h in hogs:
            h.terminate()
        print(json.dumps({"note": note, "after": sc._AUTO["note"], "run": run,
                          "header": dem.threads_for(s)}))
""")


def _probe(busy: int, threads: int, bodies: int, omp: str | None = None) -> dict:
    import json

    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    if omp is not None:
        env["OMP_NUM_THREADS"] = omp
    out = subprocess.run([sys.executable, "-c", _PROBE, str(busy), str(threads), str(bodies)],
                         capture_output=True, text=True, check=True, env=env)
    return {**json.loads(out.stdout.strip().splitlines()[-1]), "stderr": out.stderr}


CORES = len(os.sched_getaffinity(0))


@pytest.mark.skipif(CORES < 2, reason="needs two cores")
def test_automatic_threads_leave_a_busy_core_and_say_so():
    """With another process spinning on every core but one, a scene of AUTO_SERIAL_BODIES
    bodies runs on the free core alone (both cores of a 2-core machine with one busy took
    3.4 x as long as one thread: bench/threads_auto.py), and says so on stderr."""
    got = _probe(busy=CORES - 1, threads=0, bodies=sc.AUTO_SERIAL_BODIES)
    assert got["run"] == 1, got
    assert "busy with other work" in got["after"], got
    assert "[threads]" in got["stderr"], got


def test_a_small_scene_runs_on_one_thread_and_an_explicit_choice_stands():
    small = _probe(busy=0, threads=0, bodies=27)
    assert small["run"] == 1 and small["header"] == 1, small
    assert "automatic" in small["note"] and small["stderr"] == "", small
    if CORES >= 2:
        assert _probe(busy=0, threads=2, bodies=27)["run"] == 2  # (--threads 2: a choice)
    omp = _probe(busy=0, threads=0, bodies=27, omp="2")
    assert omp["run"] == 2 and "OMP_NUM_THREADS" in omp["note"], omp


def test_set_num_threads_ends_automatic_threads():
    sc._AUTO.update(on=True, threads=2)
    try:
        sc.set_num_threads(1)
        assert sc._AUTO["on"] is False
    finally:
        sc._AUTO["on"] = False
