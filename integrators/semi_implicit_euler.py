"""Semi-implicit (symplectic) Euler."""

from __future__ import annotations

import dataclasses

from .base import Stepper


@dataclasses.dataclass(frozen=True)
class SemiImplicitEuler(Stepper):
    """1st order semi-implicit (symplectic) Euler. One force evaluation per step.

    Update the velocity from the old state, then the position from the *new* velocity:
    v1 = v + dt a(t, q, v); q1 = q + dt v1. The standard game-physics step (Box2D's).
    Symplectic: on an undamped oscillator the energy error stays bounded for
    omega dt < 2.
    """

    name = "semi-implicit-euler"
    order = 1
    evaluations = 1
    symplectic = True
    partitioned = True
    style = ("tab:orange", "s")
    stability_note = "2 undamped; 2 sqrt(1 + zeta^2) - 2 zeta damped"

    def step(self, model, t, y, dt, carry):
        q, v = y[0], y[1]
        v1 = v + dt * model.acceleration(t, q, v)
        q1 = q + dt * v1
        return model.xp.stack([q1, v1]), carry
