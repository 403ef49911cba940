"""Truncation study: the lecture's explicit Euler numbers, and global error against dt.

For every fixed-step integrator and every problem, the global error at the end time
is measured for dt = T / 2^k, in float64 and float32, from large steps down until
round-off dominates: truncation error falls as dt^p, accumulated round-off rises as
the step count grows, and the curve shows the V of total error. The fitted slope on
the truncation branch is compared with the declared order.

The search stops at 2^20 steps. A first-order method's float64 floor is out of reach:
truncation C dt meets accumulated round-off eps T / dt near dt = sqrt(eps T / C), some
10^8 steps, so its curve is still falling at the last point (``floor_reached`` false).
"""

from __future__ import annotations

import functools

import numpy as np
from steplab.integrators import INTEGRATORS, DivergenceError, Stepper, get_integrator
from steplab.integrators.simulate import final_state_function

from . import plotting
from .lecture import lecture_check
from .problems import oscillator_problem, projectile_problem, scene_problem, true_final
from .runner import Study, run_tasks
from .system import is_system
from .tables import Table, format_value, markdown_table

#: after the smallest error, keep halving dt this many times to show the round-off branch
ROUNDOFF_POINTS = 3
#: errors below this count as "exact to round-off" (the method integrates the problem exactly)
EXACT_THRESHOLD = 1e-9
#: the fit uses only points whose error is this many times above the curve's minimum,
#: so round-off does not bend the fitted slope
FIT_MARGIN = 100.0
#: errors below this many ulps of the solution's scale are round-off noise, not truncation
ROUNDOFF_NOISE = 1e4
#: how many of the smallest truncation-dominated steps the order fit uses
FIT_POINTS = 5
#: implicit Euler solves a linear system per Newton iteration; cap its step count
IMPLICIT_MAX_LOG2_STEPS = 16
#: a system under test (an engine stepped from Python) stops at 2^14 steps: enough for the
#: truncation branch of every method at the oscillator's 1.125 periods
SYSTEM_MAX_LOG2_STEPS = 14


def _problems(names):
    factories = {
        "projectile": projectile_problem,
        "oscillator": lambda: oscillator_problem(0.0),
        "damped-oscillator": lambda: oscillator_problem(0.1),
        "drag-projectile": lambda: scene_problem("drag-projectile", 2.0, "football with quadratic drag "
                                                 "(reference: diffrax Dopri8)"),
        "soft-cube": lambda: scene_problem("soft-cube", 0.5, "soft cube, 28 springs and dampers "
                                           "(reference: diffrax Dopri8)"),
    }
    return [factories[name]() for name in names]


