"""bench/shear_band.py (issue 38): its measures on synthetic fields (they can fail), and the
bench itself at a tiny size (the documented command's code path)."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    sys.path.insert(0, str(ROOT / "bench"))
    spec = importlib.util.spec_from_file_location("shear_band", ROOT / "bench" / "shear_band.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_equivalent_shear_strain_of_simple_shear_and_of_isotropic_strain():
    sb = _bench()
    g = 1e-2
    shear = np.array([[[0.0, g], [0.0, 0.0]]])  # simple shear: e_xy = g/2
    assert sb.equivalent_shear_strain(shear)[0] == pytest.approx(g / math.sqrt(3), rel=1e-12)
    # plane-strain isotropic in-plane strain still has a deviator (e_zz = 0): 2/3 sqrt(...)
    iso = np.array([np.eye(2) * 1e-3])
    assert sb.equivalent_shear_strain(iso)[0] == pytest.approx(2e-3 / 3, rel=1e-12)


@pytest.mark.parametrize("angle", [30.0, 55.0, 120.0])
def test_band_direction_finds_a_synthetic_band_and_not_a_round_spot(angle):
    sb = _bench()
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 1, (2000, 2))
    t = math.radians(angle)
    d = np.abs(-(pts[:, 0] - 0.5) * math.sin(t) + (pts[:, 1] - 0.5) * math.cos(t))
    eq = 0.01 + 0.1 * np.exp(-(d / 0.03) ** 2)  # a band through the centre
    b = sb.band_direction(pts, eq)
    expect = angle if angle <= 90 else 180 - angle
    assert b["angle_deg"] == pytest.approx(expect, abs=2.0)
    assert b["leans"] == ("right" if angle <= 90 else "left")
    assert b["elongation"] > 5
    spot = 0.01 + 0.1 * np.exp(-(np.linalg.norm(pts - 0.5, axis=1) / 0.1) ** 2)
    assert sb.band_direction(pts, spot)["elongation"] < 1.5  # round: no band


@pytest.mark.parametrize("angle, width", [(30.0, 8e-3), (55.0, 5e-3), (120.0, 12e-3)])
def test_band_profile_fits_a_noisy_band_s_angle_and_width(angle, width):
    sb = _bench()
    rng = np.random.default_rng(5)
    pts = rng.uniform(0, 1, (300, 2)) * [0.05, 0.10]
    t = math.radians(angle)
    s = -(pts[:, 0] - 0.02) * math.sin(t) + (pts[:, 1] - 0.05) * math.cos(t)
    sigma = width / (2 * math.sqrt(2 * math.log(2)))
    eq = 0.01 + 0.05 * np.exp(-0.5 * (s / sigma) ** 2) + rng.normal(0, 0.003, len(s))
    f = sb.band_profile(pts, eq, sb.band_direction(pts, eq))
    expect = angle if angle <= 90 else 180 - angle
    assert abs(f["angle_deg"] - expect) < 3 * f["angle_se_deg"] + 0.2
    assert f["angle_se_deg"] < 1.0
    assert f["width_m"] == pytest.approx(width, rel=0.1)
    assert abs(f["width_m"] - width) < 4 * f["width_se_m"] + 2e-4
    assert f["leans"] == ("right" if angle <= 90 else "left")
    err = sb.band_error(pts, eq, f)
    assert err >= 1.96 * f["angle_se_deg"] and err < 3.0
    # a wider band is measured wider (the measure can fail)
    wide = 0.01 + 0.05 * np.exp(-0.5 * (s / (2 * sigma)) ** 2)
    assert sb.band_profile(pts, wide, sb.band_direction(pts, wide))["width_m"] == \
        pytest.approx(2 * width, rel=0.1)


def test_the_mesh_study_says_whether_the_angle_moves_beyond_its_error():
    sb = _bench()

    def row(mesh, angle, err, width, cell, seed=1):
        return {"mesh": mesh, "elements": 1, "cell_m": cell, "seed": seed, "band_fit": {
            "angle_deg": angle, "width_m": width, "width_se_m": 1e-4},
            "angle_error_deg": err, "localization_index": 5.0, "axial_strain_reached": 0.03}

    rows = [row("a", 54.0, 1.0, 10e-3, 12.5e-3), row("b", 50.0, 1.0, 8e-3, 10e-3),
            row("c", 49.0, 1.0, 8e-3, 8e-3)]
    st = sb.mesh_study(rows)
    assert [p["angle_moves"] for p in st["pairs"]] == [True, False]
    assert st["pairs"][0]["angle_move_deg"] == pytest.approx(-4.0)
    assert st["pairs"][0]["angle_error_deg"] == pytest.approx(math.sqrt(2))
    assert st["pairs"][0]["width_ratio"] == pytest.approx(0.8)
    assert st["pairs"][1]["cell_ratio"] == pytest.approx(0.8)
    assert st["seed_sd_deg"] is None and st["seed_dof"] == 0
    # a second seed of mesh b 2 deg off: the seeds' scatter enters every error, and the
    # 4 deg move is no longer beyond it
    st = sb.mesh_study(rows[:2] + [row("b", 52.0, 1.0, 8e-3, 10e-3, seed=1001)] + rows[2:])
    sd = math.sqrt(2.0)  # (50 and 52 about 51: sd sqrt(2), one degree of freedom)
    t1 = 12.7062  # Student's t, 0.975, one degree of freedom
    assert st["seed_sd_deg"] == pytest.approx(sd) and st["seed_dof"] == 1
    assert st["seed_t975"] == pytest.approx(t1, rel=1e-5)
    b = st["meshes"][1]
    assert (b["runs"], b["seeds"], b["angle_deg"]) == (2, [1, 1001], pytest.approx(51.0))
    assert b["angles_deg"] == [50.0, 52.0] and b["widths_m"] == [8e-3, 8e-3]
    assert b["angle_fit_errors_deg"] == [1.0, 1.0]
    assert b["angle_error_deg"] == pytest.approx(math.hypot(1.0, t1 * sd) / math.sqrt(2),
                                                 rel=1e-5)
    a = st["meshes"][0]
    assert a["angle_error_deg"] == pytest.approx(math.hypot(1.0, t1 * sd), rel=1e-5)
    assert st["pairs"][0]["angle_move_deg"] == pytest.approx(-3.0)
    assert st["pairs"][0]["angle_moves"] is False


def test_a_pooled_study_gives_its_own_numbers_and_takes_new_seeds(tmp_path):
    """--pool: the runs of an earlier study (their files gone) as rows again. The study made
    from them is the earlier one; a new seed joins its mesh and the seeds' scatter; a run
    counted twice, a local run among nonlocal ones, a study of the other field or one that
    kept no run's own angle are refused by name."""
    sb = _bench()

    def row(mesh, angle, err, width, cell, seed=1, length=0.006):
        return {"mesh": mesh, "elements": 1, "cell_m": cell, "seed": seed,
                "nonlocal_length_m": length, "band_fit": {
                    "angle_deg": angle, "width_m": width, "width_se_m": 2e-4},
                "angle_error_deg": err, "localization_index": 5.0,
                "axial_strain_reached": 0.03}

    rows = [row("a", 54.0, 1.0, 10e-3, 12.5e-3), row("a", 51.0, 1.5, 9e-3, 12.5e-3, 1001),
            row("b", 50.0, 1.0, 8e-3, 10e-3)]
    st = sb.mesh_study(rows)
    st["field"] = "displacement"
    f = tmp_path / "mesh_study.json"
    f.write_text(json.dumps(st))
    again = sb.mesh_study(sb.check_poolable(sb.pooled_runs(f)))
    for m, n in zip(st["meshes"], again["meshes"]):
        for k in ("angle_deg", "angle_error_deg", "width_m", "width_se_m", "runs", "seeds"):
            assert n[k] == pytest.approx(m[k], rel=1e-12), k
    assert again["seed_sd_deg"] == pytest.approx(st["seed_sd_deg"])
    # a new seed on mesh b (given first: the study sorts coarse to fine)
    new = sb.mesh_study(sb.check_poolable([row("b", 46.0, 1.0, 8e-3, 10e-3, 2001)]
                                          + sb.pooled_runs(f)))
    assert [m["mesh"] for m in new["meshes"]] == ["a", "b"]
    assert new["meshes"][1]["seeds"] == [1, 2001] and new["seed_dof"] == 2
    assert new["meshes"][1]["angle_deg"] == pytest.approx(48.0)
    with pytest.raises(ValueError, match="mesh b seed 1: twice"):
        sb.check_poolable(sb.pooled_runs(f) + [row("b", 49.0, 1.0, 8e-3, 10e-3)])
    with pytest.raises(ValueError, match="nonlocal lengths"):
        sb.check_poolable(sb.pooled_runs(f) + [row("b", 49.0, 1.0, 8e-3, 10e-3, 7, 0.0)])
    with pytest.raises(ValueError, match="its band is of the field 'displacement'"):
        sb.pooled_runs(f, "elements")
    old = dict(st, meshes=[{k: v for k, v in m.items() if k != "angles_deg"}
                           for m in st["meshes"]])
    f.write_text(json.dumps(old))
    with pytest.raises(ValueError, match="mesh a keeps no run's own angle"):
        sb.pooled_runs(f)
    # the committed nonlocal study of seed 1 (one run a mesh, no seeds' scatter, an older
    # bench's file without the runs' lists) pools as its runs
    seed1 = ROOT / "docs/data/shear_band_nonlocal_seed1.json"
    data = json.loads(seed1.read_text())
    assert all(m["runs"] == 1 and "angles_deg" not in m for m in data["meshes"])
    runs = sb.pooled_runs(seed1)
    assert [r["band_fit"]["angle_deg"] for r in runs] == [m["angle_deg"] for m in data["meshes"]]
    assert [r["seed"] for r in runs] == [1, 1, 1]
    with pytest.raises(SystemExit):
        sb.main(["--pool", str(f), "--out", str(tmp_path / "x")])


