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
