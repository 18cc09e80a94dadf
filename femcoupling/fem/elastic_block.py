"""The toolchain check: a linear-elastic rectangular block, gmsh geometry -> dolfinx mesh ->
solve -> stresses, against its closed-form answer.

The first, smallest piece of the continuum side. It proves the toolchain
(gmsh, :func:`dolfinx.io.gmsh.model_to_mesh`, :class:`dolfinx.fem.petsc.LinearProblem`)
and the shape of the FEM -> DEM boundary: plain NumPy values in a dataclass,
no dolfinx type crosses it. (The meshing step it shares with the other models is
:mod:`femcoupling.fem.gmsh_mesh`.)

Problem (SI units throughout)::

    domain      [0, lx_m] x [0, ly_m] x [0, lz_m]
    bottom z=0  roller: u_z = 0
    side  x=0   symmetry plane (roller): u_x = 0
    side  y=0   symmetry plane (roller): u_y = 0
    top   z=lz  uniform normal traction, compressive for top_traction_pa > 0
    sides x=lx, y=ly  traction free

These three roller planes remove every rigid-body mode without constraining
lateral expansion, so the exact solution is homogeneous uniaxial stress,
sigma_zz = -top_traction_pa and u_z(top) = -top_traction_pa * lz_m / young_pa,
which any conforming Lagrange space (P1 or P2) reproduces to round-off.

Sign convention: stresses are tension-positive (continuum mechanics), so a
compressive top traction gives a negative ``sigma_zz``. Displacements are
positive along +z.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from femcoupling import _dolfinx
from femcoupling._checks import _CELLS_PER_SIZE, _check_cells, _pos, _real
from femcoupling.fem.gmsh_mesh import GMSH_RANK, gmsh_mesh_on_root
from femcoupling.fem.quadrature import lu_options

__all__ = ["ElasticBlockResult", "solve_elastic_block"]

# Physical-group tags written into the gmsh model (cell tags and facet tags are
# separate namespaces in gmsh and in the dolfinx MeshTags).
VOLUME_TAG = 1
"""Cell tag of the block volume."""
BOTTOM_TAG = 1
"""Facet tag of the bottom face z = 0 (rollers, u_z = 0)."""
TOP_TAG = 2
"""Facet tag of the top face z = lz_m (normal traction)."""
X_MIN_TAG = 3
"""Facet tag of the face x = 0 (symmetry plane, u_x = 0)."""
Y_MIN_TAG = 4
"""Facet tag of the face y = 0 (symmetry plane, u_y = 0)."""

_problem_counter = itertools.count()  # unique PETSc options prefix per solve


@dataclasses.dataclass(frozen=True)
class ElasticBlockResult:
    """Outcome of :func:`solve_elastic_block`; NumPy values only, identical on every rank.

    Attributes:
        mean_stress_pa: 3x3 Cauchy stress averaged over the whole volume,
            ``(1/V) * integral(sigma dV)`` (equivalently the volume-weighted mean
            of the per-cell averages), Pa, **tension positive**, indices
            (x, y, z). Read-only array.
        top_mean_displacement_z_m: mean vertical displacement of the top face,
            ``integral(u_z dA) / A_top``, m, positive upwards (negative under
            compression).
        num_cells: number of tetrahedra in the (global) mesh.
        volume_m3: mesh volume, m^3 (should equal lx_m * ly_m * lz_m).
        degree: polynomial degree of the vector Lagrange displacement space.
    """

    mean_stress_pa: npt.NDArray[np.float64]
    top_mean_displacement_z_m: float
    num_cells: int
    volume_m3: float
    degree: int


def _validate(
    lx_m: Any,
    ly_m: Any,
    lz_m: Any,
    young_pa: Any,
    poisson: Any,
    top_traction_pa: Any,
    mesh_size_m: Any,
    degree: Any,
    max_cells: Any = None,
) -> tuple[float, float, float, float, float, float, float, int]:
    """Check every input of :func:`solve_elastic_block`; errors name the field and value."""
    lx = _pos("lx_m", lx_m)
    ly = _pos("ly_m", ly_m)
    lz = _pos("lz_m", lz_m)
    young = _pos("young_pa", young_pa)
    nu = _real("poisson", poisson)
    if not -1.0 < nu < 0.5:
        raise ValueError(f"poisson={nu!r}: must be in (-1, 0.5)")
    traction = _real("top_traction_pa", top_traction_pa)
    h = _pos("mesh_size_m", mesh_size_m)
    if isinstance(degree, bool) or not isinstance(degree, (int, np.integer)) or degree not in (1, 2):
        raise ValueError(f"degree={degree!r}: must be 1 or 2")
    _check_cells(f"mesh_size_m={h!r}", _CELLS_PER_SIZE[3] * lx * ly * lz / h**3, max_cells, 3)
    return lx, ly, lz, young, nu, traction, h, int(degree)


def _build_box(gmsh: Any, lx_m: float, ly_m: float, lz_m: float, mesh_size_m: float) -> None:
    """Mesh the box [0,lx]x[0,ly]x[0,lz] with tetrahedra of size ~mesh_size_m, tagged."""
    # Clamp the size field from both sides: with only a maximum, gmsh's default
    # point sizes (a fraction of the bounding-box diagonal) win for coarse h.
    gmsh.option.setNumber("Mesh.MeshSizeMin", mesh_size_m)
    gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size_m)
    volume = gmsh.model.occ.addBox(0.0, 0.0, 0.0, lx_m, ly_m, lz_m)
    gmsh.model.occ.synchronize()

    # Identify the faces by their centres of mass (OCC face numbering is not API;
    # OCC bounding boxes are padded by the kernel tolerance, so are not used).
    tol_m = 1e-6 * max(lx_m, ly_m, lz_m)
    faces: dict[int, list[int]] = {BOTTOM_TAG: [], TOP_TAG: [], X_MIN_TAG: [], Y_MIN_TAG: []}
    for _, face in gmsh.model.getBoundary([(3, volume)], oriented=False):
        x_m, y_m, z_m = gmsh.model.occ.getCenterOfMass(2, face)
        if abs(z_m) < tol_m:
            faces[BOTTOM_TAG].append(face)
        elif abs(z_m - lz_m) < tol_m:
            faces[TOP_TAG].append(face)
        elif abs(x_m) < tol_m:
            faces[X_MIN_TAG].append(face)
        elif abs(y_m) < tol_m:
            faces[Y_MIN_TAG].append(face)
    names = {BOTTOM_TAG: "bottom", TOP_TAG: "top", X_MIN_TAG: "x_min", Y_MIN_TAG: "y_min"}
    for tag, entity_tags in faces.items():
        if len(entity_tags) != 1:
            raise RuntimeError(f"gmsh box: found {len(entity_tags)} '{names[tag]}' faces, expected 1")
        gmsh.model.addPhysicalGroup(2, entity_tags, tag, name=names[tag])
    gmsh.model.addPhysicalGroup(3, [volume], VOLUME_TAG, name="block")
    gmsh.model.mesh.generate(3)


def _sum_over_ranks(comm: Any, values: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Sum an array over all ranks."""
    from_all = comm.allreduce(np.ascontiguousarray(values, dtype=np.float64))
    return np.asarray(from_all, dtype=np.float64)


