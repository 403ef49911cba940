"""Stability study: the largest stable omega dt of every integrator, measured and derived.

Measured: on the oscillator x'' = -omega^2 x - 2 zeta omega x', by bisection on long runs
of the real integrator (a run is unstable when the growth per step of its measured
LONG_RUN_STEPS-step map exceeds GROWTH_TOLERANCE). Methods whose one-step amplification
exceeds 1 at even the smallest omega dt are recorded as 0 (unstable for every dt > 0);
methods stable at omega dt = OMEGA_DT_MAX as null (no limit found).

Derived: the largest y = omega dt with spectral radius <= 1 of each method's one-step
map on the scalar test equation: |R(y mu)| <= 1 with mu = -zeta + i sqrt(1 - zeta^2) for
Runge-Kutta methods (R from their Butcher tableau), and the 2x2 / 3x3 recurrence matrix
for the partitioned methods (semi-implicit Euler, velocity and position Verlet).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from integrators import INTEGRATORS, ExplicitRungeKutta, Stepper
from integrators.simulate import final_state_function

from . import plotting
from .problems import oscillator_problem
from .runner import Study

#: steps of one stability run; the largest growth per step (log of the spectral radius of
#: the measured N-step map, over N) that still counts as stable; the probe deviation, m
LONG_RUN_STEPS = 20_000
GROWTH_TOLERANCE = 1e-9
PROBE = 1e-6
#: search interval of omega dt, and the bisection's relative tolerance
OMEGA_DT_MIN, OMEGA_DT_MAX = 1e-3, 100.0
BISECTION_RTOL = 1e-6
#: a one-step spectral radius above 1 + this at omega dt = OMEGA_DT_MIN is growth, not round-off
AMPLIFICATION_TOLERANCE = 1e-14
THEORY_TOLERANCE = 1e-14


def parameters(quick: bool) -> dict:
    steppers = [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)]
    return {"integrators": steppers, "damping_ratios": [0.0, 0.1],
            "long_run_steps": LONG_RUN_STEPS // 4 if quick else LONG_RUN_STEPS,
            "energy_steps": 10_000 if quick else 1_000_000, "energy_omega_dt": 0.1}


# --- theory -------------------------------------------------------------------------


def _partitioned_map(method: str, y: float, zeta: float) -> np.ndarray:
    """One-step matrix of a partitioned method on u'' = -u - 2 zeta u' (omega = 1, h = y).

    Written out from each method's definition (integrators/*.py docstrings), acting on
    (u, v), or (u, v, carry) for the Verlet methods, which keep an acceleration between
    steps: velocity Verlet its last evaluation (at the predicted velocity), position
    Verlet the one it estimates the half-step velocity from.
    """
    h = y

    def acc(u, v):
        return -u - 2 * zeta * v

    columns = []
    size = 3 if method in ("velocity-verlet", "position-verlet") else 2
    for basis in np.eye(size):
        u, v = basis[0], basis[1]
        if method == "semi-implicit-euler":
            v1 = v + h * acc(u, v)
            columns.append([u + h * v1, v1])
        elif method == "velocity-verlet":
            a0 = basis[2]
            u1 = u + h * v + h * h / 2 * a0
            a1 = acc(u1, v + h * a0)
            columns.append([u1, v + h / 2 * (a0 + a1), a1])
        else:  # position-verlet: drift, kick with the half-step velocity estimated from a_prev
            u_half = u + h / 2 * v
            a = acc(u_half, v + h / 2 * basis[2])
            v1 = v + h * a
            columns.append([u_half + h / 2 * v1, v1, a])
    return np.array(columns).T


def spectral_radius(method: str, y: float, zeta: float) -> float:
    """Largest |growth factor| per step at omega dt = y (from the method's definition)."""
    mu = complex(-zeta, np.sqrt(1 - zeta**2))
    integrator = INTEGRATORS[method]
    if isinstance(integrator, ExplicitRungeKutta):
        return abs(integrator.tableau.stability_function(y * mu))
    if method == "euler":
        return abs(1 + y * mu)
    if method == "implicit-euler":
        return abs(1 / (1 - y * mu))
    return float(np.max(np.abs(np.linalg.eigvals(_partitioned_map(method, y, zeta)))))


def theoretical_limit(method: str, zeta: float) -> float | None:
    """Largest omega dt with spectral radius <= 1: 0 if none, None if unbounded."""
    ys = np.geomspace(OMEGA_DT_MIN, OMEGA_DT_MAX, 4000)
    # |eigenvalue| = 1 exactly on the stable range of a symplectic method: allow round-off
    excess = lambda y: spectral_radius(method, y, zeta) - 1 - THEORY_TOLERANCE  # noqa: E731
    stable = np.array([excess(y) <= 0 for y in ys])
    if not stable[0]:
        return 0.0
    if stable.all():
        return None
    k = int(np.argmin(stable))  # first unstable grid point
    return float(brentq(excess, ys[k - 1], ys[k], xtol=1e-14))


CLOSED_FORMS = {
    "euler": "0 undamped (|1 + i y| > 1); 2 zeta damped",
    "semi-implicit-euler": "2 undamped; 2 sqrt(1 + zeta^2) - 2 zeta damped",
    "velocity-verlet": "2 undamped (trace 2 - y^2, det 1)",
    "position-verlet": "2 undamped",
    "heun": "0 undamped (|R(i y)|^2 = 1 + y^4 / 4)",
    "midpoint": "0 undamped (same R as Heun)",
    "rk4": "2 sqrt(2) = 2.8284 undamped",
    "implicit-euler": "none: |1 / (1 - z)| <= 1 on the whole left half-plane (A-stable)",
}


# --- measurement --------------------------------------------------------------------


def measured_limit(method: str, zeta: float, steps: int) -> dict:
    """Largest stable omega dt by bisection on long runs of the real integrator.

    Each test runs ``steps`` steps from two small deviations from rest (position, and
    velocity / omega, of size PROBE), which gives the empirical ``steps``-step map M_N
    of the linearised dynamics; the run is stable when its growth per step,
    log(spectral radius of M_N) / steps, is at most GROWTH_TOLERANCE. The probes are
    small enough that a 10^5-fold growth stays linear.
    """
    import jax.numpy as jnp

    problem = oscillator_problem(zeta)
    run = final_state_function(problem.model.cast(jnp), method)
    starts = []
    for u, v in ((PROBE, 0.0), (0.0, PROBE)):
        y0 = np.zeros_like(problem.y0)
        y0[0, 1, 0], y0[1, 1, 0] = 1.0 + u, v * problem.omega
        starts.append(jnp.asarray(y0))

    def stable(y: float) -> bool:
        dt = y / problem.omega
        columns = []
        for y0 in starts:
            final, bad = run(y0, 0.0, dt, steps)
            if int(bad) >= 0:
                return False
            columns.append([float(final[0, 1, 0]) - 1.0, float(final[1, 1, 0]) / problem.omega])
        radius = np.max(np.abs(np.linalg.eigvals(np.array(columns).T / PROBE)))
        return bool(np.isfinite(radius) and np.log(max(radius, 1e-300)) / steps <= GROWTH_TOLERANCE)

    growth = _one_step_growth(problem, method, OMEGA_DT_MIN)
    if growth > 1 + AMPLIFICATION_TOLERANCE:
        return {"omega_dt_max": 0.0, "growth_per_step_at_min": growth}
    if stable(OMEGA_DT_MAX):
        return {"omega_dt_max": None}
    lo, hi = OMEGA_DT_MIN, OMEGA_DT_MAX
    if not stable(lo):
        return {"omega_dt_max": 0.0}
    while hi - lo > BISECTION_RTOL * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return {"omega_dt_max": lo, "bracket": [lo, hi]}


def _one_step_growth(problem, method: str, y: float) -> float:
    """Spectral radius of one real step of the integrator on (deviation, velocity / omega)."""
    integrator = INTEGRATORS[method]
    dt = y / problem.omega
    columns = []
    for u, v in ((1.0, 0.0), (0.0, 1.0)):
        state = problem.y0.copy()
        state[0, 1, 0], state[1, 1, 0] = 1.0 + u, v * problem.omega
        carry = integrator.init(problem.model, 0.0, state)
        new, _ = integrator.step(problem.model, 0.0, state, dt, carry)
        columns.append([new[0, 1, 0] - 1.0, new[1, 1, 0] / problem.omega])
    return float(np.max(np.abs(np.linalg.eigvals(np.array(columns).T))))


def energy_history(method: str, steps: int, omega_dt: float) -> dict:
    """Relative energy error of the undamped oscillator at log-spaced times over ``steps`` steps."""
    from integrators import DivergenceError, simulate

    problem = oscillator_problem(0.0)
    dt = omega_dt / problem.omega
    save_every = max(1, steps // 200)
    diverged = None
    try:
        traj = simulate(problem.model, method, problem.y0, 0.0, steps * dt, dt, backend="jax",
                        save_every=save_every)
    except DivergenceError as err:  # show the growth up to the step before divergence
        diverged = err.step
        traj = simulate(problem.model, method, problem.y0, 0.0, (err.step - 1) * dt, dt, backend="jax",
                        save_every=max(1, (err.step - 1) // 200))
    e0 = float(problem.model.energy(problem.y0))
    errors = [abs(float(problem.model.energy(y)) - e0) / e0 for y in traj.y[1:]]
    return {"integrator": method, "t": traj.t[1:].tolist(), "relative_energy_error": errors,
            "max_relative_energy_error": max(errors), "diverged_at_step": diverged}


def compute(params: dict, progress=None) -> dict:
    measured, theory = {}, {}
    for zeta in params["damping_ratios"]:
        key = f"{zeta:g}"
        measured[key], theory[key] = {}, {}
        for method in params["integrators"]:
            measured[key][method] = measured_limit(method, zeta, params["long_run_steps"])
            theory[key][method] = theoretical_limit(method, zeta)
            if progress is not None:
                progress()
    energy = [energy_history(m, params["energy_steps"], params["energy_omega_dt"]) for m in params["integrators"]]
    undamped = f"{params['damping_ratios'][0]:g}"
    return {
        "omega_dt_max": {m: r["omega_dt_max"] for m, r in measured[undamped].items()},
        "theory": theory[undamped],
        "by_damping_ratio": {z: {"measured": {m: r["omega_dt_max"] for m, r in measured[z].items()},
                                 "theory": theory[z], "details": measured[z]} for z in measured},
        "closed_forms": CLOSED_FORMS,
        "energy": energy,
    }


# --- figures ------------------------------------------------------------------------


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    figures = []

    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    x, y = np.meshgrid(np.linspace(-4.5, 2.5, 560), np.linspace(-3.5, 3.5, 560))
    z = x + 1j * y  # the grid avoids z = 1, the pole of implicit Euler's R
    regions = {"euler": np.abs(1 + z), "heun / midpoint": np.abs(INTEGRATORS["heun"].tableau.stability_function(z)),
               "rk4": np.abs(INTEGRATORS["rk4"].tableau.stability_function(z)),
               "implicit-euler": np.abs(1 / (1 - z))}
    colours = {"euler": "tab:red", "heun / midpoint": "tab:purple", "rk4": "tab:blue",
               "implicit-euler": "tab:brown"}
    for name, r in regions.items():
        implicit = name == "implicit-euler"
        if not implicit:  # implicit Euler is stable *outside* its circle: shading would cover the plot
            ax.contourf(x, y, r, levels=[0, 1], colors=[colours[name]], alpha=0.12)
        ax.contour(x, y, r, levels=[1], colors=[colours[name]], linewidths=1.5)
        label = f"|R(z)| = 1: {name}" + (" (stable outside)" if implicit else "")
        ax.plot([], [], color=colours[name], lw=2, label=label)
    # measured thresholds: on the imaginary axis (undamped) and on the damped ray
    for zeta, result in record["by_damping_ratio"].items():
        mu = complex(-float(zeta), np.sqrt(1 - float(zeta) ** 2))
        for method, value in result["measured"].items():
            if value is None or value == 0:
                continue
            point = value * mu
            style = plotting.style(method)
            ax.plot(point.real, point.imag, linestyle="none", ms=8, mfc="none", mew=1.5,
                    color=style["color"], marker=style["marker"],
                    label=f"measured {method}" if zeta == "0" else None)
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
    ax.legend(fontsize=7, loc="lower left", ncol=2)
    figures += plotting.save_figure(fig, out, "stability_regions")

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for e in record["energy"]:
        style = plotting.style(e["integrator"])
        if e["diverged_at_step"]:
            style["label"] += f" (diverges at step {e['diverged_at_step']})"
        ax.loglog(e["t"], np.maximum(e["relative_energy_error"], 1e-17), lw=1.2, ms=0, **style)
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("relative energy error |E(t) - E(0)| / E(0)")
    ax.set_title("Energy over long runs: harmonic oscillator, omega dt = 0.1\n"
                 "symplectic methods stay bounded; explicit Euler grows; RK4 and implicit Euler dissipate")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    figures += plotting.save_figure(fig, out, "stability_energy")
    return figures


def summary(record: dict) -> list[tuple[str, str]]:
    rows = []
    for method, value in record["omega_dt_max"].items():
        theory = record["theory"][method]
        text = "no limit found" if value is None else f"{value:.4f}"
        text += f" (theory {'none' if theory is None else f'{theory:.4f}'})"
        rows.append((f"largest stable omega dt, {method}", text))
    return rows


STUDY = Study("stability", "Stability: largest stable omega dt, stability regions, long-run energy",
              parameters, compute, plot, summary)
