"""Hierarchical FEM x DEM in 3D (femcoupling.fem.model.FemModel on femcoupling.fem.bodies.Box, issue 38 item 4), at small
size: one hexahedron of six P1 tetrahedra, a periodic element of 80 grains at each quadrature point.

- a homogeneous field (every node on u = G x) converges in one Newton iteration, every element
  sees G's increment, and each element is the stand-alone element given the same increments;
- 1 and 2 Dask workers give bitwise the same run;
- a triaxial step (top moved, sides confined) is accepted with a status;
- bad input is refused with the field named.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from cpp_dem.elements.pool import ElementPool, PeriodicFactory  # noqa: E402
from femcoupling.fem.bodies import Box  # noqa: E402
from femcoupling.fem.model import FemModel, split_options  # noqa: E402
from femcoupling.materials.element_pool import voigt_stress  # noqa: E402

FACTORY = PeriodicFactory(n=80, same=True, isotropic=True)
def _box(pool, **kw):
    """A FemModel on a Box of ``kw``'s body arguments, the rest the model's."""
    body, options = split_options(Box, kw)
    return FemModel(Box(**body), elements=pool, **options)


G1 = np.array([[1e-4, 0.0, 2e-5], [0.0, -0.5e-4, 0.0], [0.0, 1e-5, -2e-4]])


def _run(workers):
    with ElementPool.build(6, FACTORY, workers=workers) as pool:
        m = _box(pool, lx=0.01, ly=0.01, lz=0.01, nx=1, ny=1, nz=1,
                           homogeneous=True)
        steps = [m.step(gradient=k * G1) for k in (1, 2)]
        return steps, m.u.x.array.copy()


@pytest.fixture(scope="module")
def runs():
    return {1: _run(1), 2: _run(2)}


def test_a_homogeneous_field_gives_the_elements_response(runs):
    steps, _ = runs[2]
    for r in steps:
        assert r.newton_iterations == 1 and r.status == "converged"
        # every element sees the gradient's increment (to rounding: every node is on the
        # boundary), rotation included
        np.testing.assert_allclose(r.increments, np.broadcast_to(G1, (6, 3, 3)), rtol=0,
                                   atol=1e-12)
    for k in range(6):
        el = FACTORY(k)
        for r in steps:
            s = el.apply_strain(r.increments[k])
        assert np.array_equal(voigt_stress(s), steps[-1].element_stresses[k])


def test_one_and_two_workers_give_the_same_run(runs):
    (s1, u1), (s2, u2) = runs[1], runs[2]
    assert np.array_equal(u1, u2)
    for a, b in zip(s1, s2):
        assert np.array_equal(a.element_stresses, b.element_stresses)


def test_a_triaxial_step(tmp_path):
    with ElementPool.build(6, FACTORY, workers=1) as pool:
        m = _box(pool, lx=0.01, ly=0.01, lz=0.01, nx=1, ny=1, nz=1,
                           confining_pa=100e3, out=tmp_path)
        r = m.step(top_displacement=-2e-6)
    assert r.status in ("converged", "stopped_at_scatter")
    # the top shortened, the sides carry the confining pressure (tension positive, Pa)
    assert r.mean_stress[2] < r.mean_stress[0] < 0
    assert r.mean_stress[0] == pytest.approx(-100e3, rel=0.05)
    assert (tmp_path / "elements.h5").exists() and (tmp_path / "report.md").exists()


def test_bad_input_is_refused():
    from femcoupling import FemInputError

    with ElementPool.build(6, FACTORY, workers=1) as pool:
        with pytest.raises(FemInputError, match="confining_pa=None"):
            _box(pool, lx=0.01, ly=0.01, lz=0.01, nx=1, ny=1, nz=1)
        with pytest.raises(FemInputError, match="pool: has 6 elements for 12 cells"):
            _box(pool, lx=0.01, ly=0.01, lz=0.01, nx=2, ny=1, nz=1,
                           homogeneous=True)
        with pytest.raises(FemInputError, match="tangent='secant'"):
            _box(pool, lx=0.01, ly=0.01, lz=0.01, nx=1, ny=1, nz=1,
                           homogeneous=True, tangent="secant")
        m = _box(pool, lx=0.01, ly=0.01, lz=0.01, nx=1, ny=1, nz=1,
                           homogeneous=True)
        with pytest.raises(FemInputError, match="gradient: shape"):
            m.step(gradient=np.zeros((2, 2)))