def solve_elastic_block(
    *,
    lx_m: float,
    ly_m: float,
    lz_m: float,
    young_pa: float,
    poisson: float,
    top_traction_pa: float,
    mesh_size_m: float,
    degree: int = 1,
    comm: Any = None,
    max_cells: int | None = None,
) -> ElasticBlockResult:
    """Solve a linear-elastic box on rollers under a uniform normal top traction.

    The box ``[0, lx_m] x [0, ly_m] x [0, lz_m]`` is built and meshed by gmsh
    (physical groups: volume ``block``; faces ``bottom``, ``top``, ``x_min``,
    ``y_min``), converted by :func:`dolfinx.io.gmsh.model_to_mesh`, and solved
    with vector Lagrange elements and a direct LU solver (MUMPS; on more than one
    rank ``femcoupling.fem.quadrature.PARALLEL_LU``). The bottom
    face and the planes x = 0, y = 0 are rollers (zero normal displacement);
    the top face carries the traction ``-top_traction_pa * n``.

    All arguments are keyword-only: seven bare floats are too easy to swap.

    Args:
        lx_m: box length along x, m, > 0.
        ly_m: box length along y, m, > 0.
        lz_m: box height along z, m, > 0.
        young_pa: Young's modulus, Pa, > 0.
        poisson: Poisson's ratio, dimensionless, in (-1, 0.5).
        top_traction_pa: normal traction on the top face, Pa, finite;
            **compression positive** (a positive value pushes the top face down).
        mesh_size_m: target tetrahedron edge length (gmsh ``Mesh.MeshSizeMin`` =
            ``Mesh.MeshSizeMax``), m, > 0; the mesh never has fewer than one
            element across the shortest side.
        degree: displacement polynomial degree, 1 or 2.
        comm: mpi4py communicator; ``MPI.COMM_WORLD`` if None. Collective: every
            rank of ``comm`` must call this; gmsh runs on rank 0 only.
        max_cells: the most tetrahedra the mesh may have, estimated before meshing
            (4.63 per mesh_size_m^3 of volume); None is the default cap, 150 000
            (femcoupling.fem.geometry.ReinforcedSoilBody.max_cells).

    Returns:
        An :class:`ElasticBlockResult` (stresses tension-positive), the same on
        every rank.

    Raises:
        ValueError: an input is out of range; the message names the field and value.
        TypeError: an input is not a real number.
    """
    lx, ly, lz, young, nu, traction, h, degree = _validate(
        lx_m, ly_m, lz_m, young_pa, poisson, top_traction_pa, mesh_size_m, degree, max_cells
    )

    fx = _dolfinx.load()
    fem, ufl, PETSc, MPI = fx.fem, fx.ufl, fx.PETSc, fx.MPI
    if comm is None:
        comm = MPI.COMM_WORLD

    # --- geometry and mesh: gmsh on one rank, distributed by model_to_mesh ---
    # Rank 0's name for everyone: the PETSc options prefix must agree across ranks.
    model_name = comm.bcast(f"femcoupling_elastic_block_{next(_problem_counter)}", root=GMSH_RANK)
    petsc_prefix = f"{model_name}_"
    mesh_data = gmsh_mesh_on_root(comm, model_name, lambda gmsh: _build_box(gmsh, lx, ly, lz, h),
                                  gdim=3, what="build the block")
    msh = mesh_data.mesh
    facet_tags = mesh_data.facet_tags
    assert facet_tags is not None, "model_to_mesh returned no facet tags"
    tdim = msh.topology.dim
    fdim = tdim - 1

    # --- linear elasticity, tension-positive Cauchy stress ---
    mu_pa = young / (2.0 * (1.0 + nu))
    lmbda_pa = young * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))

    def sigma(w: Any) -> Any:
        eps = ufl.sym(ufl.grad(w))
        return lmbda_pa * ufl.tr(eps) * ufl.Identity(tdim) + 2.0 * mu_pa * eps

    V = fem.functionspace(msh, ("Lagrange", degree, (tdim,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=msh, subdomain_data=facet_tags)
    dx = ufl.Measure("dx", domain=msh)
    traction_vec = fem.Constant(msh, np.array([0.0, 0.0, -traction], dtype=PETSc.ScalarType))
    a = ufl.inner(sigma(u), ufl.sym(ufl.grad(v))) * dx
    L = ufl.inner(traction_vec, v) * ds(TOP_TAG)

    msh.topology.create_connectivity(fdim, tdim)
    bcs = []
    for tag, component in ((BOTTOM_TAG, 2), (X_MIN_TAG, 0), (Y_MIN_TAG, 1)):
        dofs = fem.locate_dofs_topological(V.sub(component), fdim, facet_tags.find(tag))
        bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, V.sub(component)))

    problem = fx.fem_petsc.LinearProblem(
        a,
        L,
        bcs=bcs,
        petsc_options_prefix=petsc_prefix,
        petsc_options={**lu_options(comm), "ksp_error_if_not_converged": True},
    )
    uh = problem.solve()
    assert isinstance(uh, fem.Function)
    reason = problem.solver.getConvergedReason()
    if reason <= 0:
        raise RuntimeError(f"elastic block: PETSc KSP did not converge (reason {reason})")

    # --- stress extraction: per-cell integrals of sigma, summed (owned cells only) ---
    W = fem.functionspace(msh, ("DG", 0, (tdim, tdim)))
    cell_stress_integral = fem.assemble_vector(
        fem.form(ufl.inner(sigma(uh), ufl.TestFunction(W)) * dx)
    )
    num_owned_cells = msh.topology.index_map(tdim).size_local
    owned = cell_stress_integral.array[: num_owned_cells * tdim * tdim]
    local_stress_integral = owned.reshape(num_owned_cells, tdim, tdim).sum(axis=0)
    stress_integral_pa_m3 = _sum_over_ranks(comm, local_stress_integral)

    one = fem.Constant(msh, PETSc.ScalarType(1.0))
    volume_m3 = comm.allreduce(fem.assemble_scalar(fem.form(one * dx)), op=MPI.SUM)
    top_area_m2 = comm.allreduce(fem.assemble_scalar(fem.form(one * ds(TOP_TAG))), op=MPI.SUM)
    top_uz_integral_m3 = comm.allreduce(
        fem.assemble_scalar(fem.form(uh[2] * ds(TOP_TAG))), op=MPI.SUM
    )

    mean_stress_pa = np.array(stress_integral_pa_m3 / volume_m3, dtype=np.float64)
    mean_stress_pa.setflags(write=False)
    return ElasticBlockResult(
        mean_stress_pa=mean_stress_pa,
        top_mean_displacement_z_m=float(top_uz_integral_m3 / top_area_m2),
        num_cells=int(msh.topology.index_map(tdim).size_global),
        volume_m3=float(volume_m3),
        degree=degree,
    )
