"""The bodies a :class:`femcoupling.fem.model.FemModel` solves: each chooses the mesh, the
boundary conditions and the loads, and what a load step moves
(docs/coupling_hierarchical.md).

- :class:`Rectangle`: plane strain, ``lx`` x ``ly`` (m) in ``2 nx ny`` triangles (P1, one
  quadrature point each; ``degree=2``: P2, three points each, which do not lock under
  isochoric or dilatant flow as constant-strain triangles do). Platens:

  - ``"smooth"`` (default): left u_x = 0, bottom u_y = 0; the top moved by
    ``top_displacement`` (u_y, m); the right loaded by a confining pressure
    (``confining_pa``, compression positive: a biaxial test) or moved
    (``right_displacement``, u_x, m, when ``confining_pa`` is None);
  - ``"rough"`` (a biaxial test whose platens grip the sample, the usual set-up for shear
    bands): the bottom held (u_x = u_y = 0), the top moved down without sliding (u_x = 0,
    u_y = ``top_displacement``), both sides under the confining pressure;
  - ``"footing"``: a rigid smooth strip footing of half width ``footing_b`` (m) beside its
    symmetry plane: the left and right on rollers (u_x = 0), the bottom u_y = 0, the top
    moved by ``top_displacement`` over 0 <= x <= ``footing_b`` (u_y; u_x free) and loaded
    by the surcharge ``confining_pa`` beyond it.

  ``homogeneous=True`` (smooth platens) moves every boundary node with the homogeneous field
  u = (e_x x, e_y y) of ``right_displacement`` and ``top_displacement``: every point sees the
  same strain. A step: ``step(top_displacement=, right_displacement=)``.
- :class:`Box`: ``lx`` x ``ly`` x ``lz`` (m) of P1 tetrahedra (six per hexahedron of an
  ``nx`` x ``ny`` x ``nz`` grid). ``homogeneous=True``: every boundary node on u = G x, G the
  total displacement gradient (3 x 3, -) of ``step(gradient=G)``; otherwise a triaxial test:
  u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 on z = 0, the top z = lz moved by
  ``step(top_displacement=)`` (u_z, m), the faces x = lx and y = ly under ``confining_pa``.
- :class:`Cylinder`: a triaxial specimen of ``radius_m`` and ``height_m`` (m), its quarter
  x, y >= 0 (``section="quarter"``: u_x = 0 on x = 0, u_y = 0 on y = 0) or whole
  (``section="full"``: the rigid-body motions held at the bottom's centre, u_x = u_y = 0, and
  at (radius, 0, 0), u_y = 0), P1 tetrahedra about ``size_m`` across (gmsh). Smooth platens:
  u_z = 0 at the bottom, u_z = ``step(top_displacement=)`` at the top, free radially; the
  curved face under ``confining_pa`` normal to it. ``platens="rough"``: the ends held
  radially too (u_x = u_y = 0), as end friction does. ``homogeneous=True``: u = G x on the
  whole boundary, as the box's.

Every body checks its own arguments (a bad one raises ``FemInputError`` naming it). The
``FemModel`` calls its hooks: ``mesh``, ``serial_mesh``, ``expected_points``, ``loads``,
``bcs``, ``target``, ``apply`` and ``scale_length``. Stresses tension positive, Pa;
lengths m.
"""

from __future__ import annotations

import inspect
import itertools
import math

import numpy as np

from femcoupling import _dolfinx
from femcoupling._checks import (FemInputError, _choice, _confining, _flag, _pos, _real,
                                 _whole)
from femcoupling.fem.gmsh_mesh import gmsh_mesh_on_root

__all__ = ["Box", "Cylinder", "Rectangle", "SECTIONS", "cylinder_cells", "quadrature_points"]


def _rectangle(fx, lx: float, ly: float, nx: int, ny: int, comm=None):
    """[0, lx] x [0, ly] (m) in 2 nx ny triangles, on ``comm`` (None: serial)."""
    return fx.mesh.create_rectangle(fx.MPI.COMM_SELF if comm is None else comm,
                                    [np.array([0.0, 0.0]), np.array([lx, ly])], [nx, ny],
                                    fx.mesh.CellType.triangle)


