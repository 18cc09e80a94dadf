"""Statuses that tell the truth (issue 37): every coupled loop ends in one of converged,
stopped_at_scatter, stalled or failed, and converged only when every check held.

Mostly the status logic on synthetic inputs (femcoupling.coupling.status); a few cheap loops on the
FEM test body with stand-in elements (a few seconds each): the two-way loop's axes check for
a walled element, and the region mode's stall judged against the region's own forces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from femcoupling import FemInputError
from femcoupling.coupling.status import (EXIT_CODES, STATUSES, exit_code, judge_region, judge_steps,
                                         newton_acceptance, worst)

# a region that passes every check: a change within tol, axes near the walls, strains met
GOOD = dict(settled=True, final_change=0.005, tol=0.02, walled=True, axes_rotation_deg=3.0,
            dem_fem_strain_ratio=1.1, scatter=0.05)


def test_every_check_held_is_converged():
    st = judge_region(**GOOD)
    assert st.status == "converged" and st.converged
    assert st.checks == {"tolerance": True, "axes": True, "strain_ratio": True}
    assert "every check held" in st.reason
    d = st.as_dict()
    assert {k: d[k] for k in ("status", "final_change", "tol", "axes_rotation_deg",
                              "dem_fem_strain_ratio")} == {
        "status": "converged", "final_change": 0.005, "tol": 0.02, "axes_rotation_deg": 3.0,
        "dem_fem_strain_ratio": 1.1}


def test_a_walled_element_with_axes_past_the_limit_is_not_converged():
    """The two-way smoke had its axes turned 15.1-19.8 deg and said converged (issue 37)."""
    st = judge_region(**{**GOOD, "axes_rotation_deg": 15.1})
    assert st.status == "stalled" and not st.converged
    assert st.checks["axes"] is False
    assert "turned 15.1 deg from the walls (> 15" in st.reason
    # at the limit it holds; a periodic element takes the full tensor: the axes do not count
    assert judge_region(**{**GOOD, "axes_rotation_deg": 15.0}).status == "converged"
    full = judge_region(**{**GOOD, "axes_rotation_deg": 40.0, "walled": False})
    assert full.status == "converged" and full.checks["axes"] is None
    assert full.axes_rotation_deg == 40.0  # (reported all the same)
    # another limit
    assert judge_region(**{**GOOD, "axes_rotation_deg": 15.1},
                        max_rotation_deg=20.0).status == "converged"


def test_a_change_within_the_scatter_but_above_tol_is_stopped_at_scatter():
    """Three of the smoke's five 'converged' runs had stopped at changes of 2.8-5.1 % against
    a 2 % tolerance, within the elements' bootstrap scatter (issue 37)."""
    st = judge_region(**{**GOOD, "final_change": 0.028})
    assert st.status == "stopped_at_scatter" and not st.converged
    assert st.checks == {"tolerance": False, "axes": True, "strain_ratio": True}
    assert "above tol 0.02, within the scatter" in st.reason
    assert "not convergence" in st.reason


@pytest.mark.parametrize("ratio", [2.01, 0.49, 67.0, math.inf, math.nan])
def test_a_strain_ratio_outside_a_factor_two_is_not_converged(ratio):
    st = judge_region(**{**GOOD, "dem_fem_strain_ratio": ratio})
    assert st.status == "stalled" and st.checks["strain_ratio"] is False
    assert ("the scales have not met" in st.reason) or ("unknown" in st.reason)
    # the bounds themselves hold
    for q in (0.5, 2.0):
        assert judge_region(**{**GOOD, "dem_fem_strain_ratio": q}).status == "converged"


def test_checks_that_fail_with_a_change_within_the_scatter_are_stalled_not_at_scatter():
    st = judge_region(**{**GOOD, "final_change": 0.03, "axes_rotation_deg": 18.0,
                         "dem_fem_strain_ratio": 3.0})
    assert st.status == "stalled"
    assert "turned 18.0 deg" in st.reason and "strains 3 times" in st.reason


def test_a_loop_that_did_not_settle_failed():
    st = judge_region(**{**GOOD, "settled": False, "final_change": 0.3}, iterations=8)
    assert st.status == "failed"
    assert "not settled after 8 FEM solves" in st.reason
    # even if its last change happened to be small, unsettled is unsettled
    assert judge_region(**{**GOOD, "settled": False}).status == "failed"


def test_worst_and_exit_codes():
    assert STATUSES == ("converged", "stopped_at_scatter", "stalled", "failed")
    assert worst([]) == "converged"
    assert worst(["converged", "stopped_at_scatter"]) == "stopped_at_scatter"
    assert worst(["stalled", "stopped_at_scatter", "converged"]) == "stalled"
    assert worst(["failed", "stalled"]) == "failed"
    assert [exit_code(s) for s in STATUSES] == [0, 3, 4, 5]
    # none of the codes the runs already use (1 error, 2 arguments, 130/143 interrupted)
    assert not set(EXIT_CODES.values()) & {1, 2, 130, 143}


