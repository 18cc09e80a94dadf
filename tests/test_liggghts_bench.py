"""bench/liggghts_throughput.py: the throughput scene as LIGGGHTS input (issue 63's bench),
checked without LIGGGHTS: the data file holds the packing, the input the bench's stiffnesses,
walls, dt and skin, and a run's loop time is read from its output (a stand-in executable)."""

from __future__ import annotations

import math
import stat
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import liggghts_throughput as lt  # noqa: E402

RNG = np.random.default_rng(3)
CENTERS = RNG.uniform(0.003, 0.017, (20, 3))
RADII = RNG.uniform(0.0016, 0.0024, 20)
LO, HI = np.zeros(3), np.full(3, 0.02)


def test_the_data_file_holds_the_packing(tmp_path):
    path = tmp_path / "p.data"
    lt.write_data(path, CENTERS, RADII, LO, HI, 2600.0)
    text = path.read_text().splitlines()
    assert "20 atoms" in text and "2 atom types" in text
    rows = np.array([ln.split() for ln in text[text.index("Atoms") + 2:]], float)
    assert rows.shape == (20, 7)
    np.testing.assert_array_equal(rows[:, 0], np.arange(1, 21))
    np.testing.assert_allclose(rows[:, 2], 2 * RADII, rtol=1e-15)
    np.testing.assert_allclose(rows[:, 4:], CENTERS, rtol=1e-15)
    box = [ln.split() for ln in text if ln.endswith("hi")]
    lo = np.array([float(b[0]) for b in box])
    hi = np.array([float(b[1]) for b in box])
    assert np.all(lo < LO) and np.all(hi > HI)  # the walls inside the simulation box


def test_the_input_is_the_bench_scene():
    s = lt.input_script(Path("p.data"), LO, HI, young=1e7, poisson=0.3, friction_angle_deg=30,
                        mean_radius=2e-3, dt=1.25e-5, skin=4e-4, warmup=10, steps=100)
    lines = s.splitlines()
    kn = next(ln for ln in lines if " kn peratomtypepair" in ln).split()[-4:]
    assert [float(v) for v in kn] == [2e4, 4e4, 4e4, 4e4]  # E R, 2 E R against a wall
    kt = next(ln for ln in lines if " kt peratomtypepair" in ln).split()[-4:]
    assert [float(v) for v in kt] == pytest.approx([6e3, 1.2e4, 1.2e4, 1.2e4])
    mu = next(ln for ln in lines if "coefficientFriction" in ln).split()[-4:]
    assert float(mu[0]) == pytest.approx(math.tan(math.radians(30)))
    assert [float(v) for v in mu[1:]] == [0, 0, 0]  # frictionless walls
    walls = [ln for ln in lines if "wall/gran" in ln]
    assert len(walls) == 6 and all("tangential history" in w for w in walls)
    assert {w.split()[-2] for w in walls} == {"xplane", "yplane", "zplane"}
    assert float(next(ln for ln in lines if ln.startswith("timestep")).split()[1]) == 1.25e-5
    assert float(next(ln for ln in lines if ln.startswith("neighbor")).split()[1]) == 4e-4
    assert lines[-2:] == ["run 10", "run 100"]


def _fake(tmp_path, body: str) -> str:
    exe = tmp_path / "fake_liggghts"
    exe.write_text("#!/bin/sh\n" + body)
    exe.chmod(exe.stat().st_mode | stat.S_IEXEC)
    return str(exe)


def test_a_block_reads_the_timed_runs_loop_time(tmp_path):
    exe = _fake(tmp_path, 'echo "Loop time of 9.0 on 1 procs for 10 steps with 20 atoms"\n'
                          'echo "     110       20     50 1e-9"\n'
                          'echo "Loop time of 0.5 on 1 procs for 100 steps with 20 atoms, x"\n')
    r = lt.run_block(exe, tmp_path / "w", CENTERS, RADII, LO, HI, young=1e7, poisson=0.3,
                     friction_angle_deg=30, density=2600, dt=1e-5, skin=4e-4, warmup=10,
                     steps=100)
    assert r["loop_s"] == 0.5 and r["steps"] == 100 and r["atoms"] == 20
    assert r["particle_steps_per_s"] == pytest.approx(20 * 100 / 0.5)
    assert r["pair_contacts"] == 25


@pytest.mark.parametrize("body, words", [
    ("echo 'ERROR: Unknown command'\nexit 1\n", "exit 1"),
    ("echo 'Loop time of 1.0 on 1 procs for 10 steps with 20 atoms'\n", "exit 0"),
])
def test_a_failed_block_says_so(tmp_path, body, words):
    exe = _fake(tmp_path, body)
    with pytest.raises(lt.LiggghtsError, match=words):
        lt.run_block(exe, tmp_path / "w", CENTERS, RADII, LO, HI, young=1e7, poisson=0.3,
                     friction_angle_deg=30, density=2600, dt=1e-5, skin=4e-4, warmup=10,
                     steps=100)


def test_a_failed_block_in_the_throughput_bench_is_said_and_not_run_again(tmp_path):
    # As Yade's: the bench's line says liggghts_error (the first line) and cpp_dem's blocks
    # go on; no later LIGGGHTS block runs.
    import throughput

    calls = tmp_path / "calls"
    exe = _fake(tmp_path, f"echo x >> {calls}\necho 'ERROR: Unknown command'\nexit 1\n")
    p = throughput.Packing(centers=CENTERS, radii=RADII, lo=LO, hi=HI, csv=tmp_path / "p.csv",
                           meta={})
    blocks = throughput.LiggghtsBlocks(exe, p, throughput.BenchScene(), 100, 10, tmp_path)
    blocks()
    blocks()
    assert blocks.error == "liggghts failed (exit 1):" and blocks.blocks == []
    assert calls.read_text() == "x\n"