def _qdeg(degree: int) -> int:
    """The quadrature degree of the points: one point (P1) or three (P2)."""
    return 1 if degree == 1 else 2


def point_coordinates(fx, mesh, qpoints: np.ndarray) -> np.ndarray:
    """The coordinates (m, shape (points, gdim)) of the reference points ``qpoints`` in every
    cell of ``mesh``, in (cell, point) order: the elements' order."""
    gdim = mesh.geometry.dim
    cells = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local, dtype=np.int32)
    expr = fx.fem.Expression(fx.ufl.SpatialCoordinate(mesh), qpoints)
    return expr.eval(mesh, cells).reshape(-1, gdim)


def quadrature_points(lx: float, ly: float, nx: int, ny: int, degree: int = 1) -> np.ndarray:
    """The coordinates (m, shape (n, 2)) of the quadrature points of a model on
    ``Rectangle(lx=, ly=, nx=, ny=, degree=)``, in its elements' order (element k at cell
    k // nq, point k % nq), without building the model: to choose elements by place before
    the pool is built (a weaker zone: ``geogrid_dem.studies.biaxial.WeakZoneFactory``)."""
    import basix

    fx = _dolfinx.load()
    pts, _ = basix.make_quadrature(basix.CellType.triangle, _qdeg(degree))
    return point_coordinates(fx, _rectangle(fx, lx, ly, nx, ny), pts)


def _voigt(ufl, w, dim: int):
    """The strain of ``w`` as the elements' Voigt vector with engineering shear: (xx, yy,
    xy) in 2D, (xx, yy, zz, yz, xz, xy) in 3D."""
    e = ufl.sym(ufl.grad(w))
    if dim == 2:
        return ufl.as_vector([e[0, 0], e[1, 1], 2 * e[0, 1]])
    return ufl.as_vector([e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2], 2 * e[0, 2], 2 * e[0, 1]])


def _finite_positive(**values) -> None:
    for name, v in values.items():
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise FemInputError(f"{name}={v!r}: must be > 0 (m)")


def _cells_count(**values) -> None:
    for name, v in values.items():
        _whole(name, v, 1, None, "cells along the side")


class _Body:
    """What every body shares: its repr from its constructor's arguments (each kept under
    its own name)."""

    def __repr__(self) -> str:
        names = inspect.signature(type(self)).parameters
        return f"{type(self).__name__}(" + ", ".join(
            f"{k}={getattr(self, k)!r}" for k in names) + ")"


