"""cases/prs_element.py: FEM -> DEM smoke run (RE and PRS), DEM-only mode without dolfinx,
and a homogeneous FEM field handed over reproducing the standalone element test."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "prs_element.py"


def run_case(out, *args):
    return subprocess.run([sys.executable, str(CASE), "--out", str(out), *args],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)


def _xdmf_times(path) -> list:
    """The distinct times of an XDMF file's series, in order."""
    import re

    return sorted({float(t) for t in re.findall(r'Time Value="([^"]+)"', path.read_text())})


@pytest.fixture(scope="module")
def smoke(case_smoke):
    return case_smoke("prs_element")  # --smoke (conftest.SMOKE_ARGS)


@pytest.fixture(scope="module")
def given_smoke(tmp_path_factory):
    """The serial ``--smoke --soil given`` run (its folder and process), shared by the tests
    that need one."""
    out = tmp_path_factory.mktemp("given") / "w1"
    return out, run_case(out, "--smoke", "--soil", "given")


def test_fem_to_dem_smoke_outputs_and_servo_hold(smoke):
    out, proc = smoke
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in ("summary.json", "report.md", "handover.h5", "fem_RE.xdmf", "fem_PRS.xdmf",
                 "fem_PRS.png", "element_RE.h5", "element_PRS.csv",
                 "vtk/element_PRS_contacts.vtp", "vtk/element_PRS_geogrid.vtp"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    s = json.loads((out / "summary.json").read_text())
    for v in ("RE", "PRS"):
        # the FEM state before the footing load and after each of its load steps (the
        # calibrated soil has no cohesion: a rigid footing pushed down to the pressure, its
        # times the pressure's fraction of the footing's, ending within 1 %)
        times = _xdmf_times(out / f"fem_{v}.xdmf")
        assert times[0] == 0.0 and len(times) > 4 and times[-1] == pytest.approx(1.0, abs=0.01)
        e = s["elements"][v]
        assert e["hold_max_rel_error"] <= 0.01
        np.testing.assert_allclose(e["stress_final_pa"], e["targets_pa"][-1], rtol=0.01)
        np.testing.assert_allclose(e["targets_pa"][-1], s["fem"][v]["targets_final_pa"])
    # the prestress is there on both sides: FEM layer force ~ T_p, DEM grid in tension
    assert s["fem"]["PRS"]["layer_force_upper_n_per_m"] > 0.8 * 2000.0
    assert (s["fem"]["PRS"]["layer_force_upper_n_per_m"]
            - s["fem"]["RE"]["layer_force_upper_n_per_m"]) > 0.6 * 2000.0
    assert (s["elements"]["PRS"]["grid_force_longitudinal_mean_n"]
            > s["elements"]["RE"]["grid_force_longitudinal_mean_n"])
    # PRS raises the horizontal x stress of the initial state (the band compresses the soil)
    assert s["fem"]["PRS"]["targets_initial_pa"][0] > s["fem"]["RE"]["targets_initial_pa"][0]
    assert "principal axes turned" in proc.stdout
    # the element's strain against its FEM region's (issue 18): measured, and the known
    # mismatch of the one-way element (tens of times) is warned about, not hidden
    for v in ("RE", "PRS"):
        e = s["elements"][v]
        ratio = (np.abs(e["strain_increment"]).max()
                 / np.abs(s["fem"][v]["strain_increment"]).max())
        assert e["dem_fem_strain_ratio"] == pytest.approx(ratio)
        assert (not 0.5 <= ratio <= 2) == any("strains" in w for w in e["warnings"])
        assert np.abs(e["stress_scatter_pa"]).max() > 0
    report = (out / "report.md").read_text()
    assert "## Warnings" in report
    assert all(w in report for v in ("RE", "PRS") for w in s["elements"][v]["warnings"])
    # the FEM layer's tension across the region, handed to the grid ends (issue 18): PRS
    # below T_p (it gave some to the soil); a layer in compression (RE's initial state,
    # measured -46 N/m) is handed as 0
    import h5py

    for v in ("RE", "PRS"):
        fem_t = s["fem"][v]["grid_tension_n_per_m"]
        e = s["elements"][v]
        assert e["grid_tension_n_per_m"] == [max(t, 0.0) for t in fem_t]
        assert e["grid_end_force_n"] == pytest.approx(0.095 / 9 * max(fem_t[1], 0), rel=1e-2)
    # the prestressed layer keeps part of T_p across the region once equilibrated with the
    # soil (it shortens as the soil gives: the softer the soil, the more it loses; measured
    # 1530 N/m of 2000 on the calibrated soil of 1.23 MPa, 1950 on the given 50 MPa, checked
    # in test_one_soil_on_both_scales_by_default)
    assert 0.5 * 2000 < s["fem"]["PRS"]["grid_tension_n_per_m"][0] < 2000
    with h5py.File(out / "handover.h5") as f:
        np.testing.assert_allclose(f["grid_tension_n_per_m"][:],
                                   [s["fem"][v]["grid_tension_n_per_m"][1] for v in ("RE", "PRS")])
    assert "handed to the element's grid ends" in report
    assert "coupling" not in s and "## Coupling status" not in report  # (none asked)


DEM_ONLY = """
import runpy, sys, json
sys.argv = ["prs_element.py", "--smoke", "--out", {out!r}, "--stresses", {st!r}]
try:
    runpy.run_path({case!r}, run_name="__main__")
except SystemExit as e:
    assert not e.code, e.code
print(json.dumps(sorted(m for m in sys.modules if m.split(".")[0] in
                        ("dolfinx", "dolfinx_solver", "ufl", "petsc4py", "gmsh"))))
"""


def test_dem_only_mode_imports_no_dolfinx_and_holds_given_stresses(tmp_path):
    code = DEM_ONLY.format(out=str(tmp_path), st="25000,25000,60000", case=str(CASE))
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300, cwd=ROOT)
    assert p.returncode == 0, p.stderr[-3000:]
    assert json.loads(p.stdout.strip().splitlines()[-1]) == []
    s = json.loads((tmp_path / "summary.json").read_text())
    e = s["elements"]["RE"]
    np.testing.assert_allclose(e["stress_final_pa"], [25e3, 25e3, 60e3], rtol=0.01)
    assert e["hold_max_rel_error"] <= 0.01


