"""Region mode with the element's tangent (issue 18): the region takes a full stiffness made
from the DEM element's tangent, corrected to reproduce the element's increment exactly
(femcoupling.coupling.handover.secant_tangent, a BFGS update), instead of an isotropic secant.

The stand-in element is linear and transversely isotropic (stiffer vertically): its exact
stiffness is known, so the loop must put exactly that stiffness into the region, and the
region must then strain as the element does. The isotropic secant cannot: the test measures
how far it stays. The FEM side is checked on its own first: an isotropic stiffness given as a
full matrix gives the isotropic material's answer.
"""

from __future__ import annotations

import numpy as np
import pytest

from femcoupling import FemInputError
from femcoupling.coupling.handover import HandoverError, secant_tangent
from femcoupling.materials.continuum import (AnisotropicElastic, LinearElastic, elastic_tangent,
                                             mandel_to_tensor, tensor_to_mandel,
                                             voigt_to_mandel_stiffness)
from test_fem_handover import _footing, _one_region_model


def _spd(rng, scale=1e7):
    a = rng.normal(size=(6, 6))
    return scale * (a @ a.T + 6 * np.eye(6))


def test_secant_tangent_reproduces_the_increment_exactly():
    rng = np.random.default_rng(3)
    t, c_true = _spd(rng), _spd(rng)
    de = rng.normal(size=6) * 1e-3
    ds = c_true @ de
    c = secant_tangent(t, strain_increment=de, stress_increment_pa=ds)
    assert np.abs(c @ de - ds).max() <= 1e-12 * np.abs(ds).max()
    assert np.array_equal(c, c.T) or np.abs(c - c.T).max() <= 1e-12 * np.abs(c).max()
    assert np.linalg.eigvalsh(c).min() > 0
    # T is kept on the strains that do no work with T de or with ds (4 of the 6 directions)
    basis = np.linalg.svd(np.vstack([t @ de, ds]))[2][2:]
    for v in basis:
        np.testing.assert_allclose(c @ v, t @ v, rtol=0, atol=1e-9 * np.abs(t).max())
    # an exact tangent is left as it is
    np.testing.assert_allclose(secant_tangent(c_true, strain_increment=de,
                                              stress_increment_pa=ds), c_true, rtol=1e-12)


def test_secant_tangent_refuses_an_element_that_gave_back_energy():
    rng = np.random.default_rng(4)
    de = rng.normal(size=6) * 1e-3
    with pytest.raises(HandoverError, match="gave back energy"):
        secant_tangent(_spd(rng), strain_increment=de, stress_increment_pa=-_spd(rng) @ de)


def test_anisotropic_material_checks_its_matrix_and_projects_to_e_nu():
    lin = LinearElastic(20e6, 0.3)
    c = elastic_tangent(lin.bulk_pa, lin.shear_pa, 6)[0]
    m = AnisotropicElastic(c)
    assert m.young_pa == pytest.approx(20e6, rel=1e-12) and m.poisson == pytest.approx(0.3)
    assert m.matrix(4).shape == (4, 4) and m.matrix(4)[1, 1] == c[2, 2]  # (xx, zz, yy, xz)
    with pytest.raises(FemInputError, match="c_mandel_pa: shape"):
        AnisotropicElastic(np.eye(3))
    bad = c.copy()
    bad[0, 1] *= 1.5
    with pytest.raises(FemInputError, match="not symmetric"):
        AnisotropicElastic(bad)
    with pytest.raises(FemInputError, match="not positive definite"):
        AnisotropicElastic(c - 2 * np.linalg.eigvalsh(c).max() * np.eye(6))


def test_soil_model_takes_a_full_stiffness_region():
    """An isotropic stiffness given as a matrix gives the isotropic material's FEM answer."""
    lin = LinearElastic(12e6, 0.28)
    out = []
    for mat in (lin, AnisotropicElastic(elastic_tangent(lin.bulk_pa, lin.shear_pa, 6)[0])):
        m = _one_region_model()
        m.set_region_material("a", mat)
        _footing(m)
        out.append((m.region_stress("a"), m.region_strain("a"), m.footing_settlement_m()))
    for x, y in zip(out[0], out[1]):
        np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-12 * np.abs(x).max())


def _transversely_isotropic(e_h, e_v, nu_h, nu_vh, g_v):
    """Mandel stiffness (Pa) of a soil stiffer vertically (z): compliance, inverted."""
    s = np.zeros((6, 6))
    s[0, 0] = s[1, 1] = 1 / e_h
    s[2, 2] = 1 / e_v
    s[0, 1] = s[1, 0] = -nu_h / e_h
    s[0, 2] = s[2, 0] = s[1, 2] = s[2, 1] = -nu_vh / e_v
    g_h = e_h / (2 * (1 + nu_h))
    s[3, 3] = s[4, 4] = 1 / (2 * g_v)  # Mandel shear: 1 / (2 G)
    s[5, 5] = 1 / (2 * g_h)
    return np.linalg.inv(s)


C_TRUE = _transversely_isotropic(8e6, 25e6, 0.2, 0.15, 5e6)


