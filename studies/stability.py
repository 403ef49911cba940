"""Stability study: how large a step each integrator survives, and what it costs near the edge.

* Limits on the oscillator: the largest stable omega dt of every method, undamped and
  damped, measured on long runs (studies/stability_limits.py) and stated by the method
  itself (``Stepper.stability_limit``, from its stability function or its own step),
  drawn on the stability regions |R(z)| <= 1 of the methods that have an R.
* Energy over long runs (10^6 steps) on the oscillator and a Kepler orbit.
* Stiff springs: the largest stable dt against the stiffness of the soft body, and the
  numerical damping implicit Euler pays for being stable at any dt (studies/stiffness.py).
* The extremes: huge dt, positions far from the origin in float32 and float64, mass
  ratios up to 10^6 across a spring (studies/extremes.py).
"""

from __future__ import annotations

import numpy as np
from steplab.integrators import INTEGRATORS, Stepper, get_integrator

from . import extremes, plotting, stiffness
from .problems import kepler_problem, oscillator_problem
from .runner import Study, run_tasks
from .stability_limits import GROWTH_TOLERANCE, LONG_RUN_STEPS, measured_limit, oscillator_mode
from .system import is_system
from .tables import Table, format_value, markdown_table

#: energy runs up to this many steps use the NumPy backend; windows of an energy envelope
SHORT_RUN_STEPS = 10_000
ENVELOPE_WINDOWS = 200
#: points of the complex plane on which two stability functions are compared: equal
#: there (to round-off) means one region for both; R is a polynomial or a rational
#: function of low degree, so a handful of generic points decide it
SAME_REGION_PROBES = (0.3 + 0.1j, -1.1 + 0.7j, -2.3 - 1.9j, 0.05 - 2.9j, -3.7 + 0.2j, 1.7 + 2.3j, -0.6 - 0.4j)
SAME_REGION_RTOL = 1e-12