def test_homogeneous_field_handed_over_reproduces_the_standalone_element(tmp_path):
    """An oedometric FEM block (weightless, elastic, uniform surcharge p on the whole top):
    sigma_zz = -p, sigma_xx = sigma_yy = -nu/(1-nu) p exactly; handed over, the element
    reaches them within 1 % and matches the element run with the numbers given directly."""
    sys.path.insert(0, str(ROOT / "cases"))
    import prs_element as pe

    from femcoupling.coupling.handover import fem_to_dem
    from femcoupling.fem.geometry import ElementRegion, ReinforcedSoilBody
    from femcoupling.fem.model import FemModel
    from femcoupling.materials.continuum import LinearElastic

    p_pa, nu = 60e3, 0.3
    body = ReinforcedSoilBody(width_m=1.0, height_m=1.0, footing_half_width_m=1.0,
                              regions=(ElementRegion("e", (0.5, 0.5), 0.1),),
                              mesh_size_m=0.25, fine_size_m=0.05)
    m = FemModel(body, soil=LinearElastic(30e6, nu), degree=1)
    m.set_geostatic()
    m.load_footing(pressure_pa=p_pa, steps=1)
    t = fem_to_dem(m.region_stress("e"))
    exact = np.array([nu / (1 - nu) * p_pa, nu / (1 - nu) * p_pa, p_pa])
    np.testing.assert_allclose(t.normal_pa, exact, rtol=1e-6)
    assert t.rotation_deg == 0.0 and np.all(np.abs(t.shear_pa) < 1e-6 * p_pa)

    prm = pe.Params(**pe.SMOKE)
    a = pe.run_element(prm, [t.normal_pa], prestressed=False, label="handed", out=tmp_path)
    b = pe.run_element(prm, [exact], prestressed=False, label="given", out=tmp_path)
    for e in (a, b):
        assert e["hold_max_rel_error"] <= 0.01
        np.testing.assert_allclose(e["stress_final_pa"], exact, rtol=0.01)
    np.testing.assert_allclose(a["stress_final_pa"], b["stress_final_pa"], rtol=0.01)
    assert a["porosity_final"] == pytest.approx(b["porosity_final"], abs=0.005)


