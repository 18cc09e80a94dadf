"""Hierarchical FEM x DEM in 3D: a periodic DEM element at the quadrature point of every
tetrahedron (docs/coupling_hierarchical.md, "In 3D: a box"), in a box
(:class:`Hierarchical3D`) or a cylindrical triaxial specimen (:class:`HierarchicalCylinder`,
meshed by gmsh; the box's geometry is a set of hooks the cylinder replaces).

The FEM is a box ``lx`` x ``ly`` x ``lz`` (m) of P1 tetrahedra (dolfinx's ``create_box``: six
per hexahedron of an ``nx`` x ``ny`` x ``nz`` grid), one quadrature point each; the pool's
element k is cell k. Everything else is the plane-strain mode's
(:class:`femcoupling.coupling.hierarchical.HierarchicalPlaneStrain`): the elements as the points'
material (``ElementPoolMaterial(dim=3)``: each element takes the full displacement-gradient
increment of its point, rotation included, and returns its stress and tangent in its own
Voigt order xx, yy, zz, yz, xz, xy with engineering shear), Newton and its acceptance
(``femcoupling.fem.quadrature.newton_solve``), step cuts, records (``out=``) and statuses.

Loading (``step``):

- ``homogeneous=True``: every boundary node on u = G x, G the total displacement gradient
  (3 x 3, -) given to ``step(gradient=G)``: every element sees the same increment (a
  verification: a homogeneous field gives the element's own response);
- otherwise a triaxial test: u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 on z = 0, the top
  z = lz moved by ``step(top_displacement=)`` (u_z, m), and the faces x = lx and y = ly loaded
  by ``confining_pa`` (Pa, compression positive).

The force scale of the tolerance is the largest element stress times the box's volume to the
power 2/3. Stresses are tension positive, Pa. The FEM is serial, or split over the ranks of
``comm`` with the elements' pool on rank 0 (as the plane-strain mode's;
:mod:`femcoupling.fem.mpi_points`). The secant tangent is plane strain only.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from femcoupling import _dolfinx
from femcoupling._checks import FemInputError
from femcoupling.coupling.hierarchical import HierarchicalPlaneStrain
from femcoupling.fem.gmsh_mesh import gmsh_mesh_on_root
from femcoupling.fem.quadrature import QuadratureSystem, lu_package

__all__ = ["Hierarchical3D", "HierarchicalCylinder", "cylinder_cells", "SECTIONS"]


class Hierarchical3D(HierarchicalPlaneStrain):
    """See the module doc. ``pool``: an ElementPool with one element per tetrahedron
    (6 nx ny nz); the other arguments as ``HierarchicalPlaneStrain``'s."""

    gdim = 3

    def __init__(self, pool, *, lx: float, ly: float, lz: float, nx: int, ny: int, nz: int,
                 homogeneous: bool = False, confining_pa: float | None = None,
                 newton_rtol: float = 1e-3, max_newton: int = 10,
                 strain_kw: dict | None = None, tangent: str = "network",
                 convergence: str = "noise", relaxation: str | float = "aitken",
                 noise_factor: float = 2.0, noise_ceiling: float | None = None, comm=None,
                 verbose: bool = False, out=None, overwrite: bool = False) -> None:
        for name, v in (("lx", lx), ("ly", ly), ("lz", lz)):
            if not (math.isfinite(v) and v > 0):
                raise FemInputError(f"{name}={v!r}: must be > 0 (m)")
        for name, v in (("nx", nx), ("ny", ny), ("nz", nz)):
            if not (isinstance(v, int) and v >= 1):
                raise FemInputError(f"{name}={v!r}: must be an integer >= 1")
        self.lx, self.ly, self.lz = float(lx), float(ly), float(lz)
        self.nx, self.ny, self.nz = nx, ny, nz
        self._setup(pool, homogeneous=homogeneous, confining_pa=confining_pa,
                    newton_rtol=newton_rtol, max_newton=max_newton, strain_kw=strain_kw,
                    tangent=tangent, convergence=convergence, relaxation=relaxation,
                    noise_factor=noise_factor, noise_ceiling=noise_ceiling, comm=comm,
                    verbose=verbose, out=out, overwrite=overwrite)

    def _setup(self, pool, *, homogeneous: bool = False, confining_pa: float | None = None,
               newton_rtol: float = 1e-3, max_newton: int = 10,
               strain_kw: dict | None = None, tangent: str = "network",
               convergence: str = "noise", relaxation: str | float = "aitken",
               noise_factor: float = 2.0, noise_ceiling: float | None = None, comm=None,
               verbose: bool = False, out=None, overwrite: bool = False) -> None:
        """Everything but the geometry's own arguments: the mesh (``_mesh``), the pool's
        check (``_cells``), the spaces, the boundary (``_confinement``, ``_confine``,
        ``_triaxial_bcs``) and the elements as the points' material."""
        if not homogeneous and confining_pa is None:
            raise FemInputError("confining_pa=None: a triaxial test needs the confining "
                                "pressure (Pa, compression positive), or homogeneous=True")
        fx = self._fx = _dolfinx.load()
        fem, ufl = fx.fem, fx.ufl
        self.pool = pool
        self.comm = comm
        self._options(out=out, overwrite=overwrite, verbose=verbose, tangent=tangent,
                      tangents=("network", "network-elastic"), convergence=convergence,
                      relaxation=relaxation, noise_factor=noise_factor,
                      noise_ceiling=noise_ceiling, newton_rtol=newton_rtol,
                      max_newton=max_newton)
        self.homogeneous, self.confining_pa = homogeneous, confining_pa
        self.strain_kw = dict(strain_kw or {})
        msh = self.mesh = self._mesh(comm)
        self.n_cells = msh.topology.index_map(3).size_local  # (this rank's)
        self._check_pool(pool, *self._cells())

        def eps(w):  # Voigt xx, yy, zz, yz, xz, xy with engineering shear (the element's)
            e = ufl.sym(ufl.grad(w))
            return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2], 2 * e[0, 2],
                                  2 * e[0, 1]])

        fdim = 2
        st = fx.PETSc.ScalarType
        loads = self._confinement(msh)
        sysq = self.system = QuadratureSystem(
            msh, degree=1, qdeg=1, ncomp=6, strain=eps, loads=loads,
            lu=lu_package(self.comm, None))
        self.V, self.Wv, self.Wt = sysq.V, sysq.Wv, sysq.Wt
        self._points(1)
        self.u, self.u_n, self.du = sysq.u, sysq.u_n, sysq.du
        self.sig_q, self.tan_q = sysq.sig_q, sysq.tan_q
        self.expr_grad = fem.Expression(ufl.grad(self.u), sysq.qpoints)
        self.expr_grad_n = fem.Expression(ufl.grad(self.u_n), sysq.qpoints)
        self.top_u = fem.Constant(msh, st(0.0))
        if homogeneous:
            self._h = fem.Function(self.V)
            facets = fx.mesh.locate_entities_boundary(
                msh, fdim, lambda x: np.ones(x.shape[1], dtype=bool))
            self.bcs = [fem.dirichletbc(self._h, fem.locate_dofs_topological(
                self.V, fdim, facets))]
        else:
            self.bcs = self._triaxial_bcs(msh)
            self._confine(float(confining_pa))
        self._material(pool, tangent=tangent, strain_kw=self.strain_kw, dim=3)
        self._gradient = np.zeros((3, 3))

    # ---- the box's geometry (the hooks a body of another shape replaces) -----------------

    def _mesh(self, comm):
        """The model's mesh on ``comm`` (None: serial)."""
        return self._box(comm)

    def _cells(self) -> tuple[int, str]:
        """The elements the pool must hold, and what they are (for its error)."""
        return 6 * self.nx * self.ny * self.nz, "cells (6 nx ny nz tetrahedra)"

    def _fixed(self, c: int, facets, value):
        """The Dirichlet condition u_c = ``value`` on the boundary ``facets`` (their indices)."""
        fem = self._fx.fem
        sub = self.V.sub(c)
        return fem.dirichletbc(value, fem.locate_dofs_topological(sub, 2, facets), sub)

    def _confinement(self, msh):
        """The confining loads (``v`` -> the forms of their work): the faces x = lx and
        y = ly under the tractions ``traction_x`` and ``traction_y``."""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        st = fx.PETSc.ScalarType
        at = lambda c, v: (lambda x: np.isclose(x[c], v))  # noqa: E731
        right = np.sort(fx.mesh.locate_entities_boundary(msh, 2, at(0, self.lx)))
        back = np.sort(fx.mesh.locate_entities_boundary(msh, 2, at(1, self.ly)))
        both = np.concatenate([right, back])
        order = np.argsort(both, kind="stable")
        tags = fx.mesh.meshtags(msh, 2, both[order], np.concatenate(
            [np.full(len(right), 1, np.int32), np.full(len(back), 2, np.int32)])[order])
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        self.traction_x = fem.Constant(msh, np.zeros(3, dtype=st))
        self.traction_y = fem.Constant(msh, np.zeros(3, dtype=st))
        return lambda v: (ufl.dot(self.traction_x, v) * ds(1),
                          ufl.dot(self.traction_y, v) * ds(2))

    def _confine(self, p: float) -> None:
        """The confining pressure ``p`` (Pa, compression positive) on the loaded faces."""
        self.traction_x.value[:] = [-p, 0.0, 0.0]
        self.traction_y.value[:] = [0.0, -p, 0.0]

    def _triaxial_bcs(self, msh) -> list:
        """u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 on z = 0, u_z = ``top_u`` on top."""
        fx = self._fx
        st = fx.PETSc.ScalarType
        at = lambda c, v: fx.mesh.locate_entities_boundary(  # noqa: E731
            msh, 2, lambda x: np.isclose(x[c], v))
        return [self._fixed(0, at(0, 0.0), st(0.0)), self._fixed(1, at(1, 0.0), st(0.0)),
                self._fixed(2, at(2, 0.0), st(0.0)), self._fixed(2, at(2, self.lz), self.top_u)]

    def _box(self, comm=None):
        """The box of tetrahedra on ``comm`` (None: serial)."""
        fx = self._fx
        return fx.mesh.create_box(fx.MPI.COMM_SELF if comm is None else comm,
                                  [np.zeros(3), np.array([self.lx, self.ly, self.lz])],
                                  [self.nx, self.ny, self.nz], fx.mesh.CellType.tetrahedron)

    _serial_mesh = _box

    def _scale_length(self) -> float:
        return (self.lx * self.ly * self.lz) ** (2.0 / 3.0)

    def step(self, *, gradient=None, top_displacement: float | None = None,
             max_cuts: int = 4):
        """One load step: ``gradient`` (3 x 3, -, total since the start: the homogeneous
        mode's u = G x) or ``top_displacement`` (m, total: the triaxial test's top u_z). A
        step Newton fails is rolled back and halved, at most ``max_cuts`` times
        (``HierarchicalPlaneStrain.step``); returns the last accepted step's ``HierStep``
        (all are in ``history``; its ``load`` is G_zz, or the top displacement)."""
        if self.homogeneous:
            if gradient is None or top_displacement is not None:
                raise FemInputError("step: the homogeneous mode takes gradient= (3 x 3) only")
            g = np.asarray(gradient, float)
            if g.shape != (3, 3) or not np.all(np.isfinite(g)):
                raise FemInputError(f"gradient: shape {g.shape}; a finite 3 x 3 displacement "
                                    "gradient expected")
            target = g
        else:
            if top_displacement is None or gradient is not None:
                raise FemInputError("step: the triaxial test takes top_displacement= only")
            target = float(top_displacement)
        now = self._gradient if self.homogeneous else self._bc_now[0]
        return self._cut_steps(now, target, max_cuts, self._step_to)

    def _restore(self, point) -> None:
        if self.homogeneous:
            self._pending_gradient = np.array(point, float)
            self._set_boundary(float(point[2, 2]), 0.0)
        else:
            self._set_boundary(float(point), 0.0)

    def _step_to(self, target):
        if self.homogeneous:
            self._pending_gradient = np.array(target, float)
            r = self._step(float(target[2, 2]), 0.0)
            self._gradient = self._pending_gradient
            return r
        return self._step(float(target), 0.0)

    def _set_boundary(self, top_displacement: float, right_displacement: float) -> None:
        if self.homogeneous:
            g = self._pending_gradient
            self._h.interpolate(lambda x: g @ x)
        else:
            self.top_u.value = top_displacement


