"""cpp_dem.fixedorder: small arithmetic in a fixed order (no BLAS, no LAPACK), and what uses
it — the FEM's Newton (PETSc's own LU, exactly rounded norms), a periodic cell's map, the
handover's fits — gives the same bits under every BLAS kernel (``OPENBLAS_CORETYPE``: the
kernel another CPU picks)."""

import json
import math
import os
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from cpp_dem import fixedorder as fo

KERNELS = ({}, {"OPENBLAS_CORETYPE": "Haswell"}, {"OPENBLAS_CORETYPE": "Sandybridge"})
#: NumPy's own loops as on a CPU without AVX2 or AVX-512 (its array power, exp, log, tan,
#: arccos... and its quicksort's order of ties are others there)
NUMPY_BASELINE = {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"}
HERE = Path(__file__).resolve().parent


def _run(args, env_add, cwd=None, timeout=600):
    r = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd,
                       env={**os.environ, "OMP_NUM_THREADS": "1", **env_add}, timeout=timeout)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def test_the_sums_of_products_are_exactly_rounded():
    rng = np.random.default_rng(5)
    x = rng.normal(size=5000) * 10.0 ** rng.integers(-8, 8, 5000)
    y = rng.normal(size=5000)
    # (each product rounded once, as IEEE multiplication does on every CPU; their sum exact)
    exact_ss = float(sum(Fraction(float(v) * float(v)) for v in x))
    exact_dot = float(sum(Fraction(float(a) * float(b)) for a, b in zip(x, y)))
    assert fo.sum_squares(x) == exact_ss
    assert fo.dot(x, y) == exact_dot
    with pytest.raises(ValueError, match="shapes"):
        fo.dot(x, y[:10])
    w, rows = rng.random(40), rng.normal(size=(40, 3, 2))
    got = fo.weighted_rows(w, rows)
    assert got.shape == (3, 2)
    assert np.allclose(got, np.einsum("n,nij->ij", w, rows), rtol=1e-14, atol=0)


def test_small_products_inverses_and_eigenproblems_agree_with_lapack():
    rng = np.random.default_rng(6)
    for _ in range(50):
        a, b = rng.normal(size=(2, 3, 3))
        assert np.allclose(fo.matmul3(a, b), a @ b, rtol=0, atol=1e-14)
        assert np.allclose(fo.inv3(a), np.linalg.inv(a), rtol=1e-12,
                           atol=1e-12 * np.abs(np.linalg.inv(a)).max())
        assert math.isclose(fo.det3(a), np.linalg.det(a), rel_tol=1e-12, abs_tol=1e-14)
        m, v = rng.normal(size=(6, 4)), rng.normal(size=6)
        assert np.allclose(fo.matmul(m.T, m), m.T @ m, rtol=0, atol=1e-13)
        assert np.allclose(fo.matmul(v, m), v @ m, rtol=0, atol=1e-13)
        assert np.allclose(fo.matmul(m.T, v), m.T @ v, rtol=0, atol=1e-13)
        for n in (2, 3, 6):
            s = rng.normal(size=(n, n))
            s = s + s.T
            w, vec = fo.eigh(s)
            assert np.allclose(w, np.linalg.eigvalsh(s), rtol=0, atol=1e-13 * np.abs(w).max())
            assert np.allclose(vec @ np.diag(w) @ vec.T, s, rtol=0, atol=1e-13 * np.abs(w).max())
            assert np.allclose(vec.T @ vec, np.eye(n), rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="singular"):
        fo.inv3(np.ones((3, 3)))
    d, m = rng.normal(size=(40, 3)), rng.normal(size=(3, 5))
    assert np.allclose(fo.rows_matmul(d, m), d @ m, rtol=0, atol=1e-14)
    x = rng.normal(size=30)
    y = 2.5 * x + rng.normal(size=30)
    assert math.isclose(fo.line_slope(x, y), np.polyfit(x, y, 1)[0], rel_tol=1e-13)
    # many 3 x 3 at once, degenerate ones too
    t = rng.normal(size=(3000, 3, 3))
    t = t + np.swapaxes(t, 1, 2)
    t[:10] = np.diag([1.0, 2.0, 3.0])
    t[10:20] = 5.0 * np.eye(3)
    t[20:30] = np.diag([1e8, -1e-8, 0.0])
    w = fo.eigvalsh3_batch(t)
    ref = np.linalg.eigvalsh(t)
    assert np.all(np.abs(w - ref) <= 1e-14 * np.abs(ref).max(axis=1, keepdims=True))