@pytest.mark.parametrize("args,msg", [
    (["--stresses", "1,2"], "need three numbers sx,sy,sz in Pa, got 2"),
    (["--stresses", "1000,-5,3000"], "--stresses: sy=-5.0: must be > 0"),
    (["--stresses", "/nonexistent.csv"], "--stresses=/nonexistent.csv: no such file"),
    (["--prestress", "-1"], "--prestress=-1.0: must be >= 0 (N/m)"),
    (["--stresses", "1e4,1e4,2e4", "--two-way"], "--two-way and --hierarchical need"),
    (["--stresses", "1e4,1e4,2e4", "--soil", "given"], "--soil=given: the FEM soil; not with"),
    (["--soil", "1e6,0.6,30,0"], "--soil='1e6,0.6,30,0': NU=0.6 must be in [0, 0.5)"),
    (["--soil", "soft"], "--soil='soft': 'calibrated', 'given' or four numbers"),
    (["--calibrate", "--soil", "given"], "--calibrate (kept for older run files: it means "
                                         "--soil calibrated) with --soil='given'"),
    (["--stresses", "1e4,1e4,2e4", "--preset", "fast"], "--preset sets the FEM mesh"),
    (["--preset", "quick"], "invalid choice: 'quick'"),
    (["--two-way-element", "periodic"], "--two-way-element periodic: the loop's element; "
                                        "needs --two-way"),
    (["--stresses", "1e4,1e4,2e4", "--no-grid-handover"], "--no-grid-handover: the grid "
                                                          "tension comes from the FEM"),
    (["--hierarchical", "--two-way"], "--hierarchical: the element is inside the FEM's Newton"),
    (["--stresses", "1e4,1e4,2e4", "--hierarchical"], "--two-way and --hierarchical need"),
    (["--two-way", "--tangent-probe", "0.8"], "--tangent-probe=0.8: the probe's size"),
    (["--cell-elements"], "--cell-elements: elements per cell of the region's material; "
                          "needs --hierarchical"),
    (["--hierarchical", "--cell-elements", "--cell-grains", "20"],
     "--cell-grains=20: must be >= 50"),
    (["--hierarchical", "--cell-grains", "100"], "--cell-grains=100: the cells' elements; "
                                                 "needs --cell-elements"),
])
def test_bad_inputs(tmp_path, args, msg):
    p = run_case(tmp_path, "--smoke", *args)
    assert p.returncode != 0 and msg in p.stderr, p.stderr


@pytest.mark.parametrize("name,h,tol", [("fast", 0.05, 0.1), ("balanced", 0.025, 0.02),
                                        ("accurate", 0.0125, 0.005)])
def test_preset_sets_the_fem_mesh_and_the_two_way_tolerance(name, h, tol):
    """--preset: fine mesh = fem_size_per_element x the 0.1 m element edge, coarse 20 x that,
    the preset's two-way tolerance; the DEM element's settings unchanged."""
    sys.path.insert(0, str(ROOT / "cases"))
    import prs_element

    p, _ = prs_element.parse_args(["--preset", name])
    d, _ = prs_element.parse_args([])
    assert p.fine_size == pytest.approx(h) and p.mesh_size == pytest.approx(20 * h)
    assert p.two_way_tol == tol
    assert (p.n, p.damping, p.hold_steps) == (d.n, d.damping, d.hold_steps)


