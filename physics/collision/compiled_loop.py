"""The incremental event loop's impacts, compiled: one Numba call resolves every impact of a step.

The incremental loop (:mod:`.step`) tests the step's candidate pairs once, then resolves
the impacts earliest first; after each one only the moved bodies are re-integrated and
their pairs re-tested. Per impact that is a heap update, two chords, a few dozen sphere
tests and one response: microseconds of arithmetic, which a round of Python per impact
(objects, dispatch, small NumPy calls) turns into hundreds. Here the whole sequence runs
in one compiled call per step, for the scenes games are made of: spheres in a room of
planes, swept testing, forces constant over the step, semi-implicit Euler, and no
prologue, epilogue or trigger that asks to see an impact as it happens (those scenes take
the Python loop, which calls back into them; :func:`applies`).

What the call does per impact is the Python loop's, step for step and in the same order,
calling the same kernels (the one definition of each formula):

- the earliest valid pair of the queue (:data:`ENTRY` rows, a binary heap of their numbers
  keyed as :class:`.impact_queue.ImpactQueue` keys its heap: time, then body pairs before
  planes, then the pair, then the order the pairs were tested in; lazy deletion by stamps);
- its bodies placed on their chords (:func:`.chords.state_at`), its contact and approach
  (:func:`.compiled_response.contact_terms`), resting or impact (:func:`.resting.rest_speed`),
  the response (:func:`.compiled_response.respond`, through ``impulse_of``; for spheres that
  spin, :func:`_spinning_impact`: turned on to the impact, the impulse's angular part);
- the moved bodies' rest of the step (semi-implicit Euler under the constant field:
  v' = v + h a, q' = q + h v', the integrator's own expressions), their new chords and
  swept bounds (:func:`.chords._restart`), the grid (:func:`.changed_pairs._place`);
- their pairs found (:func:`.changed_pairs.query_into`, :func:`.retest.planes_reached`) and
  re-tested (:func:`.retest.test_pair`: what :func:`.retest.retest_spheres_and_planes` does
  for the Python loop, pair by pair) and the watched resting contacts tested again
  (:meth:`.impact_queue.ImpactQueue.take_watched`, with the NumPy path's rest speeds:
  :func:`_test_rows`);
- the impact appended to the log's columns (:data:`LOGGED`).

The arrays it appends to (the pair rows, the heap, the watched list, the log) grow by
doubling inside the call, so no impact is ever dropped; a step that reaches the cap
returns to Python, which raises :class:`.impact_cap.ImpactCapError` as the Python loop does.
The numbers are the Python loop's bit for bit (tests/test_event_loop_compiled.py compares
logs and trajectories on the collision scenes and on random rooms).

Why the code is shaped as it is: Numba counts references to arrays with atomic operations,
and in three places it does so inside a loop, where they cost more than the arithmetic (on
the crowded 2,000-ball pit, 1,160 of them per impact, half of the call's time, found by
counting the calls to ``NRT_incref`` and ``NRT_decref`` in gdb): an array variable replaced
inside a loop (a buffer grown in place), an inlined function handed an array and left by
several returns, and a call handed arrays (it holds each one for the call). So buffers are
given room before a batch of appends (:func:`_room`), never inside it, the per-impact
kernels are inlined tuple-returning functions (``contact_terms``, ``respond``, ``test_pair``)
and the query's candidate test takes numbers (:func:`.changed_pairs._may_pair`); the call
went from 0.44 to 0.17 s of CPU time on that pit (7.5 to 2.8 us per impact), the same bytes.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed
from .changed_pairs import _place, query_into, sorted_pairs
from .chords import _restart, state_at
from .compiled_response import NO_TURN, contact_terms, respond, respond_spinning, spinning, turn_to
from .resting import rest_speed
from .retest import planes_reached, test_pair
from .sphere_contacts import (
    plane_height,
    row3,
    row3_of,
    sphere_plane,
    sphere_plane_entry_of,
    sphere_sphere,
    sphere_sphere_entry,
    sub3,
)

#: one tested pair: bodies ``i`` and ``j`` (``j = -1 - k`` for the plane k), its heap rank (0 for
#: body pairs, 1 + k for the plane k: body pairs first, planes in the world's order), the stamps
#: of its bodies when tested, its times ``s`` and ``lo`` as fractions of the sub-step
#: ``[t_sub, t_sub + h]`` and ``time`` = t_sub + s h, its start state (touching, approach speed,
#: normal, rest speed) and whether it is still valid (not taken for a re-test)
ENTRY = np.dtype([("i", np.int64), ("j", np.int64), ("rank", np.int64), ("stamp_i", np.int64),
                  ("stamp_j", np.int64), ("s", np.float64), ("lo", np.float64), ("t_sub", np.float64),
                  ("h", np.float64), ("time", np.float64), ("speed", np.float64), ("nx", np.float64),
                  ("ny", np.float64), ("nz", np.float64), ("rest", np.float64), ("in_contact", np.bool_),
                  ("valid", np.bool_)], align=True)
#: one logged impact: time, bodies (``other = -1 - k`` for the plane k), normal, approach speed,
#: the impulse Lambda on ``body`` and the bracket
LOGGED = np.dtype([("t", np.float64), ("body", np.int64), ("other", np.int64), ("nx", np.float64),
                   ("ny", np.float64), ("nz", np.float64), ("speed", np.float64), ("lx", np.float64),
                   ("ly", np.float64), ("lz", np.float64), ("t_lo", np.float64), ("t_hi", np.float64)],
                  align=True)

#: the counters of :func:`resolve_impacts` (``sizes``), by position
N_ENTRIES, N_HEAP, N_WATCHED, N_LOGGED, RESOLVED, RESTING, CAP, CAP_REACHED = range(8)


def new_sizes(n_entries: int, cap: int) -> np.ndarray:
    """The counters of a step's call: ``n_entries`` pairs tested (none queued yet), the cap."""
    sizes = np.zeros(8, np.int64)
    sizes[N_ENTRIES], sizes[CAP] = n_entries, cap
    return sizes


