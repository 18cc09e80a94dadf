"""The cylindrical triaxial test in a membrane (cpp_dem.protocols.cylinder_triaxial): the
specimen made in a mould is held by the membrane at the cell pressure, then sheared at a
constant axial strain rate with its volume from the membrane; the rows are what the docs say;
bad input is refused by name."""

import math

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.protocols import cylinder_triaxial as ct

P = 100e3  # Pa


@pytest.fixture(scope="module")
def sheared():
    radii = 0.002 * np.random.default_rng(1).uniform(0.8, 1.0, 300)
    mat = dem.linear_material(density=2650, young=5e7, poisson=0.3, friction_angle_deg=30)
    spec = ct.prepare(radii, radius_m=0.017, height_m=0.05, pressure_pa=P, material=mat)
    prepared = dict(spec.prepared)
    rows = ct.shear(spec, strain_rate=0.5, stop_strain=0.02, record_every=1000)
    return spec, prepared, rows


def test_the_membrane_holds_the_specimen_at_the_cell_pressure(sheared):
    spec, prepared, rows = sheared
    assert prepared["reached"]
    assert prepared["grains_outside"] == 0
    assert prepared["axial_stress_pa"] == pytest.approx(P, rel=0.01)
    # The grains' radial stress is the cell pressure plus the membrane's correction (what
    # its tension adds), measured: 2.5 kPa here.
    assert prepared["radial_stress_pa"] == pytest.approx(P + prepared["membrane_correction_pa"],
                                                         rel=1e-12)
    assert abs(prepared["membrane_correction_pa"]) < 0.05 * P
    assert rows[0]["axial_strain"] == 0 and rows[0]["volumetric_strain"] == 0


def test_shearing_gives_the_deviator_and_the_volume_change_from_the_membrane(sheared):
    spec, prepared, rows = sheared
    eps_a = np.array([r["axial_strain"] for r in rows])
    q = np.array([r["deviatoric_stress_pa"] for r in rows])
    eps_v = np.array([r["volumetric_strain"] for r in rows])
    assert eps_a[-1] >= 0.02 and np.all(np.diff(eps_a) > 0)
    # The specimen (friction 30 deg, made in a frictionless mould) stiffens and contracts.
    assert q[-1] > 0.8 * P
    assert np.all(eps_v[1:] > 0)
    # The deviator is the axial stress on the current cross-section less the cell pressure,
    # and the cross-section is the volume inside the membrane over the height.
    z0, z1 = spec.scene.wall_positions
    last = rows[-1]
    assert last["area_m2"] == pytest.approx(spec.membrane.inner_volume_m3(spec.scene) / (z1 - z0),
                                            rel=1e-12)
    assert last["deviatoric_stress_pa"] == pytest.approx(last["axial_stress_pa"] - P, rel=1e-12)
    assert last["volumetric_strain"] == pytest.approx(
        1 - spec.membrane.inner_volume_m3(spec.scene) / spec.volume0_m3, rel=1e-12)
    # The membrane's correction is measured (the grains' radial stress less the cell
    # pressure: what the membrane's tension adds) and small beside the deviator.
    corr = np.array([r["membrane_correction_pa"] for r in rows])
    assert np.all(np.abs(corr) < 0.05 * P)
    assert all(r["grains_outside"] == 0 for r in rows)
    # The base carries what the lid does but what the membrane takes by its friction with
    # the grains, and the loading's dynamics: within 3.1 % here once loading is under way
    # (at 0.5 /s a 1 500-grain specimen of soft grains runs 15 % apart).
    late = [r for r in rows if r["axial_strain"] > 0.005]
    assert all(abs(r["axial_stress_pa"] - r["base_stress_pa"]) < 0.05 * r["axial_stress_pa"]
               for r in late)


def test_bad_input_is_refused_by_name(sheared):
    spec, _, _ = sheared
    with pytest.raises(dem.ParameterError, match="strain_rate=0"):
        ct.shear(spec, strain_rate=0.0, stop_strain=0.1)
    with pytest.raises(dem.ParameterError, match="stop_strain=nan"):
        ct.shear(spec, strain_rate=0.1, stop_strain=math.nan)
    with pytest.raises(dem.ParameterError, match="pressure_pa=-1"):
        ct.prepare([0.002] * 10, radius_m=0.017, height_m=0.05, pressure_pa=-1,
                   material=dem.linear_material(density=2650, young=5e7, poisson=0.3,
                                                friction_angle_deg=30))
