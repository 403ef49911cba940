"""The linear test of a fixed-step method: what one step does to the damped oscillator.

Near equilibrium every model is a set of independent damped oscillators (its modes),
so a method's stability on u'' = -omega^2 u - 2 zeta omega u' decides how large a step
it survives. With omega = 1 the step is y = omega dt, and one step of a method is a
linear map of its state: the (u, v) pair, plus whatever it carries between steps
(velocity and position Verlet keep an acceleration). :func:`linear_map` finds that map
by running the method's own ``step`` on the basis states of :class:`LinearTestModel`;
the model is linear, so the map is exact to round-off and a new stepper has its theory
without writing any.

A method is stable at y when the spectral radius of its map is at most 1: the largest
|R(y lambda)| for a method with a scalar stability function R(z) (Runge-Kutta methods,
implicit Euler), lambda = -zeta +- sqrt(zeta^2 - 1) the oscillator's eigenvalues;
the largest |eigenvalue| of the map otherwise. :func:`stability_limit` searches the
largest stable y.
"""

from __future__ import annotations

import cmath
import functools
import math

import numpy as np

#: search interval of omega dt: stable already at OMEGA_DT_MIN or not at all counts as
#: "unstable for every dt" (0); still stable at OMEGA_DT_MAX as "no limit" (None)
OMEGA_DT_MIN, OMEGA_DT_MAX = 1e-3, 100.0
#: |eigenvalue| = 1 exactly on the stable range of a symplectic method: a spectral radius
#: up to 1 + this is round-off, not growth
THEORY_TOLERANCE = 1e-14
#: points of the log-spaced grid that brackets the first crossing (fine enough that no
#: stable island between two points is skipped for the methods' smooth radii), and the
#: root finder's absolute tolerance on omega dt
LIMIT_GRID_POINTS = 4000
LIMIT_XTOL = 1e-14
#: the grid is scanned every LIMIT_COARSE_STRIDE-th point first (1.4 % apart in omega dt), then point by
#: point only between the last stable and the first unstable of those: the same bracket as the whole
#: grid's unless an unstable window lies between two stable coarse points (none does for the registered
#: methods: tests/test_method_theory.py), in about 220 evaluations of the radius instead of 4,000
LIMIT_COARSE_STRIDE = 20


class LinearTestModel:
    """One body on the damped oscillator a(t, q, v) = -q - 2 zeta v (omega = 1), in NumPy.

    It offers what a stepper may use of a :class:`~steplab.physics.Model`: ``xp``,
    ``dtype``, ``n_bodies``, ``masses``, ``inverse_masses``, ``pinned``,
    ``acceleration``, ``vector_field``, ``jacobian`` (so implicit methods run) and
    ``energy``. The three coordinates are three independent copies of the oscillator.
    """

    xp = np
    dtype = np.dtype(np.float64)
    n_bodies = 1

    def __init__(self, zeta: float = 0.0):
        self.zeta = float(zeta)
        self.masses = np.ones(1)
        self.inverse_masses = np.ones(1)
        self.pinned = np.zeros(1, dtype=bool)

    def acceleration(self, t, q, v):
        return -q - (2 * self.zeta) * v

    def vector_field(self, t, y):
        return np.stack([y[1], self.acceleration(t, y[0], y[1])])

    def jacobian(self, t, q, v):
        """da/dq and da/dv, each shape (3N, 3N)."""
        eye = np.eye(3 * self.n_bodies)
        return -eye, (-2 * self.zeta) * eye

    def energy(self, y):
        return 0.5 * float(np.sum(y[1] ** 2) + np.sum(y[0] ** 2))

    def cast(self, xp=None, dtype=None):
        if xp not in (None, np) or dtype not in (None, np.float64):
            raise ValueError("the linear test model exists in NumPy float64 only")
        return self


