"""``geogrid-dem continue RUN_DIR LABEL --steps N`` (issue 59 item 7): a finished element of
prs_element_002 restored from its final state (<label>_final.h5) and cycled on
(geogrid_dem.continue_run; the skeleton: cpp_dem.elements.box.prepare_woven_element's
``build_only``)."""

import hashlib
import json
import os
import subprocess
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cpp_dem import _core
from cpp_dem.measure.inertial import InertialNumberWarning
from cpp_dem.elements import box
from geogrid_dem import cli
from geogrid_dem import continue_run as cr
from geogrid_dem.cases import prs_element_002 as case

#: Two rows of targets (Pa): the grown state, then a vertical load.
ROWS = [[5e3, 5e3, 5e3], [6e3, 6e3, 8e3]]
LABELS = ("detailed_RE_s1", "detailed_PRS_s1")
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}


def small_params(**kw) -> case.Params:
    """The case's smoke at 150 clumps of 6 spheres (below the case's aperture check, so run
    through box.run_element directly), density scaling 8, every axis servoed."""
    return case.Params(**{**case.SMOKE, "n": 150, "density_scaling": 8.0,
                          "grains": "clumps:gravel@6", "seed": 1, "geogrid": "woven-detailed",
                          "kinematics": "stress", "max_steps": 20_000, **kw})


def quiet(_msg: str) -> None:
    pass


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A small real run: RE (grid ends free) and PRS (ends pulled by T_p: an EndTension) on
    one grown packing, as the case runs them; summary.json holds the elements' summaries."""
    out = tmp_path_factory.mktemp("prs002_run")
    p = small_params()
    prepared: dict = {}
    elements = {}
    for label, prs, ends in (("detailed_RE_s1", False, "lock"),
                             ("detailed_PRS_s1", True, "tension")):
        with warnings.catch_warnings():  # (the small element's first stage is a jump)
            warnings.simplefilter("ignore", InertialNumberWarning)
            elements[label] = box.run_element(replace(p, grid_ends=ends), ROWS,
                                              prestressed=prs, label=label, out=out,
                                              prepared=prepared, draw_figures=False, log=quiet)
    (out / "summary.json").write_text(json.dumps({"elements": elements}, default=float))
    return out


def tree_hashes(d: Path) -> dict:
    return {str(f.relative_to(d)): hashlib.sha256(f.read_bytes()).hexdigest()
            for f in sorted(d.rglob("*")) if f.is_file()}


def cli_run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "geogrid_dem.cli", "continue", *map(str, args)],
                          capture_output=True, text=True, env=ENV, timeout=600)


def test_each_element_saved_its_final_state(run_dir):
    assert sorted(cr.final_states(run_dir)) == sorted(LABELS)
    extra = cr.read_extra(run_dir / "detailed_PRS_s1_final.h5")
    assert extra["grid_end_tension_n_per_m"] == pytest.approx(small_params().prestress)
    assert extra["modes"] == ["stress"] * 3 and extra["prestressed"] is True
    assert cr.read_extra(run_dir / "detailed_RE_s1_final.h5")["grid_end_tension_n_per_m"] is None


@pytest.mark.parametrize("label", LABELS)
def test_zero_steps_restore_the_exact_final_state(run_dir, label):
    summary = json.loads((run_dir / "summary.json").read_text())["elements"][label]
    res = cr.continue_element(run_dir, label, 0, log=quiet)
    assert list(res) == ["label", "steps", "added_strain", "stress_pa", "inertial_number"]
    assert res["label"] == label and res["steps"] == 0
    assert res["added_strain"] == [0.0, 0.0, 0.0] and res["inertial_number"] == 0.0
    np.testing.assert_allclose(res["stress_pa"], summary["stress_final_pa"], rtol=1e-9, atol=0)
    # The grid's end conditions as they were: PRS's ends still pulled by T_p (the restored
    # external forces), RE's free.
    r = cr.restore_element(run_dir / f"{label}_final.h5", log=quiet)
    ext = np.asarray(r.sample.scene.external_forces)
    if label == "detailed_PRS_s1":
        assert r.ends is not None and r.ends.tension_per_m == pytest.approx(2000.0)
        e = r.ends.ends
        assert sorted(np.concatenate([e.low, e.high])) == list(np.flatnonzero(ext.any(axis=1)))
        pull = ext[e.high, e.axis].sum() / len(e.lines)
        assert pull == pytest.approx(2000.0 * e.spacing, rel=0.05)
        assert ext[e.low, e.axis].sum() == pytest.approx(-ext[e.high, e.axis].sum())
        # Its end bodies are those the run pulled: set() again pulls the same bodies by
        # about the same forces (the lines' spacing is measured again, on the final grid).
        r.ends.set(2000.0)
        ext2 = np.asarray(r.sample.scene.external_forces)
        assert np.array_equal(ext2.any(axis=1), ext.any(axis=1))
        assert ext2[e.high, e.axis].sum() == pytest.approx(ext[e.high, e.axis].sum(), rel=0.05)
    else:
        assert r.ends is None and r.prestress is None and not np.any(ext)
    for a in range(3):
        assert r.sample.controller.mode(a) == "stress"
        assert r.sample.controller.goal(a) == r.extra["set_points"][a]