def applies(world, field, planes) -> bool:
    """Whether a scene's incremental step can run compiled (its integrator aside, see
    :func:`.step.steps_as_semi_implicit_euler`): spheres and planes only, none a trigger, swept
    testing, constant forces, no prologue but the built-in one (which only cancels triggers)
    and no epilogue."""
    from .events import cancel_triggers

    return (world.detector == "swept" and field is not None and len(planes) == len(world.shapes)
            and not any(p.trigger for p in planes) and tuple(world.prologues) in ((), (cancel_triggers,))
            and not world.epilogues)


@njit(cache=True)
def first_rows(pairs, chords, now, bodies, planes, split, stamps):
    """The step's first tests as :data:`ENTRY` rows: ``(entries, watched, n_watched)``.

    ``pairs`` = (i, j), the broadphase's candidate groups concatenated in their order (body
    pairs, then each plane's bodies, ``j = -1 - k`` for the plane k); ``now`` the state at the
    step's start (the chords' start). Each pair is tested as the NumPy path's
    :meth:`.step.CollisionStep._test` tests the groups (its start state, the rest speeds when
    some pair touches and approaches, the impact or resting state of a touching pair, the
    swept time of impact of a pair apart, the resting contacts to watch): by
    :func:`_test_rows`, which re-tests the watched contacts, on the whole step.
    """
    i, j = pairs
    t, dt = split[0], split[1]
    k = i.shape[0]
    entries = np.zeros(2 * k + 64, ENTRY)
    for p in range(k):
        _append(entries, p, i[p], j[p], stamps, t, dt)
    watched = np.empty(k + 64, np.int64)
    # first as an int64, as the loop's later calls pass it: the literal 0 compiled _test_rows a second time
    n_watched = _test_rows(chords, now, bodies, planes, split, entries[:k], watched, np.int64(0))
    for p in range(k):
        entries[p].time = t + entries[p].s * dt
    return entries, watched, n_watched