def test_bad_input_names_the_field():
    with pytest.raises(FemInputError, match=r"status='done': must be one of"):
        worst(["converged", "done"])
    with pytest.raises(FemInputError, match=r"tol=0: must be > 0"):
        judge_region(**{**GOOD, "tol": 0})
    with pytest.raises(FemInputError, match=r"max_strain_ratio=1.0: must be > 1"):
        judge_region(**GOOD, max_strain_ratio=1.0)
    with pytest.raises(FemInputError, match=r"max_rotation_deg=-1: must be > 0"):
        judge_region(**GOOD, max_rotation_deg=-1)


def test_hierarchical_noise_above_the_ceiling_is_not_accepted():
    """Issue 37: near the peak the noise was 2.6e-3 and a step was accepted at 1.5e-3 with
    rtol 1e-3. Within the noise it is stopped_at_scatter below the ceiling (10 x rtol), and
    not acceptable above it (the step is cut: test_hierarchical)."""
    kw = dict(rtol=1e-3, noise_factor=2.0, ceiling=1e-2)
    assert newton_acceptance(8e-4, noise_residual=2.6e-3, **kw) == "converged"
    assert newton_acceptance(1.5e-3, noise_residual=2.6e-3, **kw) == "stopped_at_scatter"
    assert newton_acceptance(1.5e-2, noise_residual=2e-2, **kw) is None  # above the ceiling
    assert newton_acceptance(6e-3, noise_residual=2e-3, **kw) is None  # beyond the noise
    assert newton_acceptance(1.5e-3, **kw) is None  # no noise measured
    # the ceiling is inclusive, as the tolerance is
    assert newton_acceptance(1e-2, noise_residual=1e-2, **kw) == "stopped_at_scatter"


class _Step:
    def __init__(self, status, residual, tol):
        self.status, self.residual, self.tol = status, residual, tol


def test_region_newton_steps():
    ok = [_Step("converged", 1e-7, 1e-6), _Step("converged", 5e-7, 1e-6)]
    st = judge_steps(ok, dem_fem_strain_ratio=1.0, axes_rotation_deg=30.0)
    assert st.status == "converged" and st.checks["axes"] is None
    assert (st.final_change, st.tol) == (5e-7, 1e-6)
    stall = ok + [_Step("stalled", 2e-3, 3e-7)]
    st = judge_steps(stall, dem_fem_strain_ratio=1.0)
    assert st.status == "stalled" and st.final_change == 2e-3 and st.tol == 3e-7
    assert "1 of 3 load steps taken at a stall" in st.reason
    st = judge_steps(ok, dem_fem_strain_ratio=3.0)
    assert st.status == "stalled" and st.checks["strain_ratio"] is False
    assert judge_steps([], dem_fem_strain_ratio=1.0).status == "failed"
    # a step within the elements' noise above its tolerance: stopped_at_scatter, unless a
    # check of the coupled state fails (then stalled)
    scat = ok + [_Step("stopped_at_scatter", 1e-3, 1e-6)]
    st = judge_steps(scat, dem_fem_strain_ratio=1.0)
    assert st.status == "stopped_at_scatter" and st.checks["tolerance"] is False
    assert st.final_change == 1e-3 and st.failures == ()
    assert judge_steps(scat, dem_fem_strain_ratio=3.0).status == "stalled"
    with pytest.raises(FemInputError, match=r"steps\[0\].status='failed'"):
        judge_steps([_Step("failed", 1e-3, 1e-6)])


# ---- the loops themselves, with stand-in elements on the FEM test body ---------------------


class _Elastic:
    """A linear elastic stand-in (10 MPa, 0.25), walled (three normal stresses) unless it
    says it takes the full tensor (as a periodic element does)."""

    def __init__(self, full_tensor: bool):
        self.full = full_tensor

    def __call__(self, name, initial, final):
        from femcoupling.coupling.twoway import ElementResponse

        ds = final.normal_pa - initial.normal_pa
        return ElementResponse(stress_initial_pa=initial.normal_pa,
                               stress_final_pa=final.normal_pa,
                               strain_increment=(ds - 0.25 * (ds.sum() - ds)) / 10e6,
                               info={"full_tensor": True} if self.full else {})


