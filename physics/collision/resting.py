"""Resting contact: a body at rest on the floor stays at rest.

A ball lying on the floor is pulled into it by gravity during every step; an impulse
with restitution would make it bounce by a step's worth of speed every step (jitter),
and ignoring it lets it sink. At the end of each step a contact is *resting* when

- the bodies overlap by more than the contact slop (the step pushed one into the other), or
- they touched without approaching at the start of the (sub-)step and end it touching and
  approaching (explicit Euler moves positions with the old velocity, so a ball resting on
  the floor gains a step's worth of downward speed without moving into it).

The bodies are put back in touch along the contact normal, and the part of their
relative velocity that pushes them together is removed: a restitution-free (eps = 0)
impulse, with Coulomb friction limited by it. A resting ball so stays exactly on the
floor with zero velocity: what gravity added over the step is what the contact takes
away, as the floor's support force would. Removing approach speed never adds energy.

Bodies touching several surfaces (a ball in a corner, a stack) are settled by up to
:data:`RESTING_PASSES` Gauss-Seidel passes, one contact after the other.

Sliding and rolling (spheres with spin)
---------------------------------------
The normal impulse J_n a resting contact takes at the end of the step is what its support
force N gave over the step, N = J_n / dt (m g dt for a ball on a level floor), and Coulomb's
kinetic friction mu N acts at the contact point for as long as the contact slips. For spheres
that spin (:class:`.compiled_response.Spin`) this has a closed form over the step: the slip u_t
falls linearly, at mu N (1/m + R^2/I), until it is zero at tau = |J_t| / (mu N) (or the step
ends first), and v and omega change linearly with it (a ball launched sliding on the floor rolls
at 5/7 v0 from t = 2 v0 / (7 mu g)). The step-end impulse with its angular part
(:func:`.compiled_response.respond_spinning`, eps = 0) is that motion's total: J_t = -mu J_n u_t / |u_t|
while it slides, exactly the impulse that stops the slip when it stops within the step. So the
velocities and spins at the step's end are the closed form's. The positions are too: the chord
moved the body by its velocity at the step's start, and friction acting over [0, tau] and
nothing after moves it by J_t / m (dt - tau / 2) less, which :func:`_slide` adds (and turns the
orientation on by the spin's change times the same dt - tau / 2). Measured in
tests/test_spin.py: the rolling ball's v, omega and x at every step's end are the closed form's
to round-off at any dt. This takes N constant over the step, as for a body resting on its
support the whole step; in the step a body lands in, the slide it is given is that of a contact
that began at the step's start (first order in dt there, as the resting impulse itself). Point
masses (no sphere of the scene spins) keep the friction impulse alone, their numbers unchanged:
their velocities are exact at the step's ends as well, their positions first order in dt.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed, approach_speeds
from .compiled_response import NO_TURN, respond, respond_spinning, spinning
from .manifold_geometry import cross3
from .pairs import BodyPairs
from .rigid_solver import EXPONENTIAL, _turn
from .sphere_contacts import dot3, row3, row3_of, sphere_plane, sphere_sphere, sub3

#: an impact slower than what the forces pressing the pair together add over this many
#: steps does not bounce (eps = 0): it ends the endless series of ever smaller bounces
#: (Zeno's) of a body coming to rest, which an energy-gaining integrator (explicit Euler)
#: would otherwise sustain as a jitter of about g dt^2
RESTING_STEPS = 2


@njit(cache=True)
def rest_speed(floor, pressing, dt):
    """Approach speeds at or below this are resting contacts, not bounces (m/s).

    ``pressing`` is the relative acceleration pushing the pair together along the normal;
    ``floor`` (the world's ``rest_speed``) is a floor for pairs nothing presses together (a row of touching
    balls passing on round-off-sized speeds back and forth). Compiled, it is the one definition the
    event loop's NumPy path (on arrays), its re-test and the contact solver (on numbers) call.
    """
    return floor + RESTING_STEPS * np.maximum(pressing, 0.0) * dt


#: passes over the contacts; each pass settles every contact once, one after the other
RESTING_PASSES = 4


def settle(world, contacts, y, bodies, split, ignored=frozenset()) -> int:
    """Settle the resting contacts of the state ``y`` (in place); ``contacts`` = (groups, starts),
    the starts from the sub-step's start; ``bodies`` = (radii, inverse masses, spin) (a
    :class:`.compiled_response.Spin`, whose omega and orientation change in place); ``split`` =
    (slop, dt).

    Returns the number of corrections made.
    """
    groups, starts = contacts
    radii, inverse_masses, spin = bodies
    slop, dt = split
    corrections = 0
    for _ in range(RESTING_PASSES):
        settled: list[np.ndarray] = []
        for pairs, start in zip(groups, starts):
            if pairs.trigger:
                continue
            contact = pairs.contact(radii, y[0])
            depth = contact.penetration_depth
            pressed = depth > slop
            if start.resting.any():
                speed = approach_speeds(y[1][pairs.i], pairs.velocity_b(y[1]), contact.normal)
                pressed |= start.resting & (depth >= -slop) & (speed > 0)
            pressed = np.flatnonzero(pressed)
            if ignored:
                pressed = np.array([k for k in pressed if pairs.key(k) not in ignored], dtype=int)
            if not pressed.size:
                continue
            if isinstance(pairs, BodyPairs):
                for k in pressed:  # pairs may share bodies: one after the other
                    one = pairs.subset([k])
                    now = one.contact(radii, y[0])
                    friction = world.properties(int(one.i[0]), int(one.j[0]))[1]
                    press_rows(y, (one.i.astype(np.int64), one.j.astype(np.int64)), inverse_masses,
                               (np.ascontiguousarray(now.normal, dtype=float), _column(now.penetration_depth)),
                               _column(friction), (spin, float(dt)))
                settled += [pairs.i[pressed], pairs.j[pressed]]
            else:  # one shape: every body at most once, so in any order
                body = pairs.i[pressed].astype(np.int64)
                friction = np.array([world.properties(int(i), pairs.shape)[1] for i in body])
                press_rows(y, (body, np.full(len(body), -1, np.int64)), inverse_masses,
                           (np.ascontiguousarray(contact.normal[pressed], dtype=float), _column(depth[pressed])),
                           _column(friction), (spin, float(dt)))
                settled.append(body)
        if not settled:
            break
        corrections += sum(len(b) for b in settled)
        touched = np.concatenate(settled)
        if len(np.unique(touched)) == len(touched):
            break  # no body settled twice: no contact disturbed another
    return corrections


def _column(x) -> np.ndarray:
    return np.ascontiguousarray(np.atleast_1d(np.asarray(x, dtype=float)))


@njit(cache=True)
def press_rows(y, pairs, inverse_masses, contact, friction, sliding):
    """:func:`press_spinning` (without spin, :func:`.compiled_response.respond` with eps = 0) for each
    row k: ``pairs`` = (i, j) columns (``j < 0``: a static shape),
    ``contact`` = (normals (K, 3), depths (K,)), ``friction`` (K,), ``sliding`` = (spin, dt)."""
    i, j = pairs
    normals, depths = contact
    spin, dt = sliding
    spins = spinning(spin)
    for k in range(i.shape[0]):
        if spins:
            press_spinning(y, (i[k], j[k]), inverse_masses, (row3(normals, k), depths[k]), friction[k], sliding)
        else:
            respond(y, (i[k], j[k]), inverse_masses, row3(normals, k), depths[k], (0.0, friction[k]), NO_TURN)


@njit(cache=True, inline="always")
def press_spinning(y, pair, inverse_masses, contact, friction, sliding):
    """One resting contact among spheres that spin put back in touch, its approach removed (eps = 0)
    with Coulomb friction limited by it (:func:`.compiled_response.respond_spinning`), and the slide's
    closed form over the step (:func:`_slide`). Point masses take :func:`.compiled_response.respond`
    alone, with eps = 0."""
    spin, dt = sliding
    normal, depth = contact
    lam = respond_spinning(y, pair, inverse_masses, normal, depth, (0.0, friction), spin)
    if friction > 0:
        _slide(y, pair, inverse_masses, (normal, lam, friction), spin, dt)


@njit(cache=True, inline="always")
def _slide(y, pair, inverse_masses, impulse, spin, dt):
    """Where friction acting over the step puts the pair, beside where the chord did: each body
    moved J_t / m (dt - tau / 2) further and turned (R / I) (n x J_t) (dt - tau / 2) further, tau =
    dt |J_t| / (mu J_n) the time the contact slid (the module's docstring)."""
    normal, lam, friction = impulse
    i, j = pair
    lam_n = dot3(lam, normal)
    j_t = (lam[0] - lam_n * normal[0], lam[1] - lam_n * normal[1], lam[2] - lam_n * normal[2])
    size = np.sqrt(dot3(j_t, j_t))
    if size == 0.0 or lam_n == 0.0:
        return
    slid = size / (friction * abs(lam_n))  # tau / dt
    late = dt * (1.0 - 0.5 * (slid if slid < 1.0 else 1.0))  # dt - tau / 2
    turn = cross3(normal, lam)
    omega, inverse_inertia, radii, orientation, _ = spin
    for body, sign in ((i, 1.0), (j, -1.0)):
        if body < 0:
            continue
        move = sign * inverse_masses[body] * late
        for k in range(3):
            y[0, body, k] = y[0, body, k] + move * j_t[k]
        scale = radii[body] * inverse_inertia[body]
        if scale > 0:
            _turn(orientation, body, (scale * turn[0], scale * turn[1], scale * turn[2]), late, EXPONENTIAL)


@njit(cache=True)
def settle_spheres_and_planes(y, contacts, bodies, planes, friction, split):
    """:func:`settle` compiled, for spheres and planes (no triggers, none ignored): the same passes,
    decisions and responses in the same order (the incremental event loop's compiled step calls it).

    ``contacts`` = (i, j, resting, first): the groups' pairs concatenated, ``j = -1 - k`` for the
    plane k, ``resting`` the start states' :attr:`.detectors.StartState.resting`, ``first`` (G + 1,)
    where each group begins; ``bodies`` = (radii, inverse masses, spin); ``planes`` = (normals,
    offsets); ``friction`` = (body material (N,), plane material (P,), friction (M, M)); ``split``
    = (slop, dt). Returns the corrections made.
    """
    i, j, resting, first = contacts
    radii, inverse_masses, spin = bodies
    slop, dt = split
    normals, offsets = planes
    body_material, plane_material, mu = friction
    spins = spinning(spin)  # once: the spin's arrays reach the per-contact code only where some body spins
    pressed = np.zeros(i.shape[0], np.bool_)
    settled = np.zeros(radii.shape[0], np.int64)  # how often each body was settled in a pass
    corrections = 0
    for _ in range(RESTING_PASSES):
        count, twice = 0, False
        for g in range(first.shape[0] - 1):
            # which of the group's pairs are pressed, from the state as the group starts
            for p in range(first[g], first[g + 1]):
                a, b = i[p], j[p]
                if b >= 0:
                    n, depth = sphere_sphere(sub3(row3_of(y, 0, b), row3_of(y, 0, a)), radii[a] + radii[b])
                    v_b = row3_of(y, 1, b)
                else:
                    n, depth, _ = sphere_plane(row3_of(y, 0, a), radii[a], row3(normals, -1 - b), offsets[-1 - b])
                    v_b = AT_REST
                approach = approach_speed(row3_of(y, 1, a), v_b, n)
                pressed[p] = depth > slop or (resting[p] and depth >= -slop and approach > 0)
            # each pressed pair put back in touch, one after the other, from its contact now
            for p in range(first[g], first[g + 1]):
                if not pressed[p]:
                    continue
                a, b = i[p], j[p]
                if b >= 0:
                    n, depth = sphere_sphere(sub3(row3_of(y, 0, b), row3_of(y, 0, a)), radii[a] + radii[b])
                    m = body_material[b]
                else:
                    n, depth, _ = sphere_plane(row3_of(y, 0, a), radii[a], row3(normals, -1 - b), offsets[-1 - b])
                    m = plane_material[-1 - b]
                if spins:
                    press_spinning(y, (a, b), inverse_masses, (n, depth), mu[body_material[a], m], (spin, dt))
                else:
                    respond(y, (a, b), inverse_masses, n, depth, (0.0, mu[body_material[a], m]), NO_TURN)
                for body in (a, b):
                    if body >= 0:
                        count += 1
                        settled[body] += 1
                        twice = twice or settled[body] > 1
        if count == 0:
            break
        corrections += count
        settled[:] = 0
        if not twice:
            break  # no body settled twice: no contact disturbed another
    return corrections
