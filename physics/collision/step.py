"""One physics step with collisions, read as its stages.

    forces -> integrate -> broadphase -> narrowphase -> respond, then resting contacts

The integrator knows nothing of collisions: it steps the ODE (the model sums the forces)
over what is left of the step. The broadphase proposes pairs, the detector finds the
earliest collision among them, and the response resolves it *at its time*: the bodies are
moved back along their chords to the collision (the lecture's "split into two parts,
t to t_c and then t_c to t + dt; integrate twice for each collision"), the collision is
resolved, and the rest of the step is integrated again, until no collision is left in
the step. Last, bodies pressed into a surface they rest on are put back on it
(:mod:`.resting`).

Inside a step, bodies move along straight chords from their start to their end
positions, with velocities interpolated linearly; this is exact for the velocities under
a constant force and leaves an O(dt^2) error in the positions of the bodies at the
collision, the order of a fixed-step integrator's own local error. It is also what the
swept tests assume, so what they test is exactly where the bodies go: nothing can pass
between two tested positions.

Two event loops (``CollisionWorld.event_loop``)
-----------------------------------------------
``"full"``, the reference: after every collision the whole scene is integrated again
over the rest of the step, the broadphase runs again and every candidate pair is tested
again. It costs O(N) broadphase and narrow-phase work per collision.

``"incremental"`` does only what the collision changed. The broadphase runs once per
step, over the swept bounds of the whole step; every candidate pair is tested once and
its time kept (:mod:`.impact_queue`). A collision changes the motion of its two bodies
and of the bodies tied to them by springs and dampers (:mod:`.coupling`); only their
rest of the step is integrated again (only their rows, under constant forces), only
their pairs are found again (their new swept bounds in a grid of everyone's,
:mod:`.changed_pairs`) and tested again (in one compiled kernel for spheres and planes,
:mod:`.retest`). Every other body keeps its chord (:mod:`.chords`), and its pairs keep
their times: the work per collision is O(1), not O(N).

Where the two agree: a body the collision did not touch moves, in the full loop, from
lerp(y, y_end, s) over the rest h' = (1 - s) dt of the step. Under semi-implicit Euler and
forces that are constant over the step (gravity, a steady wind), v' = v_s + h' a and
q' = q_s + h' v' land on y_end again, up to round-off. With a force that depends on the
state (springs, drag) or another integrator (explicit Euler, velocity Verlet, RK4:
q' = q_s + h' v_s + h'^2 a / 2 misses q_1 by s (1 - s) dt^2 a / 2) they land O(dt^2) away,
so there the incremental loop's trajectories differ from the full loop's by O(dt^2) per
collision, the order of the chord approximation itself, not by round-off (measured on
the built-in scenes: billiards under velocity Verlet, impact times 5e-5 s apart at
dt = 0.01 s; Newton's cradle, whose strings are springs, 1e-6 s; chaotic n-balls
diverges after a few collisions). ``"auto"``, the default, therefore runs the
incremental loop exactly where it agrees with the full one to round-off
(:func:`rest_of_step_is_unchanged`, and every force constant) and the full loop
elsewhere, so every existing scene and study keeps its numbers.

Measured where they agree (tests/test_event_loop.py, and every built-in collision scene
under semi-implicit Euler): the same collision log, in the same order, with times and
speeds to about 1e-11 relative; steps without a collision are the same bit for bit.
Overlap testing sees collisions only where it looks, at the ends of the sub-steps: the
full loop's split of the step at a collision is one more place where every pair is
looked at (:mod:`.overlap`), and its brackets belong to the sub-step. So with overlap
testing the incremental loop tests every candidate pair again at every split (with
neither the broadphase nor the integration run again) and gives the full loop's log.

For the scenes games are made of (spheres and planes, swept testing, constant forces,
semi-implicit Euler, no prologue, epilogue or trigger that asks to see an impact as it
happens) the incremental loop's impacts run in one compiled call per step
(:mod:`.compiled_loop`) and its resting contacts in another
(:func:`.resting.settle_spheres_and_planes`): the same stages in the same order, so the
same collision log and trajectories bit for bit (tests/test_event_loop_compiled.py).
``CollisionWorld(compiled_loop=False)`` keeps the Python loop, the reference of that test.

Spheres that spin (where friction can turn them) run :class:`.spin_step.SpinningCollisionStep`:
this step with their omega and orientation beside ``y`` (:class:`.compiled_response.Spin`),
the impulse's angular part at every impact and the closed-form slide of the resting contacts
(:mod:`.resting`), on every path; without spin the kernels take the point masses' code.

At most ``max_impacts_per_step`` collisions are resolved in a step (the default scales
with the bodies, :mod:`.impact_cap`); a step holding more raises
:class:`.impact_cap.ImpactCapError` instead of leaving them unresolved.

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

from . import compiled_loop
from .approach import approach_speeds
from .changed_pairs import SweptGrid
from .chords import Chords
from .compiled_response import impact_terms, no_spin, resolve_pair, turn_all_to, turn_to
from .coupling import Coupling
from .detectors import StartState, earliest_impact, pair_times, start_state
from .events import Collision, CollisionLog, ImpactRows
from .impact_cap import ImpactCapError
from .impact_queue import ImpactQueue
from .pairs import BodyPairs, ShapePairs, candidates, changed_candidates
from .response import resolve_spinning
from .resting import rest_speed, settle, settle_spheres_and_planes
from .retest import Bodies, Planes, Split, retest_spheres_and_planes

#: bodies closer than this many rounding units of the largest coordinate are touching
SLOP_ULPS = 100


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
        self.cap = self.world.impact_cap(len(self.radii))
        self.coupling = Coupling(self.model)
        field = self.model.constant_acceleration  # (N, 3) when every force is constant, else None
        self.field = None if field is None else np.array(field, dtype=float, order="C")  # writable: one kernel type
        planes = [shape for shape in self.world.shapes if shape.kind == "plane"]
        #: spheres, planes, swept testing and constant forces: the changed pairs' narrow phase compiled
        self.compiled_retest = (self.world.detector == "swept" and self.field is not None
                                and len(planes) == len(self.world.shapes))
        self.planes = tuple(Planes(np.array([p.normal for p in planes], dtype=float).reshape(-1, 3),
                                   np.array([p.offset for p in planes], dtype=float),
                                   np.array([p.trigger for p in planes], dtype=bool)))
        #: the loop this run uses: "auto" is "incremental" where it agrees with "full" to round-off
        self.event_loop = self.world.event_loop
        if self.event_loop == "auto":
            exact = self.field is not None and rest_of_step_is_unchanged(self.integrator)
            self.event_loop = "incremental" if exact else "full"
        self._active = np.ones(len(self.radii), bool)  # bodies not removed (removal is for good)
        #: the spheres' spin (:class:`.compiled_response.Spin`): empty, the point-mass path, unless a
        #: :class:`.spin_step.SpinningCollisionStep` sets it
        self.spin = getattr(self, "spin", None) or no_spin()
        self._bodies = tuple(Bodies(self.radii, self.inverse_masses, self._active, self.field))
        self._is_changed = np.zeros(len(self.radii), bool)  # scratch: the bodies of one re-test
        #: the incremental loop's impacts in one compiled call per step (:mod:`.compiled_loop`; off
        #: with the compiled re-test, which it contains)
        self.compiled_loop = (self.world.compiled_loop and self.compiled_retest and self.event_loop == "incremental"
                              and compiled_loop.applies(self.world, self.field, planes)
                              and steps_as_semi_implicit_euler(self.integrator))
        if self.compiled_loop:
            self._materials = _material_tables(self.world, len(self.radii), planes)
            self._heap = np.empty(1024, np.int64)  # the compiled call's buffers, kept from step to step
            self._logged = np.empty(256, compiled_loop.LOGGED)

    def __call__(self, t, y, dt, carry):
        """Advance ``y`` (2, N, 3) from ``t`` by ``dt`` with collisions; returns ``(y, carry)``."""
        if self.event_loop == "incremental":
            return self._incremental(t, y, dt, carry)
        return self._full(t, y, dt, carry)

    def _incremental(self, t, y, dt, carry):
        """The step re-testing only what each collision changed (see the module docstring)."""
        world, log, model, integrator = self.world, self.log, self.model, self.integrator
        radii, inverse_masses = self.radii, self.inverse_masses
        t_start, t_end = t, t + dt
        y = np.array(y)
        ignored = set(log.cancelled_pairs)  # pairs a prologue cancelled, until they separate
        if self.compiled_loop and self.compiled_retest and not ignored and not log.removed:
            return self._compiled(t, y, dt, carry)
        # Forces, integration, broadphase and the pairs' start states: the whole step, once
        y_end, carry_end, slop, groups, starts = self._sweep(t, y, dt, carry)
        # Narrowphase, once per pair: every candidate's time of impact, in the queue
        queue = ImpactQueue(len(radii))
        chords = Chords(y, y_end, t, t_end, radii, slop)
        grid = SweptGrid(chords.centers, chords.reach)
        self._test(queue, (groups, starts), t, y, y_end, dt, dt, self._accelerations(t, chords))
        resolved = 0
        while True:
            found = self._next_queued(queue, t, t_end, dt, chords, ignored, resolved, t_start)
            if found is None:
                break
            # Respond: move to the time of the collision, resolve it
            impact, event, pair, contact = found
            t = t + impact.s * (t_end - t)
            moved = self.coupling.moved_by(pair)  # the pair, and what springs tie to it
            y = chords.at(np.setdiff1d(moved, pair), t) if len(moved) > len(pair) else chords.now
            removed = set(log.removed)
            self._respond(impact, event, y, contact, compiled=True)
            resolved += 1
            # Only what the collision changed: its bodies' rest of the step and their pairs
            chords.restart(moved, t, self._rest_of_step(chords, moved, t, t_end - t), slop)
            grid.moved(moved)
            queue.changed(moved)
            if log.removed != removed:  # an epilogue removed bodies: their pairs are out of date too
                queue.changed(np.array(sorted(log.removed - removed), dtype=np.int64))
            if self.compiled_retest:  # spheres and planes: one kernel for the changed bodies' pairs
                self._retest(queue, chords, grid, moved, t, t_end, dt, slop)
                new = []
            else:
                new = changed_candidates(world.shapes, chords, grid, inverse_masses, log.removed, moved)
            if world.detector == "overlap":  # overlap testing looks at every pair at every split
                new += queue.take_all()
            else:
                new += queue.take_watched()  # resting contacts speeding up along their chords
            if new:
                y = chords.at(np.unique(np.concatenate([_pair_bodies(pairs) for pairs in new])), t)
                self._test(queue, (new, [start_state(pairs, radii, y, slop) for pairs in new]), t, y, y_end,
                           t_end - t, dt, self._accelerations(t, chords))
        log.most_impacts_in_a_step = max(log.most_impacts_in_a_step, resolved)
        if resolved:
            groups, starts = queue.current_groups()
            if carry_end is not None:  # the carry of the state the step ends in
                carry_end = integrator.init(model, t_end, y_end)
        return self._finish((groups, starts), y_end, carry_end, (t_start, t_end), ignored, slop)

    def _compiled(self, t, y, dt, carry):
        """:meth:`_incremental` in compiled calls: the first tests (:func:`.compiled_loop.first_rows`),
        the impacts (:func:`.compiled_loop.resolve_impacts`) and the resting contacts
        (:func:`.resting.settle_spheres_and_planes`): the same stages, the same numbers."""
        from .compiled_loop import CAP_REACHED, N_ENTRIES, N_LOGGED, N_WATCHED, RESOLVED, RESTING

        log, t_end = self.log, t + dt
        # Forces, integration and broadphase: the whole step, once
        y_end, carry_end, slop, groups = self._broadphase(t, y, dt, carry)
        chords = Chords(y, y_end, t, t_end, self.radii, slop)
        grid = SweptGrid(chords.centers, chords.reach)
        # Narrowphase, once per pair: every candidate's time of impact, as the rows of the queue
        stamps = np.zeros(len(self.radii), np.int64)
        split = tuple(Split(t, dt, slop, self.world.rest_speed))
        entries, watched, n_watched = compiled_loop.first_rows(
            _group_columns(groups), chords.arrays, chords.now, self._bodies, self.planes, split, stamps)
        sizes = compiled_loop.new_sizes(sum(len(pairs) for pairs in groups), self.cap)
        sizes[N_WATCHED] = n_watched
        # Respond, earliest first, re-testing what each impact changed: one call
        entries, self._heap, _, self._logged = compiled_loop.resolve_impacts(
            chords.arrays, chords.now, (grid.arrays, grid.links), self._bodies,
            (self.planes, self._materials, self.spin), split,
            (entries, self._heap, watched, stamps, self._is_changed, sizes), self._logged)
        if sizes[N_LOGGED]:
            log.add_impacts(ImpactRows(self._logged[:sizes[N_LOGGED]].copy(), tuple(self.model.names),
                                       self.world.shapes, self.world.properties))
        log.resting_corrections += int(sizes[RESTING])
        resolved = int(sizes[RESOLVED])
        if sizes[CAP_REACHED]:
            raise ImpactCapError(t, resolved, self.cap)
        log.most_impacts_in_a_step = max(log.most_impacts_in_a_step, resolved)
        if resolved and carry_end is not None:  # the carry of the state the step ends in
            carry_end = self.integrator.init(self.model, t_end, y_end)
        # Resting contacts: bodies pressed into a surface are put back on it
        if len(self.spin.inverse_inertia):  # spheres that spin: turned on to the step's end
            turn_all_to(self.spin, t_end)
        body_material, plane_material, _, friction = self._materials
        corrections = settle_spheres_and_planes(
            y_end, compiled_loop.settle_rows(entries, sizes[N_ENTRIES], stamps),
            (self.radii, self.inverse_masses, self.spin), (self.planes[0], self.planes[1]),
            (body_material, plane_material, friction), (float(slop), t_end - t))  # dt as _finish has it
        if corrections:
            log.resting_corrections += corrections
            carry_end = self.integrator.init(self.model, t_end, y_end)
        return y_end, carry_end

    def _retest(self, queue, chords, grid, moved, t, t_end, dt, slop):
        """The changed bodies' pairs, found and tested in one kernel (:mod:`.retest`), into the queue."""
        active, is_changed = self._active, self._is_changed
        if self.log.removed:
            active[list(self.log.removed)] = False
        is_changed[moved] = True
        i, j, in_contact, speed, normal, rest, s, watch = retest_spheres_and_planes(
            grid.arrays, chords.arrays, self._bodies, self.planes, (t, dt, slop, self.world.rest_speed),  # a Split
            moved, is_changed)
        is_changed[moved] = False
        js = j.tolist()  # the body pairs come first, then one run per plane
        n = len(js)
        nb = 0
        while nb < n and js[nb] >= 0:
            nb += 1
        edges = [0, nb, *(p for p in range(nb + 1, n) if js[p] != js[p - 1]), n]
        for lo, hi in zip(edges[:-1], edges[1:]):
            if lo == hi:
                continue
            if js[lo] >= 0:
                pairs = BodyPairs(i[lo:hi], j[lo:hi])
            else:
                pairs = ShapePairs(-1 - js[lo], self.world.shapes[-1 - js[lo]], i[lo:hi])
            start = StartState(in_contact[lo:hi], speed[lo:hi], normal[lo:hi], rest[lo:hi])
            queue.add(pairs, start, s[lo:hi], s[lo:hi], t, t_end - t, watch[lo:hi])

    def _accelerations(self, t, chords):
        """A callable giving every body's acceleration at ``t``, (N, 3) (evaluated when first asked)."""
        if self.field is not None:  # constant forces: no state needed
            return lambda: self.field
        cache = []

        def evaluate():
            if not cache:
                y = chords.at(np.arange(len(self.radii)), t)
                cache.append(np.asarray(self.model.acceleration(t, y[0], y[1])))
            return cache[0]

        return evaluate

    def _rest_of_step(self, chords, moved, t, h):
        """The new end states of the bodies ``moved``, integrated from their states at ``t`` over ``h``.

        Under constant forces the bodies move independently: only their rows are integrated
        (with the field's rows, the same arithmetic row by row). Otherwise the whole state
        at ``t`` is integrated and their rows taken.
        """
        integrator = self.integrator
        if self.field is not None and not integrator.implicit:
            rows = ConstantField(self.field[moved])
            y = chords.now[:, moved]
            return np.asarray(integrator.step(rows, t, y, h, integrator.init(rows, t, y))[0])
        everyone = np.arange(len(self.radii))
        keep = chords.now[:, moved].copy()
        y = chords.at(everyone, t)
        y[:, moved] = keep  # the responded states (``at`` knows only the chords before the collision)
        y_rest, _ = integrator.step(self.model, t, y, h, integrator.init(self.model, t, y))
        return np.asarray(y_rest)[:, moved]

    def _test(self, queue, candidates, t, y, y_end, h, dt, accelerations):
        """Test the ``candidates`` (groups of pairs and their start states) on the sub-step
        ``[t, t + h]`` (``y -> y_end``) of the step ``dt``; queue their times."""
        groups, starts = candidates
        self._set_rest_speeds(groups, starts, t, y, dt, accelerations)
        for pairs, start in zip(groups, starts):
            s, lo = pair_times(self.world.detector, pairs, start, self.radii, y, y_end,
                               self.world.bisection_iterations)
            queue.add(pairs, start, s, lo, t, h, _speeding_up(pairs, start, y_end))

    def _next_queued(self, queue, t, t_end, dt, chords, ignored, resolved, t_start):
        """The earliest queued collision the prologues accept: (impact, event, its bodies, contact), or None."""
        h = t_end - t
        while True:
            found = queue.pop(ignored)
            if found is None:
                return None
            if resolved == self.cap:
                raise ImpactCapError(t_start, resolved, self.cap)
            table, k = found
            impact = table.impact(k, t, h)
            pair = _bodies(impact)
            t_hit = t + impact.s * h
            y_hit = chords.at(pair, t_hit, table.t_sub, table.s[k])
            if self.compiled_retest:  # spheres and planes under constant forces: one kernel
                j = int(impact.pairs.j[k]) if isinstance(impact.pairs, BodyPairs) else -1 - impact.pairs.index
                contact = _PairContact(*impact_terms(y_hit, int(impact.pairs.i[k]), j, self.radii, self.field,
                                                     self.planes))
            else:
                contact = impact.pairs.subset([k]).contact(self.radii, y_hit[0])
            event = self._event(impact, y_hit, t, h, dt, self._accelerations(t_hit, chords), contact)
            if all(prologue(event, self.log) for prologue in self.world.prologues):
                return impact, event, pair, contact
            event.kind = "trigger" if event.trigger else "cancelled"
            self.log.events.append(event)
            ignored.add(impact.pairs.key(impact.k))

    def _finish(self, contacts, y_end, carry_end, span, ignored, slop):
        """Resting contacts: bodies pressed into a surface are put back on it; ``contacts`` = (groups,
        starts), ``span`` = (t_start, t_end), the step's."""
        log = self.log
        groups, starts = contacts
        t_start, t_end = span
        if len(self.spin.inverse_inertia):  # spheres that spin: turned on to the step's end
            turn_all_to(self.spin, t_end)
        corrections = settle(self.world, contacts, y_end, (self.radii, self.inverse_masses, self.spin),
                             (slop, t_end - t_start), ignored)
        if corrections:
            log.resting_corrections += corrections
            carry_end = self.integrator.init(self.model, t_end, y_end)
        if ignored:
            log.cancelled_pairs = _still_touching(ignored, groups, self.radii, y_end, slop)
        return y_end, carry_end

    def _full(self, t, y, dt, carry):
        """The reference step: after every collision, everything is integrated and tested again."""
        world, log, model, integrator = self.world, self.log, self.model, self.integrator
        radii = self.radii
        t_start, t_end = t, t + dt
        y = np.array(y)
        ignored = set(log.cancelled_pairs)  # pairs a prologue cancelled, until they separate
        resolved = 0
        while True:
            h = t_end - t
            # Forces, integration and broadphase over the rest of the step
            y_end, carry_end, slop, groups, starts = self._sweep(t, y, h, carry)
            # Narrowphase: the earliest collision of the sub-step that the prologues let through
            self._set_rest_speeds(groups, starts, t, y, dt)
            if resolved == self.cap:
                if earliest_impact(world.detector, groups, starts, radii, y, y_end, world.bisection_iterations,
                                   ignored):
                    raise ImpactCapError(t_start, resolved, self.cap)  # never leave impacts unresolved
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
        return self._finish((groups, starts), y_end, carry_end, (t_start, t_end), ignored, slop)

    def _sweep(self, t, y, h, carry):
        """The stages before the narrow phase, over the (sub-)step from ``t`` to ``t + h``.

        Forces and integration: the integrator steps the ODE. Broadphase: the pairs whose
        bounding spheres, around their motion over the sub-step, overlap. Then each candidate
        pair's start state (touching, approach speed). Returns ``(y_end, carry_end, slop,
        groups, starts)``.
        """
        y_end, carry_end, slop, groups = self._broadphase(t, y, h, carry)
        starts = [start_state(pairs, self.radii, y, slop) for pairs in groups]
        return y_end, carry_end, slop, groups, starts

    def _broadphase(self, t, y, h, carry):
        """Forces, integration and broadphase over the (sub-)step: ``(y_end, carry_end, slop, groups)``."""
        y_end, carry_end = self.integrator.step(self.model, t, y, h, carry)
        y_end = np.array(y_end)
        slop = contact_slop(y_end[0])
        groups = candidates(self.world.shapes, y[0], y_end[0], self.radii, self.inverse_masses,
                            self.world.broadphase, self.log.removed, slop)
        return y_end, carry_end, slop, groups

    def _set_rest_speeds(self, groups, starts, t, y, dt, accelerations=None):
        """Each touching, approaching pair's rest speed (one force evaluation, when there is one)."""
        if not any(np.any(start.in_contact & (start.speed > 0)) for start in starts):
            return
        a = accelerations() if accelerations is not None else np.asarray(self.model.acceleration(t, y[0], y[1]))
        for pairs, start in zip(groups, starts):
            pressing = approach_speeds(a[pairs.i], pairs.velocity_b(a), start.normal)
            start.rest_speed = rest_speed(self.world.rest_speed, pressing, dt)

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

    def _event(self, impact, y_hit, t, h, dt, accelerations=None, contact=None) -> Collision:
        """The collision ``impact`` in state ``y_hit``; ``contact``: the pair's, when already known."""
        world, model = self.world, self.model
        if isinstance(contact, _PairContact):
            return self._event_of_pair(impact, t, h, dt, contact)
        pair = impact.pairs.subset([impact.k])
        t_hit = t + impact.s * h
        normal = (contact if contact is not None else pair.contact(self.radii, y_hit[0])).normal[0]
        body = int(pair.i[0])
        if isinstance(pair, BodyPairs):
            other, other_name, trigger = int(pair.j[0]), model.names[int(pair.j[0])], False
            restitution, friction = world.properties(body, other)
        else:
            other, other_name, trigger = pair.shape.name, pair.shape.name, pair.shape.trigger
            restitution, friction = world.properties(body, pair.shape)
        speed = float(approach_speeds(y_hit[1, body], pair.velocity_b(y_hit[1])[0], normal))
        a = accelerations() if accelerations is not None else np.asarray(model.acceleration(t_hit, y_hit[0], y_hit[1]))
        pressing = float(approach_speeds(a[body], pair.velocity_b(a)[0], normal))
        kind = "impact"
        if speed <= rest_speed(world.rest_speed, pressing, dt):
            kind, restitution = "resting", 0.0  # a resting contact, not a bounce
        return Collision(kind=kind, t=float(t_hit), body=body, other=other, body_name=model.names[body],
                         other_name=other_name, normal=np.asarray(normal, dtype=float), impact_speed=speed,
                         restitution=restitution, friction=friction,
                         bracket=(float(t + impact.lo * h), float(t + impact.s * h)), trigger=trigger)

    def _event_of_pair(self, impact, t, h, dt, contact) -> Collision:
        """:meth:`_event` from the compiled :class:`_PairContact` (the same numbers)."""
        world, names = self.world, self.model.names
        pairs, k = impact.pairs, impact.k
        t_hit = t + impact.s * h
        body = int(pairs.i[k])
        if isinstance(pairs, BodyPairs):
            other = int(pairs.j[k])
            other_name, trigger = names[other], False
            restitution, friction = world.properties(body, other)
        else:
            other, other_name, trigger = pairs.shape.name, pairs.shape.name, pairs.shape.trigger
            restitution, friction = world.properties(body, pairs.shape)
        speed = contact.speed
        kind = "impact"
        if speed <= rest_speed(world.rest_speed, contact.pressing, dt):
            kind, restitution = "resting", 0.0  # a resting contact, not a bounce
        return Collision(kind=kind, t=float(t_hit), body=body, other=other, body_name=names[body],
                         other_name=other_name, normal=contact.normal[0], impact_speed=speed,
                         restitution=restitution, friction=friction,
                         bracket=(float(t + impact.lo * h), float(t + impact.s * h)), trigger=trigger)

    def _respond(self, impact, event, y, contact=None, compiled=False) -> None:
        """Place the pair at the point of impact, give it new velocities, run the epilogues.

        ``compiled``: through :func:`.compiled_response.resolve_pair` (the same numbers).
        """
        material, spin = (float(event.restitution), float(event.friction)), self.spin
        if len(spin.inverse_inertia):  # spheres that spin: turned on to the impact, where omega changes
            for body in _bodies(impact):
                turn_to(spin, int(body), float(event.t))
        if compiled and isinstance(contact, _PairContact):
            pairs, k = impact.pairs, impact.k
            j = int(pairs.j[k]) if isinstance(pairs, BodyPairs) else -1
            lam = resolve_pair(y, (int(pairs.i[k]), j), self.inverse_masses, contact.normal[0], contact.depth,
                               material, spin)[None]
            self._record(event, lam)
            return
        pair = impact.pairs.subset([impact.k])
        contact = contact if contact is not None else pair.contact(self.radii, y[0])
        other = pair.j if isinstance(pair, BodyPairs) else None
        if compiled:
            j = -1 if other is None else int(other[0])
            lam = resolve_pair(y, (int(pair.i[0]), j), self.inverse_masses, np.ascontiguousarray(contact.normal[0]),
                               float(contact.penetration_depth[0]), material, spin)[None]
        else:
            lam = resolve_spinning(y, (pair.i, other), self.inverse_masses,
                                   (contact.normal, contact.penetration_depth), material, spin)
        self._record(event, lam)

    def _record(self, event, lam) -> None:
        """Log a responded collision (``lam``: its impulse) and run the epilogues; settling is counted."""
        if event.kind == "resting" or event.impact_speed <= 0:  # settling, or grazing: no collision
            self.log.resting_corrections += 1
        else:
            event.impulse = float(np.linalg.norm(lam[0]))
            self.log.events.append(event)
            for epilogue in self.world.epilogues:
                epilogue(event, self.log)


