"""cpp_dem.element, the servo-walled DEM element of 002 as a library API (moved out of
cases/prs_element.py): driven from ElementParams alone, it reaches and holds the given wall
stresses and writes its records, without importing dolfinx."""

import subprocess
import sys

import numpy as np
import pytest

from cpp_dem.element import ElementParams, grid_axial_stiffness, run_element


def test_element_from_its_own_parameters_holds_the_targets(tmp_path):
    p = ElementParams(n=200, hold_steps=400, max_steps=80_000, unbalanced=0.05, tol=0.01,
                      record_every=100, threads=1)
    targets = [np.array([20e3, 20e3, 40e3])]  # Pa, compression positive
    logged = []
    s = run_element(p, targets, prestressed=False, label="RE", out=tmp_path, log=logged.append)
    assert s["converged"] == [True]
    # Held within 1 % over hold_steps (the case's own bound), and the stresses are the targets.
    assert s["hold_max_rel_error"] < 0.01
    np.testing.assert_allclose(s["stress_final_pa"], targets[0], rtol=0.01)
    assert (tmp_path / "RE.h5").exists() and (tmp_path / "vtk" / "RE_geogrid.vtp").exists()
    assert any("grown to" in m for m in logged)
    # J = E pi R^2 / spacing (N/m per metre width).
    assert grid_axial_stiffness(p) == pytest.approx(np.pi * 1e9 * 1e-6 / (0.095 / 9), rel=1e-14)


def test_importing_the_element_imports_no_dolfinx():
    code = "import sys, cpp_dem.element; print('dolfinx' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