def test_rve_angles_of_a_synthetic_curve():
    from geogrid_dem.studies import biaxial

    e1 = np.linspace(0, 0.05, 101)
    s3 = np.full_like(e1, 100e3)
    s1 = 100e3 * (1 + 2.0 * np.minimum(e1 / 0.02, 1.0))  # peak 300 kPa from 2 %
    s1[e1 > 0.02] -= 1e3 * (e1[e1 > 0.02] - 0.02) / 0.03  # then softening
    psi = math.radians(10.0)
    # eps_v = -sin(psi) gamma with gamma = 2 e1 - eps_v: eps_v = -2 sin(psi) e1 / (1 - sin psi)
    ev = -2 * math.sin(psi) * e1 / (1 - math.sin(psi))
    r = biaxial.rve_angles({"sigma_axial": s1, "sigma_lateral": s3, "axial_strain": e1,
                            "volumetric_strain": ev})
    assert r["phi_peak_deg"] == pytest.approx(math.degrees(math.asin(0.5)), abs=1e-9)
    assert r["psi_deg"] == pytest.approx(10.0, abs=1e-6)


def test_the_bench_runs_at_a_tiny_size(tmp_path, capsys):
    pytest.importorskip("dolfinx_solver")
    sb = _bench()
    assert sb.main(["--nx", "1", "--ny", "2", "--degree", "2", "--grains", "40", "--strain",
                    "0.004", "--steps", "2", "--workers", "1", "--rve-seeds", "1",
                    "--weak-radius", "0.3", "--out", str(tmp_path)]) == 0
    row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert row["elements"] == 12 and row["weak_elements"] >= 1
    assert row["localization_index"] >= 1.0 and row["axial_strain_reached"] == 0.004
    assert set(row["statuses"]) <= {"converged", "stopped_at_scatter"}
    sc = row["scale"]
    assert sc["workers"] == 1 and sc["worker_rss_bytes"] > sc["accepted_state_bytes"] > 0
    assert 0 < sc["client_bytes_per_accepted_step"] < sc["accepted_state_bytes"]
    for f in ("strain.xdmf", "shear_band.png", "shear_band.json", "records/fem.xdmf"):
        assert (tmp_path / f).is_file(), f
    assert row["cell_m"] == pytest.approx(0.05) and row["nonlocal_length_m"] == 0.0
    assert "angle_deg" in row["band_fit"] and "angle_error_deg" in row
    with pytest.raises(SystemExit):
        sb.main(["--weak-radius", "1.5", "--out", str(tmp_path / "x")])
    for bad in (["--nonlocal-length", "-1"], ["--nonlocal-weight", "0"]):
        with pytest.raises(SystemExit):
            sb.main(bad + ["--out", str(tmp_path / "x")])


