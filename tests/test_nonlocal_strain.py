"""femcoupling.fem.nonlocal_strain: the averaging leaves a homogeneous strain alone, spreads
a concentrated one over its length, and refuses what it cannot be."""

from __future__ import annotations

import math

import numpy as np
import pytest

from femcoupling._checks import FemInputError
from femcoupling.fem.nonlocal_strain import NonlocalStrain


def _grid(n=41, h=1e-3):
    x, y = np.meshgrid(np.arange(n) * h, np.arange(n) * h)
    return np.column_stack([x.ravel(), y.ravel()]), np.full(n * n, h * h)


def test_a_homogeneous_strain_reaches_every_point_unchanged_also_by_the_boundary():
    pts, vol = _grid()
    vol = vol * np.random.default_rng(1).uniform(0.5, 2.0, len(vol))  # uneven cells
    nl = NonlocalStrain(pts, vol, 3e-3, 0.7)
    g = np.tile(np.array([[1e-3, 2e-4], [-5e-4, -2e-3]]), (len(pts), 1, 1))
    out = nl.apply(g)
    assert out.shape == g.shape
    np.testing.assert_allclose(out, g, rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.asarray(nl.matrix.sum(axis=1)).ravel(), 1.0, rtol=1e-12)


def test_a_spike_spreads_over_the_length_and_keeps_its_integral_in_the_interior():
    pts, vol = _grid()
    k = len(pts) // 2  # the centre
    g = np.zeros((len(pts), 1))
    g[k] = 1.0
    for length in (2e-3, 4e-3):
        out = NonlocalStrain(pts, vol, length).apply(g)[:, 0]
        # a Gaussian of variance length^2 / 2 per axis around the spike
        r2 = np.sum((pts - pts[k]) ** 2, axis=1)
        var = (out * r2).sum() / out.sum() / 2
        assert var == pytest.approx(length ** 2 / 2, rel=0.02)
        assert out.sum() == pytest.approx(1.0, rel=1e-3)  # (far from the edges)
        assert out[k] < 0.1
    mixed = NonlocalStrain(pts, vol, 2e-3, weight=0.25).apply(g)[:, 0]
    assert mixed[k] > 0.75  # its own share kept
    assert NonlocalStrain(pts, vol, 2e-3, 0.25).own_share[k] == pytest.approx(mixed[k])


def test_the_averaging_has_no_zero_energy_pattern_on_its_points():
    """The smallest eigenvalue of the (volume-symmetrised) averaging is positive: no strain
    pattern on the points averages to nothing (a Gaussian's transform is positive)."""
    pts, vol = _grid(15)
    a = NonlocalStrain(pts, vol, 1.5e-3).matrix.toarray()
    ev = np.linalg.eigvals(a)
    assert np.all(np.isfinite(ev)) and ev.real.min() > 1e-6
    # (the check can fail: a box kernel over a point's 8 neighbours has a zero pattern)
    box = (np.abs(pts[:, None, :] - pts[None, :, :]).max(axis=2) < 1.5e-3).astype(float)
    box /= box.sum(axis=1, keepdims=True)
    assert np.linalg.eigvals(box).real.min() < 1e-6


@pytest.mark.parametrize("kw, field", [
    ({"length_m": 0.0}, "nonlocal_length"), ({"length_m": -1e-3}, "nonlocal_length"),
    ({"length_m": math.nan}, "nonlocal_length"), ({"length_m": 1e-3, "weight": 0.0},
                                                  "nonlocal_weight"),
    ({"length_m": 1e-3, "weight": 1.5}, "nonlocal_weight"),
    ({"length_m": 1e-3, "cutoff": 1.0}, "cutoff")])
def test_bad_settings_are_refused_by_name(kw, field):
    pts, vol = _grid(5)
    with pytest.raises(FemInputError, match=field):
        NonlocalStrain(pts, vol, **kw)


def test_points_without_a_volume_each_or_a_wrong_field_are_refused():
    pts, vol = _grid(5)
    with pytest.raises(FemInputError, match="one positive volume"):
        NonlocalStrain(pts, vol[:-1], 1e-3)
    with pytest.raises(FemInputError, match="one positive volume"):
        NonlocalStrain(pts, np.zeros_like(vol), 1e-3)
    with pytest.raises(FemInputError, match="increments: 3 points"):
        NonlocalStrain(pts, vol, 1e-3).apply(np.zeros((3, 2, 2)))


