"""A linear elastic element behind the strain-driven element interface
(``cpp_dem.elements.interface.StrainElement``): the verification stand-in of a DEM element.

A hierarchical FEM model with :class:`LinearElement` at its quadrature points is an
isotropic elastic continuum, whose boundary-value problems have closed-form answers: it
checks the model's mesh, boundary conditions and loads apart from the grains' scatter
(``femcoupling.fem.model.FemModel`` on a ``Cylinder``: the triaxial specimen, in its tests). It
runs on an ``ElementPool`` as a ``DemElement`` does (``LinearFactory``).

Stresses are 3 x 3, Pa, tension positive; tangents 6 x 6 in the elements' Voigt order xx, yy,
zz, yz, xz, xy with engineering shear strains."""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from cpp_dem import fixedorder
from cpp_dem._core import ParameterError
from cpp_dem.elements import state_format

__all__ = ["LinearElement", "LinearFactory"]

#: The kind of a LinearElement's bytes (cpp_dem.elements.state_format).
_KIND = "cpp_dem.LinearElement"


class LinearElement:
    """Isotropic linear elasticity: Young's modulus ``young`` (Pa), Poisson's ratio
    ``poisson`` (-), the initial stress ``stress`` (3 x 3, Pa, tension positive).
    ``apply_strain(de)`` adds C : sym(de) (de the displacement-gradient increment, -) and
    returns the stress."""

    #: what its bytes hold, for cpp_dem.elements.state_format
    STATE_KIND = _KIND

    def __init__(self, young: float, poisson: float, stress=None) -> None:
        if not (np.isfinite(young) and young > 0):
            raise ParameterError(f"young={young!r}: must be > 0 (Pa)")
        if not (np.isfinite(poisson) and -1.0 < poisson < 0.5):
            raise ParameterError(f"poisson={poisson!r}: must be in (-1, 0.5)")
        self.young, self.poisson = float(young), float(poisson)
        s = np.zeros((3, 3)) if stress is None else np.array(stress, float)
        if s.shape != (3, 3) or not np.all(np.isfinite(s)):
            raise ParameterError(f"stress: shape {s.shape}; a finite 3 x 3 tensor (Pa)")
        self._stress = s
        #: what the last increment took (the pool reads its DEM steps): none
        self.last_report = SimpleNamespace(steps=0, relax_steps=0, unbalanced=0.0, ok=True)

    @property
    def tangent(self) -> np.ndarray:
        """The 6 x 6 Voigt stiffness (engineering shear), Pa."""
        e, v = self.young, self.poisson
        lam, g = e * v / ((1 + v) * (1 - 2 * v)), e / (2 * (1 + v))
        c = np.zeros((6, 6))
        c[:3, :3] = lam
        c[range(3), range(3)] += 2 * g
        c[range(3, 6), range(3, 6)] = g
        return c

    def stress(self) -> np.ndarray:
        return self._stress.copy()

    def apply_strain(self, de, **kw) -> np.ndarray:
        d = np.asarray(de, float)
        if d.shape != (3, 3):
            raise ParameterError(f"de: shape {d.shape}; a 3 x 3 displacement gradient")
        e = 0.5 * (d + d.T)
        ds = fixedorder.matmul(self.tangent, [e[0, 0], e[1, 1], e[2, 2], 2 * e[1, 2],
                                              2 * e[0, 2], 2 * e[0, 1]])
        self._stress = self._stress + np.array([[ds[0], ds[5], ds[4]], [ds[5], ds[1], ds[3]],
                                                [ds[4], ds[3], ds[2]]])
        return self.stress()

    def contact_count(self) -> int:
        return 0

    def stress_scatter(self) -> np.ndarray:
        return np.zeros((3, 3))

    def network_tangent(self, **kw):
        return self.tangent, None

    def fd_tangent(self, **kw) -> np.ndarray:
        return self.tangent

    def to_bytes(self) -> bytes:
        """Young's modulus, Poisson's ratio and the stress in cpp_dem's element format
        (``cpp_dem.elements.state_format``: JSON, exact, with its checksum)."""
        return state_format.pack(_KIND, {"young": self.young, "poisson": self.poisson,
                                         "stress": self._stress.tolist()})

    @classmethod
    def from_bytes(cls, data: bytes) -> "LinearElement":
        """The element of ``to_bytes``; other bytes (a pickle included: nothing in them runs)
        and values the constructor refuses raise a ParameterError."""
        d, _ = state_format.unpack(data, _KIND)
        try:
            return cls(float(d["young"]), float(d["poisson"]), d["stress"])
        except KeyError as e:
            raise ParameterError(f"data: a saved LinearElement without its field {e}") from None
        except (TypeError, ValueError) as e:
            raise ParameterError(f"data: a saved LinearElement with a malformed field: {e}") \
                from None


@dataclass
class LinearFactory:
    """A picklable maker for ``ElementPool.build(..., element_type=LinearElement)``: every
    element the same :class:`LinearElement`, at the isotropic stress ``-stress`` I (``stress``
    Pa, compression positive)."""

    young: float = 50e6
    poisson: float = 0.25
    stress: float = 100e3

    def __call__(self, index: int) -> LinearElement:
        return LinearElement(self.young, self.poisson, -self.stress * np.eye(3))
