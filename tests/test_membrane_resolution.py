"""The cylinder's membrane resolution (``membrane_side`` of
cpp_dem.protocols.cylinder_triaxial.prepare, the triaxial case's ``--membrane-side``): the
coarsest membrane the library allows holds the specimen as the default one does, with about a
quarter of its nodes; out-of-range sides are refused by name; bench/membrane_resolution.py
pairs two sides over seeds, and docs/studies/membrane_resolution.md's table is its rendering
of the committed data file."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import load_bench

import cpp_dem as dem
from cpp_dem.build.membrane import lattice_sides
from cpp_dem.protocols import cylinder_triaxial as ct

ROOT = Path(__file__).resolve().parents[1]
P = 100e3  # Pa
R_MIN = 0.0016  # m: the smallest grain radius below


def _material():
    return dem.linear_material(density=2650, young=5e7, poisson=0.3, friction_angle_deg=30)


def test_the_coarsest_membrane_holds_the_specimen_with_a_quarter_of_the_nodes():
    radii = 0.002 * np.random.default_rng(1).uniform(0.8, 1.0, 300)
    spec = ct.prepare(radii, radius_m=0.017, height_m=0.05, pressure_pa=P,
                      material=_material(), membrane_side=ct.MEMBRANE_SIDE_MAX)
    s = spec.prepared
    assert s["reached"] and s["grains_outside"] == 0
    assert s["axial_stress_pa"] == pytest.approx(P, rel=0.01)
    assert abs(s["membrane_correction_pa"]) < 0.05 * P
    # every triangle as wide as the smallest grain at most (the library's limit) ...
    mb, r_min = spec.membrane, float(radii.min())
    n = len(mb.rings[0])
    chord, diagonal, rings = lattice_sides(mb.radius_m, mb.height_m, n)
    assert len(mb.rings) == rings and max(chord, diagonal) <= 2 * r_min
    # ... and about a quarter of the default's nodes (the default's segments and rings from
    # the same rule, not built)
    n1 = ct._auto_segments(mb.radius_m, mb.height_m, r_min, r_min)
    rings1 = lattice_sides(mb.radius_m, mb.height_m, n1)[2]
    assert len(mb.nodes) == n * rings
    assert 0.2 < len(mb.nodes) / (n1 * rings1) < 0.3
    rows = ct.shear(spec, strain_rate=0.5, stop_strain=0.01, record_every=1000)
    assert all(r["grains_outside"] == 0 for r in rows)
    assert rows[-1]["deviatoric_stress_pa"] > 0.3 * P


def test_the_default_side_keeps_the_chord_within_the_smallest_radius():
    # (side 1: the rule the membrane was built by before the option: chord <= r_min)
    for radius in (0.0176, 0.04, 0.1):
        n = ct._auto_segments(radius, 0.1, R_MIN, R_MIN)
        assert n == max(12, math.ceil(2 * math.pi * radius / R_MIN))
        assert lattice_sides(radius, 0.1, n)[0] <= R_MIN


@pytest.mark.parametrize("side", [0.5, 2.5, math.nan])
def test_a_membrane_side_out_of_range_is_refused_by_name(side):
    with pytest.raises(dem.ParameterError, match=r"membrane_side=.*must be in \[0.75, 2\]"):
        ct.prepare([0.002] * 10, radius_m=0.017, height_m=0.05, pressure_pa=P,
                   material=_material(), membrane_side=side)


def test_a_renewed_time_step_holds_the_specimen_at_its_fraction_of_the_critical_one():
    radii = 0.002 * np.random.default_rng(1).uniform(0.8, 1.0, 300)
    spec = ct.prepare(radii, radius_m=0.017, height_m=0.05, pressure_pa=P,
                      material=_material(), membrane_side=ct.MEMBRANE_SIDE_MAX, dt_safety=0.5)
    s, sc = spec.prepared, spec.scene
    assert s["reached"] and s["grains_outside"] == 0
    # renewed every 100 steps: within a few per cent of half the critical step at the hold
    # (the grains and the membrane), and longer than the protocol's kept step
    assert sc.dt == pytest.approx(0.5 * sc.critical_dt(), rel=0.05)
    kept = ct.prepare(radii, radius_m=0.017, height_m=0.05, pressure_pa=P,
                      material=_material(), membrane_side=ct.MEMBRANE_SIDE_MAX).scene.dt
    assert sc.dt > 1.5 * kept
    rows = ct.shear(spec, strain_rate=0.5, stop_strain=0.01, record_every=1000)
    assert all(r["grains_outside"] == 0 for r in rows)


@pytest.mark.parametrize("dt", [0.0, 1.5, math.nan])
def test_a_time_step_fraction_out_of_range_is_refused_by_name(dt):
    with pytest.raises(dem.ParameterError, match=r"dt_safety=.*must be in \(0, 1\]"):
        ct.prepare([0.002] * 10, radius_m=0.017, height_m=0.05, pressure_pa=P,
                   material=_material(), dt_safety=dt)


def test_the_case_passes_dt_safety_to_the_cylinder_only_when_given(tmp_path):
    from geogrid_dem.cases import triaxial

    base = ["--smoke", "--specimen", "cylinder", "--out", str(tmp_path)]
    assert triaxial.parse_args(base)[0].dt_safety is None  # (the protocol's step)
    assert triaxial.parse_args([*base, "--dt-safety", "0.5"])[0].dt_safety == 0.5
    assert triaxial.parse_args(["--smoke", "--out", str(tmp_path)])[0].dt_safety == 0.5  # box


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    base = tmp_path_factory.mktemp("mres")

    def bench(name: str, *args: str) -> dict:
        """The bench's smoke of seed 1 with ``args``, its runs in mr_runs/ (a run already
        there is read again), its data file ``name``.json."""
        out = base / f"{name}.json"
        p = subprocess.run([sys.executable, str(ROOT / "bench" / "membrane_resolution.py"),
                            "--smoke", "--seeds", "1", *args, "--runs", str(base / "mr_runs"),
                            "--out", str(out)],
                           capture_output=True, text=True, timeout=600, cwd=base,
                           env={**os.environ, "OMP_NUM_THREADS": "1"})
        assert p.returncode == 0, p.stderr[-2000:]
        return json.loads(out.read_text())

    sides = bench("mr")
    # the time step at side 1: the kept run of seed 1 read again, the renewed one run
    step = bench("dt", "--sides", "1", "--dt-safety", "0.5")
    # both options together: the kept run of side 1 read again, side 2's renewed one run
    both = bench("both", "--sides", "1,2", "--dt-safety", "0.5")
    return base / "mr_runs", sides, step, both


def test_the_bench_runs_the_case_at_both_sides_and_pairs_them(smoke):
    runs, data, *_ = smoke
    by = {r["side"]: r for r in data["runs"]}
    assert set(by) == {1.0, 2.0} and by[1.0]["num_grains"] == by[2.0]["num_grains"]
    for side in (1, 2):
        s = json.loads((runs / f"side{side}_s1" / "summary.json").read_text())
        assert s["membrane"]["side"] == side and s["grains_outside_max"] == 0
    assert by[2.0]["membrane_nodes"] < 0.3 * by[1.0]["membrane_nodes"]
    assert by[2.0]["link_length_m"] > 1.8 * by[1.0]["link_length_m"]
    d = next(x for x in data["paired"] if x["measure"] == "deviatoric_stress"
             and x["axial_strain"] == 0.01)
    assert (d["mean"] == by[2.0]["deviatoric_stress"][1] - by[1.0]["deviatoric_stress"][1])
    assert d["n"] == 1 and not d["resolved"]  # (one seed resolves nothing)
    speed = next(x for x in data["paired"] if x["measure"] == "speedup_wall_time_total_s")
    assert speed["mean"] == pytest.approx(by[1.0]["wall_time_total_s"]
                                          / by[2.0]["wall_time_total_s"])
    mod = load_bench("membrane_resolution")
    lines = mod.table(data)
    assert len(lines) == 2 + 3 * len(data["params"]["at"]) + 2 + 4 + 2


def test_the_bench_pairs_the_kept_time_step_with_the_renewed_one(smoke):
    runs, _, data, _ = smoke
    by = {r.get("dt_safety"): r for r in data["runs"]}
    assert set(by) == {None, 0.5} and {r["side"] for r in data["runs"]} == {1.0}
    s = json.loads((runs / "side1_dt0.5_s1" / "summary.json").read_text())
    assert s["membrane"]["dt_safety"] == 0.5 and s["grains_outside_max"] == 0
    # the renewed step is longer here: fewer steps to the same strain
    assert by[0.5]["deviatoric_steps"] < by[None]["deviatoric_steps"]
    d = next(x for x in data["paired"] if x["measure"] == "volumetric_strain"
             and x["axial_strain"] == 0.01)
    assert d["mean"] == by[0.5]["volumetric_strain"][1] - by[None]["volumetric_strain"][1]
    lines = load_bench("membrane_resolution").table(data)
    assert lines[0].startswith("| measure | axial strain, % | side 1 | side 1, step 0.5 renewed "
                               "| 0.5 - kept (+- SE) |")


def test_the_bench_pairs_the_default_with_both_options_together(smoke):
    runs, plain, _, data = smoke
    by = {(r["side"], r.get("dt_safety")): r for r in data["runs"]}
    assert set(by) == {(1.0, None), (2.0, 0.5)}
    # the default's run is the first study's, read again
    assert by[1.0, None] == next(r for r in plain["runs"] if r["side"] == 1.0)
    s = json.loads((runs / "side2_dt0.5_s1" / "summary.json").read_text())
    assert s["membrane"]["dt_safety"] == 0.5 and s["membrane"]["side"] == 2
    d = next(x for x in data["paired"] if x["measure"] == "deviatoric_stress"
             and x["axial_strain"] == 0.01)
    both, default = by[2.0, 0.5], by[1.0, None]
    assert d["mean"] == both["deviatoric_stress"][1] - default["deviatoric_stress"][1]
    lines = load_bench("membrane_resolution").table(data)
    assert lines[0].startswith("| measure | axial strain, % | side 1 | side 2, step 0.5 renewed "
                               "| side 2, step 0.5 - side 1 (+- SE) |")


@pytest.mark.parametrize("name", ["membrane_resolution", "membrane_resolution_fine",
                                  "membrane_time_step", "membrane_time_step_side1",
                                  "membrane_options_together"])
def test_the_docs_table_is_the_committed_data_s(name):
    mod = load_bench("membrane_resolution")
    data = json.loads((ROOT / "docs" / "data" / f"{name}.json").read_text())
    text = (ROOT / "docs" / "studies" / "membrane_resolution.md").read_text()
    for line in mod.table(data):
        assert line in text, line


@pytest.mark.parametrize("args, msg", [
    (["--sides", "2,1"], "--sides=2,1: must be two sides in [0.75, 2], the finer first"),
    (["--sides", "1,3"], "--sides=1,3: must be two sides in [0.75, 2]"),
    (["--sides", "2,1", "--dt-safety", "0.5"],
     "--sides=2,1: with --dt-safety, one side in [0.75, 2], or two, the finer first"),
    (["--sides", "1,1.5,2", "--dt-safety", "0.5"], "--sides=1,1.5,2: with --dt-safety"),
    (["--sides", "1", "--dt-safety", "1.5"], "--dt-safety=1.5: must be in (0, 1]"),
])
def test_the_bench_refuses_bad_sides_by_name(tmp_path, args, msg):
    p = subprocess.run([sys.executable, str(ROOT / "bench" / "membrane_resolution.py"), *args,
                        "--out", str(tmp_path / "x.json")], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 2 and msg in p.stderr, p.stderr
