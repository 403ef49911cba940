"""Explicit Runge-Kutta methods as data: a checked Butcher tableau plus one generic step."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .base import Stepper

#: tolerance of the tableau consistency checks (the coefficients are exact fractions)
TABLEAU_TOLERANCE = 1e-14


@dataclasses.dataclass(frozen=True)
class ButcherTableau:
    """The coefficients of an explicit Runge-Kutta method with s stages.

    Parameters
    ----------
    a_lower : tuple of tuples
        Row i (i = 1 .. s-1) holds a_{i,0..i-1}, the weights of the earlier stages in
        stage i. Stage 0 is always the derivative at the start of the step.
    b : tuple, length s
        Weights of the stages in the step.
    c : tuple, length s - 1
        Nodes of stages 1 .. s-1 (c_0 = 0).

    Notes
    -----
    The constructor checks the consistency conditions: each row of ``a`` sums to its
    node c_i, and sum(b) = 1.
    """

    a_lower: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]
    c: tuple[float, ...]

    def __post_init__(self):
        stages = len(self.b)
        if len(self.a_lower) != stages - 1 or len(self.c) != stages - 1:
            raise ValueError(f"Butcher tableau with {stages} weights needs {stages - 1} rows "
                             f"of a and nodes c, got {len(self.a_lower)} and {len(self.c)}")
        for i, (row, ci) in enumerate(zip(self.a_lower, self.c), start=1):
            # named as in Python and as in the textbook, which counts stages from 1: a_lower[0] is a_21
            entries = f"a_lower[{i - 1}] ({f'a_{i + 1}1' if i == 1 else f'a_{i + 1}1 .. a_{i + 1}{i}'})"
            if len(row) != i:
                raise ValueError(f"Butcher tableau: {entries} must have {i} entries, got {len(row)}")
            if abs(sum(row) - ci) > TABLEAU_TOLERANCE:
                raise ValueError(f"Butcher tableau: {entries} sums to {sum(row):.6g}, not its node c[{i - 1}] "
                                 f"(c_{i + 1}) = {ci:.6g}")
        if abs(sum(self.b) - 1) > TABLEAU_TOLERANCE:
            raise ValueError(f"Butcher tableau weights b sum to {sum(self.b)}, not 1")

    @property
    def stages(self) -> int:
        return len(self.b)

    def stability_function(self, z):
        """R(z) = 1 + z b^T (I - z A)^{-1} 1, the growth factor on y' = lambda y, z = lambda dt."""
        s = self.stages
        a = np.zeros((s, s))
        for i, row in enumerate(self.a_lower, start=1):
            a[i, :i] = row
        z = np.asarray(z, dtype=complex)
        # For explicit methods (I - zA)^{-1} = sum_k (zA)^k, a polynomial of degree s.
        term, coeffs = np.ones(s), []
        for _ in range(s):
            coeffs.append(np.dot(self.b, term))  # b^T A^k 1
            term = a @ term
        return 1 + sum(c * z ** (k + 1) for k, c in enumerate(coeffs))


def rk_step(f, t, y, dt, tableau: ButcherTableau):
    """One explicit Runge-Kutta step of y' = f(t, y) with the given tableau."""
    k = [f(t, y)]
    for row, ci in zip(tableau.a_lower, tableau.c):
        increment = sum(aij * kj for aij, kj in zip(row, k) if aij != 0)
        k.append(f(t + ci * dt, y + dt * increment))
    return y + dt * sum(bi * ki for bi, ki in zip(tableau.b, k) if bi != 0)


@dataclasses.dataclass(frozen=True)
class ExplicitRungeKutta(Stepper):
    """Explicit Runge-Kutta method driven by a Butcher tableau."""

    tableau: ClassVar[ButcherTableau]

    def __new__(cls, *args, **kwargs):
        # a method is a class whose class data is its tableau, not an instance given one: say so
        # to whoever writes the natural ExplicitRungeKutta(tableau=t)
        fields = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else []
        if len(args) > len(fields) or set(kwargs) - set(fields):
            raise TypeError(f"{cls.__name__}() takes no tableau: a Runge-Kutta method is a subclass with "
                            "the tableau as class data, `class MyMethod(ExplicitRungeKutta): name = 'my-method'; "
                            "order = 2; evaluations = 2; tableau = ButcherTableau(...)`, then MyMethod()")
        return super().__new__(cls)

    def step(self, model, t, y, dt, carry):
        return rk_step(model.vector_field, t, y, dt, self.tableau), carry

    def stability_function(self, z):
        """R(z) of the tableau: one step multiplies y' = lambda y by R(lambda dt)."""
        return self.tableau.stability_function(z)


@dataclasses.dataclass(frozen=True)
class RK4(ExplicitRungeKutta):
    """4th order classical Runge-Kutta method. Uses 4 stages.

    Exact to round-off for a constant force (the solution is a quadratic in t).
    """

    name = "rk4"
    order = 4
    evaluations = 4
    style = ("tab:blue", "*")
    stability_note = "2 sqrt(2) = 2.8284 undamped"
    tableau = ButcherTableau(
        a_lower=((1 / 2,), (0.0, 1 / 2), (0.0, 0.0, 1.0)),
        b=(1 / 6, 1 / 3, 1 / 3, 1 / 6),
        c=(1 / 2, 1 / 2, 1.0),
    )


@dataclasses.dataclass(frozen=True)
class Heun(ExplicitRungeKutta):
    """2nd order Heun method (explicit trapezoid). Uses 2 stages."""

    name = "heun"
    order = 2
    evaluations = 2
    style = ("tab:purple", "D")
    stability_note = "0 undamped (|R(i y)|^2 = 1 + y^4 / 4)"
    tableau = ButcherTableau(a_lower=((1.0,),), b=(1 / 2, 1 / 2), c=(1.0,))


@dataclasses.dataclass(frozen=True)
class Midpoint(ExplicitRungeKutta):
    """2nd order explicit midpoint method. Uses 2 stages."""

    name = "midpoint"
    order = 2
    evaluations = 2
    style = ("tab:pink", "P")
    stability_note = "0 undamped (same R as Heun)"
    tableau = ButcherTableau(a_lower=((1 / 2,),), b=(0.0, 1.0), c=(1 / 2,))
