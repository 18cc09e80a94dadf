"""cases/prs_element.py's coupled modes at smoke size: two-way (the walls element with its
probed tangent, the periodic loop element) and hierarchical (one region element, an element
per cell). Each ends in the status its checks give. (A file of its own so that the suite's
two processes share the case's tests.)"""

from __future__ import annotations

import json

import numpy as np

from test_case_prs_element import _xdmf_times, run_case


def _coupling_status_said(out, proc, key: str) -> dict:
    """The summary's statuses of a coupled run (issue 37): per variant its status with its
    checks (converged only when every check held), the worst of them in ``coupling``, in the
    report and the log, and the exit status that says it (non-zero with one line on stderr
    when not converged; the results written all the same). Returns the summary."""
    from femcoupling.coupling.status import STATUSES, exit_code, worst

    s = json.loads((out / "summary.json").read_text())
    report = (out / "report.md").read_text()
    for v in ("RE", "PRS"):
        t = s[key][v]
        assert t["status"] in STATUSES and t["reason"], t
        assert {"final_change", "tol", "axes_rotation_deg", "dem_fem_strain_ratio"} <= set(t)
        held = [c for c in t["checks"].values() if c is not None]
        assert (t["status"] == "converged") == all(held), t
        if t["status"] == "converged":
            assert t["final_change"] <= t["tol"] and 0.5 <= t["dem_fem_strain_ratio"] <= 2
        assert f"**{t['status']}**" in report
    c = s["coupling"]
    assert c["status"] == worst(s[key][v]["status"] for v in ("RE", "PRS"))
    assert proc.returncode == c["exit_code"] == exit_code(c["status"]), proc.stderr[-3000:]
    assert f"coupling: {c['status']}" in proc.stdout
    if c["status"] != "converged":
        assert "coupling did not converge" in proc.stderr
        assert f"(exit status {c['exit_code']}" in proc.stderr
    assert (out / "report.md").is_file() and "## Coupling status" in report
    return s


def _two_way_gave_full_stiffnesses(out, element: str) -> dict:
    """The two-way summary of both variants: the loop's element, a symmetric positive
    definite 6 x 6 stiffness given, in the summary and in handover.h5. Returns the
    summary."""
    import h5py

    s = json.loads((out / "summary.json").read_text())
    for v in ("RE", "PRS"):
        t = s["two_way"][v]
        assert t["element"] == element, t
        if t["status"] == "stalled":  # (settled, a check failed: said)
            assert any("stopped, NOT converged (stalled)" in w for w in t["warnings"])
        c = np.array(t["stiffness_mandel_pa"])
        assert c.shape == (6, 6) and np.allclose(c, c.T, rtol=0, atol=1e-9 * np.abs(c).max())
        assert np.linalg.eigvalsh(c).min() > 0
    with h5py.File(out / "handover.h5") as f:
        rows = f["stiffness_mandel_pa"][:]
        regions = f["region"][:]
    for j in (0, 1):  # element_RE, element_PRS: full stiffnesses given
        assert any(np.all(np.isfinite(r)) for r in rows[regions == j])
    return s


def test_two_way_with_the_walls_element_gives_the_region_its_probed_tangent(tmp_path):
    """--two-way (the case's own element; issue 18: its tangent in place of the isotropic
    secant): each iteration probes the element at its final state (three 5 % stress probes)
    and the region gets that tangent made to reproduce the increment, a full stiffness.
    Smoke, seeds 1-3: both variants settle in 4-8 FEM solves and the case's element then
    strains 0.90-1.00 times its region; each ends in the status its checks give (issue 37:
    the principal axes turned past the walls' 15 deg, a stop at the scatter)."""
    out = tmp_path / "tw"
    p = run_case(out, "--smoke", "--two-way", "--workers", "2",  # RE and PRS side by side
                 "--soil", "given")
    assert p.returncode in (0, 3, 4, 5), p.stdout[-3000:] + p.stderr[-3000:]
    assert "tangent by three 5 % stress probes" in p.stdout
    _coupling_status_said(out, p, "two_way")
    s = _two_way_gave_full_stiffnesses(out, "walls")
    for v in ("RE", "PRS"):
        assert s["two_way"][v]["checks"]["axes"] is not None  # (walls: the axes count)
        if s["two_way"][v]["status"] == "converged":  # the element strains as its region
            assert s["elements"][v]["dem_fem_strain_ratio"] < 2.0
        # the last (coupled) iteration's load steps
        assert _xdmf_times(out / f"fem_{v}.xdmf") == [0.0, 1 / 3, 2 / 3, 1.0]


