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
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed, approach_speeds
from .compiled_response import resolve_pair
from .pairs import BodyPairs
from .response import resolve
from .sphere_contacts import row3, row3_of, sphere_plane, sphere_sphere, sub3

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


def settle(world, groups, starts, y, radii, inverse_masses, slop: float, ignored=frozenset()) -> int:
    """Settle the resting contacts of the state ``y`` (in place); ``starts`` from the sub-step's start.

    Returns the number of corrections made.
    """
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
                    resolve(y, one.i, one.j, inverse_masses, now.normal, now.penetration_depth, 0.0, friction)
                settled += [pairs.i[pressed], pairs.j[pressed]]
            else:  # one shape: every body at most once, so all at once
                body = pairs.i[pressed]
                friction = np.array([world.properties(int(i), pairs.shape)[1] for i in body])
                resolve(y, body, None, inverse_masses, contact.normal[pressed], depth[pressed], 0.0, friction)
                settled.append(body)
        if not settled:
            break
        corrections += sum(len(b) for b in settled)
        bodies = np.concatenate(settled)
        if len(np.unique(bodies)) == len(bodies):
            break  # no body settled twice: no contact disturbed another
    return corrections


@njit(cache=True)
def settle_spheres_and_planes(y, contacts, radii, inverse_masses, planes, friction, slop):
    """:func:`settle` compiled, for spheres and planes (no triggers, none ignored): the same passes,
    decisions and responses in the same order (the incremental event loop's compiled step calls it).

    ``contacts`` = (i, j, resting, first): the groups' pairs concatenated, ``j = -1 - k`` for the
    plane k, ``resting`` the start states' :attr:`.detectors.StartState.resting`, ``first`` (G + 1,)
    where each group begins; ``planes`` = (normals, offsets); ``friction`` = (body material (N,),
    plane material (P,), friction (M, M)). Returns the corrections made.
    """
    i, j, resting, first = contacts
    normals, offsets = planes
    body_material, plane_material, mu = friction
    pressed = np.zeros(i.shape[0], np.bool_)
    settled = np.zeros(radii.shape[0], np.int64)  # how often each body was settled in a pass
    normal = np.empty(3)
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
                normal[0], normal[1], normal[2] = n
                resolve_pair(y, a, b, inverse_masses, normal, depth, 0.0, mu[body_material[a], m])
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
