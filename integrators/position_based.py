"""Position-based dynamics: ``pbd`` (Mueller et al. 2007) and ``xpbd`` (Macklin et al. 2016), with substeps.

Both act on the model's springs as distance constraints (:meth:`Model.distance_constraints`:
a spring of stiffness k is a constraint of compliance alpha = 1 / k, ``inf`` an inextensible
one) and on its constant forces (gravity, constant forces) as external accelerations; a
model with other forces is refused in one line. One step of dt is ``substeps`` substeps of
h = dt / substeps, each:

    v* = v + h a_ext,   x = q + h v*                           (predict)
    ``iterations`` Gauss-Seidel sweeps over the constraints    (project, :mod:`.constraint_projection`)
    v1 = (x - q) / h,   q1 = x                                  (update velocities)

XPBD's converged sweep is implicit Euler on the springs (its multiplier lambda = -C / alpha
is the spring force times h^2), so it is stable at every dt and damps like implicit Euler;
with substeps and one iteration it is Macklin et al.'s "Small steps in physics simulation"
(SCA 2019). On NumPy the sweep is a Numba loop; on JAX (``backend="jax"``, the compiled loop)
the same Gauss-Seidel sweep in the same colour order, traced (:mod:`.constraint_projection_jax`).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, NamedTuple

import numpy as np

from . import linear_stability
from .base import Integrator, check_count

#: displacement and velocity of the linear map's basis states, m, m/s: along the spring's axis
#: C = x - l_rest is exactly linear, so any size that keeps x > 0 gives the map to round-off
LINEAR_AMPLITUDE = 0.25
#: the most substeps a step of pbd, xpbd or vbd takes, and the most iterations (sweeps over the
#: constraints) a substep takes: settings above them are refused in one line. Real use is 1 to a few
#: hundred of each (Macklin et al.'s small steps: tens of substeps of one iteration; vbd's tests: 400
#: iterations); 10^4 is far above that and still a bounded step, where 10^11 never ends
MAX_SUBSTEPS = 10_000
MAX_ITERATIONS = 10_000
#: the most sweeps, substeps x iterations, a step takes: a sweep over the 1,000 springs of the
#: built-in cloth takes about 3 us, so a step at this bound takes about 0.3 s there (10^4 x 10^4
#: would take five minutes a step)
MAX_SWEEPS = 100_000


class SweepCarry(NamedTuple):
    """What a pbd or xpbd run keeps between steps, its bodies in the sweep's rows: body b of the model is
    row ``rows[b]`` (:func:`.arrangement.arranged`). The ``constraints`` on the rows in the sweep's order
    (:func:`.constraint_projection.wavefront` of the colour order), ``external`` (3, M), m/s^2, as
    coordinate rows (:func:`.constraint_projection.coordinates`), ``inverse_mass`` (N,), 1/kg, ``work``
    (:class:`.constraint_projection.Workspace`), the step's scratch, ``segments`` (where each run of one
    colour starts), and ``sweep``, the columns the kernel reads for substeps of ``h``
    (:func:`.constraint_projection.sweep_columns`; None before the first step, rebuilt when the step
    changes)."""

    constraints: tuple
    external: np.ndarray
    inverse_mass: np.ndarray
    work: tuple
    segments: np.ndarray
    rows: np.ndarray
    h: float = float("nan")
    sweep: tuple | None = None

    def in_rows(self, y):
        """The state ``y`` (2, N, 3), each body in its row of the sweep, and the external accelerations (N, 3)
        in the same rows: what a loop over :attr:`constraints` reads (copies)."""
        from .arrangement import in_rows
        from .constraint_projection import bodies

        return in_rows(np.asarray(y, float), self.rows, axis=1), np.array(bodies(self.external, len(self.rows)))

    def for_substep(self, h: float) -> SweepCarry:
        """This carry with its ``sweep`` for substeps of ``h`` (itself when it has it)."""
        from .constraint_projection import sweep_columns

        if h == self.h:
            return self
        return self._replace(h=h, sweep=sweep_columns(self.constraints, self.segments, self.inverse_mass, h))


@dataclasses.dataclass(frozen=True)
class PositionBased(Integrator):
    """Predict, project the distance constraints, update velocities; ``substeps`` x ``iterations``.

    A fixed-step method like a :class:`~.base.Stepper` (``init``, ``step``, a linear map and
    its stability theory), but a kind of its own, ``"position-based"``: it steps only models
    of springs, dampers and constant forces, on NumPy, so what is parametrised over every
    Stepper (studies, drag and JAX tests) leaves it out, and it has its own tests.

    Parameters
    ----------
    substeps : int
        Substeps of h = dt / substeps per step, 1 to :data:`MAX_SUBSTEPS`.
    iterations : int
        Gauss-Seidel sweeps over the constraints per substep, 1 to :data:`MAX_ITERATIONS`;
        substeps x iterations at most :data:`MAX_SWEEPS`.
    """

    substeps: int = 1
    iterations: int = 10

    order = 1
    implicit = True
    kind = "position-based"
    #: whether the sweep carries the multipliers lambda between iterations (XPBD) or not (PBD)
    accumulate: ClassVar[bool]
    stability_note = "none (stable at every dt)"
    #: no scalar stability function: the map on the oscillator is a matrix (:meth:`linear_map`)
    stability_function = None

    @property
    def evaluations(self) -> int:
        """Constraint sweeps per step, substeps x iterations (each one pass over the springs, as a force evaluation)."""
        return self.substeps * self.iterations

    def __post_init__(self):
        where = "steplab.integrators.position_based"
        check_count(self.name, "substeps", self.substeps, MAX_SUBSTEPS, f"{where}.MAX_SUBSTEPS")
        check_count(self.name, "iterations", self.iterations, MAX_ITERATIONS, f"{where}.MAX_ITERATIONS")
        if self.substeps * self.iterations > MAX_SWEEPS:
            raise ValueError(f"{self.name}: substeps x iterations must be at most {MAX_SWEEPS:,} sweeps a step "
                             f"({where}.MAX_SWEEPS), got {self.substeps:,} x {self.iterations:,} = "
                             f"{self.substeps * self.iterations:,}")

    def constraints(self, model):
        """The model's springs as constraints, its external accelerations (N, 3) and inverse masses (N,)
        (NumPy, float64), refusing (one line) what the method cannot step: other forces, negative compliance."""
        c = model.distance_constraints()  # refuses forces it cannot express, before the first step
        bad = np.flatnonzero((c.compliance < 0) | (c.damping < 0))
        if bad.size:
            p = bad[0]
            raise ValueError(f"{self.name}: the spring between bodies {c.i[p]} and {c.j[p]} has compliance "
                             f"{c.compliance[p]:g} m/N and damping {c.damping[p]:g} N s/m; both must be >= 0 "
                             "(a stiffness k > 0, alpha = 1 / k)")
        field = None if model.constant_field is None else np.asarray(model.constant_field, float)
        external = np.zeros((model.n_bodies, 3)) if field is None else np.broadcast_to(field, (model.n_bodies, 3))
        # copies (np.array): a read-only view of the field would be another Numba type, another compile
        return c, np.array(external, float), np.array(model.inverse_masses, float)

    def init(self, model, t, y):
        """What :meth:`step` keeps for a run: the constraints in the sweep's colour order
        (:func:`.constraint_projection.ordered`), swept in bands (:func:`.constraint_projection.wavefront`,
        the same bytes), the external accelerations, the inverse masses and the scratch the step
        writes (a :class:`SweepCarry`); on the JAX backend the constraints in colour order as a
        padded table by colour (:class:`.constraint_projection_jax.ColourTable`)."""
        from .arrangement import arranged, in_rows
        from .constraint_projection import coordinates, ordered, workspace

        c, external, inverse_mass = self.constraints(model)
        c, colours = ordered(c, model.n_bodies)
        if model.xp is not np:
            from .constraint_projection_jax import colour_table

            return colour_table(c, colours, inverse_mass, external, model.dtype)
        rows, c, segments = arranged(c, colours, model.n_bodies)
        return SweepCarry(c, coordinates(in_rows(external, rows)), in_rows(inverse_mass, rows),
                          workspace(model.n_bodies, len(c.i)), segments, rows)

    def substep(self, dt: float) -> float:
        """The substep h = dt / substeps; ValueError (one line) where it underflows to 0 (dt = 5e-324 s in 2
        substeps), which every projection and vertex solve divides by."""
        h = dt / self.substeps
        if not h > 0:
            raise ValueError(f"{self.name}: dt = {dt:g} s in {self.substeps} substeps gives the substep h = dt / "
                             f"substeps = {h:g} s (it underflows): a larger dt, or fewer substeps")
        return h

    def check_dt(self, model, dt: float) -> None:
        """Refuses (one line, naming the spring) a spring too soft or a damper too heavy for the substeps of
        ``dt``: where alpha / h^2 or gamma = alpha c / h passes the float range the projection moves bodies by
        NaN. Both backends (:func:`.simulate.simulate` calls it for JAX, whose step traces dt)."""
        from .projection_law import factors

        c, _, inverse_mass = self.constraints(model)
        h = self.substep(dt)
        with np.errstate(over="ignore", invalid="ignore"):
            alpha_tilde, gamma, denominator = factors(c.compliance, c.damping, inverse_mass[c.i] + inverse_mass[c.j],
                                                      h)
        bad = np.flatnonzero(~np.isfinite(denominator))
        if bad.size:
            p = bad[0]
            if not np.isfinite(alpha_tilde[p]):  # the compliance's term, whatever the damping
                raise ValueError(f"{self.name}: the spring between bodies {c.i[p]} and {c.j[p]}: its compliance "
                                 f"{c.compliance[p]:g} m/N gives alpha / h^2 = {alpha_tilde[p]:g} at the substep "
                                 f"h = {h:g} s; it must be finite (a stiffer spring, or a longer substep)")
            raise ValueError(f"{self.name}: the spring between bodies {c.i[p]} and {c.j[p]}: its damping "
                             f"{c.damping[p]:g} N s/m with compliance {c.compliance[p]:g} m/N gives "
                             f"gamma = alpha c / h = {gamma[p]:g} at the substep h = {h:g} s; it must be finite "
                             "(a smaller damping)")

    def substeps_of(self, dt: float):
        """:class:`.constraint_projection.Substeps` of a step of ``dt``."""
        from .constraint_projection import Substeps

        return Substeps(dt / self.substeps, self.substeps, self.iterations, self.accumulate and self.iterations > 1)

    def step(self, model, t, y, dt, carry):
        from .constraint_projection import advance, bodies  # Numba: only when a position-based run steps

        if carry is None:  # a caller that did not call init
            carry = self.init(model, t, y)
        steps = self.substeps_of(dt)
        if model.xp is not np:
            from .constraint_projection_jax import advance as traced

            return model.xp.stack(traced(carry, y[0], y[1], steps)), carry
        if steps.h != carry.h:
            self.check_dt(model, dt)
        carry = carry.for_substep(steps.h)
        state = bodies(carry.work.state, model.n_bodies)  # (2, N, 3) view of the rows the kernel steps in place
        state[:, carry.rows] = y
        advance(carry.work.state[0], carry.work.state[1], carry.external, carry.inverse_mass, carry.sweep, steps,
                carry.work)
        return state[:, carry.rows].astype(y.dtype, copy=False), carry

    def linear_map(self, omega_dt: float, zeta: float = 0.0) -> np.ndarray:
        """One-step matrix on u'' = -u - 2 zeta u', from :meth:`step` on a spring of k = 1 to a
        pinned anchor (m = 1, damper 2 zeta): along its axis C = x - l_rest is linear, so the
        step is exactly linear in (u, v)."""
        from steplab.physics import Dampers, Model, Springs

        i, j = np.array([0]), np.array([1])
        forces = [Springs(i, j, np.ones(1), np.ones(1))]
        if zeta:
            forces.append(Dampers(i, j, np.array([2.0 * zeta])))
        model = Model(np.ones(2), np.ones(2), forces, pinned=np.array([True, False]))
        carry = self.init(model, 0.0, None)
        columns = []
        for u, v in ((1.0, 0.0), (0.0, 1.0)):
            y = np.zeros((2, 2, 3))
            y[0, 1, 0], y[1, 1, 0] = 1.0 + LINEAR_AMPLITUDE * u, LINEAR_AMPLITUDE * v
            y1, _ = self.step(model, 0.0, y, float(omega_dt), carry)
            columns.append([(y1[0, 1, 0] - 1.0) / LINEAR_AMPLITUDE,
                            y1[1, 1, 0] / LINEAR_AMPLITUDE])
        return np.array(columns).T

    def spectral_radius(self, omega_dt: float, zeta: float = 0.0) -> float:
        """Largest |eigenvalue| of :meth:`linear_map`."""
        return linear_stability.spectral_radius(self, omega_dt, zeta)

    def stability_limit(self, zeta: float = 0.0) -> float | None:
        """Largest stable omega dt on the oscillator: None, stable at every dt (implicit Euler per substep)."""
        return linear_stability.stability_limit(self, zeta)

    def describe(self) -> dict:
        return super().describe() | {"substeps": self.substeps, "iterations": self.iterations,
                                     "stability_limit_omega_dt": self.stability_limit(0.0)}


@dataclasses.dataclass(frozen=True)
class PBD(PositionBased):
    """Position-based dynamics, stiffness as a per-iteration factor (Mueller et al. 2007); 1st order with one iteration.

    Each projection moves the constraint the fraction s = w / (w + alpha / h^2) = k h^2 w / (1 + k h^2 w)
    of the way to C = 0 (w the pair's inverse masses, k the spring's stiffness, h the substep):
    the fraction one XPBD projection removes from lambda = 0, applied in every iteration with
    no multiplier carried (Mueller et al., "Position based dynamics", 2007, section 3.3, with
    their stiffness k_pbd in [0, 1] taken as s). ``iterations`` sweeps remove 1 - (1 - s)^n of
    C, so the effective stiffness grows with the iterations: about n k as h -> 0 on one spring
    (period shortened by sqrt(n)); with one iteration, or k = inf (s = 1), PBD is XPBD.
    Dampers enter as in XPBD, without the multiplier.
    """

    name = "pbd"
    accumulate = False
    style = ("#7b4173", "p")  # plum: no other method has it

    @property
    def order(self) -> int:
        """1 with one iteration (then it is xpbd); 0 with more: it converges to springs of another stiffness."""
        return 1 if self.iterations == 1 else 0


@dataclasses.dataclass(frozen=True)
class XPBD(PositionBased):
    """1st order extended position-based dynamics, compliance alpha = 1 / k (Macklin, Mueller, Chentanez 2016).

    The multiplier lambda of each constraint accumulates over the iterations of a substep
    (their eq. 18): converged, the substep is implicit Euler on the springs, whatever the
    iteration count, and k keeps its meaning (the period of a mass on a spring tends to
    2 pi sqrt(m / k) as dt -> 0). alpha_tilde = alpha / h^2. A damper beta beside a spring
    enters as their eq. 26, gamma = alpha_tilde beta_tilde / h with beta_tilde = h^2 beta,
    i.e. gamma = beta / (k h); an inextensible constraint (alpha = 0) is undamped. With
    ``substeps = n, iterations = 1`` it is Macklin et al., "Small steps in physics
    simulation" (SCA 2019).
    """

    name = "xpbd"
    accumulate = True
    style = ("#5254a3", "d")  # periwinkle: no other method has it


class InPlaceStep(NamedTuple):
    """A position-based method stepping one state buffer in place, as a game engine does (the bench's
    step): ``advance(n)`` takes n steps of ``dt`` on ``state`` (2, N, 3), body b in row ``rows[b]``
    (:mod:`.arrangement`; :attr:`y` and :meth:`set` in the model's order), and allocates nothing; the
    bytes one step must move at the least are ``bytes_read_and_written`` (the state q, v) and
    ``bytes_read`` (the constraints, inverse masses and external accelerations), for the
    memory-traffic bound (``steplab.peers.memory_stream``); ``stream()``, where given, moves those bytes in
    one compiled pass computing nothing (the tighter bound) and returns the read ones' sum as integers."""

    state: np.ndarray
    rows: np.ndarray
    advance: object
    bytes_read_and_written: int
    bytes_read: int
    stream: object = None

    @property
    def y(self) -> np.ndarray:
        """The state q, v (2, N, 3) in the model's order (a copy)."""
        return self.state[:, self.rows]

    def set(self, y) -> None:
        """Put the state q, v (2, N, 3), in the model's order, where the step moves it."""
        self.state[:, self.rows] = y


def cloth_benchmark_step(model, y0, dt: float, method: PositionBased | None = None) -> InPlaceStep:
    """``method`` (default ``XPBD(substeps=1, iterations=1)``) on ``model`` from ``y0``, stepping in place.

    For the issue's benchmark, the cloth of ``steplab.bench.systems.cloth_model(160)``: 25,600
    particles, 101,442 springs with dampers. Each step is :func:`.constraint_projection.advance`,
    the kernel every pbd and xpbd step runs, on the carry :meth:`PositionBased.init` builds (so
    its result is :meth:`PositionBased.step`'s to the byte). The state lives where the kernel
    steps it, the coordinate rows (2, 3, M) of the carry's workspace, the bodies in the sweep's rows
    (:mod:`.arrangement`); ``state`` is their view (2, N, 3). Its bytes read and written are counted
    as (2, N, 3) float64, the least a step must move (the rows' ends past N, M - N = 8 to 15 values,
    are the step's own cost, not the bound's).

    Each step calls a compiled entry point resolved once, on one argument: a call through Numba's
    dispatcher types the kernel's seven arguments (three NamedTuples of 13 arrays) in Python
    first, about 30 us more from cold caches, and the kernel's own entry point still unboxes
    them one by one, 15 to 25 us more than one array; so the step passes the kernel a table of
    the arrays' addresses (:func:`.position_based_entry.advance_at`), as a game engine calling
    native code passes pointers. Its ``stream`` moves the bytes the step counts through the same table
    and the same kind of call, computing nothing (:func:`.position_based_entry.stream_at`).
    """
    from numba import typeof

    from .constraint_projection import bodies
    from .position_based_entry import advance_at, stream_at, table

    method = XPBD(substeps=1, iterations=1) if method is None else method
    substeps = method.substeps_of(dt)
    carry = method.init(model, 0.0, y0).for_substep(substeps.h)
    state = bodies(carry.work.state, model.n_bodies)
    arguments = table(carry.external, carry.inverse_mass, carry.sweep, substeps, carry.work)
    kernel = advance_at.compile((typeof(arguments),))  # loaded from Numba's cache where it is
    stream_kernel = stream_at.compile((typeof(arguments), typeof(1.0)))

    held = (arguments, carry)  # the table, and the arrays it points at, alive as long as the step

    def steps(n: int = 1) -> None:
        at = held[0]
        for _ in range(n):
            kernel(at)

    # the columns the sweep reads: alpha_tilde only where the multipliers are carried
    read = [a for name, a in carry.sweep._asdict().items() if name != "alpha_tilde" or substeps.carried]
    # and the external field as (N, 3) float64, as the model holds it (the rows' ends past N are the step's own)
    data = sum(a.nbytes for a in read) + carry.inverse_mass.nbytes + 3 * 8 * model.n_bodies

    def stream() -> int:
        return stream_kernel(held[0], 1.0)

    step = InPlaceStep(state, carry.rows, steps, state.nbytes, data, stream)
    step.set(y0)
    return step
