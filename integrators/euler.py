"""Explicit (forward) Euler."""

from __future__ import annotations

import dataclasses

from .base import Stepper


@dataclasses.dataclass(frozen=True)
class ExplicitEuler(Stepper):
    """1st order explicit Euler. One force evaluation per step.

    The lecture's integrator: S(t + dt) = S(t) + dt dS/dt(t), every term on the right at
    the old time t. Truncation error O(dt^2) per step, O(dt) globally. Energy grows on
    an undamped oscillator at any dt: the method is unconditionally unstable there.
    """

    name = "euler"
    order = 1
    evaluations = 1

    def step(self, model, t, y, dt, carry):
        return y + dt * model.vector_field(t, y), carry