def test_the_bench_runs_nonlocal_and_compares_its_meshes(tmp_path, capsys):
    """The documented nonlocal run and mesh comparison, at a tiny size: the model averages
    the strain (its records say so), and --compare reads the runs' files."""
    pytest.importorskip("dolfinx_solver")
    sb = _bench()
    runs = []
    for nx, ny in ((1, 2), (2, 3)):
        out = tmp_path / f"m{nx}x{ny}"
        assert sb.main(["--nx", str(nx), "--ny", str(ny), "--grains", "40", "--strain",
                        "0.002", "--steps", "1", "--workers", "1", "--rve-seeds", "0",
                        "--weak-radius", "0.3", "--nonlocal-length", "0.02",
                        "--nonlocal-weight", "0.8",
                        "--out", str(out)]) == 0
        row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
        assert row["nonlocal_length_m"] == 0.02 and row["nonlocal_weight"] == 0.8
        assert "nonlocal (NonlocalStrain(length_m=0.02, weight=0.8" in (
            out / "records" / "report.md").read_text()
        runs.append(str(out / "shear_band.json"))
    assert sb.main(["--compare", *runs, "--out", str(tmp_path / "study")]) == 0
    study = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert [m["mesh"] for m in study["meshes"]] == ["1x2", "2x3"]
    assert len(study["pairs"]) == 1 and (tmp_path / "study" / "mesh_study.json").is_file()
    assert study["field"] == "displacement"
    # the band of the strain the elements took: the averaged field, saved with the run and
    # the same as the sum of the increments in its records
    r = json.loads(Path(runs[1]).read_text())
    el = np.asarray(r["eps_q_elements"])
    assert not np.allclose(el, r["eps_q"])
    del r["eps_q_elements"]
    np.testing.assert_allclose(sb.elements_strain(Path(runs[1]), r), el, rtol=1e-9, atol=1e-15)
    assert sb.main(["--compare", *runs, "--field", "elements", "--out",
                    str(tmp_path / "study_el")]) == 0
    study = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert study["field"] == "elements"
    assert study["meshes"][1]["localization_index"] == pytest.approx(el.max() / el.mean())
    with pytest.raises(ValueError, match="none.json: not a readable shear_band.json"):
        sb.main(["--compare", str(tmp_path / "none.json"), "--out", str(tmp_path / "s2")])
