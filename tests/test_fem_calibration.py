"""Scales that agree (femcoupling.coupling.continuum_fit; issue 18): the FEM soil (Drucker–Prager
matched to Mohr–Coulomb) fitted to a periodic DEM element along its region's stress path."""

from __future__ import annotations

import math

import numpy as np
import pytest

from femcoupling import FemInputError
from femcoupling.coupling.continuum_fit import fit_along_path, friction_angle_deg

INITIAL = np.diag([-25e3, -25e3, -50e3])  # FEM tensors, tension positive, Pa
FINAL = np.diag([-25e3, -25e3, -80e3])
FINAL[0, 2] = FINAL[2, 0] = -3e3


def test_friction_angle_of_a_stress_state():
    assert friction_angle_deg(np.diag([-100e3, -50e3, -300e3])) == pytest.approx(30.0)
    # turned in the x-z plane: the same principal stresses
    c, s = math.cos(0.4), math.sin(0.4)
    R = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    turned = R @ np.diag([-100e3, -50e3, -300e3]) @ R.T
    assert friction_angle_deg(turned) == pytest.approx(30.0)
    # with cohesion: s1 - s3 = (s1 + s3) sin(phi) + 2 c cos(phi)
    phi = friction_angle_deg(np.diag([-100e3, -50e3, -300e3]), cohesion_pa=10e3)
    p = math.radians(phi)
    assert 200e3 == pytest.approx(400e3 * math.sin(p) + 20e3 * math.cos(p), rel=1e-9)
    assert phi < 30.0


@pytest.fixture(scope="module")
def fit():
    return fit_along_path(INITIAL, FINAL, n=150, beyond=4.0, points=16)


def test_the_fit_carries_what_the_element_carries(fit):
    assert fit.strength_reached
    phi = fit.material.friction_deg
    assert 20.0 < phi < 45.0
    # every state the element carried is inside the fitted strength; the failing point is
    # outside it, within the bracket of three halvings of the path step (0.25 / 8)
    mobilised = [friction_angle_deg(s) for s in fit.stresses_pa]
    assert max(mobilised) == pytest.approx(phi)
    t_fail = fit.t[-1] + 0.25 / 8
    assert friction_angle_deg(INITIAL + t_fail * (FINAL - INITIAL)) > phi
    assert friction_angle_deg(INITIAL + t_fail * (FINAL - INITIAL)) - phi < 1.0
    assert "failed at t" in fit.message


def test_the_fitted_elasticity_is_the_elements_secant(fit):
    from femcoupling.coupling.handover import secant_stiffness

    j = int(np.searchsorted(fit.t, 1.0 + 1e-12)) - 1
    ds = -np.diag(fit.stresses_pa[j] - fit.stresses_pa[0])
    de = -np.diag(fit.strains[j])
    E, nu = secant_stiffness(stress_increment_pa=ds, strain_increment=de)
    assert fit.material.young_pa == E and fit.material.poisson == nu
    # it predicts the element's largest strain (the axial one) within 40 %: the isotropic fit
    # of a 150-grain element over-predicts it, by +7 % to +29 % over seeds 1-21 (mean +21 %,
    # sd 6 %; 40 % is the mean + 3 sd); the earlier 25 % failed at 4 of those 21 seeds
    pred = (ds - nu * (ds.sum() - ds)) / E
    assert pred[2] == pytest.approx(de[2], rel=0.4)


def test_bad_input_is_refused():
    with pytest.raises(FemInputError, match="initial_pa"):
        fit_along_path(np.eye(2), FINAL)
    with pytest.raises(FemInputError, match="beyond"):
        fit_along_path(INITIAL, FINAL, beyond=0.5)
