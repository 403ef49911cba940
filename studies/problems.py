"""The test problems the studies share, each with its exact solution or a trusted reference."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from steplab.integrators import get_integrator, simulate
from steplab.physics import Dampers, Model, Springs, kepler_orbit, projectile
from steplab.physics.scene import load_scene

#: tolerance of the adaptive references used where no closed form exists
REFERENCE_RTOL = 1e-13


@dataclasses.dataclass(frozen=True)
class Problem:
    """A model, an initial state, a time span and the true final state (exact or reference)."""

    name: str
    title: str
    model: Model
    y0: np.ndarray
    t_start: float
    t_end: float
    #: ``solution(t) -> y`` (2, N, 3), exact; ``None`` for reference problems
    solution: Callable | None = None
    #: the characteristic angular frequency (rad/s), to express dt as omega dt
    omega: float | None = None

    def exact_final(self) -> np.ndarray:
        return self.solution(self.t_end)


def constant_force_solution(model: Model, y0: np.ndarray, t_start: float) -> Callable | None:
    """``solution(t) -> y`` (2, N, 3) in closed form, the lecture's projectile, where the total
    force of ``model`` is constant; None where it is not."""
    if model.constant_acceleration is None:
        return None
    g = np.asarray(model.constant_acceleration)

    def solution(t):
        p, v = projectile(t, y0[0], y0[1], g, t_start)
        return np.stack([p, v])

    return solution


def problem_of(scene, t_end: float) -> Problem:
    """``scene`` run to ``t_end``: exact where its force is constant, else measured against the references."""
    return Problem(scene.name, scene.description, scene.model, scene.y0, scene.t_start, t_end,
                   constant_force_solution(scene.model, scene.y0, scene.t_start))


def projectile_problem() -> Problem:
    """The lecture's projectile from t = 5 s, integrated for 2 s (constant force: exact)."""
    scene = load_scene("projectile")
    return Problem("projectile", "lecture projectile (exact)", scene.model, scene.y0, 5.0, 7.0,
                   constant_force_solution(scene.model, scene.y0, scene.t_start))


def oscillator_problem(damping_ratio: float = 0.0, t_end: float = 1.125) -> Problem:
    """A 1 kg mass on a spring to a pinned anchor (omega = 2 pi), optionally with a damper.

    The default end time, 1.125 periods (omega t = 2 pi + pi / 4), keeps both phase and
    amplitude errors visible in the position: at whole periods a phase error cancels, at
    quarter periods an amplitude error does, and a method's order can look one too high.

    x(t) = l_rest + A e^{-zeta w t} (cos(w_d t) + zeta w / w_d sin(w_d t)), w_d = w sqrt(1 - zeta^2),
    for release from rest at amplitude A (underdamped, zeta < 1).
    """
    if isinstance(damping_ratio, bool) or not (isinstance(damping_ratio, (int, float)) and 0 <= damping_ratio < 1):
        # the closed form below is the underdamped one: w_d = w sqrt(1 - zeta^2) is 0 or imaginary beyond
        raise ValueError(f"oscillator_problem: damping_ratio must be in [0, 1) (underdamped: its exact solution "
                         f"is the one given), got {damping_ratio!r}")
    omega, amplitude, rest = 2 * np.pi, 0.5, 1.0
    k, m = omega**2, 1.0
    forces = [Springs(np.array([0]), np.array([1]), np.array([k]), np.array([rest]))]
    if damping_ratio:
        forces.append(Dampers(np.array([0]), np.array([1]), np.array([2 * damping_ratio * omega * m])))
    model = Model([m, m], [0.05, 0.05], forces, pinned=[True, False], names=["anchor", "mass"])
    y0 = np.zeros((2, 2, 3))
    y0[0, 1, 0] = rest + amplitude
    zeta, wd = damping_ratio, omega * np.sqrt(1 - damping_ratio**2)

    def solution(t):
        decay = amplitude * np.exp(-zeta * omega * t)
        x = rest + decay * (np.cos(wd * t) + zeta * omega / wd * np.sin(wd * t))
        v = -decay * (omega**2 / wd) * np.sin(wd * t)
        y = np.zeros((2, 2, 3))
        y[0, 1, 0], y[1, 1, 0] = x, v
        return y

    name = "damped-oscillator" if damping_ratio else "oscillator"
    title = f"damped oscillator, zeta = {damping_ratio:g} (exact)" if damping_ratio else "harmonic oscillator (exact)"
    return Problem(name, title, model, y0, 0.0, t_end, solution, omega)


def kepler_problem(t_end: float = 1.0) -> Problem:
    """The ``kepler`` scene: a = 1 m, e = 0.5, period 1 s, exact through Kepler's equation."""
    scene = load_scene("kepler")
    (gravity,) = scene.model.forces
    mu, center = float(gravity.mu), np.asarray(gravity.center)

    def solution(t):
        q, v = kepler_orbit(t, scene.y0[0, 0], scene.y0[1, 0], mu, scene.t_start, center)
        return np.stack([q[..., None, :], v[..., None, :]], axis=-3)  # (..., 2, 1, 3)

    return Problem("kepler", "Kepler orbit, e = 0.5 (exact)", scene.model, scene.y0, scene.t_start, t_end,
                   solution, omega=2 * np.pi)


def scene_problem(scene_name: str, t_end: float, title: str, omega: float | None = None) -> Problem:
    """A built-in scene whose true final state comes from the adaptive references."""
    scene = load_scene(scene_name)
    return Problem(scene_name, title, scene.model, scene.y0, scene.t_start, t_end, None, omega)


def reference_final(problem: Problem) -> tuple[np.ndarray, dict]:
    """The final state from diffrax Dopri8, cross-checked against scipy DOP853.

    Returns the diffrax state and a record of both tolerances and how far apart the two
    references are (max |difference| of the final positions, m).
    """
    ts = np.array([problem.t_start, problem.t_end])
    results = {}
    for name in ("diffrax-dopri8", "scipy-dop853"):
        method = dataclasses.replace(get_integrator(name), rtol=REFERENCE_RTOL, atol=REFERENCE_RTOL)
        traj = simulate(problem.model, method, problem.y0, ts[0], ts[1], ts[1] - ts[0])
        results[name] = traj.y[-1]
    agreement = float(np.max(np.abs(results["diffrax-dopri8"][0] - results["scipy-dop853"][0])))
    return results["diffrax-dopri8"], {"reference": "diffrax-dopri8", "cross_check": "scipy-dop853",
                                       "rtol": REFERENCE_RTOL, "atol": REFERENCE_RTOL,
                                       "agreement": agreement}


def true_final(problem: Problem) -> tuple[np.ndarray, dict]:
    """The true final state and a description of where it came from."""
    if problem.solution is not None:
        return problem.exact_final(), {"reference": "exact"}
    return reference_final(problem)
