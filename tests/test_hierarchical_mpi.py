"""The hierarchical FEM under MPI (femcoupling.fem.mpi_points; docs/coupling_mpi.md).

examples/05_hierarchical_mpi.py runs on 2 ranks (MPICH's mpiexec of the venv) and on 1: every
element is at the serial model's place, and the two runs agree within the Newton tolerance
(the FEM's sums run in another order on 2 ranks; the DEM elements turn that rounding into
differences of about 1e-3 of the stress, as they do for any change of their increments at
1e-16). The point matching is also tested without MPI, on one rank's shuffled points.
"""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_examples import declared

pytest.importorskip("dolfinx_solver")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "05_hierarchical_mpi.py"
MPIEXEC = Path(sys.executable).parent / "mpiexec"


def _rows(path: Path) -> list[dict]:
    with open(path) as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    out = {}
    for ranks in (1, 2):
        d = tmp_path_factory.mktemp(f"ranks{ranks}")
        p = subprocess.run([str(MPIEXEC), "-n", str(ranks), sys.executable, str(EXAMPLE),
                            "--smoke", "--out", str(d)], capture_output=True, text=True,
                           timeout=600, cwd=ROOT)
        assert p.returncode == 0, f"{ranks} rank(s):\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
        assert f"{ranks} rank(s): status" in p.stdout
        for name in declared(EXAMPLE, "OUTPUTS"):  # (the example's RUN_BY names this test)
            assert (d / name).stat().st_size > 0, name
        (d / "output.txt").write_text(p.stdout + p.stderr)
        out[ranks] = d
    return out


def test_each_kind_of_warning_is_one_line(runs):
    """The elements' warnings (raised on the Dask workers) reach rank 0's display: one line
    per kind, then how many more; none in Python's format with its echoed source line."""
    import re

    from geogrid_dem.warnings_display import key

    for ranks, d in runs.items():
        text = (d / "output.txt").read_text()
        assert not re.search(r"\.py:\d+: \w+Warning", text), (ranks, text[-3000:])
        shown = [m.groups() for m in re.finditer(r"^\[warning\] (\w+): (.*)$", text, re.M)
                 if " more like it (" not in m.group(2)]
        keys = [key(type(c, (Warning,), {}), msg) for c, msg in shown]
        assert len(keys) == len(set(keys)), (ranks, shown)
        assert shown, ranks  # (the smoke's elements do warn: the test can fail)


def test_every_element_is_at_the_serial_models_place(runs):
    from femcoupling.fem.bodies import quadrature_points

    serial = quadrature_points(0.04, 0.08, 2, 2)
    for ranks, d in runs.items():
        rows = _rows(d / "elements.csv")
        xy = np.array([[float(r["x_m"]), float(r["y_m"])] for r in rows])
        assert [int(r["element"]) for r in rows] == list(range(8))
        assert np.abs(xy - serial).max() < 1e-12, ranks


def test_two_ranks_give_the_one_rank_run_within_the_newton_tolerance(runs):
    one, two = (_rows(runs[k] / "biaxial.csv") for k in (1, 2))
    assert len(one) == len(two) == 1
    for a, b in zip(one, two):
        assert {a["status"], b["status"]} <= {"converged", "stopped_at_scatter"}
        for c in ("sigma_axial_pa", "sigma_lateral_pa"):
            assert float(b[c]) == pytest.approx(float(a[c]), rel=5e-3), c
    cols = ("sigma_xx_pa", "sigma_yy_pa", "sigma_xy_pa")
    s1, s2 = (np.array([[float(r[c]) for c in cols] for r in _rows(runs[k] / "elements.csv")])
              for k in (1, 2))
    # (measured: 0.4 % of the largest stress at most; distinct packings: a swapped element
    # would differ by its own packing's scatter, about 10 %)
    assert np.abs(s2 - s1).max() < 0.02 * np.abs(s1).max()
    assert np.abs(s1[:, 0] - s1[:, 0].mean()).max() > 0.02 * np.abs(s1).max()


def test_the_records_are_written_once_by_rank_0(runs):
    import h5py

    d = runs[2]
    steps = len((d / "steps.csv").read_text().splitlines()) - 1  # (a cut step: its halves)
    assert steps >= 1
    with h5py.File(d / "elements.h5") as f:
        assert list(f["step"][:]) == [k for k in range(steps) for _ in range(8)]
        assert list(f["element"][:]) == list(range(8)) * steps
    assert (d / "fem.xdmf").read_text().count('Attribute Name="stress_pa"') == steps


def _partition(local, serial, size=1.0):
    from femcoupling.fem.mpi_points import PointPartition, world

    return PointPartition(world().Split(world().rank), local, serial, size)


