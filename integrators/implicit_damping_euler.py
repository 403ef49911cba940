"""Semi-implicit Euler with implicit damping: MuJoCo's ``implicit`` and ``implicitfast`` integrators."""

from __future__ import annotations

import dataclasses

from .base import Stepper, solve_or_nan


@dataclasses.dataclass(frozen=True)
class ImplicitDampingEuler(Stepper):
    """1st order semi-implicit Euler, implicit in the velocity. One force and Jacobian evaluation per step.

    The velocity takes the backward-Euler step of the velocity-dependent forces, linearised
    at the start of the step (one linear solve, no Newton iteration); the position then
    moves with the new velocity, as in semi-implicit Euler:

        v1 = v + dt (I - dt da/dv)^-1 a(t, q, v),   q1 = q + dt v1.

    For a linear damper (a = -k/m x - c/m v) it is exactly v1 = (v - dt k/m x) / (1 + dt c/m):
    the damping is backward Euler, the spring semi-implicit Euler. Without
    velocity-dependent forces it *is* semi-implicit Euler, symplectic. This is what MuJoCo's
    ``implicit`` and ``implicitfast`` integrators do (they differ only in Coriolis terms,
    which particles have none of), and what its ``Euler`` does for damping on joints (not
    for tendons: steplab's dampers become tendons in MuJoCo, and its ``Euler`` treats them
    explicitly). Implicit damping raises the damped stability limit from semi-implicit
    Euler's 2 sqrt(1 + zeta^2) - 2 zeta to 2 sqrt(1 + zeta^2) + 2 zeta.
    """

    name = "implicit-damping-euler"
    order = 1
    evaluations = 1
    symplectic = True
    #: linearly implicit: one solve with the damping Jacobian, no Newton iteration
    implicit = True
    scheme = "linearly implicit"
    style = ("tab:gray", "h")
    stability_note = "2 undamped; 2 sqrt(1 + zeta^2) + 2 zeta damped"

    def step(self, model, t, y, dt, carry):
        xp = model.xp
        q, v = y[0], y[1]
        n3 = 3 * model.n_bodies
        _, dadv = model.jacobian(t, q, v)
        eye = xp.eye(n3, dtype=y.dtype)
        dv = solve_or_nan(xp, eye - dt * dadv, dt * model.acceleration(t, q, v).reshape(n3))
        v1 = v + dv.reshape(v.shape)
        return xp.stack([q + dt * v1, v1]), carry