def test_two_way_a_walled_element_past_the_axes_limit_is_not_converged():
    """Region b of the test body (off the footing's edge) has its principal axes turned
    about 30 deg. The loop settles either way (to round-off, with the element's own
    stiffness); with a walled element it is stalled (before issue 37: converged, with a
    warning), with one that takes the full tensor it converges."""
    from test_fem_handover import _footing, two_region_model

    from femcoupling.coupling.twoway import two_way

    runs = {full: two_way(two_region_model(("b",)), regions=["b"], load=_footing,
                          element_runner=_Elastic(full), tol=1e-3, max_iterations=6)
            for full in (False, True)}
    walled, periodic = runs[False], runs[True]
    assert walled.changes[-1] < 1e-3 and periodic.changes[-1] < 1e-3
    assert walled.status == "stalled" and not walled.converged
    st = walled.regions["b"]
    assert st.checks == {"tolerance": True, "axes": False, "strain_ratio": True}
    assert st.axes_rotation_deg > 15 and "from the walls" in walled.reason
    assert walled.converged_on == "stalled"  # (the older name)
    assert any("stopped, NOT converged (stalled)" in w for w in walled.warnings)
    assert periodic.status == "converged" and periodic.regions["b"].checks["axes"] is None


def _rough_stand_in(amp_pa: float):
    """A linear region element (C_TRUE: test_fem_region_element.LinearStandIn) whose answer
    is off by a seeded random amount of standard deviation ``amp_pa`` (xx and zz), drawn
    anew at every call, as a DEM element is rough at the scale of Newton's last corrections:
    Newton's residual stalls at a level set by ``amp_pa``, and the noise probe (a second call
    on nearly the same increment) measures a noise of that size. (A roughness that only
    alternated in sign from call to call would be undone by the probe's own call.)"""
    from test_fem_region_element import LinearStandIn

    class RoughStandIn(LinearStandIn):
        def __init__(self):
            super().__init__()
            self.amp, self.rng = amp_pa, np.random.default_rng(7)

        def trial(self, de):
            s, c = super().trial(de)
            return s + self.amp * self.rng.standard_normal() * np.diag([1.0, 0.0, 1.0]), c

    return RoughStandIn()


def _rough_model(amp_pa: float):
    from test_fem_handover import two_region_model

    m = two_region_model(("a",))
    m.set_region_element("a", _rough_stand_in(amp_pa))
    m.max_cuts, m.max_newton = 0, 8
    return m


def test_a_step_cut_at_the_ceiling_names_the_element_that_moved_most():
    """Two region elements, a rough one (2000 Pa, ``_rough_stand_in``) and a smooth one
    (the same stand-in without roughness): the message of the step cut above the ceiling
    names the rough one first, with how far its points moved at the probe (Pa)."""
    import re

    from femcoupling.fem.steps import NewtonFailure
    from test_fem_handover import two_region_model

    m = two_region_model(("a", "b"))
    m.set_region_element("a", _rough_stand_in(0.0))
    m.set_region_element("b", _rough_stand_in(2000.0))
    m.max_cuts, m.max_newton = 0, 8
    with pytest.raises(NewtonFailure):
        m.load_footing(pressure_pa=20e3, steps=1)
    got = re.search(r"the elements that moved most at the probe: b ([0-9.e+-]+) Pa, "
                    r"a ([0-9.e+-]+) Pa", m.last_failure)
    assert got, m.last_failure
    assert float(got[1]) > 100 * max(float(got[2]), 1e-12)  # (a's: its tangent's own)


def test_region_mode_stall_is_judged_against_the_regions_own_forces():
    """Region a (0.2 m) of the 4 x 3 m test body under a 20 kPa footing, its material a rough
    stand-in. The region's own internal force is about 29 times smaller than the body's
    (measured). Newton stalls, measures the stand-in's noise and compares on the region's own
    force. A roughness of 2000 Pa stalls within the noise at 9.6e-4 of the body's force scale
    (a rule on the body's scale would take it), which is 2.6e-2 of the region's own force,
    above the ceiling (noise_ceiling, 1e-2): the step is not taken. 30 Pa stalls at 4.1e-4 of
    the region's force: taken, as stopped_at_scatter (not converged), its residual in Pa
    too."""
    from femcoupling.fem.steps import NewtonFailure

    m = _rough_model(2000.0)
    assert m.noise_ceiling == 1e-2
    with pytest.raises(NewtonFailure, match="Newton failed"):
        m.load_footing(pressure_pa=20e3, steps=1)
    assert "within the elements' noise" in m.last_failure and "above the ceiling" in \
        m.last_failure
    m = _rough_model(30.0)
    (r,) = m.load_footing(pressure_pa=20e3, steps=1)
    assert r.status == "stopped_at_scatter" and r.converged_on == "noise"
    assert r.tol < r.residual <= m.noise_ceiling  # judged on the region's scale
    assert r.noise_residual > 0  # the measured noise (on the body's scale)
    assert r.residual_pa == pytest.approx(r.residual * m._largest_stress(m._region_points()),
                                          rel=1e-12)
    assert 1 < r.residual_pa < 1e3  # Pa
    assert len(m.warnings) == 1 and "stopped_at_scatter, not converged" in m.warnings[0]