def test_a_model_s_elements_take_the_averaged_increments(tmp_path):
    """FemModel(nonlocal_length=...) hands its elements the averaged displacement-gradient
    increments (the same as NonlocalStrain.apply of the local ones), and without it the
    local ones: the averaging is applied where the elements are strained."""
    pytest.importorskip("dolfinx_solver")
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from femcoupling.fem.bodies import Rectangle
    from femcoupling.fem.model import FemModel

    fac = PeriodicFactory(n=40, stress=100e3, isotropic=True,
                          options={"prep_friction_deg": 0.0})
    rng = np.random.default_rng(2)
    with ElementPool.build(4, fac, workers=1) as pool:
        got = {}
        for length in (None, 0.03):
            m = FemModel(Rectangle(lx=0.05, ly=0.10, nx=1, ny=2, degree=1,
                                   confining_pa=100e3), elements=pool, nonlocal_length=length)
            m.u.x.array[:] = 1e-5 * rng.standard_normal(m.u.x.array.size)
            m.u.x.scatter_forward()
            m._evaluate(True)
            g = m._grad_increment()
            sent = np.asarray(m.material.increments)[:, [0, 2]][:, :, [0, 2]]
            want = g if length is None else m.nonlocal_strain.apply(g)
            np.testing.assert_allclose(sent, want, rtol=0, atol=1e-18)
            got[length] = (g, sent)
            m.material.reject()
        g, sent = got[0.03]
        assert np.abs(sent - g).max() > 1e-3 * np.abs(g).max()  # (averaged: not the local)
    with pytest.raises(FemInputError, match="nonlocal_weight=0.5: given without"):
        with ElementPool.build(4, fac, workers=1) as pool:
            FemModel(Rectangle(lx=0.05, ly=0.10, nx=1, ny=2, degree=1, confining_pa=100e3),
                     elements=pool, nonlocal_weight=0.5)


def test_the_nonlocal_jacobian_solves_a_linear_body_in_one_correction():
    """With fixed element tangents (a linear body), Newton's correction with the nonlocal
    strain's consistent Jacobian (G^T D A W^-1 G) ends at equilibrium in one step; the
    local Jacobian's (what the elements' tangents alone give) does not: the check can fail."""
    pytest.importorskip("dolfinx_solver")
    from cpp_dem.elements.pool import ElementPool, PeriodicFactory
    from femcoupling.fem.bodies import Rectangle
    from femcoupling.fem.model import FemModel

    fac = PeriodicFactory(n=40, stress=100e3, isotropic=True,
                          options={"prep_friction_deg": 0.0})
    with ElementPool.build(12, fac, workers=1) as pool:
        m = FemModel(Rectangle(lx=0.05, ly=0.10, nx=1, ny=2, degree=2, platens="rough",
                               confining_pa=100e3), elements=pool, nonlocal_length=0.02,
                     nonlocal_weight=0.9)
        m._evaluate(True)
        tan, sig0 = np.asarray(m._tan).copy(), np.asarray(m._sig).copy()
        m.material.reject()

        def linear():  # the averaged strain through fixed tangents
            g = m.nonlocal_strain.apply(m._grad_increment())
            eps = np.stack([g[:, 0, 0], g[:, 1, 1], g[:, 0, 1] + g[:, 1, 0]], axis=1)
            m._set_q(sig0 + np.einsum("nij,nj->ni", tan, eps), tan)

        after = {}
        for how in ("nonlocal", "local"):
            m.u.x.array[:] = 0.0
            m.u.x.scatter_forward()
            m.body.apply(m, m.body.target(top_displacement=-1e-4))
            linear()
            r0 = m.system.residual(m.bcs)
            du = (m._nonlocal_correction(lambda: "") if how == "nonlocal"
                  else m.system.correction(m.bcs))
            m.system.move(du, 1.0)
            linear()
            after[how] = m.system.residual(m.bcs) / r0
        assert after["nonlocal"] < 1e-10
        assert after["local"] > 1e-4


def test_a_model_split_over_mpi_ranks_refuses_the_nonlocal_strain():
    pytest.importorskip("dolfinx_solver")
    from types import SimpleNamespace

    from femcoupling.fem.bodies import Rectangle
    from femcoupling.fem.model import FemModel

    with pytest.raises(FemInputError, match="nonlocal_length=0.01: serial only"):
        FemModel(Rectangle(lx=0.05, ly=0.10, nx=1, ny=2, degree=1, confining_pa=1e5),
                 elements=None, nonlocal_length=0.01, comm=SimpleNamespace(size=2, rank=0))
