"""One physics step of the contact solver on rigid bodies that rotate, read as its stages.

    forces -> bounds (speed and rotation) -> broadphase -> manifolds -> sweep order (domains,
           each sorted) -> warm start by feature -> substeps (velocities and the gyroscopic term,
              solve, positions and orientations, relax) -> restitution -> impacts

``[collisions] method = "solver"`` on a scene with boxes, capsules or spinning spheres runs this
step (:class:`RigidSolverStep`); a scene of spheres that do not rotate keeps the sphere solver
(:mod:`.solver_step`) bit for bit. The kernels are :mod:`.rigid_solver`; the contact points come
from the narrow phase of :mod:`.manifolds` (up to 4 per pair, each with a feature id), once per
step at its start, with their normals kept through the substeps as Box2D and Box3D keep them.

Speculative contacts: a pair becomes a contact while its bodies' bounds can meet during the step.
Each body's bound is its bounding sphere swept from where it is to where its forces alone take
it, q + dt (v + dt a), widened by what its rotation can move a point of it, |omega| dt R (R its
bounding radius; at most 2 R, the diameter), as Box3D bounds it, and by a margin
(:data:`SPECULATIVE_OF_RADIUS` of the median bounding radius) for what a contact can add to its
speed within the step. Points found up to that margin apart are speculative: the solver lets them
close the gap, not pass it.

The rotation: each substep's velocity stage adds the gyroscopic term and its position stage
turns each orientation by h omega, both as the scene's rotation method does them when it is one
that composes with semi-implicit Euler (:data:`ROTATION_STAGES`); the others (explicit Euler, the
splittings and implicit rules of order 2 and more) have no place between the solver's velocity and
position stages and are refused in one line.

Springs and dampers at body-frame points (:mod:`steplab.physics.attachments`, a box hung by a
spring at its corner): their force on a centre depends on the orientations, through the lever
arms R(q) r, and they turn the bodies with the torque (R r) x F. With them, every substep
(the first's included, whose acceleration the step's bounds use) turns the lever arms of the
step's own model to the orientations and angular velocities now (:class:`.attachments.LeverArms`:
built once, turned in place) for the centres' acceleration, and kicks each body's world angular
velocity by h I_w^-1 tau, I_w^-1 = R diag(1/I1, 1/I2, 1/I3) R^T, just before the kernel's
substep: the torque is explicit, from the state at the substep's start, and the kernel's velocity
stage then adds the gyroscopic term to the kicked omega, Box3D's order and that of
``implicit-gyroscopic`` (torque, then the gyroscopic term), so that with one substep and no
contact the step is :mod:`steplab.integrators.attached`'s coupled step of semi-implicit Euler with
that method. The methods that take the torque and the gyroscopic
term both at the substep's start (``exponential-map``, ``first-order-quaternion``) or rescale
first (``momentum-rescaled``) differ from their coupled step by h^2 I^-1 (d(omega x I omega) /
d omega) I^-1 tau a step, first order as both are (nothing for a body of equal moments). The
bounds grow each body's turning speed by what its torque can add in the step, |omega| + dt |alpha|.
A pinned body neither moves nor turns (zero inverse inertia: no kick).
"""

from __future__ import annotations

import dataclasses
import importlib

import numba
import numpy as np

from .. import attachments
from .. import quaternion as quat
from . import rigid_solver as rs
from .chords import turning_bounds
from .contact_buffer import Materials
from .contact_domains import cut_into_domains, domain_count, lay_out
from .events import CollisionLog, ImpactBlock, cancel_triggers
from .heap import keep_freed_memory
from .manifolds import BOX, CAPSULE, SPHERE, check_shapes
from .pairs import SweptSpheres
from .rigid_columns import first_impacts, gather, inverse, is_sorted
from .solver_step import check_solver_integrator, non_finite
from .step import ConstantField

