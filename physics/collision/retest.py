"""The narrow phase after an impact, compiled: the changed bodies' pairs with spheres and planes.

After an impact the incremental loop (:mod:`.step`) tests the pairs of the bodies it
moved. For the scenes games are made of (spheres in a room of planes, swept testing,
constant forces) one kernel does all of it per changed body: its candidate partners
(the swept-sphere grid of :mod:`.changed_pairs`), each pair's state at the split (the
chords of :mod:`.chords`), its contact (:func:`.narrow_phase.collide_sphere_sphere`,
:func:`.narrow_phase.collide_sphere_plane`), its approach speed and rest speed
(:func:`.step.rest_speed`) and its time of impact (:func:`.time_of_impact.sphere_sphere`,
:func:`.time_of_impact.sphere_plane`). Every formula is written out in the NumPy code's
order of operations, and the kernels are compiled without ``fastmath``, so the numbers
are the NumPy path's bit for bit (tests/test_event_loop.py compares the two loops).
Other shapes, overlap testing and state-dependent forces take the NumPy path.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .changed_pairs import _query


@njit(cache=True, inline="always")
def _dot3(x0, x1, x2, y0, y1, y2):
    """(x * y).sum(axis=-1) for one row: NumPy adds the three products left to right."""
    return x0 * y0 + x1 * y1 + x2 * y2


@njit(cache=True, inline="always")
def _state(y_from, y_end, t_from, t_end, t, b, out):
    """Body ``b``'s state at ``t`` on its chord, as :meth:`.chords.Chords.at` computes it: out (2, 3)."""
    length = t_end - t_from[b]
    f = (t - t_from[b]) / length if length > 0 else 0.0
    for d in range(2):
        for k in range(3):
            y0 = y_from[d, b, k]
            out[d, k] = y0 + f * (y_end[d, b, k] - y0)


@njit(cache=True, inline="always")
def _first_entry(a, b, c):
    disc = b * b - a * c
    if c > 0 and b < 0 and disc >= 0:
        t = c / (-b + np.sqrt(disc))
        if t <= 1:
            return t
    return np.inf


