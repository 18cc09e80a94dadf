"""The part of :class:`femcoupling.fem.model.FemModel` for a body of
:mod:`femcoupling.fem.bodies` with a DEM element at every quadrature point: the hierarchical
mode (the model's module doc; docs/coupling_hierarchical.md)."""

from __future__ import annotations

import math
import time

import numpy as np
from cpp_dem import fixedorder

from femcoupling import _dolfinx
from femcoupling._checks import FemInputError, _max_newton, _newton_rtol
from femcoupling.coupling.records import ElementRecords
from femcoupling.coupling.relaxation import check_relaxation
from femcoupling.fem.bodies import point_coordinates
from femcoupling.fem.mpi_points import PointPartition, RootMaterial, bcast_from_root, check_on_root
from femcoupling.fem.nonlocal_strain import NonlocalStrain
from femcoupling.fem.quadrature import (NewtonRules, QuadratureSystem, check_material, lu_package,
                                        newton_solve)
from femcoupling.fem.solver import body_kind
from femcoupling.fem.steps import LoadStep, NewtonFailure
from femcoupling.materials.element_pool import TANGENTS, ElementPoolMaterial

__all__ = ["ElementPart"]


@body_kind("elements", "a model of a body of femcoupling.fem.bodies (Rectangle, Box, "
           "Cylinder) with DEM elements at its points; the reinforced soil body is "
           "loaded by its stages")
