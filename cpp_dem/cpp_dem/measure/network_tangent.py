"""The tangent stiffness of a granular assembly in a periodic cell from its contact network.

The network (stiffness-matrix) approach of Kruyt & Rothenburg (1998, "Statistical theories for
the elastic moduli of two-dimensional assemblies of granular materials", Int. J. Eng. Sci.
36:1127) and of Agnolin & Roux (2007, "Internal states of model isotropic granular packings.
III. Elastic properties", Phys. Rev. E 76:061304): under a homogeneous strain increment the
grains' translations and rotations relax to equilibrium of the linearised contact forces, and
the stress increment follows from the contact force increments (Love–Weber). The frozen
network gives the quasi-static tangent of the current state; an affine (Voigt) estimate
without the relaxation is returned beside it.

Conventions (SI units):

- Contact c joins grain ``i[c]`` and grain ``j[c]`` (indices 0 .. n_bodies-1);
  ``branch[c]`` = x_j + H s - x_i (m, to j's periodic image), ``normal[c]`` = branch/|branch|
  (from i to j); ``li[c]``, ``lj[c]`` (m) are the distances from the centres to the contact
  point along the normal.
- The force on j is f = fn n + fs (``fn`` > 0 repulsive, N; ``fs`` the elastic shear force,
  N); i gets -f. ``kn``, ``ks`` are the tangent stiffnesses (N/m), ``tan_phi`` the friction.
- **Stress here is tension positive** (continuum mechanics): sigma = -(1/V) sum f (x) l (Pa).
  The rest of the project reports compression positive (its negative).
- A strain increment E is a displacement-gradient increment (3 x 3, -): the mean field moves
  x by E x. The tangent D (Pa) gives d sigma_ij = D_ijkl E_kl; ``to_voigt`` turns it into the
  6 x 6 matrix of the symmetric parts (order xx, yy, zz, yz, xz, xy; engineering shear).

Kinematics of a contact with grain translations u (m) and small rotations theta (rad): the
relative displacement of j's contact point, delta = u_j - u_i + E l + lj n x theta_j +
li n x theta_i, and the change of the branch, dl = u_j - u_i + E l. The linearised force:

    df = -K delta                                        (elastic or sliding)
         + fn (I - n n) dl / |l| + omega x fs            (geometric: the frame turns)

with K = kn n n + ks (I - n n) (sliding: the shear part along t = fs/|fs| replaced by the
cone, + tan_phi kn t n), and omega = n x dl / |l| + n (n . (theta_i + theta_j) / 2) the
rotation of the contact frame. Moments about the centres include the turn of the lever arms.
With the geometric terms a rigid spin gives d sigma = W sigma - sigma W exactly.

The stiffness matrix has the rigid translations of the periodic assembly and the rattlers'
motions as null space: 1e-10 x its mean diagonal is added to the diagonal for the
factorisation (the right-hand sides have no component in the null space), four passes of
iterative refinement against the unregularised matrix remove its effect on the soft modes,
and the residual of the solved system is reported.
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from cpp_dem import fixedorder
from cpp_dem._core import ParameterError

#: Voigt order of the 6 x 6 tangents.
VOIGT = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]x for each row of v (C, 3) -> (C, 3, 3): [v]x a = v x a."""
    s = np.zeros(v.shape[:-1] + (3, 3))
    s[..., 0, 1], s[..., 0, 2] = -v[..., 2], v[..., 1]
    s[..., 1, 0], s[..., 1, 2] = v[..., 2], -v[..., 0]
    s[..., 2, 0], s[..., 2, 1] = -v[..., 1], v[..., 0]
    return s


