"""Stiff springs: how the largest stable dt shrinks with the stiffness, and what implicit Euler pays.

Part of the stability study. On the lecture's soft body (a cube of 8 particles with a
spring between every pair), an explicit method is stable while omega_max dt stays
under its limit on the oscillator, where omega_max is the highest natural frequency of
the spring network; omega_max grows as sqrt(k), so the largest stable dt falls as
k^(-1/2). The largest stable dt is measured per method and stiffness on the stiffest
mode (stability.stiffest_mode) by the same bisection on long runs as the oscillator.

Implicit Euler is stable at every dt, and pays in amplitude: its growth factor per step
on an undamped mode is |R(i y)| = 1 / sqrt(1 + y^2), y = omega dt, so a period
(2 pi / y steps) keeps (1 + y^2)^(-pi / y) of the amplitude. That loss is measured on the
same soft body mode, from the growth per step of the measured N-step map.

At scale: on a cloth of 1,600 particles (:func:`implicit_euler_at_scale`), where implicit
Euler's Newton steps are solved by conjugate gradients on the sparse Jacobian, semi-implicit
Euler holds just below 2 / omega_max and blows up just above it, while implicit Euler runs
at 10 and 100 times that step, its energy never above the start's.
"""

from __future__ import annotations

import numpy as np
from steplab.integrators import get_integrator
from steplab.physics import Model, soft_body

from . import plotting
from .stability_limits import growth_function, stable_dt, stiffest_mode, worst_deviation

#: the soft body: a 1 m cube of 8 particles of 1 kg, all pairs connected, one corner pinned
CUBE_MASS, PINNED_CORNER = 1.0, 7
#: the stiffness the amplitude loss of implicit Euler is measured at, N/m
DAMPING_STIFFNESS = 2000.0
#: the method whose numerical damping is measured: stable at every dt
DAMPING_METHOD = "implicit-euler"
#: the at-scale part: particle mass, kg; the random start's displacement, in spacings; the dts,
#: in units of semi-implicit Euler's limit 2 / omega_max, of the explicit and the implicit runs
SCALE_MASS, SCALE_DISPLACEMENT = 1e-3, 1e-2
EXPLICIT_FACTORS, IMPLICIT_FACTORS = (0.9, 1.1), (10.0, 100.0)


def soft_cube(stiffness: float) -> tuple[Model, np.ndarray]:
    """The lecture's all-pairs soft cube without gravity or dampers, and its rest positions."""
    mesh = soft_body.box()
    springs, _ = soft_body.connect(mesh.vertices, soft_body.all_pairs(8), stiffness, 0.0)
    pinned = np.zeros(8, bool)
    pinned[PINNED_CORNER] = True
    return Model(np.full(8, CUBE_MASS), np.full(8, 0.05), [springs], pinned=pinned), mesh.vertices


def stable_dt_against_stiffness(methods, stiffnesses, steps: int, rtol: float, progress=None) -> dict:
    """Largest stable dt of each method at each stiffness, measured and from theory."""
    rows = []
    for k in stiffnesses:
        for method in methods:
            rows.append(stiffness_row(k, method, steps, rtol))
            if progress is not None:
                progress()
    return stiffness_sweep(rows, methods)


def stiffness_row(k: float, method, steps: int, rtol: float) -> dict:
    """One point of the sweep: the largest stable dt of ``method`` on the soft cube of stiffness ``k``."""
    model, vertices = soft_cube(k)
    return {"stiffness": k, "integrator": method} | stable_dt(stiffest_mode(model, vertices), method, steps, rtol)


def stiffness_sweep(rows: list[dict], methods) -> dict:
    """The sweep from its rows: each method's fitted slope of log dt_max against log k, the worst deviation."""
    slopes = {}
    for method in methods:
        pts = [(r["stiffness"], r["dt_max"]) for r in rows if r["integrator"] == method and r["dt_max"]]
        if len(pts) >= 2:
            k, dt = np.log(np.array(pts)).T
            slopes[method] = float(np.polyfit(k, dt, 1)[0])
    return {"rows": rows, "slopes": slopes, "worst_deviation_from_theory": worst_deviation(rows)}


def implicit_euler_damping(omega_dts) -> dict:
    """Amplitude kept per period by implicit Euler on the soft cube's stiffest mode, against omega dt.

    Each point runs the whole steps of one period, ceil(2 pi / (omega dt)), so the decay
    stays far above round-off even where a single step removes 90 % of the amplitude.
    """
    model, vertices = soft_cube(DAMPING_STIFFNESS)
    mode = stiffest_mode(model, vertices)
    growth = growth_function(mode, DAMPING_METHOD, 1)
    method = get_integrator(DAMPING_METHOD)
    rows = []
    for y in omega_dts:
        steps_per_period = 2 * np.pi / y
        per_step = growth(y, int(np.ceil(steps_per_period)))
        rows.append({"omega_dt": float(y), "dt": float(y / mode.omega),
                     "amplitude_kept_per_period": float(np.exp(per_step * steps_per_period)),
                     # the method's growth per step, over a period: (1 + y^2)^(-pi / y) for implicit Euler
                     "theory": float(method.spectral_radius(y) ** steps_per_period)})
    return {"stiffness": DAMPING_STIFFNESS, "omega_max": mode.omega, "rows": rows,
            "worst_deviation_from_theory": max(abs(r["amplitude_kept_per_period"] / r["theory"] - 1) for r in rows)}


