"""Conjugate gradients for implicit Euler's Newton step: preconditioned, compiled, checked.

The Newton matrix A = M - h D - h^2 K (:func:`steplab.physics.sparse_jacobian.newton_matrix`)
is symmetric positive definite, with 3x3 diagonal blocks that hold most of it: the mass
and each body's own share of its springs. Preconditioning by their inverses (block
Jacobi) takes the masses' spread and each body's own stiffness out of the condition
number; what is left grows as h^2 omega_max^2 of the spring network, and conjugate
gradients need about its square root of iterations, h omega_max, per digit. Symmetric
block Gauss-Seidel (:mod:`.gauss_seidel`, the default) also takes out much of the
coupling between neighbours: on the bench's cloth at its largest useful dt (h omega_max
= 4.5) it needs 5-6 iterations per Newton solve where block Jacobi needs 11-16, and each
costs about 1.6 products with A instead of one (two dependent triangular sweeps,
Eisenstat's trick), so the step takes 41 ms instead of 48.

The iteration is the textbook preconditioned CG (the one :func:`scipy.sparse.linalg.cg`
runs, which ``tests/test_implicit_sparse.py`` compares it with, iterate by iterate, for
both preconditioners), compiled with Numba over the matrix's blocks, each pair's stored
once (:class:`~steplab.physics.symmetric_blocks.SymmetricBlockMatrix`, 0.4 ms a product
on the cloth); an iteration allocates nothing. scipy's loop makes a dozen NumPy and BLAS
calls per iteration instead; on the 2-core development VM, shared with other jobs,
OpenBLAS's idle threads spinning after each vector dot product slowed it down 15-fold
(2.5 s instead of 0.16 s for one step of the bench's cloth), and on a quiet machine it is
still 1.5x slower than a compiled loop.

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
from steplab.physics.symmetric_blocks import product

from .gauss_seidel import backward_sweep, forward_sweep, residual_norm, transformed_product

#: relative residual |b - A x| / |b| a Newton step's solve stops at. Newton's own test
#: (on the update, see implicit_euler) decides when the step is done: a looser solve
#: costs a Newton iteration more, a tighter one more CG iterations in every Newton iteration
#: (1e-3 took the bench's cloth step at dt = 7 ms from 42 CG iterations at 1e-6 to 21, 60 ms
#: to 39, with as many Newton iterations; 1e-2 would take 17, but costs a Newton iteration
#: more in 12 of the 28 steps of the cloth's fall over 0.2 s)
CG_RTOL = 1e-3
#: CG iterations before a solve is reported as not converged (h omega_max = 100 needs
#: about 100 per digit of the residual)
CG_MAX_ITERATIONS = 2_000
#: the preconditioners :func:`solve` knows, and the one it uses unless told (see the module)
PRECONDITIONERS = ("block-jacobi", "gauss-seidel")
PRECONDITIONER = "gauss-seidel"
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


def solve(matrix, b, rtol: float = CG_RTOL, maxiter: int = CG_MAX_ITERATIONS,
          preconditioner: str = PRECONDITIONER) -> CGResult:
    """Solve ``matrix @ x = b`` for a symmetric positive definite ``matrix`` by preconditioned CG.

    From x = 0, stopping at |b - A x| <= rtol |b| or after ``maxiter`` iterations.
    ``matrix`` is a :class:`~steplab.physics.symmetric_blocks.SymmetricBlockMatrix` (as
    :func:`newton_matrix` makes it), or a symmetric scipy sparse or dense array of 3n
    rows, converted to one. ``preconditioner``: ``"gauss-seidel"`` (symmetric block
    Gauss-Seidel, :mod:`.gauss_seidel`) or ``"block-jacobi"`` (the inverses of the 3x3
    diagonal blocks). NotPositiveDefiniteError when a 3x3 diagonal block is not positive
    definite, or CG meets p^T A p <= 0. A non-finite right-hand side gives a non-finite
    x and ``converged = False``, which the caller turns into a failed step.
    """
    from steplab.physics.symmetric_blocks import SymmetricBlockMatrix

    if preconditioner not in PRECONDITIONERS:
        raise ValueError(f"conjugate gradients: preconditioner must be one of {', '.join(PRECONDITIONERS)}, "
                         f"got {preconditioner!r}")
    b = np.asarray(b, dtype=float)
    if not np.all(np.isfinite(b)):
        return CGResult(np.full_like(b, np.nan), 0, float("nan"), False)
    if not isinstance(matrix, SymmetricBlockMatrix):
        matrix = SymmetricBlockMatrix.from_sparse(matrix)
    if b.shape != (matrix.shape[0],):
        raise ValueError(f"conjugate gradients: b needs shape ({matrix.shape[0]},), got {b.shape}")
    inverse = np.empty((matrix.size, 3, 3))
    if not _invert_positive_definite(matrix.diagonal, inverse):
        raise NotPositiveDefiniteError("a 3x3 diagonal block of the matrix is not positive definite")
    x = np.zeros_like(b)
    loop = _gauss_seidel_cg if preconditioner == "gauss-seidel" else _block_jacobi_cg
    iterations, status, residual = loop(matrix.blocks, matrix.pairs.above_ptr, matrix.pairs.hi, inverse, b,
                                        float(rtol), int(maxiter), x)
    if status == _NOT_POSITIVE_DEFINITE:
        raise NotPositiveDefiniteError(f"conjugate gradients met p^T A p <= 0 at iteration {iterations}")
    # a little slack on the stopping test: the recomputed residual differs from the
    # recurrence's by round-off
    return CGResult(x, iterations, residual, bool(residual <= 2 * rtol))


@njit(cache=True)
def _dot(x, y):  # pragma: no cover - compiled
    total = 0.0
    for i in range(x.size):
        total += x[i] * y[i]
    return total


@njit(cache=True)
def _residual(blocks, above_ptr, hi, b, x, work, scale):  # pragma: no cover - compiled
    # |b - A x| / |b| of the x returned, recomputed
    product(blocks, above_ptr, hi, x, work)
    total = 0.0
    for i in range(b.size):
        total += (b[i] - work[i]) ** 2
    return np.sqrt(total) / scale


@njit(cache=True)
def _block_jacobi_cg(blocks, above_ptr, hi, inverse, b, rtol, maxiter, x):  # pragma: no cover - compiled
    # x = 0, r = b, z = D^-1 r, p = z; then alpha = r.z / p.A p, x += alpha p, r -= alpha A p,
    # z = D^-1 r, beta = r.z (new) / r.z (old), p = z + beta p, until |r| <= rtol |b|.
    # Each iteration: one product with A (which sums p.A p as it goes), one pass that
    # updates x and r and applies D^-1 block by block, one for p; no temporaries.
    n = b.size
    r, z, p, q = b.copy(), np.empty(n), np.empty(n), np.empty(n)
    scale = np.sqrt(_dot(b, b))
    if scale == 0:
        return 0, _CONVERGED, 0.0
    rz = 0.0
    for m in range(n // 3):
        for i in range(3):
            zi = inverse[m, i, 0] * r[3 * m] + inverse[m, i, 1] * r[3 * m + 1] + inverse[m, i, 2] * r[3 * m + 2]
            z[3 * m + i] = zi
            rz += r[3 * m + i] * zi
    p[:] = z
    status, iterations = _NOT_CONVERGED, maxiter
    for k in range(maxiter):
        curvature = product(blocks, above_ptr, hi, p, q)
        if not curvature > 0:
            status, iterations = _NOT_POSITIVE_DEFINITE, k
            break
        alpha = rz / curvature
        rr = rz_next = 0.0
        for m in range(n // 3):
            r0 = r[3 * m] - alpha * q[3 * m]
            r1 = r[3 * m + 1] - alpha * q[3 * m + 1]
            r2 = r[3 * m + 2] - alpha * q[3 * m + 2]
            r[3 * m], r[3 * m + 1], r[3 * m + 2] = r0, r1, r2
            rr += r0 * r0 + r1 * r1 + r2 * r2
            for i in range(3):
                x[3 * m + i] += alpha * p[3 * m + i]
                zi = inverse[m, i, 0] * r0 + inverse[m, i, 1] * r1 + inverse[m, i, 2] * r2
                z[3 * m + i] = zi
                rz_next += r[3 * m + i] * zi
        if np.sqrt(rr) <= rtol * scale:
            status, iterations = _CONVERGED, k + 1
            break
        beta = rz_next / rz
        rz = rz_next
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    return iterations, status, _residual(blocks, above_ptr, hi, b, x, q, scale)


@njit(cache=True)
def _gauss_seidel_cg(blocks, above_ptr, hi, inverse, b, rtol, maxiter, x):  # pragma: no cover - compiled
    # CG on A' x' = b' (A' = W^-1 A W^-T, b' = W^-1 b, W = D + L) preconditioned by D:
    # the iterates of CG on A preconditioned by symmetric Gauss-Seidel (see gauss_seidel).
    # r' = W^-1 r, so the stopping test is on |W r'|, half a product; it is taken once
    # |D r'|, free with z' = D r', falls below the tolerance, and from then on every iteration.
    n = b.size
    r, z, p, q, t, work = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    scale = np.sqrt(_dot(b, b))
    if scale == 0:
        return 0, _CONVERGED, 0.0
    forward_sweep(blocks, above_ptr, hi, inverse, b, r, work)
    x_prime = np.zeros(n)
    rz = _diagonal_product(blocks, r, z)
    p[:] = z
    status, iterations, checking = _NOT_CONVERGED, maxiter, False
    for k in range(maxiter):
        curvature = transformed_product(blocks, above_ptr, hi, inverse, p, q, t, work)
        if not curvature > 0:
            status, iterations = _NOT_POSITIVE_DEFINITE, k
            break
        alpha = rz / curvature
        for i in range(n):
            x_prime[i] += alpha * p[i]
            r[i] -= alpha * q[i]
        rz_next = _diagonal_product(blocks, r, z)
        if not checking:
            checking = np.sqrt(_dot(z, z)) <= rtol * scale
        if checking and residual_norm(blocks, above_ptr, hi, r, z, work) <= rtol * scale:
            status, iterations = _CONVERGED, k + 1
            break
        beta = rz_next / rz
        rz = rz_next
        for i in range(n):
            p[i] = z[i] + beta * p[i]
    backward_sweep(blocks, above_ptr, hi, inverse, x_prime, x)  # x = W^-T x'
    return iterations, status, _residual(blocks, above_ptr, hi, b, x, q, scale)


@njit(cache=True)
def _diagonal_product(blocks, r, z):  # pragma: no cover - compiled
    # z = D r, the 3x3 diagonal blocks of A; returns r . z
    rz = 0.0
    for m in range(r.size // 3):
        r0, r1, r2 = r[3 * m], r[3 * m + 1], r[3 * m + 2]
        for i in range(3):
            zi = blocks[m, i, 0] * r0 + blocks[m, i, 1] * r1 + blocks[m, i, 2] * r2
            z[3 * m + i] = zi
            rz += r[3 * m + i] * zi
    return rz


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
        inverse_det = 1.0 / det
        out[k, 0, 0] = c00 * inverse_det
        out[k, 1, 0] = c01 * inverse_det
        out[k, 2, 0] = c02 * inverse_det
        out[k, 0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) * inverse_det
        out[k, 1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) * inverse_det
        out[k, 2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) * inverse_det
        out[k, 0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) * inverse_det
        out[k, 1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) * inverse_det
        out[k, 2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) * inverse_det
    return True