def _arr(x, name: str, shape_tail=()) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}: must be numbers") from None
    if a.shape[1:] != tuple(shape_tail) or a.ndim != 1 + len(shape_tail):
        raise ParameterError(f"{name}: expected shape (C{''.join(', ' + str(t) for t in shape_tail)}),"
                             f" got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ParameterError(f"{name}: must be finite")
    return a


def stress_from_contacts(*, branch, normal=None, fn, fs, volume: float) -> np.ndarray:
    """Love–Weber stress, Pa, **tension positive**, not symmetrised:
    -(1/V) sum_c (fn n + fs) (x) l (n = the given normals, or branch / |branch|)."""
    if not (np.isfinite(volume) and volume > 0):
        raise ParameterError(f"volume={volume}: must be > 0 (m^3)")
    l = _arr(branch, "branch", (3,))
    n = l / np.linalg.norm(l, axis=1)[:, None] if normal is None else _arr(normal, "normal", (3,))
    f = _arr(fn, "fn")[:, None] * n + _arr(fs, "fs", (3,))
    return -np.einsum("ci,cj->ij", f, l) / volume


def _one_blas_thread(fn):
    """``fn`` with BLAS on one thread: OpenBLAS splits some of its kernels (SuperLU's dense
    supernode solves go through them) by the number of threads, so their rounding, and the
    tangent's, would depend on it (a Dask worker runs one thread, the client process as many
    as the machine has cores). Same input, same output."""

    @functools.wraps(fn)
    def one_thread(*args, **kw):
        with _blas_controller().limit(limits=1, user_api="blas"):
            return fn(*args, **kw)

    return one_thread


@functools.cache
def _blas_controller():
    """The BLAS libraries loaded once SciPy's sparse solvers are (found once: a fresh look
    costs 0.8 ms, against 0.01 ms to set their threads)."""
    import scipy.sparse.linalg  # noqa: F401  (loads SciPy's OpenBLAS)
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@_one_blas_thread
def network_tangent(*, i, j, branch, normal, li, lj, kn, ks, fn, fs, tan_phi, volume: float,
                    n_bodies: int, rotations: bool = True, sliding: str = "plastic",
                    geometric: bool = True, bonded=None, k_bend=None, k_twist=None,
                    weights=None) -> tuple[np.ndarray, dict]:
    """The tangent D (3, 3, 3, 3), Pa, tension positive, of the contact network (see the module
    doc), and an info dict: ``n_contacts_used``, ``n_sliding``, ``n_rattlers`` (grains with
    fewer than 2 contacts), ``residual`` (of the solved equilibrium, relative), ``affine`` (D
    without the grains' relaxation), ``affine_voigt``, ``elapsed_s``.

    ``sliding``: "plastic" (contacts at the Coulomb limit slide on the cone) or "elastic";
    ``rotations``: False holds the grains' rotations at zero; ``geometric``: include the turn
    of the contact frame, of the branch vectors and of the lever arms, and the volume change.

    Bonds (a sheet's, ``cpp_dem.laws`` bond records) enter as more rows of the same arrays:
    ``bonded`` (C,) bool marks them. A bonded row is kept in tension (``fn`` < 0) and never
    slides; its ``kn``, ``ks`` are its springs along and across the normal (the linear
    contact's plus the parallel bond's k_bar A). ``k_bend``, ``k_twist`` (C,), N m/rad: the
    parallel bond's rotational springs on the relative rotation of its two spheres, across
    and about the normal (0 for a contact; default none). Their moments do not enter the
    Love–Weber stress; they hold the grains' rotations. The turn of a bond's stored moment
    with its frame is left out (a second-order term for the moments a sheet carries).
    ``weights`` (C,): each row's weight in the stress sum (default 1): the stress of a
    continuum that counts a part of the network more than once (a band's sheet,
    ``DemElement.set_band_thickness``). The grains' equilibrium does not depend on them.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    t0 = time.perf_counter()
    if sliding not in ("plastic", "elastic"):
        raise ParameterError(f"sliding={sliding!r}: must be 'plastic' or 'elastic'")
    if not (np.isfinite(volume) and volume > 0):
        raise ParameterError(f"volume={volume}: must be > 0 (m^3)")
    if int(n_bodies) < 1:
        raise ParameterError(f"n_bodies={n_bodies}: must be >= 1")
    nb = int(n_bodies)
    I = np.asarray(i, dtype=np.int64)
    J = np.asarray(j, dtype=np.int64)
    C = len(I)
    if len(J) != C:
        raise ParameterError(f"j: has {len(J)} entries for {C} contacts")
    if C and (I.min() < 0 or J.min() < 0 or I.max() >= nb or J.max() >= nb):
        raise ParameterError(f"i, j: body indices must be in [0, n_bodies={nb})")
    l = _arr(branch, "branch", (3,))
    n = _arr(normal, "normal", (3,))
    arrays = {k: _arr(v, k) for k, v in (("li", li), ("lj", lj), ("kn", kn), ("ks", ks),
                                         ("fn", fn), ("tan_phi", tan_phi))}
    f_s = _arr(fs, "fs", (3,))
    for k, v in (("k_bend", k_bend), ("k_twist", k_twist), ("weights", weights)):
        arrays[k] = np.zeros(C) if v is None and k != "weights" else (
            np.ones(C) if v is None else _arr(v, k))
    bond = np.zeros(C, bool) if bonded is None else np.asarray(bonded, dtype=bool)
    if bond.shape != (C,):
        raise ParameterError(f"bonded: expected shape ({C},), got {bond.shape}")
    for k, a in list(arrays.items()) + [("branch", l), ("normal", n), ("fs", f_s)]:
        if len(a) != C:
            raise ParameterError(f"{k}: has {len(a)} entries for {C} contacts")
    use = (arrays["fn"] > 0) | bond
    I, J, l, n, f_s, bond = I[use], J[use], l[use], n[use], f_s[use], bond[use]
    a_li, a_lj, k_n, k_s, f_n, mu, k_b, k_t, wt = (
        arrays[k][use] for k in ("li", "lj", "kn", "ks", "fn", "tan_phi", "k_bend", "k_twist",
                                 "weights"))
    C = len(I)
    eye = np.eye(3)
    nn = np.einsum("ca,cb->cab", n, n)
    K = k_n[:, None, None] * nn + k_s[:, None, None] * (eye - nn)
    fs_norm = np.linalg.norm(f_s, axis=1)
    slide = np.zeros(C, bool)
    if sliding == "plastic":
        slide = (fs_norm >= mu * f_n * (1 - 1e-9)) & (fs_norm > 0) & ~bond
        if slide.any():
            t = f_s[slide] / fs_norm[slide, None]
            tt = np.einsum("ca,cb->cab", t, t)
            K[slide] -= k_s[slide, None, None] * tt
            K[slide] += (mu[slide] * k_n[slide])[:, None, None] * np.einsum("ca,cb->cab", t, n[slide])
    lnorm = np.linalg.norm(l, axis=1)
    nx = _skew(n)
    # G: delta = G q + E l, q = (u_i, th_i, u_j, th_j); H: dl = H q + E l; P: (th_i + th_j)/2.
    G = np.zeros((C, 3, 12))
    G[:, :, 0:3] = -eye
    G[:, :, 6:9] = eye
    if rotations:
        G[:, :, 3:6] = a_li[:, None, None] * nx
        G[:, :, 9:12] = a_lj[:, None, None] * nx
    H = np.zeros((C, 3, 12))
    H[:, :, 0:3] = -eye
    H[:, :, 6:9] = eye
    if geometric:
        fsx = _skew(f_s)
        M1 = (f_n / lnorm)[:, None, None] * (eye - nn) - np.einsum("cab,cbd->cad", fsx, nx) / lnorm[:, None, None]
        M2 = -np.einsum("cab,cbd->cad", fsx, nn)
        P = np.zeros((C, 3, 12))
        if rotations:
            P[:, :, 3:6] = 0.5 * eye
            P[:, :, 9:12] = 0.5 * eye
        S = np.einsum("cab,cbj->caj", K, G) - np.einsum("cab,cbj->caj", M1, H) - np.einsum("cab,cbj->caj", M2, P)
        R = K - M1
        # The lever arms turn: moment rows get l_side [f]x (I - n n) dl / |l| (tau = -l n x f).
        f = f_n[:, None] * n + f_s
        fx = _skew(f)
        T = np.zeros((C, 12, 3))
        if rotations:
            base = np.einsum("cab,cbd->cad", fx, eye - nn) / lnorm[:, None, None]
            T[:, 3:6, :] = a_li[:, None, None] * base
            T[:, 9:12, :] = a_lj[:, None, None] * base
    else:
        S = np.einsum("cab,cbj->caj", K, G)
        R = K
        T = np.zeros((C, 12, 3))
        f = f_n[:, None] * n + f_s
    # Global system: sum_c (G^T S - T H) q = sum_c (T - G^T R) E l.
    blocks = np.einsum("cai,caj->cij", G, S) - np.einsum("cia,caj->cij", T, H)
    if rotations and (np.any(k_b) or np.any(k_t)):
        # a bond's rotational springs: moment on j -Kr (th_j - th_i), on i the opposite
        kr = k_b[:, None, None] * (eye - nn) + k_t[:, None, None] * nn
        blocks[:, 3:6, 3:6] += kr
        blocks[:, 9:12, 9:12] += kr
        blocks[:, 3:6, 9:12] -= kr
        blocks[:, 9:12, 3:6] -= kr
    dofs = np.concatenate([6 * I[:, None] + np.arange(6), 6 * J[:, None] + np.arange(6)], axis=1)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    ndof = 6 * nb
    kg = sp.coo_matrix((blocks.ravel(), (rows, cols)), shape=(ndof, ndof)).tocsc()
    diag = np.abs(kg.diagonal())
    reg = 1e-10 * (diag[diag > 0].mean() if np.any(diag > 0) else 1.0)
    if not rotations:
        rot = np.zeros(ndof, bool)
        rot.reshape(nb, 6)[:, 3:] = True
        kg = kg + sp.diags(np.where(rot, 1.0, 0.0) * (diag.mean() if diag.any() else 1.0))
    kreg = (kg + reg * sp.eye(ndof)).tocsc()
    coef = np.einsum("cia,cab->cib", T, np.broadcast_to(eye, (C, 3, 3))) - np.einsum("cai,cab->cib", G, R)
    # right-hand sides for the 9 unit strains e_k (x) e_l: (E l) = e_k l_l
    rhs = np.zeros((ndof, 9))
    for k in range(3):
        for m in range(3):
            contrib = coef[:, :, k] * l[:, m][:, None]
            rhs[:, 3 * k + m] = np.bincount(dofs.ravel(), weights=contrib.ravel(), minlength=ndof)
    # The grains' rotations are solved relative to the strain's rigid spin w = axial(skew E):
    # every grain turning with it is the exact answer to a spin (for a network in
    # equilibrium), and the null modes (rattlers, grains free to spin about a chain of two
    # contacts) then take the continuum's spin, as the DEM's mean spin gives them, instead of
    # an arbitrary one.
    q_spin = np.zeros((ndof, 9))
    if rotations:
        for k in range(3):
            for m in range(3):
                e = np.zeros((3, 3))
                e[k, m] = 1.0
                w = 0.5 * (e - e.T)
                q_spin.reshape(nb, 6, 9)[:, 3:, 3 * k + m] = [w[2, 1], w[0, 2], w[1, 0]]
    rhs_rel = rhs - kg @ q_spin
    lu = spla.splu(kreg)
    q = lu.solve(rhs_rel)
    # Iterative refinement against the unregularised matrix: the regularisation's error on the
    # stiff modes shrinks by reg / (lambda + reg) per pass (exactly null modes get nothing).
    for _ in range(4):
        q += lu.solve(rhs_rel - kg @ q)
    q += q_spin
    res = kg @ q - rhs
    residual = math.sqrt(fixedorder.sum_squares(res)) / max(
        math.sqrt(fixedorder.sum_squares(rhs)), 1e-300)
    sigma = -np.einsum("ci,cj->ij", wt[:, None] * f, l) / volume
    D = np.zeros((3, 3, 3, 3))
    A = np.zeros((3, 3, 3, 3))
    for k in range(3):
        for m in range(3):
            El = np.zeros((C, 3))
            El[:, k] = l[:, m]
            qc = q[dofs, 3 * k + m]  # (C, 12)
            for target, qq in ((D, qc), (A, np.zeros_like(qc))):
                df = -(np.einsum("caj,cj->ca", S, qq) + np.einsum("cab,cb->ca", R, El))
                ds = -np.einsum("ci,cj->ij", wt[:, None] * df, l) / volume
                if geometric:
                    dl = np.einsum("caj,cj->ca", H, qq) + El
                    ds += -np.einsum("ci,cj->ij", wt[:, None] * f, dl) / volume
                    if k == m:
                        ds -= sigma
                target[:, :, k, m] = ds
    counts = np.bincount(I, minlength=nb) + np.bincount(J, minlength=nb)
    info = {"n_contacts_used": int(C), "n_sliding": int(slide.sum()),
            "n_rattlers": int(np.sum(counts < 2)), "residual": residual, "affine": A,
            "affine_voigt": to_voigt(A), "elapsed_s": time.perf_counter() - t0}
    return D, info


def to_voigt(D: np.ndarray) -> np.ndarray:
    """6 x 6 (xx, yy, zz, yz, xz, xy; engineering shear strain) of the symmetric parts:
    row a = the symmetrised stress component, column b = the unit symmetric strain."""
    D = np.asarray(D, dtype=float)
    if D.shape != (3, 3, 3, 3):
        raise ParameterError(f"D: expected shape (3, 3, 3, 3), got {D.shape}")
    out = np.zeros((6, 6))
    for a, (p, q) in enumerate(VOIGT):
        for b, (k, m) in enumerate(VOIGT):
            col = D[:, :, k, k] if k == m else 0.5 * (D[:, :, k, m] + D[:, :, m, k])
            out[a, b] = 0.5 * (col[p, q] + col[q, p])
    return out


def from_voigt(C: np.ndarray) -> np.ndarray:
    """The (3, 3, 3, 3) tangent with minor symmetries of a 6 x 6 Voigt matrix (to_voigt's)."""
    C = np.asarray(C, dtype=float)
    if C.shape != (6, 6):
        raise ParameterError(f"C: expected shape (6, 6), got {C.shape}")
    D = np.zeros((3, 3, 3, 3))
    for a, (p, q) in enumerate(VOIGT):
        for b, (k, m) in enumerate(VOIGT):
            v = C[a, b] if k == m else 0.5 * C[a, b]
            for (pp, qq) in {(p, q), (q, p)}:
                for (kk, mm) in {(k, m), (m, k)}:
                    D[pp, qq, kk, mm] = v
    return D


__all__ = ["network_tangent", "stress_from_contacts", "to_voigt", "from_voigt", "VOIGT"]
