"""PSD: sampling by mass and by count reproduces the sieve curve; bad curves are refused."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.build import psd


def test_mass_sampling_follows_the_curve():
    sizes, passing = [0.004, 0.007, 0.01, 0.02], [0.0, 0.3, 0.5, 1.0]
    r = psd.radii_from_psd(sizes, passing, 20000, by="mass", seed=1)
    assert r.min() >= 0.002 and r.max() <= 0.01
    got = psd.passing_of(r, sizes, by="mass")
    assert np.max(np.abs(got - passing)) < 0.01  # measured ~2e-3


def test_count_sampling_follows_the_curve():
    sizes, passing = [0.004, 0.007, 0.01, 0.02], [0.0, 0.3, 0.5, 1.0]
    r = psd.radii_from_psd(sizes, passing, 5000, by="count", seed=2)
    got = psd.passing_of(r, sizes, by="count")
    assert np.max(np.abs(got - passing)) < 2e-3  # stratified


def test_expected_count_matches_sampling():
    sizes, passing = psd.truncate_psd(psd.APPENDIX_B_SIZES, psd.APPENDIX_B_PASSING, 0.007)
    n = psd.expected_count(sizes, passing, 0.01)
    r = psd.radii_from_psd(sizes, passing, 4000, seed=3)
    mean_v = np.mean(4 / 3 * np.pi * r**3)
    assert abs(0.01 / mean_v / n - 1) < 0.02


def test_fit_to_count_truncate_and_scale():
    d, p, dmin = psd.fit_psd_to_count(psd.APPENDIX_B_SIZES, psd.APPENDIX_B_PASSING, 15000,
                                      0.6 * 0.054)
    assert abs(psd.expected_count(d, p, 0.6 * 0.054) / 15000 - 1) < 1e-6
    assert 0.007 < dmin < 0.02 and d[-1] == 0.025
    d2, p2, s = psd.fit_psd_to_count([0.01, 0.02], [0, 1], 100, 0.01, by="count",
                                     method="scale")
    assert abs(psd.expected_count(d2, p2, 0.01, by="count") / 100 - 1) < 1e-9


def test_uniform_mean_dispersion():
    r = psd.radii_uniform(0.012, 0.006, 1000, seed=0)  # 000 Table 1
    assert r.min() >= 0.006 and r.max() <= 0.018 and abs(r.mean() - 0.012) < 1e-4


@pytest.mark.parametrize("sizes,passing,msg", [
    ([0.001, 0.002, 0.003], [0.0, 0.6, 0.5], "passing[2]=0.5: must be >= passing[1]"),
    ([0.001, 0.002, 0.003], [0.0, 0.5, 0.9], "passing[-1]=0.9: must be 1"),
    ([-0.001, 0.002, 0.003], [0.0, 0.5, 1.0], "sizes[0]=-0.001: must be > 0"),
    ([0.002, 0.001, 0.003], [0.0, 0.5, 1.0], "sizes[1]=0.001: must be > sizes[0]"),
    ([0.001, 0.002], [0.0, 0.5, 1.0], "passing: has 3 values for 2 sizes"),
])
def test_bad_curves_are_refused(sizes, passing, msg):
    with pytest.raises(dem.ParameterError, match=msg.replace("[", r"\[").replace("]", r"\]")):
        psd.radii_from_psd(sizes, passing, 10)


def test_bad_uniform_refused():
    with pytest.raises(dem.ParameterError, match="dispersion=0.02"):
        psd.radii_uniform(0.01, 0.02, 10)
