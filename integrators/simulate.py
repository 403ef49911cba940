"""The driver: run any integrator on a model, on NumPy step by step or as a compiled JAX loop."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from steplab.physics.attachments import attached_forces

from .base import Solver, Stepper, check_count, check_step_result
from .loop import compiled_loop, run_once
from .position_based import PositionBased

#: default step budget of one run; a larger run must ask for it explicitly
MAX_STEPS = 10_000_000
#: save_every takes any whole number from 1 (one beyond the run's steps keeps the first state and the last)
ANY_COUNT = 2**63 - 1
#: a state this many times larger than the initial one (or than 1) has diverged
DIVERGENCE_FACTOR = 1e12
#: relative slack when dividing the interval by dt, so 0.2 / 0.2 is one step, not zero
STEP_COUNT_SLACK = 1e-9
#: largest trajectory a run keeps in memory, bytes: a longer one must save fewer states
#: (save_every) instead of ending in an out-of-memory kill
MAX_TRAJECTORY_BYTES = 2 * 2**30


class DivergenceError(ArithmeticError):
    """The state became non-finite or absurdly large.

    Attributes name what a study needs to record "unstable": ``integrator``, ``dt``,
    ``step`` (1-based index of the first bad step) and ``t`` (its end time).
    """

    def __init__(self, integrator: str, dt: float, step: int, t: float):
        self.integrator, self.dt, self.step, self.t = integrator, dt, step, t
        super().__init__(f"integrator '{integrator}' diverged with dt = {dt:g} s: the state is "
                         f"non-finite or beyond the divergence limit at step {step} (t = {t:g} s)")


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Saved states of a run.

    Attributes
    ----------
    t : ndarray, shape (K,)
    y : ndarray, shape (K, 2, N, 3)
        Positions ``y[:, 0]`` and velocities ``y[:, 1]`` at the saved times.
    steps : int
        Fixed steps taken (0 for a solver).
    wall_time : float
        Seconds spent integrating (for JAX: compilation excluded, see ``compile_time``).
    collisions : physics.collision.CollisionLog or None
        Every collision of the run, when it was run with collisions.
    """

    t: np.ndarray
    y: np.ndarray
    integrator: str
    dt: float
    steps: int
    backend: str
    wall_time: float
    compile_time: float = 0.0
    collisions: object = None

    @property
    def positions(self) -> np.ndarray:
        return self.y[:, 0]

    @property
    def velocities(self) -> np.ndarray:
        return self.y[:, 1]


def step_count(t_start: float, t_end: float, dt: float) -> int:
    """Whole fixed steps of ``dt`` in [t_start, t_end]; the run ends at t_start + n dt.

    ValueError when the count itself overflows (t_end = 1e300 with dt = 1e-10).
    """
    steps = np.floor((t_end - t_start) / dt * (1 + STEP_COUNT_SLACK))
    if not np.isfinite(steps):
        raise ValueError(f"[{t_start:g}, {t_end:g}] s holds more steps of dt = {dt:g} s than a float can count")
    return int(steps)


def steps_end(t_start: float, n_steps: int, dt: float) -> float:
    """The time ``n_steps`` steps of ``dt`` from ``t_start`` end at, t_start + n dt; ValueError when
    that overflows float64 (3 steps of dt = 1e308 s), as no clock of the run could count it."""
    t_end = t_start + int(n_steps) * dt
    if not np.isfinite(t_end):
        raise ValueError(f"{n_steps} steps of dt = {dt:g} s from t = {t_start:g} s end beyond the largest float64 "
                         f"time, {np.finfo(np.float64).max:g} s: use a smaller dt or fewer steps")
    return t_end


def check_time_advances(t_start: float, t_end: float, dt: float, dtype) -> None:
    """ValueError unless every step advances time: dt must be at least the floating-point
    spacing (one unit in the last place) at the run's largest |t|, in the run's precision,
    and that largest |t| a number of the precision (t_end = 1e300 s is none in float32).

    A smaller dt makes ``t + dt == t`` (or t + dt skip ahead unevenly): time would stand
    still while the state moves, or a loop ``while t < t_end: t += dt`` would never end.
    """
    largest = float(np.finfo(dtype).max)
    if not max(abs(t_start), abs(t_end)) <= largest:
        raise ValueError(f"t = {max(abs(t_start), abs(t_end)):g} s is beyond the largest {np.dtype(dtype).name} "
                         f"number, {largest:g}: the run's times cannot be represented (use times nearer 0, or a "
                         "wider precision)")
    t_far = np.asarray(max(abs(t_start), abs(t_end)), dtype=dtype)
    smallest = float(np.spacing(t_far))
    if not dt >= smallest:
        raise ValueError(f"dt = {dt:g} s is smaller than the {np.dtype(dtype).name} spacing {smallest:g} s at "
                         f"t = {float(t_far):g} s: t + dt would round back to t, so time would not advance "
                         "(use a larger dt, or a t_start nearer 0)")


