"""One physics step by the contact solver, read as its stages (``[collisions] method = "solver"``).

    forces -> contacts (broadphase once, narrow phase) -> warm start -> substeps
           (velocities, solve, positions, relax) -> restitution -> events

This is how engines (Box2D, Bullet, PhysX, MuJoCo) handle contact, and it is not the
lecture's: instead of splitting the step at each impact and resolving impacts one after
another at their times (:mod:`.step`, the event loop, exact, the default), every contact
of the step is gathered once and all are solved together, iteratively, by sequential
impulses (:mod:`.sequential_impulses`), with the settings of :mod:`.solver_settings`. The
motion between contacts is semi-implicit Euler with the substep h = dt / substeps: the
scene's integrator must be semi-implicit Euler.

What it trades: the work per step is a fixed number of sweeps over the contacts, however
many impacts there are, and resting contact (piles, stacks) is solved as a whole instead
of as an endless series of tiny impacts. The price is accuracy: an impact is resolved
at the end of the step it happens in (not at its time), restitution acts on the approach
speed at the start of that step, and a chain of simultaneous contacts (Newton's cradle)
passes its impulse along only as far as the iterations reach. ``steplab study contacts``
measures each of these against the event loop.

Warm starting: each contact starts from its impulse of the last substep, and a contact
found again in the next step (the same pair) from its impulse at the end of this one, so
a pile at rest is solved in one sweep. Collision events: a contact that receives an
impulse in a step, having received none in the step before, is an impact; each one goes
through the world's prologues (one saying no cancels it: the step is solved again without
that pair, which is then left alone until the pair is no longer a contact, so a trigger
reports once) and after the solve, with its impulse, through the epilogues, into the log.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import sequential_impulses as si
from .contact_buffer import (
    BodyState,
    Contacts,
    Materials,
    find_contacts,
    newly_hit,
    previous_rows,
    speculative_margin,
    warm_start,
)
from .events import CollisionLog, ImpactBlock, cancel_triggers
from .resting import rest_speed
from .step import ConstantField

#: the semi-implicit Euler the solver's substeps are
INTEGRATOR = "semi-implicit-euler"


@dataclasses.dataclass
class SolverStep:
    """The contact solver's physics step of one run: ``step(t, y, dt, carry) -> (y, carry)``.

    Attributes
    ----------
    world : physics.collision.CollisionWorld
        With ``method = "solver"``; ``world.solver`` holds the settings.
    model : physics.Model
    integrator : Stepper
        Semi-implicit Euler (what the substeps are).
    log : CollisionLog
        Every impact of the run; ``log.largest_residual`` is the largest complementarity
        residual (m/s) left by the solver at the end of a step.
    """

    world: object
    model: object
    integrator: object
    log: CollisionLog = dataclasses.field(default_factory=CollisionLog)

    def __post_init__(self):
        check_solver_integrator(self.integrator, self.world)
        self.settings = self.world.solver
        self.radii = np.asarray(self.model.radii, dtype=float)
        self.inverse_masses = np.ascontiguousarray(self.model.inverse_masses, dtype=float)
        field = self.model.constant_acceleration  # (N, 3) when every force is constant, else None
        self.field = None if field is None else np.array(field, dtype=float, order="C")  # writable: one kernel type
        self.materials = Materials.of(self.world, len(self.radii))
        self.margin = speculative_margin(self.radii)
        self.log.largest_residual = 0.0
        # the built-in prologue says no to triggers only: asked here without a call per impact
        self._prologues = tuple(p for p in self.world.prologues if p is not cancel_triggers)
        self._triggers_cancel = len(self._prologues) < len(self.world.prologues)
        # nobody to ask or tell about each impact: the log takes them as columns (ImpactBlock)
        self._columnar = not (self._prologues or self.world.epilogues or any(s.trigger for s in self.world.shapes))
        self._previous = _NO_CONTACTS  # last step's contacts: keys (sorted), impulses, whether hit
        self._cancelled = set()  # keys of pairs a prologue cancelled, until they are no longer contacts
        load_kernels(self.world, self.field is not None, self.integrator)

    def __call__(self, t, y, dt, carry):
        """Advance ``y`` (2, N, 3) from ``t`` by ``dt``; returns ``(y, carry)``, in ``y``'s precision: the
        solver computes in float64 (its kernels are compiled for it), and a float32 run carries its
        state from step to step in float32, as a game engine stores its bodies."""
        start = self.prepare(t, y, dt)
        return self.conclude(start, *self.solve(start)).astype(np.asarray(y).dtype, copy=False), carry

    # --- stages --------------------------------------------------------------------------

    def prepare(self, t, y, dt) -> StepStart:
        """Forces, contacts and warm start: everything the kernel needs for the step from ``t``."""
        q0, v0 = np.ascontiguousarray(y[0], dtype=float), np.ascontiguousarray(y[1], dtype=float)
        a = self.field if self.field is not None else np.asarray(self.model.acceleration(t, q0, v0), dtype=float)
        # where the forces alone take each body in the step: the scene's integrator's step under
        # the accelerations at its start (semi-implicit Euler: q + dt (v + dt a))
        y_forces, _ = self.integrator.step(ConstantField(a), t, np.asarray(y, dtype=float), dt, None)
        contacts = find_contacts(self.world, self.materials, BodyState(q0, v0, a, self.radii, self.inverse_masses),
                                 np.ascontiguousarray(y_forces[0]), self.log.removed, self.margin)
        if self._cancelled:
            self._cancelled &= set(contacts.key.tolist())  # pairs no longer in contact are free again
            contacts = contacts.subset(~np.isin(contacts.key, list(self._cancelled)))
        return self._start(t, dt, q0, v0, a, contacts)

    def _start(self, t, dt, q0, v0, a, contacts) -> StepStart:
        s = self.settings
        h = dt / s.substeps
        threshold = rest_speed(self.world.rest_speed, contacts.pressing, dt)
        old = self._previous
        previous = previous_rows(old.contacts.key, contacts.key)
        pn, pt = warm_start(previous, old.pn, old.pt, contacts.normal)
        return StepStart(t, dt, h, q0, v0, a, contacts, threshold, s.softness(h), pn, pt, previous)

    def solve(self, start: StepStart):
        """The substeps and the restitution pass; returns (q, v, solved contacts)."""
        s, c = self.settings, start.contacts
        bias_rate, mass_scale, impulse_scale = start.softness
        n, m, h = len(self.radii), len(c), start.h
        if self.field is not None:  # constant forces: the whole step in one compiled call
            [result] = solve_members([start], [s], np.array([0, n]), self.inverse_masses, start.a)
            return result
        q, v = start.q.copy(), start.v.copy()
        columns = _contact_columns(c, start.threshold, start.pn.copy(), start.pt.copy())
        sub = si.Substep(h, s.iterations, bias_rate, mass_scale, impulse_scale, s.push_speed, s.slop)
        dq = np.zeros_like(q)  # forces of the state: evaluated in every substep
        for k in range(s.substeps):
            a_k = start.a if k == 0 else np.asarray(self.model.acceleration(start.t + k * h, q, v), dtype=float)
            bodies = si.BodyColumns(q, v, dq, self.inverse_masses, np.ascontiguousarray(a_k))
            si.substep(bodies, columns, 0, n, 0, m, sub)
        residual = si.finish(si.BodyColumns(q, v, dq, self.inverse_masses, start.a), columns, 0, m, sub)
        pn, pt, total = columns.pn, columns.pt, columns.total
        return q, v, Solved(c, pn, pt, total, residual)

    def conclude(self, start: StepStart, q, v, solved) -> np.ndarray:
        """Events through the prologues (solving again without what they cancel), the epilogues,
        the log, and what the next step warm-starts from; returns the new state (2, N, 3)."""
        if self._columnar:
            block, _ = self._impacts(start, solved)
            self.log.add_impacts(block)
            return self._close(start, q, v, solved, len(block))
        asked, said_no = set(), []  # keys the prologues have seen this step, and the events they cancelled
        while True:
            events, cancelled = self._events(start, solved, asked)
            said_no += [e for e in events if e.kind != "impact"]
            if not cancelled:
                break
            self._cancelled |= cancelled
            keep = ~np.isin(start.contacts.key, list(cancelled))
            start = self._start(start.t, start.dt, start.q, start.v, start.a, start.contacts.subset(keep))
            q, v, solved = self.solve(start)
        events = said_no + [e for e in events if e.kind == "impact"]
        for event in events:
            self.log.events.append(event)
            if event.kind == "impact":
                for epilogue in self.world.epilogues:
                    epilogue(event, self.log)
        return self._close(start, q, v, solved, sum(e.kind == "impact" for e in events))

    def _close(self, start: StepStart, q, v, solved, impacts: int) -> np.ndarray:
        """The log's counters, what the next step warm-starts from, and the new state (2, N, 3)."""
        self.log.most_impacts_in_a_step = max(self.log.most_impacts_in_a_step, impacts)
        self.log.largest_residual = max(self.log.largest_residual, solved.residual)
        self._previous = solved
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise FloatingPointError(non_finite(self.model.names, start.t, self.log.largest_residual,
                                                position=q, velocity=v))
        return np.stack([q, v])

    def _impacts(self, start: StepStart, solved) -> tuple[ImpactBlock, np.ndarray]:
        """Impacts of the step, the contacts hit now (an impulse) and not in the last step, and their keys."""
        t, dt = start.t, start.dt
        k = np.flatnonzero(newly_hit(solved.total, start.previous, self._previous.total))
        c = start.contacts.subset(k)
        approach = -c.normal_speed
        # the time of touching, had the approach speed stayed what it was; in the bracket (t, t + dt)
        t_touch = t + np.where(approach > 0, np.minimum(np.maximum(c.separation, 0.0) / np.where(
            approach > 0, approach, 1.0), dt), 0.0)
        return ImpactBlock(t_touch, c.i, np.where(c.j >= 0, c.j, -1 - c.shape), c.normal, approach, c.restitution,
                           c.friction, solved.total[k], (float(t), float(t + dt)), self.model.names,
                           self.world.shapes), c.key

    def _events(self, start: StepStart, solved, asked: set):
        """The step's impacts (:meth:`_impacts`) as collisions, through the prologues.

        Returns (events, keys cancelled now); each pair meets the prologues once per step.
        """
        block, keys = self._impacts(start, solved)
        events, cancelled = [], set()
        for event, key in zip(block.collisions(), keys.tolist()):
            if key not in asked:
                asked.add(key)
                if ((event.trigger and self._triggers_cancel)
                        or not all(prologue(event, self.log) for prologue in self._prologues)):
                    event.kind, event.impulse = ("trigger" if event.trigger else "cancelled"), 0.0
                    cancelled.add(key)
            events.append(event)
        return events, cancelled


