"""``steplab recommend``: the cheapest fixed-step integrator and dt that meet an error tolerance.

It measures rather than predicts: each fixed-step method runs on the problem at halving
dt until its error against the exact solution (or the reference) is below the
tolerance, using the work-precision study's measurement of one fixed-step point. A
scene with collisions is measured with them instead (:mod:`.recommend_collisions`).
"""

from __future__ import annotations

import functools

import numpy as np
from steplab.integrators import INTEGRATORS, Stepper, get_integrator
from steplab.integrators.simulate import final_state_function

from steplab.core.timing import interleaved_medians

from .problems import Problem, true_final
from .work_precision import TIMING_REPEATS, adaptive_point, fixed_step_point

#: the smallest step ``recommend`` considers sensible, as a fraction of the run
DT_FLOOR_FRACTION = 2.0**-20


def check_dt_max(span: float, dt_max: float | None) -> None:
    """ValueError, one line, for a ``dt_max`` that leaves no dt to measure: below twice the smallest
    dt recommend considers (span x DT_FLOOR_FRACTION, the run in 2^20 steps), as a dt is accepted
    only with its check at dt/2; a step count that overflows a float's (dt_max = 1e-320) among them."""
    smallest = 2 * span * DT_FLOOR_FRACTION
    if dt_max is not None and not span / dt_max * (1 - 1e-12) <= span / smallest:
        shown = next(v for v in (float(f"{smallest * (1 + k * 1e-3):.3g}") for k in range(11)) if v >= smallest)
        raise ValueError(f"--dt-max {dt_max:g} s is below the smallest recommend measures, {shown:g} s (a dt "
                         f"and its check at dt/2 within the run of {span:g} s in {round(1 / DT_FLOOR_FRACTION)} "
                         f"steps); pass --dt-max {shown:g} or more")


def _final(run, y0, t_start, dt, n):
    """One compiled run to its final state, waited for (what a candidate's time is)."""
    return run(y0, t_start, dt, n)[0].block_until_ready()


class NoFixedStepError(RuntimeError):
    """Neither a fixed-step method above the dt floor nor the adaptive reference meets the tolerance."""


def recommend(problem: Problem, tol: float, *, dt_max: float | None = None, integrators=None) -> dict:
    """The cheapest fixed-step integrator and dt, measured on ``problem``, whose error <= ``tol``.

    For each integrator dt is halved from a quarter of the run (or from the largest whole
    division of the run not above ``dt_max``) until the error is below ``tol`` at that dt
    and at half of it (so a lucky cancellation at one dt is not trusted); its cost is the
    median compiled wall time, every method's answer timed in the same interleaved rounds.
    ``integrators`` names the candidates (default: every fixed-step method). Returns
    ``integrator``, ``dt``, ``error``, ``seconds``; when no method gets there above the dt
    floor, the result names the reference that does instead (``integrator`` is then that
    reference).
    """
    import jax.numpy as jnp

    span = problem.t_end - problem.t_start
    check_dt_max(span, dt_max)  # before the reference solve
    truth, _ = true_final(problem)
    most = round(1 / DT_FLOOR_FRACTION)
    # the first dt: a quarter of the run, or the largest whole division not above dt_max
    first = 4 if dt_max is None else max(4, int(np.ceil(span / dt_max * (1 - 1e-12))))
    names = integrators if integrators is not None else [n for n, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    candidates, calls = [], {}
    y0 = jnp.asarray(problem.y0)
    for method in names:
        run = final_state_function(problem.model.cast(jnp), method)
        previous, n = None, first
        while n <= most:
            point = fixed_step_point(problem, method, n, truth, run, timed=False)
            ok = point["error"] is not None and point["error"] <= tol
            if ok and previous is not None:  # the method's answer: timed below, with the others'
                candidates.append(previous)
                calls[method] = functools.partial(_final, run, y0, problem.t_start, previous["dt"], previous["steps"])
                break
            previous = point if ok else None
            if get_integrator(method).implicit and n >= 2**16:
                break
            n *= 2
    if candidates:
        # every answer timed in the same interleaved rounds: a burst of load falls on them alike, where timed one
        # after another it could make a slower method look the cheapest (midpoint over rk4 at load 4 to 8)
        seconds = interleaved_medians(calls, TIMING_REPEATS)
        candidates = [p | {"seconds": seconds[p["method"]]} for p in candidates]
        best = min(candidates, key=lambda p: p["seconds"])
        return {"integrator": best["method"], "dt": best["dt"], "error": best["error"],
                "seconds": best["seconds"], "steps": best["steps"]}
    # no fixed step reaches tol: report the adaptive reference that does
    floor = f"no fixed-step method reaches {tol:g} m with dt >= {span * DT_FLOOR_FRACTION:.3g} s"
    best, compiled = np.inf, {}  # one compilation for every rtol (a traced argument)
    for rtol in (1e-8, 1e-10, 1e-12, 1e-13):
        point = adaptive_point(problem, "diffrax-dopri8", rtol, truth, compiled)
        best = min(best, point["error"])
        if point["error"] <= tol:
            return {"integrator": "diffrax-dopri8", "dt": None, "rtol": rtol, "error": point["error"],
                    "seconds": point["seconds"], "note": floor}
    raise NoFixedStepError(f"{floor}, and neither does diffrax-dopri8 at rtol = 1e-13 (its error "
                           f"{best:.2g} m): {tol:g} m is below what float64 round-off allows here")
