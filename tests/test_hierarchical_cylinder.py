"""A 3D hierarchical triaxial specimen beyond a box (femcoupling.fem.model.FemModel
on femcoupling.fem.bodies.Cylinder; docs/coupling_hierarchical.md, "A cylindrical triaxial specimen"): a quarter
cylinder of P1 tetrahedra (gmsh), or the whole cylinder, an element at each quadrature
point.

With linear elastic elements (cpp_dem.elements.linear.LinearElement, E = 50 MPa, nu = 0.25,
at 100 kPa) the specimen is an elastic continuum with closed-form answers:
- an isotropic step (the confining pressure raised to 120 kPa, the top moved by the
  isotropic strain) is homogeneous: every element sees eps I and ends at -120 kPa I, to
  rounding. A uniform pressure on the faceted curved face is exactly -p n on every facet,
  so nothing but rounding separates the FEM from this answer;
- a triaxial step (the top moved, the pressure kept): the specimen's volume-mean stress is
  sigma_zz = -p + E eps_zz and sigma_xx = sigma_yy = -p (to 1e-4; measured 1.2e-5); each
  element's axial strain is within 3 % of the top's (the facets' normals lean off the
  horizontal, so the pressure has a small vertical part: measured 2 %);
- on 2 MPI ranks every element is at the serial mesh's place and the answers are the
  serial run's to 1e-10 (the whole cylinder);
- the whole cylinder (section="full", no symmetry planes) gives the same answers.
With periodic DEM elements (40 grains, distinct packings) a step is accepted with a status
and the specimen carries its confining pressure within 5 %.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from cpp_dem.elements.linear import LinearElement, LinearFactory  # noqa: E402
from cpp_dem.elements.pool import ElementPool, PeriodicFactory  # noqa: E402
from femcoupling.fem.bodies import Cylinder, cylinder_cells  # noqa: E402
from femcoupling.fem.model import FemModel, split_options  # noqa: E402


def _cyl(pool, **kw):
    """A FemModel on a Cylinder of ``kw``'s body arguments, the rest the model's."""
    body, options = split_options(Cylinder, kw)
    return FemModel(Cylinder(**body), elements=pool, **options)


ROOT = Path(__file__).resolve().parents[1]
MPIEXEC = Path(sys.executable).parent / "mpiexec"
R, H, SIZE = 0.025, 0.1, 0.025  # m: a 50 mm x 100 mm specimen, 205 tetrahedra in the quarter
E, NU, P0 = 50e6, 0.25, 100e3
K = E / (3 * (1 - 2 * NU))


def _linear(section="quarter", **kw):
    n = cylinder_cells(R, H, SIZE, section)
    pool = ElementPool.build(n, LinearFactory(E, NU, P0), workers=1, element_type=LinearElement)
    return pool, _cyl(pool, radius_m=R, height_m=H, size_m=SIZE,
                                      newton_rtol=1e-10, section=section, **kw)


def test_an_isotropic_step_is_homogeneous_to_rounding():
    eps = -20e3 / (3 * K)
    pool, m = _linear(confining_pa=P0 + 20e3)
    with pool:
        r = m.step(top_displacement=eps * H)
    assert r.status == "converged"
    assert len(r.increments) > 100
    np.testing.assert_allclose(r.increments, np.broadcast_to(eps * np.eye(3), r.increments.shape),
                               rtol=0, atol=1e-9 * abs(eps))
    want = np.array([-120e3, -120e3, -120e3, 0, 0, 0])
    np.testing.assert_allclose(r.element_stresses, np.broadcast_to(want, (len(r.increments), 6)),
                               rtol=0, atol=1e-6 * 120e3)


def test_a_triaxial_step_gives_the_elastic_answer():
    ez = -1e-3
    pool, m = _linear(confining_pa=P0)
    with pool:
        r = m.step(top_displacement=ez * H)
        s = m.volume_mean_stress()
        w = m.element_volumes
    assert r.status == "converged"
    assert w.sum() == pytest.approx(0.25 * np.pi * R**2 * H, rel=0.05)  # (faceted: 2.3 % less)
    np.testing.assert_allclose(s[:3], [-P0, -P0, -P0 + E * ez], rtol=1e-4)
    assert np.abs(s[3:]).max() < 1e-4 * P0
    zz = r.increments[:, 2, 2] / ez
    assert np.abs(zz - 1).max() < 0.03
    assert np.abs(w @ zz / w.sum() - 1) < 1e-3
    lateral = r.increments[:, 0, 0] / ez
    assert w @ lateral / w.sum() == pytest.approx(-NU, rel=1e-2)


def test_the_full_cylinder_gives_the_elastic_answers():
    """section="full": the whole cylinder, no symmetry planes; its rigid-body motions are
    held at the bottom's centre (u_x = u_y = 0) and at (R, 0, 0) (u_y = 0). Those holds are
    compatible with every homogeneous field of these tests, so they carry no load: an
    isotropic step is homogeneous to rounding (measured 4e-14), and a triaxial step's
    volume-mean stress is the elastic answer within 1e-4 (measured 7e-6), with no shear
    (measured 2e-16 of p). A hold that fought the field (u_x at (R, 0, 0)) would break both."""
    eps = -20e3 / (3 * K)
    pool, m = _linear("full", confining_pa=P0 + 20e3)
    with pool:
        r = m.step(top_displacement=eps * H)
        w = m.element_volumes
    assert r.status == "converged" and len(r.increments) > 400
    assert w.sum() == pytest.approx(np.pi * R**2 * H, rel=0.05)  # (faceted: 2.9 % less)
    np.testing.assert_allclose(r.increments, np.broadcast_to(eps * np.eye(3), r.increments.shape),
                               rtol=0, atol=1e-9 * abs(eps))
    ez = -1e-3
    pool, m = _linear("full", confining_pa=P0)
    with pool:
        r = m.step(top_displacement=ez * H)
        s = m.volume_mean_stress()
    assert r.status == "converged"
    np.testing.assert_allclose(s[:3], [-P0, -P0, -P0 + E * ez], rtol=1e-4)
    assert np.abs(s[3:]).max() < 1e-6 * P0


def test_rough_platens_restrain_the_ends():
    """platens="rough" holds the ends radially: the same linear specimen then carries more
    axial stress for the same shortening (end restraint: measured 2.7 % for H/D = 2 and
    nu = 0.25) and strains unevenly along its height (measured 0.80 to 1.06 of the top's
    strain), where smooth platens give E within 1e-4."""
    ez = -1e-3
    pool, m = _linear(confining_pa=P0, platens="rough")
    with pool:
        r = m.step(top_displacement=ez * H)
        s = m.volume_mean_stress()
    assert r.status == "converged"
    apparent = (s[2] + P0) / (E * ez)
    assert 1.01 < apparent < 1.10
    zz = r.increments[:, 2, 2] / ez
    assert zz.max() - zz.min() > 0.15


def test_periodic_dem_elements_carry_the_confining_pressure(tmp_path):
    n = cylinder_cells(R, H, 0.05)
    with ElementPool.build(n, PeriodicFactory(n=40, seed=3, isotropic=True), workers=2) as pool:
        m = _cyl(pool, radius_m=R, height_m=H, size_m=0.05,
                                 confining_pa=100e3, out=tmp_path)
        r = m.step(top_displacement=-1e-5)
        s = m.volume_mean_stress()
    assert r.status in ("converged", "stopped_at_scatter")
    assert s[2] < s[0] < 0
    assert -0.5 * (s[0] + s[1]) == pytest.approx(100e3, rel=0.05)
    assert (tmp_path / "elements.h5").exists()


def test_bad_input_is_refused():
    from femcoupling import FemInputError

    with pytest.raises(FemInputError, match=r"radius_m=-0.1: must be > 0 \(m\)"):
        cylinder_cells(-0.1, H, SIZE)
    with pytest.raises(FemInputError, match=r"size_m=1.0: must be <= 2 max"):
        cylinder_cells(R, H, 1.0)
    with pytest.raises(FemInputError, match=r"section='half': one of 'quarter', 'full'"):
        cylinder_cells(R, H, SIZE, "half")
    with ElementPool.build(3, LinearFactory(), workers=1, element_type=LinearElement) as pool:
        with pytest.raises(FemInputError, match=r"pool: has 3 elements for 205 tetrahedra "
                                                r"\(cylinder_cells\(0.025, 0.1, 0.025, "
                                                r"'quarter'\)\)"):
            _cyl(pool, radius_m=R, height_m=H, size_m=SIZE, confining_pa=1e5)
        with pytest.raises(FemInputError, match="confining_pa=None"):
            _cyl(pool, radius_m=R, height_m=H, size_m=SIZE)
        with pytest.raises(FemInputError, match=r"platens='glued': 'smooth' or 'rough'"):
            _cyl(pool, radius_m=R, height_m=H, size_m=SIZE, platens="glued",
                                 confining_pa=1e5)


def test_two_mpi_ranks_give_the_serial_specimen(tmp_path):
    """The whole cylinder (192 tetrahedra; its rigid-body holds at two nodes, found on
    whichever rank owns them, and the facet tags of the quarter's faces but its symmetry
    planes) on 2 ranks: every element at its serial place, the answers the serial run's to
    1e-10 (measured 1.2e-14)."""
    if not MPIEXEC.exists():
        pytest.skip(f"no mpiexec beside {sys.executable}")
    out = {}
    for ranks in (1, 2):
        d = tmp_path / f"r{ranks}"
        d.mkdir()
        p = subprocess.run([str(MPIEXEC), "-n", str(ranks), sys.executable,
                            str(ROOT / "tests" / "mpi_cylinder.py"), str(d), "full",
                            "0.035"],
                           capture_output=True, text=True, timeout=600, cwd=ROOT)
        assert p.returncode == 0, f"{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
        out[ranks] = json.loads((d / "result.json").read_text())
    one, two = out[1], out[2]
    assert np.abs(np.array(one["points"]) - np.array(two["points"])).max() < 1e-12
    for key in ("stresses", "increments", "volume_mean"):
        a, b = np.asarray(one[key]), np.asarray(two[key])
        assert np.abs(a - b).max() <= 1e-10 * np.abs(a).max(), key


def test_the_bench_smoke_runs_and_keeps_its_rows(tmp_path):
    """bench/cylinder_triaxial.py --smoke: 52 elements of 30 grains, 2 steps; a row per step
    in the CSV, the figure, the final JSON line; a second run into the same folder is
    refused (the rows are not overwritten)."""
    import csv

    out = tmp_path / "cyl"
    cmd = [sys.executable, str(ROOT / "bench" / "cylinder_triaxial.py"), "--smoke",
           "--out", str(out)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert p.returncode == 0, f"{p.stdout[-2000:]}\n{p.stderr[-4000:]}"
    last = json.loads(p.stdout.strip().splitlines()[-1])
    assert last["elements"] == 52 and last["steps_done"] == 2 and last["failed"] is None
    assert set(last["statuses"]) <= {"converged", "stopped_at_scatter"}
    assert last["radial_pa"] == pytest.approx(100e3, rel=0.02)
    assert 0 < last["q_pa"] < 100e3
    assert "ETA" in p.stdout
    with open(out / "cylinder_triaxial.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["step"]) for r in rows] == [1, 2]
    assert float(rows[1]["q_pa"]) > float(rows[0]["q_pa"]) > 0
    assert (out / "cylinder_triaxial.png").stat().st_size > 0
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert again.returncode == 2 and "holds a cylinder_triaxial.csv already" in again.stderr
    with open(out / "cylinder_triaxial.csv") as fh:
        assert len(list(csv.DictReader(fh))) == 2
