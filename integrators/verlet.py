"""Velocity Verlet and position Verlet (leapfrog)."""

from __future__ import annotations

import dataclasses

from .base import Stepper


@dataclasses.dataclass(frozen=True)
class VelocityVerlet(Stepper):
    """2nd order velocity Verlet. One force evaluation per step (the last one is kept).

    q1 = q + dt v + dt^2/2 a0;  a1 = a(t + dt, q1, .);  v1 = v + dt/2 (a0 + a1).
    Symplectic and time-reversible for position-dependent forces; exact for a constant
    force. Velocity-dependent forces (dampers, drag) are evaluated at the predicted
    velocity v + dt a0, whose O(dt^2) error keeps the method 2nd order.
    """

    name = "velocity-verlet"
    order = 2
    evaluations = 1
    symplectic = True
    partitioned = True
    style = ("tab:green", "^")
    stability_note = "2 undamped (trace 2 - y^2, det 1)"

    def init(self, model, t, y):
        return model.acceleration(t, y[0], y[1])

    def step(self, model, t, y, dt, carry):
        q, v, a0 = y[0], y[1], carry
        q1 = q + dt * v + (0.5 * dt * dt) * a0
        a1 = model.acceleration(t + dt, q1, v + dt * a0)
        v1 = v + (0.5 * dt) * (a0 + a1)
        return model.xp.stack([q1, v1]), a1


@dataclasses.dataclass(frozen=True)
class PositionVerlet(Stepper):
    """2nd order position Verlet (leapfrog, drift-kick-drift). One force evaluation per step.

    q_half = q + dt/2 v;  v1 = v + dt a(t + dt/2, q_half, .);  q1 = q_half + dt/2 v1.
    Symplectic and time-reversible for position-dependent forces. Velocity-dependent
    forces need the velocity at the half step, which is estimated as v + dt/2 a_prev
    from the previous step's acceleration (the carry); its O(dt^2) error keeps 2nd order.
    """

    name = "position-verlet"
    order = 2
    evaluations = 1
    symplectic = True
    partitioned = True
    style = ("tab:olive", "v")
    stability_note = "2 undamped"

    def init(self, model, t, y):
        return model.acceleration(t, y[0], y[1])

    def step(self, model, t, y, dt, carry):
        q, v = y[0], y[1]
        q_half = q + (0.5 * dt) * v
        a = model.acceleration(t + 0.5 * dt, q_half, v + (0.5 * dt) * carry)
        v1 = v + dt * a
        q1 = q_half + (0.5 * dt) * v1
        return model.xp.stack([q1, v1]), a
