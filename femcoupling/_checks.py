"""Input checks shared by the femcoupling modules: one error type, one message format
("<field>=<value>: <what is allowed>")."""

from __future__ import annotations

import math
from typing import Any


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
