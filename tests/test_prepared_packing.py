"""A grown packing of 002's element on disk (cpp_dem.elements.box.save_prepared and
restore_prepared): a resumed run restores it instead of growing it again, and the element it
loads from there is bitwise the one it would have grown (its series, measures, growth history
and summary); a file of other parameters is set aside and the packing grown again."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from cpp_dem.elements.box import restore_prepared, run_element

ROWS = [np.array([3e3, 3e3, 5.4e3])]


@pytest.fixture(scope="module")
def params():
    from geogrid_dem.cases import prs_element_002 as case

    return replace(case.Params(**case.SMOKE), geogrid="woven-detailed", seed=1, n=150,
                   hold_steps=300)


def _summary(res: dict) -> str:
    def strip(d):
        if isinstance(d, dict):
            return {k: strip(v) for k, v in d.items()
                    if "wall" not in k and k not in ("label", "prepared_sha256")}
        return [strip(x) for x in d] if isinstance(d, list) else d
    return json.dumps(strip(res), sort_keys=True, default=float)


def test_a_restored_packing_gives_the_grown_element_bitwise(params, tmp_path):
    file = tmp_path / "packing.h5"
    said: list[str] = []
    grown = run_element(params, ROWS, prestressed=False, label="a", out=tmp_path / "a",
                        log=said.append, prepared={"file": file}, grow_stress=4e3)
    assert file.is_file()
    said.clear()
    again = run_element(params, ROWS, prestressed=False, label="b", out=tmp_path / "b",
                        log=said.append, prepared={"file": file}, grow_stress=4e3)
    assert any("the grown packing restored from" in m and "no growth" in m for m in said), said
    assert _summary(again) == _summary(grown)
    for name in ("{}.csv", "{}_measures.csv", "{}_growth.csv"):
        a = (tmp_path / "a" / name.format("a")).read_bytes()
        b = (tmp_path / "b" / name.format("b")).read_bytes()
        assert a == b, name


def test_a_packing_of_other_parameters_is_set_aside(params, tmp_path):
    from cpp_dem.elements.box import prepare_woven_element, save_prepared

    file = tmp_path / "packing.h5"
    sample, _grid = prepare_woven_element(params, 4e3, log=lambda m: None)
    save_prepared(file, sample, params, 4e3, "a")
    said: list[str] = []
    prepared = {"file": file}
    assert not restore_prepared(prepared, replace(params, seed=2), 4e3, log=said.append)
    assert "state" not in prepared and not file.exists()
    assert (tmp_path / "packing.h5.stale").is_file()
    assert "other element parameters: set aside as packing.h5.stale" in said[0], said
    assert not restore_prepared({"file": file}, params, 4e3)  # (no file: grown as before)