#: the rotation method's stages in the solver's substep, by its name: (gyroscopic term, orientation
#: update), each as that method writes it (:mod:`steplab.integrators.rotation`)
ROTATION_STAGES = {
    "exponential-map": ("explicit", "exponential"),
    "first-order-quaternion": ("explicit", "first-order"),
    "implicit-gyroscopic": ("implicit", "exponential"),
    "momentum-rescaled": ("rescaled", "exponential"),
}
#: the rotation method of a scene that names none (as steplab.integrators.rotation.DEFAULT_ROTATION)
DEFAULT_ROTATION = "exponential-map"
#: the shapes' numbers in :class:`.manifolds.RigidShapes`, by their names in a scene
KINDS = {"sphere": SPHERE, "box": BOX, "capsule": CAPSULE}
#: the most a rotation moves a point of a body: its diameter, 2 R (a half turn)
MAX_ROTATION_REACH = 2.0
#: the margin each body's bound adds for what a contact can add to its speed within the step, as a
#: fraction of the median bounding radius. A pair's constant part is twice this, 1/8 R: 0.022 m on the
#: bench's 0.2 m cubes, Box3D's speculative distance (4 linear slops, 0.02 m). Box3D stops there; here
#: each body's move under its forces and its rotation's reach come on top, so a falling or spinning
#: body's contacts are still known before it touches. The sphere solver's margin,
#: :data:`.contact_buffer.MARGIN_OF_RADIUS` (1/4), is four times wider: at 1/4 the 10^4-box pit's
#: steps 1 to 30 carried 51,000 points a step against 32,000, and the same 9,400 of them pressed
#: (docs/performance.md); every study scene gives the same bytes at either width
SPECULATIVE_OF_RADIUS = 1 / 16


@dataclasses.dataclass(frozen=True)
class RigidScene:
    """What the solver needs of a scene's rigid bodies besides the translational state.

    Attributes
    ----------
    kind : int8 ndarray, shape (N,)
        :data:`.manifolds.SPHERE`, ``BOX`` or ``CAPSULE`` for each of the N bodies.
    radius : ndarray, shape (N,)
        The sphere's or capsule's radius, m (0 for a box).
    half : ndarray, shape (N, 3)
        The box's half edges; a capsule's (0, 0, half its segment), m.
    bodies : physics.rigid_body.RigidBodies
        The rotating bodies and their state at the start of the run.
    rotation : str
        The rotation method (one of :data:`ROTATION_STAGES`).
    """

    kind: np.ndarray
    radius: np.ndarray
    half: np.ndarray
    bodies: object
    rotation: str = DEFAULT_ROTATION

    @property
    def has_corners(self) -> bool:
        """Whether some body is a box or a capsule (what the event loop cannot step)."""
        return bool(np.any((self.kind == BOX) | (self.kind == CAPSULE)))


def rotation_codes(rotation: str) -> tuple[int, int]:
    """The kernels' (gyroscopic, update) codes of a rotation method, or one line naming those that fit."""
    if rotation not in ROTATION_STAGES:
        raise ValueError(f"the contact solver's substeps are semi-implicit Euler; rotation method {rotation!r} "
                         f"does not compose with it; use one of {', '.join(ROTATION_STAGES)}")
    gyroscopic, update = ROTATION_STAGES[rotation]
    return rs.GYROSCOPIC[gyroscopic], rs.UPDATES[update]


def contact_columns(count: int) -> rs.RigidContactColumns:
    """Columns for ``count`` contacts, to be filled (:func:`.rigid_columns.gather`, :func:`.rigid_solver.prepare`)."""
    return rs.RigidContactColumns(
        np.empty(count, np.int64), np.empty(count, np.int64), *(np.empty((count, 3)) for _ in range(3)),
        np.empty((count, 2, 3)), *(np.empty(count) for _ in range(3)), np.zeros((count, 3)),
        *(np.empty(count) for _ in range(4)), np.empty(count), np.empty((count, 2)), np.empty((count, 3)),
        np.empty(count), np.empty(count), np.zeros(count), np.zeros((count, 3)), np.zeros((count, 3)))


@dataclasses.dataclass
class Solved:
    """A step's contacts, for the next step's warm start and the log: the keys (a, b, feature) of
    their points, int64, sorted, and the solver's columns in its sweep order, point i at row
    ``place[i]`` (the columns are kept as they are, not copied back into the sorted order)."""

    key: tuple
    contacts: rs.RigidContactColumns
    place: np.ndarray

    @property
    def pn(self) -> np.ndarray:
        """The points' last substep's normal impulses, in the sorted order, N s."""
        return self.contacts.pn[self.place]

    @property
    def total(self) -> np.ndarray:
        """The points' normal impulses of the step, in the sorted order, N s."""
        return self.contacts.total[self.place]

    @property
    def normal(self) -> np.ndarray:
        """The points' normals, (C, 3), in the sorted order."""
        return self.contacts.normal[self.place]


_NOTHING = Solved((np.zeros(0, np.int64),) * 3, contact_columns(0), np.zeros(0, np.int64))