@njit(cache=True)
def settle_rows(entries, n_entries, stamps):
    """The current pairs of the step's rows (valid, their bodies unchanged since tested) as
    :func:`.resting.settle_spheres_and_planes` takes its groups: ``(i, j, resting, first)``,
    the body pairs (one group, lexicographic) and then one group per plane (by body), as
    :meth:`.impact_queue.ImpactQueue.current_groups` orders them."""
    n = stamps.shape[0]
    key = np.empty(n_entries, np.int64)
    row = np.empty(n_entries, np.int64)
    m = 0
    for e in range(n_entries):
        if _current(entries, stamps, e):
            x = entries[e]
            key[m] = x.i * n + x.j if x.j >= 0 else n * n + (-1 - x.j) * n + x.i
            row[m] = e
            m += 1
    order = np.argsort(key[:m])  # the keys are distinct: each pair is current once
    i, j = np.empty(m, np.int64), np.empty(m, np.int64)
    resting = np.empty(m, np.bool_)
    first = np.empty(m + 2, np.int64)
    groups = 0
    first[0] = 0
    for p in range(m):
        x = entries[row[order[p]]]
        i[p], j[p] = x.i, x.j
        resting[p] = x.in_contact and not x.speed > x.rest
        if p > 0 and j[p] != j[p - 1] and j[p] < 0:  # a new plane's group
            groups += 1
            first[groups] = p
    if m:
        groups += 1
        first[groups] = m
    return i, j, resting, first[:groups + 1]


# --- the heap: entry numbers, earliest first --------------------------------------------------


@njit(cache=True, inline="always")
def _before(entries, a, b):
    """Whether entry a comes before entry b: (time, rank, i, j, order tested), ImpactQueue's heap key."""
    x, y = entries[a], entries[b]
    if x.time != y.time:
        return x.time < y.time
    if x.rank != y.rank:
        return x.rank < y.rank
    if x.i != y.i:
        return x.i < y.i
    jx = x.j if x.j >= 0 else 0
    jy = y.j if y.j >= 0 else 0
    if jx != jy:
        return jx < jy
    return a < b


@njit(cache=True)
def _push(heap, n, entries, e):
    """Push entry ``e`` onto the heap of ``n`` (room made beforehand: :func:`_room`); returns ``n + 1``."""
    k = n
    while k > 0:
        parent = (k - 1) >> 1
        if not _before(entries, e, heap[parent]):
            break
        heap[k] = heap[parent]
        k = parent
    heap[k] = e
    return n + 1


@njit(cache=True)
def _pop(heap, n, entries):
    """Remove the earliest entry; returns ``(it, n - 1)``."""
    top = heap[0]
    n -= 1
    last = heap[n]
    k = 0
    while True:
        child = 2 * k + 1
        if child >= n:
            break
        if child + 1 < n and _before(entries, heap[child + 1], heap[child]):
            child += 1
        if not _before(entries, heap[child], last):
            break
        heap[k] = heap[child]
        k = child
    if n > 0:
        heap[k] = last
    return top, n


@njit(cache=True)
def _room(a, n, more):
    """``a`` (its first ``n`` elements in use) with room for ``more``: itself, or a copy twice as long.

    The arrays the loop appends to are given room before each batch of appends, never inside it:
    an array variable replaced inside a loop costs an atomic reference count up and down at every
    iteration, which made most of a query's time when its buffer grew in place."""
    if n + more <= a.shape[0]:
        return a
    b = np.empty(max(2 * a.shape[0], n + more) + 16, a.dtype)
    b[:n] = a[:n]
    return b


@njit(cache=True, inline="always")
def _current(entries, stamps, e):
    x = entries[e]
    if not x.valid or stamps[x.i] != x.stamp_i:
        return False
    return x.j < 0 or stamps[x.j] == x.stamp_j


@njit(cache=True, inline="always")
def _append(entries, n, a, b, stamps, t, h):
    """Row ``n`` (room made beforehand) is the pair (a, b) tested on [t, t + h], stamped now; returns ``n + 1``."""
    x = entries[n]
    x.i, x.j = a, b
    x.rank = 0 if b >= 0 else -b  # 1 + the plane's number
    x.stamp_i = stamps[a]
    x.stamp_j = stamps[b] if b >= 0 else 0
    x.t_sub, x.h, x.valid = t, h, True
    return n + 1


