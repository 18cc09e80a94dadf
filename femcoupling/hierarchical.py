"""Hierarchical FEM x DEM in plane strain: a DEM element at every quadrature point (issue 18,
second part; docs/multiscale.md).

The FEM is a rectangle ``lx`` x ``ly`` (m) of P1 triangles with one quadrature point each, in
dolfinx. Each cell owns one persistent ``DemElement`` held by an ``ElementPool`` on Dask
workers (the pool's element k is cell k). In a load step Newton iterates:

1. the displacement-gradient increment since the start of the step, grad(u) - grad(u_n), at
   every quadrature point (shear and rotation included; the FEM's (x, y) is the element's
   (x, z), and its out-of-plane y is held: plane strain);
2. every element is restored to the start of the step (``pool.reject``: a rejected iterate
   leaves no trace) and takes that increment; it returns its stress and its network tangent;
3. the residual and the Jacobian are assembled from them (Voigt xx, yy, xy with engineering
   shear), and the displacements are corrected.

An accepted step is saved (``pool.accept``: every element's state saved as bytes). Each
step ends in a status (:mod:`femcoupling.status`): ``converged`` (the residual within
``newton_rtol``) or ``stopped_at_scatter`` (``convergence="noise"``: Newton stalled above
``newton_rtol`` with the residual within ``noise_factor`` times the elements' measured noise
and within the ``noise_ceiling``, 10 x ``newton_rtol`` by default). A step whose residual is
within the noise but above the ceiling is not accepted: it is cut, as a step Newton fails
(``NewtonFailure``; a step that still fails after its cuts raises it, the run has
``failed``). The residual is relative to the internal force scale (the largest element
stress times the square root of the domain's area) and also given in stress units
(``HierStep.residual_pa``, Pa: that relative residual times the largest element stress).
The
Drucker–Prager model of ``femcoupling.elastoplastic`` sits behind the same quadrature-space
interface there; here the material is the DEM.

Boundary conditions: left u_x = 0, bottom u_y = 0; the top is moved by ``top_displacement``
(u_y, m); the right is either loaded by a confining pressure (``confining_pa``, compression
positive: a biaxial test) or moved (``right_displacement``, u_x, m). With both
``right_displacement`` and ``top_displacement`` and ``homogeneous=True`` every boundary node
is moved with the homogeneous field, so every element sees the same strain.

Stresses are tension positive here (FEM), Pa. Serial (one MPI rank; the elements are the
parallel part).

Records (``out=DIR``), appended and flushed at every accepted step:
- ``elements.h5``: one row per element per step: step, load, element, increment, stress,
  its bootstrap scatter, tangent, contact count, DEM seconds and steps;
- ``fem.xdmf``: the displacement and the elements' stresses per cell, at every step;
- ``steps.csv``: iterations, residual (relative and in Pa), the measured noise, what ended
  the step and its status, and the FEM/DEM time split;
- ``report.md``: the run so far and every warning.
"""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from femcoupling import _dolfinx
from femcoupling.geometry import FemInputError
from femcoupling.relaxation import aitken_factor, check_relaxation, next_factor
from femcoupling.status import newton_acceptance, worst

__all__ = ["HierarchicalPlaneStrain", "HierStep", "NewtonFailure", "NoiseWarning", "TANGENTS",
           "aitken_factor", "secant_update"]

_IX = [0, 2, 4]  # DEM Voigt (xx, yy, zz, yz, xz, xy) rows of the FEM's (xx, yy, xy)


def dem_increment(g: np.ndarray) -> np.ndarray:
    """The DEM element's 3 x 3 increment from a FEM 2 x 2 displacement-gradient increment:
    FEM (x, y) -> element (x, z); the out-of-plane y is held (plane strain)."""
    de = np.zeros((3, 3))
    de[0, 0], de[0, 2], de[2, 0], de[2, 2] = g[0, 0], g[0, 1], g[1, 0], g[1, 1]
    return de


def fem_stress(s: np.ndarray) -> np.ndarray:
    """FEM Voigt stress (xx, yy, xy), Pa, from the element's 3 x 3 stress."""
    return np.array([s[0, 0], s[2, 2], 0.5 * (s[0, 2] + s[2, 0])])


def fem_tangent(d6: np.ndarray) -> np.ndarray:
    """FEM 3 x 3 tangent (xx, yy, xy; engineering shear) from the element's 6 x 6 Voigt one."""
    return np.asarray(d6)[np.ix_(_IX, _IX)]


