"""Position-first symplectic Euler, plain and with exact (exponential) damping: Chipmunk2D's step."""

from __future__ import annotations

import dataclasses

from .base import Stepper


@dataclasses.dataclass(frozen=True)
class PositionFirstEuler(Stepper):
    """1st order symplectic Euler that moves first. One force evaluation per step.

    q1 = q + dt v;  v1 = v + dt a(t + dt, q1, v). The other half of the symplectic Euler
    pair: semi-implicit Euler kicks the velocity first and moves with the new one; this
    one moves with the old velocity, then kicks with the force at the new position. Its
    one-step map on the oscillator is semi-implicit Euler's conjugated (same trace and
    determinant), so the same stability limit. Under a constant force its positions are
    explicit Euler's: q_n = q_0 + n dt v_0 + n (n - 1) dt^2 g / 2 lags the exact curve by
    n dt^2 g / 2 (semi-implicit Euler leads it by as much). This is Chipmunk2D's step:
    positions are integrated first, then the velocities, with forces evaluated at the new
    positions.
    """

    name = "position-first-euler"
    order = 1
    evaluations = 1
    symplectic = True
    style = ("tab:cyan", "<")
    stability_note = "2 undamped; 2 sqrt(1 + zeta^2) - 2 zeta damped (as semi-implicit Euler)"

    def step(self, model, t, y, dt, carry):
        q, v = y[0], y[1]
        q1 = q + dt * v
        v1 = v + dt * model.acceleration(t + dt, q1, v)
        return model.xp.stack([q1, v1]), carry


@dataclasses.dataclass(frozen=True)
class ExponentialDampingEuler(Stepper):
    """1st order position-first Euler with exact damping. One force and Jacobian evaluation per step.

    q1 = q + dt v;  v* = v + dt (a(t + dt, q1, v) - D v);  v1 = exp(dt D) v*,  D = da/dv.

    The velocity-dependent part of the force, linear in v for dampers (a = a0(q) + D v),
    is integrated exactly over the step, v' = D v giving v1 = exp(dt D) v, after the kick
    of everything else: the relative speed along a damper decays by exp(-c dt / m_eff)
    per step whatever dt, so damping never overshoots or goes unstable by itself.
    Chipmunk2D's damped spring does exactly this (``v_coef = 1 - exp(-damping dt / m_eff)``)
    after its position-first step; without damping it is :class:`PositionFirstEuler`.
    """

    name = "exponential-damping-euler"
    order = 1
    evaluations = 1
    symplectic = True
    #: it needs the damping Jacobian and its matrix exponential, as an implicit method its solve
    implicit = True
    scheme = "exponential"
    style = ("black", "8")
    stability_note = "2 undamped; the root of (omega dt)^2 = 2 (1 + exp(2 zeta omega dt)) damped"

    def step(self, model, t, y, dt, carry):
        xp = model.xp
        q, v = y[0], y[1]
        n3 = 3 * model.n_bodies
        q1 = q + dt * v
        _, dadv = model.jacobian(t + dt, q1, v)
        kick = model.acceleration(t + dt, q1, v).reshape(n3) - dadv @ v.reshape(n3)
        decay = _expm(xp)(dt * dadv)
        v1 = (decay @ (v.reshape(n3) + dt * kick)).reshape(v.shape)
        return xp.stack([q1, v1]), carry


def _expm(xp):
    """The matrix exponential of the backend (scipy's for NumPy, jax.scipy's for JAX)."""
    import numpy as np

    if xp is np:
        from scipy.linalg import expm

        return expm
    from jax.scipy.linalg import expm

    return expm