# --- the step's impacts ---------------------------------------------------------------------


@njit(cache=True)
def resolve_impacts(chords, now, grid, bodies, world, split, queue, log):
    """Every impact of the step, earliest first, until none is left or the cap is reached.

    ``chords`` a :class:`.chords.ChordArrays`, ``now`` the chords' state array, ``grid`` =
    (:class:`.changed_pairs.GridArrays`, links), ``bodies`` a :class:`.retest.Bodies`, ``world`` =
    (:class:`.retest.Planes`, (body material (N,), plane material (P,), restitution (M, M),
    friction (M, M)), :class:`.compiled_response.Spin`), ``split`` a :class:`.retest.Split` at the
    step's start, ``queue`` = (entries, heap, watched, stamps (N,), is_changed (N,), sizes) and
    ``log`` the :data:`LOGGED` rows; all plain tuples. ``sizes`` (:func:`new_sizes`) is updated in place.
    Returns ``(entries, heap, watched, log)``, grown where they filled up.
    """
    radii, inverse_masses, active, acc = bodies
    planes, materials, spin = world
    spins = spinning(spin)  # once: the spin's arrays reach the per-impact code only where some body spins
    body_material, plane_material, restitution, friction = materials
    t, dt, slop, floor = split
    t_end = chords[3]
    grid_arrays, links = grid
    centers, reach = grid_arrays[1], grid_arrays[2]
    entries, heap, watched, stamps, is_changed, sizes = queue
    n_entries, n_heap, n_watched, n_log = sizes[N_ENTRIES], sizes[N_HEAP], sizes[N_WATCHED], sizes[N_LOGGED]
    resolved, resting, cap = 0, sizes[RESTING], sizes[CAP]
    heap = _room(heap, n_heap, n_entries)
    for e in range(n_entries):  # the step's first tests
        if np.isfinite(entries[e].s):
            n_heap = _push(heap, n_heap, entries, e)
    y_rest = np.empty((2, 2, 3))  # the new end states of an impact's bodies
    pair = np.empty(2, np.int64)  # an impact's bodies
    found = np.empty((64, 2), np.int64)  # the candidate pairs of its bodies
    new_i, new_j = np.empty(64, np.int64), np.empty(64, np.int64)  # their pairs, in the order tested
    while True:
        h = t_end - t
        e = -1
        while n_heap > 0:
            top, n_heap = _pop(heap, n_heap, entries)
            if _current(entries, stamps, top):
                e = top
                break
        if e < 0:
            break
        if resolved == cap:
            sizes[CAP_REACHED] = 1
            break
        # The impact as a fraction of what is left of the step (ImpactQueue's PairTable.impact)
        x = entries[e]
        if t == x.t_sub:
            s, lo = x.s, x.lo
        else:
            f = (x.t_sub + x.s * x.h - t) / h
            s = f if f > 0.0 else 0.0
            f = (x.t_sub + x.lo * x.h - t) / h
            f = f if f > 0.0 else 0.0
            lo = f if f < s else s
        a, b = x.i, x.j
        t_hit = t + s * h
        # Its bodies at the impact, on their chords (at the detector's own fraction where tested)
        for body in (a, b):
            if body >= 0:
                q, v = state_at(chords, body, t_hit, x.s if chords[2][body] == x.t_sub else -1.0)
                now[0, body, 0], now[0, body, 1], now[0, body, 2] = q
                now[1, body, 0], now[1, body, 1], now[1, body, 2] = v
        normal, depth, speed, pressing = contact_terms(now, a, b, radii, acc, planes)
        mb = body_material[b] if b >= 0 else plane_material[-1 - b]
        eps, mu = restitution[body_material[a], mb], friction[body_material[a], mb]
        settling = speed <= rest_speed(floor, pressing, dt)
        if settling:
            eps = 0.0  # a resting contact, not a bounce
        t_lo = t + lo * h
        t = t + s * (t_end - t)
        # Respond (spheres that spin: turned on to the impact first, their omega changes in it)
        if spins:
            lam = _spinning_impact(now, (a, b), inverse_masses, normal, depth, (eps, mu), spin, t_hit)
        else:
            lam = respond(now, (a, b), inverse_masses, normal, depth, (eps, mu), NO_TURN)
        if settling or speed <= 0:  # settling, or grazing: no collision
            resting += 1
        else:
            log = _room(log, n_log, 1)
            r = log[n_log]
            r.t, r.body, r.other, r.speed, r.t_lo, r.t_hi = t_hit, a, b, speed, t_lo, t_hit
            r.nx, r.ny, r.nz, r.lx, r.ly, r.lz = normal[0], normal[1], normal[2], lam[0], lam[1], lam[2]
            n_log += 1
        resolved += 1
        # Only what the impact changed: its bodies' rest of the step, their chords, bounds and stamps
        pair[0], pair[1] = a, b
        moved = pair[:2] if b >= 0 else pair[:1]
        h = t_end - t
        for p in range(moved.shape[0]):  # semi-implicit Euler under the constant field
            m = moved[p]
            for k in range(3):
                y_rest[1, p, k] = now[1, m, k] + h * acc[m, k]
                y_rest[0, p, k] = now[0, m, k] + h * y_rest[1, p, k]
        _restart(chords, now, (centers, reach, radii), moved, t, y_rest, slop)
        _place(grid_arrays, links, moved)
        for m in moved:
            stamps[m] += 1
        # Their pairs (:func:`.retest.retest_spheres_and_planes`'s, in its order), re-tested on [t, t_end]
        for m in moved:
            is_changed[m] = True
        k = query_into(grid_arrays, inverse_masses, active, moved, is_changed, found)
        if k > found.shape[0]:
            found = np.empty((2 * k, 2), np.int64)
            query_into(grid_arrays, inverse_masses, active, moved, is_changed, found)
        for m in moved:
            is_changed[m] = False
        body_pairs = sorted_pairs(found, k, radii.shape[0])
        new_i, new_j = _room(new_i, 0, k + planes[0].shape[0] * 2), _room(new_j, 0, k + planes[0].shape[0] * 2)
        for p in range(k):
            new_i[p], new_j[p] = body_pairs[p, 0], body_pairs[p, 1]
        k = planes_reached(grid_arrays, bodies, planes, moved, new_i, new_j, k)
        entries, heap, watched = _room(entries, n_entries, k), _room(heap, n_heap, k), _room(watched, n_watched, k)
        split_now = (t, dt, slop, floor)
        for p in range(k):
            n_entries = _append(entries, n_entries, new_i[p], new_j[p], stamps, t, h)
            y = entries[n_entries - 1]
            y.in_contact, y.speed, n, y.rest, y.s, watch = test_pair(chords, bodies, planes, split_now, new_i[p],
                                                                     new_j[p])
            y.nx, y.ny, y.nz = n
            y.lo, y.time = y.s, t + y.s * h
            if np.isfinite(y.s):
                n_heap = _push(heap, n_heap, entries, n_entries - 1)
            if watch:
                watched[n_watched] = n_entries - 1
                n_watched += 1
        # Resting contacts speeding up along their chords: tested again at every impact, as new rows
        first = n_entries
        entries = _room(entries, n_entries, n_watched)
        for w in range(n_watched):
            if _current(entries, stamps, watched[w]):
                z = entries[watched[w]]
                z.valid = False
                n_entries = _append(entries, n_entries, z.i, z.j, stamps, t, h)
        n_watched = 0
        if n_entries > first:
            for e in range(first, n_entries):  # every body's state at t first, as Chords.at before the tests
                for body in (entries[e].i, entries[e].j):
                    if body >= 0:
                        q, v = state_at(chords, body, t, -1.0)
                        now[0, body, 0], now[0, body, 1], now[0, body, 2] = q
                        now[1, body, 0], now[1, body, 1], now[1, body, 2] = v
            n_watched = _test_rows(chords, now, bodies, planes, split_now, entries[first:n_entries], watched, first)
            heap = _room(heap, n_heap, n_entries - first)
            for e in range(first, n_entries):
                entries[e].time = t + entries[e].s * h
                if np.isfinite(entries[e].s):
                    n_heap = _push(heap, n_heap, entries, e)
    sizes[N_ENTRIES], sizes[N_HEAP], sizes[N_WATCHED], sizes[N_LOGGED] = n_entries, n_heap, n_watched, n_log
    sizes[RESOLVED], sizes[RESTING] = resolved, resting
    return entries, heap, watched, log