def cloth(side: int, stiffness: float) -> tuple[Model, np.ndarray]:
    """A 1 m square cloth of side x side particles of 1 g, structural and shear springs, two
    corners pinned, no gravity or dampers (the bench's cloth without them), and its rest positions."""
    mesh = soft_body.grid(side, side, 1.0 / side)
    springs, _ = soft_body.connect(mesh.vertices, mesh.edges, stiffness, 0.0)
    n = side * side
    pinned = np.zeros(n, bool)
    pinned[[0, side - 1]] = True
    return Model(np.full(n, SCALE_MASS), np.full(n, 0.2 / side), [springs], pinned=pinned), mesh.vertices


def implicit_euler_at_scale(side: int, stiffness: float, steps: int, seed: int) -> dict:
    """Explicit and implicit Euler on a cloth large enough for the sparse Newton solve.

    The cloth (:func:`cloth`) starts at rest, every free particle displaced at random by
    SCALE_DISPLACEMENT of its spacing (seeded), which excites every mode, the stiffest
    (omega_max, :func:`steplab.physics.modes.stiffest_mode`) included. Semi-implicit Euler
    runs ``steps`` steps just below and just above its limit 2 / omega_max
    (EXPLICIT_FACTORS); implicit Euler, its Newton steps solved by conjugate gradients on
    the sparse Jacobian above DENSE_MAX_BODIES bodies, at IMPLICIT_FACTORS times the limit.
    Without dampers the exact motion keeps its energy; implicit Euler's must never grow
    (its numerical damping), and the record keeps the largest and the last energy over
    the run, relative to the first.
    """
    from steplab.integrators import DivergenceError, simulate
    from steplab.physics.modes import stiffest_mode

    model, rest = cloth(side, stiffness)
    omega = stiffest_mode(model, rest, derivative="difference").omega
    limit = 2.0 / omega  # semi-implicit Euler's largest stable dt on the stiffest mode
    free = ~np.asarray(model.pinned)[:, None]
    q0 = rest + np.random.default_rng(seed).uniform(-1, 1, rest.shape) * free * SCALE_DISPLACEMENT / side
    y0 = np.stack([q0, np.zeros_like(q0)])
    e0 = float(model.energy(y0))
    runs = []
    for method, factors in (("semi-implicit-euler", EXPLICIT_FACTORS), (DAMPING_METHOD, IMPLICIT_FACTORS)):
        for factor in factors:
            dt = factor * limit
            try:
                traj = simulate(model, method, y0, 0.0, dt=dt, n_steps=steps)
            except DivergenceError as err:
                runs.append({"integrator": method, "dt_over_limit": factor, "dt": dt, "diverged_at_step": err.step})
                continue
            energy = np.array([float(model.energy(y)) for y in traj.y]) / e0
            runs.append({"integrator": method, "dt_over_limit": factor, "dt": dt, "diverged_at_step": None,
                         "largest_energy": float(energy.max()), "final_energy": float(energy[-1])})
    return {"bodies": model.n_bodies, "springs": int(np.asarray(model.forces[0].i).size), "stiffness": stiffness,
            "omega_max": omega, "explicit_limit_dt": limit, "steps": steps, "runs": runs}


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.8))
    plotting.stable_dt_panel(left, record["rows"], "stiffness", "theory: limit on the oscillator / omega_max(k)",
                             record["slopes"])
    left.set_xlabel("spring stiffness k (N/m)")
    left.set_title("Largest stable dt against the stiffness k\n(soft cube: 8 x 1 kg, a spring between every pair)")
    # below the axes: inside, it covered the measured limits and the 1/60 s line
    left.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)

    damping = record["implicit_euler_damping"]
    y = [r["omega_dt"] for r in damping["rows"]]
    right.semilogx(y, [r["amplitude_kept_per_period"] for r in damping["rows"]], linestyle="none", ms=7,
                   mfc="none", **plotting.style(DAMPING_METHOD))
    y_fine = np.geomspace(min(y), max(y), 200)
    right.semilogx(y_fine, (1 + y_fine**2) ** (-np.pi / y_fine), color="k", lw=0.8,
                   label="theory (1 + (omega dt)^2)^(-pi / (omega dt))")
    right.set_xlabel("omega_max dt")
    right.set_ylabel("amplitude kept per period")
    right.set_ylim(0, 1.05)
    right.set_title(f"What implicit Euler pays: numerical damping\n(the cube's stiffest mode, k = "
                    f"{damping['stiffness']:g} N/m, omega_max = {damping['omega_max']:.1f} rad/s)")
    right.grid(True, which="both", alpha=0.3)
    right.legend(fontsize=8)
    fig.tight_layout()
    return plotting.save_figure(fig, out, "stability_stiffness")
