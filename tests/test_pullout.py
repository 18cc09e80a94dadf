"""Pull-out machinery (cpp_dem.protocols.pullout) and the two pull-out cases as smoke tests."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.build import geogrid
from cpp_dem.protocols import prep
from cpp_dem.protocols import pullout
from cpp_dem.io import read_csv_series, read_h5_series, read_h5_snapshot

ROOT = Path(__file__).resolve().parents[1]


def _bar_sample(*, n_links=8, length=0.8, young=1e8, rc=1e-3, v_damp=0.5):
    """A straight chain along x at z = 0.1 in a 1 x 0.2 x 0.2 m box, two grains far away in a
    corner; the back node fixed, the front node is the clamp."""
    lo, hi = np.zeros(3), np.array([1.0, 0.2, 0.2])
    centers = np.array([[0.95, 0.15, 0.02], [0.95, 0.15, 0.06]])
    radii = np.array([0.015, 0.015])
    grain = dem.linear_material(density=2600, young=1e7, poisson=0.3, friction_angle_deg=30)
    xs = np.linspace(0.1, 0.1 + length, n_links + 1)
    pts = np.column_stack([xs, np.full_like(xs, 0.1), np.full_like(xs, 0.1)])
    beam = dem.BeamParams(young=young, poisson=0.3, radius=rc, normal_cohesion=0.0,
                          shear_cohesion=0.0)

    def gb(sc):
        gm = sc.add_material(dem.linear_material(density=1000, young=young, poisson=0.3,
                                                  friction_angle_deg=20))
        return geogrid.polyline(sc, pts, params=beam, material=gm, density=1000)

    s = pullout.build_sample(centers, radii, lo, hi, grain=grain, grid_builder=gb, grid_z=0.1,
                             clamp_depth=0.0, local_damping=v_damp)
    s.scene.block_dofs(s.grid.nodes[-1], "all")  # the far end is anchored
    return s, young * math.pi * rc**2 / length


def test_set_radii_keeps_grid_node_masses_and_refuses_new_node_radius():
    sc = dem.Scene()
    m = sc.add_material(dem.linear_material(density=1000, young=1e7, poisson=0.3,
                                            friction_angle_deg=30))
    sc.add_spheres([[0, 0, 0]], [0.01], material=m)
    beam = dem.BeamParams(young=1e8, poisson=0.3, radius=1e-3, normal_cohesion=0.0,
                          shear_cohesion=0.0)
    g = geogrid.polyline(sc, [[0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0]], params=beam,
                         material=m, density=1000)
    before = np.asarray(sc.masses)[g.nodes].copy()
    r = np.asarray(sc.radii).copy()
    r[0] *= 1.1  # grow the sphere only, as RadiusGrowth does
    sc.radii = r
    np.testing.assert_array_equal(np.asarray(sc.masses)[g.nodes], before)
    assert sc.masses[0] == pytest.approx(1000 * 4 / 3 * math.pi * 0.011**3, rel=1e-12)
    r[g.nodes[0]] = 2e-3
    with pytest.raises(dem.ParameterError, match="grid node"):
        sc.radii = r


def test_layered_cloud_keeps_the_grid_layer_clear_and_splits_volume():
    rng = np.random.default_rng(3)
    radii = rng.uniform(0.004, 0.008, 400)
    c, r = pullout.layered_cloud(radii, (0, 0, 0), (0.3, 0.2, 0.3), grid_z=0.12,
                                 clearance=0.002, seed=2)
    assert len(r) == 400
    np.testing.assert_allclose(np.sort(r), np.sort(radii))
    below = c[:, 2] < 0.12
    assert np.all(c[below, 2] + r[below] <= 0.118 + 1e-12)
    assert np.all(c[~below, 2] - r[~below] >= 0.122 - 1e-12)
    # Volumes follow the layer heights (0.118 vs 0.178) within one largest grain.
    v_lo, v_hi = np.sum(r[below] ** 3), np.sum(r[~below] ** 3)
    assert v_lo / (v_lo + v_hi) == pytest.approx(0.118 / 0.296, abs=0.008**3 / v_lo + 1e-3)
    with pytest.raises(dem.ParameterError, match="grid_z"):
        pullout.layered_cloud(radii, (0, 0, 0), (0.3, 0.2, 0.3), grid_z=0.299, clearance=0.002)


def test_clamp_reaction_equals_bar_force_EA_dL_over_L():
    """A bar anchored at its far end, pulled slowly at its front: the recorded pull-out force
    (clamp reaction) and every member's axial force equal EA dL / L (1 %)."""
    s, k = _bar_sample()
    d = 2e-4
    rec = pullout.pull(s, velocity=2e-3, distance=d, record_every=20)
    f_expected = k * rec["displacement"][-1]
    assert rec["pull_force"][-1] == pytest.approx(f_expected, rel=0.01)
    f_members = s.grid.member_axial_forces(s.scene)
    np.testing.assert_allclose(f_members, f_expected, rtol=0.01)
    # The front column is the clamp here: both measures agree.
    assert rec["front_force"][-1] == pytest.approx(rec["pull_force"][-1], rel=1e-12)
    # The imposed displacement is what the record says.
    assert rec["displacement"][-1] == pytest.approx(2e-3 * (rec["time"][-1] - rec["time"][0]),
                                                    rel=1e-9)
    assert np.all(np.isnan(rec["force_A1"]))  # a chain has no apertures


