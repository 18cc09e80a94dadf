"""The thesis's own pull-out force (geogrid_dem.cases.pullout_001: force_001): the bodies its
Appendix A script sums, ids 91-100, found again by position in our grid, and the sum of their
|x force|; the study's statistics over seeds. Small scenes only (no grains): a second or two."""

from __future__ import annotations

import math

import numpy as np
import pytest

import cpp_dem as dem
from cpp_dem.build import geogrid
from geogrid_dem.cases import pullout_001 as case

SPACING = 0.01  # m: App. A's square grid, L / nbL = 0.10 / 10


def _grid(kind: str):
    """A scene holding only the case's grid at its size (10 x 10 nodes at 1 cm, or the grid of
    triangles), every node blocked; returns (scene, grid)."""
    sc = dem.Scene()
    mat = sc.add_material(dem.linear_material(density=2650, young=5e6, poisson=0.3,
                                              friction_angle_deg=20))
    beam = dem.BeamParams(young=5e6, poisson=0.3, radius=1e-3, normal_cohesion=1e7,
                          shear_cohesion=1e7)
    if kind == "square":
        g = geogrid.square_grid(sc, origin=(0.005, 0.005, 0.05), length=0.09, width=0.09,
                                nodes_x=10, nodes_y=10, params=beam, material=mat,
                                density=2650)
    else:
        side = 0.0143
        h = side * math.sqrt(3) / 2
        g = geogrid.triangular_grid(sc, origin=(0.5 * (0.1 - 6 * side), 0.5 * (0.1 - 7 * h),
                                            0.05),
                                    length=6 * side, width=7 * h, side=side, params=beam,
                                    material=mat, density=2650)
    sc.block_dofs(g.nodes, "all")
    return sc, g


def test_yade_creation_order_of_the_square_grid():
    bodies = case.yade_square_bodies(10, 10)
    # 100 nodes, then 2 x 10 x 9 connections: the walls follow at 280-285, and App. A servoes
    # body 285 as its top wall (the last of aabbWalls' x-, x+, y-, y+, z-, z+).
    assert len(bodies) == 280
    assert bodies[0] == ("node", (0, 0)) and bodies[99] == ("node", (9, 9))
    assert [bodies[k] for k in range(91, 100)] == [("node", (9, j)) for j in range(1, 10)]
    assert bodies[90] == ("node", (9, 0))  # not summed by App. A
    assert bodies[100] == ("connection", (0, 1))  # the first connection: front row, y = min
    assert bodies[101] == ("connection", (0, 10))
    assert sorted(case.FORCE_IDS_001) == list(case.force_ids_001(10, 10)) == \
        list(range(91, 101))


def test_force_001_sums_exactly_the_back_row_but_its_y_min_node():
    sc, g = _grid("square")
    pos = np.asarray(sc.positions)[g.nodes]
    # Found by position, whatever the order the nodes come in.
    perm = np.random.default_rng(3).permutation(len(g.nodes))
    sel = case.force_bodies_001("square", g.nodes[perm], pos[perm])
    assert sel.yade_ids == tuple(sorted(case.FORCE_IDS_001))
    want = g.nodes[(np.abs(pos[:, 0] - pos[:, 0].max()) < 1e-9)
                   & (np.abs(pos[:, 1] - pos[:, 1].min()) > 1e-9)]
    assert len(sel.nodes) == 9
    assert set(sel.nodes.tolist()) == set(want.tolist())
    # Id 100 is a GridConnection (no force in Yade): its nodes are the first two of the front row.
    (k, a, b), = sel.zero_ids
    assert k == 100
    pa, pb = np.asarray(sc.positions)[[a, b]]
    assert pa[0] == pb[0] == pytest.approx(pos[:, 0].min())
    assert sorted([pa[1], pb[1]]) == pytest.approx([pos[:, 1].min(), pos[:, 1].min() + SPACING])

    # Known x forces on every node (signs mixed): the measure is the hand sum of |f_x| over
    # those 9 nodes and no other.
    fx = np.random.default_rng(7).uniform(-5.0, 5.0, len(g.nodes))
    ext = np.zeros((sc.num_bodies, 3))
    ext[g.nodes, 0] = fx
    ext[g.nodes, 2] = 1.0  # a z force changes nothing
    sc.external_forces = ext
    sc.run(1)
    f = np.asarray(sc.forces)
    np.testing.assert_allclose(f[g.nodes, 0], fx, rtol=0, atol=1e-12)
    hand = sum(abs(fx[i]) for i in range(len(g.nodes)) if g.nodes[i] in set(want.tolist()))
    assert case.force_001(sc, sel.nodes) == pytest.approx(hand, rel=1e-12)
    # Another row (the front, x = min) or the whole back row gives another sum: the test
    # fails if the selection moves.
    front = g.nodes[np.abs(pos[:, 0] - pos[:, 0].min()) < 1e-9]
    back = g.nodes[np.abs(pos[:, 0] - pos[:, 0].max()) < 1e-9]
    assert set(front.tolist()) != set(sel.nodes.tolist())
    assert case.force_001(sc, front) != pytest.approx(hand, rel=1e-6)
    assert case.force_001(sc, back) == pytest.approx(hand + abs(fx[g.nodes == back[0]][0]))


