"""The load stages of :class:`femcoupling.fem.model.FemModel`: the K0 initial state, the
prestress of the geogrid layers, and the footing (a pressure, a settlement, or a rigid
footing pushed to a pressure). A part of ``FemModel`` for the soil body: each stage runs its equilibrium
steps through ``FemModel._run_stage``."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from femcoupling._checks import FemInputError
from femcoupling.fem import geometry as geo
from femcoupling.fem.solver import SOIL_ONLY, body_kind
from femcoupling.fem.steps import LoadStep, NewtonFailure
from femcoupling.materials.continuum import DruckerPrager, mandel_identity

SQRT2 = math.sqrt(2.0)


@body_kind("soil", SOIL_ONLY)
class LoadingStages:
    """See the module doc."""

    def set_geostatic(self, *, k0: float | None = None) -> None:
        """K0 initial state from the self-weight (tension positive, see the module doc).

        ``k0`` (-, > 0) defaults to the soil's: 1 - sin(phi) for Drucker–Prager, nu / (1 - nu)
        for an elastic soil. The state is in equilibrium with the body force; a check solve is
        run (it converges in 0 or 1 iterations where the state lies inside every point's
        yield surface). A ``k0`` given is refused (FemInputError, before any state is set)
        where the K0 state lies outside the yield surface of a point's Drucker–Prager
        material: the message gives the points and the range of k0 the soil holds at the
        body's base. (The default of a cohesionless Drucker–Prager soil with phi above 35.9
        deg, Jaky's 1 - sin(phi), lies outside the plane-strain cone at every point: the check
        solve returns every point onto it, ``LoadStep.plastic_points``.)
        """
        given = k0 is not None
        k0 = self.soil.k0() if k0 is None else geo._pos("k0", k0)
        fx = self._fx
        x = fx.fem.Expression(fx.ufl.SpatialCoordinate(self.mesh), self.qpoints)
        xq = x.eval(self.mesh, np.arange(self.n_cells, dtype=np.int32)).reshape(-1, self.tdim)
        sv = -self.unit_weight_n_m3 * (self.body.height_m - xq[:, self.zc])
        sig = np.zeros((len(sv), self.ncomp))
        sig[:, :3] = k0 * sv[:, None]
        sig[:, self.zc] = sv
        if given:
            self._check_k0(k0, sig)
        self.sig_n = sig
        self._ext_scale = self.unit_weight_n_m3 * self.body.height_m * self.footing_area
        self._run_stage("geostatic", lambda lf: None, 1)

    def _check_k0(self, k0: float, sig: np.ndarray) -> None:
        """Refuses a given ``k0`` whose K0 state ``sig`` ((cell, q), Mandel, Pa) lies outside
        the Drucker–Prager yield surface (f = 3 alpha p + sqrt(J2) - k > 0, as
        ``drucker_prager_return`` judges it) at any point of a continuum material (the
        points of DEM region elements are not judged). Collective."""
        own = self.n_owned * self.nq
        al, kk = np.zeros(own), np.full(own, np.inf)
        tags = np.repeat(self.cell_tag_of, self.nq)[:own]
        for tag in np.unique(tags):
            a, _, k = self.material_of_tag(int(tag)).dp_parameters()
            al[tags == tag], kk[tags == tag] = a, k
        s = sig[:own]
        p = s[:, :3].sum(1) / 3.0
        sqrt_j2 = np.linalg.norm(s - p[:, None] * mandel_identity(self.ncomp), axis=1) / SQRT2
        with np.errstate(invalid="ignore"):
            f = 3.0 * al * p + sqrt_j2 - kk
        out = np.isfinite(kk) & (f > 0.0) & ~self._region_points()[:own]
        MPI = self._fx.MPI
        n_out, n_all = (int(self.comm.allreduce(int(v), op=MPI.SUM))
                        for v in (np.count_nonzero(out), own))
        if n_out == 0:
            return
        held = ""
        depth_pa = self.unit_weight_n_m3 * self.body.height_m
        if isinstance(self.soil, DruckerPrager) and depth_pa > 0:
            a, _, k = self.soil.dp_parameters()
            r3, c = 1.0 / math.sqrt(3.0), k / depth_pa
            lo, hi = max(0.0, (r3 - a - c) / (r3 + 2.0 * a)), (r3 + a + c) / (r3 - 2.0 * a)
            held = (f"; the soil (friction_deg={self.soil.friction_deg!r}, cohesion_pa="
                    f"{self.soil.cohesion_pa!r}) holds k0 in [{lo:.4g}, {hi:.4g}] at the "
                    f"body's base (vertical stress {depth_pa:.4g} Pa; the active and passive "
                    "limits of its plane-strain Drucker–Prager cone)")
        raise FemInputError(
            f"k0={k0!r}: the K0 state lies outside the yield surface at {n_out} of {n_all} "
            "quadrature points: it is not a state the material can hold (the check solve "
            "would yield them away from it)" + held)

    def apply_prestress(self, *, steps: int = 1) -> list[LoadStep]:
        """Add each layer's prestress T_p / t (tension along x) and equilibrate (PRS, 002)."""
        add = np.zeros_like(self.sig_n)
        for i, lm in enumerate(self.layers):
            sel = np.repeat(self.cell_tag_of == geo.LAYER_TAG0 + i, self.nq)
            add[sel, 0] = lm.prestress_n_per_m / self.body.layers[i].thickness_m
        base = self.sig_n.copy()
        done = [0.0]

        def apply(lf: float) -> None:
            self.sig_n = self.sig_n + (lf - done[0]) * add
            done[0] = lf

        del base
        return self._run_stage("prestress", apply, steps)

    def load_footing(self, *, pressure_pa: float | None = None,
                     settlement_m: float | None = None, steps: int = 10,
                     callback: Any = None) -> list[LoadStep]:
        """Load the footing by a pressure (Pa, compression positive; load control) or a
        settlement (m, downward positive; displacement control of a smooth footing), from the
        current state, in ``steps`` equal increments. Returns the converged steps."""
        if (pressure_pa is None) == (settlement_m is None):
            raise FemInputError("load_footing: give exactly one of pressure_pa, settlement_m")
        if pressure_pa is not None:
            p = geo._real("pressure_pa", pressure_pa)
            t0 = float(self.traction.value[self.zc])
            if p - t0 < 0 and self._cohesionless_under_footing():
                raise FemInputError(
                    f"pressure_pa={p!r}: a tensile footing load (the footing pressure, "
                    f"compression positive, would go from {0.0 - t0:g} to {p - t0:g} Pa); the "
                    "soil is a cohesionless Drucker-Prager (cohesion_pa="
                    f"{self.soil.cohesion_pa!r}), which carries no tension, so no load step "
                    "could converge. Load in compression (pressure_pa > 0), unload by at most "
                    f"the current footing pressure ({0.0 - t0:g} Pa), or give the soil "
                    "cohesion")
            self._displacement_control = False

            def apply(lf: float) -> None:
                self.traction.value[self.zc] = t0 - lf * p
            self._ext_scale = max(self._ext_scale, abs(p) * self.footing_area)
        else:
            d = geo._real("settlement_m", settlement_m)
            self._displacement_control = True
            u0 = -self.footing_settlement_m()

            def apply(lf: float) -> None:
                self.footing_u.value = u0 - lf * d
        try:
            return self._run_stage("footing", apply, steps, callback)
        except NewtonFailure as e:
            if settlement_m is not None and d < 0 and self._cohesionless_under_footing():
                raise NewtonFailure(
                    f"{e}; settlement_m={d!r} lifts the footing, and the soil is a "
                    f"cohesionless Drucker-Prager (cohesion_pa={self.soil.cohesion_pa!r}), "
                    "which carries no tension") from e
            if pressure_pa is not None:
                raise NewtonFailure(
                    f"{e}; the footing carries {self.footing_pressure_pa():.6g} Pa of "
                    f"pressure_pa={p:g}. A uniform (flexible) pressure is limited by the "
                    "soil yielding at its edge, often far below what a rigid footing carries: "
                    "push the footing by settlement_m, or use load_footing_to_pressure") from e
            raise

    def load_footing_to_pressure(self, pressure_pa: float, *, steps: int = 10,
                                 callback: Any = None, tol: float = 0.01,
                                 max_steps_factor: int = 4,
                                 slope_pa_per_m: float | None = None) -> list[LoadStep]:
        """Push the footing down as a rigid smooth footing (displacement control) until its
        mean pressure (the reaction, Pa, compression positive) has risen by ``pressure_pa``
        from the current state, within ``tol`` (relative). For a cohesionless soil, whose
        surface carries no flexible pressure at the footing's edge (with a Drucker–Prager
        soil without cohesion, a pressure load failed at 19 % of 100 kPa).

        A first small settlement gives the elastic slope; then settlement steps, each aimed
        at the target over the steps left by the last step's secant slope (from half to four
        times the last step), until the pressure reaches the target. A step that passes it
        beyond ``tol`` is taken again, shortened by linear interpolation. The results' ``load_factor`` is the pressure's fraction of the
        target; ``callback(r)`` is called for each step as it is accepted. Raises NewtonFailure if
        the pressure has not reached the target after ``max_steps_factor`` x ``steps``
        steps (the soil's bearing capacity is below it), or if a step fails after its cuts
        (its message then says how far the pressure rose, and at what settlement; the model
        is left at the last accepted step).

        ``slope_pa_per_m`` (Pa/m, > 0): a known pressure–settlement slope to start from
        instead of the first small settlement (1e-6 of the body's height). With DEM region
        elements that first settlement raises the pressure by less than the elements' own
        scatter, so its slope can be anything, and the step it sizes can tear the elements
        apart; give the slope of a previous stage or of the continuum model then."""
        if callback is not None and not callable(callback):
            raise FemInputError(f"callback={callback!r}: must be callable (called with each "
                                "accepted step's LoadStep), or None")
        target = geo._real("pressure_pa", pressure_pa)
        if not target > 0:
            raise FemInputError(f"pressure_pa={pressure_pa!r}: must be > 0 (Pa, compression "
                                "positive)")
        if not isinstance(steps, int) or steps < 1:
            raise FemInputError(f"steps={steps!r}: must be an integer >= 1")
        tol = geo._real("tol", tol)
        if not 0 < tol < 1:
            # (a tolerance of 0 or below can never be met: the step would be taken again for
            # ever)
            raise FemInputError(f"tol={tol!r}: must be in (0, 1) (the pressure's relative "
                                "tolerance, -)")
        if not isinstance(max_steps_factor, int) or max_steps_factor < 1:
            raise FemInputError(f"max_steps_factor={max_steps_factor!r}: must be an integer "
                                ">= 1")
        # (from the footing's current mean settlement, as ``load_footing(settlement_m=)``:
        # after a prestress stage the surface has moved, and the footing starts there)
        u_start = -self.footing_settlement_m()
        self._displacement_control = True
        p0 = self.footing_pressure_pa()
        done: list[LoadStep] = []
        d = 0.0

        def go(d_to: float) -> None:
            d_from = d

            def apply(lf: float) -> None:
                self.footing_u.value = u_start - (d_from + lf * (d_to - d_from))

            for r in self._run_stage("footing", apply, 1):  # (one step: the history's last)
                r2 = dataclasses.replace(r, load_factor=(r.footing_pressure_pa - p0) / target)
                self.history[-1] = r2
                done.append(r2)

        def rise() -> float:
            return self.footing_pressure_pa() - p0

        def accepted(since: int) -> None:  # (as each step is taken: a run's progress)
            if callback is not None:
                for r in done[since:]:
                    callback(r)

        d1 = 1e-6 * self.body.height_m
        if slope_pa_per_m is None:
            go(d1)
            accepted(0)
            d = d1
            slope = rise() / d1
            if not slope > 0:
                raise NewtonFailure(f"footing: a settlement of {d1:.3g} m gave no pressure "
                                    f"({rise():.3g} Pa)")
        else:
            slope = geo._real("slope_pa_per_m", slope_pa_per_m)
            if not slope > 0:
                raise FemInputError(f"slope_pa_per_m={slope_pa_per_m!r}: must be > 0 (Pa/m)")
        dd = max((target - rise()) / slope / steps, d1)
        taken = 0
        while rise() < target * (1.0 - tol):
            if taken >= max_steps_factor * steps:
                raise NewtonFailure(
                    f"footing: the pressure rose by {rise():.4g} Pa after a settlement of "
                    f"{d:.4g} m in {taken} steps, short of pressure_pa={target:g}: the soil's "
                    "bearing capacity is below it")
            state, n_done, p_now = self.save_state(), len(done), rise()
            try:
                go(d + dd)
            except NewtonFailure as exc:
                # (back to the last accepted step: its stresses, not the failed iterate's)
                self.restore_state(state)
                del done[n_done:]
                raise NewtonFailure(
                    f"{exc}; the footing stopped where its pressure had risen by "
                    f"{p_now:.4g} Pa of pressure_pa={target:g}, at a settlement of "
                    f"{self.footing_settlement_m():.4g} m (the model is left there)") from exc
            p_new = rise()
            if p_new > target * (1.0 + tol):
                self.restore_state(state)
                del done[n_done:]
                dd *= (target - p_now) / (p_new - p_now)
                continue
            d += dd
            taken += 1
            accepted(n_done)
            # the next step from the last one's secant slope, aiming at the target over the
            # steps left (at most 4 x longer, at least half as long as this one)
            slope = (p_new - p_now) / dd
            want = ((target - p_new) / slope / max(1, steps - taken) if slope > 0
                    else 4.0 * dd)
            dd = min(max(want, 0.5 * dd), 4.0 * dd)
        return done

    def _cohesionless_under_footing(self) -> bool:
        """The soil under the footing carries no tension: a Drucker-Prager soil without
        cohesion, and no element region (whose material may carry tension) reaching the top
        under the footing."""
        b, h = self.body.footing_half_width_m, self.body.height_m
        regions_on_top = any(r.center_m[-1] + r.size_m / 2 >= h - 1e-9 * h
                             and r.center_m[0] - r.size_m / 2 < b for r in self.body.regions)
        return (isinstance(self.soil, DruckerPrager) and self.soil.cohesion_pa == 0
                and not regions_on_top)
