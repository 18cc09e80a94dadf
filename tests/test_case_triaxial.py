"""cases/triaxial.py --smoke: isotropic stage within 1 % with unbalanced force < 0.01, lateral
stress held within 1 % during axial loading, every output written, same results with 1 and
2 threads (bitwise), bad inputs answered clearly."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cpp_dem.io import read_csv_series, read_h5_series

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "triaxial.py"


def run_case(out, *args):
    return subprocess.run([sys.executable, str(CASE), "--out", str(out), *args],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)


@pytest.fixture(scope="module")
def smoke(case_smoke):
    return case_smoke("triaxial")  # --smoke --threads 2 (conftest.SMOKE_ARGS)


def test_smoke_runs_and_meets_the_stated_bounds(smoke):
    out, proc = smoke
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in ("triaxial.h5", "triaxial.csv", "triaxial.png", "isotropic.h5",
                 "packing_isotropic.csv", "summary.json", "vtk/spheres_final.vtp"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    s = json.loads((out / "summary.json").read_text())
    assert np.all(np.abs(np.array(s["isotropic_axis_stresses_Pa"]) / 75e3 - 1) <= 0.01)
    assert s["isotropic_unbalanced"] < 0.01
    assert s["lateral_stress_max_rel_error"] <= 0.01
    assert s["axial_axis"] == "z" and s["q_peak_Pa"] > 0
    csv = read_csv_series(out / "triaxial.csv")
    for col in ("axial_strain", "volumetric_strain", "deviatoric_stress"):
        assert col in csv
    h5 = read_h5_series(out / "triaxial.h5")
    assert np.array_equal(h5["deviatoric_stress"], csv["deviatoric_stress"])
    assert csv["axial_strain"][-1] >= 0.04


def test_thread_count_independence(tmp_path):
    a = run_case(tmp_path / "t1", "--n", "1500", "--stop-strain", "0.005", "--strain-rate",
                 "0.5", "--threads", "1")
    b = run_case(tmp_path / "t2", "--n", "1500", "--stop-strain", "0.005", "--strain-rate",
                 "0.5", "--threads", "2")
    assert a.returncode == 0 and b.returncode == 0, a.stderr[-2000:] + b.stderr[-2000:]
    assert (tmp_path / "t1/triaxial.csv").read_bytes() == (tmp_path / "t2/triaxial.csv").read_bytes()
    assert ((tmp_path / "t1/packing_isotropic.csv").read_bytes()
            == (tmp_path / "t2/packing_isotropic.csv").read_bytes())


@pytest.mark.parametrize("args,msg", [
    (["--cell-pressure", "-75000"], "--cell-pressure=-75000.0: must be > 0"),
    (["--stop-strain", "0.7"], "--stop-strain=0.7: must be in (0, 0.5)"),
    (["--damping", "1.5"], "--damping=1.5: must be in [0, 1)"),
    (["--packing", "/nonexistent.csv"], "--packing=/nonexistent.csv: no such file"),
    (["--grain-scale", "0"], "--grain-scale=0.0: must be > 0"),
    (["--dt-safety", "1.2"], "--dt-safety=1.2: must be in (0, 1]"),
    (["--membrane-side", "2"], "--membrane-side=2.0: has no effect with --specimen box"),
    (["--specimen", "cylinder", "--membrane-side", "2.5"],
     "--membrane-side=2.5: must be in [0.75, 2]"),
])
def test_bad_inputs(tmp_path, args, msg):
    p = run_case(tmp_path, "--smoke", *args)
    assert p.returncode != 0 and msg in p.stderr, p.stderr


def test_help_names_the_axial_axis():
    p = subprocess.run([sys.executable, str(CASE), "--help"], capture_output=True, text=True)
    assert "AXIAL axis is z" in " ".join(p.stdout.split())  # (the help wraps its lines)


def test_dense_sample_dilates_loose_sample_contracts(tmp_path):
    """App. B PSD, E = 4.5 MPa, 75 kPa, 1500 grains, to 25 % axial strain: the dense sample
    (expanded without friction, porosity ~0.31) contracts, peaks and then dilates past its
    initial volume; the loose one (expanded at 32 deg, porosity ~0.37) only contracts.

    Three samples (seeds) of each: past its peak contraction a 1500-grain loose sample at
    critical state swings by up to ~0.7 % of volume from one sample to the next (8 seeds:
    0 to 0.0068), so the bound on its dilation holds for the mean of the three; every dense
    sample must dilate past its start and every loose one stay contracted."""
    import csv
    import subprocess
    import sys

    from conftest import ROOT

    swing = {"dense": [], "loose": []}
    for seed in ("1", "2", "3"):
        for name, prep in (("dense", "0"), ("loose", "32")):
            d = tmp_path / f"{name}{seed}"
            subprocess.run([sys.executable, str(ROOT / "cases" / "triaxial.py"), "--n", "1500",
                            "--prep-friction", prep, "--strain-rate", "0.5", "--stop-strain",
                            "0.25", "--seed", seed, "--out", str(d)], check=True,
                           capture_output=True, text=True)
            rows = list(csv.DictReader(open(d / "triaxial.csv")))
            ev = [float(r["volumetric_strain"]) for r in rows]
            swing[name].append(max(ev) - ev[-1])
            if name == "dense":
                assert ev[-1] < 0, f"seed {seed}: dense ends at {ev[-1]}"  # past its start
            else:
                assert ev[-1] > 0.02, f"seed {seed}: loose ends at {ev[-1]}"  # contracted
    assert min(swing["dense"]) > 0.02  # every dense sample dilates after its peak
    assert sum(swing["loose"]) / 3 < 0.005  # the loose ones do not (mean of three)


def test_grain_scale_coarsens_the_same_box(tmp_path):
    """--grain-scale 1.26 fills the same box with grains 1.26 x larger: about half as many
    (n / 1.26^3 = 0.5 n), and the summary's inertial number is rate x d_mean x sqrt(rho/p)."""
    base = run_case(tmp_path / "a", "--smoke", "--threads", "1", "--stop-strain", "0.005")
    big = run_case(tmp_path / "b", "--smoke", "--threads", "1", "--stop-strain", "0.005",
                   "--grain-scale", "1.26")
    assert base.returncode == 0 and big.returncode == 0, base.stderr[-2000:] + big.stderr[-2000:]
    sa = json.loads((tmp_path / "a/summary.json").read_text())
    sb = json.loads((tmp_path / "b/summary.json").read_text())
    assert 0.4 <= sb["num_grains"] / sa["num_grains"] <= 0.6
    for d, s in (("a", sa), ("b", sb)):
        r = np.loadtxt(tmp_path / d / "packing_isotropic.csv", delimiter=",", skiprows=1)[:, 3]
        expect = 0.5 * 2 * r.mean() * np.sqrt(2650.0 / 75e3)  # smoke rate 0.5 /s
        assert s["inertial_number"] == pytest.approx(expect, rel=1e-9)
    assert sb["inertial_number"] > 1.2 * sa["inertial_number"]


