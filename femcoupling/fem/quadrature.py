"""One material interface and one Newton for every quadrature-point model of this package.

Two models solve equilibrium with a stress and a tangent at quadrature points: the FEM soil
(:class:`femcoupling.fem.model.FemModel`: elastic, anisotropic elastic and
Drucker–Prager points, and DEM elements for element regions or cells) and the hierarchical
FEM x DEM (:class:`femcoupling.fem.model.FemModel`: a DEM element at every quadrature
point). Both use what this module gives:

:class:`QuadratureMaterial`
    the one exchange of every material: it declares its ``strain_measure`` (the increment
    ``trial`` takes: :data:`STRAIN_MEASURES`); ``trial(increment)`` returns its total stress
    and tangent after ``increment`` (since the last commit); ``stress_n`` and ``plastic`` are
    its committed stress and last plastic multipliers; ``commit()`` keeps the last trial,
    ``state()``/``set_state(data)`` save and restore the committed state (bitwise); a Dask
    group of DEM elements answers its members at once (``trial_many``).
    ``femcoupling.materials.continuum.ElasticPoints`` (isotropic or anisotropic),
    ``femcoupling.materials.continuum.DruckerPragerPoints`` (``LinearElastic.at_points``,
    ``AnisotropicElastic.at_points``, ``DruckerPrager.at_points``),
    ``femcoupling.fem.soil_regions.RegionPoints``,
    ``femcoupling.materials.dem_elements.DemRegionMaterial``, the members of a
    ``femcoupling.materials.dem_elements.PoolRegionMaterials`` and
    ``femcoupling.materials.element_pool.ElementPoolMaterial`` implement it.
:class:`QuadratureSystem`
    the dolfinx side: displacement and quadrature spaces, the internal force and Jacobian
    forms of a stress and a tangent at the points, the residual with lifted Dirichlet values,
    and the LU solve of a Newton correction (:func:`lu_package`: which LU, by rank count).
:func:`newton_solve` with :class:`NewtonRules`
    the Newton iteration of one load step and its acceptance rules, the same for both models:

    - ``converged``: the residual within ``rtol`` of the model's force scale;
    - when Newton stalls (the residual has not halved in two iterations, or the last
      iteration is reached) and the model's materials are noisy (DEM elements), the noise is
      measured: every point is evaluated again on its increment scaled by 1 + 1e-9 (the
      elements' chaos), or by 1 + and 1 - the size of Newton's last correction, the second
      difference of the stresses over sqrt 3 (``probe_size="correction"``: the elements'
      roughness at the scale Newton works at; the smooth part of their answer, and so the
      tangents' error, drops out to first order), and the residual of that change of the
      stresses is what no iterate can get below. The step is
      then ``stopped_at_scatter`` if its residual is within ``noise_factor`` times that noise
      and within ``ceiling`` of the noisy points' own force scale; within the noise but above
      the ceiling Newton takes up to ``redraws`` (:data:`REDRAWS`) more iterates, each a
      new draw of that noise, and accepts the first within the noise and the ceiling; if
      none is, the step is cut (:class:`NewtonFailure`);
    - otherwise Newton goes on (a model without DEM points halves a correction where its
      residual made no progress over :data:`CYCLE_WINDOW` iterations: a cycle), and a step
      that reaches
      ``max_newton``, or whose residual or correction is not finite, or whose linear solve
      fails, is cut (:class:`NewtonFailure`).

    The caller cuts a failed step (halves it) as its loading asks.

SI units: stresses in Pa, forces in N; tension positive.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol, runtime_checkable

import numpy as np
from cpp_dem.fixedorder import sum_squares

from femcoupling import _dolfinx
from femcoupling._checks import FemInputError
from femcoupling.coupling.relaxation import next_factor
from femcoupling.coupling.status import newton_acceptance
from femcoupling.fem.steps import NewtonFailure  # (the one failure type; re-exported)

__all__ = ["QuadratureMaterial", "STRAIN_MEASURES", "NewtonRules", "NewtonOutcome",
           "NewtonFailure", "QuadratureSystem", "check_material", "newton_solve", "lu_options",
           "lu_package", "lu_pc_type",
           "CYCLE_RATIO", "CYCLE_WINDOW", "LINE_SEARCH_RISE", "NOISE_PROBE", "PARALLEL_LU", "SERIAL_LU"]

#: the relative change of every increment that measures the elements' noise
NOISE_PROBE = 1e-9
#: More iterates a step stalled within the elements' noise but above the ceiling takes before
#: it is cut (NewtonRules.redraws). Such a residual is a draw of the elements' noise, and where
#: the noise straddles the ceiling, the first draw decided the step by the rounding of the
#: machine: the footing smoke's RE seed 1 stalled at 0.86-0.93 % of its zone's force against
#: the 1 % ceiling, its noise measured at 1.3-1.6 % (twice: the acceptance band): whether a
#: step was taken or cut (and the run's path after it) was the rounding's choice, and a fresh
#: machine's failed the run. A later iterate of the same step is another draw; one within the
#: same bounds is as good an answer (docs/coupling_newton.md).
REDRAWS = 4

#: A smooth model's correction is halved where the least of its last CYCLE_WINDOW residuals is
#: not below this fraction of the least of the CYCLE_WINDOW before (``NewtonRules.
#: break_cycles``). A
#: Drucker–Prager soil whose points flip between the cone and its apex makes full Newton
#: corrections cycle between two iterates (tests/mpi_soil_body.py's prestress: 4.93e-2 and
#: 6.23e-2 of the force scale in turn for 50 iterations, until max_newton cut the step),
#: and whether a step falls into such a cycle was the rounding's choice: the same body took
#: 10 load steps under one LU and 11 under another, 0.3 % apart in its stresses. Halving
#: the correction leaves the cycle; the three LUs then take the same 10 steps, within
#: 5e-11 of each other (docs/coupling_newton.md).
CYCLE_RATIO = 0.9
#: The iterations of each of the two windows CYCLE_RATIO compares (a cycle of up to this
#: period: tests/mpi_soil_body.py's serial body cycled with periods 2 and 4).
CYCLE_WINDOW = 4

#: A smooth model's backtracking (``NewtonRules.line_search``) goes back where the residual
#: rose above this many times the residual before the correction (1.0: any rise).
LINE_SEARCH_RISE = 1.0

#: The LU package of the FEM's solves on more than one MPI rank: None, PETSc's own LU on
#: every rank at once (``PCREDUNDANT``: each rank gathers the whole matrix and factors it
#: with plain loops), so a correction has the same bits on every CPU. SuperLU_DIST's and
#: MUMPS's fronts call BLAS: tests/mpi_soil_body.py on 2 ranks with SuperLU_DIST took 10
#: load steps under two BLAS kernels and 11 under a third, its Newton iterations and last
#: bits others under each; MUMPS's parallel LU also ended 5 runs of 15 beside busy
#: processes in other last bits (docs/fem.md, "Under MPI"). "superlu_dist" or "mumps" may be
#: set here, to trade that for a parallel factorization; bench/parallel_lu.py measures all
#: three.
PARALLEL_LU: str | None = None


#: The LU package of the FEM's solves on one rank: None, PETSc's own LU. Its factorization
#: and solve are plain loops, so a Newton correction has the same bits on every CPU. MUMPS's
#: dense fronts call BLAS, whose kernel (picked by the CPU, or by ``OPENBLAS_CORETYPE``)
#: rounds in its own order: 002's soil took 16 load steps under one kernel and 8 under
#: another (docs/fem.md, "The same bits on every CPU"). "mumps" may be set here, to trade
#: that for speed; bench/serial_lu.py measures both.
SERIAL_LU: str | None = None


def lu_package(comm: Any) -> str | None:
    """The LU package of a linear solve on ``comm`` (an mpi4py communicator, or None: one
    rank): :data:`SERIAL_LU` on one rank, :data:`PARALLEL_LU` on more."""
    return SERIAL_LU if comm is None or comm.size == 1 else PARALLEL_LU


def lu_pc_type(comm: Any, package: str | None) -> str:
    """The PETSc preconditioner of a direct solve on ``comm`` with LU ``package``: "lu", or
    "redundant" (PETSc's own LU on every rank) for None on more than one rank."""
    return "redundant" if package is None and comm is not None and comm.size > 1 else "lu"


def lu_options(comm: Any) -> dict:
    """PETSc options of a direct solve (``dolfinx.fem.petsc.LinearProblem``) on ``comm``:
    LU by :func:`lu_package`."""
    pkg = lu_package(comm)
    return {"ksp_type": "preonly", "pc_type": lu_pc_type(comm, pkg),
            **({"pc_factor_mat_solver_type": pkg} if pkg is not None else {})}


#: The strain measures a material may declare (``QuadratureMaterial.strain_measure``): the
#: increment its ``trial`` takes, and the form of the stress and tangent it returns. A model
#: hands each material the measure it declares and refuses one it cannot give.
STRAIN_MEASURES = {
    "mandel": "the small-strain increment since the last commit at each point, Mandel form, "
              "(n, ncomp): 2D (xx, yy, zz, sqrt2 xy), 3D (xx, yy, zz, sqrt2 yz, sqrt2 xz, "
              "sqrt2 xy); the stress (n, ncomp) and tangent (n, ncomp, ncomp) in the same "
              "form (the soil body's points: FemModel)",
    "gradient": "the displacement-gradient increment since the last commit at each point, "
                "(n, gdim, gdim) (a DEM element needs its rotation too); the stress in Voigt "
                "form, 2D (xx, yy, xy), 3D (xx, yy, zz, yz, xz, xy), and the tangent with "
                "engineering shear (the hierarchical models' points)",
    "tensor": "one strain increment tensor since the last commit, 3 x 3 (a region's or a "
              "cell's volume mean: the region elements of FemModel.set_region_element and "
              "set_cell_elements); the stress 3 x 3 and the tangent 6 x 6 Mandel",
}


@runtime_checkable
class QuadratureMaterial(Protocol):
    """A material at a set of quadrature points, or of a region (see the module doc): one
    exchange for every material, as a constitutive law's in Kratos.

    - ``strain_measure``: the increment ``trial`` takes (a key of :data:`STRAIN_MEASURES`);
    - ``trial(increment)``: the **total** stress and the tangent after ``increment`` (since
      the last commit); a rejected trial leaves no trace: the next ``trial`` starts again
      from the committed state;
    - ``stress_n``: the committed stress, Pa, tension positive (in the measure's form);
    - ``plastic``: the last trial's plastic multiplier per point, (n,) (0: elastic; a DEM
      element's is 0: its plasticity is in its contacts, not a multiplier);
    - ``commit()`` keeps the last trial; ``state()``/``set_state(data)`` save and restore the
      committed state, bitwise."""

    strain_measure: str
    stress_n: Any
    plastic: Any

    def trial(self, increment: Any) -> tuple[Any, Any]: ...

    def commit(self) -> None: ...

    def state(self) -> Any: ...

    def set_state(self, data: Any) -> None: ...


def check_material(material: Any, name: str, measure: str | None = None) -> Any:
    """``material`` if it implements :class:`QuadratureMaterial` (and declares ``measure``,
    where given: the one the model hands it); else a FemInputError (a ValueError) naming
    ``name``, the missing members or the measure declared and the one allowed."""
    missing = [k + "()" for k in ("trial", "commit", "state", "set_state")
               if not callable(getattr(material, k, None))]
    missing += [k for k in ("strain_measure", "stress_n", "plastic")
                if not hasattr(material, k)]
    if missing:
        raise FemInputError(f"{name}={material!r}: needs a {', '.join(missing)} (a "
                            "femcoupling.fem.quadrature.QuadratureMaterial, as femcoupling."
                            "materials.dem_elements.DemRegionMaterial)")
    got = material.strain_measure
    if measure is not None and got != measure:
        raise FemInputError(f"{name}.strain_measure={got!r}: this model hands it "
                            f"{measure!r} ({STRAIN_MEASURES[measure]})")
    if got not in STRAIN_MEASURES:
        raise FemInputError(f"{name}.strain_measure={got!r}: one of "
                            f"{sorted(STRAIN_MEASURES)}")
    return material


# ---- Newton ----------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class NewtonRules:
    """The acceptance rules of a load step (module doc). ``rtol``: the tolerance relative to
    the model's force scale, -; ``max_newton``: the last iteration; ``noise_factor``: a
    stalled step within this many times the measured noise ...; ``ceiling``: ... and within
    this fraction of the noisy points' own force scale is stopped_at_scatter (inf: no
    ceiling); ``probe``: measure the noise when Newton stalls (the model has DEM points)."""

    rtol: float
    max_newton: int
    noise_factor: float = 2.0
    ceiling: float = math.inf
    probe: bool = False
    #: the noise probe's relative change of the increments: a number (``NOISE_PROBE``, 1e-9:
    #: the elements' chaos), or "correction": the size of Newton's last correction relative
    #: to the step's displacement increment (at least 1e-9), both ways, the second
    #: difference of the stresses (the elements' roughness at the scale Newton works at,
    #: which the tangents' error does not enter)
    probe_size: float | str = NOISE_PROBE
    #: a step stalled within the noise but above the ceiling: Newton takes up to this many
    #: more iterates (each a new draw of the elements' noise) and accepts the first within
    #: the same bounds (the noise and the ceiling), before the step is cut (module doc)
    redraws: int = REDRAWS
    #: a smooth model's (no DEM points) backtracking: where the residual rose over Newton's
    #: last correction (not a step's first, which puts the displacement on its boundary
    #: values) above :data:`LINE_SEARCH_RISE` times its value before, the iterate goes back by
    #: half that correction, up to this many times in a row (0: none). A Drucker–Prager
    #: soil's points that flip between the cone and its apex made full corrections cycle: a
    #: step stuck at 3.5e-2 of the force scale for 100 iterations.
    line_search: int = 0
    #: a smooth model's (no DEM points) correction is halved where the least of its last
    #: :data:`CYCLE_WINDOW` residuals is not below :data:`CYCLE_RATIO` times the least of the
    #: window before (a Newton cycling); with ``probe`` it does nothing (a noisy residual
    #: that does not fall is a stall, which the noise probe judges)
    break_cycles: bool = True

    def __post_init__(self) -> None:
        if not (self.probe_size == "correction" or (isinstance(self.probe_size, float)
                                                    and 0 < self.probe_size < 1)):
            raise FemInputError(f"probe_size={self.probe_size!r}: a relative change in (0, "
                                "1), or 'correction'")
        if not (isinstance(self.redraws, int) and self.redraws >= 0):
            raise FemInputError(f"redraws={self.redraws!r}: must be a whole number >= 0")
        if not (isinstance(self.line_search, int) and self.line_search >= 0):
            raise FemInputError(f"line_search={self.line_search!r}: must be a whole number "
                                ">= 0")
        if self.line_search and self.probe:
            raise FemInputError("line_search: only for a model without DEM points (probe="
                                "False): a noisy residual's rise is a draw, not an overshoot")


@dataclasses.dataclass
class NewtonOutcome:
    """An accepted load step's Newton: ``iterations``; ``residual`` relative to ``scale``
    (the force scale, N, at the end); ``noise_residual``: the measured noise on the same
    scale (NaN if not measured); ``noise_scale``: the noisy points' own force scale, N;
    ``converged_on``: "tolerance" or "noise"; ``status``: "converged" or
    "stopped_at_scatter"; ``relaxation``: the factor of each correction; ``redraws``: see
    :data:`REDRAWS`."""

    iterations: int
    residual: float
    scale: float
    noise_residual: float
    noise_scale: float
    converged_on: str
    status: str
    relaxation: tuple
    #: iterates taken after a stall within the noise but above the ceiling before one was
    #: within both (REDRAWS), 0 where none was needed
    redraws: int = 0


class NewtonProblem(Protocol):
    """What :func:`newton_solve` asks of a model. It may also have
    ``noisiest(before) -> str``: which elements moved most at a noise probe, named in the
    message of a step cut above the ceiling (``FemModel``'s region elements)."""

    def evaluate(self, first: bool, perturb: float = 0.0) -> None:
        """Every material's trial at the current iterate (increments x (1 + perturb))."""

    def residual(self) -> float:
        """|R| (N) of the current iterate, Dirichlet rows lifted."""

    def force_scale(self) -> float:
        """The tolerance's force scale, N (> 0)."""

    def noise_scale(self) -> float:
        """The noisy (DEM) points' own force scale, N (> 0): the ceiling's."""

    def stresses(self) -> np.ndarray:
        """A copy of the current stresses at the points."""

    def stress_change_residual(self, before: np.ndarray) -> float:
        """|internal force| (N) of the stress change since ``before``, Dirichlet rows
        zeroed."""

    def increment_norm(self) -> float:
        """|u - u_n|: the step's displacement increment so far (only with
        ``probe_size="correction"``)."""

    def at_boundary_values(self) -> bool:
        """Whether the displacement is on its Dirichlet values (a step may then be accepted
        before any correction)."""

    def correction(self) -> np.ndarray:
        """The full Newton correction of the displacement (raises NewtonFailure)."""

    def move(self, correction: np.ndarray, factor: float) -> None:
        """u += factor * correction."""


def newton_solve(problem: NewtonProblem, rules: NewtonRules, *, relaxation: Any = "none",
                 log: Any = None) -> NewtonOutcome:
    """The Newton iteration of a load step on ``problem`` under ``rules`` (module doc);
    ``relaxation`` of the corrections ("none", "aitken" or a factor: ``femcoupling.
    coupling.relaxation``; the first correction of a step is always a full one, as it also puts the
    displacement on its new boundary values); ``log(msg)`` gets a line per iteration. Returns
    the accepted step's :class:`NewtonOutcome`, or raises :class:`NewtonFailure`."""
    rel = noise_rel = float("nan")
    nscale = float("nan")
    omega, d_prev, omegas = 1.0, None, []
    hist: list[float] = []
    drawn: list[float] = []  # the residuals since the first stall: draws of the noise
    above: str | None = None  # the ceiling failure that the redraws try to get under
    redraws = 0
    back_from = None  # (the residual before the last correction, it, its factor)
    backtracks = 0
    for it in range(rules.max_newton + 1):
        problem.evaluate(first=(it == 0))
        rnorm = problem.residual()
        scale = problem.force_scale()
        rel = rnorm / scale
        hist.append(rel)
        if not math.isnan(noise_rel):
            drawn.append(rel)
        if log is not None:
            log(f"iteration {it}: residual {rel:.3e}")
        if not math.isfinite(rel) and not back_from:
            raise NewtonFailure(f"Newton: the residual is not finite at iteration {it}")
        rose = back_from and (not math.isfinite(rel) or rel > LINE_SEARCH_RISE * back_from[0])
        if rose and backtracks < rules.line_search and it < rules.max_newton:
            # the residual rose over the last correction: back by half of it
            backtracks += 1
            half = 0.5 * back_from[2]
            back_from = (back_from[0], back_from[1], half)
            problem.move(back_from[1], -half)
            omegas[-1] -= half
            if log is not None:
                log(f"line search: back by half the correction ({backtracks})")
            continue
        if not math.isfinite(rel):
            raise NewtonFailure(f"Newton: the residual is not finite at iteration {it}")
        # (before any correction the displacement may be off its new Dirichlet values: their
        # rows hold the gap in metres, which a force tolerance does not see)
        if rel <= rules.rtol and (it > 0 or problem.at_boundary_values()):
            return NewtonOutcome(it, rel, scale, noise_rel, nscale, "tolerance", "converged",
                                 tuple(omegas))
        if above is not None:
            # a redraw (REDRAWS): accepted within the noise already measured and the ceiling,
            # the ceiling on this iterate's noisy points (their force at the probe's iterate
            # was up to 4 x it: a footing step was taken at 4.2 % of its zone's own force)
            nscale = problem.noise_scale()
            accept = newton_acceptance(rel, rtol=rules.rtol, noise_residual=noise_rel,
                                       noise_factor=rules.noise_factor,
                                       ceiling=rules.ceiling * nscale / scale)
            if accept is not None:
                if log is not None:
                    log(f"redraw {redraws}: residual {rel:.3e} within the noise and the "
                        "ceiling: accepted")
                return NewtonOutcome(it, rel, scale, noise_rel, nscale, "noise", accept,
                                     tuple(omegas), redraws)
            if redraws >= rules.redraws or it == rules.max_newton:
                raise NewtonFailure(f"{above}; {redraws} more iterates, each a new draw of "
                                    f"the elements' noise, were above it too (the last at "
                                    f"{rel:.3g})")
            redraws += 1
        stalled = above is None and (it == rules.max_newton
                                     or (len(hist) >= 3 and rel > 0.5 * hist[-3]))
        if rules.probe and it > 0 and stalled:
            # Newton stalls above the tolerance: the noise (the largest of the step's probes
            # counts; after a probe, two more iterations before the next)
            before = problem.stresses()
            if rules.probe_size == "correction":
                # the increments changed both ways by Newton's last correction: the second
                # difference s(+) + s(-) - 2 s(0) keeps the answer's roughness at that scale
                # and drops its smooth part, to first order in the change, whatever the
                # tangent (a one-sided change less the tangents' prediction measured the
                # tangents' error as noise); divided by sqrt 3, its size for a noise of the
                # one-sided probe's size (sd sqrt 6 against sqrt 2 of one evaluation's)
                last = 0.0 if d_prev is None else omegas[-1] * math.sqrt(sum_squares(d_prev))
                size = max(NOISE_PROBE, last / max(problem.increment_norm(), 1e-300))
                problem.evaluate(first=False, perturb=size)
                before = 2.0 * before - problem.stresses()
                problem.evaluate(first=False, perturb=-size)
                v = problem.stress_change_residual(before) / scale / math.sqrt(3.0)
            else:
                size = rules.probe_size
                problem.evaluate(first=False, perturb=size)
                v = problem.stress_change_residual(before) / scale
            noisiest = getattr(problem, "noisiest", None)
            where = noisiest(before) if noisiest is not None else ""
            # After a first stall every iterate is a draw of the elements' noise, and their
            # spread measures it too: at a second stall the noise is at least that spread (one
            # probe can miss most of it: 8.6e-6 against iterates spread over 5.7e-6-3.5e-5, so
            # whether a draw fell within 2 x the probe's noise was luck, and the rounding path
            # decided the iteration count). The spread counted is the largest rise of a draw
            # above an earlier one: a Newton that still converges, slowly, lowers its
            # residual from draw to draw, and that fall is its progress, not noise (a smooth
            # problem with a tangent 5 x too stiff was taken within the "noise" of its own
            # descent).
            spread = max((drawn[k] - min(drawn[:k]) for k in range(1, len(drawn))),
                         default=0.0) if len(drawn) >= 3 else 0.0
            if rules.probe_size == "correction":
                # (the latest probe's: its second difference keeps the answer's curvature at
                # the probe's size too, and an earlier probe at a larger correction would
                # keep a smooth problem's curvature as its noise to the end of the step)
                noise_rel = max(v, spread)
                # back on the iterate: the state a step accepts is the iterate's (a 1e-9 probe
                # is within the noise of it, and is kept)
                problem.evaluate(first=False)
            else:
                noise_rel = v if math.isnan(noise_rel) else max(noise_rel, v, spread)
            rnorm = problem.residual()
            rel = rnorm / scale
            hist = [rel]
            nscale = problem.noise_scale()
            if log is not None:
                log(f"noise probe: residual {rel:.3e}, the noise's {noise_rel:.3e}")
            accept = newton_acceptance(rel, rtol=rules.rtol, noise_residual=noise_rel,
                                       noise_factor=rules.noise_factor,
                                       ceiling=rules.ceiling * nscale / scale)
            if accept is not None:
                return NewtonOutcome(it, rel, scale, noise_rel, nscale,
                                     "tolerance" if accept == "converged" else "noise",
                                     accept, tuple(omegas))
            if rel <= rules.noise_factor * noise_rel:
                above = (
                    f"Newton stalled at {rel:.3g} of the force scale, within the elements' "
                    f"noise ({noise_rel:.3g}) but above the ceiling noise_ceiling="
                    f"{rules.ceiling:g} of the DEM points' own force ("
                    f"{rules.ceiling * nscale / scale:.3g} of the force scale; asked "
                    f"newton_rtol={rules.rtol:g}): the step is cut"
                    + (f" (the elements that moved most at the probe: {where})"
                       if where else ""))
                if rules.redraws == 0 or it == rules.max_newton:
                    raise NewtonFailure(above)
                redraws = 1
        if it == rules.max_newton:
            raise NewtonFailure(f"Newton: no convergence in {rules.max_newton} iterations "
                                f"(residual {rel:.3g} of the force scale; asked "
                                f"newton_rtol={rules.rtol:g}"
                                + (f"; the elements' noise makes {noise_rel:.3g}"
                                   if rules.probe else "") + ")")
        dk = problem.correction()
        omega = next_factor(relaxation, omega, d_prev, dk)
        w_k = 1.0 if it == 0 else omega
        if (rules.break_cycles and not rules.probe and len(hist) >= 2 * CYCLE_WINDOW
                and min(hist[-CYCLE_WINDOW:])
                >= CYCLE_RATIO * min(hist[-2 * CYCLE_WINDOW:-CYCLE_WINDOW])):
            # the last CYCLE_WINDOW residuals got no lower than the ones before: a cycle (of
            # any period up to the window); half a correction leaves it, whatever the
            # rounding put the iterates on
            w_k *= 0.5
            if log is not None:
                log("no progress over the last iterations: half the correction")
        omegas.append(w_k)
        d_prev = dk
        problem.move(dk, w_k)
        backtracks = 0
        # (a step's first correction is never backtracked: it sets the boundary values)
        back_from = (rel, dk, w_k) if rules.line_search and it > 0 else None
    raise AssertionError("unreachable")


# ---- the dolfinx side ------------------------------------------------------------------------

class QuadratureSystem:
    """Spaces, forms and solver of a quadrature-point model on ``mesh`` (module doc).

    ``degree``: the displacement's Lagrange degree; ``qdeg``: the quadrature degree (default
    scheme); ``ncomp``: the stress vector's length; ``strain(w)``: the UFL strain vector of a
    displacement ``w`` that pairs with the stress (Mandel for the soil; Voigt with engineering
    shear for the hierarchical mode); ``loads(v)``: the external virtual work terms (UFL
    forms), each subtracted in turn from the internal one; ``lu``: the LU package ("mumps",
    "superlu_dist", or None for PETSc's own: on more than one rank, on every rank at once,
    :func:`lu_pc_type`)."""

    def __init__(self, mesh, *, degree: int, qdeg: int, ncomp: int, strain, loads=None,
                 lu: str | None = None) -> None:
        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        import basix
        import basix.ufl

        self.mesh, self.ncomp, self.qdeg, self.strain = mesh, ncomp, qdeg, strain
        cell = mesh.basix_cell()
        self.V = fem.functionspace(mesh, ("Lagrange", degree, (mesh.topology.dim,)))
        qe_v = basix.ufl.quadrature_element(cell, value_shape=(ncomp,), scheme="default",
                                            degree=qdeg)
        qe_t = basix.ufl.quadrature_element(cell, value_shape=(ncomp, ncomp),
                                            scheme="default", degree=qdeg)
        self.Wv, self.Wt = fem.functionspace(mesh, qe_v), fem.functionspace(mesh, qe_t)
        pts, wts = basix.make_quadrature(cell, qdeg)
        self.qpoints, self.qweights = pts, wts / wts.sum()
        self.u, self.u_n, self.du = (fem.Function(self.V) for _ in range(3))
        self.sig_q = fem.Function(self.Wv)  # the points' current stress
        self.tan_q = fem.Function(self.Wt)  # and tangent
        self.dxq = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": qdeg,
                                                             "quadrature_scheme": "default"})
        v, dv = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        self.f_int = ufl.dot(self.sig_q, strain(v)) * self.dxq
        res = self.f_int
        for term in (loads(v) if loads is not None else ()):
            res = res - term
        self.res = res  # (UFL: the internal minus the external virtual work)
        self.form_res = fem.form(res)
        self.form_jac = fem.form(ufl.dot(ufl.dot(self.tan_q, strain(dv)), strain(v))
                                 * self.dxq)
        # the internal force of a stress field alone (the noise's residual)
        self.sig_change = fem.Function(self.Wv)
        self.form_change = fem.form(ufl.dot(self.sig_change, strain(v)) * self.dxq)
        self.A = fx.fem_petsc.create_matrix(self.form_jac)
        self.b = fx.fem_petsc.create_vector(self.V)
        self.b_change = fx.fem_petsc.create_vector(self.V)
        self.ksp = fx.PETSc.KSP().create(mesh.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType(lu_pc_type(mesh.comm, lu))
        if lu is not None:
            pc.setFactorSolverType(lu)

    def reaction(self, form, dofs: np.ndarray, comm=None) -> float:
        """The sum of the assembled vector of ``form`` (a residual: the reaction where ``dofs``
        are constrained), N (per m in 2D), over ``dofs`` (this rank's owned ones, summed in
        dof order, then over the ranks of ``comm``): the footing's reaction in every model."""
        fx = self._fx
        vec = fx.fem.assemble_vector(form)
        vec.scatter_reverse(fx.dolfinx.la.InsertMode.add)
        n_own = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        total = float(np.sum(vec.array[np.sort(dofs[dofs < n_own])]))
        if comm is not None and comm.size > 1:
            total = comm.allreduce(total)
        return total

    def residual(self, bcs: list) -> float:
        """b = R(u) lifted by J (g - u) at the constrained dofs (the predictor of the
        prescribed increment), b = u - g there; returns |b| (dolfinx's Newton convention:
        solve J dx = b, u <- u - dx)."""
        fx = self._fx
        PETSc = fx.PETSc
        with self.b.localForm() as loc:
            loc.set(0.0)
        fx.fem_petsc.assemble_vector(self.b, self.form_res)
        fx.fem_petsc.apply_lifting(self.b, [self.form_jac], bcs=[bcs], x0=[self.u.x.petsc_vec],
                                   alpha=-1.0)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fx.fem_petsc.set_bc(self.b, bcs, x0=self.u.x.petsc_vec, alpha=-1.0)
        return self.norm(self.b.array)

    def norm(self, owned: np.ndarray) -> float:
        """The Euclidean norm of a vector whose ``owned`` entries (this rank's) are given,
        over the ranks: exactly rounded on each rank (``cpp_dem.fixedorder.sum_squares``;
        PETSc's norm is BLAS's, whose kernel, picked by the CPU, rounds in its own order, and
        a residual at its tolerance then decides another step on another machine)."""
        ss = sum_squares(owned)
        comm = self.mesh.comm
        return math.sqrt(comm.allreduce(ss) if comm.size > 1 else ss)

    def at_boundary_values(self, bcs: list) -> bool:
        """Whether u equals its Dirichlet values ``bcs`` at every constrained dof."""
        fx = self._fx
        v = self.u.x.petsc_vec.copy()
        fx.fem_petsc.set_bc(v, bcs)
        v.axpy(-1.0, self.u.x.petsc_vec)
        gap = v.norm(fx.PETSc.NormType.NORM_INFINITY)
        v.destroy()
        return gap == 0.0

    def change_residual(self, field: np.ndarray, bcs: list, set_field) -> float:
        """|internal force| (N) of a stress field alone (``set_field(function, field)`` puts
        it at the points), Dirichlet rows zeroed."""
        fx = self._fx
        set_field(self.sig_change, field)
        with self.b_change.localForm() as loc:
            loc.set(0.0)
        fx.fem_petsc.assemble_vector(self.b_change, self.form_change)
        self.b_change.ghostUpdate(addv=fx.PETSc.InsertMode.ADD,
                                  mode=fx.PETSc.ScatterMode.REVERSE)
        fx.fem_petsc.set_bc(self.b_change, bcs, alpha=0.0)
        return self.norm(self.b_change.array)

    def correction(self, bcs: list, describe=None) -> np.ndarray:
        """The full Newton correction -du of J du = b (``residual`` first), as an array;
        :class:`NewtonFailure` if the solve fails or gives a value that is not finite
        (``describe()`` adds what the model knows of why)."""
        fx = self._fx
        self.A.zeroEntries()
        fx.fem_petsc.assemble_matrix(self.A, self.form_jac, bcs=bcs)
        self.A.assemble()
        self.ksp.setOperators(self.A)
        self.ksp.solve(self.b, self.du.x.petsc_vec)
        reason = self.ksp.getConvergedReason()
        self.du.x.scatter_forward()
        if reason <= 0 or not np.all(np.isfinite(self.du.x.array)):
            why = "" if describe is None else f"; {describe()}"
            raise NewtonFailure(f"the Newton correction failed (linear solve reason {reason}"
                                f", or not finite: a singular Jacobian{why})")
        return -self.du.x.array.copy()

    def move(self, correction: np.ndarray, factor: float) -> None:
        """u += factor * correction."""
        if factor == 1.0:
            self.u.x.array[:] += correction
        else:
            self.u.x.array[:] += factor * correction
        self.u.x.scatter_forward()
