"""Soil and geogrid materials and the Drucker–Prager return mapping (pure NumPy kernels).

Sign convention: **tension positive** (continuum mechanics); a compressive mean stress p is
negative. Stresses and strains are Mandel vectors (shear components scaled by sqrt 2, so that
dot products are the tensor double contractions):

- plane strain (2D), coordinates (x, z), z vertical, y out of plane:
  ``(s_xx, s_zz, s_yy, sqrt2 s_xz)`` -- index 2 is the out-of-plane component;
- 3D, coordinates (x, y, z): ``(s_xx, s_yy, s_zz, sqrt2 s_yz, sqrt2 s_xz, sqrt2 s_xy)``.

Drucker–Prager yield function and plastic potential (perfect plasticity)::

    f = alpha I1 + sqrt(J2) - k,     g = beta I1 + sqrt(J2)

matched to Mohr–Coulomb (c, phi) in **plane strain with associated flow** (Drucker &
Prager 1952; e.g. de Souza Neto et al., *Computational Methods for Plasticity*, 2008, §8.2):
alpha = tan(phi) / sqrt(9 + 12 tan^2 phi), k = 3 c / sqrt(9 + 12 tan^2 phi). With associated
flow (beta = alpha) the plane-strain collapse loads of this cone equal Mohr–Coulomb's.
For non-associated flow (dilation psi < phi), beta is obtained from psi the same way; the
match of the collapse load is then approximate.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
from cpp_dem import fixedorder

from femcoupling._checks import FemInputError, _pos, _real

__all__ = ["LinearElastic", "AnisotropicElastic", "DruckerPrager", "GeogridLayerMaterial",
           "elastic_tangent", "isotropic_projection", "stiffness_block",
           "voigt_to_mandel_stiffness",
           "drucker_prager_return", "mandel_identity", "mandel_to_tensor",
           "tensor_to_mandel", "PLANE_STRAIN_OF_3D"]

SQRT2 = math.sqrt(2.0)


@dataclasses.dataclass(frozen=True)
class LinearElastic:
    """Isotropic linear elasticity: Young's modulus ``young_pa`` (Pa, > 0), ``poisson`` (-)."""

    young_pa: float
    poisson: float

    def __post_init__(self) -> None:
        _pos("young_pa", self.young_pa)
        nu = _real("poisson", self.poisson)
        if not -1.0 < nu < 0.5:
            raise FemInputError(f"poisson={nu!r}: must be in (-1, 0.5)")

    @property
    def bulk_pa(self) -> float:
        """Bulk modulus K = E / (3 (1 - 2 nu)), Pa."""
        return self.young_pa / (3.0 * (1.0 - 2.0 * self.poisson))

    @property
    def shear_pa(self) -> float:
        """Shear modulus G = E / (2 (1 + nu)), Pa."""
        return self.young_pa / (2.0 * (1.0 + self.poisson))

    def k0(self) -> float:
        """At-rest coefficient of an elastic soil under 1D loading, nu / (1 - nu), -."""
        return self.poisson / (1.0 - self.poisson)

    def dp_parameters(self) -> tuple[float, float, float]:
        """(alpha, beta, k/Pa) of the yield function: never yields (k = inf)."""
        return 0.0, 0.0, math.inf

    def at_points(self, stress_pa: npt.ArrayLike):
        """This material at quadrature points whose committed stress is ``stress_pa``
        ((n, ncomp) Mandel, Pa): a ``femcoupling.fem.quadrature.QuadratureMaterial``
        (``DruckerPragerPoints`` on this material's cone; an elastic one never yields)."""
        a, b, k = self.dp_parameters()
        return DruckerPragerPoints(bulk_pa=self.bulk_pa, shear_pa=self.shear_pa, alpha=a,
                                   beta=b, k_pa=k, stress_pa=stress_pa)


PLANE_STRAIN_OF_3D = (0, 2, 1, 4)
"""The 3D Mandel components (xx, yy, zz, yz, xz, xy) that make the plane-strain ones
(xx, zz, yy, xz)."""


def isotropic_projection(c_mandel_pa: npt.ArrayLike) -> tuple[float, float]:
    """The isotropic (K, G) nearest to a 6 x 6 Mandel stiffness (Pa): K = (1 : C : 1) / 9,
    G = (tr C - 3K) / 10 (the projection on 3K P_vol + 2G P_dev)."""
    c = np.asarray(c_mandel_pa, float)
    one = mandel_identity(6)
    k = fixedorder.dot(one, fixedorder.matmul(c, one)) / 9.0
    return k, (float(np.trace(c)) - 3.0 * k) / 10.0


