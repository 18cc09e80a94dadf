"""Packing generators: loose cloud, hexagonal packing, gravity deposition, CSV round trip."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem import measure
from cpp_dem.build import packing
from cpp_dem.build import psd
from cpp_dem.protocols import prep


def _overlaps(c, r, chunk=512):
    """True if any two spheres overlap (row blocks keep the memory small)."""
    for a in range(0, len(c), chunk):
        d = np.linalg.norm(c[a:a + chunk, None] - c[None], axis=2)
        d[np.arange(len(d)), a + np.arange(len(d))] = np.inf
        if np.any(d < r[a:a + chunk, None] + r[None] - 1e-12):
            return True
    return False


def test_loose_cloud_non_overlapping_inside_and_seeded(tmp_path):
    r = psd.radii_uniform(0.004, 0.001, 300, seed=1)
    c, rr = packing.loose_cloud(r, (0, 0, 0), (0.08, 0.08, 0.08), seed=5)
    assert not _overlaps(c, rr)
    assert np.all(c - rr[:, None] >= 0) and np.all(c + rr[:, None] <= 0.08)
    c2, _ = packing.loose_cloud(r, (0, 0, 0), (0.08, 0.08, 0.08), seed=5)
    assert np.array_equal(c, c2)
    packing.write_packing_csv(tmp_path / "p.csv", c, rr)
    c3, r3 = dem.read_packing_csv(tmp_path / "p.csv")
    assert np.array_equal(c3, c) and np.array_equal(r3, rr)


def test_box_smaller_than_largest_grain():
    with pytest.raises(dem.ParameterError, match=r"box size along x=0.01: must be > the largest"):
        packing.loose_cloud([0.006], (0, 0, 0), (0.01, 0.1, 0.1))
    with pytest.raises(dem.ParameterError, match="box size along z"):
        packing.hex_packing((0, 0, 0), (0.1, 0.1, 0.005), 0.003)


def test_too_dense_cloud_fails_clearly():
    with pytest.raises(dem.ParameterError, match="could not place sphere"):
        packing.loose_cloud(np.full(200, 0.01), (0, 0, 0), (0.1, 0.1, 0.1), max_tries=50)


def test_hex_packing_porosity_of_the_lattice():
    r = 0.001
    c, rr = packing.hex_packing((0, 0, 0), (0.04, 0.04, 0.04), r)
    assert not _overlaps(c, rr)
    # Interior density: spheres with centres in a core region of a close packing fill
    # pi / (3 sqrt 2) = 0.7405 of it.
    lo, hi = 0.01, 0.03
    inside = np.all((c >= lo) & (c < hi), axis=1)
    frac = inside.sum() * 4 / 3 * np.pi * r**3 / (hi - lo) ** 3
    assert abs(frac / (np.pi / (3 * np.sqrt(2))) - 1) < 0.04
    # Touching neighbours: 12 in the bulk.
    k = np.argmin(np.linalg.norm(c - 0.02, axis=1))
    d = np.linalg.norm(c - c[k], axis=1)
    assert np.sum(np.abs(d - 2 * r) < 1e-9) == 12


def test_porosity_of_a_simple_cubic_lattice():
    r = 0.005
    g = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
    s = dem.Scene()
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    walls = s.add_box((0, 0, 0), (0.04, 0.04, 0.04), material=m)
    s.add_spheres(r + 2 * r * g, np.full(len(g), r), material=m)
    assert abs(measure.porosity(s, walls) - (1 - np.pi / 6)) < 1e-12


def test_gravity_deposition_settles():
    mat = dem.linear_material(density=2650, young=1e6, poisson=0.3, friction_angle_deg=30)
    r = psd.radii_uniform(0.004, 0.001, 60, seed=2)
    c, rr, info = prep.gravity_deposition(r, (0, 0, 0), (0.05, 0.05, 0.1), material=mat,
                                             seed=2, max_time=1.5, settled_speed=5e-3)
    assert info["settled"], info
    assert c[:, 2].max() < 0.05  # the cloud filled the box; the deposit sits in its lower half


def test_a_builder_placing_fewer_grains_than_asked_says_so_and_records_both():
    lines = []
    rec = packing.placed_count(300, 255, "cleared from the grid's layer", log=lines.append)
    assert lines == ["300 grains asked, 255 placed: 45 cleared from the grid's layer"]
    assert rec == {"grains_asked": 300, "grains_placed": 255}
    lines.clear()
    assert packing.placed_count(60, 60, "-", log=lines.append, what="clumps") == \
        {"grains_asked": 60, "grains_placed": 60}
    assert lines == []  # as asked: nothing to say
    packing.placed_count(60, 47, "did not fit", log=lines.append, what="clumps")
    assert lines == ["60 clumps asked, 47 placed: 13 did not fit"]
    with pytest.raises(dem.ParameterError, match="placed=61"):
        packing.placed_count(60, 61, "-")