#: The element tangents the FEM's Jacobian can be built from.
TANGENTS = {
    "network": "the contact network's stiffness at the relaxed state: contacts on their "
               "friction cone there slide, the others stick (relaxation leaves few on the "
               "cone, so it is close to the elastic network tangent, and equal to it where "
               "none is)",
    "network-elastic": "the contact network's stiffness with every contact stuck: the "
                       "elastic network tangent",
    "secant": "the network tangent changed (BFGS, rank two) to reproduce the element's "
              "stress increment over the step's strain increment so far: it sees the "
              "sliding of the increment; the network tangent where the increment is zero "
              "or the element gave back energy",
}


def secant_update(tangent: np.ndarray, strain: np.ndarray, stress: np.ndarray,
                  min_eig_fraction: float = 1e-3) -> np.ndarray | None:
    """The FEM tangent (3 x 3, Voigt xx, yy, xy with engineering shear, Pa) changed to map
    the strain increment ``strain`` (3,) onto the stress increment ``stress`` (3,), both
    tension positive: T - (T de)(T de)^T / (de . T de) + ds ds^T / (ds . de) on the
    symmetric, positive part of ``tangent`` (eigenvalues raised to ``min_eig_fraction`` of the
    largest). None where no positive secant exists (ds . de <= 0: the element gave back
    energy) or the increment is zero."""
    from femcoupling.handover import HandoverError, spd_floor

    try:
        t = spd_floor(tangent, min_eig_fraction, name="secant_update")
    except HandoverError:  # (no positive stiffness at all)
        return None
    td = t @ strain
    curv_t, curv = float(strain @ td), float(stress @ strain)
    if not (curv_t > 0 and curv > 1e-12 * curv_t):
        return None
    return t - np.outer(td, td) / curv_t + np.outer(stress, stress) / curv


class NewtonFailure(RuntimeError):
    """Newton did not converge in a load step (even after the step was cut)."""


class NoiseWarning(UserWarning):
    """The tolerance asked for is below what the DEM elements can resolve: re-running them
    on (to 1e-9) the same increment moves the residual by more, so a load step is accepted at
    that noise instead (below the ceiling: stopped_at_scatter, not converged)."""


@dataclasses.dataclass
class HierStep:
    """One accepted load step: the top displacement (m), Newton iterations, the residual at
    the end (relative to the internal force scale; in Pa: ``residual_pa``), the elements'
    mean Voigt stress (xx, yy, xy), tension positive, Pa, the element
    stresses (n_cells, 3), the DEM seconds (sum over the elements' work), the FEM seconds
    (the step's wall time outside the pool's calls), the wall seconds, and the elements
    rebuilt after a lost worker."""

    load: float
    iterations: int
    residual: float
    mean_stress: np.ndarray
    element_stresses: np.ndarray
    dem_s: float
    fem_s: float
    wall_s: float
    recovered: list
    increments: np.ndarray  # (n_cells, 3, 3): each element's increment of the step, -
    #: the residual the elements' own noise makes (relative to the same scale as
    #: ``residual``): measured when Newton stalled; NaN if it was not needed
    noise_residual: float = float("nan")
    #: what ended Newton: "tolerance" (``newton_rtol``) or "noise" (the residual is within
    #: the elements' noise and the ceiling: ``NoiseWarning``)
    converged_on: str = "tolerance"
    #: the step's status (femcoupling.status): "converged" (``newton_rtol`` met) or
    #: "stopped_at_scatter" (accepted within the elements' noise, above ``newton_rtol``)
    status: str = "converged"
    #: the accepted residual in stress units, Pa: ``residual`` times the largest element
    #: stress (the residual force over the square root of the domain's area)
    residual_pa: float = float("nan")
    #: the noise's residual in the same units, Pa (NaN if it was not measured)
    noise_residual_pa: float = float("nan")
    #: (n_cells, 3) each element's stress scatter (xx, yy, xy), Pa: the bootstrap of its
    #: contact network (``DemElement.stress_scatter``), how far a sample of its size is from
    #: the material's mean
    element_scatter: np.ndarray | None = None
    #: the relaxation factor of each Newton correction (1: plain Newton)
    relaxation: tuple = ()


def _relative_scatter(r: HierStep) -> float:
    """The elements' mean bootstrap scatter relative to their largest stress component."""
    if r.element_scatter is None:
        return float("nan")
    big = np.abs(r.element_stresses).max(axis=1)
    return float(np.mean(r.element_scatter.max(axis=1) / np.maximum(big, 1e-300)))


