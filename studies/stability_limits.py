"""Stability limits: the largest stable omega dt of an integrator on one mode, measured.

Measured: by bisection on long runs of the real integrator on a :class:`Mode` (the
oscillator's, the stiffest mode of a spring network, the stretch of a spring between two
bodies): a run is unstable when the growth per step of its measured LONG_RUN_STEPS-step
map exceeds GROWTH_TOLERANCE. Methods whose one-step amplification exceeds 1 at even the
smallest omega dt are recorded as 0 (unstable for every dt > 0); methods stable at
omega dt = OMEGA_DT_MAX as None (no limit found).

Derived: each method states its own (``Stepper.stability_limit``: the largest omega dt
with spectral radius <= 1 of its one-step map on the damped oscillator, from its
stability function or from its own ``step``; steplab.integrators.linear_stability).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from steplab.integrators import get_integrator
from steplab.integrators.linear_stability import OMEGA_DT_MAX, OMEGA_DT_MIN  # the theory's interval
from steplab.integrators.simulate import DivergenceError, final_state_function

from .problems import oscillator_problem
from .system import is_system

#: steps of one stability run; the largest growth per step (log of the spectral radius of
#: the measured N-step map, over N) that still counts as stable; the probe deviation, m.
#: The tolerance sits above what round-off and the springs' geometric nonlinearity (which
#: trades energy between the modes of a spring network) show near a limit, up to about
#: 2e-8 per step, and costs almost nothing in resolution: just past a limit the growth
#: rises steeply (as sqrt(omega dt - 2) for the symplectic methods)
LONG_RUN_STEPS = 20_000
GROWTH_TOLERANCE = 1e-7
PROBE = 1e-6
#: the probe of a float32 system, m: 1e-6 m is a few ulps of a position near 1 m in float32;
#: the oscillator's spring is linear along its axis, so any amplitude measures the same map
FLOAT32_PROBE = 1e-2
#: points of the log-spaced scan from OMEGA_DT_MIN to OMEGA_DT_MAX whose first unstable one
#: brackets the limit (a factor of 2 apart)
SCAN_POINTS = 17
#: the bisection's relative tolerance
BISECTION_RTOL = 1e-6
#: a one-step spectral radius above 1 + this at omega dt = OMEGA_DT_MIN is growth, not round-off
AMPLIFICATION_TOLERANCE = 1e-14


# --- measurement --------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Mode:
    """One oscillation mode of a model at rest, as the linear stability test sees it.

    The state ``equilibrium + u * pattern`` (positions) with velocity ``v omega pattern``
    has amplitude (u, v); :meth:`amplitudes` reads them back from any state through
    ``weights`` (a left eigenvector: ``sum(weights * pattern) = 1``). A pure mode of the
    linearised dynamics stays a pure mode, so the pair (u, v) after N real steps is the
    N-step map of that mode alone.
    """

    model: object
    omega: float
    equilibrium: np.ndarray  # (2, N, 3), at rest
    pattern: np.ndarray  # (N, 3)
    weights: np.ndarray  # (N, 3)

    def state(self, u: float, v: float) -> np.ndarray:
        y = self.equilibrium.copy()
        y[0] += u * self.pattern
        y[1] += v * self.omega * self.pattern
        return y

    def amplitudes(self, y) -> tuple[float, float]:
        y = np.asarray(y, dtype=float)
        return (float(np.sum(self.weights * (y[0] - self.equilibrium[0]))),
                float(np.sum(self.weights * y[1])) / self.omega)


def oscillator_mode(zeta: float) -> Mode:
    """The oscillator's one mode: the mass moving along the spring."""
    problem = oscillator_problem(zeta)
    equilibrium = np.zeros_like(problem.y0)
    equilibrium[0, 1, 0] = 1.0  # rest length
    pattern = np.zeros((2, 3))
    pattern[1, 0] = 1.0
    return Mode(problem.model, problem.omega, equilibrium, pattern, pattern)


def stiffest_mode(model, q_rest) -> Mode:
    """The highest-frequency mode of a spring network at rest (it bounds every explicit dt).

    From the analytic Jacobian: the eigenvector of -da/dq = M^-1 K with the largest
    eigenvalue omega^2, read back with the mass-weighted projection (M^-1 K is
    self-adjoint in the mass inner product, so this is its left eigenvector).
    """
    q_rest = np.asarray(q_rest, dtype=float)
    dadq, _ = model.jacobian(0.0, q_rest, np.zeros_like(q_rest))
    values, vectors = np.linalg.eig(-np.asarray(dadq))
    k = int(np.argmax(values.real))
    pattern = vectors[:, k].real.reshape(q_rest.shape)
    pattern /= np.abs(pattern).max()
    masses = np.asarray(model.masses)[:, None]
    weights = masses * pattern / np.sum(masses * pattern * pattern)
    return Mode(model, float(np.sqrt(values[k].real)), np.stack([q_rest, np.zeros_like(q_rest)]), pattern, weights)