def parameters(quick: bool) -> dict:
    steppers = [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    return {"integrators": steppers, "damping_ratios": [0.0] if quick else [0.0, 0.1],
            "long_run_steps": LONG_RUN_STEPS // 4 if quick else LONG_RUN_STEPS,
            # quick: the orbit at a coarser dt, so that its 2000 steps still span 20 periods
            "energy_steps": 2_000 if quick else 1_000_000, "energy_omega_dt": 0.1,
            "kepler_dt": 1e-2 if quick else 1e-3,
            # the sweeps below measure a limit per point: a first look sweeps the game default only
            "sweep_integrators": ["semi-implicit-euler"] if quick else steppers,
            # stiff springs (studies/stiffness.py)
            # quick: four stiffnesses still show the k^(-1/2) line the slope is fitted to
            "stiffnesses": np.geomspace(10, 1e4, 4).tolist() if quick else np.geomspace(10, 1e5, 5).tolist(),
            "stiffness_steps": 1000 if quick else 5000, "stiffness_rtol": 1e-2 if quick else 1e-4,
            "damping_omega_dts": np.geomspace(1e-3, 100, 6 if quick else 21).tolist(),
            # a cloth large enough for implicit Euler's sparse Newton solve (above 200 bodies)
            "scale_side": 15 if quick else 40, "scale_steps": 50 if quick else 200, "scale_seed": 1,
            # the extremes (studies/extremes.py)
            "huge_omega_dts": [3.0, 10.0, 100.0], "huge_max_steps": 1000,
            "precisions": ["float64", "float32"], "far_offsets": 9 if quick else 17,
            "far_speeds": [1e-3, 1e-2, 1e-1, 1.0], "coasting_steps": 60, "jitter_periods": 5,
            "mass_ratios": np.geomspace(1, 1e6, 4).tolist() if quick else np.geomspace(1, 1e6, 7).tolist(),
            "mass_ratio_steps": 1000 if quick else 5000, "mass_ratio_rtol": 1e-2 if quick else 1e-4}


def energy_history(problem, method: str, steps: int, dt: float) -> dict:
    """Relative energy error |E(t) - E(0)| / |E(0)| over ``steps`` steps, as an envelope.

    The energy is evaluated after every step; the record keeps the largest error in each
    of about ENVELOPE_WINDOWS log-spaced windows of steps (and the time each window ends),
    so a log-time plot shows the first period and the last alike, and a symplectic
    method's band is drawn whole (a sample every so many steps would alias with the
    orbit). A run that diverges (or, for implicit Euler on the orbit, whose Newton
    iteration fails once numerical damping has spiralled the body into the singular
    centre) is shown up to the step before, and the step is recorded. ``method`` is a
    steplab integrator's name or a system under test (:mod:`.system`).
    """
    energy, diverged = _energy_after_every_step(problem, method, steps, dt)
    name = method.name if is_system(method) else method
    errors = np.abs(energy[1:] - energy[0]) / abs(energy[0])
    starts = np.unique(np.round(np.geomspace(1, len(errors), ENVELOPE_WINDOWS)).astype(int)) - 1
    ends = np.append(starts[1:], len(errors))  # step number at the end of each window
    return {"integrator": name, "t": (ends * dt).tolist(),  # time since the start
            "relative_energy_error": np.maximum.reduceat(errors, starts).tolist(),
            "max_relative_energy_error": float(errors.max()), "final_relative_energy_error": float(errors[-1]),
            "diverged_at_step": diverged}


def _energy_after_every_step(problem, method: str, steps: int, dt: float) -> tuple[np.ndarray, int | None]:
    """E(y_0), ..., E(y_n) and the first diverged step (None): n = steps, or the step before divergence.

    Short runs step in NumPy (compiling costs about as much as 10^4 NumPy steps); long
    ones are one compiled scan that returns only the energies, never the states.
    """
    if is_system(method):
        return _system_energy(problem, method, steps, dt)
    integrator = INTEGRATORS[method]
    if steps <= SHORT_RUN_STEPS:
        from steplab.integrators import DivergenceError, simulate

        try:
            traj, diverged = simulate(problem.model, method, problem.y0, 0.0, dt=dt, n_steps=steps), None
        except DivergenceError as err:
            diverged = err.step
            traj = simulate(problem.model, method, problem.y0, 0.0, dt=dt, n_steps=err.step - 1)
        return np.array([float(problem.model.energy(y)) for y in traj.y]), diverged

    import jax
    import jax.numpy as jnp
    from steplab.integrators.loop import fixed_step_loop
    from steplab.integrators.simulate import divergence_limit

    model = problem.model.cast(jnp)
    # after every step, only the energy is kept; once diverged the loop stops stepping
    loop = fixed_step_loop(model, integrator, chunks=steps, observe=model.energy, halt=True)
    limit = divergence_limit(problem.y0, np.float64)
    y0 = jnp.asarray(problem.y0)
    energy, bad = jax.jit(lambda y0: loop(y0, 0.0, dt, steps, limit))(y0)  # dt a constant, as recorded
    energy, bad = np.concatenate([[float(jax.jit(model.energy)(y0))], np.asarray(energy)]), int(bad)
    if bad < 0:
        return energy, None
    return energy[:bad], bad


def _system_energy(problem, system, steps: int, dt: float) -> tuple[np.ndarray, int | None]:
    """E(y_0), ..., E(y_n) of a system under test (:mod:`.system`), and the first diverged step."""
    import jax
    import jax.numpy as jnp
    from steplab.integrators import DivergenceError

    run = system.build(problem.model, None, dt, problem.y0)
    try:
        traj, diverged = run.advance(problem.y0, dt, steps), None
    except DivergenceError as err:
        diverged = err.step
        traj = run.advance(problem.y0, dt, err.step - 1) if err.step > 1 else None
    states = problem.y0[None] if traj is None else traj.y
    energy = jax.jit(jax.vmap(problem.model.cast(jnp).energy))(jnp.asarray(states))
    return np.asarray(energy, dtype=float), diverged


def tasks(params: dict) -> list[list]:
    """The sweep's independent runs: each limit, energy history, stiffness and mass-ratio point,
    the damping sweep, and the extremes' other three sweeps."""
    methods, sweep = params["integrators"], params["sweep_integrators"]
    return ([["limit", zeta, m] for zeta in params["damping_ratios"] for m in methods]
            + [["energy", problem, m] for problem in ("oscillator", "kepler") for m in methods]
            + [["stiffness", k, m] for k in params["stiffnesses"] for m in sweep] + [["damping"], ["at_scale"]]
            + [["huge_dt"], ["coasting"], ["jitter"]]
            + [["mass_ratio", ratio, m] for ratio in params["mass_ratios"] for m in sweep])


def task(params: dict, item: list):
    """One run of :func:`tasks`."""
    kind = item[0]
    if kind == "limit":
        return measured_limit(oscillator_mode(item[1]), item[2], params["long_run_steps"])
    if kind == "energy":
        if item[1] == "oscillator":
            problem = oscillator_problem(0.0)
            return energy_history(problem, item[2], params["energy_steps"], params["energy_omega_dt"] / problem.omega)
        return energy_history(kepler_problem(), item[2], params["energy_steps"], params["kepler_dt"])
    if kind == "stiffness":
        return stiffness.stiffness_row(item[1], item[2], params["stiffness_steps"], params["stiffness_rtol"])
    if kind == "damping":
        return stiffness.implicit_euler_damping(params["damping_omega_dts"])
    if kind == "at_scale":
        return stiffness.implicit_euler_at_scale(params["scale_side"], stiffness.DAMPING_STIFFNESS,
                                                 params["scale_steps"], params["scale_seed"])
    if kind == "huge_dt":
        return extremes.huge_dt(params["integrators"], params["huge_omega_dts"], params["huge_max_steps"])
    if kind == "coasting":
        return extremes.coasting(extremes.far_offsets(params), params["far_speeds"], params["precisions"],
                                 params["coasting_steps"])
    if kind == "jitter":
        return extremes.oscillator_jitter(extremes.far_offsets(params), params["precisions"], params["jitter_periods"])
    return extremes.mass_ratio_row(item[1], item[2], params["mass_ratio_steps"], params["mass_ratio_rtol"])


def reduce(params: dict, results: list) -> dict:
    """The record from the runs of :func:`tasks`, in their order."""
    by_kind = {}
    for item, result in zip(tasks(params), results):
        by_kind.setdefault(item[0], []).append((item, result))
    measured, theory = {}, {}
    for (_, zeta, method), result in by_kind["limit"]:
        key = f"{zeta:g}"
        measured.setdefault(key, {})[method] = result
        theory.setdefault(key, {})[method] = get_integrator(method).stability_limit(zeta)
    energy = {problem: [result for (_, name, _), result in by_kind["energy"] if name == problem]
              for problem in ("oscillator", "kepler")}
    undamped = f"{params['damping_ratios'][0]:g}"
    stiff = stiffness.stiffness_sweep([result for _, result in by_kind["stiffness"]], params["sweep_integrators"])
    stiff["implicit_euler_damping"] = by_kind["damping"][0][1]
    stiff["implicit_euler_at_scale"] = by_kind["at_scale"][0][1]
    [[_, huge]], [[_, coast]], [[_, jitter]] = by_kind["huge_dt"], by_kind["coasting"], by_kind["jitter"]
    return {
        "growth_tolerance": GROWTH_TOLERANCE,
        "omega_dt_max": {m: r["omega_dt_max"] for m, r in measured[undamped].items()},
        "theory": theory[undamped],
        "by_damping_ratio": {z: {"measured": {m: r["omega_dt_max"] for m, r in measured[z].items()},
                                 "theory": theory[z], "details": measured[z]} for z in measured},
        "closed_forms": {m: get_integrator(m).stability_note for m in params["integrators"]},
        "energy": energy,
        "stiff_springs": stiff,
        "extremes": extremes.assemble(params, huge, coast, jitter, [result for _, result in by_kind["mass_ratio"]]),
    }


def compute(params: dict, progress=None) -> dict:
    """Every task in turn, then the reduction (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


# --- figures ------------------------------------------------------------------------


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    figures = []

    fig, ax = plt.subplots(figsize=(10, 6.5))
    x, y = np.meshgrid(np.linspace(-4.5, 2.5, 400), np.linspace(-3.5, 3.5, 400))
    z = x + 1j * y  # the grid avoids z = 1, the pole of implicit Euler's R
    for methods in stability_regions(record["parameters"]["integrators"]):
        first = get_integrator(methods[0])
        name, colour = " / ".join(methods), plotting.style(methods[0])["color"]
        r = np.abs(first.stability_function(z))
        # a stable region that holds z -> -infinity (implicit methods) lies outside its curve
        outside = bool(abs(first.stability_function(-1e6)) <= 1)
        if not outside:  # shading the outside would cover the plot
            ax.contourf(x, y, r, levels=[0, 1], colors=[colour], alpha=0.12)
        ax.contour(x, y, r, levels=[1], colors=[colour], linewidths=1.5)
        label = f"|R(z)| = 1: {name}" + (" (stable outside)" if outside else "")
        ax.plot([], [], color=colour, lw=2, label=label)
    # measured thresholds: on the imaginary axis (undamped) and on the damped ray; each method
    # named once, where it first appears (a method unstable undamped has only its damped marker)
    named = set()
    for zeta, result in record["by_damping_ratio"].items():
        mu = complex(-float(zeta), np.sqrt(1 - float(zeta) ** 2))
        for method, value in result["measured"].items():
            if value is None or value == 0:
                continue
            point = value * mu
            style = plotting.style(method)
            ax.plot(point.real, point.imag, linestyle="none", ms=8, mfc="none", mew=1.5,
                    color=style["color"], marker=style["marker"],
                    label=None if method in named else f"measured {method}")
            named.add(method)
    ax.axhline(0, color="k", lw=0.5)
    ax.axvline(0, color="k", lw=0.5)
    for zeta in record["by_damping_ratio"]:
        if zeta != "0":
            mu = complex(-float(zeta), np.sqrt(1 - float(zeta) ** 2))
            ax.plot([0, 3.4 * mu.real], [0, 3.4 * mu.imag], "k:", lw=0.8, label=f"damped ray, zeta = {zeta}")
    ax.set_xlabel("Re z = Re(lambda) dt")
    ax.set_ylabel("Im z = Im(lambda) dt")
    ax.set_aspect("equal")
    ax.set_xlim(-4.5, 2.5)
    ax.set_ylim(-3.5, 3.5)
    ax.set_title("Stability regions |R(z)| <= 1 (shaded) and measured limits\n"
                 "markers: largest stable omega dt on the oscillator, undamped (imaginary axis) and damped")
    # beside the axes: inside, it covered RK4's contour
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0)
    figures += plotting.save_figure(fig, out, "stability_regions")

    fig, axes = plt.subplots(1, 2, figsize=(13, 5), sharey=True)
    params = record["parameters"]
    titles = {"oscillator": f"harmonic oscillator, omega dt = {params['energy_omega_dt']:g}",
              "kepler": f"Kepler orbit (e = 0.5, period 1 s), dt = {params['kepler_dt']:g} s"}
    for ax, (problem, runs) in zip(axes, record["energy"].items()):
        for e in runs:
            style = plotting.style(e["integrator"])
            if e["diverged_at_step"]:
                style["label"] += f" (stops at step {e['diverged_at_step']})"
            ax.loglog(e["t"], np.maximum(e["relative_energy_error"], 1e-17), lw=1.2, ms=0, **style)
        ax.set_xlabel("time t (s)")
        ax.set_title(f"{titles[problem]}, {params['energy_steps']:,} steps", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("relative energy error |E(t) - E(0)| / |E(0)|\n(largest in each window of steps)")
    fig.suptitle("Energy over long runs: symplectic methods stay bounded, explicit Euler grows, "
                 "RK4 and implicit Euler dissipate")
    figures += plotting.save_figure(fig, out, "stability_energy")
    figures += stiffness.plot(record["stiff_springs"], out)
    figures += extremes.plot(record["extremes"], out)
    return figures


def stability_regions(methods) -> list[list[str]]:
    """The methods that have a stability function R(z), grouped by R (one region each).

    Two methods share a region when their R agree at SAME_REGION_PROBES (Heun and the
    midpoint method: both 1 + z + z^2 / 2); the groups keep the order of ``methods``.
    """
    groups: list[tuple[np.ndarray, list[str]]] = []
    for name in methods:
        method = get_integrator(name)
        if getattr(method, "stability_function", None) is None:
            continue
        values = np.asarray(method.stability_function(np.array(SAME_REGION_PROBES)), dtype=complex)
        for probe_values, names in groups:
            if np.allclose(values, probe_values, rtol=SAME_REGION_RTOL, atol=0):
                names.append(name)
                break
        else:
            groups.append((values, [name]))
    return [names for _, names in groups]


def summary(record: dict) -> list[tuple[str, str]]:
    rows = []
    for method, value in record["omega_dt_max"].items():
        theory = record["theory"][method]
        text = "no limit found" if value is None else f"{value:.4f}"
        text += f" (theory {'none' if theory is None else f'{theory:.4f}'})"
        rows.append((f"largest stable omega dt, {method}", text))
    for problem, runs in record["energy"].items():
        worst = max(runs, key=lambda e: e["final_relative_energy_error"])
        best = min(runs, key=lambda e: e["final_relative_energy_error"])
        rows.append((f"final energy error, {problem}",
                     f"{best['integrator']} {best['final_relative_energy_error']:.1e} ... "
                     f"{worst['integrator']} {worst['final_relative_energy_error']:.1e}"))
    slopes = record["stiff_springs"]["slopes"]
    rows.append(("slope of largest stable dt against k", ", ".join(f"{m} {v:.3f}" for m, v in slopes.items())))
    scale = record["stiff_springs"]["implicit_euler_at_scale"]
    for run in scale["runs"]:
        outcome = (f"diverged at step {run['diverged_at_step']}" if run["diverged_at_step"] else
                   f"largest energy {run['largest_energy']:.3g}, last {run['final_energy']:.2g} of the first")
        rows.append((f"cloth of {scale['bodies']:,}, {run['integrator']} at {run['dt_over_limit']:g} x 2/omega_max",
                     outcome))
    far = record["extremes"]["far_from_origin"]
    for speed, offset in far["first_stall"].get("float32", {}).items():
        rows.append((f"float32 body at {speed} m/s stalls from", "never (to 1e7 m)" if offset is None else
                     f"{offset:.3g} m (rounding model: {far['stall_edge']['float32'][speed]:.4g} m)"))
    return rows


# --- the paper's tables -------------------------------------------------------------


def stability_table(data: dict) -> str:
    """Largest stable omega dt of each method, measured and theory, per damping ratio."""
    zetas = list(data)
    header = ["integrator"] + [f"{kind}, zeta = {z}" for z in zetas for kind in ("measured", "theory")]
    methods = list(data[zetas[0]]["measured"])
    rows = [[m] + [format_value(data[z][kind][m], ".4f") for z in zetas for kind in ("measured", "theory")]
            for m in methods]
    return markdown_table(header, rows) + "\n\n(0: unstable for every dt > 0; none: no limit found.)"


TABLES = (
    Table("stability", lambda r: {z: {k: v[k] for k in ("measured", "theory")}
                                  for z, v in r["by_damping_ratio"].items()}, stability_table),
) + tuple(table.within("extremes") for table in extremes.TABLES)


STUDY = Study("stability", "Stability: largest stable omega dt, stability regions, long-run energy",
              parameters, compute, plot, summary, tables=TABLES,
              tasks=tasks, task=task, reduce=reduce)
