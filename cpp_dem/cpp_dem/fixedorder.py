"""Small vector arithmetic in a fixed order, for what a scene is built from.

NumPy hands a vector's ``np.linalg.norm``, ``a @ b`` and ``np.dot`` to BLAS, whose kernel (picked
by the CPU, or by ``OPENBLAS_CORETYPE``) sums in its own order; LAPACK's ``eigh`` rounds as that
kernel does. A scene built from such a number differs in the last bit between machines, and a
chaotic packing grows the bit into another sample (docs/core.md, "The same bits on every x86-64
CPU"). These helpers use +, -, *, / and sqrt in a fixed order: the same bits everywhere."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["cayley_rate", "det3", "dot", "eigh", "eigvalsh", "eigvalsh3_batch", "inv3", "matmul",
           "matmul3", "line_slope", "norm", "on_grid", "powers", "rows_matmul", "sum_squares",
           "unit", "weighted_rows"]


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


def sum_squares(a) -> float:
    """The sum of the squares of every entry of the array ``a``: each square rounded once (as
    IEEE multiplication is on every CPU), their sum exactly rounded (``math.fsum``), so the
    same bits whatever the order, the CPU or the BLAS kernel. For the norms a decision reads
    (a Newton's residual against its tolerance)."""
    x = np.asarray(a, dtype=float).ravel()
    return math.fsum(x * x)


def dot(a, b) -> float:
    """The sum of the products of the entries of the arrays ``a`` and ``b`` (same shape): each
    product rounded once, their sum exactly rounded (``math.fsum``)."""
    x, y = np.asarray(a, dtype=float).ravel(), np.asarray(b, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"dot: shapes {x.shape} and {y.shape} differ")
    return math.fsum(x * y)


# ---- 3 x 3 matrices (a periodic cell's map), each entry summed left to right ----------------
# (NumPy hands even a 3 x 3 product to BLAS, and SciPy's matrix functions to LAPACK)

def _m(a) -> list:
    return [[float(x) for x in row] for row in np.asarray(a, dtype=float).reshape(3, 3)]


def matmul3(a, b) -> np.ndarray:
    """The product of two 3 x 3 matrices."""
    a, b = _m(a), _m(b)
    return np.array([[a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j]
                      for j in range(3)] for i in range(3)])


def _det3(a: list) -> float:
    return (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]))


def det3(a) -> float:
    """The determinant of a 3 x 3 matrix (cofactors of the first row)."""
    return _det3(_m(a))


def inv3(a) -> np.ndarray:
    """The inverse of a 3 x 3 matrix (its adjugate over its determinant); ValueError if
    the determinant is 0."""
    m = _m(a)
    d = _det3(m)
    if d == 0.0:
        raise ValueError("inv3: the matrix is singular")
    c = lambda i, j: (m[(j + 1) % 3][(i + 1) % 3] * m[(j + 2) % 3][(i + 2) % 3]  # noqa: E731
                      - m[(j + 1) % 3][(i + 2) % 3] * m[(j + 2) % 3][(i + 1) % 3])
    return np.array([[c(i, j) / d for j in range(3)] for i in range(3)])


def _fro(a: np.ndarray) -> float:
    return norm(a)


def _expm1(x: np.ndarray) -> np.ndarray:
    """exp(X) - I of a 3 x 3 matrix, with no cancellation for a small X: the Taylor series
    of X / 2^s (|X| / 2^s <= 1/8), then s doublings E(2X) = E(X) (2 I + E(X))."""
    s = 0
    while _fro(x) / 2.0**s > 0.125:
        s += 1
    y = np.asarray(x, float) / 2.0**s
    term, out = y.copy(), y.copy()
    for k in range(2, 30):
        term = matmul3(term, y) / k
        out = out + term
        if _fro(term) <= 1e-18 * _fro(out):
            break
    for _ in range(s):
        out = 2.0 * out + matmul3(out, out)
    return out