_names = itertools.count()

#: Facet tags of the quarter cylinder (``HierarchicalCylinder``).
CYL_BOTTOM, CYL_TOP, CYL_X0, CYL_Y0, CYL_SIDE = 1, 2, 3, 4, 5


#: The cylinder's sections (``HierarchicalCylinder(section=)``): the quarter x, y >= 0 with
#: its two symmetry planes, or the whole cylinder.
SECTIONS = ("quarter", "full")


def _cylinder_mesh(fx, radius: float, height: float, size: float, comm,
                   section: str = "quarter"):
    """The ``section`` of a cylinder x^2 + y^2 <= radius^2, 0 <= z <= height (m): the
    quarter x, y >= 0 or the full cylinder (a node embedded at the bottom's centre, for its
    rigid-body constraints), of P1 tetrahedra about ``size`` (m) across, meshed by gmsh on
    rank 0 of ``comm`` (None: serial) and distributed: (mesh, facet tags ``CYL_*``)."""
    comm = fx.MPI.COMM_SELF if comm is None else comm
    kinds = ([CYL_BOTTOM, CYL_TOP, CYL_X0, CYL_Y0, CYL_SIDE] if section == "quarter"
             else [CYL_BOTTOM, CYL_TOP, CYL_SIDE])

    def build(gmsh) -> None:
        occ = gmsh.model.occ
        cyl = occ.addCylinder(0, 0, 0, 0, 0, height, radius)
        if section == "quarter":
            box = occ.addBox(0, 0, 0, radius, radius, height)
            vols, _ = occ.intersect([(3, cyl)], [(3, box)])
        else:
            vols = [(3, cyl)]
            centre = occ.addPoint(0, 0, 0)
        occ.synchronize()
        tol = 1e-6 * max(radius, height)
        groups: dict = {}
        for _, tag in gmsh.model.getEntities(2):
            c = occ.getCenterOfMass(2, tag)
            kind = (CYL_BOTTOM if abs(c[2]) < tol else CYL_TOP
                    if abs(c[2] - height) < tol else CYL_SIDE if section == "full"
                    else CYL_X0 if abs(c[0]) < tol else CYL_Y0 if abs(c[1]) < tol
                    else CYL_SIDE)
            groups.setdefault(kind, []).append(tag)
        if sorted(groups) != kinds:
            raise RuntimeError(f"the {section} cylinder's faces: {groups}")
        if section == "full":
            gmsh.model.mesh.embed(0, [centre], 2, groups[CYL_BOTTOM][0])
        for kind, tags in groups.items():
            gmsh.model.addPhysicalGroup(2, tags, kind)
        gmsh.model.addPhysicalGroup(3, [v[1] for v in vols], 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * size)
        gmsh.model.mesh.generate(3)

    data = gmsh_mesh_on_root(comm, f"femcoupling_cylinder_{next(_names)}", build, gdim=3,
                             what="mesh the cylinder")
    return data.mesh, data.facet_tags


