"""What every integrator is: small immutable data, class-level properties, one method.

Two kinds share one driver (:func:`integrators.simulate`):

- a :class:`Stepper` advances the state by one fixed step ``dt``: ``step(model, t, y, dt,
  carry) -> (y, carry)``. ``y`` has shape (2, N, 3) (positions, velocities); ``carry`` is
  what a method keeps between steps (velocity Verlet keeps the last acceleration so it
  evaluates the force once per step), ``None`` for most. Steppers only combine
  evaluations of ``model.acceleration`` / ``model.vector_field``: they never know what a
  spring is.
- a :class:`Solver` returns the solution at requested times (the closed form, or an
  adaptive reference from diffrax or scipy at a recorded tolerance).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar


@dataclasses.dataclass(frozen=True)
class Integrator:
    #: registry name, as typed on the command line
    name: ClassVar[str]
    #: global order of accuracy (``None`` for the exact solution)
    order: ClassVar[int | None]
    #: evaluations of the force per step (per Newton iteration for implicit methods;
    #: ``None`` for adaptive references, where it varies)
    evaluations: ClassVar[int | None]
    symplectic: ClassVar[bool] = False
    implicit: ClassVar[bool] = False
    kind: ClassVar[str] = "fixed-step"

    def describe(self) -> dict:
        """Machine-readable properties, as ``steplab integrators --json`` prints them."""
        doc = (type(self).__doc__ or "").strip().splitlines()
        return {
            "name": self.name,
            "kind": self.kind,
            "order": self.order,
            "evaluations_per_step": self.evaluations,
            "symplectic": self.symplectic,
            "implicit": self.implicit,
            "description": doc[0] if doc else "",
        }


class Stepper(Integrator):
    def init(self, model, t, y):
        """The carry before the first step (``None`` unless the method keeps something)."""
        return None

    def step(self, model, t, y, dt, carry):
        raise NotImplementedError


class Solver(Integrator):
    kind: ClassVar[str] = "reference"
    #: which backend the solver needs its model on ("numpy" or "jax")
    backend: ClassVar[str] = "numpy"

    def solve(self, model, ts, y0):
        """The state at each time in ``ts`` (shape (K,)), shape (K, 2, N, 3)."""
        raise NotImplementedError

    def describe(self) -> dict:
        out = super().describe()
        out.update({f.name: getattr(self, f.name) for f in dataclasses.fields(self)})
        return out
