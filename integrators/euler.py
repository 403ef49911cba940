"""Explicit (forward) Euler: the one-stage Runge-Kutta method."""

from __future__ import annotations

import dataclasses

from .runge_kutta import ButcherTableau, ExplicitRungeKutta


@dataclasses.dataclass(frozen=True)
class ExplicitEuler(ExplicitRungeKutta):
    """1st order explicit Euler. One force evaluation per step.

    The lecture's integrator: S(t + dt) = S(t) + dt dS/dt(t), every term on the right at
    the old time t. Truncation error O(dt^2) per step, O(dt) globally. As a tableau it is
    one stage with weight 1, so R(z) = 1 + z: |1 + i y| > 1 on an undamped oscillator at
    any y = omega dt, and energy grows at every dt (unconditionally unstable there).
    """

    name = "euler"
    order = 1
    evaluations = 1
    style = ("tab:red", "o")
    stability_note = "0 undamped (|1 + i y| > 1); 2 zeta damped"
    tableau = ButcherTableau(a_lower=(), b=(1.0,), c=())
