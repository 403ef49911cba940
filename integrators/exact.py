"""The exact solution for scenes whose total force is constant."""

from __future__ import annotations

import dataclasses

import numpy as np
from steplab.physics.projectile import projectile

from .base import Solver


class NotConstantForceError(ValueError):
    """Raised when ``exact`` is asked to solve a scene whose force is not constant."""


@dataclasses.dataclass(frozen=True)
class Exact(Solver):
    """Exact closed-form projectile solution, for scenes whose total force is constant.

    p(t) = p0 + v0 (t - t0) + 1/2 a (t - t0)^2, with a = g + F/m the model's constant
    acceleration (gravity and every other constant force, ``model.constant_acceleration``),
    evaluated from the initial state at every requested time, so no error accumulates over
    steps. The reference for error studies on the projectile.
    """

    name = "exact"
    order = None
    evaluations = 0
    kind = "exact"

    def solve(self, model, ts, y0):
        accel = model.constant_acceleration
        if accel is None:
            varying = sorted({f.name for f in model.forces if not f.constant})
            raise NotConstantForceError(
                f"integrator 'exact' needs a constant total force, but the scene declares "
                f"{', '.join(varying)}; use a numerical integrator or a reference")
        y0 = np.asarray(y0, dtype=float)
        ts = np.asarray(ts, dtype=float)
        p, v = projectile(ts, y0[0], y0[1], np.asarray(accel, dtype=float), ts[0])
        return np.stack([p, v], axis=1)
