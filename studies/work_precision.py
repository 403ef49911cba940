"""Work-precision study and ``steplab recommend``: what accuracy each method buys per unit cost.

Every fixed-step integrator runs over a range of dt, and the adaptive solvers (diffrax
Tsit5 and Dopri8, scipy DOP853 and RK45) over a range of tolerances, on a small panel
of scenes. Each point records the final position error against the exact solution or
the reference, the wall time, and the force evaluations. Compiled code is timed
properly: compiled once (compile time recorded separately), warmed up, the median of
TIMING_REPEATS calls, each ended with ``block_until_ready``.
"""

from __future__ import annotations

import time

import numpy as np
from steplab.integrators import INTEGRATORS, Stepper
from steplab.integrators.simulate import final_state_function

from . import plotting
from .problems import Problem, oscillator_problem, scene_problem, true_final
from .runner import Study

TIMING_REPEATS = 5
#: new force evaluations per step of the FSAL diffrax solvers (stages - 1)
DIFFRAX_EVALUATIONS = {"Tsit5": 6, "Dopri8": 13}
#: the smallest step ``recommend`` considers sensible, as a fraction of the run
DT_FLOOR_FRACTION = 2.0**-20


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
            "adaptive": ["diffrax Tsit5", "diffrax Dopri8", "scipy DOP853", "scipy RK45"]}


def _median_time(call) -> float:
    """Median wall time of a warmed-up call that blocks until its result is ready."""
    call()
    times = []
    for _ in range(TIMING_REPEATS):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _error(y, truth) -> float:
    return float(np.max(np.abs(np.asarray(y, dtype=float)[0] - truth[0])))


def fixed_step_point(problem: Problem, method: str, n: int, truth, run=None, timed: bool = True) -> dict:
    """One (dt, error, seconds, evaluations) point of a fixed-step method, JAX-compiled."""
    import jax.numpy as jnp

    run = run or final_state_function(problem.model.cast(jnp), method)
    y0 = jnp.asarray(problem.y0)
    dt = (problem.t_end - problem.t_start) / n
    y, bad = run(y0, problem.t_start, dt, n)
    evaluations = None if INTEGRATORS[method].implicit else n * INTEGRATORS[method].evaluations
    point = {"method": method, "dt": dt, "steps": n, "evaluations": evaluations}
    if int(bad) >= 0:
        return point | {"error": None, "seconds": None}
    if not timed:
        return point | {"error": _error(y, truth), "seconds": None}
    seconds = _median_time(lambda: run(y0, problem.t_start, dt, n)[0].block_until_ready())
    return point | {"error": _error(y, truth), "seconds": seconds}


def adaptive_point(problem: Problem, solver: str, rtol: float, truth, compiled: dict) -> dict:
    """One point of an adaptive solver at ``rtol`` (atol = rtol x 1e-3 m)."""
    library, name = solver.split()
    if library == "scipy":
        from scipy.integrate import solve_ivp

        y0 = np.asarray(problem.y0, float)
        fun = lambda t, y: np.asarray(problem.model.vector_field(t, y.reshape(y0.shape))).ravel()  # noqa: E731
        call = lambda: solve_ivp(fun, (problem.t_start, problem.t_end), y0.ravel(), method=name,  # noqa: E731
                                 rtol=rtol, atol=rtol * 1e-3)
        sol = call()
        y = sol.y[:, -1].reshape(y0.shape)
        seconds = float(np.median([_timed(call) for _ in range(3)]))
        return {"method": solver, "rtol": rtol, "error": _error(y, truth), "seconds": seconds,
                "evaluations": int(sol.nfev), "steps": int(sol.t.size - 1)}
    import jax.numpy as jnp

    if solver not in compiled:
        compiled[solver] = _compile_diffrax(problem, name)
    run, compile_time = compiled[solver]
    rtol_arr = jnp.asarray(rtol)
    y, steps = run(rtol_arr)
    seconds = _median_time(lambda: run(rtol_arr)[0].block_until_ready())
    return {"method": solver, "rtol": rtol, "error": _error(y, truth), "seconds": seconds,
            "evaluations": int(steps) * DIFFRAX_EVALUATIONS[name] + 1, "steps": int(steps),
            "compile_seconds": compile_time}