def test_force_001_of_the_triangular_grid_and_bad_input():
    sc, g = _grid("triangular")
    pos = np.asarray(sc.positions)[g.nodes]
    sel = case.force_bodies_001("triangular", g.nodes, pos)
    assert sel.yade_ids == () and sel.zero_ids == ()
    rows = np.unique(np.round(pos[:, 1], 9))
    assert len(sel.nodes) == len(rows) - 1 == 7
    by_id = {int(n): p for n, p in zip(g.nodes, pos)}
    for n in sel.nodes:  # the last node of its row, never the row at y = min
        same_row = pos[np.abs(pos[:, 1] - by_id[n][1]) < 1e-9]
        assert by_id[n][0] == same_row[:, 0].max()
        assert by_id[n][1] > rows[0] + 1e-9
    with pytest.raises(ValueError, match="grid_kind='hexagonal'"):
        case.force_bodies_001("hexagonal", g.nodes, pos)
    with pytest.raises(ValueError, match="do not form a full lattice"):
        case.force_bodies_001("square", g.nodes, pos)


def test_jittered_lattice_keeps_grains_apart_and_seeds_differ():
    p = case.Params(radius=2.5e-3, box=0.05)
    c0, r0 = case.grains(p)
    c1, r1 = case.grains(case.Params(radius=2.5e-3, box=0.05, jitter=1.0, seed=1))
    c2, _ = case.grains(case.Params(radius=2.5e-3, box=0.05, jitter=1.0, seed=2))
    assert len(c1) == len(c0) and np.array_equal(r0, r1)
    move = np.linalg.norm(c1 - c0, axis=1)
    assert 0 < move.max() <= 0.5 * (p.radius / 2) + 1e-15  # at most half the gap
    assert not np.array_equal(c1, c2)
    d = np.linalg.norm(c1[:, None] - c1[None], axis=2) + np.eye(len(c1))
    assert d.min() >= 2 * p.radius - 1e-12
    assert np.all(c1 >= p.radius - 1e-15) and np.all(c1 <= p.box - p.radius + 1e-15)
    assert np.all(np.abs(c1[:, 2] - 0.5 * p.box) >= p.radius + 1.5e-3 - 1e-15)


def _row(seed, m001, cov001, m, cov, status="ok", r=2.5e-3, P=75e3):
    return {"grid": "square", "radius_m": r, "pressure_Pa": P, "grid_young_Pa": 5e6,
            "grains": "spheres", "jitter": 0.001, "seed": seed, "num_grains": 100,
            "pulled_m": 0.095 if status == "ok" else 0.03, "mean_force_N": m,
            "cov_force": cov, "mean_force_001_N": m001, "cov_001": cov001,
            "mean_front_force_N": 0.1, "wall_time_s": 100.0, "status": status}


def test_study_cells_mean_sd_and_within():
    rows = [_row(1, 21.0, 0.5, 300.0, 0.3), _row(2, 25.0, 0.6, 320.0, 0.4),
            _row(3, 23.0, 0.55, 310.0, 0.35), _row(4, 99.0, 0.1, 999.0, 0.1, status="stopped")]
    c, = case.study_cells(rows)
    assert (c["runs"], c["completed"]) == (4, 3)  # the stopped run is left out of the stats
    assert c["mean_force_001_N"] == pytest.approx(23.0)
    assert c["sd_mean_force_001_N"] == pytest.approx(2.0)  # ddof 1
    assert c["thesis_mean_force_N"] == 26.29 and c["thesis_cov"] == 0.543
    assert c["thesis_force_within"] is True  # |26.29 - 23| <= 2 x 2
    assert c["thesis_cov_within"] is True  # |0.543 - 0.55| <= 2 x 0.05
    assert "seed 4 at 30.0 mm" in c["status"]
    rows[0]["mean_force_001_N"] = 22.0
    rows[1]["mean_force_001_N"] = 22.5  # 22.5 +- 0.5: 26.29 is 7.6 sd away
    c, = case.study_cells(rows)
    assert c["thesis_force_within"] is False
    one, = case.study_cells(rows[:1])
    assert one["thesis_force_within"] is None  # one seed: no scatter to compare with
    # CoV trend over the grain size: r = 1.5 mm with a CoV well below r = 2.5 mm's.
    small = [_row(s, 15.0, 0.2 + 0.01 * s, 250.0, 0.3, r=1.5e-3) for s in (1, 2, 3)]
    lines = case.cov_trend(case.study_cells(rows + small))
    assert len(lines) == 1 and "the thesis's measure" in lines[0]
    assert lines[0].split("the thesis's measure")[1].split(";")[0].endswith("falls")