def parameters(quick: bool) -> dict:
    steppers = [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    if quick:
        return {"problems": ["projectile", "oscillator"], "integrators": steppers,
                "precisions": ["float64", "float32"], "min_log2_steps": 2, "max_log2_steps": 14}
    return {"problems": ["projectile", "oscillator", "damped-oscillator", "drag-projectile", "soft-cube"],
            "integrators": steppers, "precisions": ["float64", "float32"],
            "min_log2_steps": 2, "max_log2_steps": 20}


def error_curve(problem, method: str, precision: str, truth, min_log2: int, max_log2: int) -> list[dict]:
    """Global position error at t_end for dt = T / 2^k, k = min_log2, ..., until round-off wins.

    ``method``: a steplab integrator (run compiled, in ``precision``) or a system under test
    (:mod:`.system`, run in its own precision).
    """
    span = problem.t_end - problem.t_start
    if is_system(method):  # an engine (or steplab behind the system protocol), in its own precision
        system = method.build(problem.model, None, span / 2**min_log2, problem.y0)
        max_log2 = min(max_log2, SYSTEM_MAX_LOG2_STEPS)
        y0, dtype = problem.y0, np.float64

        def run(y0, t_start, dt, n):
            try:
                return system.advance(y0, float(dt), n, t_start=float(t_start), save_every=n).y[-1], -1
            except DivergenceError as err:
                return None, err.step
    else:
        import jax.numpy as jnp

        dtype = np.dtype(precision)
        model = problem.model.cast(jnp, dtype)
        run = final_state_function(model, method)
        y0 = jnp.asarray(problem.y0, dtype)
        if get_integrator(method).implicit:
            max_log2 = min(max_log2, IMPLICIT_MAX_LOG2_STEPS)
    points, best, rising, falling, entered = [], np.inf, 0, 0, False
    for k in range(min_log2, max_log2 + 1):
        n = 2**k
        dt = span / n
        y, bad = run(y0, np.asarray(problem.t_start, dtype), np.asarray(dt, dtype), n)
        if int(bad) >= 0:
            points.append({"dt": dt, "steps": n, "error": None, "diverged_at_step": int(bad)})
            continue
        error = float(np.max(np.abs(np.asarray(y[0], dtype=float) - truth[0])))
        # Only a rise after the curve has entered its truncation branch (two halvings that
        # each cut the error) is round-off; large steps can make errors rise before that.
        falling = falling + 1 if points and points[-1]["error"] and error < points[-1]["error"] / 1.3 else 0
        points.append({"dt": dt, "steps": n, "error": error})
        if error < best:
            best, rising = error, 0
        elif entered:
            rising += 1
            if rising == ROUNDOFF_POINTS:
                break
        entered = entered or falling >= 2
    return points


def fit_order(points: list[dict], noise: float = 0.0) -> float | None:
    """Slope of log error against log dt on the truncation branch (None if exact or too few points).

    The branch ends where round-off takes over: points below ``noise`` are dropped, and
    if the curve turned up, so are points within FIT_MARGIN of its minimum. Of what
    remains, the FIT_POINTS smallest steps (the most asymptotic) are fitted.
    """
    finite = [p for p in points if p["error"] is not None and p["error"] > noise]
    if not finite or max(p["error"] for p in finite) < EXACT_THRESHOLD:
        return None
    i_min = int(np.argmin([p["error"] for p in finite]))
    branch = finite[: i_min + 1]
    if i_min < len(finite) - 1:  # round-off reached: stay well above its floor
        branch = [p for p in branch if p["error"] > FIT_MARGIN * finite[i_min]["error"]]
    branch = branch[-FIT_POINTS:]
    if len(branch) < 3:
        return None
    slope, _ = np.polyfit(np.log([p["dt"] for p in branch]), np.log([p["error"] for p in branch]), 1)
    return float(slope)


def tasks(params: dict) -> list[list]:
    """One task per problem and integrator (every precision)."""
    return [["curve", problem, method] for problem in params["problems"] for method in params["integrators"]]


@functools.cache
def _problem_and_truth(name: str):
    """A problem and its true final state, once per process (a reference solve can take seconds)."""
    [problem] = _problems([name])
    return problem, *true_final(problem)


def task(params: dict, item: list) -> dict:
    """One integrator on one problem: its error curve in each precision, the least error, the fitted order."""
    _, name, method = item
    problem, truth, info = _problem_and_truth(name)
    result = {"problem": problem.name, "reference": info, "curves": [], "least_error": {}}
    for precision in params["precisions"]:
        try:
            points = error_curve(problem, method, precision, truth, params["min_log2_steps"],
                                 params["max_log2_steps"])
        except DivergenceError:
            points = []
        result["curves"].append({"problem": problem.name, "title": problem.title, "integrator": method,
                                 "precision": precision, "points": points})
        finite = [p for p in points if p["error"] is not None]
        if finite:
            best = min(finite, key=lambda p: p["error"])
            # the least error is a round-off floor only if smaller steps did worse
            result["least_error"][precision] = {
                "dt": best["dt"], "error": best["error"], "floor_reached": best is not finite[-1]}
        if precision == "float64":
            noise = ROUNDOFF_NOISE * np.finfo(np.float64).eps * max(1.0, float(np.max(np.abs(truth))))
            result["order"] = fit_order(points, noise)
    return result


def reduce(params: dict, results: list) -> dict:
    """The record: the lecture's tables, every error curve, the fitted and declared orders."""
    record = lecture_check()
    curves, orders, best_dt, references = [], {}, {}, {}
    for (_, _, method), result in zip(tasks(params), results):
        name = result["problem"]
        references[name] = result["reference"]
        curves += result["curves"]
        best_dt.setdefault(name, {})[method] = result["least_error"]
        orders.setdefault(name, {})
        if "order" in result:
            orders[name][method] = result["order"]
    declared = {name: get_integrator(name).order for name in params["integrators"]}
    record.update(curves=curves, orders=orders, declared_orders=declared, least_error=best_dt,
                  references=references)
    return record


def compute(params: dict, progress=None) -> dict:
    """Every task in turn, then the reduction (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    figures = []
    problems = list(dict.fromkeys(c["problem"] for c in record["curves"]))
    for name in problems:
        curves = [c for c in record["curves"] if c["problem"] == name]
        precisions = list(dict.fromkeys(c["precision"] for c in curves))
        fig, axes = plt.subplots(1, len(precisions), figsize=(6.2 * len(precisions), 4.8), sharey=True,
                                 squeeze=False)
        for ax, precision in zip(axes[0], precisions):
            for c in (c for c in curves if c["precision"] == precision):
                pts = [p for p in c["points"] if p["error"] is not None and p["error"] > 0]
                if not pts:
                    continue
                slope = record["orders"][name].get(c["integrator"]) if precision == "float64" else None
                style = plotting.style(c["integrator"])
                if slope is not None:
                    style["label"] += f" (slope {slope:.2f})"
                ax.loglog([p["dt"] for p in pts], [p["error"] for p in pts], ms=4, lw=1.2, **style)
            ax.set_xlabel("time step dt (s)")
            ax.set_title(precision)
            ax.grid(True, which="major", alpha=0.3)
            ax.invert_xaxis()
        axes[0][0].set_ylabel("global position error at t_end (m)")
        # below the panels: inside, it covered the first-order curves at small dt
        handles, labels = axes[0][0].get_legend_handles_labels()
        fig.legend(handles, labels, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=4,
                   title="fitted slope (float64)", title_fontsize=7, frameon=False)
        fig.suptitle(f"Global error against time step: {curves[0]['title']}\n"
                     "truncation error falls as dt^order; accumulated round-off rises at small dt", y=1.0)
        fig.tight_layout()
        figures += plotting.save_figure(fig, out, f"truncation_{name}")
    return figures


def summary(record: dict) -> list[tuple[str, str]]:
    rows = [("lecture misprints found", str(len(record["misprints"])))]
    for t in record["lecture_table"]:
        rows.append((f"one Euler step, dt = {t['dt']:g} s: z error", f"{t['error']:.4g} m"))
    for problem, fits in record["orders"].items():
        text = ", ".join(f"{m} {s:.2f}" for m, s in fits.items() if s is not None)
        rows.append((f"fitted orders, {problem}", text or "all exact to round-off"))
    return rows


# --- the paper's tables -------------------------------------------------------------


def orders_table(data: dict) -> str:
    """Fitted order of each integrator on each problem, beside its declared order."""
    problems = list(data["orders"])
    header = ["integrator", "declared"] + problems
    rows = [[m, str(data["declared"][m])] + [format_value(data["orders"][p].get(m), ".2f") for p in problems]
            for m in data["declared"]]
    return markdown_table(header, rows) + "\n\n(\"none\": the method is exact for that problem, " \
                                          "its error is round-off.)"


def misprints_table(data: list[dict]) -> str:
    rows = [[m["where"], m["printed"], format_value(m["computed"], "g"), m["note"]] for m in data]
    return markdown_table(["where", "printed", "computed", "why"], rows)


def least_error_table(data: dict) -> str:
    """The least error each method reaches, and at which dt, in float64 and float32."""
    columns = [(problem, precision) for problem in data for precision in ("float64", "float32")]
    methods = list(next(iter(data.values())))

    def cell(problem, method, precision):
        p = data[problem][method].get(precision)
        if p is None:
            return "-"
        return f"{p['error']:.0e} at {p['dt']:.0e}" + ("" if p["floor_reached"] else "*")

    rows = [[m] + [cell(problem, m, precision) for problem, precision in columns] for m in methods]
    return markdown_table(["integrator"] + [f"{problem}, {precision}" for problem, precision in columns], rows) + \
        "\n\n(least error in m, at dt in s; *: still falling at the smallest dt tried, the floor is further down.)"


#: the problems whose least error the paper shows
PAPER_LEAST_ERROR = ("oscillator", "drag-projectile")

TABLES = (
    Table("orders", lambda r: {"orders": r["orders"], "declared": r["declared_orders"]}, orders_table),
    Table("misprints", lambda r: r["misprints"], misprints_table),
    Table("least_error", lambda r: {p: r["least_error"][p] for p in PAPER_LEAST_ERROR if p in r["least_error"]},
          least_error_table),
)


STUDY = Study("truncation", "Truncation error: the lecture's tables, global error against dt, round-off",
              parameters, compute, plot, summary, tables=TABLES,
              tasks=tasks, task=task, reduce=reduce)