def test_two_way_with_the_periodic_element_gives_the_region_its_tangent(tmp_path):
    """--two-way-element periodic (issue 18): the loop iterates with a dense periodic element
    of the case's grains (the full FEM tensor; its tangent back as the region's full
    stiffness), then drives the case's element to the converged targets. Smoke (measured):
    RE's stresses settle in 6 FEM solves while its element strains 2.7 times the region, a
    stall, which the loop says (not converged); PRS settles in 5."""
    out = tmp_path / "pe"
    p = run_case(out, "--smoke", "--two-way", "--two-way-element", "periodic", "--workers", "2",
                 "--soil", "given")
    assert p.returncode in (0, 3, 4, 5), p.stdout[-3000:] + p.stderr[-3000:]
    assert "two-way element: periodic" in p.stdout
    _coupling_status_said(out, p, "two_way")
    s = _two_way_gave_full_stiffnesses(out, "periodic")
    for v in ("RE", "PRS"):
        assert s["two_way"][v]["checks"]["axes"] is None  # (the full tensor: not checked)
        assert s["elements"][v]["strain_increment"]  # the case's element ran after the loop
        # both porosities reported: the dense loop element's and the case's element's
        assert 0.3 < s["two_way"][v]["porosity_loop_element"] < s["elements"][v]["porosity_final"]
    report = (out / "report.md").read_text()
    assert "with the periodic element (porosity" in report


def test_hierarchical_region_element_strains_as_its_region(tmp_path):
    """--hierarchical (issue 18, the hierarchical mode on the reinforced-soil body): the
    region's material is a dense periodic element of the case's grains inside the FEM's
    Newton. Its strain increment is the region's (measured to 0.2 %), every load step
    is taken (Newton stalls at the element's resolution, a few 1e-3 of the region's own
    internal force, and says so: stalled, not converged), and the case's element is then
    driven to the coupled targets. Run with --workers 2 (RE and PRS side by side)."""
    import h5py

    out = tmp_path / "h"
    p = run_case(out, "--smoke", "--hierarchical", "--workers", "2", "--soil", "given")
    assert p.returncode in (0, 3, 4), p.stdout[-3000:] + p.stderr[-3000:]
    s = _coupling_status_said(out, p, "hierarchical")
    assert s["mode"] == "FEM -> DEM (hierarchical)"
    for v in ("RE", "PRS"):
        h = s["hierarchical"][v]
        fem = np.array(s["fem"][v]["strain_increment"])
        np.testing.assert_allclose(h["element_strain_increment"], fem, rtol=0,
                                   atol=0.01 * np.abs(fem).max())
        assert len(h["newton_iterations"]) == 3 and max(h["newton_iterations"]) <= 25
        assert len(h["warnings"]) == h["converged_on"].count("noise")
        assert h["step_statuses"].count("stopped_at_scatter") == h["converged_on"].count("noise")
        # (the strain ratio and the axes hold: a step within the noise is stopped_at_scatter)
        assert (h["status"] == "stopped_at_scatter") == ("stopped_at_scatter"
                                                        in h["step_statuses"])
        assert h["checks"]["axes"] is None and 0.9 < h["dem_fem_strain_ratio"] < 1.1
        assert all(r <= 1e-2 for r in h["step_residuals"])  # (noise_ceiling, the region's)
        assert s["fem"][v]["state"] == "hierarchical"
        assert _xdmf_times(out / f"fem_{v}.xdmf") == [0.0, 1 / 3, 2 / 3, 1.0]  # coupled steps
        with h5py.File(out / f"region_element_{v}.h5") as f:  # a row per committed step
            assert f["step"][:].tolist() == [1, 2, 3]
            np.testing.assert_allclose(-np.diag(f["strain"][-1]),
                                       h["element_strain_increment"], rtol=1e-12)
        assert s["elements"][v]["strain_increment"]  # the case's element ran after it
    assert "## Hierarchical" in (out / "report.md").read_text()


def test_hierarchical_cell_elements_strain_as_their_cells(tmp_path):
    """--hierarchical --cell-elements: every cell of the element region its own dense
    periodic element (60 grains, its own seed, prepared at its cell's stress) on 2 Dask
    workers. The cells strain differently, their volume mean is the region's strain
    increment (each element strains as its cell), every cell's element has a records row per
    load step, and the case's element runs after them."""
    import h5py

    out = tmp_path / "c"
    p = run_case(out, "--smoke", "--hierarchical", "--cell-elements", "--cell-grains", "60",
                 "--workers", "2", "--soil", "given")
    assert p.returncode in (0, 3, 4), p.stdout[-3000:] + p.stderr[-3000:]
    s = _coupling_status_said(out, p, "hierarchical")
    for v in ("RE", "PRS"):
        h = s["hierarchical"][v]
        n = h["cells"]
        assert n > 4 and h["cell_grains"] == 60
        ez = np.array(h["cell_strain_increments"])[:, 2]
        assert len(ez) == n and ez.min() > 0 and ez.max() > 1.2 * ez.min()  # a field, not one
        fem = np.array(s["fem"][v]["strain_increment"])
        np.testing.assert_allclose(h["element_strain_increment"], fem, rtol=0,
                                   atol=1e-9 * np.abs(fem).max())  # (measured 2e-16)
        k = len(h["newton_iterations"])
        assert k >= 3  # three load steps; more where Newton's rules cut one
        assert len(h["warnings"]) == h["converged_on"].count("noise")
        with h5py.File(out / f"region_element_{v}.h5") as f:
            assert sorted(f["step"][:].tolist()) == sorted(list(range(1, k + 1)) * n)
            assert len(f.attrs["names"]) == n
        assert s["elements"][v]["strain_increment"]
    assert "per cell of the region" in (out / "report.md").read_text()