class HierarchicalPlaneStrain:
    """See the module doc. ``pool``: an ElementPool with one element per cell (cell k ->
    element k). ``newton_rtol``: the residual's tolerance relative to the internal force
    scale, -; ``noise_factor``: with ``convergence="noise"``, a stalled step is accepted
    within this many times the elements' measured noise ...; ``noise_ceiling``: ... and only
    up to this residual (relative, like ``newton_rtol``; default 10 x ``newton_rtol``), above
    which the step is cut."""

    def __init__(self, pool, *, lx: float, ly: float, nx: int, ny: int,
                 confining_pa: float | None = None, homogeneous: bool = False,
                 newton_rtol: float = 1e-3, max_newton: int = 10, strain_kw: dict | None = None,
                 tangent: str = "network", convergence: str = "noise",
                 relaxation: str | float = "aitken", noise_factor: float = 2.0,
                 noise_ceiling: float | None = None,
                 verbose: bool = False, out=None, overwrite: bool = False) -> None:
        if not (lx > 0 and ly > 0 and math.isfinite(lx) and math.isfinite(ly)):
            raise FemInputError(f"lx={lx}, ly={ly}: must be > 0 (m)")
        if nx < 1 or ny < 1:
            raise FemInputError(f"nx={nx}, ny={ny}: must be >= 1")
        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        import basix
        import basix.ufl

        self.pool, self.lx, self.ly = pool, float(lx), float(ly)
        self.out = None if out is None else Path(out)
        if self.out is not None:
            old = [f for f in ("elements.h5", "fem.xdmf", "fem.h5", "steps.csv", "report.md")
                   if (self.out / f).exists()]
            if old and not overwrite:
                raise FemInputError(f"out={str(self.out)!r}: holds the records of an earlier "
                                    f"run ({', '.join(old)}); give a new folder, or "
                                    "overwrite=True to replace them")
            for f in old:
                (self.out / f).unlink()
        self.verbose = verbose
        self.bad_tangents = 0  # element tangents replaced by their last good one
        if tangent not in TANGENTS:
            raise FemInputError(f"tangent={tangent!r}: one of " + "; ".join(
                f"'{k}' ({v})" for k, v in TANGENTS.items()))
        self.tangent = tangent
        #: what the elements are asked for (the secant is built here from the network one)
        self._element_tangent = "network" if tangent == "secant" else tangent
        self.secants_used = 0  # element tangents replaced by their secant (tangent="secant")
        if convergence not in ("noise", "tolerance"):
            raise FemInputError(f"convergence={convergence!r}: 'noise' (newton_rtol, or, "
                                "when Newton stalls above it, within the elements' measured "
                                "noise) or 'tolerance' (newton_rtol only)")
        self.convergence = convergence
        self.relaxation = check_relaxation(relaxation)
        if not (noise_factor > 0 and math.isfinite(noise_factor)):
            raise FemInputError(f"noise_factor={noise_factor}: must be > 0 (a stalled step is "
                                "accepted within this many times the noise's residual)")
        self.noise_factor = float(noise_factor)
        if not (newton_rtol > 0 and math.isfinite(newton_rtol)):
            raise FemInputError(f"newton_rtol={newton_rtol!r}: must be > 0 (relative to the "
                                "internal force scale)")
        ceiling = 10.0 * newton_rtol if noise_ceiling is None else noise_ceiling
        if not (math.isfinite(ceiling) and ceiling >= newton_rtol):
            raise FemInputError(f"noise_ceiling={noise_ceiling!r}: must be >= newton_rtol="
                                f"{newton_rtol!r} and finite (the largest residual, relative "
                                "to the internal force scale, a step may be accepted at "
                                "within the elements' noise; default 10 x newton_rtol)")
        self.noise_ceiling = float(ceiling)
        #: every warning of the run (also given as ``NoiseWarning``), in order
        self.warnings: list[str] = []
        self.homogeneous = homogeneous
        self.confining_pa = confining_pa
        self.newton_rtol, self.max_newton = newton_rtol, max_newton
        self.strain_kw = dict(strain_kw or {})
        comm = fx.MPI.COMM_SELF
        msh = self.mesh = fx.mesh.create_rectangle(
            comm, [np.array([0.0, 0.0]), np.array([lx, ly])], [nx, ny],
            fx.mesh.CellType.triangle)
        self.n_cells = msh.topology.index_map(2).size_local
        if pool.n != self.n_cells:
            raise FemInputError(f"pool: has {pool.n} elements for {self.n_cells} cells "
                                f"(2 nx ny triangles)")
        self.V = fem.functionspace(msh, ("Lagrange", 1, (2,)))
        qe_v = basix.ufl.quadrature_element("triangle", value_shape=(3,), scheme="default",
                                            degree=1)
        qe_t = basix.ufl.quadrature_element("triangle", value_shape=(3, 3), scheme="default",
                                            degree=1)
        self.Wv, self.Wt = fem.functionspace(msh, qe_v), fem.functionspace(msh, qe_t)
        pts, _ = basix.make_quadrature(basix.CellType.triangle, 1)
        if len(pts) != 1:
            raise RuntimeError("one quadrature point per triangle expected")
        self.u, self.u_n, self.du = (fem.Function(self.V) for _ in range(3))
        self.sig_q, self.tan_q = fem.Function(self.Wv), fem.Function(self.Wt)
        dxq = ufl.Measure("dx", domain=msh, metadata={"quadrature_degree": 1,
                                                       "quadrature_scheme": "default"})
        v, dv = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)

        def eps(w):
            e = ufl.sym(ufl.grad(w))
            return ufl.as_vector([e[0, 0], e[1, 1], 2 * e[0, 1]])

        fdim = 1
        right = fx.mesh.locate_entities_boundary(msh, fdim, lambda x: np.isclose(x[0], lx))
        tags = fx.mesh.meshtags(msh, fdim, np.sort(right), np.full(len(right), 1, np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        st = fx.PETSc.ScalarType
        self.traction = fem.Constant(msh, np.zeros(2, dtype=st))
        f_int = ufl.dot(self.sig_q, eps(v)) * dxq
        self.form_res = fem.form(f_int - ufl.dot(self.traction, v) * ds(1))
        self.form_jac = fem.form(ufl.dot(ufl.dot(self.tan_q, eps(dv)), eps(v)) * dxq)
        # the internal force of a stress field alone (the noise's residual)
        self.sig_noise = fem.Function(self.Wv)
        self.form_noise = fem.form(ufl.dot(self.sig_noise, eps(v)) * dxq)
        self.expr_grad = fem.Expression(ufl.grad(self.u), pts)
        self.expr_grad_n = fem.Expression(ufl.grad(self.u_n), pts)
        # boundary conditions
        self.top_u = fem.Constant(msh, st(0.0))
        self.right_u = fem.Constant(msh, st(0.0))
        V0, V1 = self.V.sub(0), self.V.sub(1)

        def dofs(sub, where):
            facets = fx.mesh.locate_entities_boundary(msh, fdim, where)
            return fem.locate_dofs_topological(sub, fdim, facets)

        self.bcs = [fem.dirichletbc(st(0.0), dofs(V0, lambda x: np.isclose(x[0], 0.0)), V0),
                    fem.dirichletbc(st(0.0), dofs(V1, lambda x: np.isclose(x[1], 0.0)), V1),
                    fem.dirichletbc(self.top_u, dofs(V1, lambda x: np.isclose(x[1], ly)), V1)]
        if homogeneous:
            # every boundary node on the homogeneous field u = (e_x x, e_y y)
            self._hx = fem.Function(self.V.sub(0).collapse()[0])
            self._hy = fem.Function(self.V.sub(1).collapse()[0])
            bnd = lambda x: (np.isclose(x[0], 0) | np.isclose(x[0], lx) |  # noqa: E731
                             np.isclose(x[1], 0) | np.isclose(x[1], ly))
            facets = fx.mesh.locate_entities_boundary(msh, fdim, bnd)
            hdofs = [fem.locate_dofs_topological((V0, self._hx.function_space), fdim, facets),
                     fem.locate_dofs_topological((V1, self._hy.function_space), fdim, facets)]
            self.bcs = [fem.dirichletbc(self._hx, hdofs[0], V0),
                        fem.dirichletbc(self._hy, hdofs[1], V1)]
        else:
            self.bcs.append(None)  # placeholder for the right: traction (confining) or u_x
            if confining_pa is None:
                self.bcs[-1] = fem.dirichletbc(self.right_u,
                                               dofs(V0, lambda x: np.isclose(x[0], lx)), V0)
            else:
                self.traction.value[:] = [-float(confining_pa), 0.0]
            self.bcs = [b for b in self.bcs if b is not None]
        self.A = fx.fem_petsc.create_matrix(self.form_jac)
        self.b = fx.fem_petsc.create_vector(self.V)
        self.b_noise = fx.fem_petsc.create_vector(self.V)
        self.ksp = fx.PETSc.KSP().create(comm)
        self.ksp.setOperators(self.A)
        self.ksp.setType("preonly")
        self.ksp.getPC().setType("lu")
        # the elements' current state: stress and tangent at the start
        self.history: list[HierStep] = []
        first = pool.apply_strain([np.zeros((3, 3))] * pool.n, tangent=self._element_tangent,
                                  **self.strain_kw)
        pool.reject()  # (a zero increment with relaxation: measured, then undone)
        self._increments = np.zeros((pool.n, 3, 3))
        self._set_q(first.stresses, first.tangents)
        self._sig_start = self._sig.copy()  # the element stresses at the step's start

    # ---- quadrature data ----------------------------------------------------------------
    def _set_q(self, stresses, tangents) -> None:
        sig = np.array([fem_stress(s) for s in stresses])
        tan = np.array([fem_tangent(t) for t in tangents])
        if self.tangent == "secant":  # (the first call's increments are zero)
            for k, g in enumerate(self._increments):
                de = np.array([g[0, 0], g[2, 2], g[0, 2] + g[2, 0]])  # (FEM x, y = DEM x, z)
                if np.any(de != 0):
                    c = secant_update(tan[k], de, sig[k] - self._sig_start[k])
                    if c is not None:
                        tan[k] = c
                        self.secants_used += 1
        # A tangent far from positive (its smallest eigenvalue below -10 % of its largest) or
        # not finite is not a softening element but a near-singular network solve: seen as
        # -730 MPa against +3 MPa, and it sent Newton away. Such an element keeps its last good
        # tangent for this iterate (counted in bad_tangents).
        last = getattr(self, "_tan", None)
        for k, c in enumerate(tan):
            ok = bool(np.all(np.isfinite(c)))
            if ok:
                ev = np.linalg.eigvalsh(0.5 * (c + c.T))
                ok = ev[0] >= -0.1 * ev[-1]
            if not ok and last is not None:
                tan[k] = last[k]
                self.bad_tangents += 1
        self._tan = tan
        self.sig_q.x.array[:] = sig.reshape(-1)
        self.tan_q.x.array[:] = tan.reshape(-1)
        self._sig = sig

    def _grad_increment(self) -> np.ndarray:
        cells = np.arange(self.n_cells, dtype=np.int32)
        g = self.expr_grad.eval(self.mesh, cells).reshape(-1, 2, 2)
        gn = self.expr_grad_n.eval(self.mesh, cells).reshape(-1, 2, 2)
        return g - gn

    def _evaluate(self, first: bool, perturb: float = 0.0) -> tuple[float, float, list]:
        """Stress and tangent of every element for the current iterate (its increments
        scaled by 1 + ``perturb``: the noise probe); returns the DEM seconds, the wall
        seconds of the pool call and the recovered elements."""
        if not first:
            self.pool.reject()
        from cpp_dem.elements.pool import ElementError

        self._increments = np.array([dem_increment(g) for g in self._grad_increment()])
        if perturb:
            self._increments *= 1.0 + perturb
        try:
            step = self.pool.apply_strain(list(self._increments),
                                          tangent=self._element_tangent, scatter=True,
                                          **self.strain_kw)
        except ElementError as e:  # an element could not take this iterate: cut the step
            raise NewtonFailure(f"an element failed on this iterate: {e}") from e
        self._set_q(step.stresses, step.tangents)
        self._scat = (None if step.scatters is None else
                      np.array([fem_stress(c) for c in step.scatters]))
        self._last_pool_step = step
        return float(sum(step.cpu_s)), step.wall_s, step.recovered

    def _residual(self) -> float:
        fx = self._fx
        with self.b.localForm() as loc:
            loc.set(0.0)
        fx.fem_petsc.assemble_vector(self.b, self.form_res)
        fx.fem_petsc.apply_lifting(self.b, [self.form_jac], bcs=[self.bcs],
                                   x0=[self.u.x.petsc_vec], alpha=-1.0)
        self.b.ghostUpdate(addv=fx.PETSc.InsertMode.ADD, mode=fx.PETSc.ScatterMode.REVERSE)
        fx.fem_petsc.set_bc(self.b, self.bcs, x0=self.u.x.petsc_vec, alpha=-1.0)
        return self.b.norm()

    def _field_residual(self, field: np.ndarray) -> float:
        """|internal force| (N) of a stress field alone ((n_cells, 3), Pa), Dirichlet rows
        zeroed: the residual that a change of the element stresses by ``field`` makes."""
        fx = self._fx
        self.sig_noise.x.array[:] = np.asarray(field, float).reshape(-1)
        with self.b_noise.localForm() as loc:
            loc.set(0.0)
        fx.fem_petsc.assemble_vector(self.b_noise, self.form_noise)
        self.b_noise.ghostUpdate(addv=fx.PETSc.InsertMode.ADD,
                                 mode=fx.PETSc.ScatterMode.REVERSE)
        fx.fem_petsc.set_bc(self.b_noise, self.bcs, alpha=0.0)
        return float(self.b_noise.norm())

    def _softest(self, n: int = 3) -> str:
        """The ``n`` elements of the current iterate with the smallest tangent eigenvalue:
        index, that eigenvalue (Pa), contacts and mean stress (Pa)."""
        ev = np.array([np.linalg.eigvalsh(0.5 * (c + c.T))[0] for c in self._tan])
        contacts = self._last_pool_step.contacts
        return "; ".join(f"element {k}: smallest tangent eigenvalue {ev[k]:.3g} Pa, "
                         f"{contacts[k]} contacts, mean stress {self._sig[k][:2].mean():.4g} Pa"
                         for k in np.argsort(ev)[:n])

    def _warn(self, msg: str) -> None:
        import warnings

        self.warnings.append(msg)
        warnings.warn(msg, NoiseWarning, stacklevel=3)

    def _scale(self) -> float:
        """|F_int| of the current stresses (the tolerance's scale)."""
        return float(np.abs(self._sig).max()) * math.sqrt(self.lx * self.ly) + 1e-300

    @property
    def status(self) -> str:
        """The run's status so far: the worst of its accepted steps' ("converged" before
        any). A step that could not be accepted raised ``NewtonFailure``: the run failed."""
        return worst(r.status for r in self.history)

    # ---- a load step -----------------------------------------------------------------------
    def step(self, *, top_displacement: float, right_displacement: float = 0.0,
             max_cuts: int = 4) -> HierStep:
        """One load step to the given boundary displacements (m, total since the start). If
        Newton fails, the step is rolled back (the elements to their accepted state, u to
        u_n) and taken in two halves, at most ``max_cuts`` times deep; the last half-step's
        record is returned (all of them are in ``history``)."""
        try:
            return self._step(top_displacement, right_displacement)
        except NewtonFailure:
            if max_cuts <= 0:
                raise
            self.pool.reject()
            self.u.x.array[:] = self.u_n.x.array
            self.u.x.scatter_forward()
            t0, r0 = self._bc_now
            self.step(top_displacement=0.5 * (t0 + top_displacement),
                      right_displacement=0.5 * (r0 + right_displacement),
                      max_cuts=max_cuts - 1)
            return self.step(top_displacement=top_displacement,
                             right_displacement=right_displacement, max_cuts=max_cuts - 1)

    _bc_now = (0.0, 0.0)  # the boundary displacements of the last accepted step, m

    def _step(self, top_displacement: float, right_displacement: float) -> HierStep:
        t0 = time.perf_counter()
        fx = self._fx
        self.top_u.value = top_displacement
        self.right_u.value = right_displacement
        if self.homogeneous:
            ex, ey = right_displacement / self.lx, top_displacement / self.ly
            self._hx.interpolate(lambda x: ex * x[0])
            self._hy.interpolate(lambda x: ey * x[1])
        dem_s = pool_s = 0.0
        recovered: list = []
        rel = noise_rel = float("nan")
        its = 0
        omega, d_prev, omegas = 1.0, None, []
        converged_on = "tolerance"
        probe = self.convergence == "noise"
        hist: list[float] = []
        for it in range(self.max_newton + 1):
            d, w, rec = self._evaluate(first=(it == 0))
            dem_s, pool_s, recovered = dem_s + d, pool_s + w, recovered + rec
            rnorm = self._residual()
            scale = self._scale()
            rel = rnorm / scale
            hist.append(rel)
            if self.verbose:
                print(f"[hier] iteration {it}: residual {rel:.3e}", flush=True)
            its = it
            if it > 0 and rel <= self.newton_rtol:
                converged_on = "tolerance"
                break
            stalled = it == self.max_newton or (len(hist) >= 3 and rel > 0.5 * hist[-3])
            if probe and it > 0 and stalled:
                # Newton stalls above the tolerance: measure the elements' noise. Re-run
                # every element on its increment scaled by 1 + 1e-9: the deterministic
                # answer moves by 1e-9, the DEM's by its noise (its relaxation to a
                # tolerance and the chaos of a granular packing). The residual of that
                # change is what no Newton iterate can get below. (The largest of the step's
                # probes counts; after a probe, two more iterations before the next.)
                before = self._sig.copy()
                d, w, rec = self._evaluate(first=False, perturb=1e-9)
                dem_s, pool_s, recovered = dem_s + d, pool_s + w, recovered + rec
                v = self._field_residual(self._sig - before) / scale
                noise_rel = v if math.isnan(noise_rel) else max(noise_rel, v)
                rel = self._residual() / scale
                hist = [rel]
                if self.verbose:
                    print(f"[hier] noise probe: residual {rel:.3e}, the noise's "
                          f"{noise_rel:.3e}", flush=True)
                accept = newton_acceptance(rel, rtol=self.newton_rtol,
                                           noise_residual=noise_rel,
                                           noise_factor=self.noise_factor,
                                           ceiling=self.noise_ceiling)
                if accept == "converged":
                    converged_on = "tolerance"
                    break
                if accept == "stopped_at_scatter":
                    converged_on = "noise"
                    break
                if rel <= self.noise_factor * noise_rel:
                    # within the noise but above the ceiling: not accepted; cut the step
                    raise NewtonFailure(
                        f"Newton stalled at {rel:.3g} of the internal force scale, within "
                        f"the elements' noise ({noise_rel:.3g}) but above the ceiling "
                        f"noise_ceiling={self.noise_ceiling:g} (asked newton_rtol="
                        f"{self.newton_rtol:g}): the step is cut")
            if it == self.max_newton or not math.isfinite(rel):
                raise NewtonFailure(f"Newton: no convergence in {self.max_newton} iterations "
                                    f"(residual {rel:.3g} of the internal force scale; asked "
                                    f"{self.newton_rtol}; the elements' noise makes "
                                    f"{noise_rel:.3g})")
            self.A.zeroEntries()
            fx.fem_petsc.assemble_matrix(self.A, self.form_jac, bcs=self.bcs)
            self.A.assemble()
            self.ksp.setOperators(self.A)
            self.ksp.solve(self.b, self.du.x.petsc_vec)
            self.du.x.scatter_forward()
            if not np.all(np.isfinite(self.du.x.array)):
                # (a singular Jacobian: softening elements whose tangents lost stiffness)
                raise NewtonFailure("the Newton correction is not finite (singular Jacobian"
                                    f"; the softest elements: {self._softest()})")
            dk = -self.du.x.array.copy()  # the full Newton correction
            omega = next_factor(self.relaxation, omega, d_prev, dk)
            # (the first correction of a step is a full one: it also puts u on the boundary
            # values)
            w_k = 1.0 if it == 0 else omega
            omegas.append(w_k)
            d_prev = dk
            self.u.x.array[:] += w_k * dk
            self.u.x.scatter_forward()
        stress_of_scale = scale / math.sqrt(self.lx * self.ly)  # Pa: the largest stress
        if converged_on == "noise":
            self._warn(f"load step {len(self.history)} (top {top_displacement:.6g} m): the "
                       f"tolerance asked (newton_rtol={self.newton_rtol:g}) is below the "
                       f"elements' noise (a 1e-9 change of their increments moves the "
                       f"residual by {noise_rel:.3g} of the internal force scale); stopped "
                       f"at the noise at {rel:.3g} ({rel * stress_of_scale:.3g} Pa; ceiling "
                       f"{self.noise_ceiling:g}): stopped_at_scatter, not converged")
        self.pool.accept()
        self._sig_start = self._sig.copy()
        self._bc_now = (top_displacement, right_displacement)
        self.u_n.x.array[:] = self.u.x.array
        wall = time.perf_counter() - t0
        r = HierStep(load=top_displacement, iterations=its, residual=rel,
                     mean_stress=self._sig.mean(axis=0), element_stresses=self._sig.copy(),
                     dem_s=dem_s, fem_s=wall - pool_s, wall_s=wall, recovered=recovered,
                     increments=self._increments.copy(), noise_residual=noise_rel,
                     converged_on=converged_on, relaxation=tuple(omegas),
                     element_scatter=self._scat.copy(),
                     status="converged" if converged_on == "tolerance" else "stopped_at_scatter",
                     residual_pa=rel * stress_of_scale,
                     noise_residual_pa=noise_rel * stress_of_scale)
        self.history.append(r)
        if self.out is not None:
            self._write_records(r)
        return r

    # ---- records -----------------------------------------------------------------------------
    def _write_records(self, r: HierStep) -> None:
        """Appends the accepted step to ``out``: one row per element in ``elements.h5`` (the
        step, its load, the element, its displacement-gradient increment, stress (tension
        positive, Pa), its bootstrap scatter (Pa), tangent (Voigt 6 x 6, Pa), contact count,
        DEM seconds and steps),
        flushed; the FEM state in ``fem.xdmf`` (displacement m, the elements' stress Pa per
        cell, at the load as time); and a line of ``steps.csv`` with the FEM/DEM time split."""
        from femcoupling.records import append_rows

        self.out.mkdir(parents=True, exist_ok=True)
        ps = self._last_pool_step
        n = self.n_cells
        k = len(self.history) - 1
        rows = {
            "step": np.full(n, k, dtype=np.int64),
            "load_m": np.full(n, r.load),
            "element": np.arange(n, dtype=np.int64),
            "increment": np.asarray(r.increments, float).reshape(n, 3, 3),
            "stress_pa": np.asarray(ps.stresses, float).reshape(n, 3, 3),
            "tangent_pa": np.array([np.full((6, 6), np.nan) if t is None else t
                                    for t in ps.tangents], float).reshape(n, 6, 6),
            "scatter_pa": np.asarray(ps.scatters, float).reshape(n, 3, 3),
            "contacts": np.asarray(ps.contacts, dtype=np.int64),
            "cpu_s": np.asarray(ps.cpu_s, float),
            "dem_steps": np.asarray(ps.steps, dtype=np.int64),
        }
        append_rows(self.out / "elements.h5", rows,
                    units=("SI; stress tension positive; increment: displacement-gradient "
                           "increment of the step, the element's (x, y, z) with the FEM's "
                           "(x, y) as (x, z)"))
        self._write_xdmf(r, append=k > 0)
        csv = self.out / "steps.csv"
        new = not csv.exists()
        with open(csv, "a") as fh:
            if new:
                fh.write("step,load_m,iterations,residual,noise_residual,converged_on,"
                         "relaxation_min,fem_s,dem_s,wall_s,recovered,bad_tangents,status,"
                         "residual_pa,noise_residual_pa\n")
            fh.write(f"{k},{r.load!r},{r.iterations},{r.residual!r},{r.noise_residual!r},"
                     f"{r.converged_on},{min(r.relaxation, default=1.0)!r},{r.fem_s!r},"
                     f"{r.dem_s!r},{r.wall_s!r},{len(r.recovered)},{self.bad_tangents},"
                     f"{r.status},{r.residual_pa!r},{r.noise_residual_pa!r}\n")
        self._write_report()

    def _write_report(self) -> None:
        """``report.md``: the run so far: per load step the Newton iterations, residual,
        noise and what converged it, and the elements' scatter; the FEM/DEM CPU split; and
        every warning. Rewritten
        at every accepted step."""
        h = self.history
        fem_s = sum(r.fem_s for r in h)
        dem_s = sum(r.dem_s for r in h)
        wall_s = sum(r.wall_s for r in h)
        lines = ["# Hierarchical FEM x DEM run", "",
                 f"- status: **{self.status}** (the worst of the steps'; converged: every "
                 f"step's residual within newton_rtol; stopped_at_scatter: a step accepted "
                 f"within the elements' noise, above newton_rtol)",
                 f"- {self.n_cells} elements, {len(h)} load steps accepted; tangent "
                 f"`{self.tangent}`, convergence `{self.convergence}` (newton_rtol "
                 f"{self.newton_rtol:g}, noise factor {self.noise_factor:g}, noise ceiling "
                 f"{self.noise_ceiling:g}), relaxation `{self.relaxation}`",
                 f"- CPU: FEM {fem_s:.2f} s (the wall time outside the element calls), DEM "
                 f"{dem_s:.2f} s (the elements' work summed over workers), wall {wall_s:.2f} s"
                 f"; DEM share of the work {dem_s / max(fem_s + dem_s, 1e-300):.1%}",
                 f"- element tangents replaced by their last good one: {self.bad_tangents}",
                 "- element scatter: the bootstrap standard deviation of each element's "
                 "stress over its contacts, as a fraction of its largest stress component, "
                 "mean over the elements",
                 "", "| step | top, m | iterations | residual | residual, Pa | noise residual "
                 "| status | converged on | min relaxation | mean sigma_xx, kPa | mean "
                 "sigma_yy, kPa | element scatter |",
                 "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for k, r in enumerate(h):
            lines.append(f"| {k} | {r.load:.6g} | {r.iterations} | {r.residual:.3g} | "
                         f"{r.residual_pa:.3g} | {r.noise_residual:.3g} | {r.status} | "
                         f"{r.converged_on} | "
                         f"{min(r.relaxation, default=1.0):.3g} | "
                         f"{r.mean_stress[0] / 1e3:.2f} | {r.mean_stress[1] / 1e3:.2f} | "
                         f"{_relative_scatter(r):.3f} |")
        lines += ["", f"## Warnings ({len(self.warnings)})", ""]
        lines += [f"- {w}" for w in self.warnings] or ["none"]
        (self.out / "report.md").write_text("\n".join(lines) + "\n")

    def _write_xdmf(self, r: HierStep, append: bool) -> None:
        fx = self._fx
        fem = fx.fem
        import dolfinx.io

        T = fem.functionspace(self.mesh, ("DG", 0, (3, 3)))
        sig = fem.Function(T, name="stress_pa")
        st = np.asarray(self._last_pool_step.stresses, float).reshape(self.n_cells, 9)
        sig.x.array[:] = st.reshape(-1)[: sig.x.array.size]
        self.u.name = "displacement_m"
        with dolfinx.io.XDMFFile(self.mesh.comm, str(self.out / "fem.xdmf"),
                                 "a" if append else "w") as xf:
            if not append:
                xf.write_mesh(self.mesh)
            xf.write_function(self.u, r.load)
            xf.write_function(sig, r.load)
