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


def _calibrate_synthetic(update, steep: float, young0_pa: float, passes: int = 4,
                         root_pa: float = 1.2e6):
    """The calibration's loop on a synthetic element whose secant falls with the FEM soil's
    modulus E (ln secant = -steep ln(E/root) + 0.5 sin(ln(E/root)), relative to the root);
    the element's strain ratio is E / secant. Returns the rows and whether a pass after the
    first held the ratio within [1/2, 2]."""
    rows, E = [], young0_pa
    for k in range(1, passes + 1):
        x = math.log(E / root_pa)
        sec = root_pa * math.exp(-steep * x + 0.5 * math.sin(x))
        rows.append({"pass": k, "soil_young_pa": E, "dem_fem_strain_ratio": E / sec,
                     "secant_young_pa": sec})
        if k > 1 and 0.5 <= E / sec <= 2.0:
            return rows, True
        E = update(rows)
    return rows, False


def test_calibration_update_brackets_a_steep_element():
    """The calibration's next E (``next_soil_young``): the plain secant update (the pass's
    element secant) swings about the root when the element answers the FEM soil's modulus
    more steeply than 1 : 1 in log-log, and never lands inside [1/2, 2] in four passes (the
    smoke element did this: ratios 87, 0.29, 2.3, 0.41); once two passes bracket ratio 1 the
    update interpolates inside the bracket and lands within four passes, from either side,
    at every steepness tried. Before a bracket it is the element's secant."""
    from geogrid_dem.studies.prs_element import next_soil_young

    def plain(rows):
        return rows[-1]["secant_young_pa"]

    def bracketed(rows):
        E, rule = next_soil_young(rows)
        r = [row["dem_fem_strain_ratio"] for row in rows]
        if min(r) < 1 < max(r):  # inside the closest bracket
            lo = max((row for row in rows if row["dem_fem_strain_ratio"] < 1),
                     key=lambda row: row["dem_fem_strain_ratio"])["soil_young_pa"]
            hi = min((row for row in rows if row["dem_fem_strain_ratio"] > 1),
                     key=lambda row: row["dem_fem_strain_ratio"])["soil_young_pa"]
            assert min(lo, hi) < E < max(lo, hi) and rule.startswith("interpolated")
        else:
            assert E == rows[-1]["secant_young_pa"] and "secant" in rule
        return E

    for steep in (0.5, 1.0, 1.3, 2.0, 3.0):
        for E0 in (50e6, 0.05e6):
            rows, held = _calibrate_synthetic(bracketed, steep, E0)
            assert held, (steep, E0, [r["dem_fem_strain_ratio"] for r in rows])
            if steep >= 1.0:
                rows, held = _calibrate_synthetic(plain, steep, E0)
                assert not held, (steep, E0)
    # a ratio that is not finite (strains not both measured) is not a bracket's end
    rows = [{"pass": 1, "soil_young_pa": 5e6, "dem_fem_strain_ratio": float("nan"),
             "secant_young_pa": 2e6},
            {"pass": 2, "soil_young_pa": 2e6, "dem_fem_strain_ratio": 0.3,
             "secant_young_pa": 3e6}]
    assert next_soil_young(rows)[0] == 3e6
