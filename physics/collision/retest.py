"""The narrow phase after an impact, compiled: the changed bodies' pairs with spheres and planes.

After an impact the incremental loop (:mod:`.step`) tests the pairs of the bodies it
moved. For the scenes games are made of (spheres in a room of planes, swept testing,
constant forces) one kernel does all of it per changed body: its candidate partners
(the swept-sphere grid of :mod:`.changed_pairs`), each pair's state at the split (the
chords of :mod:`.chords`), its contact (:func:`.sphere_contacts.sphere_sphere`,
:func:`.sphere_contacts.sphere_plane`), its approach speed and rest speed
(:func:`.resting.rest_speed`) and its time of impact
(:func:`.sphere_contacts.sphere_sphere_entry`, :func:`.sphere_contacts.sphere_plane_entry_of`).
Those are the kernels the NumPy path calls too, so the numbers are its bit for bit
(tests/test_event_loop.py compares the two loops). Other shapes, overlap testing and
state-dependent forces take the NumPy path.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed
from .changed_pairs import _query
from .chords import state_at
from .resting import rest_speed
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

# Bodies, Planes and Split reach the kernel as plain tuples, unpacked there in their order
# (:class:`.chords.ChordArrays` says why)


class Bodies(NamedTuple):
    """What the re-test reads of the bodies, (N,) or (N, 3)."""

    radii: np.ndarray
    inverse_masses: np.ndarray
    active: np.ndarray  # bool: not removed from the world
    accelerations: np.ndarray  # (N, 3), constant over the step


class Planes(NamedTuple):
    """The world's planes n . x <= offset, (P, 3) and (P,)."""

    normals: np.ndarray
    offsets: np.ndarray
    triggers: np.ndarray  # bool: reported, never responded to


class Split(NamedTuple):
    """Where the step is split: the time of the impact, the step, the contact slop, the rest-speed floor."""

    t: float
    dt: float
    slop: float  # touching: penetration depth >= -slop, m
    rest_floor: float  # m/s (:func:`.resting.rest_speed`)


@njit(cache=True)
def retest_spheres_and_planes(grid, chords, bodies, planes, split, changed, is_changed):
    """Every pair of a changed body, tested on the sub-step from ``split.t``.

    ``grid`` a :class:`.changed_pairs.GridArrays`, ``chords`` a :class:`.chords.ChordArrays`,
    ``bodies``, ``planes``, ``split`` the structures above (all as plain tuples),
    ``changed`` the changed bodies (ascending) and ``is_changed`` (N,) bool marking them.
    Returns ``(i, j, in_contact, speed, normal, rest, s, watch)`` per pair, ``j >= 0`` a
    body and ``j = -1 - k`` the plane ``k``: body pairs first (lexicographic), then the
    plane pairs by plane and body: the NumPy path's groups.
    """
    pairs = _query(grid, bodies[1], bodies[2], changed, is_changed)
    m = pairs.shape[0] + planes[0].shape[0] * changed.shape[0]
    i_out = np.empty(m, np.int64)
    j_out = np.empty(m, np.int64)
    for p in range(pairs.shape[0]):
        i_out[p], j_out[p] = pairs[p, 0], pairs[p, 1]
    k = planes_reached(grid, bodies, planes, changed, i_out, j_out, pairs.shape[0])
    i_out, j_out = i_out[:k], j_out[:k]
    in_contact = np.empty(k, np.bool_)
    speed = np.empty(k)
    normal = np.empty((k, 3))
    rest = np.empty(k)
    s = np.empty(k)
    watch = np.empty(k, np.bool_)
    for p in range(k):
        in_contact[p], speed[p], n, rest[p], s[p], watch[p] = test_pair(chords, bodies, planes, split, i_out[p],
                                                                         j_out[p])
        normal[p, 0], normal[p, 1], normal[p, 2] = n
    return i_out, j_out, in_contact, speed, normal, rest, s, watch


@njit(cache=True, inline="always")
def planes_reached(grid, bodies, planes, changed, i_out, j_out, k):
    """The plane pairs of the ``changed`` bodies whose swept spheres (``grid``'s) reach the plane, by plane
    and then body, written as rows ``k, k + 1, ...`` of ``i_out`` and ``j_out`` (``j = -1 - plane``; room
    for every plane and body); returns the next free row."""
    centers, reach = grid[1], grid[2]
    inverse_masses, active = bodies[1], bodies[2]
    normals, offsets = planes[0], planes[1]
    for s_ in range(normals.shape[0]):
        for a in changed:
            if active[a] and inverse_masses[a] > 0:
                if plane_height(row3(centers, a), row3(normals, s_), offsets[s_]) <= reach[a]:
                    i_out[k], j_out[k] = a, -1 - s_
                    k += 1
    return k


@njit(cache=True, inline="always")
def test_pair(chords, bodies, planes, split, a, b):
    """Pair (a, b) (``b = -1 - k``: the plane k) tested on the sub-step from ``split.t``: its state at
    the split on the chords, ``(in_contact, speed, normal, rest, s, watch)``: touching (within the
    slop), approach speed, normal (3-tuple), rest speed, time of impact as a fraction of the
    sub-step (0: now, inf: none) and whether a resting contact is watched (its approach ends the
    step faster than its rest speed)."""
    radii, acc = bodies[0], bodies[3]
    normals, offsets, triggers = planes
    t, dt, slop, rest_floor = split
    y_end = chords[1]
    qa, va = state_at(chords, a, t, -1.0)
    if b >= 0:
        qb, vb = state_at(chords, b, t, -1.0)
        n, depth = sphere_sphere(sub3(qb, qa), radii[a] + radii[b])
        end_b, acc_b = row3_of(y_end, 1, b), row3(acc, b)
        trigger = False
    else:
        plane = -1 - b
        qb = vb = end_b = acc_b = AT_REST  # a plane: at rest
        n, depth, _ = sphere_plane(qa, radii[a], row3(normals, plane), offsets[plane])
        trigger = triggers[plane]
    end_a, acc_a = row3_of(y_end, 1, a), row3(acc, a)
    in_contact = depth >= -slop
    speed = approach_speed(va, vb, n)
    pressing = approach_speed(acc_a, acc_b, n)
    rest = rest_speed(rest_floor, pressing, dt)
    watch = False
    if in_contact:
        if speed > rest:
            s = np.inf if trigger else 0.0
        else:  # resting: watched when its approach ends the step faster than its rest speed
            s = np.inf
            watch = (not trigger) and approach_speed(end_a, end_b, n) > rest
    elif b >= 0:
        ea, eb = row3_of(y_end, 0, a), row3_of(y_end, 0, b)
        s = sphere_sphere_entry(sub3(qa, qb), sub3(sub3(ea, qa), sub3(eb, qb)), radii[a] + radii[b])
    else:  # the height above the plane, less r, is linear along the chord
        plane = -1 - b
        h0 = plane_height(qa, row3(normals, plane), offsets[plane]) - radii[a]
        h1 = plane_height(row3_of(y_end, 0, a), row3(normals, plane), offsets[plane]) - radii[a]
        s = sphere_plane_entry_of(h0, h1)
    return in_contact, speed, n, rest, s, watch
