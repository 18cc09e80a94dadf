"""Recorders never write inf or NaN (issue 20, item 2): a non-finite value stops the record
with an error naming the series, the value and the step, and nothing of that row is written.
The unbalanced force's NaN (no contacts: undefined) is the one documented exception."""

import math

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.io import CsvRecorder, H5Recorder, NonFiniteValueError, read_csv_series
from cpp_dem.io import read_h5_series


def scene_with_a_grain():
    s = dem.Scene(gravity=(0, 0, -9.81))
    m = s.add_material(dem.linear_material(density=2650, young=1e7, poisson=0.3,
                                           friction_angle_deg=30))
    s.add_box((0, 0, 0), (0.1, 0.1, 0.1), material=m)
    s.add_spheres([[0.05, 0.05, 0.05]], [0.005], material=m)
    s.dt = 1e-5
    s.track_energy = True
    return s


@pytest.mark.parametrize("recorder, reader, name", [(H5Recorder, read_h5_series, "r.h5"),
                                                    (CsvRecorder, read_csv_series, "r.csv")])
@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_a_non_finite_value_is_refused_and_nothing_of_the_row_written(tmp_path, recorder,
                                                                       reader, name, bad):
    s = scene_with_a_grain()
    rec = recorder(tmp_path / name, s)
    s.run(10)
    rec.record()  # a good row
    s.run(10)
    with pytest.raises(NonFiniteValueError,
                       match=r"series 'kinetic': value .* is not finite at step 20"):
        rec.record(kinetic=bad)
    rec.close()
    got = reader(tmp_path / name)
    assert len(got["time"]) == 1 and np.all(np.isfinite(got["kinetic"]))


def test_the_unbalanced_force_without_contacts_stays_nan(tmp_path):
    s = scene_with_a_grain()  # the grain touches nothing
    with CsvRecorder(tmp_path / "r.csv", s) as rec:
        s.run(5)
        rec.record()
    got = read_csv_series(tmp_path / "r.csv")
    assert math.isnan(got["unbalanced_force"][0])


def test_a_vector_series_with_an_inf_component_is_refused(tmp_path):
    s = scene_with_a_grain()
    with H5Recorder(tmp_path / "r.h5", s) as rec:
        with pytest.raises(NonFiniteValueError, match="wall_force_zmin"):
            rec.record(wall_force_zmin=np.array([0.0, math.inf, 0.0]))