def test_node_density_scale_keeps_the_true_weight():
    s, _ = _bar_sample()
    sc = s.scene
    sc.gravity = (0, 0, -9.81)
    true = np.asarray(sc.masses)[s.grid.nodes].copy()
    pullout.set_node_density_scale(s, 1e3)
    m = np.asarray(sc.masses)[s.grid.nodes]
    np.testing.assert_allclose(m, 1e3 * true, rtol=1e-12)
    # gravity on the scaled mass plus the external force = the true weight
    w = m * -9.81 + np.asarray(sc.external_forces)[s.grid.nodes, 2]
    np.testing.assert_allclose(w, true * -9.81, rtol=1e-12)
    pullout.set_node_density_scale(s, 1.0)
    np.testing.assert_allclose(np.asarray(sc.masses)[s.grid.nodes], true, rtol=1e-12)
    with pytest.raises(dem.ParameterError, match="node_density_scale"):
        pullout.set_node_density_scale(s, 0.0)


def test_pull_rejects_bad_input():
    s, _ = _bar_sample()
    with pytest.raises(dem.ParameterError, match="velocity=-1"):
        pullout.pull(s, velocity=-1, distance=0.01)
    with pytest.raises(dem.ParameterError, match="distance=0"):
        pullout.pull(s, velocity=0.01, distance=0)
    with pytest.raises(dem.ParameterError, match="clamp='middle'"):
        pullout.build_sample(np.zeros((1, 3)) + 0.5, np.array([0.01]), (0, 0, 0), (1, 1, 1),
                             grain=dem.linear_material(density=1, young=1, poisson=0.3,
                                                       friction_angle_deg=0),
                             grid_builder=lambda sc: None, grid_z=0.5, clamp="middle")


def test_first_peak_and_summary_statistics():
    d = np.linspace(0, 0.1, 201)
    f = np.where(d < 0.02, 100 * d / 0.02, 100 - 1500 * (d - 0.02))
    f = np.maximum(f, 40) + 10 * np.sin(200 * d) * (d > 0.05)
    dp, fp = pullout.first_peak(d, f)
    assert dp == pytest.approx(0.02, abs=0.002)
    assert fp == pytest.approx(100, rel=0.05)
    assert pullout.peak_found(d, f)
    rec = {"displacement": d, "pull_force": f,
           "force_A1": np.full_like(d, 10.0), "force_A2": np.full_like(d, 30.0),
           "force_C1": np.where(np.arange(len(d)) == 50, 12.0, 2.0),
           "force_C2": np.full_like(d, -2.0)}
    s = pullout.summarize(rec)
    assert s["mean_force_N"] == pytest.approx(np.mean(f[1:]))
    assert s["cov_force"] == pytest.approx(np.std(f[1:]) / np.mean(f[1:]))
    c1_mean = (200 * 2.0 + 12.0 - 2.0) / 200  # rows with d > 0: the first row (d = 0) is out
    assert s["transverse_over_longitudinal"] == pytest.approx((c1_mean + 2.0) / 2 / 20.0)
    assert s["transverse_peak_over_mean"] == pytest.approx(12.0 / c1_mean)
    assert pullout.inertial_number(0.01, 2500.0, 25e3) == pytest.approx(0.01 * 0.31622776601)


def test_first_peak_of_a_rising_curve_is_its_end():
    """A curve that rises to the end of the record has no initial peak before the end: the
    smoothing must not sag at the last records (a zero-padded moving average fell by 40 %
    there and reported a false peak 1.5 records before the end)."""
    d = np.linspace(0, 0.05, 101)
    f = 1000 * d / 0.05 + 50
    dp, fp = pullout.first_peak(d, f)
    assert dp == pytest.approx(d[-1])
    assert fp == pytest.approx(np.mean(f[-3:]), rel=1e-12)
    assert not pullout.peak_found(d, f)
    assert not pullout.summarize({"displacement": d, "pull_force": f})["initial_peak_found"]