def test_a_grid_keeps_digits_of_the_largest_entry():
    v = np.array([[123456.789, -0.0123456], [9.87654321, np.nan]])
    g = fo.on_grid(v, 6)
    assert g[0, 0] == 123457.0 and g[0, 1] == 0.0 and g[1, 0] == 10.0 and np.isnan(g[1, 1])
    assert np.array_equal(fo.on_grid(np.zeros(3), 6), np.zeros(3))
    # a last-bit change moves nothing (unless on a grid line's edge)
    w = np.random.default_rng(8).normal(size=1000) * 1e7
    assert np.array_equal(fo.on_grid(w, 6), fo.on_grid(w * (1 + 2.2e-16), 6))


def _cayley_power(l_dt: np.ndarray, n: int) -> np.ndarray:
    """n steps of Cayley's map of L dt, in extended precision (exponentiation by squaring)."""
    mm = lambda a, b: np.einsum("ij,jk->ik", a, b)  # noqa: E731
    x = l_dt.astype(np.longdouble) / 2
    eye = np.eye(3, dtype=np.longdouble)
    m = eye - x
    adj = np.array([[m[(j + 1) % 3, (i + 1) % 3] * m[(j + 2) % 3, (i + 2) % 3]
                     - m[(j + 1) % 3, (i + 2) % 3] * m[(j + 2) % 3, (i + 1) % 3]
                     for j in range(3)] for i in range(3)])
    step = mm(adj / (m[0] @ adj[:, 0]), eye + x)  # (I - X)^-1 (I + X)
    out = eye.copy()
    while n:
        if n & 1:
            out = mm(out, step)
        step, n = mm(step, step), n >> 1
    return out


def test_a_cells_rate_takes_it_to_its_map_to_the_last_digits():
    """L dt of ``cayley_rate``, stepped n times, gives back F within 1e-13 for stretches,
    shears and rotations up to 1e5 steps. SciPy's F^(1/n) then 2 (A - I)(A + I)^-1, the
    route before, lost A - I to cancellation: 1e-11 to 1e-10 off at 1e5 steps, so the
    check can fail."""
    from scipy.linalg import fractional_matrix_power
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(7)
    old_worst = 0.0
    for k in range(12):
        f = np.eye(3) + rng.normal(size=(3, 3)) * [1e-6, 1e-3, 0.05][k % 3]
        if k % 4 == 3:
            f = Rotation.from_rotvec(rng.normal(size=3)).as_matrix() @ f
        for n in (1, 7, 1000, 100_000):
            got = fo.cayley_rate(f, n)
            assert np.abs(_cayley_power(got, n) - f).max() <= 1e-13, (k, n)
            if n == 100_000:
                a = np.real(fractional_matrix_power(f, 1.0 / n))
                old = 2 * (a - np.eye(3)) @ np.linalg.inv(a + np.eye(3))
                old_worst = max(old_worst, float(np.abs(_cayley_power(old, n) - f).max()))
    assert old_worst > 1e-12


