"""The reinforced soil body (femcoupling.elastoplastic.SoilModel) on 2 MPI ranks is the serial
body (docs/fem.md, "Verification"): tests/mpi_soil_body.py (a Drucker-Prager soil with its
self-weight, a prestressed geogrid layer, a footing loaded by pressure and then by settlement)
run under MPICH's mpiexec of the venv on 1 and on 2 ranks. The FEM adds a node's
contributions in another order on 2 ranks, and Newton stops at 1e-8 of the force scale, so
the runs agree to that tolerance, not bitwise (measured: within 4e-10 relative)."""

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


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    out = {}
    for ranks in (1, 2):
        d = tmp_path_factory.mktemp(f"soil{ranks}")
        p = subprocess.run([str(MPIEXEC), "-n", str(ranks), sys.executable,
                            str(ROOT / "tests" / "mpi_soil_body.py"), str(d)],
                           capture_output=True, text=True, timeout=600, cwd=ROOT)
        assert p.returncode == 0, f"{ranks} rank(s):\n{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
        assert f"on {ranks} rank(s): 10 steps" in p.stdout
        out[ranks] = json.loads((d / "result.json").read_text())
    return out


def test_every_rank_returns_the_same_values(runs):
    assert runs[2]["same_on_every_rank"] is True
    assert runs[1]["same_on_every_rank"] is True


def test_two_ranks_give_the_serial_body_within_the_newton_tolerance(runs):
    one, two = runs[1], runs[2]
    assert one["status"] == two["status"] == ["converged"] * 10
    assert one["plastic_points"] == two["plastic_points"] > 0
    for key in ("settlement_m", "pressure_pa", "region_stress_pa", "point_stress_pa"):
        a, b = np.asarray(one[key]), np.asarray(two[key])
        assert np.abs(a - b).max() <= 1e-6 * np.abs(a).max(), key
    assert two["layer_force_n_per_m"] == pytest.approx(one["layer_force_n_per_m"], rel=1e-6)
    # the body is loaded: the settlement stage pushed past the 100 kPa pressure stage
    assert one["pressure_pa"][5] == pytest.approx(100e3)
    assert one["pressure_pa"][-1] > 2 * one["pressure_pa"][5]
    assert one["layer_force_n_per_m"] > 0
