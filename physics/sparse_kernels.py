"""Compiled Newton blocks of springs and dampers: the hot loop of implicit Euler at cloth sizes.

:func:`.sparse_jacobian.newton_matrix` needs, every Newton iteration, the symmetric (or
definite) part of the springs' and dampers' Jacobians, added into the Newton matrix with
the coefficients -h^2 (positions) and -h (velocities). Through NumPy that is a dozen
(P, 3, 3) temporaries per force (:meth:`Springs.jacobian_blocks`, 25 ms for the bench's
101,442 springs and dampers); these kernels compute each pair's 3x3 block where it is
added, in one pass (about 2 ms). They repeat the forces' formulas, written out once more
for the compiler; ``tests/test_implicit_sparse.py`` holds them equal to the NumPy blocks.

A kernel adds ``sign x`` to ``data[slot]`` for the pair's four blocks (``slots[p]``:
(i, j) and (j, i) with +, (i, i) and (j, j) with -, -1 where the block is not in the
matrix), as :func:`.sparse_jacobian._add_pair_blocks` does.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .dampers import Dampers
from .springs import Springs


@njit(cache=True, inline="always")
def _add(data, slots, p, r, c, x):  # pragma: no cover - compiled
    for k in range(4):
        slot = slots[p, k]
        if slot >= 0:
            data[slot, r, c] += x if k < 2 else -x


@njit(cache=True)
def _spring_blocks(data, slots, q, i, j, stiffness, rest_length, coefficient, definite):  # pragma: no cover
    # B = k [d d^T + t (I - d d^T)], t = 1 - L / l (1 at l = 0, where d = 0); definite: t >= 0
    for p in range(i.size):
        d0, d1, d2 = q[j[p], 0] - q[i[p], 0], q[j[p], 1] - q[i[p], 1], q[j[p], 2] - q[i[p], 2]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        t = 1.0
        if length > 0:
            d0, d1, d2 = d0 / length, d1 / length, d2 / length
            t = 1.0 - rest_length[p] / length
        if definite and t < 0:
            t = 0.0
        k = coefficient * stiffness[p]
        a, b = k * (1.0 - t), k * t
        d = (d0, d1, d2)
        for r in range(3):
            for c in range(3):
                _add(data, slots, p, r, c, a * d[r] * d[c] + (b if r == c else 0.0))


@njit(cache=True)
def _damper_blocks(data, slots, q, v, i, j, damping, coefficient_q, coefficient_v, definite):  # pragma: no cover
    # d f_i / d v_j = c d d^T; the symmetric part of d f_i / d q_j = c [(d . u) P + d w^T] / l
    # (P = I - d d^T, u the relative velocity, w = P u) is c [(d . u) P + (d w^T + w d^T) / 2] / l
    for p in range(i.size):
        d0, d1, d2 = q[j[p], 0] - q[i[p], 0], q[j[p], 1] - q[i[p], 1], q[j[p], 2] - q[i[p], 2]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if not length > 0:
            continue  # no axis: no damping force, a zero Jacobian
        d = (d0 / length, d1 / length, d2 / length)
        u = (v[j[p], 0] - v[i[p], 0], v[j[p], 1] - v[i[p], 1], v[j[p], 2] - v[i[p], 2])
        du = d[0] * u[0] + d[1] * u[1] + d[2] * u[2]
        w = (u[0] - du * d[0], u[1] - du * d[1], u[2] - du * d[2])
        cv = coefficient_v * damping[p]
        cq = 0.0 if definite else coefficient_q * damping[p] / length
        for r in range(3):
            for c in range(3):
                projection = (1.0 if r == c else 0.0) - d[r] * d[c]
                x = cv * d[r] * d[c] + cq * (du * projection + 0.5 * (d[r] * w[c] + w[r] * d[c]))
                _add(data, slots, p, r, c, x)


def has_kernel(force) -> bool:
    """Whether ``force`` (exactly a Springs or a Dampers, not a subclass) has a compiled kernel here."""
    return type(force) in (Springs, Dampers)


def add_symmetric_blocks(force, data, slots, q, v, coefficient_q: float, coefficient_v: float,
                         definite: bool) -> bool:
    """Add ``force``'s symmetric (or definite) Newton blocks into ``data``; False if it has no kernel.

    ``coefficient_q`` multiplies d f / d q, ``coefficient_v`` d f / d v (a spring has no
    velocity block).
    """
    if type(force) is Springs:
        if coefficient_q != 0:
            _spring_blocks(data, slots, q, force.i, force.j, np.asarray(force.stiffness, float),
                           np.asarray(force.rest_length, float), coefficient_q, definite)
        return True
    if type(force) is Dampers:
        _damper_blocks(data, slots, q, v, force.i, force.j, np.asarray(force.damping, float), coefficient_q,
                       coefficient_v, definite)
        return True
    return False