_SMALL = """
import hashlib, json, numpy as np
from cpp_dem import fixedorder as fo
from cpp_dem.elements.periodic import _rate_for
from femcoupling.coupling.handover import fem_to_dem, secant_stiffness, secant_tangent
rng = np.random.default_rng(11)
h = hashlib.sha256()
for k in range(20):
    de = rng.normal(size=(3, 3)) * 1e-3
    h.update(_rate_for(de, 1000 + k, 1e-6).tobytes())
    s = rng.normal(size=(3, 3)) * 1e4
    s = -1e5 * np.eye(3) + s + s.T
    t = fem_to_dem(s)
    h.update(t.principal_pa.tobytes()); h.update(t.principal_axes.tobytes())
    ds, e = rng.random(3) * 1e4 + 1e3, rng.random(3) * 1e-4 + 1e-5
    h.update(np.array(secant_stiffness(stress_increment_pa=ds, strain_increment=e)).tobytes())
    c = rng.normal(size=(6, 6))
    e6 = rng.normal(size=6) * 1e-4
    h.update(secant_tangent(fo.matmul(c, c.T) * 1e7, strain_increment=e6,
                            stress_increment_pa=1e7 * e6 + rng.normal(size=6) * 1e2).tobytes())
    m = rng.normal(size=(200, 3, 3))
    h.update(fo.eigvalsh3_batch(m + np.swapaxes(m, 1, 2)).tobytes())
# a sieve curve's samples (by mass and by count; NumPy's array power gave other radii for
# 200 seeds of 200 on NumPy's baseline loops) and the count it expects
from cpp_dem.build import psd
sizes, passing = np.array([0.005, 0.01, 0.02, 0.03]), np.array([0.0, 0.3, 0.7, 1.0])
for s in range(20):
    for by in ("mass", "count"):
        h.update(psd.radii_from_psd(sizes, passing, 300, seed=s, by=by).tobytes())
        h.update(np.float64(psd.expected_count(sizes, passing, 1e-3, by=by)).tobytes())
h.update(psd.passing_of(psd.radii_from_psd(sizes, passing, 300, seed=1), sizes).tobytes())
# what a periodic element is built from: its cloud's cell
from cpp_dem.protocols.periodic import cube_cloud
c, r, edge = cube_cloud(80, 1e-3, 0.2, 104, 0.25)  # (a seed whose r**3 rounded otherwise)
h.update(c.tobytes()); h.update(r.tobytes()); h.update(np.float64(edge).tobytes())
# a periodic element's network tangent (a sparse LU whose supernodes call BLAS), strained
from cpp_dem.elements.periodic import DemElement
el = DemElement.periodic(60, stress=40e3, seed=3, prep_friction_deg=0.0)
el.apply_strain(np.array([[-3e-4, 0, 2e-5], [0, 0, 0], [2e-5, 0, 1e-4]]))
h.update(el.network_tangent()[0].tobytes()); h.update(el.strain().tobytes())
print(h.hexdigest())
"""


def test_the_small_arithmetic_does_not_depend_on_the_blas_kernel():
    """A periodic cell's rate, the handover's principal frame, secant modulus and secant
    tangent, batched eigenvalues, a sieve curve's samples, a periodic cloud, and a strained
    periodic element's network tangent and strain: the same bits under three BLAS kernels
    and NumPy's baseline loops (LAPACK's eigh and lstsq, SciPy's fractional power, BLAS's
    matmul, the sparse LU's supernodes and NumPy's array power gave others)."""
    out = {_run(["-c", _SMALL], env).strip() for env in (*KERNELS, NUMPY_BASELINE)}
    assert len(out) == 1, out


def test_the_soil_bodys_newton_does_not_depend_on_the_blas_kernel(tmp_path):
    """A Drucker-Prager soil body with a prestressed layer and element regions (the MPI
    test's model, tests/mpi_soil_body.py, on one rank): its load steps, Newton iterations,
    residuals, stresses and measures are the same bits under three BLAS kernels and NumPy's
    baseline loops. With
    MUMPS's LU and PETSc's (BLAS) norms, another kernel gave another correction from the
    first iteration on, and 002's soil took 16 load steps under one and 8 under another."""
    results = []
    for k, env in enumerate((*KERNELS, NUMPY_BASELINE)):
        out = tmp_path / f"k{k}"
        out.mkdir()
        _run([str(HERE / "mpi_soil_body.py"), str(out)], env, cwd=HERE.parent)
        results.append((out / "result.json").read_text())
    assert json.loads(results[0])["newton"], "no Newton iterations recorded"
    assert results[0] == results[1] == results[2] == results[3]


def test_the_serial_lu_bench_runs_both_packages(tmp_path):
    """bench/serial_lu.py --smoke: PETSc's own LU and MUMPS on one rank, under three BLAS
    kernels each; PETSc's give one result (MUMPS's may give more: not asserted)."""
    out = _run([str(HERE.parent / "bench" / "serial_lu.py"), "--smoke", "--out",
                str(tmp_path)], {}, cwd=HERE.parent)
    last = json.loads(out.strip().splitlines()[-1])
    assert last == json.loads((tmp_path / "serial_lu.json").read_text())
    rows = {r["package"]: r for r in last["packages"]}
    assert set(rows) == {"petsc", "mumps"} and last["dofs"] > 1000
    assert rows["petsc"]["runs"] == 3 and rows["petsc"]["distinct_results"] == 1
    assert all(r["s_per_newton_iteration"] > 0 for r in rows.values())