class _PairContact:
    """One pair's contact and approach at its impact, from :func:`.compiled_response.impact_terms`."""

    __slots__ = ("normal", "depth", "speed", "pressing")

    def __init__(self, normal, depth, speed, pressing):
        self.normal = normal[None]  # (1, 3), as a Contact's
        self.depth, self.speed, self.pressing = float(depth), float(speed), float(pressing)


def _speeding_up(pairs, start, y_end):
    """Resting contacts that end the step approaching faster than their rest speed (None: none)."""
    resting = np.flatnonzero(start.resting)
    if pairs.trigger or not resting.size:
        return None
    sub = pairs.subset(resting)
    speed = approach_speeds(y_end[1][sub.i], sub.velocity_b(y_end[1]), start.normal[resting])
    watch = np.zeros(len(pairs), bool)
    watch[resting] = speed > np.broadcast_to(start.rest_speed, (len(pairs),))[resting]
    return watch


def rest_of_step_is_unchanged(integrator) -> bool:
    """Whether, under a constant force, stepping from a point of the step's chord lands on its end.

    True for semi-implicit Euler (v' = v_s + h' a, q' = q_s + h' v' give back y_end for any
    s); False for methods whose positions are not linear along the step (explicit Euler,
    velocity Verlet, RK4: the rest of the step lands O(dt^2) away) and for implicit ones.
    Checked numerically on one body, to 1e-12.
    """
    if integrator.implicit:
        return False
    model = ConstantField(np.array([[0.3, -0.7, -9.81]]))
    y0, dt, s = np.array([[[0.1, 0.2, 0.3]], [[1.0, -2.0, 0.5]]]), 0.01, 0.375
    try:
        y1 = np.asarray(integrator.step(model, 0.0, y0, dt, integrator.init(model, 0.0, y0))[0])
        ys = y0 + s * (y1 - y0)
        y2 = np.asarray(integrator.step(model, s * dt, ys, (1 - s) * dt, integrator.init(model, s * dt, ys))[0])
    except (AttributeError, NotImplementedError, TypeError):  # needs more of the model than its field
        return False
    return bool(np.allclose(y2, y1, rtol=1e-12, atol=1e-15))