def _logm(f: np.ndarray) -> np.ndarray:
    """The principal logarithm of a 3 x 3 matrix near I (a cell's map: a stretch of at most
    tens of per cent and a rotation below 180 degrees): square roots (Denman-Beavers) until
    |Y - I| <= 1/8, the Taylor series of log(I + X), times 2^s."""
    y, z = np.asarray(f, float), np.eye(3)
    s = 0
    while _fro(y - np.eye(3)) > 0.125:
        if s == 40:
            raise ValueError("logm: no square root converged (a map too far from I)")
        for _ in range(100):  # Denman-Beavers: Y -> F^(1/2)
            y_next = 0.5 * (y + inv3(z))
            z = 0.5 * (z + inv3(y))
            done = _fro(y_next - y) <= 1e-16 * _fro(y_next)
            y = y_next
            if done:
                break
        z = np.eye(3)
        s += 1
    x = y - np.eye(3)
    term, out = x.copy(), x.copy()
    for k in range(2, 200):
        term = -matmul3(term, x) * ((k - 1) / k)
        out = out + term
        if _fro(term) <= 1e-18 * _fro(out):
            break
    return out * 2.0**s


def cayley_rate(f, n: int) -> np.ndarray:
    """L dt: the constant velocity gradient (times the step) whose ``n`` steps of Cayley's
    map, F <- (I - L dt / 2)^-1 (I + L dt / 2) F, give the 3 x 3 map ``f`` (det > 0, near
    I): A = F^(1/n) = exp(log F / n) and L dt = 2 (A - I)(A + I)^-1, with A - I taken
    without cancellation (``exp(X) - I`` directly)."""
    b = _expm1(_logm(f) / float(n))
    return 2.0 * matmul3(b, inv3(2.0 * np.eye(3) + b))


# ---- symmetric eigenproblems -----------------------------------------------------------------

def _rotate(m: list, s: float, tau: float, i: int, j: int, k: int, l: int) -> None:
    g, h = m[i][j], m[k][l]
    m[i][j] = g - s * (h + g * tau)
    m[k][l] = h + s * (g - h * tau)