_LOADED = set()  # (broadphase, constant forces) whose solver kernels this process has loaded


def load_kernels(world, constant_forces: bool, integrator) -> None:
    """Step two touching balls on a floor, under gravity (constant forces: the one-call kernel)
    or gravity and drag (the per-substep kernels), with ``world``'s broadphase, so that every
    compiled kernel of that step is loaded (Numba reads each from its disk cache on first use,
    about 40 ms apiece) before a run starts, and a run's wall time is its steps'. The floor's
    world is made by ``type(world)``: this module does not import the world, which imports it."""
    broadphase = world.broadphase
    if (broadphase, constant_forces) in _LOADED:
        return
    _LOADED.add((broadphase, constant_forces))
    from ..drag import Drag
    from ..gravity import Gravity
    from ..model import Model
    from .shapes import Plane

    model = Model(np.ones(2), np.full(2, 0.1), [Gravity()] + ([] if constant_forces else [Drag(np.full(2, 0.01))]))
    floor = Plane(np.array([0.0, 0.0, 1.0]))
    world = type(world)(shapes=(floor,), method="solver", broadphase=broadphase)
    y = np.array([[[0.0, 0.0, 0.1], [0.19, 0.0, 0.1]], [[0.0, 0.0, -1.0], [-1.0, 0.0, -1.0]]])
    step = SolverStep(world, model, integrator)
    step(0.0, step(0.0, y, 0.01, None)[0], 0.01, None)  # twice: the warm start's merge too


