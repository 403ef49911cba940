"""Work-precision study: what accuracy each method buys per unit cost.

Every fixed-step integrator runs over a range of dt, and the adaptive solvers
(diffrax-tsit5, diffrax-dopri8, scipy-dop853, scipy-rk45) over a range of tolerances, on a small panel
of scenes. Each point records the final position error against the exact solution or
the reference, the wall time, and the force evaluations. Compiled code is timed
properly: compiled once (compile time recorded separately), warmed up, the median of
TIMING_REPEATS calls, each ended with ``block_until_ready`` (:mod:`.timing`); every
adaptive solve goes through ``integrators.references.solve_adaptive``.
"""

from __future__ import annotations

import time

import numpy as np
from steplab.integrators import INTEGRATORS, Stepper, get_integrator
from steplab.integrators.references import ReferenceFailedError, solve_adaptive
from steplab.integrators.simulate import final_state_function

from steplab.core.timing import first_call_seconds, median_time

from . import plotting
from .problems import Problem, oscillator_problem, scene_problem, true_final
from .runner import Study

TIMING_REPEATS = 5
#: timed solves of a scipy point (a Python loop: slower, and steadier, than compiled code)
SCIPY_TIMING_REPEATS = 3
#: new force evaluations per step of the FSAL diffrax solvers (stages - 1)
DIFFRAX_EVALUATIONS = {"diffrax-tsit5": 6, "diffrax-dopri8": 13}
#: diffrax's step budget per point (the tightest rtol of the panel takes ~10^4 steps)
DIFFRAX_MAX_STEPS = 2**20


def _panel(quick: bool) -> list[Problem]:
    panel = [oscillator_problem(0.0, t_end=10.125)]
    if not quick:
        panel += [scene_problem("drag-projectile", 2.0, "football with quadratic drag"),
                  scene_problem("soft-cube", 0.5, "soft cube, 28 springs and dampers")]
    return panel