def test_points_are_matched_to_the_serial_numbering_by_place():
    rng = np.random.default_rng(1)
    serial = rng.random((20, 2))
    order = rng.permutation(20)
    part = _partition(serial[order] + 1e-12, serial)
    assert np.array_equal(part.ids, order)
    values = rng.random((20, 3))
    assert np.array_equal(part.gather(values[order]), values)
    assert np.array_equal(part.local(values), values[order])


def test_a_point_off_the_serial_mesh_or_matched_twice_is_refused():
    serial = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(RuntimeError, match="not the serial model's"):
        _partition(serial + [[0.0, 0.0], [0.0, 0.0], [1e-6, 0.0]], serial)
    with pytest.raises(RuntimeError, match="not the serial model's"):
        _partition(serial[[0, 1, 1]], serial)


def test_the_pool_must_be_on_rank_0_only():
    from femcoupling import FemInputError
    from femcoupling.fem.mpi_points import RootMaterial, world

    with pytest.raises(FemInputError, match="rank 0 only"):
        RootMaterial(world().Split(world().rank), None)


def test_a_3d_box_on_two_ranks_is_the_serial_box(tmp_path):
    """The 3D model under MPI: its 6 elements at the serial box's places, the steps accepted,
    the faces' confining pressure carried (the elements' mean lateral stress within 5 %), a
    records row per element and step."""
    from femcoupling import _dolfinx
    from femcoupling.fem.bodies import point_coordinates as _coordinates

    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    p = subprocess.run([str(MPIEXEC), "-n", "2", sys.executable,
                        str(ROOT / "tests" / "mpi_hierarchical3d.py"), str(tmp_path)],
                       capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, f"{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
    assert "on 2 rank(s)" in p.stdout
    assert p.stdout.split("status ")[1].split()[0] in ("converged", "stopped_at_scatter")
    import basix

    fx = _dolfinx.load()
    box = fx.mesh.create_box(fx.MPI.COMM_SELF, [np.zeros(3), np.full(3, 0.02)], [1, 1, 1],
                             fx.mesh.CellType.tetrahedron)
    pts, _ = basix.make_quadrature(basix.CellType.tetrahedron, 1)
    serial = _coordinates(fx, box, pts)
    assert np.abs(np.load(tmp_path / "points.npy") - serial).max() < 1e-12
    s = np.load(tmp_path / "stresses.npy")  # (Voigt xx, yy, zz, yz, xz, xy, tension +)
    assert s.shape == (6, 6)
    assert -s[:, :2].mean() == pytest.approx(100e3, rel=0.05)
    # the records of every step, written once by rank 0 (examples/05's smoke has one step)
    import h5py

    steps = len((tmp_path / "steps.csv").read_text().splitlines()) - 1  # (cuts: halves)
    assert steps >= 2
    with h5py.File(tmp_path / "elements.h5") as f:
        assert list(f["step"][:]) == [k for k in range(steps) for _ in range(6)]
        assert list(f["element"][:]) == list(range(6)) * steps


def test_ranks_waiting_for_the_elements_idle_instead_of_spinning(tmp_path):
    """While rank 0 runs the elements, the other ranks wait. At a plain MPI broadcast MPICH
    spins: rank 1 spends the whole wait (1 s) on the CPU, a core the Dask workers need on one
    machine. Through ``on_root`` and ``bcast_from_root`` (femcoupling.fem.mpi_points, the waits of
    the hierarchical models, the soil body's regions and the two-way loop) it sleeps between
    polls: measured 0.02 s of CPU a 1 s wait, 3 ms later than the plain broadcast."""
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    import json

    p = subprocess.run([str(MPIEXEC), "-n", "2", sys.executable,
                        str(ROOT / "tests" / "mpi_idle_wait.py"), str(tmp_path)],
                       capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-4000:]
    r = json.loads((tmp_path / "result.json").read_text())
    work = r["work_s"]
    working, waiting = r["ranks_rows"]

    def wait_of(how) -> tuple:
        """rank 1's CPU, its wait from rank 0's start of the work to its own return, and what
        it got (timing its wait from its own start read 0.9995 s of a 1 s work under load)"""
        cpu, _, end, got = waiting[how]
        return cpu, end - working[how][1], got

    cpu_plain, wall_plain, got = wait_of("plain")
    assert got == 42 and wall_plain >= work
    # the control: the plain broadcast spins (this machine's MPICH; the measure can fail). At
    # least 0.3 of the wait, for a suite whose other worker shares the cores
    assert cpu_plain > 0.3 * work
    for how in ("on_root", "bcast_from_root"):
        cpu, wall, got = wait_of(how)
        assert cpu < 0.1 * work, (how, cpu)
        assert work <= wall < work + 0.25, (how, wall)
    assert wait_of("bcast_from_root")[2] == 42 and wait_of("on_root")[2] is None
