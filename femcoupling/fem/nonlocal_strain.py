"""A nonlocal strain for the hierarchical mode: the regularisation of a softening body of
DEM elements (docs/coupling_hierarchical.md#a-nonlocal-strain).

A body of DEM elements has no length of its own: once its elements soften, a shear band
narrows to the mesh's cells, and its width and angle follow the mesh. The nonlocal strain
gives the body a length ``length_m``: each element is strained by a weighted mean of the
strain increments around it,

    g_i* = (1 - weight) g_i + weight sum_j a_ij g_j,
    a_ij = v_j exp(-(r_ij / length_m)^2) / sum_k v_k exp(-(r_ik / length_m)^2),

over the points j within ``cutoff`` x ``length_m`` (v_j their volumes, r_ij the distance).
The rows sum to 1, so a homogeneous strain reaches every element unchanged (an element test
is not touched), also by a boundary. A Gaussian's Fourier transform is positive at every
wave number, so no strain pattern averages to nothing and costs nothing (no zero-energy
mode), and with ``weight`` < 1 the element's own strain keeps a share of it (Bazant's
"imbricate" mix; Jirasek 1998). The band's width then scales with ``length_m`` once the cells
are smaller than it.

Newton's matrix is the consistent one (``ElementPart._nonlocal_correction``): a point's force
answers to the strains around it, K = G^T D (A x I) W^-1 G (G the points' strain weighted by
their quadrature weights W, D the elements' tangents); it is not symmetric. A linear body is
solved in one correction (``tests/test_nonlocal_strain.py``). Serial only: a model split over
MPI ranks refuses it.
"""

from __future__ import annotations

import math

import numpy as np

from femcoupling._checks import FemInputError

__all__ = ["NonlocalStrain"]


class NonlocalStrain:
    """The averaging of the strain increments at ``points`` (n, d), m, weighted by
    ``volumes`` (n,), m^3 (m^2 in plane strain), with the length ``length_m`` > 0 and the
    nonlocal share ``weight`` in (0, 1]; ``cutoff`` (x ``length_m``) ends the kernel
    (exp(-9) at the default 3)."""

    def __init__(self, points, volumes, length_m: float, weight: float = 1.0,
                 cutoff: float = 3.0) -> None:
        from scipy.sparse import csr_matrix
        from scipy.spatial import cKDTree

        if not (isinstance(length_m, (int, float)) and math.isfinite(length_m)
                and length_m > 0):
            raise FemInputError(f"nonlocal_length={length_m!r}: must be a length > 0, m (None: "
                                "the local strain)")
        if not (isinstance(weight, (int, float)) and 0 < weight <= 1):
            raise FemInputError(f"nonlocal_weight={weight!r}: must be in (0, 1] (the share of "
                                "the averaged strain; the rest is the point's own)")
        if not (isinstance(cutoff, (int, float)) and cutoff >= 2):
            raise FemInputError(f"cutoff={cutoff!r}: must be >= 2 (x length_m)")
        x = np.asarray(points, float)
        v = np.asarray(volumes, float).reshape(-1)
        if x.ndim != 2 or len(x) != len(v) or not np.all(v > 0):
            raise FemInputError(f"points {x.shape} and volumes {v.shape}: one positive volume "
                                "per point expected")
        self.length_m, self.weight, self.n = float(length_m), float(weight), len(x)
        pairs = cKDTree(x).query_pairs(cutoff * length_m, output_type="ndarray")
        i = np.concatenate([np.arange(self.n), pairs[:, 0], pairs[:, 1]])
        j = np.concatenate([np.arange(self.n), pairs[:, 1], pairs[:, 0]])
        r2 = np.sum((x[i] - x[j]) ** 2, axis=1)
        # (math's exp, not NumPy's: NumPy's exp of an array takes its AVX-512 form on a CPU
        # that has it, and rounds otherwise there)
        w = v[j] * np.array([math.exp(e) for e in (-r2 / length_m ** 2).tolist()])
        a = csr_matrix((w, (i, j)), shape=(self.n, self.n))
        a.sum_duplicates()
        rows = np.asarray(a.sum(axis=1)).reshape(-1)
        a = csr_matrix(a.multiply(1.0 / rows[:, None]))
        a.sort_indices()  # (a fixed summation order)
        self.matrix = a
        #: the share of each point's own strain in its averaged one (diagonal of the mix)
        self.own_share = (1.0 - self.weight) + self.weight * a.diagonal()

    def __repr__(self) -> str:
        return (f"NonlocalStrain(length_m={self.length_m:g}, weight={self.weight:g}, "
                f"{self.n} points, {self.matrix.nnz / self.n:.1f} neighbours each)")

    def apply(self, g: np.ndarray) -> np.ndarray:
        """The averaged increments of ``g`` (n, d, d) (or (n, k)), same shape."""
        g = np.asarray(g, float)
        if len(g) != self.n:
            raise FemInputError(f"increments: {len(g)} points, the averaging has {self.n}")
        flat = g.reshape(self.n, -1)
        out = (1.0 - self.weight) * flat + self.weight * (self.matrix @ flat)
        return out.reshape(g.shape)

    def operator(self):
        """The mix as one sparse matrix, (1 - weight) I + weight A (n x n): what the
        consistent Jacobian multiplies by (``apply`` gives its product with the increments)."""
        from scipy.sparse import identity

        return self.weight * self.matrix + (1.0 - self.weight) * identity(self.n, format="csr")
