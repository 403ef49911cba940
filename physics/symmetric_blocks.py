"""Symmetric block-sparse matrices of 3x3 blocks, each pair's block stored once.

Implicit Euler's Newton matrix A = M - h D - h^2 K (:func:`.sparse_jacobian.newton_matrix`)
is symmetric, with a 3x3 block on the diagonal for each body and one on either side of
it for each pair of bodies a force connects, the (j, i) block the transpose of the
(i, j) one. Stored as block-sparse rows (BSR), every pair's block is there twice; here
it is kept once, above the diagonal (lo < hi), and used both ways round:

    (A x)_i = A_ii x_i + sum over pairs (i, j) of C x_j  +  sum over pairs (j, i) of C^T x_j.

For the bench's cloth (25,600 particles, 101,442 pairs) that is 127,042 blocks, 9.1 MB,
where the BSR array holds 228,484 (16.4 MB); the matrix is symmetric by construction, as
conjugate gradients need it. The product goes row by row (:func:`product`): 0.4 ms on
the cloth, where a compiled BSR product takes 0.5 and scipy's 0.8. The rows' pairs above
the diagonal are contiguous (the pairs are sorted by row), which the Gauss-Seidel sweeps
of :mod:`steplab.integrators.gauss_seidel` also walk.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit


@dataclasses.dataclass(frozen=True, eq=False)
class PairIndex:
    """The pairs (lo, hi), lo < hi, of a symmetric block matrix of ``size`` block rows, by row.

    Attributes
    ----------
    size : int
    lo, hi : int64 ndarray, shape (U,)
        The block row and column of each stored block, sorted by (lo, hi).
    above_ptr : int64 ndarray, shape (size + 1,)
        Row r's pairs above the diagonal, (r, hi), are ``above_ptr[r]:above_ptr[r + 1]``.
    """

    size: int
    lo: np.ndarray
    hi: np.ndarray
    above_ptr: np.ndarray

    @classmethod
    def of(cls, size: int, lo, hi) -> PairIndex:
        """The index of pairs (lo, hi), lo < hi < size, sorted, without repeats (each pair once)."""
        lo, hi = np.asarray(lo, np.int64), np.asarray(hi, np.int64)
        if lo.size and not (np.all(lo < hi) and lo.min() >= 0 and hi.max() < size):
            raise ValueError(f"symmetric blocks: pairs need 0 <= lo < hi < {size}")
        order = np.lexsort((hi, lo))
        lo, hi = lo[order], hi[order]
        if np.any((np.diff(lo) == 0) & (np.diff(hi) == 0)):
            raise ValueError("symmetric blocks: a pair is listed twice")
        return cls(size, lo, hi, np.searchsorted(lo, np.arange(size + 1)).astype(np.int64))

    @property
    def n_pairs(self) -> int:
        return self.lo.size


@dataclasses.dataclass(frozen=True, eq=False)
class SymmetricBlockMatrix:
    """A symmetric (3 size, 3 size) matrix of 3x3 blocks: the diagonal ones and one per pair.

    Attributes
    ----------
    blocks : ndarray, shape (size + U, 3, 3)
        ``blocks[:size]`` the diagonal blocks (each symmetric), ``blocks[size + u]`` the
        block at (lo[u], hi[u]); the one at (hi[u], lo[u]) is its transpose.
    pairs : PairIndex
    """

    blocks: np.ndarray
    pairs: PairIndex

    @property
    def size(self) -> int:
        return self.pairs.size

    @property
    def shape(self) -> tuple[int, int]:
        return (3 * self.size, 3 * self.size)

    @property
    def diagonal(self) -> np.ndarray:
        """The diagonal blocks, shape (size, 3, 3) (a view)."""
        return self.blocks[:self.size]

    @property
    def nbytes(self) -> int:
        """Bytes of the blocks and the pair index: what a product reads."""
        return self.blocks.nbytes + self.pairs.lo.nbytes + self.pairs.hi.nbytes

    def __matmul__(self, x):
        x = np.asarray(x, dtype=float)
        if x.shape != (self.shape[1],):
            raise ValueError(f"symmetric blocks: a product needs a vector of {self.shape[1]}, got shape {x.shape}")
        out = np.empty(self.shape[0])
        product(self.blocks, self.pairs.above_ptr, self.pairs.hi, np.ascontiguousarray(x), out)
        return out

    def tobsr(self):
        """The same matrix as a scipy BSR array (every pair's block twice)."""
        from scipy.sparse import bsr_array

        n, lo, hi = self.size, self.pairs.lo, self.pairs.hi
        upper = self.blocks[n:]
        rows = np.concatenate([np.arange(n), lo, hi])
        cols = np.concatenate([np.arange(n), hi, lo])
        data = np.concatenate([self.blocks[:n], upper, upper.transpose(0, 2, 1)])
        order = np.lexsort((cols, rows))
        indptr = np.searchsorted(rows[order], np.arange(n + 1))
        return bsr_array((data[order], cols[order], indptr), shape=self.shape)

    def toarray(self) -> np.ndarray:
        return self.tobsr().toarray()

    @classmethod
    def from_sparse(cls, matrix) -> SymmetricBlockMatrix:
        """A symmetric scipy sparse (or dense) matrix of 3n rows, kept as its blocks on and above the diagonal.

        ValueError if it is not square, not of 3n rows, or not symmetric (to 1e-12 of its
        largest entry: what lies below the diagonal would otherwise be dropped unseen).
        """
        from scipy.sparse import bsr_array

        shape = matrix.shape
        if len(shape) != 2 or shape[0] != shape[1] or shape[0] % 3:
            raise ValueError(f"symmetric blocks: need a square matrix of 3n rows, got shape {shape}")
        bsr = bsr_array(matrix, blocksize=(3, 3))
        bsr.sum_duplicates()
        scale = float(abs(bsr).max()) if bsr.nnz else 0.0
        if bsr.nnz and float(abs(bsr - bsr.T).max()) > 1e-12 * scale:
            raise ValueError("symmetric blocks: the matrix is not symmetric (conjugate gradients need A = A^T)")
        n = shape[0] // 3
        rows = np.repeat(np.arange(n), np.diff(bsr.indptr))
        cols = bsr.indices
        upper = rows < cols
        blocks = np.zeros((n, 3, 3))
        on = rows == cols
        blocks[rows[on]] = bsr.data[on]
        pairs = PairIndex.of(n, rows[upper], cols[upper])
        order = np.lexsort((cols[upper], rows[upper]))
        return cls(np.concatenate([blocks, bsr.data[upper][order]]), pairs)


@njit(cache=True, inline="always")
def times(blocks, m, x0, x1, x2):  # pragma: no cover - compiled
    """blocks[m] x, for x = (x0, x1, x2): the 3x3 product every sweep and product is made of."""
    return (blocks[m, 0, 0] * x0 + blocks[m, 0, 1] * x1 + blocks[m, 0, 2] * x2,
            blocks[m, 1, 0] * x0 + blocks[m, 1, 1] * x1 + blocks[m, 1, 2] * x2,
            blocks[m, 2, 0] * x0 + blocks[m, 2, 1] * x1 + blocks[m, 2, 2] * x2)


@njit(cache=True, inline="always")
def transposed_times(blocks, m, x0, x1, x2):  # pragma: no cover - compiled
    """blocks[m]^T x: a stored block above the diagonal acting as its mirror below it."""
    return (blocks[m, 0, 0] * x0 + blocks[m, 1, 0] * x1 + blocks[m, 2, 0] * x2,
            blocks[m, 0, 1] * x0 + blocks[m, 1, 1] * x1 + blocks[m, 2, 1] * x2,
            blocks[m, 0, 2] * x0 + blocks[m, 1, 2] * x1 + blocks[m, 2, 2] * x2)


@njit(cache=True)
def product(blocks, above_ptr, hi, x, out):  # pragma: no cover - compiled
    """out = A x, row by row: row r's diagonal block and its pairs (r, hi) above the diagonal.

    Each pair's block C adds C x_hi to row r (summed in registers) and C^T x_r to row hi,
    which comes later: so ``out`` starts at zero, and row r, when its turn comes, already
    holds what the rows before it gave it; then it is complete. Returns x . A x, summed
    row by row as each is completed (conjugate gradients' curvature p . A p, for free).
    """
    n = out.size // 3
    out[:] = 0.0
    curvature = 0.0
    for r in range(n):
        a = 3 * r
        x0, x1, x2 = x[a], x[a + 1], x[a + 2]
        y0, y1, y2 = times(blocks, r, x0, x1, x2)
        for u in range(above_ptr[r], above_ptr[r + 1]):
            b, k = 3 * hi[u], n + u
            c0, c1, c2 = times(blocks, k, x[b], x[b + 1], x[b + 2])
            y0, y1, y2 = y0 + c0, y1 + c1, y2 + c2
            t0, t1, t2 = transposed_times(blocks, k, x0, x1, x2)
            out[b] += t0
            out[b + 1] += t1
            out[b + 2] += t2
        out[a] += y0
        out[a + 1] += y1
        out[a + 2] += y2
        curvature += x0 * out[a] + x1 * out[a + 1] + x2 * out[a + 2]
    return curvature
