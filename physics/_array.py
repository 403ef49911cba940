"""Small array helpers that let one force formula run on NumPy and on JAX.

Every model function takes the array namespace ``xp`` (``numpy`` or ``jax.numpy``)
explicitly; the only operations that differ between the two are scatter-adds, which
NumPy does with ``bincount``/``add.at`` and JAX with ``.at[].add`` or, for pair forces,
a gather through each body's pairs (:mod:`.incidence`).
"""

from __future__ import annotations

import numpy as np

from .incidence import incidence, sum_pair_forces, take_rows


def is_numpy(xp) -> bool:
    return xp is np


def rows(xp, x, index):
    """``x[index]``: the rows of ``x`` at a constant index array (on JAX, :func:`.incidence.take_rows`)."""
    return x[index] if is_numpy(xp) else take_rows(x, index)


def scatter_pairs(xp, n: int, i, j, f):
    """Net force on ``n`` bodies from pair forces: ``+f`` on body ``i``, ``-f`` on body ``j``.

    Parameters
    ----------
    i, j : int array, shape (P,)
    f : array, shape (P, 3)
        Force on the first body of each pair (Newton's third law gives the second).
    """
    if is_numpy(xp):
        # bincount is the fastest deterministic scatter-add NumPy has.
        out = np.empty((n, 3), dtype=f.dtype)
        for c in range(3):
            out[:, c] = np.bincount(i, f[:, c], n) - np.bincount(j, f[:, c], n)
        return out
    # JAX: the same sums as a gather through each body's pairs where that pays (XLA:CPU
    # runs a scatter element by element), else the scatter-add
    table = incidence(i, j, n, f.dtype)
    if table is not None:
        return sum_pair_forces(table, f)
    return xp.zeros((n, 3), dtype=f.dtype).at[i].add(f).at[j].add(-f)


def scatter_pair_blocks(xp, n: int, i, j, block):
    """Jacobian (N, 3, N, 3) of pair forces whose block ``d f_i / d x_j`` is ``block``.

    For a pair force ``f_i = f(x_j - x_i)``, ``f_j = -f_i``: the four 3x3 blocks are
    ``(i, j): +B``, ``(i, i): -B``, ``(j, i): +B``, ``(j, j): -B``.
    """
    rows = xp.concatenate([i, i, j, j])
    cols = xp.concatenate([j, i, i, j])
    blocks = xp.concatenate([block, -block, block, -block])
    if is_numpy(xp):
        out = np.zeros((n, n, 3, 3), dtype=block.dtype)
        np.add.at(out, (rows, cols), blocks)
    else:
        out = xp.zeros((n, n, 3, 3), dtype=block.dtype).at[rows, cols].add(blocks)
    return xp.transpose(out, (0, 2, 1, 3))


def block_diagonal(xp, block):
    """Jacobian (N, 3, N, 3) of per-body forces whose block ``d f_i / d x_i`` is ``block`` (N, 3, 3)."""
    n = block.shape[0]
    idx = xp.arange(n)
    if is_numpy(xp):
        out = np.zeros((n, 3, n, 3), dtype=block.dtype)
        out[idx, :, idx, :] = block
        return out
    return xp.zeros((n, 3, n, 3), dtype=block.dtype).at[idx, :, idx, :].set(block)


def inverse_length(xp, length):
    """``1 / length``, and 0 where ``length`` is zero (no direction: the laws then see no lever)."""
    positive = length > 0
    return xp.where(positive, 1 / xp.where(positive, length, 1), 0)


def safe_unit(xp, x, length):
    """``x / length`` row-wise, and the zero vector where ``length`` is zero.

    A spring of zero length or a body at rest has no direction; the force models
    choose zero force there rather than a NaN.
    """
    positive = length > 0
    return xp.where(positive[:, None], x / xp.where(positive, length, 1)[:, None], 0)


def norm(xp, x):
    """Row-wise Euclidean length of an (M, 3) array."""
    if is_numpy(xp):
        return np.sqrt(np.sum(x * x, axis=-1))
    # The three squares summed explicitly: the same additions in the same order as the
    # NumPy sum, but elementwise, so XLA fuses it into its consumers. As a length-3
    # reduction XLA:CPU emits a separate, slow kernel (3x slower drag at 10^6 bodies).
    return xp.sqrt(x[..., 0] * x[..., 0] + x[..., 1] * x[..., 1] + x[..., 2] * x[..., 2])


def speed(xp, v):
    """:func:`norm` of velocities (M, 3) whose JAX derivative is finite at rest: sqrt's derivative at 0 is
    inf, and inf x 0 (the derivative of v . v there) is NaN, so a force like drag's |v| v, whose own
    derivative at rest is 0, differentiated (an implicit reference's Newton solves) gave NaN at any body
    at rest. The double ``where`` keeps 0 out of sqrt; the values are :func:`norm`'s to the byte."""
    if is_numpy(xp):
        return norm(xp, v)
    squared = dot(xp, v, v)
    moving = squared > 0
    return xp.where(moving, xp.sqrt(xp.where(moving, squared, 1.0)), 0.0)


def dot(xp, x, y):
    """Row-wise dot product of two (M, 3) arrays (elementwise on JAX, as :func:`norm`)."""
    if is_numpy(xp):
        return np.sum(x * y, axis=-1)
    return x[..., 0] * y[..., 0] + x[..., 1] * y[..., 1] + x[..., 2] * y[..., 2]