def growth_function(mode: Mode, method, steps: int, probe: float = PROBE):
    """``growth(omega dt[, steps])``: log of the spectral radius of the measured N-step map, per step.

    Each call runs ``steps`` steps of the real integrator from two small deviations of
    the mode (amplitude, and velocity / omega, of size PROBE), which gives the empirical
    N-step map M_N of the linearised mode; returns inf when a run diverges. The probes
    are small enough that a 10^5-fold growth stays linear.
    """
    if is_system(method):  # an engine, or steplab behind the system protocol: its own stepping
        if method.precision == "float32":
            probe = max(probe, FLOAT32_PROBE)
        system = method.build(mode.model, None, OMEGA_DT_MIN / mode.omega, mode.equilibrium)
        starts = [mode.state(u, v) for u, v in ((probe, 0.0), (0.0, probe))]

        def run(y0, t_start, dt, n):
            try:
                return system.advance(y0, dt, n, save_every=n).y[-1], -1
            except DivergenceError as err:
                return None, err.step
    else:
        import jax.numpy as jnp

        run = final_state_function(mode.model.cast(jnp), method)
        starts = [jnp.asarray(mode.state(u, v)) for u, v in ((probe, 0.0), (0.0, probe))]

    def growth(y: float, n: int = steps) -> float:
        dt = y / mode.omega
        columns = []
        for y0 in starts:
            final, bad = run(y0, 0.0, dt, n)
            if int(bad) >= 0:
                return np.inf
            columns.append(mode.amplitudes(final))
        radius = np.max(np.abs(np.linalg.eigvals(np.array(columns).T / probe)))
        return float(np.log(max(radius, 1e-300)) / n) if np.isfinite(radius) else np.inf

    return growth


def measured_limit(mode: Mode, method, steps: int, rtol: float = BISECTION_RTOL) -> dict:
    """Largest stable omega dt of ``mode`` by bisection on long runs of the real integrator
    (or of a system under test, :mod:`.system`).

    A run is stable when its growth per step (:func:`growth_function`) is at most
    GROWTH_TOLERANCE. A method whose one real step already amplifies at omega dt =
    OMEGA_DT_MIN is recorded as 0 (unstable for every dt > 0), one stable at every point
    of the scan up to OMEGA_DT_MAX as None (no limit found); otherwise the limit is bisected
    between the last stable and the first unstable point of the scan.
    """
    if not is_system(method):  # a system under test has no autodiff: its long runs decide alone
        growth = _one_step_growth(mode, method, OMEGA_DT_MIN)
        if growth > 1 + AMPLIFICATION_TOLERANCE:
            return {"omega_dt_max": 0.0, "growth_per_step_at_min": growth}
    measure = growth_function(mode, method, steps)
    stable = lambda y: measure(y) <= GROWTH_TOLERANCE  # noqa: E731
    if not stable(OMEGA_DT_MIN):
        return {"omega_dt_max": 0.0}
    # the first unstable point of a coarse log grid brackets the limit (as in the theory's
    # search): a method can be stable again beyond an unstable window, as exponential
    # damping is above omega dt = 30 at zeta = 0.1, so the largest omega dt alone says nothing
    lo = OMEGA_DT_MIN
    for hi in np.geomspace(OMEGA_DT_MIN, OMEGA_DT_MAX, SCAN_POINTS)[1:]:
        if not stable(hi):
            break
        lo = hi
    else:
        return {"omega_dt_max": None}
    while hi - lo > rtol * lo:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return {"omega_dt_max": float(lo), "bracket": [float(lo), float(hi)]}


def stable_dt(mode: Mode, method, steps: int, rtol: float) -> dict:
    """Largest stable dt on ``mode``, measured (:func:`measured_limit`) and from theory
    (the method's undamped limit on the oscillator over the mode's omega); None: no limit."""
    measured = measured_limit(mode, method, steps, rtol)["omega_dt_max"]
    theory = get_integrator(method).stability_limit(0.0)
    return {"omega": mode.omega, "dt_max": None if measured is None else measured / mode.omega,
            "dt_max_theory": None if theory is None else theory / mode.omega}


def worst_deviation(rows) -> float | None:
    """Largest |measured / theory - 1| of the largest stable dt over the rows with a finite limit."""
    deviations = [abs(r["dt_max"] / r["dt_max_theory"] - 1) for r in rows if r["dt_max"] and r["dt_max_theory"]]
    return max(deviations, default=None)


def _one_step_growth(mode: Mode, method, y: float) -> float:
    """Spectral radius of one real step of the integrator on the mode's (u, v).

    The step is linearised at the equilibrium by forward-mode autodiff through the
    integrator's own code (Newton iterations included), so the map is exact to round-off:
    a finite probe would add its nonlinearity, larger than the 1e-13 growth per step
    that marks Heun unstable at omega dt = 1e-3.
    """
    import jax
    import jax.numpy as jnp

    integrator = get_integrator(method)
    model, dt = mode.model.cast(jnp), y / mode.omega

    def step(state):
        return integrator.step(model, 0.0, state, dt, integrator.init(model, 0.0, state))[0]

    linearised = jax.jit(lambda tangent: jax.jvp(step, (jnp.asarray(mode.equilibrium),), (tangent,))[1])
    columns = []
    for u, v in ((1.0, 0.0), (0.0, 1.0)):
        out = np.asarray(linearised(jnp.asarray(mode.state(u, v) - mode.equilibrium)))
        columns.append([np.sum(mode.weights * out[0]), np.sum(mode.weights * out[1]) / mode.omega])
    return float(np.max(np.abs(np.linalg.eigvals(np.array(columns).T))))