def cylinder_cells(radius_m: float, height_m: float, size_m: float,
                   section: str = "quarter") -> int:
    """The tetrahedra, and so the elements, of :class:`HierarchicalCylinder`'s ``section``
    ("quarter" or "full"; meshed serially: the pool is built before the model)."""
    _check_cylinder(radius_m, height_m, size_m, section)
    fx = _dolfinx.load()
    mesh, _ = _cylinder_mesh(fx, radius_m, height_m, size_m, None, section)
    return mesh.topology.index_map(3).size_global


def _check_cylinder(radius_m, height_m, size_m, section="quarter") -> None:
    if section not in SECTIONS:
        raise FemInputError(f"section={section!r}: one of {', '.join(map(repr, SECTIONS))}")
    for name, v in (("radius_m", radius_m), ("height_m", height_m), ("size_m", size_m)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise FemInputError(f"{name}={v!r}: must be > 0 (m)")
    if size_m > 2 * max(radius_m, height_m):
        raise FemInputError(f"size_m={size_m!r}: must be <= 2 max(radius_m, height_m) = "
                            f"{2 * max(radius_m, height_m)!r} (m)")


class HierarchicalCylinder(Hierarchical3D):
    """A triaxial specimen: a cylinder of ``radius_m`` and ``height_m`` (m), modelled as the
    quarter x, y >= 0 (``section="quarter"``; its symmetry planes: u_x = 0 on x = 0,
    u_y = 0 on y = 0) or whole (``section="full"``: no symmetry imposed, so elements whose
    tangent couples shear and normal strains can shear; the rigid-body motions are held at
    the bottom's centre, u_x = u_y = 0, and at its point (radius, 0, 0), u_y = 0), P1
    tetrahedra about ``size_m`` across (gmsh), a periodic DEM element at the quadrature
    point of each (``pool`` holds :func:`cylinder_cells` elements of the section, element k
    at the serial mesh's cell k). Smooth platens: u_z = 0 at the bottom,
    u_z = ``step(top_displacement=)`` (m) at the top, free radially; the curved face under
    the confining pressure ``confining_pa`` (Pa, compression positive, normal to the face).
    ``homogeneous=True`` puts every boundary node on u = G x instead. The other keyword
    arguments (``options``: ``confining_pa``, ``homogeneous``, ``newton_rtol``, ``comm``,
    ``out``, ...), the steps and the records are :class:`Hierarchical3D`'s. Stresses tension
    positive, Pa.

    ``platens="rough"``: the platens hold the specimen's ends radially too (u_x = u_y = 0 at
    the bottom and the top), as end friction does in a test without lubricated ends."""

    def __init__(self, pool, *, radius_m: float, height_m: float, size_m: float,
                 platens: str = "smooth", section: str = "quarter", **options) -> None:
        _check_cylinder(radius_m, height_m, size_m, section)
        if platens not in ("smooth", "rough"):
            raise FemInputError(f"platens={platens!r}: 'smooth' or 'rough'")
        self.platens, self.section = platens, section
        self.radius_m, self.height_m, self.size_m = (float(radius_m), float(height_m),
                                                     float(size_m))
        # (the box's sizes, as the matching's scale and the records' geometry)
        self.lx = self.ly = self.radius_m
        self.lz = self.height_m
        self._setup(pool, **options)

    def _mesh(self, comm):
        mesh, self._facets = _cylinder_mesh(self._fx, self.radius_m, self.height_m,
                                            self.size_m, comm, self.section)
        return mesh

    def _serial_mesh(self):
        return _cylinder_mesh(self._fx, self.radius_m, self.height_m, self.size_m, None,
                              self.section)[0]

    def _cells(self) -> tuple[int, str]:
        return (self.mesh.topology.index_map(3).size_global,
                f"tetrahedra (cylinder_cells({self.radius_m:g}, {self.height_m:g}, "
                f"{self.size_m:g}, {self.section!r}))")

    def _scale_length(self) -> float:
        part = 0.25 if self.section == "quarter" else 1.0
        return (part * math.pi * self.radius_m ** 2 * self.height_m) ** (2.0 / 3.0)

    def _confinement(self, msh):
        """The confining pressure normal to the curved face (``pressure``, Pa)."""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        ds = ufl.Measure("ds", domain=msh, subdomain_data=self._facets)
        n = ufl.FacetNormal(msh)
        self.pressure = fem.Constant(msh, fx.PETSc.ScalarType(0.0))
        return lambda v: (-self.pressure * ufl.dot(n, v) * ds(CYL_SIDE),)

    def _confine(self, p: float) -> None:
        self.pressure.value = p

    def _triaxial_bcs(self, msh) -> list:
        fx = self._fx
        st = fx.PETSc.ScalarType
        on = lambda tag, c, value: self._fixed(c, self._facets.find(tag), value)  # noqa: E731
        bcs = [on(CYL_BOTTOM, 2, st(0.0)), on(CYL_TOP, 2, self.top_u)]
        if self.section == "quarter":
            bcs += [on(CYL_X0, 0, st(0.0)), on(CYL_Y0, 1, st(0.0))]
        elif self.platens == "smooth":  # (rough platens hold the rigid-body motions already)
            tol = 1e-9 * max(self.radius_m, self.height_m)

            def node(x0, c):
                sub = self.V.sub(c)
                v, _ = sub.collapse()
                dofs = fx.fem.locate_dofs_geometrical(
                    (sub, v), lambda x: np.linalg.norm(x - np.reshape(x0, (3, 1)), axis=0)
                    < tol)
                found = self.comm.allreduce(len(dofs[0])) if self.comm is not None \
                    else len(dofs[0])
                if found < 1:
                    raise RuntimeError(f"the full cylinder has no node at {x0} (m)")
                return fx.fem.dirichletbc(st(0.0), dofs[0], sub)

            bcs += [node((0.0, 0.0, 0.0), 0), node((0.0, 0.0, 0.0), 1),
                    node((self.radius_m, 0.0, 0.0), 1)]
        if self.platens == "rough":
            bcs += [on(tag, c, st(0.0)) for tag in (CYL_BOTTOM, CYL_TOP) for c in (0, 1)]
        return bcs

    @property
    def element_volumes(self) -> np.ndarray:
        """(n,) each element's tetrahedron's volume (m^3), in element order (collective under
        MPI): the weights of the specimen's mean stress."""
        fx = self._fx
        fem, ufl = fx.fem, fx.ufl
        dg0 = fem.functionspace(self.mesh, ("DG", 0))
        vol = fem.assemble_vector(fem.form(ufl.TestFunction(dg0) * ufl.dx)).array
        own = np.asarray(vol[: self.n_cells], float)
        return own if self.partition is None else self.partition.gather(own)

    def volume_mean_stress(self, step=None) -> np.ndarray:
        """The specimen's volume-mean stress of a step (the last if None): Voigt xx, yy, zz,
        yz, xz, xy, tension positive, Pa. (``HierStep.mean_stress`` is the elements'
        unweighted mean.)"""
        r = self.history[-1] if step is None else step
        w = self.element_volumes
        return w @ np.asarray(r.element_stresses) / w.sum()