def test_preset_sets_the_loading(tmp_path):
    """--preset accurate: the loading runs at the preset's inertial number (8e-4) with its
    local damping (0.05)."""
    from cpp_dem.presets import preset

    p = run_case(tmp_path, "--smoke", "--threads", "1", "--stop-strain", "0.005",
                 "--preset", "accurate")
    assert p.returncode == 0, p.stderr[-2000:]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["inertial_number"] == pytest.approx(preset("accurate").inertial_number, rel=1e-9)
    assert "local damping 0.05" in p.stdout


def test_a_state_is_continued_as_it_is_with_skip_isotropic(smoke, tmp_path):
    """Issue 19: a packing with given wall planes (here our own isotropic state: its CSV and
    the wall planes of its checkpoint) continues without a new isotropic stage; the given state
    is the saved one (same porosity, same wall stresses) and the loading gives a peak within
    the scatter that the lost shear-spring history causes."""
    import h5py

    out, proc = smoke
    assert proc.returncode == 0, proc.stderr
    w = h5py.File(out / "isotropic.h5", "r")["readable/wall_positions"][()]
    box = ",".join(repr(float(v)) for v in (w[0], w[2], w[4], w[1], w[3], w[5]))
    # "--box=...": a first wall plane below 0 (it is, for some seeds or machines) would be taken
    # by argparse for an option after a separate "--box".
    r = run_case(tmp_path / "cont", "--smoke", "--threads", "2", "--packing",
                 str(out / "packing_isotropic.csv"), f"--box={box}", "--skip-isotropic")
    assert r.returncode == 0, r.stderr
    assert "isotropic stage skipped" in r.stdout
    first = json.loads((out / "summary.json").read_text())
    cont = json.loads((tmp_path / "cont" / "summary.json").read_text())
    # The very grains and walls (the CSV keeps every digit): the same porosity, bitwise, and the
    # same wall stresses but for the shear springs the CSV does not keep (over seeds 1-25 of
    # this smoke: at most 2.6e-4 apart).
    assert cont["porosity_isotropic"] == first["porosity_isotropic"]
    np.testing.assert_allclose(cont["isotropic_axis_stresses_Pa"],
                               first["isotropic_axis_stresses_Pa"], rtol=1e-3)
    # The peak is a chaotic result of 300 grains: over seeds 1-25 of this smoke the continued
    # run's q_peak differed from the first run's by -9.2 % to +14.4 % (mean +2.1 %, standard
    # deviation 5.0 %; q_peak itself varies by 11.8 % from seed to seed). 20 % is about the
    # mean + 3.5 standard deviations. (A 2 % bound passed at seed 1 here, +1.4 %, and failed on
    # another machine, +2.6 %.)
    assert cont["q_peak_Pa"] == pytest.approx(first["q_peak_Pa"], rel=0.2)
    bad = run_case(tmp_path / "bad", "--smoke", f"--box={box}")
    assert bad.returncode != 0 and "--box: goes with --packing" in bad.stderr


def test_clump_grains_run_through_every_stage(tmp_path):
    # --grains clumps:gravel_a: the App. B PSD as equivalent diameters of a shipped angular
    # grain; the expansion grows the clumps about their centres, the isotropic stage converges,
    # porosity counts each clump's union volume once.
    out = tmp_path / "c"
    proc = run_case(out, "--smoke", "--grains", "clumps:gravel_a", "--threads", "2")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["num_clumps"] == s["num_grains"] >= 250
    assert s["num_spheres"] == 24 * s["num_clumps"]
    assert np.all(np.abs(np.array(s["isotropic_axis_stresses_Pa"]) / 75e3 - 1) <= 0.01)
    assert 0.25 < s["porosity_isotropic"] < 0.6
    assert s["q_peak_Pa"] > 0 and s["lateral_stress_max_rel_error"] <= 0.01
    cl = np.loadtxt(out / "clumps_isotropic.csv", delimiter=",", skiprows=1)
    assert cl.shape == (s["num_clumps"], 9)
    assert np.allclose(np.linalg.norm(cl[:, 4:8], axis=1), 1, atol=1e-9)
    bad = run_case(tmp_path / "b", "--smoke", "--grains", "clumps:nosuchgrain")
    assert bad.returncode != 0 and "nosuchgrain" in bad.stderr + bad.stdout
    bad = run_case(tmp_path / "b2", "--smoke", "--grains", "cubes")
    assert bad.returncode != 0 and "--grains=cubes" in bad.stderr