class ElementPart:
    """The part of :class:`femcoupling.fem.model.FemModel` for a body of
    :mod:`femcoupling.fem.bodies` (``Rectangle``, ``Box``, ``Cylinder``) with a DEM element
    at every quadrature point (the hierarchical mode; the model's module doc)."""

    def _build_elements(self, body, *, elements, newton_rtol: float = 1e-3,
                        max_newton: int = 10, tangent: str = "network",
                        strain_kw: dict | None = None, convergence: str = "noise",
                        relaxation: str | float = "aitken", noise_factor: float = 2.0,
                        noise_ceiling: float | None = None, nonlocal_length: float | None = None,
                        nonlocal_weight: float = 1.0, comm=None, verbose: bool = False,
                        out=None, overwrite: bool = False) -> None:
        """The model of a body of :mod:`femcoupling.fem.bodies` with the pool's elements at
        its points (``FemModel``'s arguments)."""
        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        self.pool, self.comm = elements, comm  # (self.body: FemModel's)
        if nonlocal_length is None and nonlocal_weight != 1.0:
            raise FemInputError(f"nonlocal_weight={nonlocal_weight!r}: given without "
                                "nonlocal_length (the averaging's length, m)")
        if nonlocal_length is not None and self._parallel:
            raise FemInputError(f"nonlocal_length={nonlocal_length!r}: serial only (its "
                                "Jacobian is built on one rank); run without comm")
        self.gdim, self.degree = body.gdim, body.degree
        self.records = None
        if out is not None:
            self.records = ElementRecords(out, overwrite=overwrite, root=self._root,
                                          comm=comm)
        self._options(verbose=verbose, tangent=tangent, convergence=convergence,
                      relaxation=relaxation, noise_factor=noise_factor,
                      noise_ceiling=noise_ceiling, newton_rtol=newton_rtol,
                      max_newton=max_newton)
        self.strain_kw = dict(strain_kw or {})
        msh = self.mesh = body.mesh(fx, comm)
        self.n_cells = msh.topology.index_map(msh.topology.dim).size_local  # (this rank's)
        self._check_pool(elements, *body.expected_points(self))
        loads = body.loads(self, msh)
        # spaces, forms and solver: the same as the FEM soil's (femcoupling.fem.quadrature)
        sysq = self.system = QuadratureSystem(
            msh, degree=body.degree, qdeg=body.qdeg, ncomp=body.ncomp,
            strain=lambda w: body.strain(ufl, w), loads=loads,
            lu=lu_package(self.comm))
        self.V, self.Wv, self.Wt = sysq.V, sysq.Wv, sysq.Wt
        self._points(body.nq)
        self.u, self.u_n, self.du = sysq.u, sysq.u_n, sysq.du
        self.sig_q, self.tan_q = sysq.sig_q, sysq.tan_q
        self.expr_grad = fem.Expression(ufl.grad(self.u), sysq.qpoints)
        self.expr_grad_n = fem.Expression(ufl.grad(self.u_n), sysq.qpoints)
        self.bcs = body.bcs(self)
        self._bc_now = body.start()  # the boundary of the last accepted step
        #: the elements as the quadrature points' material (femcoupling.fem.quadrature)
        self._material(elements, tangent=tangent, strain_kw=self.strain_kw, dim=body.dim)
        if nonlocal_length is not None:
            self.nonlocal_strain = NonlocalStrain(
                self.point_coordinates, self.element_volumes, nonlocal_length, nonlocal_weight)
            self._nonlocal_operators(body)

    partition = None  #: each rank's points as elements under MPI (mpi_points.PointPartition)
    nonlocal_strain = None  #: the averaging (femcoupling.fem.nonlocal_strain); None: local

    @property
    def _parallel(self) -> bool:
        """Whether the FEM is split over more than one MPI rank."""
        return self.comm is not None and self.comm.size > 1

    @property
    def _root(self) -> bool:
        """Whether this is the rank that writes the records (rank 0; serial: True)."""
        return self.comm is None or self.comm.rank == 0

    def _check_pool(self, pool, n: int, what: str) -> None:
        """The pool (rank 0's under MPI) holds one element per quadrature point."""
        if self._parallel:
            check_on_root(self.comm, pool)
            have = bcast_from_root(self.comm, pool.n if self._root else None)
        elif pool is None or not hasattr(pool, "n"):
            raise FemInputError(f"elements={pool!r}: an ElementPool with one element per "
                                f"quadrature point ({n} {what}); None only on the MPI ranks "
                                "other than 0")
        else:
            have = pool.n
        if have != n:
            raise FemInputError(f"pool: has {have} elements for {n} {what}")

    def _material(self, pool, **kw) -> None:
        """The elements as the points' material: ``ElementPoolMaterial`` (under MPI on rank 0,
        seen by every rank: ``femcoupling.fem.mpi_points.RootMaterial``)."""
        mat = ElementPoolMaterial(pool, **kw) if pool is not None else None
        if self._parallel:
            mat = RootMaterial(self.comm, mat)
        check_material(mat, "material", "gradient")
        #: the elements as the quadrature points' material (femcoupling.fem.quadrature)
        self.material = mat
        self._set_q(mat.stress, mat.tangent)

    def _options(self, *, verbose: bool, tangent: str, convergence: str, relaxation,
                 noise_factor: float, noise_ceiling: float | None, newton_rtol: float,
                 max_newton: int) -> None:
        """Checks and keeps the solver's options."""
        self.verbose = verbose
        tangents = self.body.tangents
        if tangent not in tangents:
            raise FemInputError(f"tangent={tangent!r}: one of " + "; ".join(
                f"'{k}' ({TANGENTS[k]})" for k in tangents))
        self.tangent = tangent
        if convergence not in ("noise", "tolerance"):
            raise FemInputError(f"convergence={convergence!r}: 'noise' (newton_rtol, or, "
                                "when Newton stalls above it, within the elements' measured "
                                "noise) or 'tolerance' (newton_rtol only)")
        self.convergence = convergence
        self.relaxation = check_relaxation(relaxation)
        if not (noise_factor > 0 and math.isfinite(noise_factor)):
            raise FemInputError(f"noise_factor={noise_factor}: must be > 0 (a stalled step is "
                                "accepted within this many times the noise's residual)")
        _newton_rtol(newton_rtol)
        _max_newton(max_newton)
        ceiling = 10.0 * newton_rtol if noise_ceiling is None else noise_ceiling
        if not (math.isfinite(ceiling) and ceiling >= newton_rtol):
            raise FemInputError(f"noise_ceiling={noise_ceiling!r}: must be >= newton_rtol="
                                f"{newton_rtol!r} and finite (the largest residual, relative "
                                "to the internal force scale, a step may be accepted at "
                                "within the elements' noise; default 10 x newton_rtol)")
        self._solver_options(newton_rtol=newton_rtol, max_newton=max_newton,
                             noise_factor=noise_factor, noise_ceiling=ceiling)

    # ---- the elements' material ---------------------------------------------------------
    @property
    def bad_tangents(self) -> int:
        """Element tangents replaced by their last good one (``ElementPoolMaterial``)."""
        return self.material.bad_tangents

    @property
    def secants_used(self) -> int:
        """Element tangents replaced by their secant (tangent="secant")."""
        return self.material.secants_used

    @property
    def _sig(self) -> np.ndarray:
        return self.material.stress

    @property
    def _tan(self) -> np.ndarray:
        return self.material.tangent

    @property
    def _last_pool_step(self):
        return self.material.last_step

    def _points(self, nq: int) -> None:
        """The quadrature points: ``nq`` per cell, element k at cell k // nq, point k % nq (the
        quadrature spaces' own order, checked). Under MPI a rank's points are the elements
        at their places in the serial mesh (``femcoupling.fem.mpi_points.PointPartition``)."""
        if len(self.system.qweights) != nq:
            raise RuntimeError(f"{nq} quadrature point(s) per cell expected")
        self.nq, self.n_local_points = nq, self.n_cells * nq
        if not np.array_equal(self.Wv.dofmap.list[: self.n_cells].reshape(-1),
                              np.arange(self.n_local_points)):
            raise RuntimeError("the quadrature space's points are not in (cell, point) order")
        self.partition = None
        self.n_points = self.n_local_points
        if self._parallel:
            serial = point_coordinates(self._fx, self.body.serial_mesh(self._fx),
                                       self.system.qpoints)
            self.partition = PointPartition(self.comm, self._local_coordinates(), serial,
                                            self.body.size())
            self.n_points = self.partition.n

    def _local(self, values: np.ndarray) -> np.ndarray:
        """This rank's rows of a per-element array (serial: all of it)."""
        return values if self.partition is None else self.partition.local(values)

    def _put(self, f, values: np.ndarray) -> None:
        """A quadrature function ``f`` at this rank's points from a per-element array (its
        ghost points, under MPI, from their owners)."""
        v = np.asarray(self._local(values), float).reshape(-1)
        f.x.array[: v.size] = v
        f.x.scatter_forward()

    def _set_q(self, sig: np.ndarray, tan: np.ndarray) -> None:
        self._put(self.sig_q, sig)
        self._put(self.tan_q, tan)

    def _local_coordinates(self) -> np.ndarray:
        return point_coordinates(self._fx, self.mesh, self.system.qpoints)

    @property
    def point_coordinates(self) -> np.ndarray:
        """The quadrature points' coordinates, m, shape (n_points, gdim), in element order (on
        every rank)."""
        x = self._local_coordinates()
        return x if self.partition is None else self.partition.gather(x)

    def _grad_increment(self) -> np.ndarray:
        """Every element's displacement-gradient increment since the step's start (under MPI
        gathered from the ranks, on every rank), (n_points, gdim, gdim), -."""
        cells = np.arange(self.n_cells, dtype=np.int32)
        d = self.gdim
        g = self.expr_grad.eval(self.mesh, cells).reshape(-1, d, d)
        gn = self.expr_grad_n.eval(self.mesh, cells).reshape(-1, d, d)
        return g - gn if self.partition is None else self.partition.gather(g - gn)

    def _evaluate(self, first: bool, perturb: float = 0.0) -> None:
        """Stress and tangent of every element for the current iterate (its increments
        scaled by 1 + ``perturb``: the noise probe)."""
        g = self._grad_increment()
        if self.nonlocal_strain is not None:
            g = self.nonlocal_strain.apply(g)
        self._set_q(*self.material.trial(g * (1.0 + perturb) if perturb else g))

    # ---- the nonlocal strain's Jacobian (serial) -------------------------------------------
    def _nonlocal_operators(self, body) -> None:
        """What the consistent Jacobian of the nonlocal strain needs, made once: G, the strain
        at the points weighted by their quadrature weights W (row (point, component), column
        a dof); the averaged strain of the dofs, (A x I) W^-1 G; and the mask of the dofs the
        boundary conditions constrain (their values change from step to step, not the
        dofs)."""
        import scipy.sparse as sp

        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        q, dv = ufl.TestFunction(self.Wv), ufl.TrialFunction(self.V)
        dxq = self.system.dxq
        nc = body.ncomp
        mat = fx.fem_petsc.assemble_matrix(fem.form(ufl.dot(body.strain(ufl, dv), q) * dxq))
        mat.assemble()
        indptr, indices, values = mat.getValuesCSR()
        G = sp.csr_matrix((values, indices, indptr), shape=mat.getSize())
        mat.destroy()
        w = fem.assemble_vector(fem.form(q[0] * dxq)).array
        w = np.asarray(w[: self.n_local_points * nc:nc], float)
        if G.shape[0] != self.n_local_points * nc or np.any(w <= 0):
            raise RuntimeError("the nonlocal Jacobian's operators do not match the points")
        avg = sp.kron(self.nonlocal_strain.operator(), sp.identity(nc), format="csr")
        winv = sp.diags(np.repeat(1.0 / w, nc))
        self._nl_G, self._nl_AG = G, avg @ (winv @ G)
        self._nl_fixed = self._constrained()

    def _constrained(self) -> np.ndarray:
        """A mask of the dofs the boundary conditions constrain (serial)."""
        fx = self._fx
        marks = []
        for x0 in (0.0, 1.0):
            v = fx.fem_petsc.create_vector(self.V)
            with v.localForm() as loc:
                loc.set(0.0)
            x = v.copy()
            x.set(x0)
            fx.fem_petsc.set_bc(v, self.bcs, x0=x, alpha=-1.0)
            marks.append(v.getArray().copy())
            v.destroy()
            x.destroy()
        return marks[0] != marks[1]

    def _unlifted_residual(self) -> np.ndarray:
        """R(u) at the free dofs and u - g at the constrained ones (serial), as an array."""
        fx = self._fx
        v = fx.fem_petsc.create_vector(self.V)
        with v.localForm() as loc:
            loc.set(0.0)
        fx.fem_petsc.assemble_vector(v, self.system.form_res)
        v.ghostUpdate(addv=fx.PETSc.InsertMode.ADD, mode=fx.PETSc.ScatterMode.REVERSE)
        fx.fem_petsc.set_bc(v, self.bcs, x0=self.u.x.petsc_vec, alpha=-1.0)
        b = v.getArray().copy()
        v.destroy()
        return b

    def _nonlocal_correction(self, describe) -> np.ndarray:
        """Newton's correction with the nonlocal strain's consistent Jacobian (serial):
        K = G^T D (A x I) W^-1 G, D the elements' tangents, A the averaging (a point's force
        answers to the strains around it), W the points' weights; the constrained dofs'
        rows the identity. Solves K du = b, b the residual with u - g at the constrained
        dofs, and returns -du, as ``QuadratureSystem.correction``."""
        import scipy.sparse as sp
        from scipy.sparse.linalg import splu

        tan = sp.block_diag(list(np.asarray(self._tan, float)), format="csr")
        K = (self._nl_G.T @ (tan @ self._nl_AG)).tocsr()
        # the free rows whole (their columns at the constrained dofs carry the prescribed
        # increment: the lifting, consistent), the constrained rows the identity; the
        # residual unlifted, u - g at the constrained dofs (dolfinx's Newton convention)
        fixed = self._nl_fixed
        K = (sp.diags((~fixed).astype(float)) @ K + sp.diags(fixed.astype(float))).tocsc()
        b = self._unlifted_residual()
        try:
            du = splu(K).solve(b)
        except RuntimeError as exc:  # (a singular factor)
            du = np.full_like(b, np.nan)
            why = f" ({exc})"
        else:
            why = ""
        if not np.all(np.isfinite(du)):
            raise NewtonFailure(f"the Newton correction failed (the nonlocal Jacobian is "
                                f"singular{why}; {describe()})")
        self.system.du.x.array[: du.size] = du
        self.system.du.x.scatter_forward()
        return -self.system.du.x.array.copy()

    def _softest(self, n: int = 3) -> str:
        """The ``n`` elements of the current iterate with the smallest tangent eigenvalue:
        index, that eigenvalue (Pa), contacts and mean stress (Pa)."""
        ev = np.array([fixedorder.eigvalsh(0.5 * (c + c.T))[0] for c in self._tan])
        contacts = self._last_pool_step.contacts
        return "; ".join(f"element {k}: smallest tangent eigenvalue {ev[k]:.3g} Pa, "
                         f"{contacts[k]} contacts, mean stress {self._sig[k][:2].mean():.4g} Pa"
                         for k in np.argsort(ev, kind="stable")[:n])

    def _scale(self) -> float:
        """|F_int| of the current stresses (the tolerance's scale)."""
        return float(np.abs(self._sig).max()) * self.body.scale_length() + 1e-300

    # ---- a load step -----------------------------------------------------------------------
    def step(self, *, max_cuts: int = 4, **boundary) -> LoadStep:
        """One load step to the boundary values ``boundary`` (total since the start; what a
        body takes: ``Rectangle``: ``top_displacement=`` and ``right_displacement=``, m;
        ``Box``, ``Cylinder``: ``top_displacement=``, m, or, homogeneous, ``gradient=``, a
        3 x 3 displacement gradient). If Newton fails, the step is rolled back (the elements
        to their accepted state, u to u_n) and halved, at most ``max_cuts`` (a whole number
        in [0, 20]) times below the whole step (``femcoupling.fem.steps.load_path``, the loop
        of every model: an easy half-step grows the next back); the last accepted step's
        record is returned (all of them are in ``history``). Past ``max_cuts``, the model is
        left at its last accepted step and :class:`~femcoupling.fem.steps.NewtonFailure` says
        where the load stopped."""
        target = self.body.target(**boundary)
        a, b = np.asarray(self._bc_now, float), np.asarray(target, float)

        def at(lf: float):
            """The boundary at load factor ``lf`` from the accepted one to ``target``."""
            return target if lf == 1.0 else a + lf * (b - a)

        return self._load(lambda lf: self._step(at(lf), lf),
                          lambda lf: self.body.apply(self, at(lf)), steps=1,
                          max_cuts=max_cuts, where=f"load step {len(self.history)}")[-1]

    def _step(self, point, load_factor: float = 1.0) -> LoadStep:
        t0 = time.perf_counter()
        load = self.body.apply(self, point)
        mat = self.material
        mat.new_step_counters()
        rules = NewtonRules(rtol=self.newton_rtol, max_newton=self.max_newton,
                            noise_factor=self.noise_factor, ceiling=self.noise_ceiling,
                            probe=self.convergence == "noise")
        log = ((lambda msg: print(f"[hier] {msg}", flush=True))
               if self.verbose and self._root else None)
        out = newton_solve(_ElementNewton(self), rules, relaxation=self.relaxation, log=log)
        rel, noise_rel, its = out.residual, out.noise_residual, out.iterations
        stress_of_scale = out.scale / self.body.scale_length()  # Pa: the largest stress
        if out.converged_on == "noise":
            self._warn(f"load step {len(self.history)} (top {load:.6g} m): the "
                       f"tolerance asked (newton_rtol={self.newton_rtol:g}) is below the "
                       f"elements' noise (a 1e-9 change of their increments moves the "
                       f"residual by {noise_rel:.3g} of the internal force scale); stopped "
                       f"at the noise at {rel:.3g} ({rel * stress_of_scale:.3g} Pa; ceiling "
                       f"{self.noise_ceiling:g}): stopped_at_scatter, not converged")
        mat.commit()
        self._bc_now = point
        self.u_n.x.array[:] = self.u.x.array
        wall = time.perf_counter() - t0
        footing = getattr(self.body, "platens", None) == "footing"
        r = LoadStep(load=load, load_factor=load_factor, newton_iterations=its, residual=rel,
                     mean_stress=self._sig.mean(axis=0), element_stresses=self._sig.copy(),
                     dem_s=mat.step_dem_s, fem_s=wall - mat.step_pool_s, wall_s=wall,
                     recovered=mat.step_recovered, increments=mat.increments.copy(),
                     noise_residual=noise_rel, converged_on=out.converged_on,
                     relaxation=out.relaxation, redraws=out.redraws,
                     element_scatter=mat.scatter.copy(),
                     status=out.status, residual_pa=rel * stress_of_scale,
                     noise_residual_pa=noise_rel * stress_of_scale,
                     footing_settlement_m=(self.footing_settlement_m() if footing
                                           else float("nan")),
                     footing_pressure_pa=(self.footing_pressure_pa() if footing
                                          else float("nan")))
        self.history.append(r)
        if self.records is not None:
            self.records.write(self, r)
        return r

    # ---- what the body's elements give ----------------------------------------------------
    @property
    def element_volumes(self) -> np.ndarray:
        """(n,) each element's cell's volume (m^3; in 2D its area, m^2, per metre out of
        plane), in element order (collective under MPI): the weights of the body's mean
        stress. (A cell's points share its volume equally.)"""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        dg0 = fem.functionspace(self.mesh, ("DG", 0))
        vol = fem.assemble_vector(fem.form(ufl.TestFunction(dg0) * ufl.dx)).array
        own = np.repeat(np.asarray(vol[: self.n_cells], float) / self.nq, self.nq)
        return own if self.partition is None else self.partition.gather(own)

    def volume_mean_stress(self, step=None) -> np.ndarray:
        """The body's volume-mean stress of a step (the last if None), in the elements'
        Voigt order, tension positive, Pa. (``LoadStep.mean_stress`` is the elements'
        unweighted mean.)"""
        r = self.history[-1] if step is None else step
        w = self.element_volumes
        return fixedorder.weighted_rows(w, r.element_stresses) / math.fsum(w)