def test_one_soil_on_both_scales_by_default(smoke, given_smoke):
    """The default FEM soil is calibrated on the case's own element (issue 37): by passes,
    the element driven along its region's path until it strains within [1/2, 2] times its
    FEM region (smoke, measured: 87 x with the given soil, then 0.29 x with its secant, then
    0.91 x with E interpolated between the two: three passes; the secants alone swung 2.3 x,
    0.41 x and never held); no cohesion, nu set to its limit where the secant's is above it,
    said. The run then holds: RE and PRS elements within 2 x their regions (measured 0.91 and
    0.88). The
    given soil (--soil given, 50 MPa) leaves the element straining over 50 x its region."""
    out, proc = smoke
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    c = s["calibration"]
    assert c["converged"] and len(c["passes"]) >= 2
    assert c["passes"][0]["soil_young_pa"] == 50e6 and c["passes"][0]["dem_fem_strain_ratio"] > 10
    assert 0.5 <= c["passes"][-1]["dem_fem_strain_ratio"] <= 2.0
    assert s["soil"] == {"source": "calibrated", "young_pa": c["young_pa"],
                         "poisson": c["poisson"], "cohesion_pa": 0.0, "friction_deg": 35.0,
                         "footing": s["soil"]["footing"]}
    assert 0 < c["young_pa"] < 50e6 and 0 <= c["poisson"] <= 0.45
    # a clipped Poisson's ratio is said
    clipped = [r for r in c["passes"] if r["secant_poisson_fitted"] > 0.45]
    assert len(c["warnings"]) == len(clipped)
    assert all(w in proc.stdout for w in c["warnings"])
    for v in ("RE", "PRS"):
        assert 0.5 <= s["elements"][v]["dem_fem_strain_ratio"] <= 2.0
    assert (out / "calibration.json").is_file()
    assert "## Calibration of the FEM soil" in (out / "report.md").read_text()
    # the last pass's RE FEM (the calibrated soil's) is the run's: solved once per pass, not
    # again (measured: its results equal a run that solved it again, the times aside)
    assert len(re.findall(r"FEM RE: \d+ cells", proc.stdout)) == len(c["passes"])
    assert "FEM RE: the calibration's last pass, with this soil (not solved again)" in proc.stdout
    given, p = given_smoke
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    g = json.loads((given / "summary.json").read_text())
    assert "calibration" not in g and g["soil"]["young_pa"] == 50e6
    assert g["soil"]["cohesion_pa"] == 10e3
    for v in ("RE", "PRS"):
        assert g["elements"][v]["dem_fem_strain_ratio"] > 10
        assert any("strains" in w for w in g["elements"][v]["warnings"])
    # the prestress lost to the soil's give falls with its stiffness: the layer on the given
    # 50 MPa soil keeps more of T_p than on the calibrated (softer) one, both less than T_p
    t_cal = s["fem"]["PRS"]["grid_tension_n_per_m"][0]
    t_given = g["fem"]["PRS"]["grid_tension_n_per_m"][0]
    assert c["young_pa"] < 50e6 and t_cal < t_given < 2000.0


def test_two_way_keeps_the_prepared_element_between_iterations(tmp_path, capsys):
    """The two-way runner prepares the element at the initial targets once (issue 18: it was
    rebuilt every iteration, 54k preparation steps against 2k for the increment); the next
    iteration restores it from its checkpoint bytes and runs only the final stage, bitwise
    as a fresh element would."""
    from dataclasses import asdict

    from femcoupling.coupling.handover import fem_to_dem
    from geogrid_dem.studies.prs_element import element_runner
    from geogrid_dem.cases import prs_element as pe

    p = pe.Params(**pe.SMOKE)
    ini = fem_to_dem(-np.diag([2.3e3, 2.3e3, 5.4e3]))
    runs = [element_runner(type(p), asdict(p), str(tmp_path), "element_RE", ini,
                           fem_to_dem(-np.diag([10e3, 9e3, s]))) for s in (20e3, 20e3)]
    log = capsys.readouterr().out
    assert log.count("restored from the cache") == 1
    assert log.count("grown to") == 1  # one preparation
    a, b = runs
    assert np.array_equal(a.stress_final_pa, b.stress_final_pa)
    assert np.array_equal(a.strain_increment, b.strain_increment)


def test_workers_run_re_and_prs_side_by_side_with_the_same_results(given_smoke, tmp_path):
    """--workers 2: RE and PRS each in its own process (FEM, loop, element); the elements'
    answers and the merged handover record are bitwise the serial run's (the given soil:
    the calibration runs before the variants, in the main process)."""
    import h5py

    out0, p = given_smoke
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    p = run_case(tmp_path / "w2", "--smoke", "--workers", "2", "--soil", "given")
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    assert "RE and PRS run in two processes" in p.stdout
    a = json.loads((out0 / "summary.json").read_text())
    b = json.loads((tmp_path / "w2" / "summary.json").read_text())
    for v in ("RE", "PRS"):
        for k in ("stress_final_pa", "strain_increment", "porosity_final",
                  "grid_force_longitudinal_mean_n"):
            assert a["elements"][v][k] == b["elements"][v][k], (v, k)
    with h5py.File(out0 / "handover.h5") as f, h5py.File(tmp_path / "w2" / "handover.h5") as g:
        for k in f:
            assert np.array_equal(f[k][:], g[k][:], equal_nan=True), k
    assert not list((tmp_path / "w2").glob("handover_*.h5"))  # the parts are merged