def steps_as_semi_implicit_euler(integrator) -> bool:
    """Whether the integrator's step under a constant field is v' = v + h a, q' = q + h v' bit for
    bit: the rest of the step :mod:`.compiled_loop` computes for the bodies an impact moved."""
    if integrator.implicit:
        return False
    a = np.array([[0.3, -0.7, -9.81], [1.0 / 3.0, 2.0 / 7.0, -9.81]])
    y, h = np.array([[[0.1, 0.2, 0.3], [-1.1, 0.7, 2.9]], [[1.0, -2.0, 0.5], [0.1, 1.0 / 3.0, -4.0]]]), 0.0123
    model = ConstantField(a)
    try:
        stepped = np.asarray(integrator.step(model, 0.0, y, h, integrator.init(model, 0.0, y))[0])
    except (AttributeError, NotImplementedError, TypeError):  # needs more of the model than its field
        return False
    v = y[1] + h * a
    return stepped.shape == y.shape and np.array_equal(stepped, np.stack([y[0] + h * v, v]))


class ConstantField:
    """The model seen by some bodies when every force is constant: a(t, q, v) = their rows of the field."""

    xp = np

    def __init__(self, field):
        self.field = field
        self.n_bodies = len(field)

    def acceleration(self, t, q, v):
        field = self.field
        return field if field.shape == np.shape(q) else np.broadcast_to(field, np.shape(q))

    def vector_field(self, t, y):
        return np.stack([y[1], self.acceleration(t, y[0], y[1])])


