"""Implicit (backward) Euler with Newton iteration."""

from __future__ import annotations

import dataclasses

import numpy as np

from .base import Stepper

#: Newton iterations before a step is declared failed (its state becomes NaN, so the
#: driver's divergence check reports the step)
MAX_NEWTON_ITERATIONS = 50


@dataclasses.dataclass(frozen=True)
class ImplicitEuler(Stepper):
    """1st order implicit (backward) Euler. One force and Jacobian evaluation per Newton iteration.

    v1 = v + dt a(t + dt, q1, v1),  q1 = q + dt v1. Substituting q1 leaves 3N unknowns
    v1, found by Newton's method on G(v1) = v1 - v - dt a(t + dt, q + dt v1, v1) = 0 with
    dG/dv1 = I - dt^2 da/dq - dt da/dv, the model's analytic spring/damper/drag Jacobian.
    A-stable (L-stable): a stiff soft body stays stable at any dt, at the price of
    numerical damping.

    Parameters
    ----------
    rtol : float, optional
        Newton stops when the update is below ``rtol (1 + |v1|)`` (max norm). Default:
        the square root of the machine epsilon of the state's precision; Newton's
        quadratic convergence leaves the iterate far more accurate than that.
    """

    rtol: float | None = None

    name = "implicit-euler"
    order = 1
    evaluations = 1
    implicit = True
    style = ("tab:brown", "X")
    stability_note = "none: |1 / (1 - z)| <= 1 on the whole left half-plane (A-stable)"

    def stability_function(self, z):
        """R(z) = 1 / (1 - z): v1 = v + dt a(v1) on y' = lambda y gives y1 = y / (1 - lambda dt)."""
        return 1 / (1 - z)

    def step(self, model, t, y, dt, carry):
        xp = model.xp
        q, v = y[0], y[1]
        t1 = t + dt
        n3 = 3 * model.n_bodies
        rtol = self.rtol if self.rtol is not None else float(np.sqrt(np.finfo(y.dtype).eps))
        eye = xp.eye(n3, dtype=y.dtype)

        def update(v1):
            q1 = q + dt * v1
            residual = v1 - v - dt * model.acceleration(t1, q1, v1)
            dadq, dadv = model.jacobian(t1, q1, v1)
            delta = xp.linalg.solve(eye - (dt * dt) * dadq - dt * dadv, -residual.reshape(n3))
            return v1 + delta.reshape(v.shape), xp.max(xp.abs(delta)) <= rtol * (1 + xp.max(xp.abs(v1)))

        v1 = _newton(xp, update, v)
        return xp.stack([q + dt * v1, v1]), carry


def _newton(xp, update, x0):
    """Iterate ``x, converged = update(x)`` until converged; NaN if it never does."""
    if xp is np:
        x = x0
        for _ in range(MAX_NEWTON_ITERATIONS):
            x, converged = update(x)
            if converged:
                return x
        return np.full_like(x, np.nan)

    from jax import lax

    def cond(state):
        _, converged, k = state
        return ~converged & (k < MAX_NEWTON_ITERATIONS)

    def body(state):
        x, _, k = state
        x, converged = update(x)
        return x, converged, k + 1

    x, converged, _ = lax.while_loop(cond, body, (x0, xp.asarray(False), 0))
    return xp.where(converged, x, xp.nan)
