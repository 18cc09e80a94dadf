"""bench/pullout_000_vs_yade.py: the member-force definitions on made-up link forces, and,
when Yade is installed, the hand-over of a prepared pull-out sample (the case's smoke sample)
to Yade: after one step every sphere that touches the geogrid in neither code carries the same
force in both, and the GridConnections get cpp_dem's beam stiffnesses."""

from __future__ import annotations

import importlib.util
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bench():
    path = ROOT / "bench" / "pullout_000_vs_yade.py"
    spec = importlib.util.spec_from_file_location("pullout_000_vs_yade", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, mod)
    spec.loader.exec_module(mod)
    return mod


def _made_up(edge_a, edge_c, records=3):
    """Members A1, A2 along x and C1, C2 along y, each three section links (two along the
    member, one diagonal at 45 degrees, carrying nothing) and one link across it carrying 1 N;
    the section edges carry edge_a / edge_c (N, tension positive)."""
    members, rows_ax, dirs = {}, [], []
    k = 0
    for name, axis, edges in (("A1", (1.0, 0, 0), edge_a), ("C1", (0, 1.0, 0), edge_c),
                              ("A2", (1.0, 0, 0), edge_a), ("C2", (0, 1.0, 0), edge_c)):
        ax = np.array(axis)
        across = np.array([ax[1], ax[0], 0.0])
        diag = (ax + across) / np.sqrt(2)
        links = [k, k + 1, k + 2, k + 3]
        members[name] = {"links": links, "section": links[:3], "axis": list(axis)}
        rows_ax += [edges[0], edges[1], 0.0, 1.0]
        dirs += [ax, ax, diag, across]
        k += 4
    row = {"axial": rows_ax, "shear": np.zeros((k, 3)).tolist(),
           "direction": np.array(dirs).tolist(), "displacement": 0.0}
    rows = [dict(row, displacement=1e-3 * i) for i in range(records)]
    return {"members": members}, {"rows": rows, "tracked": list(range(k))}


def test_member_definitions_on_made_up_forces():
    b = _bench()
    # A in tension (both edges +100 N), C bent in its plane (+20 N and -20 N on its edges).
    st, run = _made_up((100.0, 100.0), (20.0, -20.0))
    s = b.member_series(run, st)
    assert np.allclose(s["section_sum"]["A1"], 200.0)
    assert np.allclose(s["section_sum"]["C1"], 0.0)          # bending cancels in the sum
    assert np.allclose(s["section_abs_sum"]["C1"], 40.0)
    assert np.allclose(s["section_edge_abs"]["C2"], 20.0)    # one GridConnection's |F|
    assert np.allclose(s["along_mean_abs"]["A2"], 100.0)
    assert np.allclose(s["link_mean_abs"]["C1"], (20 + 20 + 0 + 1) / 4)
    assert np.allclose(s["link_max_abs"]["A1"], 100.0)
    assert np.allclose(s["link_total_mean"]["A1"], (100 + 100 + 0 + 1) / 4)
    r = b.ratios(s, [x["displacement"] for x in run["rows"]])
    assert r["section_sum"]["C_over_A"] == pytest.approx(0.0)
    assert r["section_abs_sum"]["C_over_A"] == pytest.approx(0.2)
    assert r["section_edge_abs"]["C1_over_A1"] == pytest.approx(0.2)


@pytest.mark.skipif(shutil.which("yade") is None, reason="Yade is not installed")
def test_handover_to_yade_one_step():
    from dataclasses import replace

    from cpp_dem import apply_threads
    from geogrid_dem.cases import pullout_000 as case

    b = _bench()
    apply_threads(1)
    p = replace(case.Params(**case.SMOKE), seed=1)
    st = b.prepare_state(p, log=lambda s: None)
    # The case's grouping: A along x, C along y, three links in each mid-section.
    assert set(st["members"]) == {"A1", "C1", "A2", "C2"}
    for name, m in st["members"].items():
        assert len(m["section"]) == 3 and set(m["section"]) <= set(m["links"])
        assert m["axis"] == ([1.0, 0.0, 0.0] if name[0] == "A" else [0.0, 1.0, 0.0])
    ours = b.run_ours(st, velocity=p.velocity, steps=1, every=1, log=lambda s: None)
    yade = b.run_yade(st, velocity=p.velocity, steps=1, every=1, kinematics="matched",
                      log=lambda s: None)
    check = b.handover_check(ours["first"], yade["first"])
    assert check["free_spheres"] > 200
    assert check["max_force_diff_over_mean"] < 1e-9
    assert yade["rows"][0]["top_force"] == pytest.approx(ours["rows"][0]["top_force"],
                                                         rel=1e-9)
    sc, _, _ = b.twin_scene(st)
    assert np.allclose(yade["link_stiffness"], sc.grid_link_stiffness, rtol=1e-9)


def test_edge_probe_ours_and_yade():
    """One PFacet and a grain overlapping its dilated body by about 0.5 mm on the face, beside
    and above an edge, beside a corner: cpp_dem has one contact with k_n x overlap in each; where
    Yade (if installed) has a contact, its force is the same."""
    b = _bench()
    res = b.edge_probe("yade" if shutil.which("yade") else None)
    for name, v in res.items():
        assert v["ours"]["contacts"] == 1, name
        assert v["ours"]["force_N"] == pytest.approx(v["expected_N"], rel=1e-9), name
        if "yade" in v and v["yade"]["contacts"]:
            assert v["yade"]["force_N"] == pytest.approx(v["ours"]["force_N"], rel=1e-9), name
    if "yade" in res["face"]:
        assert res["face"]["yade"]["contacts"] == 1