class Rectangle(_Body):
    """A plane-strain rectangle (module doc). ``confining_pa``: Pa, compression positive
    (None with smooth platens: the right is moved instead); ``footing_b``: the footing's half
    width, m (``platens="footing"`` only, on a mesh line)."""

    gdim = dim = 2
    ncomp = 3  #: Voigt xx, yy, xy with engineering shear
    tangents = ("network", "network-elastic", "secant")

    def __init__(self, *, lx: float, ly: float, nx: int, ny: int, degree: int = 1,
                 platens: str = "smooth", confining_pa: float | None = None,
                 homogeneous: bool = False, footing_b: float | None = None) -> None:
        if platens not in ("smooth", "rough", "footing"):
            raise FemInputError(f"platens={platens!r}: 'smooth' (left and bottom on rollers), "
                                "'rough' (bottom held, top without sliding, confining "
                                "pressure on both sides) or 'footing' (a smooth strip footing "
                                "of half width footing_b, the surcharge confining_pa beside it)")
        _flag("homogeneous", homogeneous)
        _confining("confining_pa", confining_pa)
        if platens in ("rough", "footing") and (homogeneous or confining_pa is None):
            raise FemInputError(f"platens={platens!r}: needs confining_pa (Pa; 'rough': on "
                                "both sides, 'footing': the surcharge), and not "
                                "homogeneous=True")
        if homogeneous and confining_pa is not None:
            raise FemInputError(f"confining_pa={confining_pa!r}: not with homogeneous=True "
                                "(every boundary node follows the homogeneous field of "
                                "top_displacement and right_displacement: no side is loaded); "
                                "give one or the other")
        _choice("degree", degree, (1, 2), "1 (P1 triangles, one point each) or 2 (P2 "
                "triangles, three points each: no volumetric locking)")
        _pos("lx", lx)
        _pos("ly", ly)
        _cells_count(nx=nx, ny=ny)
        self._check_footing(platens, footing_b, lx, nx)
        self.lx, self.ly, self.nx, self.ny = float(lx), float(ly), nx, ny
        self.degree, self.platens, self.footing_b = degree, platens, footing_b
        self.confining_pa, self.homogeneous = confining_pa, homogeneous
        self.qdeg = _qdeg(degree)
        self.nq = 1 if degree == 1 else 3

    @staticmethod
    def _check_footing(platens: str, footing_b, lx: float, nx: int) -> None:
        """``footing_b`` (m) is given with, and only with, ``platens="footing"``, inside the
        top edge and on one of the mesh's vertical lines (the footing's edge is a node)."""
        if platens != "footing":
            if footing_b is not None:
                raise FemInputError(f"footing_b={footing_b!r}: only with platens='footing'")
            return
        if footing_b is None or not (0 < footing_b < lx and math.isfinite(footing_b)):
            raise FemInputError(f"footing_b={footing_b!r}: the footing's half width, m, "
                                f"0 < footing_b < lx ({lx} m)")
        cells = footing_b * nx / lx
        if abs(cells - round(cells)) > 1e-9 * nx:
            raise FemInputError(f"footing_b={footing_b!r}: must end on a mesh line, a multiple "
                                f"of lx / nx = {lx / nx:g} m (the footing's edge is a node)")

    # ---- the model's hooks ---------------------------------------------------------------
    def mesh(self, fx, comm):
        return _rectangle(fx, self.lx, self.ly, self.nx, self.ny, comm)

    def serial_mesh(self, fx):
        return _rectangle(fx, self.lx, self.ly, self.nx, self.ny)

    def expected_points(self, m) -> tuple[int, str]:
        return (2 * self.nx * self.ny * self.nq,
                f"quadrature points (2 nx ny triangles, {self.nq} point(s) each)")

    def size(self) -> float:
        return max(self.lx, self.ly)

    def strain(self, ufl, w):
        return _voigt(ufl, w, 2)

    def loads(self, m, msh):
        """The loaded sides (``v`` -> the forms of their work): the right (smooth platens),
        both sides (rough: -p n on each), or the top beside the footing (its facets'
        midpoints beyond footing_b); ``m.traction`` (and rough: ``m._pressure``)."""
        fx = m._fx
        fem, ufl = fx.fem, fx.ufl
        lx, ly, footing_b = self.lx, self.ly, self.footing_b
        tol_x = 1e-9 * lx
        beside = lambda x: np.isclose(x[1], ly) & (x[0] >= footing_b - tol_x)  # noqa: E731
        loaded = fx.mesh.locate_entities_boundary(
            msh, 1, {"rough": lambda x: np.isclose(x[0], lx) | np.isclose(x[0], 0.0),
                     "footing": beside}.get(self.platens, lambda x: np.isclose(x[0], lx)))
        tags = fx.mesh.meshtags(msh, 1, np.sort(loaded), np.full(len(loaded), 1, np.int32))
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        st = fx.PETSc.ScalarType
        m.traction = fem.Constant(msh, np.zeros(2, dtype=st))
        if self.platens == "rough":
            m._pressure = fem.Constant(msh, st(float(self.confining_pa)))
            n_out = ufl.FacetNormal(msh)
            return lambda v: (-m._pressure * ufl.dot(n_out, v) * ds(1),)
        return lambda v: (ufl.dot(m.traction, v) * ds(1),)

    def bcs(self, m) -> list:
        """The Dirichlet conditions (module doc); ``m.top_u``, ``m.right_u`` the moved
        sides' displacements (m), ``m._footing_dofs`` and ``m._form_reaction`` for the
        footing."""
        fx = m._fx
        fem = fx.fem
        msh, lx, ly, footing_b = m.mesh, self.lx, self.ly, self.footing_b
        st = fx.PETSc.ScalarType
        fdim = 1
        tol_x = 1e-9 * lx
        m.top_u = fem.Constant(msh, st(0.0))
        m.right_u = fem.Constant(msh, st(0.0))
        V0, V1 = m.V.sub(0), m.V.sub(1)

        def dofs(sub, where):
            facets = fx.mesh.locate_entities_boundary(msh, fdim, where)
            return fem.locate_dofs_topological(sub, fdim, facets)

        bcs = [fem.dirichletbc(st(0.0), dofs(V0, lambda x: np.isclose(x[0], 0.0)), V0),
               fem.dirichletbc(st(0.0), dofs(V1, lambda x: np.isclose(x[1], 0.0)), V1),
               fem.dirichletbc(m.top_u, dofs(V1, lambda x: np.isclose(x[1], ly)), V1)]
        if self.platens == "footing":
            under = lambda x: np.isclose(x[1], ly) & (x[0] <= footing_b + tol_x)  # noqa: E731
            m._footing_dofs = dofs(V1, under)
            bcs = [bcs[0], bcs[1], fem.dirichletbc(m.top_u, m._footing_dofs, V1),
                   fem.dirichletbc(st(0.0), dofs(V0, lambda x: np.isclose(x[0], lx)), V0)]
            m.traction.value[:] = [0.0, -float(self.confining_pa)]
            m._form_reaction = fem.form(m.system.res)
        elif self.platens == "rough":
            ends = lambda x: np.isclose(x[1], 0.0) | np.isclose(x[1], ly)  # noqa: E731
            bcs = [fem.dirichletbc(st(0.0), dofs(V0, ends), V0),
                   fem.dirichletbc(st(0.0), dofs(V1, lambda x: np.isclose(x[1], 0.0)), V1),
                   fem.dirichletbc(m.top_u, dofs(V1, lambda x: np.isclose(x[1], ly)), V1)]
        elif self.homogeneous:
            # every boundary node on the homogeneous field u = (e_x x, e_y y)
            m._hx = fem.Function(m.V.sub(0).collapse()[0])
            m._hy = fem.Function(m.V.sub(1).collapse()[0])
            bnd = lambda x: (np.isclose(x[0], 0) | np.isclose(x[0], lx) |  # noqa: E731
                             np.isclose(x[1], 0) | np.isclose(x[1], ly))
            facets = fx.mesh.locate_entities_boundary(msh, fdim, bnd)
            hdofs = [fem.locate_dofs_topological((V0, m._hx.function_space), fdim, facets),
                     fem.locate_dofs_topological((V1, m._hy.function_space), fdim, facets)]
            bcs = [fem.dirichletbc(m._hx, hdofs[0], V0), fem.dirichletbc(m._hy, hdofs[1], V1)]
        elif self.confining_pa is None:
            bcs.append(fem.dirichletbc(m.right_u, dofs(V0, lambda x: np.isclose(x[0], lx)), V0))
        else:
            m.traction.value[:] = [-float(self.confining_pa), 0.0]
        return bcs

    def start(self):
        """The boundary's displacements before the first step: (top, right), m."""
        return (0.0, 0.0)

    def target(self, *, top_displacement: float, right_displacement: float = 0.0):
        """A step's boundary displacements (m, total since the start, finite): (top, right).
        ``right_displacement`` moves the right side only with smooth platens and
        ``confining_pa=None`` (or ``homogeneous=True``); elsewhere it is 0 only."""
        _real("top_displacement", top_displacement)
        _real("right_displacement", right_displacement)
        if self.platens == "footing" and right_displacement != 0.0:
            raise FemInputError(f"right_displacement={right_displacement!r}: the footing's "
                                "right side is on rollers (0 only)")
        if right_displacement != 0.0 and self.platens == "rough":
            raise FemInputError(f"right_displacement={right_displacement!r}: with "
                                "platens='rough' both sides carry confining_pa="
                                f"{self.confining_pa!r} Pa (0 only)")
        if (right_displacement != 0.0 and self.platens == "smooth" and not self.homogeneous
                and self.confining_pa is not None):
            raise FemInputError(f"right_displacement={right_displacement!r}: the right side "
                                f"carries confining_pa={self.confining_pa!r} Pa (0 only; "
                                "confining_pa=None moves it instead)")
        return (top_displacement, right_displacement)

    def apply(self, m, point) -> float:
        """The boundary at ``point`` ((top, right) displacements, m); returns the step's
        load: the top's displacement, m."""
        top, right = float(point[0]), float(point[1])
        m.top_u.value = top
        m.right_u.value = right
        if self.homogeneous:
            ex, ey = right / self.lx, top / self.ly
            m._hx.interpolate(lambda x: ex * x[0])
            m._hy.interpolate(lambda x: ey * x[1])
        return top

    def scale_length(self) -> float:
        """The force scale over the largest stress: the square root of the area, m."""
        return math.sqrt(self.lx * self.ly)

    def footing_pressure_pa(self, m) -> float:
        self._check_footing_platens("footing_pressure_pa")
        total = m.system.reaction(m._form_reaction, m._footing_dofs,
                                  m.comm if m._parallel else None)
        return -total / self.footing_b

    def footing_settlement_m(self, m) -> float:
        self._check_footing_platens("footing_settlement_m")
        return -float(m.top_u.value)

    def _check_footing_platens(self, what: str) -> None:
        if self.platens != "footing":
            raise FemInputError(f"{what}(): only with platens='footing' (this body's "
                                f"platens={self.platens!r})")