def eigh(a) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and unit eigenvectors (columns) of the symmetric n x n ``a``, by
    cyclic Jacobi rotations in plain floating point (+, -, *, / and sqrt, in a fixed order):
    the same bits on every CPU and BLAS. (LAPACK's eigh rounds as its BLAS kernel does: a
    clump's principal frame decides every member's place, and another kernel grew into
    another sample of a chaotic packing.) For the small tensors of a scene or a material
    point (n up to 6 or so: each sweep is n^3 Python operations)."""
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or not np.all(np.isfinite(a)):
        raise ValueError(f"eigh: a finite square matrix is needed (shape {a.shape})")
    n = a.shape[0]
    m = [[float(a[i][j]) for j in range(n)] for i in range(n)]
    v = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    d = [m[i][i] for i in range(n)]
    b = list(d)
    z = [0.0] * n
    for sweep in range(1, 51):
        off = 0.0
        for p in range(n - 1):
            for q in range(p + 1, n):
                off += abs(m[p][q])
        if off == 0.0:
            break
        tresh = 0.2 * off / (n * n) if sweep < 4 else 0.0
        for p in range(n - 1):
            for q in range(p + 1, n):
                g = 100.0 * abs(m[p][q])
                if sweep > 4 and abs(d[p]) + g == abs(d[p]) and abs(d[q]) + g == abs(d[q]):
                    m[p][q] = 0.0
                elif abs(m[p][q]) > tresh:
                    h = d[q] - d[p]
                    if abs(h) + g == abs(h):
                        t = m[p][q] / h
                    else:
                        theta = 0.5 * h / m[p][q]
                        t = 1.0 / (abs(theta) + math.sqrt(1.0 + theta * theta))
                        if theta < 0.0:
                            t = -t
                    c = 1.0 / math.sqrt(1.0 + t * t)
                    s = t * c
                    tau = s / (1.0 + c)
                    h = t * m[p][q]
                    z[p] -= h
                    z[q] += h
                    d[p] -= h
                    d[q] += h
                    m[p][q] = 0.0
                    for j in range(p):
                        _rotate(m, s, tau, j, p, j, q)
                    for j in range(p + 1, q):
                        _rotate(m, s, tau, p, j, j, q)
                    for j in range(q + 1, n):
                        _rotate(m, s, tau, p, j, q, j)
                    for j in range(n):
                        _rotate(v, s, tau, j, p, j, q)
        for p in range(n):
            b[p] += z[p]
            d[p] = b[p]
            z[p] = 0.0
    else:
        raise ArithmeticError(f"eigh: {a.tolist()}: Jacobi rotations did not converge in "
                              "50 sweeps (not a symmetric matrix?)")
    order = sorted(range(n), key=lambda i: (d[i], i))
    return (np.array([d[i] for i in order]),
            np.array([[v[r][i] for i in order] for r in range(n)]))


def eigvalsh(a) -> np.ndarray:
    """The eigenvalues (ascending) of the symmetric n x n ``a`` (:func:`eigh`)."""
    return eigh(a)[0]


def matmul(a, b) -> np.ndarray:
    """``a @ b`` of small arrays (a vector or a matrix each, as NumPy's ``@``), each entry
    summed left to right. For a material point's tensors; a large product belongs in
    compiled code."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    a2 = a[None, :] if a.ndim == 1 else a
    b2 = b[:, None] if b.ndim == 1 else b
    if a2.ndim != 2 or b2.ndim != 2 or a2.shape[1] != b2.shape[0]:
        raise ValueError(f"matmul: shapes {a.shape} and {b.shape} do not chain")
    al, bl = a2.tolist(), b2.T.tolist()
    out = np.empty((len(al), len(bl)))
    for i, row in enumerate(al):
        for j, col in enumerate(bl):
            s = 0.0
            for x, y in zip(row, col):
                s += x * y
            out[i, j] = s
    if a.ndim == 1:
        out = out[0]
    if b.ndim == 1:
        out = out[..., 0]
    return out


def weighted_rows(w, rows) -> np.ndarray:
    """``w @ rows``: the sum over k of ``w[k] * rows[k]`` (rows (n, ...)), each product
    rounded once and each entry's sum exactly rounded (``math.fsum``): a volume mean's
    numerator the same on every CPU."""
    w = np.asarray(w, dtype=float).ravel()
    r = np.asarray(rows, dtype=float)
    if r.shape[0] != w.shape[0]:
        raise ValueError(f"weighted_rows: {w.shape[0]} weights for {r.shape[0]} rows")
    if not len(w):  # (no rows here: an MPI rank without a region's points)
        return np.zeros(r.shape[1:])
    prod = (w.reshape((-1,) + (1,) * (r.ndim - 1)) * r).reshape(len(w), -1)
    return np.array([math.fsum(prod[:, k]) for k in range(prod.shape[1])]).reshape(r.shape[1:])


def eigvalsh3_batch(a) -> np.ndarray:
    """The eigenvalues (ascending) of many symmetric 3 x 3 matrices ``a`` (n, 3, 3), by cyclic
    Jacobi rotations applied to all at once (elementwise +, -, *, / and sqrt: the same bits
    on every CPU; LAPACK's batched eigvalsh calls BLAS)."""
    m = np.array(a, dtype=float).reshape(-1, 3, 3)
    m = 0.5 * (m + np.swapaxes(m, 1, 2))
    for _ in range(60):
        off = np.abs(m[:, 0, 1]) + np.abs(m[:, 0, 2]) + np.abs(m[:, 1, 2])
        diag = np.abs(m[:, 0, 0]) + np.abs(m[:, 1, 1]) + np.abs(m[:, 2, 2])
        if not np.any(off > 1e-17 * (diag + off)):
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = m[:, p, q]
            nz = apq != 0.0
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                theta = np.where(nz, (m[:, q, q] - m[:, p, p]) / (2.0 * np.where(nz, apq, 1.0)),
                                 0.0)
                big = np.abs(theta) > 1e150
                t = np.where(big, 0.5 / np.where(big, theta, 1.0),
                             np.sign(theta) / (np.abs(theta) + np.sqrt(
                                 np.where(big, 0.0, theta * theta) + 1.0)))
            t = np.where(nz, np.where(theta == 0.0, 1.0, t), 0.0)
            c = 1.0 / np.sqrt(t * t + 1.0)
            s = t * c
            cp, cq = m[:, :, p].copy(), m[:, :, q].copy()
            m[:, :, p] = c[:, None] * cp - s[:, None] * cq
            m[:, :, q] = s[:, None] * cp + c[:, None] * cq
            rp, rq = m[:, p, :].copy(), m[:, q, :].copy()
            m[:, p, :] = c[:, None] * rp - s[:, None] * rq
            m[:, q, :] = s[:, None] * rp + c[:, None] * rq
    else:
        raise ArithmeticError("eigvalsh3_batch: Jacobi rotations did not converge")
    return np.sort(np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1), axis=1)


