"""One projection of a distance constraint, the one definition every sweep evaluates (:mod:`.constraint_projection`).

Macklin, Mueller and Chentanez (MIG 2016) eq. 18 with the damping of their eq. 26, as
:mod:`.constraint_projection` derives it: :func:`factors`, what depends only on the constraint
and the substep, and :func:`projection`, the move per unit of d. Plain arithmetic: Numba compiles
it into the sweep's scalar step (:func:`_projection`), the sweep's vector block evaluates it on
lanes (:mod:`.projection_block`) and JAX on a colour's columns (:mod:`.constraint_projection_jax`).
"""

from __future__ import annotations

from numba import njit


def factors(compliance, damping, inverse_mass_sum, h):
    """(alpha_tilde, gamma, denominator) of a constraint for substeps of ``h``: alpha / h^2, alpha beta / h and
    (1 + gamma) w + alpha_tilde (w = ``inverse_mass_sum``; a pair of pinned bodies, w = 0, is the caller's to skip)."""
    inv_h = 1.0 / h
    alpha_tilde = compliance * (inv_h * inv_h)
    gamma = compliance * damping * inv_h
    return alpha_tilde, gamma, (1.0 + gamma) * inverse_mass_sum + alpha_tilde


def projection(rest_length, length, approach, gamma, below, held):
    """s = dlambda / l, the projection's move per unit of d (x_i -= w_i s d, x_j += w_j s d).

    dlambda = (-C - alpha_tilde lambda - gamma grad C . (x - x_prev)) / denominator with C = l - L,
    grad C . (x - x_prev) = d . u / l (``approach`` = d . u) and ``held`` = alpha_tilde lambda;
    numerator and denominator multiplied by l, ``below`` = denominator l^2 = denominator |d|^2, leave
    one square root (l) and one division per projection. ``below`` = 0 (no direction, or two pinned
    bodies) gives inf or NaN: the callers take s = 0 there.
    """
    return ((rest_length - length - held) * length - gamma * approach) / below


_projection = njit(inline="always", error_model="numpy")(projection)