@pytest.mark.parametrize("argv,match", [
    (["--seeds", "1-3"], "needs --study"),
    (["--study", "--seeds", "1-3"], "--jitter > 0"),
    (["--study", "--seeds", "3-1", "--jitter", "0.1"], "A <= B"),
    (["--study", "--seeds", "1,x", "--jitter", "0.1"], "--seeds='1,x'"),
    (["--jitter", "1.5"], "--jitter=1.5"),
    (["--record-every", "0"], "--record-every=0"),
    (["--cov-window", "0.03"], "needs --study"),
    (["--study", "--cov-window", "-1"], "--cov-window=-1.0"),
])
def test_bad_study_options_are_named(argv, match, capsys):
    with pytest.raises(SystemExit):
        case.parse_args(argv)
    assert match in capsys.readouterr().err


def test_seeds_option():
    p, *_rest, seeds, _ow, win = case.parse_args(["--study", "--seeds", "2-4", "--jitter",
                                                  "0.001"])
    assert seeds == [2, 3, 4] and p.seed == 2 and p.jitter == 0.001 and win is None
    assert case.parse_args(["--study", "--seeds", "5,1", "--jitter", "1"])[7] == [5, 1]
    assert case.parse_args([])[7] == [1]
    assert case.parse_args(["--study", "--cov-window", "0.03"])[-1] == 0.03
    got = case.parse_args(["--study", "--grids", "square", "--radius", "0.0025,0.0015",
                           "--pressure", "75e3", "--seeds", "1-2", "--jitter", "0.01"])
    assert got[3:6] == (["square"], [0.0025, 0.0015], [75e3])


def _record(path, d, f, f001):
    path.mkdir(parents=True, exist_ok=True)
    with open(path / "pullout.csv", "w") as fh:
        fh.write("displacement,pull_force,force_001,front_force\n")
        for row in zip(d, f, f001, 0.01 * np.asarray(f)):
            fh.write(",".join(map(repr, map(float, row))) + "\n")


def test_cov_window_compares_runs_over_the_pull_they_share(tmp_path):
    """Runs that stopped at different distances are compared over the shortest pull: what a
    longer run did after it is left out, and a CoV that falls within the window is seen."""
    rng = np.random.default_rng(5)
    rows = []
    for n, (r, spread, pulled) in enumerate([(2.5e-3, 0.6, 0.095), (1.5e-3, 0.2, 0.04)]):
        for seed in (1, 2, 3):
            d = np.linspace(0, pulled, int(pulled / 1e-4) + 1)
            f = 100 * (1 + spread * rng.uniform(-1, 1, len(d)))
            f[d > 0.04] = 1e6 * (1 + rng.uniform(-1, 1, np.count_nonzero(d > 0.04)))
            row = _row(seed, 1.0, 0.1, 1.0, 0.1, r=r, status="ok" if pulled > 0.09 else "x")
            row["pulled_m"] = pulled
            row["run"] = f"r{n}_s{seed}"
            _record(tmp_path / row["run"], d, f, 0.1 * f)
            rows.append(row)
    wt = case.window_trend(rows, tmp_path)
    assert [c["radius_m"] for c in wt] == [2.5e-3, 1.5e-3]
    assert all(c["window_m"] == pytest.approx(0.04) and c["runs"] == 3 for c in wt)
    big, small = wt
    # uniform on +-spread: CoV = spread / sqrt(3); the 1e6 records after 40 mm are left out
    assert big["cov_force"] == pytest.approx(0.6 / 3**0.5, rel=0.1)
    assert big["mean_force_N"] == pytest.approx(100, rel=0.05)
    assert small["cov_001"] == pytest.approx(0.2 / 3**0.5, rel=0.1)
    assert small["cov_force_step"] == "falls" and small["cov_001_step"] == "falls"
    # a window the user gives shortens it further; the lines say the window
    wt2 = case.window_trend(rows, tmp_path, window_m=0.01)
    assert all(c["window_m"] == 0.01 for c in wt2)
    line, = case.window_lines(wt)
    assert "over the first 40.0 mm" in line and "falls" in line
    # the same spread at both radii: no step
    for row in rows[3:]:
        d = np.linspace(0, 0.04, 401)
        _record(tmp_path / row["run"], d, 100 * (1 + 0.6 * rng.uniform(-1, 1, 401)),
                10 * (1 + 0.6 * rng.uniform(-1, 1, 401)))
    assert case.window_trend(rows, tmp_path)[1]["cov_force_step"] == "stays within the scatter"