def rows_matmul(d, m) -> np.ndarray:
    """``d @ m`` of many rows ``d`` (n, k) and a small matrix ``m`` (k, p), summed over k left
    to right, elementwise over the rows (BLAS's gemm sums in its kernel's order)."""
    d, m = np.asarray(d, dtype=float), np.asarray(m, dtype=float)
    if d.ndim != 2 or m.ndim != 2 or d.shape[1] != m.shape[0]:
        raise ValueError(f"rows_matmul: shapes {d.shape} and {m.shape} do not chain")
    out = d[:, :1] * m[0][None, :]
    for k in range(1, m.shape[0]):
        out = out + d[:, k:k + 1] * m[k][None, :]
    return out


def line_slope(x, y) -> float:
    """The least-squares slope of y against x (``np.polyfit(x, y, 1)[0]``, whose LAPACK calls
    BLAS): sum (x - mean x)(y - mean y) / sum (x - mean x)^2, the sums exactly rounded."""
    x, y = np.asarray(x, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape or len(x) < 2:
        raise ValueError(f"line_slope: x {x.shape} and y {y.shape}: two or more points each")
    dx = x - math.fsum(x) / len(x)
    dy = y - math.fsum(y) / len(y)
    return math.fsum(dx * dy) / math.fsum(dx * dx)


def on_grid(values, digits: int) -> np.ndarray:
    """``values`` (any shape) rounded to the grid of ``digits`` significant digits of their
    largest |entry|: a result whose last bits another CPU's BLAS would round otherwise (a
    sparse LU's, whose supernodes call BLAS) then has the same bits, unless an entry lies
    within that last-bit noise of a grid line (a chance of about 1e-16 / 10^-digits)."""
    v = np.asarray(values, dtype=float)
    finite = v[np.isfinite(v)]
    big = float(np.abs(finite).max()) if finite.size else 0.0
    if not big > 0:
        return v.copy()
    step = 10.0 ** (math.floor(math.log10(big)) - int(digits) + 1)
    return np.round(v / step) * step


def powers(x, p: float) -> np.ndarray:
    """``x ** p`` of every entry of the array ``x``, each by the C library's ``pow`` (as
    Python's ``math.pow``). NumPy's power of an array (``r**3`` too) takes its AVX-512 form
    on a CPU that has it and rounds otherwise there: a periodic cloud's edge, from its
    grains' ``r**3``, took another last bit for 29 seeds in 2000, and those were other
    packings. glibc's ``pow`` is one function on every x86-64 CPU with FMA (one without FMA,
    before 2013, takes another variant)."""
    a = np.asarray(x, dtype=float)
    p = float(p)
    return np.array([math.pow(v, p) for v in a.ravel().tolist()]).reshape(a.shape)