@dataclasses.dataclass
class RigidSolverStep:
    """The contact solver's physics step on rigid bodies: ``step(t, y, dt, carry) -> (y, carry)``.

    The rotational state lives here beside the translational ``y``: ``orientation`` (N, 4) and
    ``omega`` (N, 3, world frame) of every body (identity and zero for those that do not
    rotate); ``history`` holds them at the end of every ``record_every``-th step and of the
    last (:meth:`rotation_at`). ``narrow_phase`` is a module with
    ``RigidShapes``, ``Poses``, ``manifolds`` and ``bounding_radius`` (default
    :mod:`.manifolds`).
    """

    world: object
    model: object
    integrator: object
    narrow_phase: object = None
    log: CollisionLog = dataclasses.field(default_factory=CollisionLog)
    record_every: int = 1

    def __post_init__(self):
        check_solver_integrator(self.integrator, self.world)
        world, rigid = self.world, self.world.rigid
        if (any(p is not cancel_triggers for p in world.prologues) or world.epilogues
                or any(s.trigger for s in world.shapes)):
            raise ValueError("the contact solver on rotating bodies takes no prologues, epilogues or trigger "
                             "shapes yet (the sphere solver does)")
        if self.narrow_phase is None:  # the module (the package's name ``manifolds`` is its function)
            self.narrow_phase = importlib.import_module(f"{__package__}.manifolds")
        self.codes = rotation_codes(rigid.rotation)
        if np.any(rigid.kind < 0):
            raise ValueError('the contact solver has no manifold for a cylinder; give the body shape = "capsule"')
        n = len(rigid.kind)
        # checked once here (one line naming the body), not in every step's narrow phase
        self.shapes = check_shapes(self.narrow_phase.RigidShapes(rigid.kind, rigid.radius, rigid.half))
        self.bounding = np.asarray(self.narrow_phase.bounding_radius(self.shapes), dtype=float)
        self.inverse_masses = np.ascontiguousarray(self.model.inverse_masses, dtype=float)
        self.masses = np.divide(1.0, self.inverse_masses, out=np.zeros_like(self.inverse_masses),
                                where=self.inverse_masses > 0)  # a pinned body: no kick, no work
        # springs and dampers at body-frame points: forces and torques at each substep's orientations
        self.attached = bool(attachments.attached_forces(self.model))
        field = None if self.attached else self.model.constant_acceleration
        self.field = None if field is None else np.array(field, dtype=float, order="C")  # writable: one kernel type
        self.materials = Materials.of(world, n)
        self.margin = SPECULATIVE_OF_RADIUS * float(np.median(self.bounding)) if n else 0.0
        # spheres and capsules are rounded about their core (centre, segment) by their radius; boxes are not
        self.rounding = np.where(np.asarray(rigid.kind) != BOX, np.asarray(rigid.radius, float), 0.0)
        self.rolling = world.solver.rolling_resistance * self.rounding
        bodies = rigid.bodies
        self.orientation, self.omega = bodies.of_all(n)
        self.inverse_principal = np.zeros((n, 3))
        turns = self.inverse_masses[bodies.index] > 0  # a pinned body neither moves nor turns
        self.inverse_principal[bodies.index[turns]] = 1.0 / np.asarray(bodies.inertia, float)[turns]
        self.omega[bodies.index[~turns]] = 0.0
        self.log.largest_residual = 0.0
        self._previous = _NOTHING
        self.precision = np.dtype(float)  # the run's, from its state (:meth:`_advance`)
        self._steps = 0
        self.history = {0: (self.orientation.copy(), self.omega.copy())}
        # the model whose lever arms every substep turns in place (it never leaves the step)
        self.lever_arms = attachments.LeverArms(self.model, self.orientation, self.omega) if self.attached else None
        keep_freed_memory()  # each step's columns reuse the last one's memory (:mod:`.heap`)

    def __call__(self, t, y, dt, carry):
        """Advance ``y`` (2, N, 3) and the rotation from ``t`` by ``dt``; returns ``(y, carry)``.

        The step's parallel parts run on the solver's ``threads`` (Numba's count is set for the
        step and restored after it)."""
        threads = numba.get_num_threads()
        numba.set_num_threads(self.world.solver.threads)
        try:
            return self._advance(t, y, dt, carry)
        finally:
            numba.set_num_threads(threads)

    def _advance(self, t, y, dt, carry):
        self.precision = np.asarray(y).dtype
        state = np.array(y, dtype=float, order="C")  # (2, N, 3): q and v, stepped in place and returned
        if self.attached:
            return self._advance_attached(t, state, dt, carry)
        q0, v0 = state[0], state[1]
        a = self.field if self.field is not None else np.asarray(self.model.acceleration(t, q0, v0), dtype=float)
        points = self.contact_points(t, y, dt, a)
        bodies, contacts, sub, layout = self.columns(q0, v0, a, points, dt)
        s = self.world.solver
        if self.field is not None:  # constant forces: the whole step in one compiled call
            residual = rs.step(bodies, contacts, sub, s.substeps, layout)
        else:
            for k in range(s.substeps):
                if k:
                    bodies = bodies._replace(accel=np.ascontiguousarray(
                        self.model.acceleration(t + k * sub.h, bodies.q, bodies.v), dtype=float))
                self._count_the_kick(bodies, bodies.accel, sub.h)
                rs.substep(bodies, contacts, sub, layout)
            # the forces' work is in the energy already (m a . dq, exact for a constant field only, adds none)
            residual = rs.finish(bodies._replace(accel=np.zeros_like(a)), contacts, sub, layout)
        return self._end_step(t, dt, state, carry, contacts, bodies, residual)

    def _advance_attached(self, t, state, dt, carry):
        """:meth:`_advance` of a model with springs or dampers at body-frame points (see the module): at
        each substep the acceleration and the torque's kick h I_w^-1 tau at the orientations now."""
        q0, v0 = state[0], state[1]
        a, alpha, torque = self.attached_rates(t, q0, v0)
        points = self.contact_points(t, state, dt, a, alpha)
        bodies, contacts, sub, layout = self.columns(q0, v0, a, points, dt)
        for k in range(self.world.solver.substeps):
            if k:
                a, alpha, torque = self.attached_rates(t + k * sub.h, bodies.q, bodies.v)
                bodies = bodies._replace(accel=a)
            # both kicks' work joins the energy the restitution budget starts from (see _kick_work): the
            # centres' v -> v + h a (the kernel's velocity stage) and the torque's, in place (self.omega),
            # before that stage adds the gyroscopic term
            self._count_the_kick(bodies, a, sub.h)
            omega = bodies.omega.copy()
            np.add(bodies.omega, sub.h * alpha, out=bodies.omega)
            np.add(bodies.energy, _kick_work(torque, omega, bodies.omega, sub.h), out=bodies.energy)
            # checked as it goes, so the one line names the body and the quantity that overflowed first
            # (the kick's spin, before the kernel carries it into the velocities and positions)
            self._check(t, angular_velocity=bodies.omega)
            rs.substep(bodies, contacts, sub, layout)
            self._check(t, position=bodies.q, velocity=bodies.v, angular_velocity=bodies.omega)
        # the forces' work is in the energy already: the budget's m a . dq (a constant field's) adds none
        residual = rs.finish(bodies._replace(accel=np.zeros_like(a)), contacts, sub, layout)
        return self._end_step(t, dt, state, carry, contacts, bodies, residual)

    def attached_rates(self, t, x, v):
        """The centres' acceleration (N, 3), the bodies' angular acceleration from the attached forces'
        torque, I_w^-1 tau (N, 3, world frame; zero for a pinned body or a point mass), and that torque
        tau (N, 3, world frame), with the lever arms at the orientations and angular velocities now."""
        model = self.lever_arms.turn(self.orientation, self.omega)
        torque = attachments.torques(model, x, v)
        # a body that does not turn gets no kick at all: 0, not 0 x an overflowed torque (NaN)
        spin = np.where(self.inverse_principal > 0, quat.rotate_inverse(np, self.orientation, torque), 0.0)
        alpha = quat.rotate(np, self.orientation, spin * self.inverse_principal)
        return np.ascontiguousarray(model.acceleration(t, x, v), dtype=float), alpha, torque

    def final_model(self):
        """The model with its lever arms at the orientations now (after a run, the last step's): the
        energy at the end counts its springs there. The model itself without attached forces."""
        if not self.attached:
            return self.model
        return attachments.model_at(self.model, self.orientation, self.omega)

    def _end_step(self, t, dt, state, carry, contacts, bodies, residual):
        """The log, the checks and the rotation's record at the end of a step; returns ``(state, carry)``.

        The solver computes in float64 (its kernels are compiled for it); a run in another precision
        (float32) carries its state from step to step in that precision: the positions, velocities,
        orientations and angular velocities are rounded to it here, as a game engine stores float32
        bodies whatever its solver's arithmetic, and as the rotation methods' float64 moments are
        rounded in the other steps (:func:`steplab.integrators.attached.in_precision`). A rounded
        quaternion is off unit length by up to a few float32 ulps, so it is normalised (in float64)
        for the next step, whose narrow phase takes only unit quaternions."""
        self._conclude(t, dt, contacts, residual)
        self._check(t, position=state[0], velocity=state[1], angular_velocity=bodies.omega)
        if self.precision != state.dtype:
            state = state.astype(self.precision)
            np.copyto(self.orientation, quat.normalize(np, self.orientation.astype(self.precision).astype(float)))
            np.copyto(self.omega, self.omega.astype(self.precision))
        self._steps += 1
        if (self._steps - 1) % self.record_every:  # the last step's record was kept only while it was the last
            orientation, omega = self.history.pop(self._steps - 1)  # its arrays (no one's now) take this step's
            np.copyto(orientation, self.orientation)
            np.copyto(omega, self.omega)
        else:
            orientation, omega = self.orientation.copy(), self.omega.copy()
        self.history[self._steps] = (orientation, omega)  # the last step always
        return state, carry

    def _count_the_kick(self, bodies, a, h):
        """Adds the work of the centres' kick v -> v + h a (the kernel's velocity stage) to the energy the
        restitution budget starts from (:func:`_kick_work`), for forces that change within the step."""
        np.add(bodies.energy, _kick_work(self.masses[:, None] * a, bodies.v, bodies.v + h * a, h), out=bodies.energy)

    def _check(self, t, **rows):
        """One line (FloatingPointError) naming the first body and its quantities in ``rows`` that are not finite."""
        if not all(np.isfinite(row).all() for row in rows.values()):
            raise FloatingPointError(non_finite(self.model.names, t, self.log.largest_residual, **rows))

    # --- stages --------------------------------------------------------------------------

    def contact_points(self, t, y, dt, a, alpha=None):
        """Broadphase over the swept bounds, then the narrow phase's manifolds, sorted by (a, b, feature);
        ``alpha`` (N, 3), the angular acceleration of attached forces' torques (None: none)."""
        q0 = np.ascontiguousarray(y[0], dtype=float)
        y_forces, _ = self.integrator.step(ConstantField(a), t, np.asarray(y, dtype=float), dt, None)
        q1 = np.ascontiguousarray(y_forces[0], dtype=float)
        turning = np.ascontiguousarray(self.omega)
        if alpha is not None:  # a torque spins a body up within the step: |omega| + dt |alpha| (its length is read)
            turning = np.zeros_like(turning)
            turning[:, 0] = np.linalg.norm(self.omega, axis=1) + dt * np.linalg.norm(alpha, axis=1)
        # the reach grows by what the rotation can move a point; the margin: every point up to as far
        # apart as the two bodies can close in the step, speculative ones included
        reach, margin = turning_bounds(q0, q1, turning, self.bounding,
                                       (float(dt), MAX_ROTATION_REACH, float(self.margin)))
        swept = SweptSpheres.of(q0, q1, reach, self.inverse_masses, self.log.removed, self.margin)
        pairs = swept.pair_rows(self.world.broadphase, self.world.solver.threads)
        points = self.narrow_phase.manifolds(self.shapes, self.narrow_phase.Poses(q0, self.orientation), pairs,
                                             self.world.shapes, margin)
        points = type(points)(*(np.ascontiguousarray(column) for column in points))
        points = points._replace(a=points.a.astype(np.int64, copy=False), b=points.b.astype(np.int64, copy=False),
                                 feature=points.feature.astype(np.int64, copy=False))
        if is_sorted(points.a, points.b, points.feature):  # as the narrow phase returns them
            return points
        order = np.lexsort((points.feature, points.b, points.a))
        return type(points)(*(column[order] for column in points))

    def columns(self, q0, v0, a, points, dt):
        """The kernels' bodies, contacts (warm-started, effective masses, laid out in the sweep order:
        domain by domain, each sorted, :mod:`.contact_domains`), step context and that order's
        :class:`.contact_domains.SweepLayout`."""
        s = self.world.solver
        h = dt / s.substeps
        n = len(q0)
        bodies = rs.RigidBodyColumns(q0, v0, self.omega, self.orientation, np.empty((n, 3)), np.empty((n, 4)),
                                     self.inverse_masses, np.empty((n, 3, 3)), self.inverse_principal,
                                     np.ascontiguousarray(a, dtype=float), self.rounding, np.empty(n))
        count = len(points.a)
        contacts = contact_columns(count)
        # the points arrive sorted by (a, b, feature), the order the last step's are matched in; the
        # solver takes them in its sweep order
        key = (points.a, points.b, points.feature)
        old = self._previous
        rows = rs.previous_rows(old.key, key, old.place, s.threads)
        count = domain_count(n)  # of the scene alone: the same bytes on any number of threads
        order, layout = lay_out(points.a, points.b, cut_into_domains(q0, self.inverse_masses > 0, count), count)
        rs.start_bodies(bodies, layout)
        self._sorted_key, self._order, self._rows, self._place = key, order, rows, inverse(order)
        o = old.contacts
        gather(points, order, (q0, bodies.accel, self.rolling), self.materials,
               (rows, o.pn, o.pt, o.tangent, o.pr), (float(self.world.rest_speed), float(dt)), contacts, layout)
        rs.prepare(bodies, contacts, layout)
        bias_rate, mass_scale, impulse_scale = s.softness(h)
        sub = rs.RigidSubstep(h, s.iterations, bias_rate, mass_scale, impulse_scale, s.push_speed, s.slop,
                              *self.codes, bool(np.any(self.rolling > 0.0)))
        return bodies, contacts, sub, layout

    def _conclude(self, t, dt, contacts, residual):
        """The log (impacts, residual) and what the next step warm-starts from: the contacts as the
        solver left them, in its sweep order, and each sorted point's row among them."""
        c = contacts
        # one impact per pair: its first point newly hit
        first = first_impacts(self._sorted_key, self._place, self._rows, self._previous.contacts.total, c.total,
                              self.world.solver.threads)
        b = self._sorted_key[1][self._order[first]]  # c.b holds -1 for every static shape
        self.log.add_impacts(ImpactBlock(
            np.full(len(first), float(t)), c.a[first], b, c.normal[first],
            -c.hit[first], c.restitution[first], c.friction[first], c.total[first], (float(t), float(t + dt)),
            self.model.names, self.world.shapes))
        self.log.most_impacts_in_a_step = max(self.log.most_impacts_in_a_step, len(first))
        self.log.largest_residual = max(self.log.largest_residual, float(residual))
        self._previous = Solved(self._sorted_key, c, self._place)

    def rotation_at(self, steps: np.ndarray):
        """(orientations (K, N, 4), angular velocities (K, N, 3)) after each of ``steps`` steps (recorded ones)."""
        recorded = self.history
        missing = [int(k) for k in steps if int(k) not in recorded]
        if missing:
            raise ValueError(f"the solver recorded its rotation every {self.record_every} steps, not after step "
                             f"{missing[0]}")
        return (np.array([recorded[int(k)][0] for k in steps], self.precision),
                np.array([recorded[int(k)][1] for k in steps], self.precision))


