"""The vertex block descent sweep of ``vbd`` (a Numba kernel): per vertex, one Newton step of its local potential.

Implicit Euler on springs and dampers is the minimum over x of the incremental potential
(the variational form of implicit Euler that Chen et al., "Vertex block descent", SIGGRAPH
2024, start from)

    G(x) = sum_i m_i |x_i - y_i|^2 / (2 h^2) + sum_springs k (|x_i - x_j| - l_rest)^2 / 2 + damping,
    y = q + h v + h^2 a_ext (the inertial target),

and block coordinate descent minimises it one vertex at a time with the others held: the
3x3 Newton step H_i dx_i = f_i on vertex i's own terms (inertia and its incident springs).
Per spring, with n = (x_i - x_j) / l and l = |x_i - x_j|, the force on i is -k (l - l_rest) n
and the Hessian k [(1 - l_rest / l) (I - n n^T) + n n^T]; the transverse factor
1 - l_rest / l is negative on a compressed spring and is clamped at 0 there, so H_i (which has
m_i / h^2 I) stays positive definite and every local step lowers G (the step is a descent
step; only its length, not its fixed point, depends on the approximation). A damper beta on the
pair adds, with v = (x - q) / h, the force -beta (n . (v_i - v_j)) n and the Hessian
(beta / h) n n^T (Rayleigh damping along the axis, n's own rate of change left out of H).
Converged, every f_i = 0: dG/dx = 0, which is implicit Euler's step (``implicit-euler``'s
v1 = v + h a(q + h v1, v1) with x = q + h v1) — whatever the initial guess.

The sweep moves the displacement dx = x - q, as :mod:`.constraint_projection` does, so the
velocity dx / h carries the round-off of dx, not that of x. It visits the vertices colour by
colour (``order``): within one colour no two share a spring, so their steps are independent
and this sequential loop gives the same bytes as a parallel one over each colour would.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class VertexSprings(NamedTuple):
    """What the sweep reads, per vertex (float64 / int64 NumPy): vertex a's incident springs are the
    entries ``offsets[a]:offsets[a + 1]`` of ``other`` (the vertex at the far end), ``stiffness``
    (N/m), ``rest_length`` (m) and ``damping`` (N s/m); ``order`` are the free vertices grouped
    colour by colour; ``mass`` (N,), kg."""

    offsets: np.ndarray
    other: np.ndarray
    stiffness: np.ndarray
    rest_length: np.ndarray
    damping: np.ndarray
    order: np.ndarray
    mass: np.ndarray


@njit(cache=True)
def descend(dx, q, dy, graph, h, iterations):
    """``iterations`` sweeps of vertex block descent, moving ``dx`` (N, 3) = x - q in place.

    ``q`` (N, 3) are the positions at the start of the substep, ``dy`` (N, 3) = y - q the
    inertial target's displacement h v + h^2 a_ext; ``graph`` a :class:`VertexSprings`.
    Coincident bodies (no axis) contribute no spring term.
    """
    offsets, other, stiffness, rest_length, damping, order, mass = graph
    inv_h = 1.0 / h
    for _ in range(iterations):
        for k in range(order.shape[0]):
            a = order[k]
            inertia = mass[a] * inv_h * inv_h
            # f = -dG/dx_a, H = d2G/dx_a2 (upper triangle)
            f0 = -inertia * (dx[a, 0] - dy[a, 0])
            f1 = -inertia * (dx[a, 1] - dy[a, 1])
            f2 = -inertia * (dx[a, 2] - dy[a, 2])
            h00, h11, h22, h01, h02, h12 = inertia, inertia, inertia, 0.0, 0.0, 0.0
            for e in range(offsets[a], offsets[a + 1]):
                b = other[e]
                u0, u1, u2 = dx[a, 0] - dx[b, 0], dx[a, 1] - dx[b, 1], dx[a, 2] - dx[b, 2]
                d0, d1, d2 = q[a, 0] - q[b, 0] + u0, q[a, 1] - q[b, 1] + u1, q[a, 2] - q[b, 2] + u2
                length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if length == 0.0:
                    continue
                n0, n1, n2 = d0 / length, d1 / length, d2 / length
                k_e = stiffness[e]
                pull = k_e * (length - rest_length[e])
                transverse = k_e * max(0.0, 1.0 - rest_length[e] / length)
                axial = k_e - transverse
                beta = damping[e] * inv_h
                if beta != 0.0:
                    pull += beta * (n0 * u0 + n1 * u1 + n2 * u2)  # beta (n . (v_a - v_b)), v = u / h
                    axial += beta
                f0 -= pull * n0
                f1 -= pull * n1
                f2 -= pull * n2
                h00 += transverse + axial * n0 * n0
                h11 += transverse + axial * n1 * n1
                h22 += transverse + axial * n2 * n2
                h01 += axial * n0 * n1
                h02 += axial * n0 * n2
                h12 += axial * n1 * n2
            # dx_a += H^-1 f by the cofactors of the symmetric positive definite H
            c00, c11, c22 = h11 * h22 - h12 * h12, h00 * h22 - h02 * h02, h00 * h11 - h01 * h01
            c01, c02, c12 = h02 * h12 - h01 * h22, h01 * h12 - h02 * h11, h01 * h02 - h00 * h12
            det = h00 * c00 + h01 * c01 + h02 * c02
            dx[a, 0] += (c00 * f0 + c01 * f1 + c02 * f2) / det
            dx[a, 1] += (c01 * f0 + c11 * f1 + c12 * f2) / det
            dx[a, 2] += (c02 * f0 + c12 * f1 + c22 * f2) / det