def solve_members(starts, settings, bodies, inverse_mass, accel, parallel=False):
    """The substeps and restitution passes of members under constant forces, in one kernel call.

    ``starts`` (their :class:`StepStart`) and ``settings`` per member; ``bodies`` the offsets of
    their bodies in ``inverse_mass`` and ``accel``, all members' joined. ``parallel``: spread
    the members over the cores (a batch; one member runs faster serially). Returns, per
    member, (q, v, solved).
    """
    counts = np.array([len(start.contacts) for start in starts])
    contacts = np.concatenate([[0], np.cumsum(counts)])
    shift = [bodies[m] for m in range(len(starts))]

    joined = Contacts(*[np.concatenate([getattr(start.contacts, f.name) for start in starts])
                        for f in dataclasses.fields(Contacts)])
    joined.i = np.concatenate([start.contacts.i + shift[m] for m, start in enumerate(starts)])
    joined.j = np.concatenate([np.where(start.contacts.j >= 0, start.contacts.j + shift[m], -1)
                               for m, start in enumerate(starts)])
    joined.normal = joined.normal.reshape(-1, 3)
    columns = _contact_columns(joined, np.concatenate([start.threshold for start in starts]),
                               np.concatenate([start.pn for start in starts]),
                               np.concatenate([start.pt for start in starts]).reshape(-1, 3))
    q = np.concatenate([start.q for start in starts])
    v = np.concatenate([start.v for start in starts])
    residual = np.zeros(len(starts))
    soft = np.array([start.softness for start in starts])
    members = si.Members(bodies, contacts, np.array([start.dt for start in starts]),
                         np.array([s.substeps for s in settings]), np.array([s.iterations for s in settings]),
                         np.ascontiguousarray(soft[:, 0]), np.ascontiguousarray(soft[:, 1]),
                         np.ascontiguousarray(soft[:, 2]), np.array([s.push_speed for s in settings]),
                         np.array([s.slop for s in settings]))
    (si.step_members_parallel if parallel else si.step_members)(
        si.BodyColumns(q, v, np.zeros_like(q), inverse_mass, accel), columns, members, residual)
    pn, pt, total = columns.pn, columns.pt, columns.total
    results = []
    for m, start in enumerate(starts):
        b, c = slice(bodies[m], bodies[m + 1]), slice(contacts[m], contacts[m + 1])
        results.append((q[b].copy(), v[b].copy(),
                        Solved(start.contacts, pn[c].copy(), pt[c].copy(), total[c].copy(), float(residual[m]))))
    return results