class Box(_Body):
    """A box of tetrahedra (module doc). ``confining_pa``: Pa, compression positive (the
    triaxial test's; None only with ``homogeneous=True``)."""

    gdim = dim = 3
    ncomp = 6  #: Voigt xx, yy, zz, yz, xz, xy with engineering shear
    degree, qdeg, nq = 1, 1, 1
    tangents = ("network", "network-elastic")
    platens = "smooth"

    def __init__(self, *, lx: float, ly: float, lz: float, nx: int, ny: int, nz: int,
                 homogeneous: bool = False, confining_pa: float | None = None) -> None:
        _finite_positive(lx=lx, ly=ly, lz=lz)
        _cells_count(nx=nx, ny=ny, nz=nz)
        self.lx, self.ly, self.lz = float(lx), float(ly), float(lz)
        self.nx, self.ny, self.nz = nx, ny, nz
        self._options(homogeneous, confining_pa)

    def _options(self, homogeneous: bool, confining_pa) -> None:
        _flag("homogeneous", homogeneous)
        _confining("confining_pa", confining_pa)
        if not homogeneous and confining_pa is None:
            raise FemInputError("confining_pa=None: a triaxial test needs the confining "
                                "pressure (Pa, compression positive), or homogeneous=True")
        if homogeneous and confining_pa is not None:
            raise FemInputError(f"confining_pa={confining_pa!r}: not with homogeneous=True "
                                "(every boundary node follows u = G x: no face is loaded); "
                                "give one or the other")
        self.homogeneous, self.confining_pa = homogeneous, confining_pa

    # ---- the geometry (the hooks a body of another shape replaces) -------------------------
    def mesh(self, fx, comm):
        return fx.mesh.create_box(fx.MPI.COMM_SELF if comm is None else comm,
                                  [np.zeros(3), np.array([self.lx, self.ly, self.lz])],
                                  [self.nx, self.ny, self.nz], fx.mesh.CellType.tetrahedron)

    def serial_mesh(self, fx):
        return self.mesh(fx, None)

    def expected_points(self, m) -> tuple[int, str]:
        return 6 * self.nx * self.ny * self.nz, "cells (6 nx ny nz tetrahedra)"

    def size(self) -> float:
        return max(self.lx, self.ly, self.lz)

    def scale_length(self) -> float:
        """The force scale over the largest stress: the volume to the power 2/3, m^2."""
        return (self.lx * self.ly * self.lz) ** (2.0 / 3.0)

    def _confinement(self, m, msh):
        """The faces x = lx and y = ly under ``m.traction_x`` and ``m.traction_y``."""
        fx = m._fx
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
        m.traction_x = fem.Constant(msh, np.zeros(3, dtype=st))
        m.traction_y = fem.Constant(msh, np.zeros(3, dtype=st))
        return lambda v: (ufl.dot(m.traction_x, v) * ds(1), ufl.dot(m.traction_y, v) * ds(2))

    def _confine(self, m, p: float) -> None:
        m.traction_x.value[:] = [-p, 0.0, 0.0]
        m.traction_y.value[:] = [0.0, -p, 0.0]

    def _triaxial_bcs(self, m) -> list:
        """u_x = 0 on x = 0, u_y = 0 on y = 0, u_z = 0 on z = 0, u_z = ``top_u`` on top."""
        fx = m._fx
        st = fx.PETSc.ScalarType
        at = lambda c, v: fx.mesh.locate_entities_boundary(  # noqa: E731
            m.mesh, 2, lambda x: np.isclose(x[c], v))
        return [_fixed(m, 0, at(0, 0.0), st(0.0)), _fixed(m, 1, at(1, 0.0), st(0.0)),
                _fixed(m, 2, at(2, 0.0), st(0.0)), _fixed(m, 2, at(2, self.lz), m.top_u)]

    # ---- the model's hooks ---------------------------------------------------------------
    def strain(self, ufl, w):
        return _voigt(ufl, w, 3)

    def loads(self, m, msh):
        return self._confinement(m, msh)

    def bcs(self, m) -> list:
        fx = m._fx
        fem = fx.fem
        m.top_u = fem.Constant(m.mesh, fx.PETSc.ScalarType(0.0))
        if self.homogeneous:
            m._h = fem.Function(m.V)
            facets = fx.mesh.locate_entities_boundary(
                m.mesh, 2, lambda x: np.ones(x.shape[1], dtype=bool))
            return [fem.dirichletbc(m._h, fem.locate_dofs_topological(m.V, 2, facets))]
        bcs = self._triaxial_bcs(m)
        self._confine(m, float(self.confining_pa))
        return bcs

    def start(self):
        """Before the first step: G = 0 (homogeneous), or the top at 0 m."""
        return np.zeros((3, 3)) if self.homogeneous else 0.0

    def target(self, *, gradient=None, top_displacement: float | None = None):
        """A step's ``gradient`` (3 x 3, -, total: the homogeneous mode's u = G x) or
        ``top_displacement`` (m, total: the triaxial test's top u_z)."""
        if self.homogeneous:
            if gradient is None or top_displacement is not None:
                raise FemInputError("step: the homogeneous mode takes gradient= (3 x 3) only")
            g = np.asarray(gradient, float)
            if g.shape != (3, 3) or not np.all(np.isfinite(g)):
                raise FemInputError(f"gradient: shape {g.shape}; a finite 3 x 3 displacement "
                                    "gradient expected")
            return g
        if top_displacement is None or gradient is not None:
            raise FemInputError("step: the triaxial test takes top_displacement= only")
        return _real("top_displacement", top_displacement)

    def apply(self, m, point) -> float:
        """The boundary at ``point`` (G, or the top's displacement); returns the step's load:
        G_zz, or the top's displacement (m)."""
        if self.homogeneous:
            g = np.array(point, float)
            m._h.interpolate(lambda x: g @ x)
            return float(g[2, 2])
        m.top_u.value = float(point)
        return float(point)

    def footing_pressure_pa(self, m) -> float:
        self._no_footing("footing_pressure_pa")

    def footing_settlement_m(self, m) -> float:
        self._no_footing("footing_settlement_m")

    def _no_footing(self, what: str):
        raise FemInputError(f"{what}(): only on a Rectangle with platens='footing' (this "
                            f"body: {type(self).__name__})")