class AnisotropicElement:
    """Stand-in periodic element: linear with stiffness C_TRUE, takes the full tensor and
    returns its exact tangent (picklable)."""

    def __call__(self, name, initial, final):
        from femcoupling.coupling.twoway import ElementResponse

        ds = np.asarray(final.fem_stress_pa) - np.asarray(initial.fem_stress_pa)  # tension +
        de = mandel_to_tensor(np.linalg.solve(C_TRUE, tensor_to_mandel(ds, 6)))
        d = np.array([1, 1, 1, 1 / np.sqrt(2), 1 / np.sqrt(2), 1 / np.sqrt(2)])
        return ElementResponse(
            stress_initial_pa=initial.normal_pa, stress_final_pa=final.normal_pa,
            strain_increment=-np.diag(de),
            info={"full_tensor": True, "strain_increment_tensor": -de,
                  "stress_increment_tensor": -ds,
                  "tangent_voigt_pa": d[:, None] * C_TRUE * d[None, :]})


def test_voigt_and_mandel_stiffness_forms_agree():
    d = np.array([1, 1, 1, 1 / np.sqrt(2), 1 / np.sqrt(2), 1 / np.sqrt(2)])
    np.testing.assert_allclose(voigt_to_mandel_stiffness(d[:, None] * C_TRUE * d[None, :]),
                               C_TRUE, rtol=1e-14)


def _coupled(stiffness, tmp_path):
    import h5py

    from femcoupling.coupling.twoway import HandoverHistory, two_way

    m = _one_region_model()
    e0 = m.region_strain("a")
    with HandoverHistory(tmp_path / f"{stiffness}.h5", regions=["a"]) as hist:
        res = two_way(m, regions=["a"], load=_footing, element_runner=AnisotropicElement(),
                      tol=1e-6, max_iterations=12, history=hist, stiffness=stiffness)
    with h5py.File(tmp_path / f"{stiffness}.h5") as f:
        rows = f["stiffness_mandel_pa"][:]
    # the region's in-plane strain increment (xx, zz, xz) against the element's
    fem = m.region_strain("a") - e0
    dem = -res.responses["a"].info["strain_increment_tensor"]
    idx = ([0, 2, 0], [0, 2, 2])
    mismatch = np.abs(dem[idx] - fem[idx]).max() / np.abs(fem[idx]).max()
    return res, mismatch, rows, dem


def test_two_way_gives_the_region_the_elements_own_stiffness(tmp_path):
    res, mismatch, rows, dem = _coupled("tangent", tmp_path)
    assert res.converged and res.iterations <= 4  # measured 3 FEM solves
    np.testing.assert_allclose(res.stiffnesses["a"], C_TRUE, rtol=1e-9,
                               atol=1e-9 * np.abs(C_TRUE).max())
    assert mismatch < 1e-9  # the region strains as its element does (measured 4e-15)
    assert abs(dem[1, 1]) < 1e-9 * np.abs(dem).max()  # plane strain holds in the element too
    given = [r for r in rows if np.all(np.isfinite(r))]  # (the last row: converged, no run)
    assert rows.shape[1:] == (6, 6) and given
    np.testing.assert_allclose(given[-1], C_TRUE, rtol=1e-9, atol=1e-9 * np.abs(C_TRUE).max())
    # the isotropic secant cannot represent this element: the region strains otherwise
    iso, iso_mismatch, iso_rows, _ = _coupled("isotropic", tmp_path)
    assert iso.stiffnesses["a"] is None and np.all(np.isnan(iso_rows))
    assert iso_mismatch > 0.1  # measured 0.31
    assert iso.iterations > res.iterations  # measured 12 FEM solves to tol 1e-6


def test_two_way_refuses_an_unknown_stiffness_mode():
    from femcoupling.coupling.twoway import two_way

    with pytest.raises(FemInputError, match="stiffness='secant'"):
        two_way(_one_region_model(), regions=["a"], load=_footing,
                element_runner=AnisotropicElement(), stiffness="secant")


def test_secant_tangent_of_an_indefinite_tangent_is_positive_definite():
    """A tangent near the strength (soft or negative in some directions) is floored to
    positive definite before the update, so the region always gets a stiffness."""
    rng = np.random.default_rng(5)
    q = np.linalg.qr(rng.normal(size=(6, 6)))[0]
    t = (q * np.array([-3e6, 1e4, 5e6, 8e6, 1e7, 3e7])) @ q.T  # one negative, one soft
    de = rng.normal(size=6) * 1e-3
    ds = _spd(rng) @ de
    c = secant_tangent(t, strain_increment=de, stress_increment_pa=ds)
    assert np.abs(c @ de - ds).max() <= 1e-12 * np.abs(ds).max()
    assert np.linalg.eigvalsh(c).min() > 0
    AnisotropicElastic(c)  # accepted


class NanTangentElement(AnisotropicElement):
    """The stand-in, but its tangent is not finite (a broken contact network)."""

    def __call__(self, name, initial, final):
        r = super().__call__(name, initial, final)
        r.info["tangent_voigt_pa"] = np.full((6, 6), np.nan)
        return r


def test_a_tangent_that_gives_no_stiffness_is_said_and_the_secant_taken():
    from femcoupling.coupling.twoway import RegionWarning, two_way

    with pytest.warns(RegionWarning, match="the element's tangent gives no stiffness"):
        res = two_way(_one_region_model(), regions=["a"], load=_footing,
                      element_runner=NanTangentElement(), max_iterations=3)
    assert res.stiffnesses["a"] is None and res.materials["a"][0] > 0
