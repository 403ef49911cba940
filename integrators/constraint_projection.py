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
carried between iterations. The sweep is sequential (Gauss-Seidel: each projection sees the
positions the previous ones moved), so it is a Numba loop, the only definition of the
projection; the NumPy path calls it.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def project(dx, x_prev, inverse_mass, constraints, h, iterations, accumulate):
    """``iterations`` Gauss-Seidel sweeps over ``constraints`` (a physics.constraints.DistanceConstraints),
    moving ``dx`` (N, 3) in place.

    ``x_prev`` (N, 3) are the positions at the start of the substep, ``dx`` the predicted
    displacement h v* on entry and the projected one on return; the multipliers start at 0
    in each substep. Coincident bodies (no direction) and pairs of pinned bodies (w = 0) are
    skipped.
    """
    i, j, rest_length, compliance, damping = constraints
    lam = np.zeros(i.shape[0])
    for _ in range(iterations):
        for p in range(i.shape[0]):
            a, b = i[p], j[p]
            w = inverse_mass[a] + inverse_mass[b]
            u0, u1, u2 = dx[b, 0] - dx[a, 0], dx[b, 1] - dx[a, 1], dx[b, 2] - dx[a, 2]
            d0 = x_prev[b, 0] - x_prev[a, 0] + u0
            d1 = x_prev[b, 1] - x_prev[a, 1] + u1
            d2 = x_prev[b, 2] - x_prev[a, 2] + u2
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if w == 0.0 or length == 0.0:
                continue
            n0, n1, n2 = d0 / length, d1 / length, d2 / length
            alpha_tilde = compliance[p] / (h * h)
            gamma = compliance[p] * damping[p] / h
            # grad C . (x - x_prev): the constraint's rate times h
            rate = n0 * u0 + n1 * u1 + n2 * u2
            held = lam[p] if accumulate else 0.0
            dlam = (-(length - rest_length[p]) - alpha_tilde * held - gamma * rate) / ((1.0 + gamma) * w + alpha_tilde)
            lam[p] += dlam
            wa, wb = inverse_mass[a] * dlam, inverse_mass[b] * dlam
            dx[a, 0] -= wa * n0
            dx[a, 1] -= wa * n1
            dx[a, 2] -= wa * n2
            dx[b, 0] += wb * n0
            dx[b, 1] += wb * n1
            dx[b, 2] += wb * n2
