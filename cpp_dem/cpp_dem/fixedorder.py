"""Small vector arithmetic in a fixed order, for what a scene is built from.

NumPy hands a vector's ``np.linalg.norm``, ``a @ b`` and ``np.dot`` to BLAS, whose kernel (picked
by the CPU, or by ``OPENBLAS_CORETYPE``) sums in its own order; LAPACK's ``eigh`` rounds as that
kernel does. A scene built from such a number differs in the last bit between machines, and a
chaotic packing grows the bit into another sample (docs/core.md, "The same bits on every x86-64
CPU"). These helpers use +, -, *, / and sqrt in a fixed order: the same bits everywhere."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["norm", "unit"]


def norm(v) -> float:
    """Euclidean length of the 1-D vector ``v``, summed left to right."""
    ss = 0.0
    for x in np.asarray(v, dtype=float).ravel():
        ss += float(x) * float(x)
    return math.sqrt(ss)


def unit(v) -> np.ndarray:
    """``v`` over its length (:func:`norm`)."""
    v = np.asarray(v, dtype=float)
    return v / norm(v)