def _group_columns(groups) -> tuple:
    """The candidate groups as two columns (i, j), in their order, ``j = -1 - k`` for the plane k."""
    if not groups:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return (np.concatenate([pairs.i for pairs in groups]).astype(np.int64),
            np.concatenate([pairs.j if isinstance(pairs, BodyPairs) else np.full(len(pairs), -1 - pairs.index)
                            for pairs in groups]).astype(np.int64))


def _material_tables(world, n_bodies, planes) -> tuple:
    """Each body's and plane's material number, and (restitution, friction) of each pair of materials
    (:meth:`.world.CollisionWorld.properties` as arrays, for :mod:`.compiled_loop`)."""
    body_names = [world.material(b) for b in range(n_bodies)]
    names = sorted(set(body_names) | {p.material for p in planes})
    number = {name: k for k, name in enumerate(names)}
    table = np.array([[world.pair_properties.lookup(a, b) for b in names] for a in names], dtype=float)
    return (np.array([number[m] for m in body_names], np.int64), np.array([number[p.material] for p in planes],
            np.int64), np.ascontiguousarray(table[..., 0]), np.ascontiguousarray(table[..., 1]))


def _pair_bodies(pairs) -> np.ndarray:
    return np.concatenate([pairs.i, pairs.j]) if isinstance(pairs, BodyPairs) else pairs.i


def _bodies(impact) -> np.ndarray:
    """The bodies of an impact's pair (one for a static shape)."""
    pairs, k = impact.pairs, impact.k
    return np.array([pairs.i[k], pairs.j[k]] if isinstance(pairs, BodyPairs) else [pairs.i[k]], dtype=np.int64)


def _still_touching(keys, groups, radii, y, slop) -> set:
    """The pairs among ``keys`` that touch in state ``y`` (candidates of this step only)."""
    touching = set()
    for pairs in groups:
        mine = [k for k in range(len(pairs)) if pairs.key(k) in keys]
        if mine:
            depth = pairs.subset(mine).contact(radii, y[0]).penetration_depth
            touching |= {pairs.key(k) for k, d in zip(mine, depth) if d >= -slop}
    return touching