def test_continuing_is_deterministic_and_leaves_run_dir_untouched(run_dir, tmp_path):
    before = tree_hashes(run_dir)
    a = cli_run(run_dir, "detailed_PRS_s1", "--steps", 2000)
    b = cli_run(run_dir, "detailed_PRS_s1", "--steps", 2000)
    for proc in (a, b):
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert len(proc.stdout.splitlines()) == 1, proc.stdout  # one JSON line, nothing else
    assert a.stdout == b.stdout
    res = json.loads(a.stdout)
    assert res["label"] == "detailed_PRS_s1" and res["steps"] == 2000
    assert len(res["added_strain"]) == 3 and len(res["stress_pa"]) == 3
    assert any(x != 0 for x in res["added_strain"]) and res["inertial_number"] > 0
    # Chained: 1000 steps into --out, then 1000 more from there, is the 2000 steps' state.
    first = cli_run(run_dir, "detailed_PRS_s1", "--steps", 1000, "--out", tmp_path / "c1")
    assert first.returncode == 0, first.stderr[-3000:]
    second = cli_run(tmp_path / "c1", "detailed_PRS_s1", "--steps", 1000)
    assert second.returncode == 0, second.stderr[-3000:]
    assert json.loads(second.stdout)["stress_pa"] == res["stress_pa"]
    assert tree_hashes(run_dir) == before  # nothing written, nothing changed


def test_out_holds_a_summary_and_a_continuable_state(run_dir, tmp_path):
    out = tmp_path / "more"
    res = cr.continue_element(run_dir, "detailed_RE_s1", 400, out=out, log=quiet)
    assert sorted(f.name for f in out.iterdir()) == ["detailed_RE_s1_continue.json",
                                                      "detailed_RE_s1_final.h5"]
    s = json.loads((out / "detailed_RE_s1_continue.json").read_text())
    assert {k: s[k] for k in res} == res
    assert s["step_end"] - s["step_start"] == 400
    assert s["source_sha256"] == hashlib.sha256(
        (run_dir / "detailed_RE_s1_final.h5").read_bytes()).hexdigest()
    # A second continuation into the same folder needs --overwrite.
    with pytest.raises(cr.UsageError, match=r"--out=.*earlier continuation.*--overwrite"):
        cr.continue_element(run_dir, "detailed_RE_s1", 1, out=out, log=quiet)
    assert cr.continue_element(out, "detailed_RE_s1", 0, log=quiet)["stress_pa"] == \
        res["stress_pa"]


def _refused(capsys, *args) -> str:
    with pytest.raises(SystemExit) as e:
        cli.main(["continue", *map(str, args)])
    err = capsys.readouterr()
    assert e.value.code == 2 and err.out == ""
    lines = err.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err.err, err.err
    return lines[0]


def test_bad_inputs_are_refused_by_name(run_dir, tmp_path, capsys):
    missing = tmp_path / "nowhere"
    assert "RUN_DIR=" in _refused(capsys, missing, "x", "--steps", 10) and not missing.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    msg = _refused(capsys, empty, "x", "--steps", 10)
    assert "RUN_DIR=" in msg and "_final.h5" in msg
    msg = _refused(capsys, run_dir, "detailed_XX_s1", "--steps", 10)
    assert "LABEL='detailed_XX_s1'" in msg and all(lab in msg for lab in LABELS)
    for bad in ("0", "-5", str(cr.MAX_STEPS + 1), "abc", "1.5"):
        msg = _refused(capsys, run_dir, "detailed_RE_s1", "--steps", bad)
        assert f"--steps={bad!r}" in msg and str(cr.MAX_STEPS) in msg
    msg = _refused(capsys, run_dir, "detailed_RE_s1", "--steps", 10, "--out", run_dir)
    assert "--out=" in msg and "RUN_DIR" in msg


def test_the_skeleton_takes_a_prepared_elements_state(tmp_path):
    """build_only builds the same bodies and controllers without a step: a prepared element's
    checkpoint loads into it and saves back byte for byte (fixed walls too: their servos are
    controllers), and a final state of it is continued as saved."""
    for fixed in ("", "x-,y-,z-"):
        p = small_params(max_steps=300, fixed_walls=fixed)
        sample, grid = box.prepare_woven_element(p, 5e3, log=quiet)
        blob = bytes(_core._checkpoint_save(sample.scene))
        skel, _ = box.prepare_woven_element(p, 5e3, log=quiet, build_only=True)
        assert skel.scene.step_count == 0
        _core._checkpoint_load(skel.scene, blob)
        assert bytes(_core._checkpoint_save(skel.scene)) == blob
        # The element's final state, walls servoing at 5 kPa; continued by label.
        for a in range(3):
            sample.controller.set_stress(a, 5e3)
        sample.controller.enabled = True
        run = tmp_path / f"run{len(fixed)}"
        run.mkdir()
        box.save_final_state(run / "el_final.h5", sample, p, [5e3] * 3, prestressed=False,
                             label="el")
        held = box.held_stresses(sample)
        res = cr.continue_element(run, "el", 0, log=quiet)
        np.testing.assert_array_equal(res["stress_pa"], held)
        sample.scene.run(300)
        res = cr.continue_element(run, "el", 300, log=quiet)
        np.testing.assert_array_equal(res["stress_pa"], box.held_stresses(sample))


def test_prs_grips_are_rebuilt_as_the_variant_leaves_them():
    """load_variant(build_only=True): PRS's Prestress over the grid's end junctions, locked
    for grid_ends 'grips', released for 'lock'; no step."""
    p = small_params(max_steps=300)
    sample, grid = box.prepare_woven_element(p, 5e3, log=quiet, build_only=True)
    sc = sample.scene
    for ends, locked in (("grips", True), ("lock", False)):
        ps = box.load_variant(sample, grid, replace(p, grid_ends=ends), True, log=quiet,
                              build_only=True)
        assert ps.locked is locked and sc.step_count == 0
        blocked = np.asarray(sc._blocked)[np.concatenate([ps.held, ps.pulled])]
        assert np.all(blocked != 0) if locked else np.all(blocked == 0)
    assert box.load_variant(sample, grid, replace(p, grid_ends="tension"), True, log=quiet,
                            build_only=True) is None