def _contact_columns(c: Contacts, threshold, pn, pt) -> si.ContactColumns:
    """The solver kernels' contact constraints: ``c``'s columns, the warm start (pn, pt; changed in place)."""
    return si.ContactColumns(c.i, c.j, c.normal, c.separation, c.normal_speed, c.mass, c.friction, c.restitution,
                             threshold, pn, pt, np.zeros(len(pn)), np.zeros(len(pn)))


@dataclasses.dataclass(frozen=True)
class StepStart:
    """What a step starts from: the state, the accelerations, the contacts and their warm start."""

    t: float
    dt: float
    h: float  # the substep, s
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    contacts: Contacts
    threshold: np.ndarray  # approach speeds at or below this do not bounce, m/s
    softness: tuple  # (bias rate, mass scale, impulse scale) of the correction
    pn: np.ndarray
    pt: np.ndarray
    previous: np.ndarray  # each contact's row in the last step's contacts, -1 if it was none


@dataclasses.dataclass(frozen=True)
class Solved:
    """A step's contacts with their impulses: the last substep's (pn, pt), the step's total, the residual."""

    contacts: Contacts
    pn: np.ndarray
    pt: np.ndarray
    total: np.ndarray
    residual: float = 0.0


_EMPTY = np.zeros(0)
_NO_CONTACTS = Solved(Contacts.empty(),
                       _EMPTY, np.zeros((0, 3)), _EMPTY)


def check_solver_integrator(integrator, world) -> None:
    """The one line (ValueError) for a contact-solver ``world`` stepped by another integrator than
    :data:`INTEGRATOR`, whose stages the solver's substeps are; the event loop is the alternative for
    spheres only (``world.rigid``: boxes and capsules have no other method)."""
    if getattr(integrator, "name", None) != INTEGRATOR:
        other = "" if world.rigid is not None else ", or the collision method 'event'"
        raise ValueError(f"the contact solver integrates with {INTEGRATOR} (velocities, contacts, then positions, "
                         f"per substep), not '{integrator.name}'; use integrator '{INTEGRATOR}'{other}")


def non_finite(names, t: float, residual: float, **rows) -> str:
    """The contact solver's one line for a state that became non-finite in the step from ``t``,
    naming the first body one of whose ``rows`` (each (N, 3), by its quantity: ``position=q``,
    ``velocity=v``, ``angular_velocity=omega``) is not finite, and which of them are not. A step
    that checks as it goes passes the quantities it has changed so far, so those named are the
    ones that went first."""
    finite = {name: np.all(np.isfinite(row), axis=1) for name, row in rows.items()}
    body = int(np.argmin(np.all(list(finite.values()), axis=0)))  # the first body not finite
    quantities = [name.replace("_", " ") for name, ok in finite.items() if not ok[body]]
    which = ", ".join(quantities[:-1]) + " and " * (len(quantities) > 1) + quantities[-1]
    return (f"the contact solver's state became non-finite at body {names[body]!r} in the step from t = {t:g} s "
            f"(its {which}; largest residual {residual:.3g} m/s)")