def stiffness_block(c_mandel_pa: npt.ArrayLike, ncomp: int) -> npt.NDArray[np.float64]:
    """A 6 x 6 Mandel stiffness (Pa) for Mandel vectors of length ``ncomp``: itself (6, 3D),
    or its (xx, zz, yy, xz) rows and columns (4, plane strain: ``PLANE_STRAIN_OF_3D``)."""
    c = np.array(c_mandel_pa, float)
    if ncomp == 4:
        idx = list(PLANE_STRAIN_OF_3D)
        return c[np.ix_(idx, idx)]
    return c


def voigt_to_mandel_stiffness(c_voigt_pa: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """A 6 x 6 stiffness in Voigt form (stress components by engineering strains, order xx
    yy zz yz xz xy, as ``DemElement``'s tangents) -> Mandel form (Pa)."""
    d = np.array([1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2])
    return d[:, None] * np.asarray(c_voigt_pa, float) * d[None, :]


@dataclasses.dataclass(frozen=True, init=False)
class AnisotropicElastic(LinearElastic):
    """Linear elasticity with a full stiffness: ``c_mandel_pa``, 6 x 6 in 3D Mandel form
    (order xx yy zz yz xz xy, Pa), symmetric positive definite. In plane strain the model
    takes its (xx, zz, yy, xz) rows and columns (``PLANE_STRAIN_OF_3D``). ``young_pa`` and
    ``poisson`` are those of its isotropic projection (:func:`isotropic_projection`), for what
    needs an isotropic value (the at-rest coefficient). It never yields. The two-way loop
    gives it to a region from the DEM element's tangent (:mod:`femcoupling.coupling.twoway`)."""

    c_mandel_pa: tuple = ()

    def __init__(self, c_mandel_pa: npt.ArrayLike) -> None:
        c = np.asarray(c_mandel_pa, float)
        if c.shape != (6, 6) or not np.all(np.isfinite(c)):
            raise FemInputError(f"c_mandel_pa: shape {c.shape}, must be a finite 6 x 6 Mandel "
                                "stiffness (Pa)")
        scale = float(np.abs(c).max())
        if not scale > 0 or float(np.abs(c - c.T).max()) > 1e-9 * scale:
            raise FemInputError(f"c_mandel_pa: not symmetric (largest |C - C^T| "
                                f"{float(np.abs(c - c.T).max()):.3g} Pa of {scale:.3g} Pa)")
        c = 0.5 * (c + c.T)
        low = float(fixedorder.eigvalsh(c).min())
        if not low > 0:
            raise FemInputError(f"c_mandel_pa: not positive definite (smallest eigenvalue "
                                f"{low:.3g} Pa); a stiffness must store energy")
        k, g = isotropic_projection(c)
        object.__setattr__(self, "c_mandel_pa", tuple(map(tuple, c)))
        object.__setattr__(self, "young_pa", 9.0 * k * g / (3.0 * k + g))
        object.__setattr__(self, "poisson", (3.0 * k - 2.0 * g) / (2.0 * (3.0 * k + g)))

    def at_points(self, stress_pa: npt.ArrayLike):
        """This material at quadrature points whose committed stress is ``stress_pa``
        ((n, ncomp) Mandel, Pa): :class:`ElasticPoints` with the full
        stiffness (never yields)."""
        stress = np.asarray(stress_pa, float)
        c = self.matrix(stress.shape[1])
        return ElasticPoints(np.repeat(c[None], len(stress), axis=0), stress)

    def matrix(self, ncomp: int = 6) -> npt.NDArray[np.float64]:
        """The stiffness for Mandel vectors of length ``ncomp`` (6: 3D, 4: plane strain), Pa."""
        return stiffness_block(self.c_mandel_pa, ncomp)


@dataclasses.dataclass(frozen=True)
class DruckerPrager(LinearElastic):
    """Elastic–perfectly plastic Drucker–Prager soil matched to Mohr–Coulomb in plane strain.

    Attributes:
        young_pa, poisson: elasticity (Pa, -).
        cohesion_pa: Mohr–Coulomb cohesion c, Pa, >= 0.
        friction_deg: Mohr–Coulomb friction angle phi, deg, in [0, 60].
        dilation_deg: dilation angle psi, deg, in [0, phi]; None means associated (psi = phi).
    """

    cohesion_pa: float = 0.0
    friction_deg: float = 30.0
    dilation_deg: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if _real("cohesion_pa", self.cohesion_pa) < 0:
            raise FemInputError(f"cohesion_pa={self.cohesion_pa!r}: must be >= 0")
        phi = _real("friction_deg", self.friction_deg)
        if not 0.0 <= phi <= 60.0:
            raise FemInputError(f"friction_deg={phi!r}: must be in [0, 60]")
        if self.dilation_deg is not None:
            psi = _real("dilation_deg", self.dilation_deg)
            if not 0.0 <= psi <= phi:
                raise FemInputError(f"dilation_deg={psi!r}: must be in [0, friction_deg={phi}]")
        if self.cohesion_pa == 0.0 and phi == 0.0:
            raise FemInputError("cohesion_pa=0 and friction_deg=0: the soil has no strength")

    def k0(self) -> float:
        """Jaky's at-rest coefficient 1 - sin(phi), -."""
        return 1.0 - math.sin(math.radians(self.friction_deg))

    def dp_parameters(self) -> tuple[float, float, float]:
        """(alpha, beta, k/Pa): plane-strain match to Mohr–Coulomb (module doc)."""
        t = math.tan(math.radians(self.friction_deg))
        root = math.sqrt(9.0 + 12.0 * t * t)
        psi = self.friction_deg if self.dilation_deg is None else self.dilation_deg
        tp = math.tan(math.radians(psi))
        return t / root, tp / math.sqrt(9.0 + 12.0 * tp * tp), 3.0 * self.cohesion_pa / root


@dataclasses.dataclass(frozen=True)
class GeogridLayerMaterial:
    """A geogrid layer as a thin band of cells (the band's thickness is in the geometry).

    Attributes:
        axial_stiffness_n_per_m: geogrid tensile stiffness J, N/m (the band gets E = J / t).
        prestress_n_per_m: prestress force per metre width T_p, N/m, >= 0 (PRS, 002): an
            initial tensile stress T_p / t along x in the band, equilibrated with the soil
            by :meth:`femcoupling.fem.model.FemModel.apply_prestress`.
        poisson: Poisson's ratio of the band, -.
    """

    axial_stiffness_n_per_m: float
    prestress_n_per_m: float = 0.0
    poisson: float = 0.0

    def __post_init__(self) -> None:
        _pos("axial_stiffness_n_per_m", self.axial_stiffness_n_per_m)
        if _real("prestress_n_per_m", self.prestress_n_per_m) < 0:
            raise FemInputError(f"prestress_n_per_m={self.prestress_n_per_m!r}: must be >= 0 "
                                "(tension)")
        LinearElastic(1.0, self.poisson)

    def band(self, thickness_m: float) -> LinearElastic:
        """The band's elastic material for a band ``thickness_m`` thick (E = J / t)."""
        return LinearElastic(self.axial_stiffness_n_per_m / thickness_m, self.poisson)


# ---- Mandel algebra -----------------------------------------------------------------------


def mandel_identity(ncomp: int) -> npt.NDArray[np.float64]:
    """The identity tensor as a Mandel vector of length 4 (plane strain) or 6 (3D)."""
    i = np.zeros(ncomp)
    i[:3] = 1.0
    return i


def elastic_tangent(bulk_pa: npt.ArrayLike, shear_pa: npt.ArrayLike,
                    ncomp: int) -> npt.NDArray[np.float64]:
    """C = 3K P_vol + 2G P_dev (Mandel), shape (n, ncomp, ncomp) for n values of K, G (Pa)."""
    k = np.atleast_1d(np.asarray(bulk_pa, float))
    g = np.atleast_1d(np.asarray(shear_pa, float))
    one = mandel_identity(ncomp)
    pvol = np.outer(one, one) / 3.0
    pdev = np.eye(ncomp) - pvol
    return 3.0 * k[:, None, None] * pvol + 2.0 * g[:, None, None] * pdev


def mandel_to_tensor(v: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Mandel vectors (..., 4 or 6) -> 3x3 tensors (..., 3, 3) ordered (x, y, z)."""
    v = np.asarray(v, float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    if v.shape[-1] == 4:  # (xx, zz, yy_out, sqrt2 xz)
        out[..., 0, 0] = v[..., 0]
        out[..., 2, 2] = v[..., 1]
        out[..., 1, 1] = v[..., 2]
        out[..., 0, 2] = out[..., 2, 0] = v[..., 3] / SQRT2
    elif v.shape[-1] == 6:
        for a in range(3):
            out[..., a, a] = v[..., a]
        for k, (a, b) in enumerate(((1, 2), (0, 2), (0, 1))):
            out[..., a, b] = out[..., b, a] = v[..., 3 + k] / SQRT2
    else:
        raise FemInputError(f"Mandel vector length {v.shape[-1]}: must be 4 or 6")
    return out


def tensor_to_mandel(t: npt.ArrayLike, ncomp: int) -> npt.NDArray[np.float64]:
    """3x3 tensors (x, y, z) -> Mandel vectors of length ``ncomp`` (4: plane strain, 6: 3D)."""
    t = np.asarray(t, float)
    if ncomp == 4:
        return np.stack([t[..., 0, 0], t[..., 2, 2], t[..., 1, 1], SQRT2 * t[..., 0, 2]], -1)
    return np.stack([t[..., 0, 0], t[..., 1, 1], t[..., 2, 2], SQRT2 * t[..., 1, 2],
                     SQRT2 * t[..., 0, 2], SQRT2 * t[..., 0, 1]], -1)


APEX_TANGENT_FRACTION = 1e-6
"""At the cone's apex the consistent tangent is zero; this fraction of C keeps the Jacobian
regular (it only slows Newton where points sit at the apex)."""


def drucker_prager_return(sig_trial: npt.NDArray[np.float64], *, bulk_pa, shear_pa, alpha,
                          beta, k_pa) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return mapping of trial stresses onto the Drucker–Prager cone, with consistent tangent.

    Args:
        sig_trial: (n, ncomp) trial stresses (Mandel, Pa, tension positive).
        bulk_pa, shear_pa: (n,) elastic moduli K, G, Pa.
        alpha, beta: (n,) friction and dilatancy coefficients of f and g, -.
        k_pa: (n,) cohesion term of f, Pa (inf: elastic).

    Returns:
        (sig, tangent, dlambda): (n, ncomp) stresses, (n, ncomp, ncomp) consistent tangents
        (Pa), (n,) plastic multipliers (0 where elastic; -1 marks the apex).

    Cone return (derivation in docs/fem.md): with n = s_tr / |s_tr| the unit deviator,
    dlambda = f_tr / (G + 9 K alpha beta), sig = sig_tr - dlambda (3 K beta I + sqrt2 G n),
    C_ep = C - a_g (x) a_f / (G + 9 K alpha beta) - 2 sqrt2 G^2 dlambda / |s_tr| (P_dev - n (x) n)
    with a_g = 3 K beta I + sqrt2 G n and a_f = 3 K alpha I + sqrt2 G n. Apex return
    (when sqrt(J2_tr) - G dlambda < 0): sig = k / (3 alpha) I.
    """
    sig_trial = np.asarray(sig_trial, float)
    n, ncomp = sig_trial.shape
    K = np.broadcast_to(np.asarray(bulk_pa, float), (n,))
    G = np.broadcast_to(np.asarray(shear_pa, float), (n,))
    al = np.broadcast_to(np.asarray(alpha, float), (n,))
    be = np.broadcast_to(np.asarray(beta, float), (n,))
    kk = np.broadcast_to(np.asarray(k_pa, float), (n,))
    one = mandel_identity(ncomp)
    C = elastic_tangent(K, G, ncomp)
    p = sig_trial[:, :3].sum(1) / 3.0
    s = sig_trial - p[:, None] * one
    snorm = np.linalg.norm(s, axis=1)
    sqrt_j2 = snorm / SQRT2
    with np.errstate(invalid="ignore"):
        f = 3.0 * al * p + sqrt_j2 - kk
    f = np.where(np.isfinite(kk), f, -np.inf)
    plastic = f > 0.0
    sig = sig_trial.copy()
    tangent = C.copy()
    dlam = np.zeros(n)
    if np.any(plastic):
        idx = np.flatnonzero(plastic)
        Ki, Gi, ai, bi, ki = K[idx], G[idx], al[idx], be[idx], kk[idx]
        denom = Gi + 9.0 * Ki * ai * bi
        dl = f[idx] / denom
        cone = sqrt_j2[idx] - Gi * dl >= 0.0
        # cone points
        c_idx = idx[cone]
        if c_idx.size:
            Kc, Gc, ac, bc, dlc = Ki[cone], Gi[cone], ai[cone], bi[cone], dl[cone]
            nhat = s[c_idx] / snorm[c_idx, None]
            ag = 3.0 * Kc[:, None] * bc[:, None] * one + SQRT2 * Gc[:, None] * nhat
            af = 3.0 * Kc[:, None] * ac[:, None] * one + SQRT2 * Gc[:, None] * nhat
            sig[c_idx] = sig_trial[c_idx] - dlc[:, None] * ag
            pdev = np.eye(ncomp) - np.outer(one, one) / 3.0
            coef = 2.0 * SQRT2 * Gc**2 * dlc / snorm[c_idx]
            tangent[c_idx] = (C[c_idx] - np.einsum("ni,nj->nij", ag, af)
                              / (Gc + 9.0 * Kc * ac * bc)[:, None, None]
                              - coef[:, None, None] * (pdev[None] - np.einsum("ni,nj->nij",
                                                                                nhat, nhat)))
            dlam[c_idx] = dlc
        a_idx = idx[~cone]
        if a_idx.size:
            if np.any(al[a_idx] <= 0):
                raise FloatingPointError("Drucker-Prager apex return with alpha = 0")
            sig[a_idx] = (kk[a_idx] / (3.0 * al[a_idx]))[:, None] * one
            tangent[a_idx] = APEX_TANGENT_FRACTION * C[a_idx]
            dlam[a_idx] = -1.0
    return sig, tangent, dlam


# ---- the laws at quadrature points (femcoupling.fem.quadrature.QuadratureMaterial) ----------

class _StressPoints:
    """The committed and trial stress of ``n`` continuum points (Mandel, Pa): they take
    Mandel strain increments (``strain_measure``, femcoupling.fem.quadrature.STRAIN_MEASURES)."""

    strain_measure = "mandel"
    plastic: np.ndarray

    def __init__(self, stress_pa: np.ndarray) -> None:
        self.stress_n = np.array(stress_pa, float)
        if self.stress_n.ndim != 2:
            raise ValueError(f"stress_pa: shape {self.stress_n.shape}; (n, ncomp) expected")
        self.stress = self.stress_n.copy()  #: the last trial's stress
        self.plastic = np.zeros(len(self.stress_n))

    @property
    def n(self) -> int:
        return len(self.stress_n)

    def commit(self) -> None:
        """The last trial's stress becomes the committed one."""
        self.stress_n = self.stress.copy()

    def state(self) -> np.ndarray:
        """The committed stress, (n, ncomp), Pa."""
        return self.stress_n.copy()

    def set_state(self, data: np.ndarray) -> None:
        """Return to a committed stress ``data`` ((n, ncomp), Pa)."""
        data = np.array(data, float)
        if data.shape != self.stress_n.shape:
            raise ValueError(f"set_state: shape {data.shape}; {self.stress_n.shape} expected")
        self.stress_n, self.stress = data, data.copy()


class ElasticPoints(_StressPoints):
    """Linear elastic points: ``stiffness_pa`` (n, ncomp, ncomp) Mandel (isotropic or full
    anisotropic), committed stress ``stress_pa`` (n, ncomp). ``trial(strain increment
    (n, ncomp))`` gives sigma_n + C d_eps and C."""

    def __init__(self, stiffness_pa: np.ndarray, stress_pa: np.ndarray) -> None:
        super().__init__(stress_pa)
        self.C = np.ascontiguousarray(stiffness_pa, dtype=float)
        if self.C.shape != (self.n,) + (self.stress_n.shape[1],) * 2:
            raise ValueError(f"stiffness_pa: shape {self.C.shape}; (n, ncomp, ncomp) expected")

    def trial(self, increment: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self.stress = self.stress_n + np.einsum("nij,nj->ni", self.C, increment)
        return self.stress, self.C.copy()


class DruckerPragerPoints(_StressPoints):
    """Drucker–Prager points (:func:`drucker_prager_return`): moduli
    ``bulk_pa``, ``shear_pa`` and cone ``alpha``, ``beta``, ``k_pa`` ((n,) or scalars; k = inf
    never yields), committed stress ``stress_pa`` (n, ncomp). ``trial`` gives the returned
    stress and the consistent tangent; ``plastic`` is the last trial's plastic multiplier per
    point (0 elastic, -1 apex)."""

    def __init__(self, *, bulk_pa, shear_pa, alpha, beta, k_pa, stress_pa) -> None:
        super().__init__(stress_pa)
        full = lambda a: np.array(np.broadcast_to(np.asarray(a, float), (self.n,)))  # noqa: E731
        self.K, self.G = full(bulk_pa), full(shear_pa)
        self.alpha, self.beta, self.k = full(alpha), full(beta), full(k_pa)
        self.C = elastic_tangent(self.K, self.G, self.stress_n.shape[1])

    def trial(self, increment: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sig_tr = self.stress_n + np.einsum("nij,nj->ni", self.C, increment)
        sig, tan, dl = drucker_prager_return(sig_tr, bulk_pa=self.K, shear_pa=self.G,
                                             alpha=self.alpha, beta=self.beta, k_pa=self.k)
        self.stress, self.plastic = sig, dl
        return sig, tan
