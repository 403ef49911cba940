"""Conjugate gradients for implicit Euler's Newton step: block-Jacobi preconditioned, compiled, checked.

The Newton matrix A = M - h D - h^2 K (:func:`steplab.physics.sparse_jacobian.newton_matrix`)
is symmetric positive definite, with 3x3 diagonal blocks that hold most of it: the mass
and each body's own share of its springs. Preconditioning by their inverses (block
Jacobi) takes the masses' spread and each body's own stiffness out of the condition
number; what is left grows as h^2 omega_max^2 of the spring network, and conjugate
gradients need about its square root of iterations, h omega_max, per digit.

The iteration is the textbook preconditioned CG (the one :func:`scipy.sparse.linalg.cg`
runs, which ``tests/test_implicit_sparse.py`` compares it with), compiled with Numba over
the BSR arrays: each iteration is one pass for A p and one for the vector updates.
scipy's loop makes a dozen NumPy and BLAS calls per iteration instead; on the 2-core
development VM, shared with other jobs, OpenBLAS's idle threads spinning after each
vector dot product slowed it down 15-fold (2.5 s instead of 0.16 s for one step of the
bench's cloth), and on a quiet machine it is still 1.5x slower than the compiled loop.

Every solve reports its iterations and its relative residual |b - A x| / |b|,
recomputed from the returned x (one more product with A): a solve that stops short of
its tolerance is never taken for a converged one (:class:`CGConvergenceWarning`). A
direction of non-positive curvature p^T A p <= 0, the proof that A is not positive
definite, stops it with :class:`NotPositiveDefiniteError`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

#: relative residual |b - A x| / |b| a Newton step's solve stops at. Newton's own test
#: (on the update, see implicit_euler) decides when the step is done: a looser solve
#: costs a Newton iteration more, a tighter one more CG iterations in every Newton iteration
#: (1e-3 took the bench's cloth step at dt = 7 ms from 220 ms at 1e-6 to 150 ms, with as
#: many Newton iterations)
CG_RTOL = 1e-3
#: CG iterations before a solve is reported as not converged (h omega_max = 100 needs
#: about 100 per digit of the residual)
CG_MAX_ITERATIONS = 2_000
#: the compiled loop's exits
_CONVERGED, _NOT_CONVERGED, _NOT_POSITIVE_DEFINITE = 0, 1, 2


class CGConvergenceWarning(RuntimeWarning):
    """Conjugate gradients stopped short of their tolerance; the message gives the residual."""


class NotPositiveDefiniteError(ArithmeticError):
    """The matrix has a direction of non-positive curvature, x^T A x <= 0: CG does not apply to it."""


@dataclasses.dataclass(frozen=True)
class CGResult:
    """One conjugate-gradient solve.

    Attributes
    ----------
    x : ndarray, shape (n,)
    iterations : int
    residual : float
        |b - A x| / |b| of the returned x (0 when b = 0), recomputed, not CG's running estimate.
    converged : bool
        Whether the residual is at most the tolerance asked for (never for a non-finite one).
    """

    x: np.ndarray
    iterations: int
    residual: float
    converged: bool


def solve(matrix, b, rtol: float = CG_RTOL, maxiter: int = CG_MAX_ITERATIONS) -> CGResult:
    """Solve ``matrix @ x = b`` for a symmetric positive definite ``matrix`` by block-Jacobi preconditioned CG.

    From x = 0, stopping at |b - A x| <= rtol |b| or after ``maxiter`` iterations.
    ``matrix`` is a scipy sparse array of 3x3 blocks (BSR, as :func:`newton_matrix`
    makes it; any other sparse array is converted). NotPositiveDefiniteError when a 3x3
    diagonal block is not positive definite, or CG meets p^T A p <= 0. A non-finite
    right-hand side gives a non-finite x and ``converged = False``, which the caller
    turns into a failed step.
    """
    from scipy.sparse import bsr_array

    b = np.asarray(b, dtype=float)
    if not np.all(np.isfinite(b)):
        return CGResult(np.full_like(b, np.nan), 0, float("nan"), False)
    if getattr(matrix, "format", None) != "bsr" or matrix.blocksize != (3, 3):
        matrix = bsr_array(matrix, blocksize=(3, 3))
    matrix.sort_indices()
    data = np.ascontiguousarray(matrix.data, dtype=float)
    indices, indptr = matrix.indices.astype(np.int64), matrix.indptr.astype(np.int64)
    rows = np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    diagonal = np.flatnonzero(indices == rows)
    inverse = np.zeros((indptr.size - 1, 3, 3))
    if diagonal.size != inverse.shape[0] or not _invert_positive_definite(data[diagonal], inverse):
        raise NotPositiveDefiniteError("a 3x3 diagonal block of the matrix is not positive definite")
    x = np.zeros_like(b)
    iterations, status, residual = _preconditioned_cg(data, indices, indptr, inverse, b, float(rtol), int(maxiter), x)
    if status == _NOT_POSITIVE_DEFINITE:
        raise NotPositiveDefiniteError(f"conjugate gradients met p^T A p <= 0 at iteration {iterations}")
    # a little slack on the stopping test: the recomputed residual differs from the
    # recurrence's by round-off
    return CGResult(x, iterations, residual, bool(residual <= 2 * rtol))


@njit(cache=True)
def _bsr_product(data, indices, indptr, x, out):  # pragma: no cover - compiled
    for r in range(indptr.size - 1):
        y0 = y1 = y2 = 0.0
        for k in range(indptr[r], indptr[r + 1]):
            c = 3 * indices[k]
            x0, x1, x2 = x[c], x[c + 1], x[c + 2]
            y0 += data[k, 0, 0] * x0 + data[k, 0, 1] * x1 + data[k, 0, 2] * x2
            y1 += data[k, 1, 0] * x0 + data[k, 1, 1] * x1 + data[k, 1, 2] * x2
            y2 += data[k, 2, 0] * x0 + data[k, 2, 1] * x1 + data[k, 2, 2] * x2
        out[3 * r], out[3 * r + 1], out[3 * r + 2] = y0, y1, y2


@njit(cache=True)
def _block_product(blocks, x, out):  # pragma: no cover - compiled
    for r in range(blocks.shape[0]):
        x0, x1, x2 = x[3 * r], x[3 * r + 1], x[3 * r + 2]
        for i in range(3):
            out[3 * r + i] = blocks[r, i, 0] * x0 + blocks[r, i, 1] * x1 + blocks[r, i, 2] * x2


@njit(cache=True)
def _preconditioned_cg(data, indices, indptr, inverse, b, rtol, maxiter, x):  # pragma: no cover - compiled
    # x = 0, r = b, z = M^-1 r, p = z; then alpha = r.z / p.A p, x += alpha p, r -= alpha A p,
    # z = M^-1 r, beta = r.z (new) / r.z (old), p = z + beta p, until |r| <= rtol |b|.
    n = b.size
    r, z, p, q = b.copy(), np.empty(n), np.empty(n), np.empty(n)
    scale = np.sqrt(np.sum(b * b))
    if scale == 0:
        return 0, _CONVERGED, 0.0
    _block_product(inverse, r, z)
    p[:] = z
    rz = np.sum(r * z)
    status, iterations = _NOT_CONVERGED, maxiter
    for k in range(maxiter):
        _bsr_product(data, indices, indptr, p, q)
        curvature = np.sum(p * q)
        if not curvature > 0:
            status, iterations = _NOT_POSITIVE_DEFINITE, k
            break
        alpha = rz / curvature
        rr = 0.0
        for i in range(n):
            x[i] += alpha * p[i]
            r[i] -= alpha * q[i]
            rr += r[i] * r[i]
        if np.sqrt(rr) <= rtol * scale:
            status, iterations = _CONVERGED, k + 1
            break
        _block_product(inverse, r, z)
        rz_next = np.sum(r * z)
        beta = rz_next / rz
        rz = rz_next
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    # the residual of the x returned, recomputed
    _bsr_product(data, indices, indptr, x, q)
    return iterations, status, np.sqrt(np.sum((b - q) ** 2)) / scale


@njit(cache=True)
def _invert_positive_definite(blocks, out):  # pragma: no cover - compiled
    # Each symmetric 3x3 block: positive definite iff its leading minors are positive
    # (Sylvester's criterion); then its inverse is the adjugate over the determinant.
    # False at the first block that is not. (NumPy's batched inv and cholesky take 10x longer.)
    for k in range(blocks.shape[0]):
        a = blocks[k]
        c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
        c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
        c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
        det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
        if not (a[0, 0] > 0 and a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0] > 0 and det > 0):
            return False
        out[k, 0, 0] = c00 / det
        out[k, 1, 0] = c01 / det
        out[k, 2, 0] = c02 / det
        out[k, 0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) / det
        out[k, 1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) / det
        out[k, 2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) / det
        out[k, 0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) / det
        out[k, 1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) / det
        out[k, 2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) / det
    return True
