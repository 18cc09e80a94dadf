"""The reinforced soil body (femcoupling.fem.model.FemModel) on 2 MPI ranks is the serial
body (docs/fem.md, "Verification"; docs/coupling_mpi.md, "Region elements under MPI").

- tests/mpi_soil_body.py: a Drucker-Prager soil with its self-weight, a prestressed geogrid
  layer, a footing loaded by pressure and then by settlement, run under MPICH's mpiexec of
  the venv on 1 and on 2 ranks. The FEM adds a node's contributions in another order on 2
  ranks, and Newton stops at 1e-8 of the force scale, so the runs agree to that tolerance,
  not bitwise (measured: within 7e-10 relative). Runs on 2 ranks repeat bitwise.
- tests/mpi_soil_regions.py: DEM region elements on rank 0 (an element per cell of one
  region, one element for another). With linear stand-ins whose stiffness depends on the
  cell number they are given, 2 ranks give the serial run to 1e-14: each cell has the serial
  model's key and so its element. With periodic DEM elements on Dask, the keys and records
  are the serial run's, the prepared elements are bitwise the same, and after a load step
  the stresses agree within the elements' noise (2.2 % of the largest: 2 ranks cut the step
  and 1 does not)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

ROOT = Path(__file__).resolve().parents[1]
MPIEXEC = Path(sys.executable).parent / "mpiexec"


def _run(script: str, ranks: int, d: Path, *extra: str) -> dict:
    p = subprocess.run([str(MPIEXEC), "-n", str(ranks), sys.executable,
                        str(ROOT / "tests" / script), str(d), *extra],
                       capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, f"{ranks} rank(s):\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
    assert f"on {ranks} rank(s): " in p.stdout
    return json.loads((d / "result.json").read_text())


def test_two_ranks_give_the_same_bits_under_every_blas_kernel(runs, tmp_path):
    """The 2-rank body under two other BLAS kernels and NumPy's baseline loops gives the
    fixture's 2-rank results bitwise: its LU is PETSc's own on the gathered matrix, plain
    loops. With SuperLU_DIST (whose fronts call BLAS) the three kernels gave three results:
    10, 10 and 11 load steps, other Newton iterations under each."""
    from test_fixedorder import KERNELS, NUMPY_BASELINE

    for k, env in enumerate((*KERNELS[1:], NUMPY_BASELINE)):
        d = tmp_path / f"k{k}"
        d.mkdir()
        p = subprocess.run([str(MPIEXEC), "-n", "2",
                            *[a for key, v in env.items() for a in ("-genv", key, v)],
                            sys.executable, str(ROOT / "tests" / "mpi_soil_body.py"), str(d)],
                           capture_output=True, text=True, timeout=600, cwd=ROOT)
        assert p.returncode == 0, f"{env}: {p.stdout[-2000:]}\n{p.stderr[-4000:]}"
        assert json.loads((d / "result.json").read_text()) == runs[2], env


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    # (both on the package's default LU, PETSc's own. Before a Newton that makes no progress
    # over four iterations halved its next correction (femcoupling.fem.quadrature.
    # CYCLE_RATIO, CYCLE_WINDOW), the
    # serial run cycled at the cone's apex in the prestress until max_newton cut the step: 11
    # load steps against the 2 ranks' 10, on one machine with this LU and on another with
    # SuperLU_DIST, 0.3 % apart in the cells' stresses)
    return {ranks: _run("mpi_soil_body.py", ranks, tmp_path_factory.mktemp(f"soil{ranks}"))
            for ranks in (1, 2)}


def test_the_serial_body_takes_the_same_steps_under_another_lu(runs, tmp_path):
    """The serial body with SuperLU_DIST (another order of the LU's arithmetic) takes the
    default LU's 10 load steps, to the Newton tolerance: which LU, like which CPU, must not
    decide a step (measured 4e-11 of the largest stress apart; 0.3 % and a step more before
    CYCLE_RATIO)."""
    other = _run("mpi_soil_body.py", 1, tmp_path, "superlu_dist")
    one = runs[1]
    assert other["status"] == one["status"] == ["converged"] * 10
    for key in ("cell_stresses", "band_cell_states"):
        a = np.array(list(one[key].values()), float)
        b = np.array(list(other[key].values()), float)
        assert np.abs(a - b).max() <= 1e-7 * np.abs(a).max(), key
    assert np.allclose(other["settlement_m"], one["settlement_m"], rtol=1e-7, atol=1e-12)


def test_every_rank_returns_the_same_values(runs):
    assert runs[2]["same_on_every_rank"] is True
    assert runs[1]["same_on_every_rank"] is True


def test_two_ranks_give_the_serial_body_within_the_newton_tolerance(runs):
    """Both runs take the same steps and agree within the Newton tolerance (1e-6; measured
    7e-10): the FEM adds a node's contributions in another order on 2 ranks, and Newton
    stops at 1e-8 of the force scale."""
    one, two = runs[1], runs[2]
    assert one["status"] == two["status"] == ["converged"] * 10
    for key in ("settlement_m", "pressure_pa", "region_stress_pa", "point_stress_pa"):
        a, b = np.asarray(one[key]), np.asarray(two[key])
        assert np.abs(a - b).max() <= 1e-6 * np.abs(a).max(), key
    assert two["layer_force_n_per_m"] == pytest.approx(one["layer_force_n_per_m"], rel=1e-6)
    assert one["plastic_points"] == two["plastic_points"] > 0
    # the body is loaded: the settlement stage pushed past the 100 kPa pressure stage
    assert one["pressure_pa"][5] == two["pressure_pa"][5] == pytest.approx(100e3)
    assert one["pressure_pa"][-1] > 2 * one["pressure_pa"][5]
    assert one["layer_force_n_per_m"] > 0


def test_two_ranks_give_the_same_output_every_time(runs, tmp_path):
    """Same input, same output on 2 ranks, also when the cores are busy: two more runs at
    once (four ranks on this machine's two cores) give the fixture's 2-rank results bitwise. The
    parallel LU is PETSc's own on every rank (femcoupling.fem.quadrature.PARALLEL_LU); with
    MUMPS's parallel LU, 5 runs of 15 beside two busy processes ended in other last bits, one
    in 11 steps (bench/parallel_lu.py measures the three)."""
    procs = []
    for k in range(2):
        d = tmp_path / f"again{k}"
        d.mkdir()
        procs.append((d, subprocess.Popen(
            [str(MPIEXEC), "-n", "2", sys.executable, str(ROOT / "tests" / "mpi_soil_body.py"),
             str(d)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)))
    for d, p in procs:
        out, err = p.communicate(timeout=600)
        assert p.returncode == 0, f"{out[-2000:]}\n{err[-4000:]}"
        again = json.loads((d / "result.json").read_text())
        assert again == runs[2]


def test_the_cells_keys_and_states_are_the_serial_ones(runs):
    """cell_stresses, band_cells and band_cell_states gather the cells from their owners:
    on 2 ranks the same keys, in the same order, as the serial model's (the keys name the
    serial mesh's cells), and the same values within the Newton tolerance (the prestress
    is solved to 1e-8: measured 2e-10)."""
    one, two = runs[1], runs[2]
    assert len(one["band_cells"]) > 3 and len(one["cell_stresses"]) > 10
    for key in ("cell_stresses", "band_cells", "band_cell_states"):
        assert list(two[key]) == list(one[key]), key
    assert two["band_cells"] == one["band_cells"]
    for key in ("cell_stresses", "band_cell_states"):
        a = np.array(list(one[key].values()), float)
        b = np.array(list(two[key].values()), float)
        assert np.abs(a - b).max() <= 1e-7 * np.abs(a).max(), key  # (Newton: 1e-8)


@pytest.fixture(scope="module")
def regions(tmp_path_factory):
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    return {(ranks, mode): _run("mpi_soil_regions.py", ranks,
                                tmp_path_factory.mktemp(f"regions{ranks}{mode}"), mode)
            for mode in ("linear", "dem") for ranks in (1, 2)}


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.abs(a - b).max() / np.abs(a).max())


def test_region_elements_on_two_ranks_have_the_serial_keys_and_run(regions):
    for mode in ("linear", "dem"):
        one, two = regions[1, mode], regions[2, mode]
        assert two["same_on_every_rank"] is True, mode
        assert len(one["keys"]) > 5
        assert two["keys"] == one["keys"], mode  # the serial model's cell numbers
        assert np.all(np.isfinite(two["point_stress_pa"]))
    # the cells' starting stresses, gathered from their owners, are the serial ones
    assert _rel(regions[1, "dem"]["cell_stresses_pa"], regions[2, "dem"]["cell_stresses_pa"]) \
        < 1e-12


def test_linear_stand_ins_on_two_ranks_are_the_serial_run(regions):
    one, two = regions[1, "linear"], regions[2, "linear"]
    assert one["status"] == two["status"] == ["converged"] * 2
    assert one["newton"] == two["newton"]
    assert one["group_commits"] == two["group_commits"] == 2
    for key in ("settlement_m", "region_a_pa", "region_b_pa", "cell_stresses_after_pa",
                "point_stress_pa"):
        assert _rel(one[key], two[key]) < 1e-10, key
    # the stiffness depends on the cell: the cells do not all carry the same stress
    after = np.asarray(one["cell_stresses_after_pa"])
    assert np.ptp(after[:, 2, 2]) > 0.05 * np.abs(after[:, 2, 2]).max()


def test_dem_cell_elements_on_two_ranks_agree_within_their_noise(regions):
    """Each cell gets the serial run's element: prepared, the elements are bitwise the same
    on 1 and 2 ranks (the same seeds; distinct packings differ by 3.6 % or more, measured).
    After the load step they differ by the FEM's rounding turned into the elements' noise,
    and by the path: 2 ranks cut the step and 1 does not (measured: one element 2.2 %
    apart, the region's mean 0.16 %, the settlement 1.4e-4)."""
    one, two = regions[1, "dem"], regions[2, "dem"]
    assert one["start_stresses_pa"] == two["start_stresses_pa"]
    for r in (one, two):
        assert set(r["status"]) <= {"converged", "stopped_at_scatter"}
    assert _rel(one["element_stresses_pa"], two["element_stresses_pa"]) < 0.03
    for r in (one, two):  # a records row per element and accepted step, written once (rank 0)
        steps = len(r["status"])
        assert r["records"]["names"] == one["keys"]
        assert r["records"]["step"] == [k + 1 for k in range(steps) for _ in one["keys"]]
    assert _rel(one["region_a_pa"], two["region_a_pa"]) < 0.01
    assert _rel(one["settlement_m"], two["settlement_m"]) < 1e-3


def test_the_parallel_lu_bench_runs_its_packages(tmp_path):
    """bench/parallel_lu.py --smoke, without its two busy processes (they would slow the
    suite's other tests): the three LU packages on 2 ranks, two runs each; PETSc's and
    SuperLU_DIST's runs give one result each (MUMPS's may give one or more: not asserted)."""
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    p = subprocess.run([sys.executable, str(ROOT / "bench" / "parallel_lu.py"), "--smoke",
                        "--load", "off", "--out", str(tmp_path)], capture_output=True,
                       text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-4000:]
    last = json.loads(p.stdout.strip().splitlines()[-1])
    assert last == json.loads((tmp_path / "parallel_lu.json").read_text())
    rows = {r["package"]: r for r in last["packages"]}
    assert set(rows) == {"petsc", "superlu_dist", "mumps"} and last["dofs"] > 1000
    assert last["load"] == "off"
    for lu in ("petsc", "superlu_dist"):
        assert rows[lu]["runs"] == 2 and rows[lu]["distinct_results"] == 1, lu
    assert "time_ratio_petsc_over_superlu_dist" in last
    assert all(r["s_per_newton_iteration"] > 0 for r in rows.values())
    assert "ETA" in p.stderr
