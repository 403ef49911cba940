"""What every integrator is: small immutable data, class-level properties, one method.

Two kinds share one driver (:func:`integrators.simulate`):

- a :class:`Stepper` advances the state by one fixed step ``dt``: ``step(model, t, y, dt,
  carry) -> (y, carry)``. ``y`` has shape (2, N, 3) (positions, velocities); ``carry`` is
  what a method keeps between steps (velocity Verlet keeps the last acceleration so it
  evaluates the force once per step), ``None`` for most. Steppers only combine
  evaluations of ``model.acceleration`` / ``model.vector_field``: they never know what a
  spring is. They build arrays with ``model.xp`` (``model.xp.stack([q1, v1])``): it is
  ``numpy``, or ``jax.numpy`` on the compiled backend, where ``q`` and ``v`` are tracers
  that ``np.stack`` cannot convert (``TracerArrayConversionError``).
- a :class:`Solver` returns the solution at requested times (the closed form, or an
  adaptive reference from diffrax or scipy at a recorded tolerance).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import ClassVar

import numpy as np

from . import linear_stability


def check_count(method: str, key: str, value, maximum: int, limit: str) -> None:
    """Refuse (one-line ValueError) a setting ``key`` of ``method`` that is not a whole number
    from 1 to ``maximum`` (named ``limit``, the module constant that holds it)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{method}: {key} must be a whole number >= 1, got {value!r}")
    if value > maximum:
        raise ValueError(f"{method}: {key} must be a whole number from 1 to {maximum:,} ({limit}), got {value!r}")


def check_real(method: str, key: str, value, ok: Callable[[float], bool], allowed: str) -> None:
    """Refuse (one-line ValueError) a setting ``key`` of ``method`` that is not a finite real number
    (an int or float, not a bool or a string) for which ``ok(value)`` holds; ``allowed`` says which, in words."""
    real = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    try:
        real = real and math.isfinite(float(value)) and bool(ok(float(value)))
    except OverflowError:  # an int too large for a float
        real = False
    if not real:
        raise ValueError(f"{method}: {key} must be {allowed}, got {value!r}")


def solve_or_nan(xp, a, b):
    """``xp.linalg.solve(a, b)``, NaN where NumPy finds ``a`` singular in float64 (a damper of 1e300 N s/m):
    a non-finite step, which the run reports as diverged in one line, as JAX's solve returns NaN itself."""
    import numpy as np

    try:
        return xp.linalg.solve(a, b)
    except np.linalg.LinAlgError:
        return xp.full(b.shape, xp.nan)


def check_step_result(integrator, result, shape) -> None:
    """Refuse (one-line TypeError) a step's result that is not ``(y, carry)`` with y of the state's shape.

    A Stepper of the user's that returns y alone had y unpacked along its first axis and failed
    steps later, deep in a force (NumPy), or in ``lax.scan``'s carry-structure check (JAX). The
    NumPy loop checks the first step; the compiled loop checks the traced step, at no cost per step."""
    if not (isinstance(result, tuple) and len(result) == 2 and np.shape(result[0]) == shape):
        got = (f"a tuple of {len(result)}" if isinstance(result, tuple) and len(result) != 2 else
               f"y of shape {np.shape(result[0])}" if isinstance(result, tuple) else
               f"an array of shape {np.shape(result)}" if hasattr(result, "shape") else f"a {type(result).__name__}")
        raise TypeError(f"{integrator.name}: step(model, t, y, dt, carry) must return (y_next, carry) with y_next "
                        f"of shape {shape}; it returned {got}")


@dataclasses.dataclass(frozen=True)
class Integrator:
    #: registry name, as typed on the command line
    name: ClassVar[str]
    #: global order of accuracy (``None`` for the exact solution)
    order: ClassVar[int | None]
    #: evaluations of the force per step (per Newton iteration where ``scheme`` is "implicit";
    #: ``None`` for adaptive references, where it varies)
    evaluations: ClassVar[int | None]
    symplectic: ClassVar[bool] = False
    #: the step needs the force Jacobian (a solve with it, or its matrix exponential)
    implicit: ClassVar[bool] = False
    #: how a step finds its new state: "explicit"; "linearly implicit" (one linear solve with
    #: the Jacobian, no iteration); "implicit" (Newton's method, iterated to a tolerance);
    #: "exponential" (the damping's matrix exponential, no solve)
    scheme: ClassVar[str] = "explicit"
    kind: ClassVar[str] = "fixed-step"
    #: matplotlib (colour, marker), so a method looks the same in every figure; None: the
    #: figures pick one from the name
    style: ClassVar[tuple[str, str] | None] = None

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
            "scheme": self.scheme,
            "description": doc[0] if doc else "",
        }


class Stepper(Integrator):
    """A fixed-step method: ``step`` plus what it does to the linear test equation.

    The theory is derived from ``step`` itself (:mod:`.linear_stability`): a new method
    has its amplification matrix, spectral radius and stability limit without writing
    any. A method with a scalar stability function R(z) (growth factor on y' = lambda y,
    z = lambda dt) states it as ``stability_function``, which the stability-region
    figure draws.
    """

    #: the stability limit in closed form, in words (the studies print it beside the number)
    stability_note: ClassVar[str] = ""
    #: True for a method that updates q and v by formulas of their own and returns
    #: ``xp.stack([q1, v1])`` (semi-implicit Euler, the Verlets): the compiled loop then
    #: carries the pair (q, v), which XLA updates in place (:mod:`.loop`). A method that
    #: updates the stacked y as a whole (y + dt sum b_i k_i) is carried stacked.
    partitioned: ClassVar[bool] = False
    #: ``R(z)`` for a method that has a scalar stability function; None for one whose map
    #: on the oscillator is a matrix (partitioned methods act on u and v differently)
    stability_function: ClassVar[Callable | None] = None

    def init(self, model, t, y):
        """The carry before the first step (``None`` unless the method keeps something)."""
        return None

    def step(self, model, t, y, dt, carry):
        raise NotImplementedError

    def linear_map(self, omega_dt: float, zeta: float = 0.0) -> np.ndarray:
        """One-step matrix on u'' = -u - 2 zeta u' (omega = 1, dt = omega_dt), carry included.

        Derived from :meth:`step` on :class:`.linear_stability.LinearTestModel`; shape
        (2, 2) acting on (u, v), or (3, 3) on (u, v, carry) for a method that carries an
        array shaped like q.
        """
        return linear_stability.linear_map(self, omega_dt, zeta)

    def spectral_radius(self, omega_dt: float, zeta: float = 0.0) -> float:
        """Largest |eigenvalue| of the one-step map: |R(omega_dt lambda)| for a method with R."""
        return linear_stability.spectral_radius(self, omega_dt, zeta)

    def stability_limit(self, zeta: float = 0.0) -> float | None:
        """Largest stable omega dt on the oscillator: 0.0 if unstable at every dt, None if unbounded."""
        return linear_stability.stability_limit(self, zeta)

    def describe(self) -> dict:
        out = super().describe()
        try:  # None: stable at every dt; left out where the map cannot be derived
            out["stability_limit_omega_dt"] = self.stability_limit(0.0)
        except (TypeError, AttributeError):  # a carry or a model attribute the linear test lacks
            pass
        return out


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