def _run_case(script, out, *extra):
    r = subprocess.run([sys.executable, str(ROOT / "cases" / script), "--smoke", "--out",
                        str(out), *extra], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r


@pytest.fixture(scope="module")
def smoke000(case_smoke):
    out, r = case_smoke("pullout_000")  # --smoke --threads 2 (conftest.SMOKE_ARGS)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return out, r


def test_case_000_smoke_outputs_and_physics(smoke000):
    out, r = smoke000
    assert "initial peak" in r.stdout and "wall time" in r.stdout  # progress and summary
    for f in ("pullout.h5", "pullout.csv", "pullout_force.png", "pullout_members.png",
              "summary.json", "vtk/geogrid.pvd", "vtk/spheres.pvd", "vtk/contacts.pvd",
              "vtk/geogrid_prepared.vtp"):
        assert (out / f).is_file(), f
    rec = read_h5_series(out / "pullout.h5")
    csvrec = read_csv_series(out / "pullout.csv")
    np.testing.assert_allclose(rec["pull_force"], csvrec["pull_force"], rtol=1e-9)
    s = json.loads((out / "summary.json").read_text())
    # The servo top wall holds the confining stress during the pull (2 %).
    assert s["top_stress_max_rel_dev"] < 0.02
    # The soil resists: the force grows over the first millimetres and is positive.
    d, f = rec["displacement"], rec["pull_force"]
    assert d[-1] >= 0.01 - 1e-9
    assert f[-1] > 0 and np.mean(f[len(f) // 2:]) > np.mean(f[: len(f) // 4])
    # The longitudinal member next to the clamp carries more than the one behind it (000).
    assert np.mean(rec["force_A1"][1:]) > np.mean(rec["force_A2"][1:]) > 0
    snap = read_h5_snapshot(out / "pullout.h5", -1)
    assert snap["member_axial_force"].shape == (s["grid_members"],)
    assert s["porosity_prepared"] < 0.36  # REFD reached the target porosity (0.35)


def test_case_000_same_result_on_1_and_2_threads(smoke000, tmp_path):
    out2, _ = smoke000
    _run_case("pullout_000.py", tmp_path, "--threads", "1", "--snapshots", "0")
    a = read_csv_series(out2 / "pullout.csv")
    b = read_csv_series(tmp_path / "pullout.csv")
    for k in ("pull_force", "force_A1", "force_C2", "top_stress"):
        np.testing.assert_array_equal(a[k], b[k])


def test_case_001_smoke(case_smoke):
    out, r = case_smoke("pullout_001")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    rec = read_csv_series(out / "pullout.csv")
    assert s["top_stress_max_rel_dev"] < 0.05
    assert s["mean_force_N"] > 0
    # Rigid pull (App. A): every node is clamped and moves at the pull velocity, so the grid's
    # kinetic energy is the same (1/2 M v^2) in every record after the first.
    assert s["grid_nodes"] == 25
    ke = rec["grid_kinetic_energy"][1:]
    assert ke[0] > 0
    np.testing.assert_allclose(ke, ke[0], rtol=1e-9)
    assert "pulling at 0.06 m/s" in r.stdout


def _clump_outputs_agree(out: Path, members: int) -> dict:
    """Checks common to the clump runs of both pull-out cases; returns the summary."""
    s = json.loads((out / "summary.json").read_text())
    assert s["num_clumps"] == s["num_grains"] > 0
    assert s["num_spheres"] == members * s["num_clumps"]
    cl = np.loadtxt(out / "clumps_prepared.csv", delimiter=",", skiprows=1)
    assert cl.shape == (s["num_clumps"], 9)
    assert np.allclose(np.linalg.norm(cl[:, 4:8], axis=1), 1, atol=1e-9)
    pk = np.loadtxt(out / "packing_prepared.csv", delimiter=",", skiprows=1)
    assert len(pk) == s["num_spheres"]  # members only, never the geogrid's nodes
    assert b'Name="clump_id"' in (out / "vtk" / "spheres_prepared.vtp").read_bytes()
    # No member sank through another grain, a wall or the geogrid (the blow-up limit would
    # have stopped the run; the summary says how close it came).
    for when in ("largest_overlap_prepared", "largest_overlap_final"):
        assert max(s[when].values()) < s["max_overlap_ratio_limit"]
    return s


def test_case_001_clump_grains_resist_more_than_spheres(case_smoke, tmp_path):
    # --grains clumps:gravel_a: as many angular 24-sphere clumps as 001's lattice has spheres,
    # grown to 10 kPa, confined at 75 kPa, the grid pulled as a rigid body. Interlocking
    # angular grains hold the grid harder than the lattice of spheres (measured: mean force
    # 24.7 N against 5.6 N over the 4 mm smoke pull; asserted: more than twice).
    out = tmp_path / "c"
    r = _run_case("pullout_001.py", out, "--grains", "clumps:gravel_a")
    assert "440 clumps of 24 spheres" in r.stdout
    s = _clump_outputs_agree(out, 24)
    sph_out, sph = case_smoke("pullout_001")
    assert sph.returncode == 0
    ref = json.loads((sph_out / "summary.json").read_text())
    assert s["num_clumps"] == ref["num_grains"]  # one clump per lattice site
    assert s["top_stress_max_rel_dev"] < 0.05
    assert s["mean_force_N"] > 2.0 * ref["mean_force_N"] > 0


def test_case_000_clump_grains_from_a_template_csv_in_a_run_file(tmp_path):
    # A user's template CSV (with a header line), three overlapping members, named by the
    # run file's grains field (geogrid-dem run); REFD grows the clumps about their centres to
    # 000's porosity, then the pull.
    tpl = tmp_path / "tri.csv"
    tpl.write_text("x,y,z,r\n-0.5,0,0,0.6\n0.3,0.2,0,0.5\n0.2,-0.3,0.3,0.45\n")
    run_file = tmp_path / "po.toml"
    run_file.write_text(f'case = "pullout-000"\n[params]\ngrains = "clumps:{tpl}"\n'
                        'spheres = 200\nsnapshots = 1\nthreads = 2\n')
    out = tmp_path / "c"
    r = subprocess.run([sys.executable, "-m", "geogrid_dem.cli", "run", str(run_file), "--smoke",
                        "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "200 clumps of 3 spheres (600 spheres)" in r.stdout
    assert f'grains = "clumps:{tpl}"' in (out / "run.toml").read_text()
    s = _clump_outputs_agree(out, 3)
    assert s["grains"] == f"clumps:{tpl}"
    assert s["porosity_prepared"] < 0.36 and s["top_stress_max_rel_dev"] < 0.02
    rec = read_csv_series(out / "pullout.csv")
    assert rec["displacement"][-1] >= 0.01 - 1e-9 and rec["pull_force"][-1] > 0


@pytest.mark.parametrize("script", ["pullout_000.py", "pullout_001.py"])
@pytest.mark.parametrize("grains,match", [
    ("clumps:nosuchgrain", "grains='clumps:nosuchgrain'"),
    ("cubes", "--grains=cubes: must be 'spheres' or 'clumps:NAME'"),
    ("clumps:", "--grains=clumps:: must be"),
])
def test_case_pullout_bad_grains_are_named(script, grains, match, tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "cases" / script), "--smoke", "--out",
                        str(tmp_path), "--grains", grains], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2
    assert match in r.stderr
    assert not (tmp_path / "summary.json").exists()


@pytest.mark.parametrize("args,match", [
    (["--pressure", "-5"], "--pressure=-5.0: must be > 0"),
    (["--porosity", "1.2"], "--porosity=1.2: must be in"),
    (["--node-density-scale", "fast"], "--node-density-scale='fast'"),
])
def test_case_000_bad_input_is_named(args, match, tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "cases" / "pullout_000.py"), "--smoke",
                        "--out", str(tmp_path), *args], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode != 0
    assert match in r.stderr


def test_overlap_limit_rule():
    assert prep.overlap_limit(25e3, 1e6) == pytest.approx(0.95)
    assert prep.overlap_limit(1e3, 1e9) == pytest.approx(0.5)
    assert prep.overlap_limit(1e4, 1e6) == pytest.approx(0.6)


def test_presets_are_named_and_applied():
    from cpp_dem import presets

    with pytest.raises(dem.ParameterError, match="preset='quick': unknown"):
        presets.preset("quick")
    b = presets.preset("balanced")
    assert b.velocity(density=2600.0, stress=26e3) == pytest.approx(3.2e-3 * math.sqrt(10.0))
    s, _ = _bar_sample()
    pullout.apply_preset(s, "accurate")
    assert s.scene.local_damping == 0.05
    assert s.node_density_scale == 3e3
    assert s.scene.timestep_safety == 0.35
    assert s.scene.dt == pytest.approx(0.35 * s.scene.critical_dt(), rel=1e-12)