def _timed(call) -> float:
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def _compile_diffrax(problem: Problem, name: str):
    """A jitted diffrax solve with the tolerance as a traced argument (one compilation)."""
    import diffrax
    import jax
    import jax.numpy as jnp

    model = problem.model.cast(jnp)
    term = diffrax.ODETerm(lambda t, y, args: model.vector_field(t, y))
    y0 = jnp.asarray(problem.y0)

    @jax.jit
    def run(rtol):
        sol = diffrax.diffeqsolve(term, getattr(diffrax, name)(), problem.t_start, problem.t_end, None, y0,
                                  stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol * 1e-3),
                                  max_steps=2**20)
        return sol.ys[-1], sol.stats["num_steps"]

    start = time.perf_counter()
    run(jnp.asarray(1e-6))[0].block_until_ready()
    return run, time.perf_counter() - start


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
                if method.startswith(("diffrax", "scipy")):
                    style.update(linestyle="--", marker={"diffrax Tsit5": "1", "diffrax Dopri8": "2",
                                                         "scipy DOP853": "3", "scipy RK45": "4"}[method],
                                 color={"diffrax Tsit5": "black", "diffrax Dopri8": "dimgray",
                                        "scipy DOP853": "tab:cyan", "scipy RK45": "darkgoldenrod"}[method])
                ax.loglog([p[cost] for p in mp], [p["error"] for p in mp], ms=5, lw=1, **style)
            front = sorted((p for p in pts if p.get(f"pareto_{cost}") and p["error"] > 0), key=lambda p: p[cost])
            ax.loglog([p[cost] for p in front], [p["error"] for p in front], color="k", lw=5, alpha=0.15,
                      label="Pareto front")
            ax.set_xlabel(label)
            ax.grid(True, alpha=0.3)
        axes[0].set_ylabel("final position error (m)")
        axes[0].set_ylim(top=10.0)  # larger errors mean the method failed outright
        axes[0].legend(fontsize=7, ncol=2)
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


# --- recommend ----------------------------------------------------------------------


class NoFixedStepError(RuntimeError):
    pass


def recommend(problem: Problem, tol: float) -> dict:
    """The cheapest fixed-step integrator and dt, measured on ``problem``, whose error <= ``tol``.

    For each integrator dt is halved from a quarter of the run until the error is below
    ``tol`` at that dt and at half of it (so a lucky cancellation at one dt is not
    trusted); its cost is the median compiled wall time. Returns ``integrator``, ``dt``,
    ``error``, ``seconds``; when no method gets there above the dt floor, the result
    names the reference that does instead (``integrator`` is then that reference).
    """
    import jax.numpy as jnp

    truth, _ = true_final(problem)
    span = problem.t_end - problem.t_start
    max_log2 = int(round(-np.log2(DT_FLOOR_FRACTION)))
    candidates = []
    for method in (n for n, m in INTEGRATORS.items() if isinstance(m, Stepper)):
        run = final_state_function(problem.model.cast(jnp), method)
        previous = None
        for k in range(2, max_log2 + 1):
            point = fixed_step_point(problem, method, 2**k, truth, run, timed=False)
            ok = point["error"] is not None and point["error"] <= tol
            if ok and previous is not None:  # time only the method's answer
                candidates.append(fixed_step_point(problem, method, previous["steps"], truth, run))
                break
            previous = point if ok else None
            if INTEGRATORS[method].implicit and k >= 16:
                break
    if candidates:
        best = min(candidates, key=lambda p: p["seconds"])
        return {"integrator": best["method"], "dt": best["dt"], "error": best["error"],
                "seconds": best["seconds"], "steps": best["steps"]}
    # no fixed step reaches tol: report the adaptive reference that does
    floor = f"no fixed-step method reaches {tol:g} m with dt >= {span * DT_FLOOR_FRACTION:.3g} s"
    best = np.inf
    for rtol in (1e-8, 1e-10, 1e-12, 1e-13):
        point = adaptive_point(problem, "diffrax Dopri8", rtol, truth, {})
        best = min(best, point["error"])
        if point["error"] <= tol:
            return {"integrator": "diffrax-dopri8", "dt": None, "rtol": rtol, "error": point["error"],
                    "seconds": point["seconds"], "note": floor}
    raise NoFixedStepError(f"{floor}, and neither does diffrax-dopri8 at rtol = 1e-13 (its error "
                           f"{best:.2g} m): {tol:g} m is below what float64 round-off allows here")
