"""The DEM elements of an ``ElementPool`` as a quadrature-point material: one element at every
point of a :class:`femcoupling.fem.model.FemModel` (the hierarchical mode;
docs/coupling_hierarchical.md), and the conversions between the element's 3 x 3 tensors and
the FEM's vectors.

- :class:`ElementPoolMaterial`: the material (``strain_measure = "gradient"``): each element
  takes its point's displacement-gradient increment and returns its stress and tangent;
- :data:`TANGENTS`: the element tangents the FEM's Jacobian can be built from;
  :func:`secant_update`: the network tangent changed to reproduce the increment's stress;
- :func:`dem_increment`, :func:`fem_stress`, :func:`voigt_stress`, :func:`fem_tangent`: the
  plane-strain FEM's (x, y) as the element's (x, z), its y held; Voigt with engineering
  shear.

Stresses tension positive, Pa.
"""

from __future__ import annotations

import numpy as np
from cpp_dem import fixedorder

from femcoupling._checks import FemInputError
from femcoupling.coupling.handover import HandoverError, spd_floor
from femcoupling.fem.mpi_points import StartStress
from femcoupling.fem.quadrature import NewtonFailure

__all__ = ["ElementPoolMaterial", "TANGENTS", "dem_increment", "fem_stress", "fem_tangent",
           "secant_update", "voigt_stress"]

_IX = [0, 2, 4]  # DEM Voigt (xx, yy, zz, yz, xz, xy) rows of the FEM's (xx, yy, xy)


def dem_increment(g: np.ndarray) -> np.ndarray:
    """The DEM element's 3 x 3 increment from a FEM 2 x 2 displacement-gradient increment:
    FEM (x, y) -> element (x, z); the out-of-plane y is held (plane strain)."""
    de = np.zeros((3, 3))
    de[0, 0], de[0, 2], de[2, 0], de[2, 2] = g[0, 0], g[0, 1], g[1, 0], g[1, 1]
    return de


def fem_stress(s: np.ndarray) -> np.ndarray:
    """FEM Voigt stress (xx, yy, xy), Pa, from the element's 3 x 3 stress."""
    return np.array([s[0, 0], s[2, 2], 0.5 * (s[0, 2] + s[2, 0])])


def voigt_stress(s: np.ndarray) -> np.ndarray:
    """Voigt stress (xx, yy, zz, yz, xz, xy), Pa, from a 3 x 3 stress (its symmetric part)."""
    s = np.asarray(s, float)
    return np.array([s[0, 0], s[1, 1], s[2, 2], 0.5 * (s[1, 2] + s[2, 1]),
                     0.5 * (s[0, 2] + s[2, 0]), 0.5 * (s[0, 1] + s[1, 0])])


def fem_tangent(d6: np.ndarray) -> np.ndarray:
    """FEM 3 x 3 tangent (xx, yy, xy; engineering shear) from the element's 6 x 6 Voigt one."""
    return np.asarray(d6)[np.ix_(_IX, _IX)]


#: The element tangents the FEM's Jacobian can be built from.
TANGENTS = {
    "network": "the contact network's stiffness at the relaxed state: contacts on their "
               "friction cone there slide, the others stick (relaxation leaves few on the "
               "cone, so it is close to the elastic network tangent, and equal to it where "
               "none is)",
    "network-elastic": "the contact network's stiffness with every contact stuck: the "
                       "elastic network tangent",
    "secant": "the network tangent changed (BFGS, rank two) to reproduce the element's "
              "stress increment over the step's strain increment so far: it sees the "
              "sliding of the increment; the network tangent where the increment is zero "
              "or the element gave back energy",
}


def secant_update(tangent: np.ndarray, strain: np.ndarray, stress: np.ndarray,
                  min_eig_fraction: float = 1e-3) -> np.ndarray | None:
    """The FEM tangent (3 x 3, Voigt xx, yy, xy with engineering shear, Pa) changed to map
    the strain increment ``strain`` (3,) onto the stress increment ``stress`` (3,), both
    tension positive: T - (T de)(T de)^T / (de . T de) + ds ds^T / (ds . de) on the
    symmetric, positive part of ``tangent`` (eigenvalues raised to ``min_eig_fraction`` of the
    largest). None where no positive secant exists (ds . de <= 0: the element gave back
    energy) or the increment is zero."""
    try:
        t = spd_floor(tangent, min_eig_fraction, name="secant_update")
    except HandoverError:  # (no positive stiffness at all)
        return None
    td = fixedorder.matmul(t, strain)
    curv_t, curv = fixedorder.dot(strain, td), fixedorder.dot(stress, strain)
    if not (curv_t > 0 and curv > 1e-12 * curv_t):
        return None
    return t - np.outer(td, td) / curv_t + np.outer(stress, stress) / curv



