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
the previous ones moved), a Numba loop; the NumPy path calls it, and the JAX path
(:mod:`.constraint_projection_jax`) is the same sweep. Both evaluate the projection through the
one definition here, :func:`factors` and :func:`projection` (plain arithmetic, which Numba
compiles into the kernel and JAX evaluates on a colour's columns).

The constraints are swept in the order of a greedy edge colouring (:func:`ordered`), colour
after colour. Within a colour no two constraints share a body, so its projections are
independent: the sweep gathers a whole colour's differences d = x_j - x_i first, then solves
every projection of the colour in one loop that the compiler vectorises (the square roots
and divisions, the costliest operations, four or eight at a time), then scatters the moves.
That is the sequential Gauss-Seidel sweep exactly, the same operations in the same order per
constraint (so the same bytes). What depends only on the constraint and the substep h
(alpha_tilde, gamma and the denominator (1 + gamma) w + alpha_tilde) is computed once per run
(:func:`sweep_columns`). On the 25,600-particle cloth, one sweep: 1.40 ms in the springs'
order, 0.67-0.84 ms projection by projection in colour order, 0.53-0.57 ms gathered per colour
(load 5-6). What is left is the gather's and the scatter's scalar loads and stores, about 28 per
constraint: 5 to 7 ns a constraint (whole step) at every cloth size, in cache or not (docs/performance.md).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
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


class Sweep(NamedTuple):
    """The constraints as the sweep reads them, in its order, for one substep h (:func:`sweep_columns`).

    ``i``, ``j`` (P,) uint32 the bodies; ``rest_length``, m; ``alpha_tilde`` = alpha / h^2;
    ``gamma`` = alpha beta / h; ``denominator`` = (1 + gamma) w + alpha_tilde, 0 for a pair of
    pinned bodies (skipped); ``colours`` (C + 1,) int64: colour c is ``[colours[c], colours[c + 1])``.
    """

    i: np.ndarray
    j: np.ndarray
    rest_length: np.ndarray
    alpha_tilde: np.ndarray
    gamma: np.ndarray
    denominator: np.ndarray
    colours: np.ndarray


class Substeps(NamedTuple):
    """How a step runs: ``substeps`` of ``h`` s, each ``iterations`` sweeps, the multipliers
    ``carried`` between the iterations (xpbd with more than one iteration) or held at 0."""

    h: float
    substeps: int
    iterations: int
    carried: bool


class Workspace(NamedTuple):
    """Scratch a step writes, allocated once per run: the displacement ``dx`` (N, 3), the multipliers
    ``lam`` (P,) and ``colour`` (5, largest colour), one colour's d = x_j - x_i, |d|^2 and d . (dx_j - dx_i)."""

    dx: np.ndarray
    lam: np.ndarray
    colour: np.ndarray


def ordered(constraints, n_bodies: int):
    """``constraints`` (a physics.constraints.DistanceConstraints) sorted by the colour of a greedy edge
    colouring, then by their bodies (for locality): the order the sweep visits them in; and where
    each colour starts, (C + 1,) int64."""
    from .colouring import greedy_edge_colouring

    colour = greedy_edge_colouring(n_bodies, constraints.i, constraints.j)
    order = np.lexsort((constraints.j, constraints.i, colour))
    starts = np.searchsorted(colour[order], np.arange(colour.max(initial=-1) + 2)).astype(np.int64)
    return type(constraints)(*(np.ascontiguousarray(a[order]) for a in constraints)), starts


def sweep_columns(constraints, colours, inverse_mass, h: float) -> Sweep:
    """The :class:`Sweep` of ``constraints`` (in sweep order, colour starts ``colours``) for substeps of ``h``:
    the per-constraint factors evaluated as the projection would, the same operations in the same order."""
    w = inverse_mass[constraints.i] + inverse_mass[constraints.j]
    alpha_tilde, gamma, denominator = factors(constraints.compliance, constraints.damping, w, h)
    denominator = np.where(w == 0.0, 0.0, denominator)
    return Sweep(constraints.i.astype(np.uint32), constraints.j.astype(np.uint32), constraints.rest_length,
                 alpha_tilde, gamma, denominator, colours)


def workspace(n_bodies: int, n_constraints: int, colours: np.ndarray) -> Workspace:
    largest = max(int(np.diff(colours).max(initial=0)), 1)
    return Workspace(np.empty((n_bodies, 3)), np.empty(n_constraints), np.empty((5, largest)))


@njit(cache=True, error_model="numpy")
def project(dx, x_prev, inverse_mass, sweep, iterations, carried, work):
    """``iterations`` Gauss-Seidel sweeps over ``sweep`` (a :class:`Sweep`), moving ``dx`` (N, 3) in place.

    ``x_prev`` (N, 3) are the positions at the start of the substep, ``dx`` the predicted
    displacement h v* on entry and the projected one on return; the multipliers ``work.lam``
    (P,) start at 0 in each substep and are only read and written when ``carried`` (otherwise
    held at 0 and untouched, which saves the sweep 16 bytes of traffic per constraint).
    Coincident bodies (no direction) and pairs of pinned bodies (denominator 0) move nothing.
    """
    lam, scratch = work.lam, work.colour
    if carried:
        lam[:] = 0.0
    d_, x_ = dx.reshape(-1), x_prev.reshape(-1)  # flat: body a's coordinates at 3a, 3a + 1, 3a + 2
    d0_, d1_, d2_, squared_, s_ = scratch[0], scratch[1], scratch[2], scratch[3], scratch[4]
    for _ in range(iterations):
        for c in range(sweep.colours.shape[0] - 1):
            lo, hi = sweep.colours[c], sweep.colours[c + 1]
            # gather: d = x_prev_j - x_prev_i + u, u = dx_j - dx_i, |d|^2 and d . u (grad C . (x - x_prev) times l)
            for k in range(hi - lo):
                a, b = 3 * sweep.i[lo + k], 3 * sweep.j[lo + k]
                u0, u1, u2 = d_[b] - d_[a], d_[b + 1] - d_[a + 1], d_[b + 2] - d_[a + 2]
                d0 = x_[b] - x_[a] + u0
                d1 = x_[b + 1] - x_[a + 1] + u1
                d2 = x_[b + 2] - x_[a + 2] + u2
                d0_[k], d1_[k], d2_[k] = d0, d1, d2
                squared_[k] = d0 * d0 + d1 * d1 + d2 * d2
                s_[k] = d0 * u0 + d1 * u1 + d2 * u2
            # solve, vectorised: dlambda n = s d with n = d / l (:func:`projection`)
            rest, gamma, denominator = sweep.rest_length[lo:hi], sweep.gamma[lo:hi], sweep.denominator[lo:hi]
            if carried:
                alpha_tilde, held = sweep.alpha_tilde[lo:hi], lam[lo:hi]
                for k in range(hi - lo):
                    length = np.sqrt(squared_[k])
                    below = denominator[k] * squared_[k]
                    s = _projection(rest[k], length, s_[k], gamma[k], below, alpha_tilde[k] * held[k])
                    s = s if below != 0.0 else 0.0
                    held[k] += s * length
                    s_[k] = s
            else:
                for k in range(hi - lo):
                    length = np.sqrt(squared_[k])
                    below = denominator[k] * squared_[k]
                    s = _projection(rest[k], length, s_[k], gamma[k], below, 0.0)
                    s_[k] = s if below != 0.0 else 0.0
            # scatter: x_i -= w_i s d, x_j += w_j s d
            for k in range(hi - lo):
                a, b = sweep.i[lo + k], sweep.j[lo + k]
                wa, wb = inverse_mass[a] * s_[k], inverse_mass[b] * s_[k]
                a, b = 3 * a, 3 * b
                d_[a] -= wa * d0_[k]
                d_[a + 1] -= wa * d1_[k]
                d_[a + 2] -= wa * d2_[k]
                d_[b] += wb * d0_[k]
                d_[b + 1] += wb * d1_[k]
                d_[b + 2] += wb * d2_[k]


@njit(cache=True, error_model="numpy")
def advance(q, v, external, inverse_mass, sweep, steps, work):
    """``steps.substeps`` substeps of ``steps.h`` of a position-based step (a :class:`Substeps`), on q, v
    (N, 3) in place, allocating nothing:

        dx = h (v + h a_ext),  project dx (:func:`project`),  q += dx,  v = dx / h.

    ``external`` (N, 3), m/s^2; ``sweep`` a :class:`Sweep` for h; ``work`` a :class:`Workspace`.
    """
    dx, h = work.dx, steps.h
    # flat views of the (N, 3) arrays: one loop over 3N numbers, which the compiler vectorises
    dx_, q_, v_, a_ = dx.reshape(-1), q.reshape(-1), v.reshape(-1), external.reshape(-1)
    for _ in range(steps.substeps):
        for k in range(dx_.shape[0]):
            dx_[k] = h * (v_[k] + h * a_[k])  # predict: x* = q + h v*, v* = v + h a_ext
        project(dx, q, inverse_mass, sweep, steps.iterations, steps.carried, work)
        for k in range(dx_.shape[0]):
            q_[k] += dx_[k]
            v_[k] = dx_[k] / h