def _fixed(m, c: int, facets, value):
    """The Dirichlet condition u_c = ``value`` on the boundary ``facets`` (their indices)."""
    fem = m._fx.fem
    sub = m.V.sub(c)
    return fem.dirichletbc(value, fem.locate_dofs_topological(sub, 2, facets), sub)


_names = itertools.count()

#: Facet tags of the cylinder (``Cylinder``).
CYL_BOTTOM, CYL_TOP, CYL_X0, CYL_Y0, CYL_SIDE = 1, 2, 3, 4, 5

#: The cylinder's sections (``Cylinder(section=)``): the quarter x, y >= 0 with its two
#: symmetry planes, or the whole cylinder.
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
    """The tetrahedra, and so the elements, of a :class:`Cylinder`'s ``section`` ("quarter"
    or "full"; meshed serially: the pool is built before the model)."""
    _check_cylinder(radius_m, height_m, size_m, section)
    fx = _dolfinx.load()
    mesh, _ = _cylinder_mesh(fx, radius_m, height_m, size_m, None, section)
    return mesh.topology.index_map(3).size_global


def _check_cylinder(radius_m, height_m, size_m, section="quarter") -> None:
    if section not in SECTIONS:
        raise FemInputError(f"section={section!r}: one of {', '.join(map(repr, SECTIONS))}")
    _finite_positive(radius_m=radius_m, height_m=height_m, size_m=size_m)
    if size_m > 2 * max(radius_m, height_m):
        raise FemInputError(f"size_m={size_m!r}: must be <= 2 max(radius_m, height_m) = "
                            f"{2 * max(radius_m, height_m)!r} (m)")


