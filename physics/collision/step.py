"""One physics step with collisions, read as its stages.

    forces -> integrate -> broadphase -> narrowphase -> respond, then resting contacts

The integrator knows nothing of collisions: it steps the ODE (the model sums the forces)
over what is left of the step. The broadphase proposes pairs, the detector finds the
earliest collision among them, and the response resolves it *at its time*: the bodies are
moved back along their chords to the collision (the lecture's "split into two parts,
t to t_c and then t_c to t + dt; integrate twice for each collision"), the collision is
resolved, and the rest of the step is integrated again, at most
``max_impacts_per_step`` times per step. Last, bodies pressed into a surface they rest
on are put back on it (:mod:`.resting`).

Inside a step, bodies move along straight chords from their start to their end
positions, with velocities interpolated linearly; this is exact for the velocities under
a constant force and leaves an O(dt^2) error in the positions of the bodies at the
collision, the order of a fixed-step integrator's own local error. It is also what the
swept tests assume, so what they test is exactly where the bodies go: nothing can pass
between two tested positions.

An integrator that carries something between steps (velocity and position Verlet keep the
last acceleration) is re-initialised whenever a collision or a contact changes the
state.

A run builds its :class:`CollisionStep` once (``CollisionWorld.stepper(model, integrator)``)
and calls it as ``step(t, y, dt, carry)``, the signature of the plain ODE step; the step
holds the world, the model, the integrator and the run's log, so the driver
(``integrators.simulate``) knows nothing of collisions.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .detectors import earliest_impact, start_state
from .events import Collision, CollisionLog
from .pairs import BodyPairs, candidates
from .response import normal_speed, resolve
from .resting import settle

#: bodies closer than this many rounding units of the largest coordinate are touching
SLOP_ULPS = 100
#: an impact slower than what the forces pressing the pair together add over this many
#: steps does not bounce (eps = 0): it ends the endless series of ever smaller bounces
#: (Zeno's) of a body coming to rest, which an energy-gaining integrator (explicit Euler)
#: would otherwise sustain as a jitter of about g dt^2
RESTING_STEPS = 2


def rest_speed(world, pressing, dt):
    """Approach speeds at or below this are resting contacts, not bounces (m/s).

    ``pressing`` is the relative acceleration pushing the pair together along the normal;
    ``world.rest_speed`` is a floor for pairs nothing presses together (a row of touching
    balls passing on round-off-sized speeds back and forth).
    """
    return world.rest_speed + RESTING_STEPS * np.maximum(pressing, 0.0) * dt


def contact_slop(q) -> float:
    """The gap below which bodies count as touching: a few hundred rounding errors, m."""
    return SLOP_ULPS * float(np.finfo(q.dtype).eps) * max(1.0, float(np.max(np.abs(q))))


def lerp(y0, y1, s):
    """The state at fraction ``s`` of the way from ``y0`` to ``y1``."""
    return y0 + s * (y1 - y0)


@dataclasses.dataclass
class CollisionStep:
    """One physics step with collisions, built once per run: ``step(t, y, dt, carry) -> (y, carry)``.

    Attributes
    ----------
    world : CollisionWorld
        The static geometry, the detector, the materials.
    model : physics.Model
        On the NumPy backend.
    integrator : Stepper
    log : CollisionLog
        Every collision of the run, filled in as the run goes.
    """

    world: object
    model: object
    integrator: object
    log: CollisionLog = dataclasses.field(default_factory=CollisionLog)

    def __post_init__(self):
        self.radii = np.asarray(self.model.radii, dtype=float)
        self.inverse_masses = np.asarray(self.model.inverse_masses, dtype=float)

    def __call__(self, t, y, dt, carry):
        """Advance ``y`` (2, N, 3) from ``t`` by ``dt`` with collisions; returns ``(y, carry)``."""
        world, log, model, integrator = self.world, self.log, self.model, self.integrator
        radii, inverse_masses = self.radii, self.inverse_masses
        t_end = t + dt
        y = np.array(y)
        ignored = set(log.cancelled_pairs)  # pairs a prologue cancelled, until they separate
        resolved = 0
        while True:
            h = t_end - t
            # Forces and integration: the integrator steps the ODE over the rest of the step
            y_end, carry_end = integrator.step(model, t, y, h, carry)
            y_end = np.array(y_end)
            slop = contact_slop(y_end[0])
            # Broadphase: pairs whose bounding spheres, around their motion over the sub-step, overlap
            groups = candidates(world.shapes, y[0], y_end[0], radii, inverse_masses, world.broadphase,
                                log.removed, slop)
            # Narrowphase: the earliest collision of the sub-step that the prologues let through
            starts = [start_state(pairs, radii, y, slop) for pairs in groups]
            self._set_rest_speeds(groups, starts, t, y, dt)
            if resolved == world.max_impacts_per_step:
                if earliest_impact(world.detector, groups, starts, radii, y, y_end, world.bisection_iterations,
                                   ignored):
                    log.bound_hits += 1  # the rest of the step goes unresolved
                break
            impact, event = self._next_collision(groups, starts, t, h, dt, y, y_end, ignored)
            if impact is None:
                break
            # Respond: move to the time of the collision, resolve it, simulate the rest of the step
            y, t = lerp(y, y_end, impact.s), t + impact.s * h
            self._respond(impact, event, y)
            resolved += 1
            carry = integrator.init(model, t, y)
        log.most_impacts_in_a_step = max(log.most_impacts_in_a_step, resolved)
        # Resting contacts: bodies pressed into a surface are put back on it
        corrections = settle(world, groups, starts, y_end, radii, inverse_masses, slop, ignored)
        if corrections:
            log.resting_corrections += corrections
            carry_end = integrator.init(model, t_end, y_end)
        if ignored:
            log.cancelled_pairs = _still_touching(ignored, groups, radii, y_end, slop)
        return y_end, carry_end

    def _set_rest_speeds(self, groups, starts, t, y, dt):
        """Each touching, approaching pair's rest speed (one force evaluation, when there is one)."""
        if not any(np.any(start.in_contact & (start.speed > 0)) for start in starts):
            return
        a = np.asarray(self.model.acceleration(t, y[0], y[1]))
        for pairs, start in zip(groups, starts):
            start.rest_speed = rest_speed(self.world, normal_speed(a[pairs.i], pairs.velocity_b(a), start.normal), dt)

    def _next_collision(self, groups, starts, t, h, dt, y, y_end, ignored):
        """The earliest collision the prologues accept; cancelled ones are logged and skipped."""
        world, log = self.world, self.log
        while True:
            impact = earliest_impact(world.detector, groups, starts, self.radii, y, y_end,
                                     world.bisection_iterations, ignored)
            if impact is None:
                return None, None
            event = self._event(impact, lerp(y, y_end, impact.s), t, h, dt)
            if all(prologue(event, log) for prologue in world.prologues):
                return impact, event
            event.kind = "trigger" if event.trigger else "cancelled"
            log.events.append(event)
            ignored.add(impact.pairs.key(impact.k))

    def _event(self, impact, y_hit, t, h, dt) -> Collision:
        world, model = self.world, self.model
        pair = impact.pairs.subset([impact.k])
        t_hit = t + impact.s * h
        normal = pair.contact(self.radii, y_hit[0]).normal[0]
        body = int(pair.i[0])
        if isinstance(pair, BodyPairs):
            other, other_name, trigger = int(pair.j[0]), model.names[int(pair.j[0])], False
            restitution, friction = world.properties(body, other)
        else:
            other, other_name, trigger = pair.shape.name, pair.shape.name, pair.shape.trigger
            restitution, friction = world.properties(body, pair.shape)
        speed = float(normal_speed(y_hit[1, body], pair.velocity_b(y_hit[1])[0], normal))
        a = np.asarray(model.acceleration(t_hit, y_hit[0], y_hit[1]))
        pressing = float(normal_speed(a[body], pair.velocity_b(a)[0], normal))
        kind = "impact"
        if speed <= rest_speed(world, pressing, dt):
            kind, restitution = "resting", 0.0  # a resting contact, not a bounce
        return Collision(kind=kind, t=float(t_hit), body=body, other=other, body_name=model.names[body],
                         other_name=other_name, normal=np.asarray(normal, dtype=float), impact_speed=speed,
                         restitution=restitution, friction=friction,
                         bracket=(float(t + impact.lo * h), float(t + impact.s * h)), trigger=trigger)

    def _respond(self, impact, event, y) -> None:
        """Place the pair at the point of impact, give it new velocities, run the epilogues."""
        pair = impact.pairs.subset([impact.k])
        contact = pair.contact(self.radii, y[0])
        other = pair.j if isinstance(pair, BodyPairs) else None
        lam = resolve(y, pair.i, other, self.inverse_masses, contact.normal, contact.penetration_depth,
                      event.restitution, event.friction)
        if event.kind == "resting" or event.impact_speed <= 0:  # settling, or grazing: no collision
            self.log.resting_corrections += 1
        else:
            event.impulse = float(np.linalg.norm(lam[0]))
            self.log.events.append(event)
            for epilogue in self.world.epilogues:
                epilogue(event, self.log)


def _still_touching(keys, groups, radii, y, slop) -> set:
    """The pairs among ``keys`` that touch in state ``y`` (candidates of this step only)."""
    touching = set()
    for pairs in groups:
        mine = [k for k in range(len(pairs)) if pairs.key(k) in keys]
        if mine:
            depth = pairs.subset(mine).contact(radii, y[0]).penetration_depth
            touching |= {pairs.key(k) for k, d in zip(mine, depth) if d >= -slop}
    return touching
