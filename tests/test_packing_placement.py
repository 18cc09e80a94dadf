"""Random sequential addition (cpp_dem.build.packing.loose_cloud and loose_cylinder) checks
its tries in batches; the cloud is, to the bit, the one of trying one at a time: each sphere,
largest first, takes the first try (three uniform draws from the seeded generator) that lies
inside and overlaps no sphere placed before it. The reference below is that rule written
plainly (every placed sphere checked, one try at a time)."""

from __future__ import annotations

import numpy as np
import pytest

from cpp_dem._core import ParameterError
from cpp_dem.build.packing import loose_cloud, loose_cylinder, spatial_order


def _one_at_a_time(radii, lo, hi, seed, max_tries, inside=None):
    r = np.sort(np.asarray(radii, float))[::-1]
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    rng = np.random.default_rng(seed)
    pos = np.empty((len(r), 3))
    for k, rk in enumerate(r):
        for _ in range(max_tries):
            x = lo + rk + rng.random(3) * (hi - lo - 2 * rk)
            if inside is not None and not inside(x, rk):
                continue
            if not np.any(((pos[:k] - x) ** 2).sum(1) < (r[:k] + rk) ** 2):
                pos[k] = x
                break
        else:
            return k  # (the sphere that could not be placed)
    order = spatial_order(pos, r)
    return pos[order], r[order]


def _clouds(count):
    rng = np.random.default_rng(5)
    for i in range(count):
        n = int(rng.integers(1, 300))
        radii = rng.uniform(0.5, 1.5, n) * (rng.uniform(0.2, 1.0, n) if i % 3 == 0 else 1.0)
        frac = rng.choice([0.01, 0.1, 0.2, 0.3])
        shape = rng.uniform(0.6, 1.6, 3)
        edge = (np.sum(4 / 3 * np.pi * radii**3) / frac) ** (1 / 3) * shape / np.prod(shape) ** (1 / 3)
        yield radii, np.maximum(edge, 2.2 * radii.max()), int(rng.integers(0, 10**6))


def test_a_cloud_is_the_one_of_one_try_at_a_time_to_the_bit():
    for radii, hi, seed in _clouds(30):
        lo = (-1.0, 0.5, 2.0)
        hi = np.add(lo, hi)
        c, r = loose_cloud(radii, lo, hi, seed=seed)
        c0, r0 = _one_at_a_time(radii, lo, hi, seed, 2000)
        assert np.array_equal(c, c0) and np.array_equal(r, r0), seed


def test_a_cylinder_is_the_one_of_one_try_at_a_time_to_the_bit():
    rng = np.random.default_rng(2)
    for seed in range(8):
        radii = rng.uniform(0.5, 1.0, int(rng.integers(1, 200)))
        radius = float(np.sum(radii**3) ** (1 / 3) * rng.uniform(1.3, 3.0))
        centre = np.array([1.0, -2.0, 0.5])

        def inside(x, rk):
            return (x[0] - centre[0]) ** 2 + (x[1] - centre[1]) ** 2 <= (radius - rk) ** 2

        c, r = loose_cylinder(radii, radius, 2 * radius, centre=centre, seed=seed)
        c0, r0 = _one_at_a_time(radii, centre - [radius, radius, 0], centre + [radius, radius,
                                2 * radius], seed, 2000, inside)
        assert np.array_equal(c, c0) and np.array_equal(r, r0), seed


def test_the_tries_run_out_at_the_same_sphere_and_are_named():
    """A dense cloud with few tries: the sphere that cannot be placed is the reference's, and
    with one try more than the last sphere needed, every sphere is placed as there."""
    radii = np.full(400, 1.0)
    edge = (400 * 4 / 3 * np.pi / 0.33) ** (1 / 3)
    for tries in (5, 40):
        stuck = _one_at_a_time(radii, (0, 0, 0), (edge,) * 3, 7, tries)
        assert isinstance(stuck, int)
        with pytest.raises(ParameterError, match=rf"could not place sphere {stuck} \(r=1.0\) "
                                                 rf"in {tries} tries"):
            loose_cloud(radii, (0, 0, 0), (edge,) * 3, seed=7, max_tries=tries)


@pytest.mark.parametrize("radii, hi", [
    (np.r_[20.0, np.full(300, 1.0)], (90.0, 90.0, 90.0)),  # one large sphere among small ones
    (np.full(200, 1.0), (60.0, 60.0, 2.5)),  # a flat box: one cell across its height
    (np.array([1.0]), (2.5, 2.5, 2.5)),  # one sphere, little room
    (np.geomspace(0.1, 2.0, 400), (40.0, 25.0, 30.0)),  # a wide spread of sizes
])
def test_uneven_clouds_are_the_one_of_one_try_at_a_time(radii, hi):
    c, r = loose_cloud(radii, (0, 0, 0), hi, seed=11)
    c0, r0 = _one_at_a_time(radii, (0, 0, 0), hi, 11, 2000)
    assert np.array_equal(c, c0) and np.array_equal(r, r0)