class _ElementNewton:
    """A ``FemModel`` of elements as ``femcoupling.fem.quadrature.newton_solve``'s problem."""

    def __init__(self, m) -> None:
        self.m = m

    def evaluate(self, first: bool, perturb: float = 0.0) -> None:
        self.m._evaluate(first, perturb)

    def residual(self) -> float:
        return self.m.system.residual(self.m.bcs)

    def force_scale(self) -> float:
        return self.m._scale()

    def at_boundary_values(self) -> bool:
        return self.m.system.at_boundary_values(self.m.bcs)

    noise_scale = force_scale  # (every point is a DEM element)

    def stresses(self) -> np.ndarray:
        return self.m._sig.copy()

    def stress_change_residual(self, before: np.ndarray) -> float:
        return self.m.system.change_residual(self.m._sig - before, self.m.bcs, self.m._put)

    def correction(self) -> np.ndarray:
        def describe():
            return (f"softening elements whose tangents lost stiffness; the softest elements: "
                    f"{self.m._softest()}")

        if self.m.nonlocal_strain is not None:
            return self.m._nonlocal_correction(describe)
        return self.m.system.correction(self.m.bcs, describe=describe)

    def move(self, correction: np.ndarray, factor: float) -> None:
        self.m.system.move(correction, factor)
