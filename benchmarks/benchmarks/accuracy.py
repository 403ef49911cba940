"""Accuracy, not time: ``track_`` benchmarks, so an accuracy regression shows in asv's history.

Per fixed-step integrator: the global error at a fixed dt on the oscillator (exact
solution) and on the drag projectile (diffrax Dopri8 reference), the order fitted to the
error over four halvings of dt, and the energy drift over 100 periods.
"""

from __future__ import annotations

import functools

import numpy as np
from steplab.integrators.simulate import final_state_function

from .common import STEPPERS

#: fixed steps of the global-error benchmark over each problem's span
STEPS = 64
#: steps of the order fit: error at dt = span / n for each n (in the asymptotic range of every method)
ORDER_STEPS = (128, 256, 512, 1024)


@functools.cache
def _problems():
    from steplab.studies.problems import oscillator_problem, scene_problem

    return {"oscillator": oscillator_problem(0.0),
            "drag-projectile": scene_problem("drag-projectile", 2.0, "football with quadratic drag")}


@functools.cache
def _compiled(problem: str, method: str):
    """steplab's compiled loop for one problem and method (dt and n traced: compiled once)."""
    import jax.numpy as jnp

    return final_state_function(_problems()[problem].model.cast(jnp), method)


def _final_error(name: str, method: str, n: int, truth) -> float:
    """Largest final position error, m, after n compiled steps (inf if the run diverged)."""
    import jax.numpy as jnp

    problem, run = _problems()[name], _compiled(name, method)
    span = problem.t_end - problem.t_start
    y, bad = run(jnp.asarray(problem.y0), problem.t_start, span / n, n)
    return np.inf if int(bad) >= 0 else float(np.max(np.abs(np.asarray(y)[0] - truth[0])))


class GlobalError:
    """Final position error after 64 fixed steps (oscillator: 1.125 periods; projectile: 2 s)."""

    params = (STEPPERS, ["oscillator", "drag-projectile"])
    param_names = ["integrator", "problem"]
    unit = "m"
    timeout = 300

    def setup_cache(self):
        from steplab.studies.problems import true_final

        return {name: true_final(problem)[0] for name, problem in _problems().items()}

    def track_error(self, truths, integrator, problem):
        return _final_error(problem, integrator, STEPS, truths[problem])


class FittedOrder:
    """Slope of log(error) against log(dt) on the oscillator: should equal the declared order."""

    params = STEPPERS
    param_names = ["integrator"]
    unit = "order"
    timeout = 300

    def track_order(self, integrator):
        truth = _problems()["oscillator"].exact_final()
        errors = [_final_error("oscillator", integrator, n, truth) for n in ORDER_STEPS]
        return float(-np.polyfit(np.log(ORDER_STEPS), np.log(errors), 1)[0])


class EnergyDrift:
    """|E_end - E_0| / E_0 after 100 periods of the undamped oscillator at omega dt = 0.05."""

    params = STEPPERS
    param_names = ["integrator"]
    unit = "relative energy change"
    timeout = 300

    def track_energy_drift(self, integrator):
        import jax.numpy as jnp

        problem = _problems()["oscillator"]
        n = int(round(100 * 2 * np.pi / 0.05))
        y, bad = _compiled("oscillator", integrator)(jnp.asarray(problem.y0), 0.0, 100.0 / n, n)
        if int(bad) >= 0:
            return np.inf
        e0 = float(problem.model.energy(problem.y0))
        return abs(float(problem.model.energy(np.asarray(y))) - e0) / e0