class ElementPoolMaterial(StartStress):
    """The DEM elements of an ``ElementPool`` as the material of the hierarchical mode's
    quadrature points (a ``femcoupling.fem.quadrature.QuadratureMaterial``; element k is point k).

    ``trial(g)``: ``g`` (n, 2, 2) the displacement-gradient increments since the last commit
    (shear and rotation included; FEM (x, y) is the element's (x, z), its y held: plane
    strain); every element, restored to its committed state if an earlier trial moved it
    (``pool.reject``: a rejected iterate leaves no trace), takes its increment and returns
    its stress and ``tangent``; returns the FEM Voigt stresses (n, 3), Pa, tension positive,
    and tangents (n, 3, 3: xx, yy, xy with engineering shear), Pa. A tangent far from
    positive (its smallest eigenvalue below -10 % of its largest) or not finite is not a
    softening element but a near-singular network solve (seen as -730 MPa against +3 MPa, it
    sent Newton away): such an element keeps its last good tangent for the iterate
    (``bad_tangents`` counts them). With tangent="secant" the network tangent is changed to
    map the increment onto the stress increment (``secant_update``; ``secants_used``).
    ``commit`` accepts (``pool.accept``: the states saved on the workers); ``state`` and
    ``set_state`` are the pool's accepted states (bytes per element) with the committed
    stresses and tangents. Its ``strain_measure`` is "gradient"; ``stress_n`` the committed
    stresses; ``plastic`` 0 (an element's plasticity is in its contacts)."""

    strain_measure = "gradient"

    def __init__(self, pool, *, tangent: str = "network", strain_kw: dict | None = None,
                 dim: int = 2) -> None:
        from cpp_dem.elements.pool import ElementError

        if dim not in (2, 3) or (dim == 3 and tangent == "secant"):
            raise FemInputError(f"dim={dim!r}, tangent={tangent!r}: dim 2 (plane strain) or 3; "
                                "the secant tangent in 2D only")
        self.dim = dim
        self._element_error = ElementError
        self.pool, self.tangent_kind = pool, tangent
        self.strain_kw = dict(strain_kw or {})
        #: what the elements are asked for (the secant is built here from the network one)
        self._element_tangent = "network" if tangent == "secant" else tangent
        self.bad_tangents = 0
        self.secants_used = 0
        self.tangent = None
        first = pool.apply_strain([np.zeros((3, 3))] * pool.n, tangent=self._element_tangent,
                                  **self.strain_kw)
        pool.reject()  # (a zero increment with relaxation: measured, then undone)
        self._pending = False
        self.increments = np.zeros((pool.n, 3, 3))
        self.stress, self.tangent = self._fem_answers(first.stresses, first.tangents)
        self.stress_start = self.stress.copy()  # the element stresses at the step's start
        self.last_step = first
        self.scatter = None
        self.new_step_counters()

    def new_step_counters(self) -> None:
        """Zero the step's DEM seconds, pool seconds and recovered elements."""
        self.step_dem_s = self.step_pool_s = 0.0
        self.step_recovered: list = []

    def _fem_answers(self, stresses, tangents) -> tuple[np.ndarray, np.ndarray]:
        if self.dim == 3:  # (the element's own Voigt order and engineering shear)
            sig = np.array([voigt_stress(s) for s in stresses])
            tan = np.array([np.asarray(t, float) for t in tangents])
        else:
            sig = np.array([fem_stress(s) for s in stresses])
            tan = np.array([fem_tangent(t) for t in tangents])
        if self.tangent_kind == "secant":  # (the first call's increments are zero)
            for k, g in enumerate(self.increments):
                de = np.array([g[0, 0], g[2, 2], g[0, 2] + g[2, 0]])  # (FEM x, y = DEM x, z)
                if np.any(de != 0):
                    c = secant_update(tan[k], de, sig[k] - self.stress_start[k])
                    if c is not None:
                        tan[k] = c
                        self.secants_used += 1
        last = self.tangent
        for k, c in enumerate(tan):
            ok = bool(np.all(np.isfinite(c)))
            if ok:
                ev = fixedorder.eigvalsh(0.5 * (c + c.T))
                ok = ev[0] >= -0.1 * ev[-1]
            if not ok and last is not None:
                tan[k] = last[k]
                self.bad_tangents += 1
        return sig, tan

    def trial(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._pending:
            self.pool.reject()
        self.increments = (np.array(g, float) if self.dim == 3 else
                           np.array([dem_increment(x) for x in g]))
        self._pending = True
        try:
            step = self.pool.apply_strain(list(self.increments), tangent=self._element_tangent,
                                          scatter=True, **self.strain_kw)
        except self._element_error as e:  # an element could not take this iterate: cut
            raise NewtonFailure(f"an element failed on this iterate: {e}") from e
        self.stress, self.tangent = self._fem_answers(step.stresses, step.tangents)
        to_fem = voigt_stress if self.dim == 3 else fem_stress
        self.scatter = (None if step.scatters is None else
                        np.array([to_fem(c) for c in step.scatters]))
        self.last_step = step
        self.step_dem_s += float(sum(step.cpu_s))
        self.step_pool_s += step.wall_s
        self.step_recovered = self.step_recovered + step.recovered
        return self.stress, self.tangent

    def reject(self) -> None:
        """Back to the committed state (the last trial leaves no trace)."""
        self.pool.reject()
        self._pending = False

    def commit(self) -> None:
        self.pool.accept()
        self._pending = False
        self.stress_start = self.stress.copy()

    def state(self) -> tuple:
        """The pool's accepted states (bytes per element), the committed stresses and
        tangents."""
        return self.pool.states(), self.stress_start.copy(), self.tangent.copy()

    def set_state(self, data) -> None:
        """Back to a ``state()``: the elements, their stresses and tangents."""
        states, stress, tangent = data
        self.pool.load_states(states)
        self._pending = False
        self.stress_start = np.array(stress, float)
        self.stress, self.tangent = self.stress_start.copy(), np.array(tangent, float)