def parameters(quick: bool) -> dict:
    steppers = [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    return {"scenes": [p.name for p in _panel(quick)], "integrators": steppers,
            "log2_steps": list(range(4, 13 if quick else 17, 2 if quick else 1)),
            "rtols": [10.0**-k for k in (range(3, 10, 3) if quick else range(3, 13))],
            "adaptive": ["diffrax-tsit5", "diffrax-dopri8", "scipy-dop853", "scipy-rk45"]}


def _error(y, truth) -> float:
    return float(np.max(np.abs(np.asarray(y, dtype=float)[0] - truth[0])))


def fixed_step_point(problem: Problem, method: str, n: int, truth, run=None, timed: bool = True) -> dict:
    """One (dt, error, seconds, evaluations) point of a fixed-step method, JAX-compiled."""
    import jax.numpy as jnp

    run = run or final_state_function(problem.model.cast(jnp), method)
    y0 = jnp.asarray(problem.y0)
    dt = (problem.t_end - problem.t_start) / n
    y, bad = run(y0, problem.t_start, dt, n)
    integrator = get_integrator(method)
    evaluations = None if integrator.implicit else n * integrator.evaluations
    point = {"method": method, "dt": dt, "steps": n, "evaluations": evaluations}
    if int(bad) >= 0:
        return point | {"error": None, "seconds": None}
    if not timed:
        return point | {"error": _error(y, truth), "seconds": None}
    seconds = median_time(lambda: run(y0, problem.t_start, dt, n)[0].block_until_ready(), TIMING_REPEATS)
    return point | {"error": _error(y, truth), "seconds": seconds}


def adaptive_point(problem: Problem, solver: str, rtol: float, truth, compiled: dict) -> dict:
    """One point of an adaptive solver (a name of ``ADAPTIVE_METHODS``) at ``rtol`` (atol = rtol x 1e-3 m)."""
    ts = (problem.t_start, problem.t_end)
    if solver.startswith("scipy"):
        def call():
            return solve_adaptive(problem.model.vector_field, ts, problem.y0, solver, rtol, rtol * 1e-3,
                                  at_saved_times=False)

        sol = call()
        seconds = median_time(call, SCIPY_TIMING_REPEATS)
        return {"method": solver, "rtol": rtol, "error": _error(sol.ys[-1], truth), "seconds": seconds,
                "evaluations": sol.evaluations, "steps": sol.steps}
    import jax.numpy as jnp

    if solver not in compiled:
        compiled[solver] = _compile_diffrax(problem, solver)
    run, compile_time = compiled[solver]
    rtol_arr = jnp.asarray(rtol)
    y, steps = run(rtol_arr)
    seconds = median_time(lambda: run(rtol_arr)[0].block_until_ready(), TIMING_REPEATS)
    return {"method": solver, "rtol": rtol, "error": _error(y, truth), "seconds": seconds,
            "evaluations": int(steps) * DIFFRAX_EVALUATIONS[solver] + 1, "steps": int(steps),
            "compile_seconds": compile_time}


def _compile_diffrax(problem: Problem, solver: str):
    """A jitted diffrax solve with the tolerance as a traced argument (one compilation)."""
    import jax
    import jax.numpy as jnp

    model = problem.model.cast(jnp)
    y0 = jnp.asarray(problem.y0)

    @jax.jit
    def run(rtol):
        sol = solve_adaptive(model.vector_field, (problem.t_start, problem.t_end), y0, solver, rtol, rtol * 1e-3,
                             at_saved_times=False, max_steps=DIFFRAX_MAX_STEPS)
        return sol.ys[-1], sol.steps, sol.success

    compile_time = first_call_seconds(lambda: run(jnp.asarray(1e-6))[0].block_until_ready())

    def checked(rtol):
        y, steps, success = run(rtol)
        if not bool(success):
            raise ReferenceFailedError(f"{solver} did not reach t = {problem.t_end:g} s at rtol = {float(rtol):g}")
        return y, steps

    return checked, compile_time


def pareto(points: list[dict], cost: str) -> list[int]:
    """Indices of the points no other point beats on both error and ``cost``."""
    ok = [i for i, p in enumerate(points) if p["error"] is not None and p[cost] is not None]
    front = []
    for i in ok:
        if not any(points[j]["error"] <= points[i]["error"] and points[j][cost] <= points[i][cost]
                   and (points[j]["error"], points[j][cost]) != (points[i]["error"], points[i][cost])
                   for j in ok):
            front.append(i)
    return front


def compute(params: dict, progress=None) -> dict:
    import jax.numpy as jnp

    points = []
    for problem in _panel(len(params["scenes"]) == 1):
        truth, reference = true_final(problem)
        scene_points = []
        for method in params["integrators"]:
            start = time.perf_counter()
            run = final_state_function(problem.model.cast(jnp), method)
            run(jnp.asarray(problem.y0), problem.t_start, 0.1, 2)[0].block_until_ready()
            compile_seconds = time.perf_counter() - start
            for k in params["log2_steps"]:
                scene_points.append(fixed_step_point(problem, method, 2**k, truth, run)
                                    | {"compile_seconds": compile_seconds})
        compiled = {}
        for solver in params["adaptive"]:
            for rtol in params["rtols"]:
                scene_points.append(adaptive_point(problem, solver, rtol, truth, compiled))
        for cost in ("seconds", "evaluations"):
            for i in pareto(scene_points, cost):
                scene_points[i][f"pareto_{cost}"] = True
        points += [p | {"scene": problem.name, "reference": reference["reference"]} for p in scene_points]
        if progress is not None:
            progress()
    return {"points": points}


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    figures = []
    scenes = list(dict.fromkeys(p["scene"] for p in record["points"]))
    for scene in scenes:
        pts = [p for p in record["points"] if p["scene"] == scene and p["error"] is not None]
        fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
        for ax, cost, label in ((axes[0], "seconds", "wall time (s, compiled, median)"),
                                (axes[1], "evaluations", "force evaluations")):
            for method in dict.fromkeys(p["method"] for p in pts):
                mp = [p for p in pts if p["method"] == method and p[cost] is not None and p["error"] > 0]
                if not mp:
                    continue
                style = plotting.style(method)
                if method.startswith(("diffrax", "scipy")):  # the adaptive references, dashed, in their own colours
                    style.update(linestyle="--")
                ax.loglog([p[cost] for p in mp], [p["error"] for p in mp], ms=5, lw=1, **style)
            front = sorted((p for p in pts if p.get(f"pareto_{cost}") and p["error"] > 0), key=lambda p: p[cost])
            ax.loglog([p[cost] for p in front], [p["error"] for p in front], color="k", lw=5, alpha=0.15,
                      label="Pareto front")
            ax.set_xlabel(label)
            ax.grid(True, alpha=0.3)
        axes[0].set_ylabel("final position error (m)")
        axes[0].set_ylim(top=10.0)  # larger errors mean the method failed outright
        # below the panels: inside, it covered the cheapest runs' points
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=6,
                   frameon=False)
        fig.suptitle(f"Work against precision: {scene} (fixed-step methods over dt, adaptive over rtol; "
                     "errors above 10 m are off the chart)")
        fig.tight_layout()
        figures += plotting.save_figure(fig, out, f"work_precision_{scene}")
    return figures


def summary(record: dict) -> list[tuple[str, str]]:
    rows = []
    for scene in dict.fromkeys(p["scene"] for p in record["points"]):
        front = {p["method"] for p in record["points"] if p["scene"] == scene and p.get("pareto_seconds")}
        rows.append((f"Pareto front (time), {scene}", ", ".join(sorted(front))))
    return rows


STUDY = Study("work_precision", "Work-precision: error against wall time and force evaluations",
              parameters, compute, plot, summary)
