"""Verification of femcoupling.fem.elastic_block.solve_elastic_block (the toolchain check)
against the analytic uniaxial-stress solution.

A box on three roller planes (z=0, x=0, y=0) under a uniform compressive top
traction t is in homogeneous uniaxial stress:

    sigma_zz = -t (tension positive), all other components 0,
    u_z(top) = -t * Lz / E.

The displacement field is linear, so P1 and P2 Lagrange reproduce it exactly;
the tolerances below are therefore round-off tolerances, not discretisation ones.
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import femcoupling
from femcoupling.fem.elastic_block import ElasticBlockResult, solve_elastic_block

REPO_ROOT = pathlib.Path(__file__).resolve().parents[1]

# Non-unit values so that a swapped or dropped factor shows up.
LX_M = 1.0
LY_M = 0.6
LZ_M = 1.5
YOUNG_PA = 30.0e6
POISSON = 0.25
TRACTION_PA = 50.0e3  # compressive
MESH_SIZE_M = 0.5  # coarse: ~100 tetrahedra, the file runs in seconds

REL_TOL = 1e-6
"""Relative tolerance on sigma_zz and u_z: the exact solution is in the FE space."""
OFF_AXIS_ABS_TOL_PA = 1e-6 * TRACTION_PA
"""Absolute tolerance on the stress components that must vanish, relative to the traction."""


def _solve(degree: int) -> ElasticBlockResult:
    return solve_elastic_block(
        lx_m=LX_M,
        ly_m=LY_M,
        lz_m=LZ_M,
        young_pa=YOUNG_PA,
        poisson=POISSON,
        top_traction_pa=TRACTION_PA,
        mesh_size_m=MESH_SIZE_M,
        degree=degree,
    )


@pytest.fixture(scope="module", params=[1, 2], ids=["P1", "P2"])
def block(request: pytest.FixtureRequest) -> ElasticBlockResult:
    return _solve(request.param)


def test_result_holds_numpy_values_only(block: ElasticBlockResult) -> None:
    assert isinstance(block.mean_stress_pa, np.ndarray)
    assert block.mean_stress_pa.shape == (3, 3)
    assert block.mean_stress_pa.dtype == np.float64
    assert not block.mean_stress_pa.flags.writeable
    assert type(block.top_mean_displacement_z_m) is float
    assert type(block.num_cells) is int
    assert block.num_cells > 0
    # mesh covers the box exactly (planar faces): round-off tolerance
    assert block.volume_m3 == pytest.approx(LX_M * LY_M * LZ_M, rel=1e-12)


def test_uniaxial_stress_sigma_zz_equals_minus_traction(block: ElasticBlockResult) -> None:
    assert block.mean_stress_pa[2, 2] == pytest.approx(-TRACTION_PA, rel=REL_TOL)


def test_uniaxial_stress_other_components_vanish(block: ElasticBlockResult) -> None:
    off_axis = block.mean_stress_pa.copy()
    off_axis[2, 2] = 0.0
    np.testing.assert_allclose(off_axis, 0.0, rtol=0.0, atol=OFF_AXIS_ABS_TOL_PA)


def test_stress_tensor_is_symmetric(block: ElasticBlockResult) -> None:
    np.testing.assert_allclose(
        block.mean_stress_pa, block.mean_stress_pa.T, rtol=0.0, atol=OFF_AXIS_ABS_TOL_PA
    )


def test_top_displacement_equals_minus_t_lz_over_e(block: ElasticBlockResult) -> None:
    expected_m = -TRACTION_PA * LZ_M / YOUNG_PA
    assert block.top_mean_displacement_z_m == pytest.approx(expected_m, rel=REL_TOL)


def test_mesh_size_controls_cell_count() -> None:
    coarse = _solve(1).num_cells
    fine = solve_elastic_block(
        lx_m=LX_M,
        ly_m=LY_M,
        lz_m=LZ_M,
        young_pa=YOUNG_PA,
        poisson=POISSON,
        top_traction_pa=TRACTION_PA,
        mesh_size_m=MESH_SIZE_M / 2,
    ).num_cells
    # halving h multiplies the tetrahedron count by ~8; require at least 4x
    assert fine >= 4 * coarse


def test_existing_gmsh_session_is_left_as_found() -> None:
    gmsh = pytest.importorskip("gmsh")
    if gmsh.isInitialized():
        pytest.skip("gmsh already initialised by someone else in this process")
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", 123.0)
        gmsh.model.add("callers_model")
        gmsh.model.occ.addSphere(0.0, 0.0, 0.0, 1.0)
        gmsh.model.occ.synchronize()
        result = _solve(1)
        assert result.mean_stress_pa[2, 2] == pytest.approx(-TRACTION_PA, rel=REL_TOL)
        assert gmsh.isInitialized()
        assert gmsh.model.getCurrent() == "callers_model"
        assert gmsh.model.getEntities(3) == [(3, 1)]
        assert gmsh.option.getNumber("Mesh.MeshSizeMax") == 123.0
    finally:
        gmsh.finalize()


_GOOD = dict(
    lx_m=LX_M,
    ly_m=LY_M,
    lz_m=LZ_M,
    young_pa=YOUNG_PA,
    poisson=POISSON,
    top_traction_pa=TRACTION_PA,
    mesh_size_m=MESH_SIZE_M,
)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("lx_m", 0.0, "lx_m=0.0: must be > 0"),
        ("ly_m", -2.0, "ly_m=-2.0: must be > 0"),
        ("lz_m", float("inf"), "lz_m=inf: must be finite"),
        ("young_pa", -1.0, "young_pa=-1.0: must be > 0"),
        ("young_pa", float("nan"), "young_pa=nan: must be finite"),
        ("poisson", 0.5, "poisson=0.5: must be in (-1, 0.5)"),
        ("poisson", -1.0, "poisson=-1.0: must be in (-1, 0.5)"),
        ("top_traction_pa", float("nan"), "top_traction_pa=nan: must be finite"),
        ("mesh_size_m", 0.0, "mesh_size_m=0.0: must be > 0"),
        ("degree", 3, "degree=3: must be 1 or 2"),
    ],
)
def test_bad_input_raises_value_error_naming_the_field(
    field: str, value: object, message: str
) -> None:
    kwargs = dict(_GOOD, **{field: value})
    with pytest.raises(ValueError) as excinfo:
        solve_elastic_block(**kwargs)  # type: ignore[arg-type]
    assert str(excinfo.value) == message


def test_non_number_raises_type_error_naming_the_field() -> None:
    kwargs = dict(_GOOD, young_pa="30e6")
    with pytest.raises(TypeError, match=r"^young_pa='30e6': must be a real number$"):
        solve_elastic_block(**kwargs)  # type: ignore[arg-type]


def test_arguments_are_keyword_only() -> None:
    with pytest.raises(TypeError):
        solve_elastic_block(LX_M, LY_M, LZ_M, YOUNG_PA, POISSON, TRACTION_PA, MESH_SIZE_M)  # type: ignore[misc]


def test_public_api() -> None:
    """The package namespace holds only its one error type; the rest is in the subpackages."""
    assert set(femcoupling.__all__) == {"FemInputError"}
    assert issubclass(femcoupling.FemInputError, ValueError)


def test_import_femcoupling_does_not_import_the_fem_stack() -> None:
    code = (
        "import sys, femcoupling\n"
        "heavy = [m for m in ('dolfinx', 'dolfinx_solver', 'gmsh', 'petsc4py', 'mpi4py', 'ufl')"
        " if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(REPO_ROOT), env.get("PYTHONPATH", "")) if p
    )
    completed = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO_ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert completed.returncode == 0, completed.stderr
