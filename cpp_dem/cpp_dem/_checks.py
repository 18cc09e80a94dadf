"""Input checks shared by the DEM library's Python modules: each refuses a bad value with a
``ParameterError`` (a ``ValueError``) that names the field, the value and what is allowed."""

from __future__ import annotations

import math
import numbers

from cpp_dem._core import ParameterError

__all__ = ["positive"]


def positive(name: str, value, allowed: str = "") -> float:
    """``value`` as a float when it is a finite real number > 0 (not a bool); otherwise
    ``ParameterError`` naming ``name``, the value and ``allowed`` (its meaning and unit)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (
            math.isfinite(float(value)) and float(value) > 0):
        raise ParameterError(f"{name}={value!r}: must be a finite number > 0"
                             + (f" ({allowed})" if allowed else ""))
    return float(value)
