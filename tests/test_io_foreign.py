"""Packings in Yade, LIGGGHTS and PFC files (cpp_dem.io.foreign): round trips are exact, the
formats as those codes write them are read, bad files are named."""

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.io import foreign


@pytest.fixture
def packing(rng):
    c = rng.uniform(0, 0.1, (50, 3))
    r = rng.uniform(0.002, 0.004, 50)
    return c, r


def test_yade_text_round_trip_and_yade_layout(tmp_path, packing):
    c, r = packing
    foreign.write_yade_text(tmp_path / "s.txt", c, r)
    assert (tmp_path / "s.txt").read_text().startswith("#format x_y_z_r\n")
    c2, r2 = foreign.read_yade_text(tmp_path / "s.txt")
    np.testing.assert_array_equal(c2, c)
    np.testing.assert_array_equal(r2, r)
    (tmp_path / "y.txt").write_text("# a comment\n0.1 0.2 0.3 0.01\n\n0.4 0.5 0.6 0.02\n")
    c3, r3 = foreign.read_yade_text(tmp_path / "y.txt")
    np.testing.assert_array_equal(c3, [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    np.testing.assert_array_equal(r3, [0.01, 0.02])


def test_liggghts_data_round_trip_box_and_id_order(tmp_path, packing):
    c, r = packing
    foreign.write_liggghts_data(tmp_path / "d.data", c, r, density=2650, lo=(0, 0, 0),
                                hi=(0.1, 0.1, 0.12))
    c2, r2 = foreign.read_liggghts_data(tmp_path / "d.data")
    np.testing.assert_array_equal(c2, c)
    np.testing.assert_allclose(r2, r, rtol=1e-15)  # stored as a diameter
    lo, hi = foreign.read_liggghts_box(tmp_path / "d.data")
    np.testing.assert_array_equal(hi, [0.1, 0.1, 0.12])
    # Atoms out of id order, with a comment, as LIGGGHTS's write_data may leave them.
    (tmp_path / "l.data").write_text(
        "LIGGGHTS data\n\n2 atoms\n1 atom types\n\n0 1 xlo xhi\n0 1 ylo yhi\n0 1 zlo zhi\n\n"
        "Atoms # granular\n\n2 1 0.004 2500 0.5 0.5 0.5\n1 1 0.002 2500 0.1 0.1 0.1\n")
    c3, r3 = foreign.read_liggghts_data(tmp_path / "l.data")
    np.testing.assert_array_equal(c3[0], [0.1, 0.1, 0.1])
    np.testing.assert_array_equal(r3, [0.001, 0.002])


def test_pfc_ball_list_round_trip_and_header(tmp_path, packing):
    c, r = packing
    foreign.write_pfc_balls(tmp_path / "b.txt", c, r)
    c2, r2 = foreign.read_pfc_balls(tmp_path / "b.txt")
    np.testing.assert_array_equal(c2, c)
    np.testing.assert_array_equal(r2, r)
    (tmp_path / "p.csv").write_text("ID,X,Y,Z,RADIUS\n7,0.1,0.2,0.3,0.01\n3,0.4,0.5,0.6,0.02\n")
    c3, r3 = foreign.read_pfc_balls(tmp_path / "p.csv")
    np.testing.assert_array_equal(r3, [0.02, 0.01])  # by id


@pytest.mark.parametrize("reader, text, match", [
    (foreign.read_yade_text, "0.1 0.2 zz 0.01\n", r"y\.txt:1: not numbers"),
    (foreign.read_yade_text, "0.1 0.2 0.3 -0.01\n", r"radius -0\.01: must be > 0"),
    (foreign.read_liggghts_data, "2 atoms\nAtoms\n1 1 0.002 2500 0 0 0\n",
     r"header says 2 atoms, the Atoms section has 1"),
    (foreign.read_pfc_balls, "1 0.1 0.2\n", r"expected 5 values"),
])
def test_bad_files_name_the_file_and_line(tmp_path, reader, text, match):
    (tmp_path / "y.txt").write_text(text)
    with pytest.raises(dem.ParameterError, match=match):
        reader(tmp_path / "y.txt")
