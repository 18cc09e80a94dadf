"""Input checks shared by the femcoupling modules: one error type, one message format
("<field>=<value>: <what is allowed>")."""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np


class FemInputError(ValueError, TypeError):
    """A bad input to femcoupling; the message names the field, its value and what is allowed.
    A ValueError (bad value) and a TypeError (not a number), so either may be caught."""


def _real(name: str, value: Any) -> float:
    """``value`` as a finite float, or FemInputError naming the field."""
    numeric = isinstance(value, (int, float)) or hasattr(value, "__float__")
    if isinstance(value, (bool, str)) or not numeric:
        raise FemInputError(f"{name}={value!r}: must be a real number")
    v = float(value)
    if not math.isfinite(v):
        raise FemInputError(f"{name}={v!r}: must be finite")
    return v


def _pos(name: str, value: Any) -> float:
    """``value`` as a finite float > 0, or FemInputError naming the field."""
    v = _real(name, value)
    if v <= 0.0:
        raise FemInputError(f"{name}={v!r}: must be > 0")
    return v


#: Cells per h^dim of volume in a uniform mesh of size h (gmsh, algorithm 6 in 2D, Delaunay in
#: 3D; measured: 11 626 triangles on 2 m x 1 m at 0.02 m, 37 053 tetrahedra on 1 m^3 at 0.05 m).
_CELLS_PER_SIZE = {2: 2.33, 3: 4.63}
#: Peak memory per cell of a Drucker-Prager soil body's FemModel with P2 elements (mesh, function
#: spaces, the quadrature state and the Newton system), bytes, by dim: measured as the growth
#: of the peak RSS from 11 280 to 44 584 triangles (270 to 703 MiB) and from 4 050 to 17 643
#: tetrahedra (353 to 1 408 MiB), set_geostatic and two load steps (docs/fem.md).
_BYTES_PER_CELL = {2: 13_600, 3: 81_400}
#: The default max_cells by dim: about 12 GiB at _BYTES_PER_CELL.
_MAX_CELLS = {2: 900_000, 3: 150_000}


def _check_cells(what: str, n: float, max_cells: Any, dim: int) -> None:
    """Refuses a mesh of about ``n`` cells (estimated before meshing) above ``max_cells``
    (None: the default cap of the dimension); the message names ``what`` (the fields
    that set the size), the estimate, its memory and the cap."""
    if max_cells is not None and (isinstance(max_cells, bool) or not isinstance(max_cells, int)
                                  or max_cells < 1):
        raise FemInputError(f"max_cells={max_cells!r}: must be a whole number >= 1, or None "
                            "(the default cap)")
    cap = _MAX_CELLS[dim] if max_cells is None else max_cells
    if n > cap:
        per = _BYTES_PER_CELL[dim]
        raise FemInputError(
            f"{what}: about {n:.3g} cells (estimated from the domain's size and the mesh "
            f"sizes before meshing; about {n * per / 2**30:.3g} GiB at {per / 1024:.0f} KiB per "
            f"cell for a P2 Drucker-Prager model), above max_cells={cap}"
            f"{' (the default for dim=%d)' % dim if max_cells is None else ''}; coarsen the "
            "mesh, or raise max_cells if the machine has the memory")


def _whole(name: str, value: Any, lo: int, hi: int | None = None, what: str = "") -> Any:
    """``value`` unchanged if it is a whole number (an int or a NumPy integer; not a bool) in
    [``lo``, ``hi``] (``hi`` None: no upper bound), or FemInputError naming the field, its
    value and the range (``what``, if given, says what the field counts)."""
    ok = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
    if not ok or value < lo or (hi is not None and value > hi):
        allowed = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise FemInputError(f"{name}={value!r}: must be a whole number {allowed}"
                            + (f" ({what})" if what else ""))
    return value


def _choice(name: str, value: Any, choices: tuple, text: str) -> Any:
    """``value`` unchanged if it is a whole number (not a bool, nor a float of whole value)
    among ``choices``, or FemInputError "<name>=<value>: must be <text>"."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise FemInputError(f"{name}={value!r}: must be {text} (a whole number, not a "
                            f"{type(value).__name__})")
    if value not in choices:
        raise FemInputError(f"{name}={value!r}: must be {text}")
    return value


def _flag(name: str, value: Any) -> Any:
    """``value`` unchanged if it is a bool (or a NumPy bool), or FemInputError naming the
    field."""
    if not isinstance(value, (bool, np.bool_)):
        raise FemInputError(f"{name}={value!r}: must be True or False")
    return value


#: The largest ``newton_rtol`` of a ``FemModel``: a relative residual of 1 % of the force scale
#: (the loosest tolerance the package uses is 5e-3; at 0.5 a step was accepted unsolved, after
#: 0 iterations).
NEWTON_RTOL_MAX = 1e-2
#: The most step halvings of a load step (``max_cuts``): 2**20 cuts a step to about 1e-6 of its
#: nominal size, and a load Newton carries only in steps that small takes up to a million of
#: them (a Drucker-Prager footing pushed past its capacity crept on at 2**-21 of its step,
#: thousands of steps a minute, with max_cuts=30); at about 52 cuts a step no longer moves the
#: load factor (a double) at all. The package's own defaults are 4 and 6.
MAX_CUTS_MAX = 20


def _newton_rtol(value: Any) -> float:
    """``newton_rtol`` as a float in (0, NEWTON_RTOL_MAX], or FemInputError."""
    v = _real("newton_rtol", value)
    if not 0.0 < v <= NEWTON_RTOL_MAX:
        raise FemInputError(f"newton_rtol={value!r}: must be in (0, {NEWTON_RTOL_MAX:g}] "
                            "(Newton's tolerance, relative to the force scale)")
    return v


def _max_cuts(value: Any) -> int:
    """``max_cuts`` unchanged if a whole number in [0, MAX_CUTS_MAX], or FemInputError."""
    return _whole("max_cuts", value, 0, MAX_CUTS_MAX,
                  f"halvings of a load step before NewtonFailure; {MAX_CUTS_MAX} cuts a step "
                  f"to 1/2**{MAX_CUTS_MAX} of its size")


def _max_newton(value: Any) -> int:
    """``max_newton`` unchanged if a whole number >= 1, or FemInputError."""
    return _whole("max_newton", value, 1, None, "Newton iterations before a step is cut")


def _confining(name: str, value: Any) -> Any:
    """A confining pressure (Pa, compression positive) unchanged if None or a finite real
    >= 0, or FemInputError."""
    if value is not None and _real(name, value) < 0.0:
        raise FemInputError(f"{name}={value!r}: must be >= 0 (Pa, compression positive), or "
                            "None")
    return value
