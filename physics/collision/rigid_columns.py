"""The contact solver's columns of a step, gathered from the narrow phase's points in one compiled pass.

For each manifold point (sorted by (a, b, feature)): its bodies, normal and levers from the two
centres, its tangent basis, the material pair's friction and restitution, the speed below which
it rests (:func:`.resting.rest_speed`), its rolling resistance, and the impulses of the last step's
point of the same (a, b, feature), if any (the warm start, the tangential one kept in the new
contact plane). It is what the step did with a dozen NumPy passes over the columns, 0.8 ms of
the pyramid's step (2,360 points) and a tenth of that compiled.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .approach import AT_REST, approach_speed
from .contact_domains import groups_in, phases, rows_of, span
from .resting import rest_speed
from .sphere_contacts import dot3, row3


@njit(cache=True, inline="always")
def tangent_basis(n):
    """Two unit tangents t1, t2 with (n, t1, t2) right-handed and orthonormal.

    The branch-free basis of Duff et al., "Building an Orthonormal Basis, Revisited" (JCGT 2017):
    continuous except where n_z changes sign."""
    x, y, z = n
    sign = 1.0 if z >= 0 else -1.0
    a = -1.0 / (sign + z)
    b = x * y * a
    return (1.0 + sign * x * x * a, sign * b, -sign * x), (b, sign + y * y * a, -y)


@njit(cache=True, parallel=True)
def gather(points, order, movers, materials, previous, context, out, layout):
    """Fill ``out`` (a :class:`.rigid_solver.RigidContactColumns` of C rows): row k from point
    ``order[k]`` of ``points`` (:class:`.manifolds.ManifoldPoints`), so the points are taken in the
    solver's order without a permuted copy of them.

    ``movers`` = (q, accel, rolling) of the bodies: centres at the start of the step, the forces'
    accelerations, and each body's rolling resistance (coefficient times rounding radius, m);
    ``materials`` a :class:`.contact_buffer.Materials`; ``previous`` = (rows, pn, pt, tangent, pr):
    each point's row among the last step's contacts (in their sweep order), or -1
    (:func:`.rigid_solver.previous_rows`), and those contacts' columns, whose impulses warm-start
    the new ones (the tangential one as a world vector, pt1 t1 + pt2 t2 of the last step's
    tangents, taken into the new contact plane); ``context`` = (the world's rest speed, dt). Each row its own:
    group by group as the sweep takes them (:mod:`.contact_domains`), so each row is written by the
    thread that will sweep it; the same bytes on any number of threads.
    """
    for phase in range(phases(layout)):
        for g in prange(groups_in(layout, phase)):
            # (points and order apart: Numba's parallel loop takes no tuple of a NamedTuple)
            _gather_rows((points, order), movers, materials, previous, context, out, rows_of(layout, phase, g))


@njit(cache=True)
def _gather_rows(source, movers, materials, previous, context, out, rows_):
    """:func:`gather` of the rows ``rows_`` = (first, end)."""
    q, accel, rolls = movers
    rows, old_pn, old_pt, old_tangent, old_pr = previous
    floor, dt = context
    body_material, shape_material, restitution_table, friction_table = materials
    points, order = source
    a_, b_, normal, point, separation, _ = points
    # the columns out of the NamedTuple before the loops (a field read in a loop costs a reference count)
    (a_out, b_out, n_out, ra, rb, tangent, s0, vn0, hit, _, friction, restitution, threshold, rolling_out, pn, pt,
     pr, total, most, _, _, _) = out
    for k in range(rows_[0], rows_[1]):
        i = order[k]
        a, b = a_[i], b_[i]
        n = (normal[i, 0], normal[i, 1], normal[i, 2])
        a_out[k], b_out[k] = a, max(b, -1)
        rolling = rolls[a]
        for x in range(3):
            n_out[k, x] = n[x]
            ra[k, x] = point[i, x] - q[a, x]
            rb[k, x] = 0.0 if b < 0 else point[i, x] - q[b, x]
        # the pressing acceleration: the approach speed's one definition on the accelerations
        if b < 0:
            other = shape_material[-1 - b]
            pressing = approach_speed(row3(accel, a), AT_REST, n)
        else:
            other = body_material[b]
            pressing = approach_speed(row3(accel, a), row3(accel, b), n)
            rolling = max(rolling, rolls[b])
        friction[k] = friction_table[body_material[a], other]
        restitution[k] = restitution_table[body_material[a], other]
        threshold[k] = rest_speed(floor, pressing, dt)
        rolling_out[k] = rolling
        t1, t2 = tangent_basis(n)
        for x in range(3):
            tangent[k, 0, x], tangent[k, 1, x] = t1[x], t2[x]
        s0[k], vn0[k], hit[k] = separation[i], 0.0, np.inf
        total[k], most[k] = 0.0, 0.0
        row = rows[i]
        if row >= 0:
            p1, p2 = old_pt[row, 0], old_pt[row, 1]
            p = (p1 * old_tangent[row, 0, 0] + p2 * old_tangent[row, 1, 0],
                 p1 * old_tangent[row, 0, 1] + p2 * old_tangent[row, 1, 1],
                 p1 * old_tangent[row, 0, 2] + p2 * old_tangent[row, 1, 2])
            pn[k], pt[k, 0], pt[k, 1] = old_pn[row], dot3(p, t1), dot3(p, t2)
            for x in range(3):
                pr[k, x] = old_pr[row, x]
        else:
            pn[k], pt[k, 0], pt[k, 1] = 0.0, 0.0, 0.0
            for x in range(3):
                pr[k, x] = 0.0


@njit(cache=True)
def inverse(order):
    """``place`` with ``place[order[k]] = k``: where each sorted point went in the sweep order. (One
    pass on one thread: written by :func:`gather`'s parts on two threads, its scattered writes shared
    cache lines between the cores; step 30 of the 10^4 box pit, 65,000 points, gathered in 1.11 to
    1.19 ms that way and in 0.96 to 1.04 ms with this pass first, 2 threads, the least of 40.)"""
    place = np.empty(len(order), np.int64)
    for k in range(len(order)):
        place[order[k]] = k
    return place


@njit(cache=True, parallel=True)
def first_impacts(key, place, rows, previous_total, total, threads):
    """The step's impacts: of each pair (a, b), its first point pressed in the step (``total`` > 0)
    that was not pressed in the last step, as its row of the sweep order; the pairs in their sorted
    order. ``key`` = (a, b, feature), the sorted points, point i at row ``place[i]``; ``rows[i]``
    its row among the last step's contacts, or -1 (:func:`.rigid_solver.previous_rows`),
    ``previous_total`` their impulses. (A pair's points are one manifold: consecutive in the sorted
    order, and in the same order in the sweep.) The points in ``threads`` parts in parallel, each
    point looking back over its pair's points before it; the parts' impacts then one after another."""
    count = len(place)
    out, found = np.empty(count, np.int64), np.zeros(threads, np.int64)
    for part in prange(threads):
        found[part] = _first_impacts_of(key, (place, rows, previous_total, total), out, span(0, count, part, threads))
    end = found[0]
    for part in range(1, threads):
        first = span(0, count, part, threads)[0]
        for x in range(found[part]):  # forward: end <= first
            out[end + x] = out[first + x]
        end += found[part]
    return out[:end]


@njit(cache=True)
def _first_impacts_of(key, columns, out, points):
    """:func:`first_impacts` of the points ``points`` = (first, end), written from ``out[first]`` on;
    returns their number."""
    a, b, _ = key
    place, rows, previous_total, total = columns
    found = points[0]
    for i in range(points[0], points[1]):
        if not _newly_pressed(place, rows, previous_total, total, i):
            continue
        j = i - 1
        while j >= 0 and a[j] == a[i] and b[j] == b[i] and not _newly_pressed(place, rows, previous_total, total, j):
            j -= 1
        if j < 0 or a[j] != a[i] or b[j] != b[i]:  # none before it in its pair
            out[found] = place[i]
            found += 1
    return found - points[0]


@njit(cache=True, inline="always")
def _newly_pressed(place, rows, previous_total, total, i):
    """Whether point i was pressed in the step and not in the last one."""
    if not total[place[i]] > 0:
        return False
    row = rows[i]
    return row < 0 or not previous_total[row] > 0


@njit(cache=True)
def is_sorted(a, b, feature):
    """Whether the rows (a, b, feature) are in strictly increasing lexicographic order."""
    for k in range(1, len(a)):
        if not (a[k] > a[k - 1] or (a[k] == a[k - 1] and (b[k] > b[k - 1] or (
                b[k] == b[k - 1] and feature[k] > feature[k - 1])))):
            return False
    return True