def saved_steps(n: int, save_every: int) -> np.ndarray:
    """Indices of the saved states: every ``save_every``-th step, and always the last."""
    idx = np.arange(0, n + 1, save_every)
    return idx if idx[-1] == n else np.append(idx, n)


def divergence_limit(y0, dtype) -> float:
    """The largest |component| a sane state reaches: DIVERGENCE_FACTOR x max(1, |y0|).

    No game-physics scene legitimately grows a trillion-fold; an unstable integrator
    does so within a few hundred steps. The limit never exceeds sqrt(max float), beyond
    which squaring (energies) overflows.
    """
    scale = max(1.0, float(np.max(np.abs(y0))))
    return min(DIVERGENCE_FACTOR * scale, float(np.sqrt(np.finfo(dtype).max)))


def check_initial_state(model, y0, dtype) -> float:
    """The run's :func:`divergence_limit`; ValueError, one line naming the first body beyond it, when ``y0``
    (2, N, 3) already is: not finite, or so large that its squares (distances, energies) overflow ``dtype``
    (a body 1e300 m out in float64, 1e30 m in float32)."""
    dtype = np.dtype(dtype)
    limit = divergence_limit(y0, dtype)
    largest = float(np.max(np.abs(y0)))
    if not largest <= limit:  # also NaN
        y0 = np.asarray(y0, dtype=float)
        beyond = ~(np.abs(y0) <= limit)  # (2, N, 3)
        body = int(np.argmax(np.any(beyond, axis=(0, 2))))
        which = "position" if np.any(beyond[0, body]) else "velocity"
        raise ValueError(f"the initial state is non-finite or too large to integrate in {dtype.name}: body "
                         f"{model.names[body]!r} has {which} {y0[int(which == 'velocity'), body].tolist()} (largest "
                         f"|component| {largest:g}; states beyond {limit:g} count as diverged)")
    return limit