class Cylinder(Box):
    """A cylindrical triaxial specimen (module doc): ``pool`` holds :func:`cylinder_cells`
    elements of the section, element k at the serial mesh's cell k."""

    def __init__(self, *, radius_m: float, height_m: float, size_m: float,
                 platens: str = "smooth", section: str = "quarter", homogeneous: bool = False,
                 confining_pa: float | None = None) -> None:
        _check_cylinder(radius_m, height_m, size_m, section)
        if platens not in ("smooth", "rough"):
            raise FemInputError(f"platens={platens!r}: 'smooth' or 'rough'")
        self.platens, self.section = platens, section
        self.radius_m, self.height_m, self.size_m = (float(radius_m), float(height_m),
                                                     float(size_m))
        # (the box's sizes, as the matching's scale and the records' geometry)
        self.lx = self.ly = self.radius_m
        self.lz = self.height_m
        self._options(homogeneous, confining_pa)

    def mesh(self, fx, comm):
        mesh, self._facets = _cylinder_mesh(fx, self.radius_m, self.height_m, self.size_m,
                                            comm, self.section)
        return mesh

    def serial_mesh(self, fx):
        return _cylinder_mesh(fx, self.radius_m, self.height_m, self.size_m, None,
                              self.section)[0]

    def expected_points(self, m) -> tuple[int, str]:
        return (m.mesh.topology.index_map(3).size_global,
                f"tetrahedra (cylinder_cells({self.radius_m:g}, {self.height_m:g}, "
                f"{self.size_m:g}, {self.section!r}))")

    def scale_length(self) -> float:
        part = 0.25 if self.section == "quarter" else 1.0
        return (part * math.pi * self.radius_m ** 2 * self.height_m) ** (2.0 / 3.0)

    def _confinement(self, m, msh):
        """The confining pressure normal to the curved face (``m.pressure``, Pa)."""
        fx = m._fx
        fem, ufl = fx.fem, fx.ufl
        ds = ufl.Measure("ds", domain=msh, subdomain_data=self._facets)
        n = ufl.FacetNormal(msh)
        m.pressure = fem.Constant(msh, fx.PETSc.ScalarType(0.0))
        return lambda v: (-m.pressure * ufl.dot(n, v) * ds(CYL_SIDE),)

    def _confine(self, m, p: float) -> None:
        m.pressure.value = p

    def _triaxial_bcs(self, m) -> list:
        fx = m._fx
        st = fx.PETSc.ScalarType
        on = lambda tag, c, value: _fixed(m, c, self._facets.find(tag), value)  # noqa: E731
        bcs = [on(CYL_BOTTOM, 2, st(0.0)), on(CYL_TOP, 2, m.top_u)]
        if self.section == "quarter":
            bcs += [on(CYL_X0, 0, st(0.0)), on(CYL_Y0, 1, st(0.0))]
        elif self.platens == "smooth":  # (rough platens hold the rigid-body motions already)
            tol = 1e-9 * max(self.radius_m, self.height_m)

            def node(x0, c):
                sub = m.V.sub(c)
                v, _ = sub.collapse()
                dofs = fx.fem.locate_dofs_geometrical(
                    (sub, v), lambda x: np.linalg.norm(x - np.reshape(x0, (3, 1)), axis=0)
                    < tol)
                found = m.comm.allreduce(len(dofs[0])) if m.comm is not None \
                    else len(dofs[0])
                if found < 1:
                    raise RuntimeError(f"the full cylinder has no node at {x0} (m)")
                return fx.fem.dirichletbc(st(0.0), dofs[0], sub)

            bcs += [node((0.0, 0.0, 0.0), 0), node((0.0, 0.0, 0.0), 1),
                    node((self.radius_m, 0.0, 0.0), 1)]
        if self.platens == "rough":
            bcs += [on(tag, c, st(0.0)) for tag in (CYL_BOTTOM, CYL_TOP) for c in (0, 1)]
        return bcs