def linear_map(stepper, omega_dt: float, zeta: float = 0.0) -> np.ndarray:
    """One-step amplification matrix of ``stepper`` on u'' = -u - 2 zeta u', dt = omega_dt.

    Column j is the step applied to basis state j of (u, v) or, for a method that
    carries an array shaped like q between steps, of (u, v, carry): the carry is an
    independent part of the state (after a kick it no longer equals the acceleration
    of the state beside it). Shape (2, 2) or (3, 3).
    """
    model = LinearTestModel(zeta)
    q = np.zeros((1, 3))
    carry = stepper.init(model, 0.0, np.stack([q, q]))
    if carry is not None and np.shape(carry) != q.shape:
        raise TypeError(f"{stepper.name}: linear_map derives the map for a carry of None or an array "
                        f"shaped like q {q.shape}, got {type(carry).__name__} of shape {np.shape(carry)}; "
                        "override linear_map")
    size = 2 if carry is None else 3
    columns = []
    for basis in np.eye(size):
        y = np.zeros((2, 1, 3))
        y[0, 0, 0], y[1, 0, 0] = basis[0], basis[1]
        start = None
        if carry is not None:
            start = np.zeros((1, 3))
            start[0, 0] = basis[2]
        y1, carry1 = stepper.step(model, 0.0, y, float(omega_dt), start)
        y1 = np.asarray(y1)
        column = [y1[0, 0, 0], y1[1, 0, 0]]
        if carry is not None:
            column.append(np.asarray(carry1)[0, 0])
        columns.append(column)
    return np.array(columns, dtype=float).T


def oscillator_eigenvalues(zeta: float) -> tuple[complex, complex]:
    """lambda = -zeta +- sqrt(zeta^2 - 1): the damped oscillator's eigenvalues (omega = 1)."""
    if zeta <= 1:
        root = cmath.sqrt(zeta * zeta - 1)  # i sqrt(1 - zeta^2) when underdamped
        return complex(-zeta) + root, complex(-zeta) - root
    # overdamped: the larger root without zeta^2 (which overflows from zeta ~ 1e154), the smaller from
    # their product, 1, without the cancellation of -zeta + sqrt(zeta^2 - 1)
    fast = -zeta * (1 + math.sqrt((1 - 1 / zeta) * (1 + 1 / zeta)))
    return complex(1 / fast), complex(fast)


def spectral_radius(stepper, omega_dt: float, zeta: float = 0.0) -> float:
    """Largest |growth factor| per step: |R(omega_dt lambda)| if the method has R, else of its map.

    inf where the growth factor or the map is not finite: at a damping ratio near the float range an
    explicit step's own arithmetic overflows, which is no bounded growth."""
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is the answer here, inf
        if stepper.stability_function is not None:
            radii = [float(abs(stepper.stability_function(omega_dt * lam))) for lam in oscillator_eigenvalues(zeta)]
            return max(radii) if all(map(math.isfinite, radii)) else math.inf
        step = stepper.linear_map(omega_dt, zeta)
    if not np.all(np.isfinite(step)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(step))))


def stability_limit(stepper, zeta: float = 0.0) -> float | None:
    """Largest omega dt with spectral radius <= 1 (+ THEORY_TOLERANCE): 0 if none, None if unbounded.

    A log-spaced grid over [OMEGA_DT_MIN, OMEGA_DT_MAX] finds the first unstable point (scanned
    every LIMIT_COARSE_STRIDE-th point, then point by point where the coarse scan crossed);
    Brent's method places the crossing between it and the stable point before.
    Cached per (stepper, zeta) when the stepper is hashable (frozen dataclasses are).
    """
    try:
        hash(stepper)
    except TypeError:
        return _search_limit(stepper, float(zeta))
    return _cached_limit(stepper, float(zeta))


@functools.cache
def _cached_limit(stepper, zeta: float) -> float | None:
    return _search_limit(stepper, zeta)


def _search_limit(stepper, zeta: float) -> float | None:
    ys = np.geomspace(OMEGA_DT_MIN, OMEGA_DT_MAX, LIMIT_GRID_POINTS)
    excess = lambda y: stepper.spectral_radius(y, zeta) - 1 - THEORY_TOLERANCE  # noqa: E731
    coarse = sorted({*range(0, len(ys), LIMIT_COARSE_STRIDE), len(ys) - 1})
    k = _first_unstable(excess, ys, coarse)
    if k == 0:
        return 0.0
    if k is None:
        return None
    k = _first_unstable(excess, ys, range(coarse[coarse.index(k) - 1] + 1, k + 1))  # between the coarse pair
    from scipy.optimize import brentq  # here, not at the top: SciPy's import costs a listing 0.2 s

    return float(brentq(excess, ys[k - 1], ys[k], xtol=LIMIT_XTOL))


def _first_unstable(excess, ys, indices) -> int | None:
    """The first of ``indices`` into the grid ``ys`` where ``excess`` > 0, or None."""
    return next((k for k in indices if excess(ys[k]) > 0), None)
