"""Adaptive reference solvers behind the same driver: diffrax and scipy ``solve_ivp``.

A study asks for "the reference" and gets a high-order adaptive method at a tight,
recorded tolerance. The explicit ones (Dopri8, Tsit5, DOP853) suit smooth non-stiff
scenes; the implicit ones (Kvaerno5, Radau) stiff spring systems.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import numpy as np

from .base import Solver, check_real

#: step budget of one reference solve; exceeding it is reported, never truncated silently
MAX_REFERENCE_STEPS = 1_000_000
#: the most vector-field evaluations a scipy solve takes per step of its budget: DOP853 makes 12 a step, Radau
#: one a Newton iteration (at most 6) plus its error estimate; scipy counts no steps of its own, so the budget
#: of MAX_REFERENCE_STEPS steps is kept in evaluations (without it a span of 1e300 s never ended)
EVALUATIONS_PER_STEP = 12
#: how often (in vector-field evaluations) a scipy solve compares the time it has reached with its span. The
#: budget alone let a hopeless solve (a span of 1e300 s) make all its 12 million Python evaluations, minutes of
#: them, before it said so; the rate of its first 10,000 (a second or less) says so already
BUDGET_LOOK_EVERY = 10_000
#: a scipy solve stops early only if, at the rate of its evaluations so far, the span would take more than
#: this many times its budget. The rate of a legitimate solve varies (a fast transient, then slow motion), and
#: the margin leaves it room: a solve ended this way would have needed it to fall more than tenfold later on
BUDGET_PROJECTION_MARGIN = 10
#: the smallest rtol a reference takes: scipy's solve_ivp raises any rtol below 100 x the float64
#: machine epsilon to it (with a warning), so a tighter one would not be the tolerance recorded
MIN_RTOL = 100 * float(np.finfo(float).eps)
#: the smallest atol a reference takes. atol = 0 makes scipy's error scale atol + rtol |y| zero on
#: a coordinate that is zero (a pinned body, a planar scene), and its first step 0 / 0 = NaN, a
#: solve that never ends; a subnormal atol overflows y / atol to inf the same way. 1e-100 leaves
#: y / atol finite for any |y| < 1e200
MIN_ATOL = 1e-100
#: the largest state (6 x particles numbers) whose Kvaerno5 Newton solves form and LU-factor the dense
#: Jacobian; larger ones solve matrix-free by GMRES (a Jacobian-vector product an iteration). The dense
#: Jacobian takes n Jacobian-vector products and an n^3 / 3 factorization a step: at n = 864 (the 12 x 12
#: cloth) 46 steps took 8 s, GMRES 1.2 s; at n = 216 both 0.1-0.2 s, and the dense path is the robust one
DENSE_NEWTON_MAX_SIZE = 300
#: GMRES's tolerances in a Kvaerno5 Newton step (relative to the Newton residual): tight enough that the
#: step is the dense one's to round-off (2.5e-13 m on the 12 x 12 cloth)
GMRES_RTOL, GMRES_ATOL = 1e-12, 1e-14


class _OutOfBudget(Exception):
    """A scipy solve past its evaluations (:data:`EVALUATIONS_PER_STEP`), or on course to be (the
    message says how far it got): raised from its vector field, since solve_ivp takes no step budget."""


class ReferenceFailedError(RuntimeError):
    """The reference solver did not reach the end of the interval."""


#: the library and its solver class / solve_ivp method, by reference name
ADAPTIVE_METHODS = {"diffrax-dopri8": ("diffrax", "Dopri8"), "diffrax-tsit5": ("diffrax", "Tsit5"),
                    "diffrax-kvaerno5": ("diffrax", "Kvaerno5"), "scipy-dop853": ("scipy", "DOP853"),
                    "scipy-radau": ("scipy", "Radau"), "scipy-rk45": ("scipy", "RK45")}


class AdaptiveSolution(NamedTuple):
    """What one adaptive solve returns.

    Attributes
    ----------
    ys : array, shape (K, 2, N, 3)
        The states at the saved times (K = len(ts)), or the end state alone (K = 1).
    steps : int or array
        Steps the solver took (accepted and rejected for diffrax; scipy: None with
        saved times, since solve_ivp then reports the saved times, not its steps).
    evaluations : int or None
        Vector-field evaluations (scipy's ``nfev``; None for diffrax, which does not count).
    success : bool or array
        Whether the solve reached the end (an array inside ``jax.jit``).
    message : str
    """

    ys: object
    steps: object
    evaluations: object
    success: object
    message: str


def solve_adaptive(vector_field, ts, y0, method: str, rtol, atol, *, at_saved_times: bool = True,
                   jacobian=None, max_steps: int = MAX_REFERENCE_STEPS) -> AdaptiveSolution:
    """Solve dy/dt = vector_field(t, y) over [ts[0], ts[-1]] with an adaptive reference method.

    The one place steplab calls diffrax's ``diffeqsolve`` or scipy's ``solve_ivp``
    adaptively: the reference solvers, the work-precision study and the bench.

    Parameters
    ----------
    vector_field : callable
        ``vector_field(t, y) -> dy/dt`` for y of the shape of ``y0``; JAX-traceable for diffrax.
    ts : array, shape (K,)
        Times to save at, increasing; K >= 2.
    y0 : array, shape (2, N, 3)
    method : str
        A name of :data:`ADAPTIVE_METHODS`, e.g. ``"diffrax-dopri8"``, ``"scipy-dop853"``.
    rtol, atol : float
        The PID controller's tolerances; may be traced (diffrax inside ``jax.jit``).
    at_saved_times : bool
        True: step exactly onto every saved time and return the states there. False: a
        plain solve from ts[0] to ts[-1] that returns the end state only, the solver's
        own cost (what the work-precision study and the bench time).
    jacobian : callable, optional
        ``jacobian(t, y) -> d(dy/dt)/dy`` on the flat state (scipy's implicit methods).
    max_steps : int
        The step budget: diffrax's ``max_steps``; scipy's kept in vector-field evaluations,
        :data:`EVALUATIONS_PER_STEP` a step (solve_ivp has none, and counts no steps), and
        ended early where the rate of its evaluations so far needs far more for the span
        (:func:`_project_budget`).

    Notes
    -----
    diffrax runs with ``throw=False``: a failed solve is reported in ``success``, so the
    call can sit inside ``jax.jit``; the caller decides what a failure means.
    """
    if method not in ADAPTIVE_METHODS:
        raise ValueError(f"unknown adaptive method {method!r}; valid: {', '.join(ADAPTIVE_METHODS)}")
    library, solver = ADAPTIVE_METHODS[method]
    if library == "diffrax":
        import diffrax

        # Step exactly onto every saved time: diffrax would otherwise fill SaveAt(ts) by
        # interpolating inside steps, and the Dopri8 / Kvaerno5 interpolants are
        # 100-1000x less accurate than the steps themselves.
        controller = diffrax.PIDController(rtol=rtol, atol=atol)
        if at_saved_times:
            controller = diffrax.ClipStepSizeController(controller, step_ts=ts)
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(lambda t, y, args: vector_field(t, y)),
            kvaerno5(np.size(y0)) if solver == "Kvaerno5" else getattr(diffrax, solver)(), t0=ts[0], t1=ts[-1],
            dt0=None, y0=y0, saveat=diffrax.SaveAt(ts=ts) if at_saved_times else diffrax.SaveAt(t1=True),
            stepsize_controller=controller, max_steps=max_steps, throw=False)
        return AdaptiveSolution(sol.ys, sol.stats["num_steps"], None, sol.result == diffrax.RESULTS.successful,
                                str(sol.result))
    from scipy.integrate import solve_ivp

    y0 = np.asarray(y0, dtype=float)
    shape = y0.shape
    budget = max_steps * EVALUATIONS_PER_STEP
    t0, t1 = float(ts[0]), float(ts[-1])
    evaluations = 0

    def fun(t, y):
        nonlocal evaluations
        if evaluations >= budget:
            raise _OutOfBudget(f"it took its budget of {budget:,} vector-field evaluations")
        if evaluations and evaluations % BUDGET_LOOK_EVERY == 0:
            _project_budget(evaluations, float(t), t0, t1, budget)
        evaluations += 1
        return np.asarray(vector_field(t, y.reshape(shape))).ravel()

    kwargs = {} if jacobian is None else {"jac": jacobian}
    try:
        sol = solve_ivp(fun, (ts[0], ts[-1]), y0.ravel(), method=solver, t_eval=ts if at_saved_times else None,
                        rtol=rtol, atol=atol, **kwargs)
    except _OutOfBudget as stop:  # as diffrax reports its max_steps: the steps taken, the budget
        return AdaptiveSolution(np.empty((0,) + shape), max_steps, evaluations, False, str(stop))
    if not sol.success and isinstance(sol.y, list):  # stopped before the first saved time: solve_ivp leaves []
        return AdaptiveSolution(np.empty((0,) + shape), None, int(sol.nfev), False, sol.message)
    ys = sol.y.T.reshape((-1,) + shape)
    return AdaptiveSolution(ys if at_saved_times else ys[-1:], None if at_saved_times else int(sol.t.size - 1),
                            int(sol.nfev), bool(sol.success), sol.message)


def kvaerno5(size: int):
    """diffrax's Kvaerno5 for a state of ``size`` numbers, with a Newton solve that works on it.

    Its root finder is diffrax's VeryChord (one Jacobian a step) with the termination of the fixed
    upstream one (:func:`_very_chord`), and its linear solver the dense LU for states of up to
    :data:`DENSE_NEWTON_MAX_SIZE` numbers, else matrix-free GMRES (:data:`GMRES_RTOL`, :data:`GMRES_ATOL`).
    """
    import diffrax
    import lineax

    if size <= DENSE_NEWTON_MAX_SIZE:
        linear_solver = lineax.AutoLinearSolver(well_posed=None)  # diffrax's default: LU
    else:
        linear_solver = lineax.GMRES(rtol=GMRES_RTOL, atol=GMRES_ATOL, restart=30, stagnation_iters=30)
    root_finder = diffrax.with_stepsize_controller_tols(_very_chord())(linear_solver=linear_solver)
    return diffrax.Kvaerno5(root_finder=root_finder)


@functools.cache
def _very_chord():
    """diffrax.VeryChord with two fixes (a class made on first use: diffrax is imported lazily).

    - **Termination.** diffrax 0.7.2's VeryChord reports "diverged" after any second iteration that has
      not converged yet, diverging or not, and Optimistix 0.1 ends the iteration on that result: every
      stage that needed a third chord iteration failed, and its step was rejected (error inf) and cut
      fivefold. Kvaerno5 on the 12 x 12 cloth took 1,000+ steps, half of them rejected, for 20 steps of
      dt (215 s); here 35 and 11 (diffrax PR #754 fixes it upstream). It now reports divergence only when
      it stops on it (rate > 2 or not finite); an iteration still converging goes on, to the root
      finder's max steps.
    - **Iterative linear solvers.** Its step applied ``stop_gradient`` to the whole linear-solver state,
      which with GMRES holds the linearised operator (not arrays) and failed to trace; only its arrays
      are stopped now, as its ``init`` does.
    """
    import diffrax
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import lineax
    import optimistix as optx

    class VeryChord(diffrax.VeryChord):
        def step(self, fn, y, args, options, state, tags):
            jac, linear_state = state.linear_state
            dynamic, static = eqx.partition(linear_state, eqx.is_array)
            linear_state = eqx.combine(jax.lax.stop_gradient(dynamic), static)
            fx, aux = fn(y, args)
            sol = lineax.linear_solve(jac, fx, self.linear_solver, state=linear_state, throw=False)
            diff = sol.value
            new_y = jax.tree_util.tree_map(lambda a, b: a - b, y, diff)
            with jax.numpy_dtype_promotion("standard"):
                scale = jax.tree_util.tree_map(lambda a: self.atol + self.rtol * jnp.abs(a), new_y)
                diffsize = self.norm(jax.tree_util.tree_map(lambda a, b: a / b, diff, scale))
            return new_y, dataclasses.replace(state, diff=diff, diffsize=diffsize, diffsize_prev=state.diffsize,
                                              result=optx.RESULTS.promote(sol.result), step=state.step + 1), aux

        def terminate(self, fn, y, args, options, state, tags):
            at_least_two = state.step >= 2
            rate = state.diffsize / state.diffsize_prev
            factor = state.diffsize * rate / (1 - rate)
            small = state.diffsize < 10 ** (2 - jnp.finfo(state.diffsize.dtype).precision)
            diverged = ~jnp.isfinite(rate) | (rate > 2)
            converged = (factor > 0) & (factor < self.kappa)
            terminate = at_least_two & (small | diverged | converged)
            result = optx.RESULTS.where(at_least_two & diverged & ~small, optx.RESULTS.nonlinear_divergence,
                                        optx.RESULTS.successful)
            linsolve_failed = state.result != optx.RESULTS.successful
            return linsolve_failed | terminate, optx.RESULTS.where(linsolve_failed, state.result, result)

    return VeryChord


def _project_budget(evaluations: int, t: float, t0: float, t1: float, budget: int):
    """Raise :class:`_OutOfBudget` if ``evaluations`` that reached ``t`` say the span [t0, t1] needs far more.

    At the rate so far the whole span takes evaluations (t1 - t0) / (t - t0); the time a vector
    field is called at is a stage's, at or past the last accepted step, so the rate is if anything
    flattered and the projection low. Past :data:`BUDGET_PROJECTION_MARGIN` times the budget the
    solve cannot end within it short of a collapse in its rate, and it ends now, not minutes on when
    the budget is spent. Compared as products, not a quotient: a span of 1e300 s makes the product
    inf at worst (a float product does not raise), and no time reached (t == t0) says nothing yet.
    """
    if t > t0 and evaluations * (t1 - t0) > BUDGET_PROJECTION_MARGIN * budget * (t - t0):
        raise _OutOfBudget(f"its first {evaluations:,} vector-field evaluations reached t = {t:.4g} s of "
                           f"{t1:.4g} s: at that rate the span needs over {BUDGET_PROJECTION_MARGIN} x the "
                           f"{budget:,} of its budget")


@dataclasses.dataclass(frozen=True)
class AdaptiveReference(Solver):
    """An adaptive reference solve (:func:`solve_adaptive`) under the registry name ``name``.

    Parameters
    ----------
    rtol : float
        Relative tolerance, in [:data:`MIN_RTOL`, 1).
    atol : float
        Absolute tolerance, finite and >= :data:`MIN_ATOL`.
    """

    rtol: float = 1e-12
    atol: float = 1e-12

    evaluations = None

    def __post_init__(self):
        check_real(self.name, "rtol", self.rtol, lambda x: MIN_RTOL <= x < 1,
                   f"a number in [{MIN_RTOL:.3g}, 1) (the low end is scipy's 100 x machine epsilon, "
                   "steplab.integrators.references.MIN_RTOL)")
        check_real(self.name, "atol", self.atol, lambda x: x >= MIN_ATOL,
                   f"a finite number >= {MIN_ATOL:g} (steplab.integrators.references.MIN_ATOL; 0 stalls the "
                   "solver on a coordinate that stays 0)")

    def solve(self, model, ts, y0):
        if self.backend == "jax":
            import jax.numpy as jnp

            # in float64 whatever the run's precision, as scipy's solve_ivp solves (it takes y0 as float):
            # a reference's tolerance (rtol 1e-10 to 1e-12) is below float32's resolution (1.2e-7), so a
            # float32 solve shrank its step until it had spent its MAX_REFERENCE_STEPS (minutes) and failed.
            # simulate rounds the solution to the run's precision
            ts, y0 = jnp.asarray(ts, dtype=jnp.float64), jnp.asarray(y0, dtype=jnp.float64)
            if self.implicit:
                _check_autodiff_jacobian(self.name, model, ts[0], y0)
        jacobian = None
        if self.implicit and self.backend == "numpy":  # scipy's implicit methods take the Jacobian
            shape = np.shape(y0)
            jacobian = lambda t, y: _first_order_jacobian(model, t, y.reshape(shape))  # noqa: E731
        sol = solve_adaptive(model.vector_field, ts, y0, self.name, self.rtol, self.atol, jacobian=jacobian,
                             max_steps=MAX_REFERENCE_STEPS)
        if not sol.success:
            if sol.steps is not None and int(sol.steps) >= MAX_REFERENCE_STEPS:  # diffrax: "Try increasing
                # `max_steps`", which no command line can do
                budget = f"its budget of {MAX_REFERENCE_STEPS:,} steps (steplab.integrators.references." \
                         "MAX_REFERENCE_STEPS)"
                if sol.evaluations is not None and sol.evaluations < MAX_REFERENCE_STEPS * EVALUATIONS_PER_STEP:
                    # scipy, stopped by the rate of its evaluations (_project_budget) before it spent them
                    what = f"it would need more than {budget} to reach the end of the run ({sol.message})"
                else:
                    what = f"it took {budget} before the end of the run"
                raise ReferenceFailedError(f"{self.name} failed: {what}: a shorter run, or for a stiff scene an "
                                           "implicit reference (diffrax-kvaerno5, scipy-radau)")
            raise ReferenceFailedError(f"{self.name} failed: {sol.message}")
        return np.asarray(sol.ys)


def _check_autodiff_jacobian(name, model, t0, y0):
    """Raise :class:`ReferenceFailedError` if JAX's derivative of the vector field is not finite at ``y0``.

    An implicit diffrax solve linearises the vector field by automatic differentiation; a NaN there made
    every Newton solve fail and every step be rejected until its million-step budget was spent (minutes):
    so it was with the quadratic drag's |v| v differentiated through |v| at a body at rest (the tests'
    mixed problem's pinned anchor), before :func:`steplab.physics._array.speed`, and so it would be with a
    plugin's force of the same kind. One Jacobian-vector product shows it: a NaN entry spreads to the
    product whatever the tangent.
    """
    import jax
    import jax.numpy as jnp

    _, tangent = jax.jvp(lambda y: model.vector_field(t0, y), (y0,), (jnp.ones_like(y0),))
    bad = np.argwhere(~np.isfinite(np.asarray(tangent)))
    if bad.size:
        raise ReferenceFailedError(
            f"{name} failed: the vector field's derivative (JAX autodiff) is not finite at the initial state "
            f"({'velocity' if bad[0][0] else 'position'} of body {bad[0][1]}; e.g. a force through sqrt or |x| at 0), "
            "so its Newton solves cannot converge: use scipy-radau (an analytic Jacobian) or diffrax-dopri8")


@dataclasses.dataclass(frozen=True)
class DiffraxReference(AdaptiveReference):
    """Adaptive diffrax solve with a PID step-size controller."""

    backend = "jax"


@dataclasses.dataclass(frozen=True)
class DiffraxDopri8(DiffraxReference):
    """8th order Dormand-Prince (diffrax.Dopri8), adaptive; the default reference."""

    name = "diffrax-dopri8"
    order = 8


@dataclasses.dataclass(frozen=True)
class DiffraxTsit5(DiffraxReference):
    """5th order Tsitouras (diffrax.Tsit5), adaptive."""

    name = "diffrax-tsit5"
    order = 5


@dataclasses.dataclass(frozen=True)
class DiffraxKvaerno5(DiffraxReference):
    """5th order ESDIRK Kvaerno5 (diffrax), adaptive; implicit, for stiff spring systems."""

    rtol: float = 1e-10
    atol: float = 1e-10

    name = "diffrax-kvaerno5"
    order = 5
    implicit = True
    scheme = "implicit"


@dataclasses.dataclass(frozen=True)
class ScipyReference(AdaptiveReference):
    """Adaptive ``scipy.integrate.solve_ivp``."""


def _first_order_jacobian(model, t, y):
    """d(v, a)/d(q, v) = [[0, I], [da/dq, da/dv]] for y = (q, v)."""
    dadq, dadv = model.jacobian(t, y[0], y[1])
    n3 = dadq.shape[0]
    return np.block([[np.zeros((n3, n3)), np.eye(n3)], [dadq, dadv]])


@dataclasses.dataclass(frozen=True)
class ScipyDOP853(ScipyReference):
    """8th order Dormand-Prince (scipy DOP853), adaptive."""

    name = "scipy-dop853"
    order = 8


@dataclasses.dataclass(frozen=True)
class ScipyRadau(ScipyReference):
    """5th order Radau IIA (scipy), adaptive; implicit, for stiff spring systems."""

    rtol: float = 1e-10
    atol: float = 1e-10

    name = "scipy-radau"
    order = 5
    implicit = True
    scheme = "implicit"