def test_an_interrupted_study_run_keeps_its_row_and_runs_again(tmp_path, monkeypatch):
    calls = []

    def fake_run(q, sub):
        calls.append(q.seed)
        _record(sub, np.linspace(0, 0.01, 11), np.full(11, 50.0), np.full(11, 5.0))
        if len(calls) == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(case, "run", fake_run)
    p = case.Params(radius=2.5e-3, box=0.05, jitter=0.001)
    with pytest.raises(KeyboardInterrupt):
        case.study(p, tmp_path, ["square"], [2.5e-3], [75e3], True, seeds=[1])
    row, = case.read_rows(tmp_path)
    assert row["status"].startswith("interrupted") and row["pulled_m"] == pytest.approx(0.01)
    assert "interrupted" in (tmp_path / "study.md").read_text()
    case.study(p, tmp_path, ["square"], [2.5e-3], [75e3], True, seeds=[1])  # runs it again
    assert calls == [1, 1]
    row, = case.read_rows(tmp_path)
    assert row["status"] == "ok"
    case.study(p, tmp_path, ["square"], [2.5e-3], [75e3], True, seeds=[1])  # done: skipped
    assert calls == [1, 1]


def test_summarize_takes_a_record_without_transverse_members():
    """A grid of triangles records longitudinal member forces but no transverse ones: the
    summary has no transverse ratio instead of a KeyError."""
    from cpp_dem.protocols import pullout

    d = np.linspace(0, 0.01, 11)
    rec = {"displacement": d, "pull_force": 10 + d, "force_A1": 1 + d, "force_A2": 2 + d}
    st = pullout.summarize(rec)
    assert st["mean_force_N"] > 0 and "transverse_over_longitudinal" not in st
    rec.update(force_C1=0.5 + d, force_C2=0.5 + d)
    assert pullout.summarize(rec)["transverse_over_longitudinal"] > 0


def test_front_slot_is_its_own_cell_and_bad_values_are_named(capsys):
    """--front-slot opens the front wall during the pull: a run with it is a cell of its own
    (its run folder and study row say so), and a row written before the option existed is a
    closed-wall row."""
    p = case.parse_args(["--front-slot", "0.5"])[0]
    assert p.front_slot == 0.5 and case.parse_args([])[0].front_slot == 0.0
    assert case.run_name(p).endswith("_slot0.5_s1")
    assert "_slot" not in case.run_name(case.Params())
    for bad in ("-0.1", "2.5", "nan"):
        with pytest.raises(SystemExit):
            case.parse_args(["--front-slot", bad])
        assert f"--front-slot={float(bad)}" in capsys.readouterr().err
    closed = [_row(s, 20.0 + s, 0.5, 300.0, 0.3) for s in (1, 2)]  # no front_slot key
    slot = [{**_row(s, 10.0 + s, 0.4, 200.0, 0.3), "front_slot": 0.5} for s in (1, 2)]
    cells = case.study_cells(closed + slot)
    assert sorted(c["front_slot"] for c in cells) == [0.0, 0.5]
    by = {c["front_slot"]: c for c in cells}
    assert by[0.0]["mean_force_001_N"] == pytest.approx(21.5)
    assert by[0.5]["mean_force_001_N"] == pytest.approx(11.5)
    assert "front slot 0.5" in case.material_label(*case.material_of(by[0.5]))


def test_open_front_slot_opens_the_front_wall_around_the_grid_plane():
    from cpp_dem.protocols import pullout

    q = case.Params(**case.SMOKE)
    sample = case.build(q)
    front = sample.walls[pullout.X_MINUS]
    assert sample.scene.wall_opening(front)[0] == -1  # built closed
    with pytest.raises(dem.ParameterError, match="must exceed the largest grain radius"):
        pullout.open_front_slot(sample, 0.9 * q.radius)  # no grain fits
    pullout.open_front_slot(sample, 0.004)
    axis, lo, hi = sample.scene.wall_opening(front)
    assert axis == 2 and (lo, hi) == pytest.approx((sample.grid_z - 0.004,
                                                    sample.grid_z + 0.004))
    for w in sample.walls[1:]:
        assert sample.scene.wall_opening(w)[0] == -1  # the other walls stay closed
    for bad in (0.0, -1e-3, float("inf"), q.box):
        with pytest.raises(dem.ParameterError, match="half_height="):
            pullout.open_front_slot(sample, bad)