@njit(cache=True)
def _spinning_impact(now, pair, inverse_masses, normal, depth, material, spin, t_hit):
    """An impact among spheres that spin: both turned on to ``t_hit``, then the response with the
    impulse's angular part. Not inlined: the loop keeps the point masses' code alone (this call, taken
    only where some body spins, kept the crowded pit's loop as fast as before the spin)."""
    turn_to(spin, pair[0], t_hit)
    turn_to(spin, pair[1], t_hit)
    return respond_spinning(now, pair, inverse_masses, normal, depth, material, spin)


@njit(cache=True)
def _test_rows(chords, now, bodies, planes, split, rows, watched, first):
    """The pairs ``rows`` (new :data:`ENTRY` rows ``first, first + 1, ...``, bodies and stamps set; their
    bodies' states at ``t`` in ``now``) tested on [t, t_end] as the NumPy path tests a group
    (:meth:`.step.CollisionStep._test`): the start state at ``t``, rest speeds only when some pair
    touches and approaches (else 0), an impact now for a touching pair approaching faster, the
    swept time of impact for a pair apart. Their times are written into ``rows``; the resting
    ones to watch are written into ``watched`` (room for all of them) by their numbers. Returns
    how many."""
    radii, _, _, acc = bodies
    normals, offsets, _ = planes
    t, dt, slop, floor = split
    y_end = chords[1]
    k = rows.shape[0]
    n_watched = 0
    pressed = False
    for p in range(k):
        x = rows[p]
        a, b = x.i, x.j
        qa, va = row3_of(now, 0, a), row3_of(now, 1, a)
        if b >= 0:
            qb, vb = row3_of(now, 0, b), row3_of(now, 1, b)
            n, depth = sphere_sphere(sub3(qb, qa), radii[a] + radii[b])
        else:
            vb = AT_REST
            n, depth, _ = sphere_plane(qa, radii[a], row3(normals, -1 - b), offsets[-1 - b])
        x.nx, x.ny, x.nz = n
        x.in_contact = depth >= -slop
        x.speed = approach_speed(va, vb, n)
        pressed = pressed or (x.in_contact and x.speed > 0)
    for p in range(k):
        x = rows[p]
        a, b = x.i, x.j
        n = (x.nx, x.ny, x.nz)
        acc_b = row3(acc, b) if b >= 0 else AT_REST
        x.rest = rest_speed(floor, approach_speed(row3(acc, a), acc_b, n), dt) if pressed else 0.0
        x.lo = 0.0
        if x.in_contact:
            x.s = 0.0 if x.speed > x.rest else np.inf
            if not x.speed > x.rest:  # resting: watched again when its approach ends the step faster
                end_b = row3_of(y_end, 1, b) if b >= 0 else AT_REST
                if approach_speed(row3_of(y_end, 1, a), end_b, n) > x.rest:
                    watched[n_watched] = first + p
                    n_watched += 1
            continue
        qa = row3_of(now, 0, a)
        if b >= 0:
            qb = row3_of(now, 0, b)
            chord = sub3(sub3(row3_of(y_end, 0, a), qa), sub3(row3_of(y_end, 0, b), qb))
            x.s = sphere_sphere_entry(sub3(qa, qb), chord, radii[a] + radii[b])
        else:
            plane = -1 - b
            h0 = plane_height(qa, row3(normals, plane), offsets[plane]) - radii[a]
            h1 = plane_height(row3_of(y_end, 0, a), row3(normals, plane), offsets[plane]) - radii[a]
            x.s = sphere_plane_entry_of(h0, h1)
        x.lo = x.s
    return n_watched