def simulate(model, integrator, y0, t_start: float, t_end: float | None = None, dt: float | None = None, *,
             n_steps: int | None = None, backend: str = "numpy", dtype=None, save_every: int = 1,
             max_steps: int = MAX_STEPS, progress: bool = False, stepper=None, collisions=None) -> Trajectory:
    """Integrate ``model`` from ``y0`` with fixed steps of ``dt``, to ``t_end`` or for ``n_steps``.

    Parameters
    ----------
    model : physics.Model
    integrator : str or Integrator
        A registry name or an integrator object.
    y0 : array, shape (2, N, 3)
    t_start, t_end : float
        The interval, s: the run takes the whole steps of ``dt`` that fit (see :func:`step_count`).
    dt : float
        The step, s (for a solver: the spacing of the saved times).
    n_steps : int, optional
        Exactly this many steps instead of ``t_end`` (give one of the two): the run ends
        at ``t_start + n_steps dt`` whatever the rounding of ``t_end / dt``.
    backend : {"numpy", "jax"}
        ``numpy`` steps in Python (readable, for teaching); ``jax`` compiles the whole
        loop (:func:`.loop.compiled_loop`). Solvers use the backend they need.
    dtype : float64 (default: the model's) or float32
    save_every : int
        Keep every ``save_every``-th state (the last state is always kept).
    max_steps : int
        Refuse runs longer than this (a guard against typos such as dt = 1e-9).
    progress : bool
        Show a progress bar (NumPy steppers).
    stepper : callable, optional
        ``stepper(model, integrator) -> step`` builds, once before the loop, the step the
        loop calls instead of the integrator's own: ``step(t, y, dt, carry) -> (y, carry)``,
        with an attribute ``log`` the trajectory keeps as ``collisions`` (None: nothing to
        add to the integrator's step). It receives the model on the run's backend and
        precision, and raises ValueError for an integrator or backend it cannot serve.
        Such a step runs in the NumPy loop, unless on JAX it has a method
        ``compiled(y0, t_start, dt, n, save_every, limit) -> Trajectory`` that runs the loop.
    collisions : physics.collision.CollisionWorld, optional
        Shorthand for ``stepper=collisions.stepper``: detect and resolve collisions after
        every step; the trajectory's ``collisions`` is the log of the run.

    Raises
    ------
    DivergenceError
        When the state becomes non-finite or absurdly large.
    """
    from .registry import get_integrator

    integrator = get_integrator(integrator)
    if backend not in ("numpy", "jax"):
        raise ValueError(f"backend must be 'numpy' or 'jax', got {backend!r}")
    if dt is None:
        raise ValueError("simulate needs the step dt")
    check_count("simulate", "save_every", save_every, ANY_COUNT, "a 64-bit integer")
    if np.shape(y0) != (2, model.n_bodies, 3):
        raise ValueError(f"simulate: y0 must have shape (2, {model.n_bodies}, 3) for this model ({model.n_bodies} "
                         f"bodies; positions and velocities, x y z), got {np.shape(y0)}")
    if collisions is not None:
        if stepper is not None:
            raise ValueError("give collisions or stepper, not both")
        stepper = collisions.stepper
    dtype = np.dtype(dtype or model.dtype)
    n = _requested_steps(t_start, t_end, n_steps, dt, dtype)
    if n > max_steps:
        raise ValueError(f"{n} steps of dt = {dt:g} s exceed the limit of {max_steps} "
                         f"(raise it with max_steps / --max-steps)")
    if n < 1:
        raise ValueError(f"t_end - t_start = {t_end - t_start:g} s is shorter than one step dt = {dt:g} s")
    saves = saved_steps(n, save_every)
    size = len(saves) * np.size(y0) * dtype.itemsize
    if size > MAX_TRAJECTORY_BYTES:
        raise ValueError(f"keeping {len(saves)} states of {np.size(y0)} numbers would take {size / 2**30:.3g} GiB, "
                         f"more than the limit of {MAX_TRAJECTORY_BYTES / 2**30:g} GiB (save fewer states: "
                         "save_every / --save-every)")
    ts = t_start + saves * dt
    limit = check_initial_state(model, y0, dtype)
    # the step the loop calls, built once with its context (a collision world's log, ...)
    step = None if stepper is None else stepper(_on_backend(model, backend, dtype), integrator)
    if step is None and attached_forces(model):
        # their lever arms turn with the bodies: only the attached step (or the contact solver) moves them; the
        # integrator's own step, or the detector "none"'s, would freeze them
        raise ValueError("simulate: this model has springs or dampers at body-frame points (offsets), which turn "
                         "with the bodies: pass stepper=attached_stepper(scene.rigid_bodies, rotation) "
                         "(steplab.integrators.attached), as steplab run does")

    if isinstance(integrator, Solver):
        backend = integrator.backend
        model = _on_backend(model, backend, dtype)
        start = time.perf_counter()
        ys = np.asarray(integrator.solve(model, ts, np.asarray(y0, dtype=dtype)), dtype=dtype)
        wall = time.perf_counter() - start
        bad = np.flatnonzero(~np.all(np.abs(ys) <= limit, axis=(1, 2, 3)))
        if bad.size:
            raise DivergenceError(integrator.name, dt, int(saves[bad[0]]), float(ts[bad[0]]))
        return Trajectory(ts, ys, integrator.name, dt, 0, backend, wall)

    assert isinstance(integrator, (Stepper, PositionBased))
    if backend == "jax" and hasattr(step, "compiled"):  # a step that compiles its own loop (attached forces)
        return step.compiled(np.asarray(y0, dtype=dtype), t_start, dt, n, save_every, limit)
    if backend == "jax" and isinstance(integrator, PositionBased):  # its compiled step traces dt
        integrator.check_dt(model, dt)
    run = _FixedStepRun(_on_backend(model, backend, dtype), integrator, np.asarray(y0, dtype=dtype), t_start, dt,
                        n, save_every, saves, ts, limit, progress, step)
    return _run_numpy(run) if backend == "numpy" or step is not None else _run_jax(run)


@dataclasses.dataclass(frozen=True)
class _FixedStepRun:
    """A fixed-step run as :func:`simulate` checked and planned it: what either loop needs.

    ``model`` is on the run's backend and precision and ``y0`` in it; the run takes ``n``
    steps of ``dt`` from ``t_start`` and keeps the states after the steps ``saves`` (every
    ``save_every``-th and the last), at the times ``ts``; a state beyond ``limit`` has
    diverged. ``step``: the step the loop calls instead of the integrator's (None: its own).
    """

    model: object
    integrator: object
    y0: np.ndarray
    t_start: float
    dt: float
    n: int
    save_every: int
    saves: np.ndarray
    ts: np.ndarray
    limit: float
    progress: bool
    step: object


