"""The Gauss-Seidel sweep over distance constraints shared by ``pbd`` and ``xpbd`` (a Numba kernel).

One projection of constraint p (bodies i, j; C = |x_j - x_i| - l_rest, gradient n = (x_j - x_i) / |.|
on j and -n on i) is Macklin, Mueller and Chentanez (MIG 2016) eq. 18 with the damping of
their eq. 26:

    dlambda = (-C - alpha_tilde lambda - gamma grad C . (x - x_prev)) / ((1 + gamma) w + alpha_tilde),
    x_i -= w_i dlambda n,   x_j += w_j dlambda n,   lambda += dlambda,

on x = x_prev + dx. The sweep moves the displacement dx over the substep, not x itself:
x - x_prev is then dx exactly, and the velocity dx / h carries the round-off of dx, not
that of x divided by h (which at h = 1 ms would be a thousand times larger).

with w = w_i + w_j the inverse masses, alpha_tilde = alpha / h^2 (alpha = 1 / k the
compliance, h the substep) and, for a damper of coefficient beta beside the spring,
beta_tilde = h^2 beta and gamma = alpha_tilde beta_tilde / h = alpha beta / h = beta / (k h).
(Their eq. 26 follows from adding the Rayleigh dissipation beta (grad C . v)^2 / 2 to the
implicit-Euler step and writing v = (x - x_prev) / h.) ``accumulate`` False holds
lambda at 0 in every iteration: each projection then removes the fraction
w / (w + alpha_tilde) of C, Mueller et al.'s (2007) stiffness per iteration, with nothing
carried between iterations. The sweep is Gauss-Seidel (each projection sees the positions
the previous ones moved), a Numba loop, the only definition of the projection; the NumPy
path calls it.

The constraints are swept in the order of a greedy edge colouring (:func:`ordered`), colour
after colour: within a colour no two share a body, so a projection never waits for the
previous one's move of a shared body (as built, the cloth's springs come body by body, and
each projection's square root and division waited on the previous one's result). On the
25,600-particle cloth, one sweep: 1.40 ms as built, 0.67-0.84 ms in colour order (a
batched variant, the square roots and divisions of a colour vectorised between a gather
and a scatter pass, was slower, 0.96-1.04 ms: the passes' extra loads and stores cost more
than the vectorised arithmetic saves).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class Workspace(NamedTuple):
    """Scratch a step writes, allocated once per run: the displacement ``dx`` (N, 3), the multipliers ``lam`` (P,)."""

    dx: np.ndarray
    lam: np.ndarray


def ordered(constraints, n_bodies: int):
    """``constraints`` (a physics.constraints.DistanceConstraints) sorted by the colour of a greedy edge
    colouring, then by their bodies (for locality): the order the sweep visits them in."""
    from .colouring import greedy_edge_colouring

    colour = greedy_edge_colouring(n_bodies, constraints.i, constraints.j)
    order = np.lexsort((constraints.j, constraints.i, colour))
    return type(constraints)(*(np.ascontiguousarray(a[order]) for a in constraints))


def workspace(n_bodies: int, n_constraints: int) -> Workspace:
    return Workspace(np.empty((n_bodies, 3)), np.empty(n_constraints))


@njit(cache=True, error_model="numpy")
def project(dx, x_prev, inverse_mass, constraints, h, iterations, accumulate, lam):
    """``iterations`` Gauss-Seidel sweeps over ``constraints`` (a physics.constraints.DistanceConstraints,
    in the order of :func:`ordered`), moving ``dx`` (N, 3) in place.

    ``x_prev`` (N, 3) are the positions at the start of the substep, ``dx`` the predicted
    displacement h v* on entry and the projected one on return; the multipliers ``lam`` (P,)
    start at 0 in each substep (they are only read and written where they matter,
    ``accumulate`` with more than one iteration: otherwise held at 0 and untouched, which
    saves the sweep 16 bytes of traffic per constraint). Coincident bodies (no direction)
    and pairs of pinned bodies (w = 0) are skipped.
    """
    i, j, rest_length, compliance, damping = constraints
    carried = accumulate and iterations > 1
    if carried:
        lam[:] = 0.0
    inv_h = 1.0 / h
    inv_h2 = inv_h * inv_h
    for _ in range(iterations):
        for p in range(i.shape[0]):
            a, b = i[p], j[p]
            w = inverse_mass[a] + inverse_mass[b]
            if w == 0.0:
                continue
            u0, u1, u2 = dx[b, 0] - dx[a, 0], dx[b, 1] - dx[a, 1], dx[b, 2] - dx[a, 2]
            d0 = x_prev[b, 0] - x_prev[a, 0] + u0
            d1 = x_prev[b, 1] - x_prev[a, 1] + u1
            d2 = x_prev[b, 2] - x_prev[a, 2] + u2
            squared = d0 * d0 + d1 * d1 + d2 * d2
            if squared == 0.0:
                continue
            length = np.sqrt(squared)
            alpha_tilde = compliance[p] * inv_h2
            gamma = compliance[p] * damping[p] * inv_h
            held = lam[p] if carried else 0.0
            # dlambda n = s d with n = d / l and grad C . (x - x_prev) = d . u / l: dlambda's
            # numerator and denominator multiplied by l leave one division and one square root
            # per projection, the sweep's costliest operations
            s = ((rest_length[p] - length - alpha_tilde * held) * length - gamma * (d0 * u0 + d1 * u1 + d2 * u2)) / (
                ((1.0 + gamma) * w + alpha_tilde) * squared)
            if carried:
                lam[p] += s * length
            wa, wb = inverse_mass[a] * s, inverse_mass[b] * s
            dx[a, 0] -= wa * d0
            dx[a, 1] -= wa * d1
            dx[a, 2] -= wa * d2
            dx[b, 0] += wb * d0
            dx[b, 1] += wb * d1
            dx[b, 2] += wb * d2


@njit(cache=True, error_model="numpy")
def advance(q, v, external, inverse_mass, constraints, h, substeps, iterations, accumulate, work):
    """``substeps`` substeps of h of a position-based step, on q, v (N, 3) in place, allocating nothing:

        dx = h (v + h a_ext),  project dx (:func:`project`),  q += dx,  v = dx / h.

    ``external`` (N, 3), m/s^2; ``work`` a :class:`Workspace`.
    """
    dx = work.dx
    # flat views of the (N, 3) arrays: one loop over 3N numbers, which the compiler vectorises
    dx_, q_, v_, a_ = dx.reshape(-1), q.reshape(-1), v.reshape(-1), external.reshape(-1)
    for _ in range(substeps):
        for k in range(dx_.shape[0]):
            dx_[k] = h * (v_[k] + h * a_[k])  # predict: x* = q + h v*, v* = v + h a_ext
        project(dx, q, inverse_mass, constraints, h, iterations, accumulate, work.lam)
        for k in range(dx_.shape[0]):
            q_[k] += dx_[k]
            v_[k] = dx_[k] / h