def _kick_work(push, before, after, h):
    """The work of each body's kick over h, (N,), J: h push . (before + after) / 2, for a force's
    v -> v + h F / m (push F) or a torque's omega -> omega + h I_w^-1 tau (push tau). It is exactly the
    kinetic energy the kick adds, 1/2 m v^2 or 1/2 omega . I_w omega after less before (I_w symmetric,
    I_w (after - before) = h tau; zero for a body that does not move or turn).

    The restitution pass gives back at most the kinetic energy the step took, D = E0 + W - E1
    (:func:`.rigid_solver._limit_to_the_energy_taken`). With every kick's work in W, D is exactly what
    the substeps' contact impulses took, less what the gyroscopic stage added (nothing for equal
    moments; implicit-gyroscopic's stage loses up to 0.036 J a step of the hung box spinning at
    26 rad/s, which a bounce may give back). A constant field's W, m a . dq, is its potential's fall;
    for springs, whose force changes from substep to substep, that was the last substep's force times
    the whole step's move: 0.17 J too little to 0.06 J too much a step on a frictionless, undamped hung
    box at restitution 1, dt = 1/60 s. (Without the torques' work, a torque that slowed a spin counted
    as energy the contacts took.) That box's energy still rises 2 to 3 % after its first impacts, in
    steps without contact: semi-implicit Euler's own first-order error in the spinning box's springs
    (docs/guarantees.md)."""
    return h * np.einsum("ij,ij->i", push, 0.5 * (before + after))