def _requested_steps(t_start, t_end, n_steps, dt, dtype) -> int:
    """The number of steps of a run given by its end time or by its count (exactly one of them)."""
    if (t_end is None) == (n_steps is None):
        raise ValueError("give the end of the run as t_end or as n_steps (a whole number of steps), "
                         f"exactly one of them (got t_end = {t_end}, n_steps = {n_steps})")
    if n_steps is not None:
        if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 1:
            raise ValueError(f"n_steps must be a whole number of steps >= 1, got {n_steps!r}")
        check_time_advances(t_start, steps_end(t_start, n_steps, dt), dt, dtype)
        return int(n_steps)
    check_time_advances(t_start, t_end, dt, dtype)
    return step_count(t_start, t_end, dt)


def _on_backend(model, backend, dtype):
    if backend == "jax":
        import jax.numpy as jnp

        xp = jnp
    else:
        xp = np
    if model.xp is xp and model.dtype == dtype:
        return model
    return model.cast(xp, dtype)


def _run_numpy(run: _FixedStepRun) -> Trajectory:
    """The run stepped in Python, one step per iteration (and the collision steps)."""
    model, integrator, y, t_start, dt, n, saves, limit = (run.model, run.integrator, run.y0, run.t_start, run.dt,
                                                           run.n, run.saves, run.limit)
    out = np.empty((len(saves),) + y.shape, dtype=y.dtype)
    out[0] = y
    saved = 1
    bar = _progress_bar(n, run.progress)
    step = run.step
    if step is None:  # the plain ODE step

        def step(t, y, dt, carry):
            return integrator.step(model, t, y, dt, carry)

    start = time.perf_counter()
    carry = integrator.init(model, t_start, y)
    for k in range(n):
        result = step(t_start + k * dt, y, dt, carry)
        if k == 0:
            check_step_result(integrator, result, y.shape)
        y, carry = result
        # one reduction: NaN fails the comparison, so this also catches non-finite states
        if not np.abs(y).max() <= limit:
            raise DivergenceError(integrator.name, dt, k + 1, t_start + (k + 1) * dt)
        if saved < len(saves) and saves[saved] == k + 1:
            out[saved] = y
            saved += 1
        if bar is not None and (k + 1) % 1000 == 0:
            bar.update(1000)
    wall = time.perf_counter() - start
    if bar is not None:
        bar.close()
    return Trajectory(run.ts, out, integrator.name, dt, n, "numpy", wall, collisions=getattr(step, "log", None))


def _progress_bar(n, enabled):
    if not enabled or n < 100_000:
        return None
    from tqdm import tqdm

    return tqdm(total=n, unit="step", unit_scale=True, leave=False)


def _run_jax(run: _FixedStepRun) -> Trajectory:
    """The whole run as one compiled JAX loop (:func:`.loop.compiled_loop`), compiled apart from its timing."""
    integrator, y, t_start, dt, n = run.integrator, run.y0, run.t_start, run.dt, run.n
    loop = compiled_loop(run.model, integrator, chunks=len(run.saves) - 1, save_every=run.save_every)
    ys, bad, compile_time, wall = run_once(loop, y, t_start, dt, n, run.limit)
    if bad >= 0:
        raise DivergenceError(integrator.name, dt, bad, t_start + bad * dt)
    out = np.concatenate([y[None], np.asarray(ys)])
    return Trajectory(run.ts, out, integrator.name, dt, n, "jax", wall, compile_time)


def final_state_function(model, integrator, check: bool = True):
    """A jitted ``f(y0, t_start, dt, n) -> (y_n, first bad step or -1)`` for sweeps over dt.

    ``dt`` and ``n`` are traced, so one compilation serves a whole error-versus-dt or
    stability sweep (per model, integrator and precision). Studies time it with
    ``block_until_ready`` after a warm-up call. ``check=False`` leaves out the per-step
    divergence check (the bench measures what it costs); the bad step is then -1.
    """
    import jax
    import jax.numpy as jnp

    loop = compiled_loop(model, _stepper(integrator), check=check)

    def run(y0, t_start, dt, n):
        # the divergence limit of divergence_limit(), traced (without its overflow cap)
        return loop(y0, t_start, dt, n, DIVERGENCE_FACTOR * jnp.maximum(1, jnp.max(jnp.abs(y0))))

    return jax.jit(run)


def _stepper(integrator):
    from .registry import get_integrator

    integrator = get_integrator(integrator)
    if not isinstance(integrator, Stepper):
        raise ValueError(f"integrator '{integrator.name}' is not a fixed-step method")
    return integrator
