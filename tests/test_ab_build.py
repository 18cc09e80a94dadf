"""bench/ab_build.py's membrane and mesh-box scenes are built and stepped, and an unknown scene
refused; bench/ab_case.py's comparison of two runs' summaries and its refusals (the builds
themselves are not made here: CI does not run the A/B)."""

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ab():
    spec = importlib.util.spec_from_file_location("ab_build", ROOT / "bench" / "ab_build.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["ab_build"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_the_membrane_scene_is_the_cylindrical_specimen_in_its_membrane():
    ab = _ab()
    scene, advance = ab.membrane_scene(100)
    n0 = scene.step_count
    advance(20)
    assert scene.step_count == n0 + 20
    assert scene.num_bodies > 100  # the grains and the membrane's nodes
    assert len(scene.grid_contacts()["sphere"]) > 0  # the membrane holds the grains
    assert scene.wall_velocities[1][2] < 0  # the lid moves down


def test_the_meshbox_scene_starts_both_builds_from_one_settled_state(tmp_path):
    """The grains settle once; a second block (the other build) reads that state: the same
    scene, stepped the same, to the bit. The grains rest on the mesh's floor."""
    import numpy as np

    ab = _ab()
    a = ab.meshbox_scene(150, cache_dir=tmp_path)
    assert (tmp_path / "meshbox_150.npz").is_file()
    b = ab.meshbox_scene(150, cache_dir=tmp_path)
    for s in (a, b):
        assert (s.num_mesh_walls, s.num_walls, s.num_bodies) == (1, 0, 150)
        assert s.mesh_wall(0)["num_triangles"] == 10092
        s.run(50)
    assert np.array_equal(np.asarray(a.positions), np.asarray(b.positions))
    w = a.mesh_wall(0)
    assert w["force"][2] < 0 and np.array_equal(w["force"], b.mesh_wall(0)["force"])


def test_an_unknown_scene_is_refused_by_name():
    ab = _ab()
    with pytest.raises(SystemExit, match="membrane"):
        ab.main(["--scenes", "cylinder:100"])


def test_the_floor_block_moves_one_body_by_one_ulp(tmp_path):
    """The chaos floor's block (an A/B whose builds differ in their bits): the same scene with
    the first body moved by one ulp; before any step the positions differ by that ulp alone,
    and after steps the two runs differ, the unperturbed one repeating itself to the bit."""
    import json

    import numpy as np

    ab = _ab()
    out = {}
    for name, perturb, steps in (("a", False, 0), ("b", True, 0), ("c", False, 300),
                                 ("d", False, 300), ("e", True, 300)):
        cfg = {"variant": "new", "scene": "spheres", "n": 300, "threads": 1, "steps": steps,
               "warmup": 0, "dump": str(tmp_path / f"{name}.npy"), "overlay": "",
               "perturb": perturb}
        r = ab.worker(json.loads(json.dumps(cfg)))
        out[name] = (np.load(tmp_path / f"{name}.npy"), r["state_sha256"])
    d = out["b"][0] - out["a"][0]
    assert np.count_nonzero(d) == 1 and d[0, 0] == np.spacing(out["a"][0][0, 0])
    assert out["c"][1] == out["d"][1]
    assert out["c"][1] != out["e"][1] and np.abs(out["c"][0] - out["e"][0]).max() > 0


def _ab_case():
    _ab()  # (ab_case imports ab_build's builder)
    spec = importlib.util.spec_from_file_location("ab_case", ROOT / "bench" / "ab_case.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_case_ab_compares_every_result_but_the_wall_times():
    """bench/ab_case.py: two summaries that differ only in their wall times (and a NaN on
    both sides) are identical; one number changed in the last bit, a missing field or a
    changed type is named by its path."""
    ab = _ab_case()
    old = {"elements": {"RE_s1": {"wall_time_s": 35.9, "stage_wall_time_s": [2.8, 5.8],
                                  "porosity_final": 0.4105, "rest": {"dt": float("nan")},
                                  "converged": [True, True]}},
           "findings": [{"verdict": "not resolved", "diff_mean": 4.024e-10}],
           "wall_time_total_s": 168.2}
    new = json.loads(json.dumps(old, allow_nan=True))
    new["elements"]["RE_s1"]["wall_time_s"] = 30.1
    new["elements"]["RE_s1"]["stage_wall_time_s"] = [2.1, 5.0]
    new["wall_time_total_s"] = 150.0
    assert ab.differences(old, new) == []
    new["findings"][0]["diff_mean"] = math.nextafter(4.024e-10, 1.0)
    new["elements"]["RE_s1"]["converged"] = [True, 1]
    del new["elements"]["RE_s1"]["porosity_final"]
    d = ab.differences(old, new)
    assert len(d) == 3, d
    assert any(x.startswith(".findings[0].diff_mean: 4.024e-10 -> ") for x in d), d
    assert ".elements.RE_s1.converged[1]: True -> 1" in d, d
    assert ".elements.RE_s1.porosity_final: present -> missing" in d, d


def test_the_case_ab_refuses_an_unknown_case_and_an_out_among_its_arguments(capsys):
    ab = _ab_case()
    assert ab.case_module("prs-element-002") == "geogrid_dem.cases.prs_element_002"
    assert ab.case_module("prs_element_002") == "geogrid_dem.cases.prs_element_002"
    with pytest.raises(ab._cli.BenchInputError, match="'nosuch': not a case; one of "
                                                      "pullout-000, "):
        ab.case_module("nosuch")
    with pytest.raises(ab._cli.BenchInputError, match="--out among the case's arguments"):
        ab.main(["--ref", "HEAD", "--", "deposition", "--smoke", "--out", "x"])


def test_the_placement_ab_finds_the_same_cloud_and_refuses_bad_sizes(tmp_path):
    """bench/ab_placement.py against this very revision: the same clouds, to the bit, one
    JSON line per size appended to --out; a size out of range is refused by name."""
    import json
    import subprocess
    import sys

    bench = ROOT / "bench" / "ab_placement.py"
    out = tmp_path / "ab.jsonl"
    p = subprocess.run([sys.executable, str(bench), "--ref", "HEAD", "--sizes", "30:0.1,80:0.3",
                        "--rounds", "2", "--out", str(out)], capture_output=True, text=True,
                       cwd=ROOT)
    assert p.returncode == 0, p.stderr[-2000:]
    rows = [json.loads(x) for x in out.read_text().splitlines()]
    assert [(r["n"], r["solid_fraction"]) for r in rows] == [(30, 0.1), (80, 0.3)]
    assert all(r["identical"] and r["old_s"] > 0 and r["new_s"] > 0 for r in rows)
    bad = subprocess.run([sys.executable, str(bench), "--ref", "HEAD", "--sizes", "30:0.6"],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode != 0 and "--sizes='30:0.6'" in bad.stderr


def test_the_fastest_blocks_ratio_holds_where_the_rounds_ratios_scatter():
    """A host that slows some blocks: the new build takes 0.9 of the old's time (1.111 x the
    speed) in every undisturbed block. One disturbed block of each build moves the median of
    the rounds' ratios off the truth; the ratio of the fastest blocks keeps it. With every
    block of a build disturbed, it cannot (its documented condition)."""
    ab = _ab()
    old, new = [1.0, 1.4, 1.3], [1.3, 0.9, 1.25]
    r = ab.speed_ratios(old, new)
    assert r["ratio_fastest"] == pytest.approx(1.0 / 0.9)
    assert abs(r["ratio_new_over_old"] - 1.0 / 0.9) > 0.05
    assert (r["ratio_min"], r["ratio_max"]) == (pytest.approx(1.0 / 1.3), pytest.approx(1.4 / 0.9))
    assert ab.speed_ratios([1.0, 1.0], [0.9, 0.9])["ratio_fastest"] == pytest.approx(1.0 / 0.9)
    assert abs(ab.speed_ratios([1.0, 1.0], [1.2, 1.1])["ratio_fastest"] - 1.0 / 0.9) > 0.1
