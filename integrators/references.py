"""Adaptive reference solvers behind the same driver: diffrax and scipy ``solve_ivp``.

A study asks for "the reference" and gets a high-order adaptive method at a tight,
recorded tolerance. The explicit ones (Dopri8, Tsit5, DOP853) suit smooth non-stiff
scenes; the implicit ones (Kvaerno5, Radau) stiff spring systems.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .base import Solver

#: step budget of one reference solve; exceeding it is reported, never truncated silently
MAX_REFERENCE_STEPS = 1_000_000


class ReferenceFailedError(RuntimeError):
    """The reference solver did not reach the end of the interval."""


@dataclasses.dataclass(frozen=True)
class DiffraxReference(Solver):
    """Adaptive diffrax solve with a PID step-size controller."""

    rtol: float = 1e-12
    atol: float = 1e-12

    solver_name: ClassVar[str]
    backend = "jax"
    evaluations = None

    def solve(self, model, ts, y0):
        import diffrax
        import jax.numpy as jnp

        term = diffrax.ODETerm(lambda t, y, args: model.vector_field(t, y))
        ts = jnp.asarray(ts, dtype=model.dtype)
        sol = diffrax.diffeqsolve(
            term, getattr(diffrax, self.solver_name)(), t0=ts[0], t1=ts[-1], dt0=None,
            y0=jnp.asarray(y0, dtype=model.dtype), saveat=diffrax.SaveAt(ts=ts),
            # Step exactly onto every saved time: diffrax would otherwise fill SaveAt(ts) by
            # interpolating inside steps, and the Dopri8 / Kvaerno5 interpolants are
            # 100-1000x less accurate than the steps themselves.
            stepsize_controller=diffrax.ClipStepSizeController(
                diffrax.PIDController(rtol=self.rtol, atol=self.atol), step_ts=ts),
            max_steps=MAX_REFERENCE_STEPS, throw=False,
        )
        if sol.result != diffrax.RESULTS.successful:
            raise ReferenceFailedError(f"{self.name} failed: {sol.result}")
        return np.asarray(sol.ys)


@dataclasses.dataclass(frozen=True)
class DiffraxDopri8(DiffraxReference):
    """8th order Dormand-Prince (diffrax.Dopri8), adaptive; the default reference."""

    name = "diffrax-dopri8"
    order = 8
    solver_name = "Dopri8"


@dataclasses.dataclass(frozen=True)
class DiffraxTsit5(DiffraxReference):
    """5th order Tsitouras (diffrax.Tsit5), adaptive."""

    name = "diffrax-tsit5"
    order = 5
    solver_name = "Tsit5"


@dataclasses.dataclass(frozen=True)
class DiffraxKvaerno5(DiffraxReference):
    """5th order ESDIRK Kvaerno5 (diffrax), adaptive; implicit, for stiff spring systems."""

    rtol: float = 1e-10
    atol: float = 1e-10

    name = "diffrax-kvaerno5"
    order = 5
    implicit = True
    solver_name = "Kvaerno5"


@dataclasses.dataclass(frozen=True)
class ScipyReference(Solver):
    """Adaptive ``scipy.integrate.solve_ivp``."""

    rtol: float = 1e-12
    atol: float = 1e-12

    method: ClassVar[str]
    evaluations = None

    def solve(self, model, ts, y0):
        from scipy.integrate import solve_ivp

        y0 = np.asarray(y0, dtype=float)
        shape = y0.shape

        def fun(t, y):
            return np.asarray(model.vector_field(t, y.reshape(shape))).ravel()

        kwargs = {}
        if self.implicit:
            kwargs["jac"] = lambda t, y: _first_order_jacobian(model, t, y.reshape(shape))
        sol = solve_ivp(fun, (ts[0], ts[-1]), y0.ravel(), method=self.method, t_eval=ts,
                        rtol=self.rtol, atol=self.atol, **kwargs)
        if not sol.success:
            raise ReferenceFailedError(f"{self.name} failed: {sol.message}")
        return sol.y.T.reshape((len(ts),) + shape)


def _first_order_jacobian(model, t, y):
    """d(v, a)/d(q, v) = [[0, I], [da/dq, da/dv]] for y = (q, v)."""
    dadq, dadv = model.jacobian(t, y[0], y[1])
    n3 = dadq.shape[0]
    return np.block([[np.zeros((n3, n3)), np.eye(n3)], [dadq, dadv]])


@dataclasses.dataclass(frozen=True)
class ScipyDOP853(ScipyReference):
    """8th order Dormand-Prince (scipy DOP853), adaptive."""

    name = "scipy-dop853"
    order = 8
    method = "DOP853"


@dataclasses.dataclass(frozen=True)
class ScipyRadau(ScipyReference):
    """5th order Radau IIA (scipy), adaptive; implicit, for stiff spring systems."""

    rtol: float = 1e-10
    atol: float = 1e-10

    name = "scipy-radau"
    order = 5
    implicit = True
    method = "Radau"
