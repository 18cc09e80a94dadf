"""A strip footing by hierarchical FEM x DEM (geogrid_dem.studies.footing_dem; the model's
platens="footing"): it starts at the surcharge, its pressure is its reaction (the body is in
equilibrium with it: footing plus surcharge equal the bottom's reaction), it stiffens as it
settles, and bad input is refused by name."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dolfinx_solver")

from cpp_dem.elements.pool import ElementPool  # noqa: E402
from cpp_dem.protocols.footing import StripFootingBox  # noqa: E402
from femcoupling import FemInputError  # noqa: E402
from geogrid_dem.studies.footing_dem import (element_factory, fem_dem_footing,  # noqa: E402
                                             paired_pressures)

Q = 20e3
BOX = StripFootingBox(footing_b=0.02, length=0.08, depth=0.04, thickness=0.03,
                      surcharge_pa=Q)
SETTLEMENTS = (2e-5, 5e-5, 1e-4)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("footing")
    with ElementPool.build(16, element_factory(BOX, grains=60, seed=1), workers=2) as pool:
        res = fem_dem_footing(pool, length=BOX.length, depth=BOX.depth, nx=4, ny=2,
                              footing_b=BOX.footing_b, surcharge_pa=Q,
                              settlements_m=SETTLEMENTS, out=out, log=None)
        yield res, out


def _bottom_and_top_reactions(m):
    """The vertical reactions (N/m) of the bottom and of the whole top (the footing's dofs and
    the surcharge's load) from the residual's assembly at the model's state."""
    fx = m._fx
    vec = fx.fem.assemble_vector(m._form_reaction)
    vec.scatter_reverse(fx.dolfinx.la.InsertMode.add)
    f_int = fx.fem.assemble_vector(fx.fem.form(m.system.f_int))
    f_int.scatter_reverse(fx.dolfinx.la.InsertMode.add)

    def dofs(where):
        facets = fx.mesh.locate_entities_boundary(m.mesh, 1, where)
        return fx.fem.locate_dofs_topological(m.V.sub(1), 1, facets)

    bottom = float(np.sum(vec.array[dofs(lambda x: np.isclose(x[1], 0.0))]))
    top = float(np.sum(f_int.array[dofs(lambda x: np.isclose(x[1], m.body.ly))]))
    return bottom, top


def test_the_footing_starts_at_the_surcharge_and_stiffens(run):
    res, _ = run
    p = res["footing_pressure_pa"]
    assert res["failed"] is None and len(p) == 1 + len(SETTLEMENTS)
    # the elements are servoed to the isotropic q within their tolerance (0.5 %); the
    # reaction of a uniform -q I is q b exactly (measured: 20000.001 Pa)
    assert p[0] == pytest.approx(Q, rel=5e-3)
    assert np.all(np.diff(p) > 0) and p[-1] > 2 * Q
    m = res["model"]
    assert m.footing_settlement_m() == SETTLEMENTS[-1] and m.footing_pressure_pa() == p[-1]
    # the one step record carries the footing's measures (the soil body's names), step by step
    accepted = [r for r in m.history if r.load_factor == 1.0]
    assert [r.footing_pressure_pa for r in accepted][-len(SETTLEMENTS):] == list(p[1:])
    assert [r.footing_settlement_m for r in accepted][-len(SETTLEMENTS):] == list(SETTLEMENTS)
    assert set(res["status"][1:]) <= {"converged", "stopped_at_scatter"}


def test_the_footing_and_the_surcharge_are_the_bottoms_reaction(run):
    res, _ = run
    m = res["model"]
    bottom, top = _bottom_and_top_reactions(m)
    footing = res["footing_pressure_pa"][-1] * BOX.footing_b
    surcharge = Q * (BOX.length - BOX.footing_b)
    # the top's internal force is the footing's reaction plus the surcharge; the body in
    # equilibrium (to Newton's tolerance, 1e-3 of the force scale) carries it to the bottom
    assert -top == pytest.approx(footing + surcharge, rel=2e-3)
    assert bottom == pytest.approx(footing + surcharge, rel=2e-3)


def test_the_records_are_a_row_per_settlement(run):
    res, out = run
    rows = (out / "footing_fem_dem.csv").read_text().splitlines()
    assert rows[0] == "settlement_m,footing_pressure_pa,status,iterations,wall_s"
    assert len(rows) == 2 + len(SETTLEMENTS)
    assert float(rows[-1].split(",")[1]) == res["footing_pressure_pa"][-1]
    assert (out / "records" / "elements.h5").exists()


def test_paired_pressures_pairs_by_seed_and_refuses_mismatches():
    s = np.array([0.0, 1e-4, 2e-4])
    a = [{"settlement_m": s, "footing_pressure_pa": np.array([20e3, 50e3, 70e3]) + k}
         for k in (0.0, 2e3)]
    b = [{"settlement_m": s[:2], "footing_pressure_pa": np.array([20e3, 40e3]) + k}
         for k in (0.0, 1e3)]
    d = paired_pressures(a, b)
    assert d["seeds"] == 2 and len(d["settlement_m"]) == 2  # (what both reached)
    assert d["difference_pa"][1] == pytest.approx(10.5e3)
    assert d["se_pa"][1] == pytest.approx(500.0)
    with pytest.raises(ValueError, match="one of each per seed"):
        paired_pressures(a, b[:1])
    with pytest.raises(ValueError, match="settlements differ"):
        paired_pressures(a, [{**b[0], "settlement_m": s[:2] * 2}, b[1]])


def test_bad_footing_input_is_refused_by_name():
    from femcoupling.fem.bodies import Rectangle

    kw = dict(lx=0.08, ly=0.04, nx=4, ny=2, confining_pa=Q, platens="footing")
    with pytest.raises(FemInputError, match="footing_b=0.03: must end on a mesh line"):
        Rectangle(footing_b=0.03, **kw)
    with pytest.raises(FemInputError, match="footing_b=0.08: the footing's half width"):
        Rectangle(footing_b=0.08, **kw)
    with pytest.raises(FemInputError, match="footing_b=0.02: only with platens='footing'"):
        Rectangle(**{**kw, "platens": "smooth"}, footing_b=0.02)
    with pytest.raises(FemInputError, match="needs confining_pa"):
        Rectangle(**{**kw, "confining_pa": None}, footing_b=0.02)
    with pytest.raises(ValueError, match="settlements_m=.*increasing"):
        fem_dem_footing(None, length=0.08, depth=0.04, nx=4, ny=2, footing_b=0.02,
                        surcharge_pa=Q, settlements_m=(2e-5, 1e-5))


def test_a_footing_model_refuses_a_side_displacement(run):
    res, _ = run
    with pytest.raises(FemInputError, match="right_displacement=1e-06"):
        res["model"].step(top_displacement=-1e-4, right_displacement=1e-6)


def _bench():
    import importlib.util
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "bench"))
    spec = importlib.util.spec_from_file_location("footing_direct_dem",
                                                  root / "bench" / "footing_direct_dem.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_interior_porosity_of_a_simple_cubic_lattice():
    from types import SimpleNamespace

    r, n = 1e-3, 6
    g = (np.arange(n) + 0.5) * 2 * r
    pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    edge = 2 * r * n
    scene = SimpleNamespace(wall_positions=np.array([0, edge, 0, edge, 0, edge]),
                            positions=pos, radii=np.full(len(pos), r))
    state = SimpleNamespace(scene=scene, walls=list(range(6)), grain_ids=np.arange(len(pos)))
    est = _bench()._interior_porosity(state, 2 * r, r / 6)
    assert est == pytest.approx(1 - np.pi / 6, abs=0.01)  # 0.476
    scene.radii = np.full(len(pos), 0.5 * r)  # (the same centres, an eighth of the solid)
    assert _bench()._interior_porosity(state, 2 * r, r / 12) == pytest.approx(
        1 - np.pi / 48, abs=0.01)  # (a sphere 6 grid spacings across, as in the bench)
    # Periodic along y (--periodic-y): the four walls x-, x+, z-, z+ and the cell's y extent.
    scene.radii = np.full(len(pos), r)
    scene.wall_positions, scene.cell_matrix = np.array([0, edge, 0, edge]), np.eye(3) * edge
    state.walls = list(range(4))
    assert _bench()._interior_porosity(state, 2 * r, r / 6) == pytest.approx(est, abs=1e-12)


def test_the_bench_takes_a_periodic_box_and_refuses_the_oedometer_on_it_alone(capsys):
    bench = _bench()
    assert bench.parse(["--smoke", "--out-of-plane", "both"]).out_of_plane == "both"
    assert bench.parse(["--smoke"]).out_of_plane == "walls"
    assert [p for _, p in bench.BOXES["both"]] == [False, True]
    with pytest.raises(SystemExit):
        bench.parse(["--smoke", "--out-of-plane", "periodic", "--oedometer"])
    assert "--oedometer with --out-of-plane periodic" in capsys.readouterr().err
    assert bench.parse(["--smoke", "--out-of-plane", "both", "--oedometer"]).oedometer
    # the periodic box's first growth at a small friction (looser: the elements' porosity)
    assert bench.parse(["--smoke", "--out-of-plane", "both", "--periodic-prep-friction",
                        "1"]).periodic_prep_friction == 1.0
    assert bench.parse(["--smoke"]).periodic_prep_friction == 0.0
    for args, msg in ((["--periodic-prep-friction", "1"], "needs --out-of-plane periodic"),
                      (["--out-of-plane", "both", "--periodic-prep-friction", "40"],
                       "--periodic-prep-friction=40.0: must be >= 0 and below the grains' "
                       "friction angle, 38.66 deg")):
        with pytest.raises(SystemExit):
            bench.parse(["--smoke", *args])
        assert msg in capsys.readouterr().err


def test_the_bench_runs_at_smoke_size(tmp_path, capsys, monkeypatch):
    import json

    import geogrid_dem.studies.footing_dem as fdm

    bench = _bench()
    given = []  # the boxes the elements are made from
    real = fdm.element_factory
    monkeypatch.setattr(fdm, "element_factory", lambda box, **kw: given.append(box) or
                        real(box, **kw))
    summary = bench.main(["--smoke", "--oedometer", "--out-of-plane", "both",
                          "--periodic-prep-friction", "1", "--out", str(tmp_path)])
    # the elements (and the oedometer) take the walled box's frictionless growth, whatever
    # the periodic box's
    assert [(b.periodic_y, b.prep_friction_deg) for b in given] == [(False, 0.0)]
    row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert row["seeds"] == 1 and row["settlement_m"] == pytest.approx(0.2e-3)
    run = summary["runs"]["1"]
    assert run["dem"]["footing_pressure_pa"][-1] > run["dem"]["footing_pressure_pa"][0]
    assert run["fem_dem"]["footing_pressure_pa"][0] == pytest.approx(20e3, rel=5e-3)
    assert run["fem_dem"]["elements"] == 24 and run["fem_dem"]["failed"] is None
    # the same grains: the elements' radii are the box's, their porosity its inside's
    assert run["fem_dem"]["radius_mean_m"] == pytest.approx(run["dem"]["radius_mean_m"],
                                                            rel=0.06)
    assert abs(run["fem_dem"]["element_porosity_mean"] - run["dem"]["interior_porosity"]) < 0.03
    o = run["oedometer"]  # (the same path for both: their constrained moduli, > 0)
    assert len(o["box_pa"]) == len(o["elements_pa"]) == len(bench.OEDOMETER_STRAINS)
    assert min(o["box_pa"]) > 0 and min(o["elements_pa"]) > 0
    assert np.isnan(summary["oedometer_ratio"]["se"][0])  # (one seed: no standard error)
    for f in ("footing_direct_dem.json", "load_settlement.csv", "load_settlement.png",
              "dem_seed1/footing_dem.csv", "fem_dem_seed1/footing_fem_dem.csv"):
        assert (tmp_path / f).is_file(), f
    # --out-of-plane both: each seed's periodic box from the same grains, FEM x DEM paired
    # with each box, and the periodic box with the walled one
    assert summary["direct_dem"] == ["dem", "dem_periodic"]
    assert summary["periodic_prep_friction_deg"] == 1.0
    per = run["dem_periodic"]
    assert per["grains"] == run["dem"]["grains"]
    assert per["porosity"] < run["dem"]["porosity"]  # (no y walls' loose layers)
    pw = summary["periodic_minus_walls"]
    assert pw["fem_dem_pa"] == pytest.approx(per["footing_pressure_pa"])
    assert pw["dem_pa"] == pytest.approx(run["dem"]["footing_pressure_pa"])
    assert summary["paired_periodic"]["dem_pa"] == pw["fem_dem_pa"]
    assert (tmp_path / "dem_periodic_seed1" / "footing_dem.csv").is_file()
    rows = (tmp_path / "load_settlement.csv").read_text().splitlines()
    assert sum(r.startswith("dem_periodic,") for r in rows) == len(per["settlement_m"])
    with pytest.raises(SystemExit, match="holds an earlier run"):
        bench.main(["--smoke", "--out", str(tmp_path)])