@njit(cache=True)
def retest_spheres_and_planes(h, centers, reach, head, nxt, cell, large, large_list, n_large, inverse_masses,
                              active, changed, is_changed, y_from, y_end, t_from, t_end, t, radii, slop,
                              accelerations, rest_floor, pressing_steps, dt, normals, offsets, triggers):
    """Every pair of a changed body, tested on the sub-step from ``t``.

    Returns ``(i, j, in_contact, speed, normal, rest, s, watch)`` per pair, ``j >= 0`` a
    body and ``j = -1 - k`` the plane ``k``: body pairs first (lexicographic), then the
    plane pairs by plane and body (``changed`` is ascending): the NumPy path's groups.
    """
    pairs = _query(h, centers, reach, head, nxt, cell, large, large_list, n_large, inverse_masses, active,
                   changed, is_changed)
    n_planes = normals.shape[0]
    m = pairs.shape[0] + n_planes * changed.shape[0]
    i_out = np.empty(m, np.int64)
    j_out = np.empty(m, np.int64)
    for p in range(pairs.shape[0]):
        i_out[p], j_out[p] = pairs[p, 0], pairs[p, 1]
    k = pairs.shape[0]
    for s_ in range(n_planes):  # planes the changed bodies' swept spheres reach
        for a in changed:
            if active[a] and inverse_masses[a] > 0:
                height = (centers[a, 0] * normals[s_, 0] + centers[a, 1] * normals[s_, 1]
                          + centers[a, 2] * normals[s_, 2]) - offsets[s_]
                if height <= reach[a]:
                    i_out[k], j_out[k] = a, -1 - s_
                    k += 1
    i_out, j_out = i_out[:k], j_out[:k]
    in_contact = np.empty(k, np.bool_)
    speed = np.empty(k)
    normal = np.empty((k, 3))
    rest = np.empty(k)
    s = np.empty(k)
    watch = np.zeros(k, np.bool_)
    ya = np.empty((2, 3))
    yb = np.empty((2, 3))
    for p in range(k):
        a, b = i_out[p], j_out[p]
        _state(y_from, y_end, t_from, t_end, t, a, ya)
        if b >= 0:
            _state(y_from, y_end, t_from, t_end, t, b, yb)
            # collide_sphere_sphere: the normal joins the centres, depth = r_a + r_b - |d|
            d0, d1, d2 = yb[0, 0] - ya[0, 0], yb[0, 1] - ya[0, 1], yb[0, 2] - ya[0, 2]
            dist = np.sqrt(_dot3(d0, d1, d2, d0, d1, d2))
            if dist > 0:
                n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
            else:
                n0, n1, n2 = 1.0, 0.0, 0.0
            depth = radii[a] + radii[b] - dist
            w0, w1, w2 = ya[1, 0] - yb[1, 0], ya[1, 1] - yb[1, 1], ya[1, 2] - yb[1, 2]
            e0 = y_end[1, a, 0] - y_end[1, b, 0]
            e1 = y_end[1, a, 1] - y_end[1, b, 1]
            e2 = y_end[1, a, 2] - y_end[1, b, 2]
            g0 = accelerations[a, 0] - accelerations[b, 0]
            g1 = accelerations[a, 1] - accelerations[b, 1]
            g2 = accelerations[a, 2] - accelerations[b, 2]
            trigger = False
        else:
            plane = -1 - b
            # collide_sphere_plane: depth = r - (n . c - offset), normal -n
            height = _dot3(ya[0, 0], ya[0, 1], ya[0, 2], normals[plane, 0], normals[plane, 1],
                           normals[plane, 2]) - offsets[plane]
            n0, n1, n2 = 0.0 - normals[plane, 0], 0.0 - normals[plane, 1], 0.0 - normals[plane, 2]
            depth = radii[a] - height
            w0, w1, w2 = ya[1, 0] - 0.0, ya[1, 1] - 0.0, ya[1, 2] - 0.0
            e0, e1, e2 = y_end[1, a, 0] - 0.0, y_end[1, a, 1] - 0.0, y_end[1, a, 2] - 0.0
            g0, g1, g2 = accelerations[a, 0] - 0.0, accelerations[a, 1] - 0.0, accelerations[a, 2] - 0.0
            trigger = triggers[plane]
        normal[p, 0], normal[p, 1], normal[p, 2] = n0, n1, n2
        in_contact[p] = depth >= -slop
        speed[p] = _dot3(w0, w1, w2, n0, n1, n2)
        pressing = _dot3(g0, g1, g2, n0, n1, n2)
        rest[p] = rest_floor + pressing_steps * max(pressing, 0.0) * dt
        if in_contact[p]:
            if speed[p] > rest[p]:
                s[p] = np.inf if trigger else 0.0
            else:  # resting: watched when its approach ends the step faster than its rest speed
                s[p] = np.inf
                watch[p] = (not trigger) and _dot3(e0, e1, e2, n0, n1, n2) > rest[p]
            continue
        if b >= 0:  # sphere_sphere, the rationalised root
            a0, a1, a2 = ya[0, 0] - yb[0, 0], ya[0, 1] - yb[0, 1], ya[0, 2] - yb[0, 2]
            b0 = (y_end[0, a, 0] - ya[0, 0]) - (y_end[0, b, 0] - yb[0, 0])
            b1 = (y_end[0, a, 1] - ya[0, 1]) - (y_end[0, b, 1] - yb[0, 1])
            b2 = (y_end[0, a, 2] - ya[0, 2]) - (y_end[0, b, 2] - yb[0, 2])
            r = radii[a] + radii[b]
            qa, qb = _dot3(b0, b1, b2, b0, b1, b2), _dot3(a0, a1, a2, b0, b1, b2)
            qc = _dot3(a0, a1, a2, a0, a1, a2) - r * r
            if qc <= 0:
                s[p] = 0.0 if qb < 0 else np.inf
            else:
                s[p] = _first_entry(qa, qb, qc)
        else:  # sphere_plane: the height above the plane is linear along the chord
            plane = -1 - b
            h0 = _dot3(ya[0, 0], ya[0, 1], ya[0, 2], normals[plane, 0], normals[plane, 1],
                       normals[plane, 2]) - offsets[plane] - radii[a]
            h1 = _dot3(y_end[0, a, 0], y_end[0, a, 1], y_end[0, a, 2], normals[plane, 0], normals[plane, 1],
                       normals[plane, 2]) - offsets[plane] - radii[a]
            if h0 <= 0:
                s[p] = 0.0 if h1 < h0 else np.inf
            elif h1 <= 0:
                s[p] = h0 / (h0 - h1)
            else:
                s[p] = np.inf
    return i_out, j_out, in_contact, speed, normal, rest, s, watch
