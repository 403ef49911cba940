"""The rigid narrow phase: contact manifolds of spheres, boxes and capsules, with each other and the static shapes.

A manifold is the set of points (up to 4) at which two shapes touch or will touch within the
speculative margin: one normal per point (from a towards b), the separation there (negative =
penetration), the point midway between the two surfaces, and a feature id naming the pair of
features (faces, edges, corners, segment ends) that touch, the same from step to step while the
same features touch, so that a solver can warm start each point from its impulse of the step
before (Box2D's and Box3D's ``b2ManifoldPoint.id``).

The pair table (:func:`collide`, filed both ways round as Box2D's ``s_registers``): each pair of
kinds has one kernel, written for the kinds in the order sphere < box < capsule < plane; the
other order calls it with the shapes swapped and flips the normals.

==================  ================================================================  ==========
pair                method                                                            points
==================  ================================================================  ==========
sphere–sphere       :func:`.sphere_contacts.sphere_sphere`, the one definition        1
sphere–box          centre clamped to the box; nearest face from inside               1
sphere–capsule      centre against the closest point of the segment                   1
box–box             SAT over 15 axes, reference face clips incident face; edge–edge   <= 4
box–capsule         exact segment–box distance; clipped to a face; SAT from inside    <= 2
capsule–capsule     closest points of the segments; both ends of a side-by-side run   <= 2
sphere–plane        :func:`.sphere_contacts.sphere_plane`                             1
box–plane           the corners of the face most opposed to the plane                 <= 4
capsule–plane       each end of the segment as a sphere                               <= 2
==================  ================================================================  ==========

A static box (:class:`.shapes.Box`, :class:`.shapes.OrientedBox`) is a box body of infinite
mass; a static plane (:class:`.shapes.Plane`) is the half-space below it. Static shape k is body
``-1 - k`` in the ``b`` column. Everything is float64 and compiled with Numba (``cache=True``,
no ``fastmath``): the same inputs give the same bytes.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from .. import quaternion as quat
from .contact_domains import span
from .manifold_box import box_box, box_plane
from .manifold_capsule_box import box_capsule
from .manifold_geometry import SCRATCH_WORDS, scratch_in, to_local
from .manifold_round import (
    capsule_capsule,
    capsule_plane,
    round_points,
    sphere_box,
    sphere_capsule,
    sphere_plane_points,
)
from .shapes import Box, OrientedBox, Plane
from .sphere_contacts import dot3, sub3

#: the kinds of shape a body can be; PLANE is a static shape's only
SPHERE, BOX, CAPSULE, PLANE = 0, 1, 2, 3
KIND_NAMES = ("sphere", "box", "capsule", "plane")
#: most points one pair's manifold has (a box's face clipped and reduced, Box2D's b2_maxManifoldPoints in 3-D)
MAX_POINTS = 4
#: |q| may differ from 1 by this much: the rotation methods renormalise every step, to round-off
UNIT_TOLERANCE = 1e-9


class RigidShapes(NamedTuple):
    """The shape of each of the N bodies of a scene (spheres too)."""

    kind: np.ndarray    # (N,) int8: SPHERE, BOX or CAPSULE
    radius: np.ndarray  # (N,) m: sphere radius, capsule radius, 0 for a box
    half: np.ndarray    # (N, 3) m: box half edges; capsule (0, 0, half length of its segment along body z); sphere 0


class Poses(NamedTuple):
    position: np.ndarray     # (N, 3) centre of mass, m
    orientation: np.ndarray  # (N, 4) unit quaternions [w, x, y, z], body to world


class ManifoldPoints(NamedTuple):
    """(C,) columns, sorted by (a, b, feature): one row per contact point."""

    a: np.ndarray           # int64 body index
    b: np.ndarray           # int64 body index, or -1 - k for the k-th static shape
    normal: np.ndarray      # (C, 3) unit, from a towards b
    point: np.ndarray       # (C, 3) world point midway between the two surfaces
    separation: np.ndarray  # (C,) m, negative = penetration
    feature: np.ndarray     # int64 id of the touching feature pair, the same across steps while the same features touch


class Solids(NamedTuple):
    """Shapes placed in the world, as the kernels read them: bodies, or the static shapes.

    A plane n . x <= offset has its normal as the third axis of its frame.
    """

    kind: np.ndarray    # (M,) int8
    centre: np.ndarray  # (M, 3) m
    frame: np.ndarray   # (M, 3, 3) rotation matrices: columns are the shape's axes in the world
    half: np.ndarray    # (M, 3) m
    radius: np.ndarray  # (M,) m
    offset: np.ndarray  # (M,) m, a plane's


class Solid(NamedTuple):
    """One shape of :class:`Solids`, its vectors as tuples (the kernels' registers)."""

    kind: int
    centre: tuple
    frame: tuple  # its three axes
    half: tuple
    radius: float
    offset: float


class CheckedShapes(RigidShapes):
    """:class:`RigidShapes` that :func:`check_shapes` passed: a scene checks its shapes once, not every step."""

    __slots__ = ()


def check_shapes(shapes: RigidShapes) -> CheckedShapes:
    """``shapes`` as float64 / int8 arrays, or a one-line ValueError naming the first body that is no shape.

    Shapes it already passed (a :class:`CheckedShapes`) are returned as they are: the check is a
    few passes over the N bodies, a tenth of a step of 10^3 boxes, and a scene's shapes do not change."""
    if isinstance(shapes, CheckedShapes):
        return shapes
    kind = np.asarray(shapes.kind)
    n = len(kind)
    radius = np.asarray(shapes.radius, dtype=float).reshape(n)
    half = np.asarray(shapes.half, dtype=float).reshape(n, 3)
    box, capsule = kind == BOX, kind == CAPSULE
    problems = [  # (bodies, what is wrong with them), in the order they are reported
        (~np.isin(kind, (SPHERE, BOX, CAPSULE)),
         lambda k: f"kind {kind[k]} is no shape; valid: 0 (sphere), 1 (box), 2 (capsule)"),
        (~(np.isfinite(radius) & np.all(np.isfinite(half), axis=1)),
         lambda k: f"radius and half edges must be finite, got {radius[k]} and {half[k].tolist()}"),
        (box & ~np.all(half > 0, axis=1),
         lambda k: f"a box needs half edges > 0 m (a degenerate box has no faces), got {half[k].tolist()}"),
        (~box & ~(radius > 0), lambda k: f"a {KIND_NAMES[kind[k]]} needs a radius > 0 m, got {radius[k]}"),
        (capsule & ~(half[:, 2] >= 0),
         lambda k: f"a capsule's length must be >= 0 m, got the half length {half[k, 2]}"),
    ]
    bad = np.zeros(n, dtype=bool)
    for which, _ in problems:
        bad |= which
    if np.any(bad):
        k = int(np.argmax(bad))
        message = next(say for which, say in problems if which[k])
        raise ValueError(f"body {k}: {message(k)}")
    return CheckedShapes(kind.astype(np.int8), radius, half)


def bounding_radius(shapes: RigidShapes) -> np.ndarray:
    """(N,) m: the radius of the smallest sphere about each body's centre that holds it, for the broadphase.

    sphere r; box |half| (its corner); capsule r + half length.
    """
    return reach(check_shapes(shapes))


def reach(shapes: RigidShapes) -> np.ndarray:
    """:func:`bounding_radius` of checked shapes: :func:`extents` with no margin (x + 0 = x)."""
    return extents(shapes, np.zeros(len(shapes.kind)))


def body_solids(shapes: RigidShapes, poses: Poses) -> Solids:
    """The bodies placed by their poses (checked: finite positions, unit quaternions)."""
    n = len(shapes.kind)
    position = np.ascontiguousarray(poses.position, dtype=float)
    orientation = np.ascontiguousarray(poses.orientation, dtype=float)
    if position.shape != (n, 3) or orientation.shape != (n, 4):
        raise ValueError(f"poses must be positions (N, 3) and orientations (N, 4) for the N = {n} bodies, "
                         f"got {position.shape} and {orientation.shape}")
    frame = np.empty((n, 3, 3))
    if n >= PARALLEL_PAIRS and numba.get_num_threads() > 1:
        k = placed_frames(position, orientation, frame, numba.get_num_threads())
    else:
        k = _frames_of(position, orientation, frame, (0, n))
    if k < n:
        raise ValueError(f"body {k}: the pose needs a finite position and a unit quaternion [w, x, y, z], "
                         f"got {position[k].tolist()} and {orientation[k].tolist()}")
    return Solids(shapes.kind, position, frame, shapes.half, shapes.radius, np.zeros(n))


_matrix = njit(inline="always")(quat.matrix_components)


@njit(cache=True, parallel=True, error_model="numpy")
def placed_frames(position, orientation, frame, threads):
    """Each body's frame, the rotation matrix of its quaternion, into ``frame`` (N, 3, 3); the first
    body whose pose is none (see :func:`_frames_of`), or N; ``threads`` parts in parallel (the NumPy
    matrix and checks took 0.5 ms a step of 10^4 boxes, on one thread)."""
    n = len(position)
    first_bad = np.full(threads, n)
    for part in prange(threads):
        first_bad[part] = _frames_of(position, orientation, frame, span(0, n, part, threads))
    return first_bad.min()


@njit(cache=True, error_model="numpy")
def _frames_of(position, orientation, frame, rows):
    """:func:`placed_frames` of the bodies ``rows`` = (first, end): the first of them whose position is
    not finite or whose |q| differs from 1 by more than :data:`UNIT_TOLERANCE`, or N."""
    n = len(position)
    bad = n
    for k in range(rows[0], rows[1]):
        w, x, y, z = orientation[k, 0], orientation[k, 1], orientation[k, 2], orientation[k, 3]
        matrix = _matrix(w, x, y, z)
        for r in range(3):
            for c in range(3):
                frame[k, r, c] = matrix[r][c]
        unit = abs(np.sqrt(w * w + x * x + y * y + z * z) - 1) <= UNIT_TOLERANCE
        finite = np.isfinite(position[k, 0]) and np.isfinite(position[k, 1]) and np.isfinite(position[k, 2])
        if bad == n and not (unit and finite):
            bad = k
    return bad


def static_solids(statics) -> Solids:
    """The static shapes: a Plane, an axis-aligned Box (a box of the identity frame) or an OrientedBox each."""
    rows = []
    for k, s in enumerate(statics):
        if isinstance(s, Plane):
            normal = np.asarray(s.normal, dtype=float)
            frame = np.eye(3)
            frame[:, 2] = normal
            rows.append((PLANE, np.zeros(3), frame, np.zeros(3), float(s.offset)))
        elif isinstance(s, Box):
            rows.append((BOX, s.center, np.eye(3), s.half_extents, 0.0))
        elif isinstance(s, OrientedBox):
            rows.append((BOX, s.center, s.rotation, s.half_extents, 0.0))
        else:
            raise ValueError(f"static shape {k}: a {type(s).__name__} has no manifold; valid: Plane, Box, OrientedBox")
    m = len(rows)
    return Solids(np.array([r[0] for r in rows], dtype=np.int8),
                  np.array([r[1] for r in rows], dtype=float).reshape(m, 3),
                  np.array([r[2] for r in rows], dtype=float).reshape(m, 3, 3),
                  np.array([r[3] for r in rows], dtype=float).reshape(m, 3), np.zeros(m),
                  np.array([r[4] for r in rows], dtype=float))


@njit(cache=True, inline="always", error_model="numpy")
def solid(solids, k):
    """Shape k of ``solids`` (a :class:`Solids`, or a plain tuple of its columns) as a :class:`Solid`."""
    kind, c, f, h, radius, offset = solids
    return solid_of(kind, c, f, h, radius, offset, k)


@njit(cache=True, inline="always", error_model="numpy")
def solid_of(kind, c, f, h, radius, offset, k):
    """:func:`solid` of the columns passed one by one: in a loop, the columns taken out of their
    tuple once before it (see :func:`_slots_of_chunk`)."""
    return Solid(kind[k], (c[k, 0], c[k, 1], c[k, 2]),
                 ((f[k, 0, 0], f[k, 1, 0], f[k, 2, 0]), (f[k, 0, 1], f[k, 1, 1], f[k, 2, 1]),
                  (f[k, 0, 2], f[k, 1, 2], f[k, 2, 2])),
                 (h[k, 0], h[k, 1], h[k, 2]), radius[k], offset[k])


# The table is inlined into its caller: a call passing a Solid by value costs 2 us a pair (10^4 boxes'
# pairs: 95 ms called, 15 ms inlined)
@njit(cache=True, inline="always", error_model="numpy")
def collide_ordered(a, b, margin, out):
    """The kernel of a's and b's kinds, for a.kind <= b.kind: its points into ``out``, their count."""
    if a.kind == SPHERE:
        if b.kind == SPHERE:
            return round_points(a.centre, a.radius, b.centre, b.radius, margin, 0, out)
        if b.kind == BOX:
            return sphere_box(a.centre, a.radius, b.centre, b.frame, b.half, margin, out)
        if b.kind == CAPSULE:
            return sphere_capsule(a.centre, a.radius, b.centre, b.frame, b.half, b.radius, margin, out)
        return sphere_plane_points(a.centre, a.radius, b.frame[2], b.offset, margin, 0, out, 0)
    if a.kind == BOX:
        if b.kind == BOX:
            return box_box((a.centre, a.frame, a.half), (b.centre, b.frame, b.half), margin, out)
        if b.kind == CAPSULE:
            return box_capsule((a.centre, a.frame, a.half), (b.centre, b.frame, b.half, b.radius), margin, out)
        return box_plane(a.centre, a.frame, a.half, b.frame[2], b.offset, margin, out)
    if b.kind == CAPSULE:
        return capsule_capsule((a.centre, a.frame, a.half, a.radius), (b.centre, b.frame, b.half, b.radius), margin,
                               out)
    return capsule_plane(a.centre, a.frame, a.half, a.radius, b.frame[2], b.offset, margin, out)


@njit(cache=True, inline="always", error_model="numpy")
def collide(a, b, margin, out):
    """The pair table: the manifold of shapes a and b, normals from a to b, whichever order their kinds come in."""
    # one inlined table for either order (two were two copies of every kernel in each caller)
    swap = a.kind > b.kind
    first, second = (b, a) if swap else (a, b)
    count = collide_ordered(first, second, margin, out)
    if swap:
        for k in range(count):
            for m in range(3):
                out.normal[k, m] = -out.normal[k, m]
    return count


@njit(cache=True, error_model="numpy")
def static_candidates(bodies, statics, reach):
    """(K, 2) [body, static] whose bounding sphere (radius ``reach``, margin included) reaches the static shape."""
    found = np.empty((len(bodies.kind) * len(statics.kind), 2), dtype=np.int64)
    count = 0
    for k in range(len(bodies.kind)):
        c = (bodies.centre[k, 0], bodies.centre[k, 1], bodies.centre[k, 2])
        for s in range(len(statics.kind)):
            shape = solid(statics, s)
            if shape.kind == PLANE:
                gap = dot3(c, shape.frame[2]) - shape.offset
            else:
                local = to_local(shape.frame, sub3(c, shape.centre))
                gap2 = 0.0
                for m in range(3):
                    gap2 += max(abs(local[m]) - shape.half[m], 0.0) ** 2
                gap = np.sqrt(gap2)
            if gap < reach[k]:
                found[count, 0], found[count, 1] = k, s
                count += 1
    return found[:count]


#: the narrow phase's pairs are cut into this many chunks, each run by one thread with its own
#: scratch: enough to share out over the threads, few enough that the scratch is allocated rarely
#: (the result does not depend on it: every pair writes its own rows)
CHUNKS = 64
#: fewer pairs than this are run on the calling thread: waking the others costs more than they save,
#: and on a loaded machine a parallel region waits for its slowest thread's time slice
PARALLEL_PAIRS = 2048


@njit(cache=True, parallel=True, error_model="numpy")
def manifold_slots(bodies, statics, pairs, static_pairs, margins, slots, found):
    """Every pair's manifold into ``slots`` (a ManifoldPoints of 4 rows per pair, the body pairs first,
    then the static pairs), its count and first row into ``found`` = (counts, firsts); the pairs in
    parallel.

    ``margins`` = (margin, extent), (N,) each: a body's speculative margin and its bounding radius
    plus that margin. Each chunk of pairs writes its points one after another from the first of its
    pairs' 4 rows each, so the pairs of different chunks are independent (embarrassingly parallel):
    the same bytes on any number of threads. (Each pair's own 4 rows instead touched a cache line of
    every column for every pair, most of them holding one or two points: 19 MB for the 10^4 pit's
    65,000 points, against 5 MB packed.)"""
    total = len(pairs) + len(static_pairs)
    for chunk in prange(CHUNKS):
        _slots_of_chunk((bodies, statics), (pairs, static_pairs), margins, slots, found,
                        (chunk * total // CHUNKS, (chunk + 1) * total // CHUNKS))


@njit(cache=True, error_model="numpy")
def _slots_of_chunk(solids_, pairs_, margins, slots, found, span):
    """:func:`manifold_slots` for the pairs ``span`` = (first, end), with a scratch of its own.

    Two bodies whose centres are farther apart than their extents can have no point, and are
    passed over before their shapes are read (one distance instead of the 15 axes; a broadphase
    on swept and widened bounds hands over such pairs, though the 10^4 box pit's separated pairs
    lie within their extents: the margins are wide). (A kernel of its own, not the body of the
    parallel loop: Numba's parallel pass cannot analyse the inlined pair table.)

    Every binding of an array, or of a tuple of arrays, in the loop (a NamedTuple's field, a tuple
    unpacked, an inlined function's argument) counts a reference up and down: an atomic operation,
    which the threads contend for on the arrays they share. So the columns are taken out of their
    tuples before the loop, and a pair of boxes calls :func:`.manifold_box.box_box` directly rather
    than through the two inlined levels of the pair table, each of which bound the scratch's six
    arrays again (the same call with the same arguments: the same bytes); so does a box against a
    static box or plane (:func:`.manifold_box.box_plane`). On the 10^4 pit's step 30
    (40,755 pairs) this took the loop from 13.3 to 10.0 ms on one thread. The scratch's arrays, which
    the loop and :func:`.manifold_box.face_contact` bind at every pair, have no owner
    (:func:`.manifold_geometry.scratch_in`): their counts are a null test, 9.7 -> 7.4 ms more.

    Each kernel is inlined at one place: the body pairs and the static pairs share the calls, and
    :func:`collide` holds one copy of the table for either order. A copy per call site (six of
    ``box_box``) took 56 s to compile from an empty cache, now 21 s, and the loop is 4 % faster."""
    bodies, statics = solids_
    pairs, static_pairs = pairs_
    margin, extent = margins
    # the columns out of the NamedTuples before the loop: a field read in the loop costs a reference
    # count, an atomic operation on the array's count that the threads share (measured: a third of the
    # narrow phase's time on one thread went to counting references)
    kind, centre, frame, half, radius, offset = bodies
    s_kind, s_centre, s_frame, s_half, s_radius, s_offset = statics
    a_out, b_out, normal, point, separation, feature = slots
    counts, firsts = found
    row = MAX_POINTS * span[0]  # the chunk's next row
    store = np.empty(SCRATCH_WORDS, np.int64)
    scratch = scratch_in(store)
    found_normal, found_point, found_separation, found_feature = (scratch.normal, scratch.point, scratch.separation,
                                                                  scratch.feature)
    for p in range(span[0], span[1]):
        if p < len(pairs):
            i, j = pairs[p, 0], pairs[p, 1]
            d = (centre[j, 0] - centre[i, 0], centre[j, 1] - centre[i, 1], centre[j, 2] - centre[i, 2])
            if dot3(d, d) >= (extent[i] + extent[j]) ** 2:
                counts[p], firsts[p] = 0, row
                continue
            second = solid_of(kind, centre, frame, half, radius, offset, j)
            pair_margin, b = margin[i] + margin[j], j
        else:
            i, s = static_pairs[p - len(pairs), 0], static_pairs[p - len(pairs), 1]
            second = solid_of(s_kind, s_centre, s_frame, s_half, s_radius, s_offset, s)
            pair_margin, b = margin[i], -1 - s
        first = solid_of(kind, centre, frame, half, radius, offset, i)
        # the table's commonest entries called directly (the docstring); each kernel inlined at one place
        if first.kind == BOX and second.kind == BOX:
            count = box_box((first.centre, first.frame, first.half), (second.centre, second.frame, second.half),
                            pair_margin, scratch)
        elif first.kind == BOX and second.kind == PLANE:
            count = box_plane(first.centre, first.frame, first.half, second.frame[2], second.offset, pair_margin,
                              scratch)
        else:
            count = collide(first, second, pair_margin, scratch)
        counts[p], firsts[p] = count, row
        for k in range(count):  # element by element: a row slice would be a view made and freed per point
            a_out[row], b_out[row] = i, b
            for m in range(3):
                normal[row, m], point[row, m] = found_normal[k, m], found_point[k, m]
            separation[row], feature[row] = found_separation[k], found_feature[k]
            row += 1
    store[0] = 0  # the scratch's memory kept to here


@njit(cache=True, error_model="numpy")
def sorted_starts(pairs, static_pairs, counts, n):
    """Each pair's first row among :func:`manifold_slots`'s points in the order (a, b, feature), and
    the number of points: for each body a in turn, its static shapes (b = -1 - s, so s descending),
    then its partners j > a ascending (``pairs`` and ``static_pairs`` are sorted), each pair's
    ``counts`` rows together."""
    start = np.empty(len(counts), np.int64)
    rows, p, s = 0, 0, 0
    for a in range(n):
        first = s
        while s < len(static_pairs) and static_pairs[s, 0] == a:
            s += 1
        for q in range(s - 1, first - 1, -1):
            start[len(pairs) + q] = rows
            rows += counts[len(pairs) + q]
        while p < len(pairs) and pairs[p, 0] == a:
            start[p] = rows
            rows += counts[p]
            p += 1
    return start, rows


@njit(cache=True, parallel=True, error_model="numpy")
def take_sorted(slots, found, out, threads):
    """Each pair's points of ``slots`` into its rows of ``out`` from its start, by feature; ``found`` =
    (counts, firsts, starts) (:func:`manifold_slots`, :func:`sorted_starts`); ``threads`` parts of the
    pairs in parallel (one pass: NumPy's fancy indexing of the six columns took a millisecond on 10^4
    boxes' points)."""
    for part in prange(threads):
        _take_sorted_of(slots, found, out, span(0, len(found[0]), part, threads))


@njit(cache=True, error_model="numpy")
def _take_sorted_of(slots, found, out, pairs):
    """:func:`take_sorted` of the pairs ``pairs`` = (first, end). A pair's points by feature, equal
    features in the order found (as a stable sort of all the points would put them), by insertion
    (at most 4 points)."""
    counts, firsts, starts = found
    a, b, normal, point, separation, feature = slots
    a_out, b_out, normal_out, point_out, separation_out, feature_out = out
    order = np.empty(MAX_POINTS, np.int64)
    for p in range(pairs[0], pairs[1]):
        for k in range(counts[p]):
            x = firsts[p] + k
            j = k
            while j > 0 and feature[order[j - 1]] > feature[x]:
                order[j] = order[j - 1]
                j -= 1
            order[j] = x
        for k in range(counts[p]):
            i, row = order[k], starts[p] + k
            a_out[row], b_out[row], separation_out[row], feature_out[row] = a[i], b[i], separation[i], feature[i]
            for m in range(3):
                normal_out[row, m], point_out[row, m] = normal[i, m], point[i, m]


@njit(cache=True, error_model="numpy")
def _pairs_state(pairs, n):
    """(the first pair that does not join two different bodies 0 .. n - 1, or -1; whether each pair
    (i, j) has i < j and the pairs are strictly increasing, lexicographically), in one pass."""
    in_order = True
    for p in range(len(pairs)):
        i, j = pairs[p, 0], pairs[p, 1]
        if min(i, j) < 0 or max(i, j) >= n or i == j:
            return p, False
        if i >= j or (p and (i < pairs[p - 1, 0] or (i == pairs[p - 1, 0] and j <= pairs[p - 1, 1]))):
            in_order = False
    return -1, in_order


def extents(shapes: CheckedShapes, margin: np.ndarray) -> np.ndarray:
    """(N,) m: each body's :func:`reach` plus its ``margin``, the distance from its centre within which
    another shape can have a point with it."""
    return _extents(shapes.kind, shapes.half, shapes.radius, np.ascontiguousarray(margin))


@njit(cache=True, error_model="numpy")
def _extents(kind, half, radius, margin):
    """:func:`extents`, compiled: a box's reach is its corner, |half|; a sphere's its radius; a
    capsule's its radius plus its half length. (NumPy's temporaries took 0.2 ms a step of 10^4 boxes.)"""
    out = np.empty(len(kind))
    for k in range(len(kind)):
        if kind[k] == BOX:
            out[k] = np.sqrt(half[k, 0] * half[k, 0] + half[k, 1] * half[k, 1] + half[k, 2] * half[k, 2]) + margin[k]
        else:
            out[k] = (radius[k] + (half[k, 2] if kind[k] == CAPSULE else 0.0)) + margin[k]
    return out


def manifolds(shapes: RigidShapes, poses: Poses, pairs, statics=(), margin=0.0) -> ManifoldPoints:
    """The contact manifolds of the body pairs and of every body against the static shapes.

    Parameters
    ----------
    shapes : RigidShapes
    poses : Poses
    pairs : int array, shape (P, 2)
        Body pairs from a broadphase (either order, each once); tested as (min, max).
    statics : sequence of Plane, Box, OrientedBox
        The scene's static shapes; every body is tested against each one its bounding sphere reaches.
    margin : float or array, shape (N,)
        m, >= 0: a point is reported when its separation is below margin[a] + margin[b] (a static
        shape's margin is 0), so a fast body's contact is known before it touches (speculative contacts).

    Returns
    -------
    ManifoldPoints, sorted by (a, b, feature).
    """
    shapes = check_shapes(shapes)
    n = len(shapes.kind)
    # a copy of its own: a read-only view (broadcast_to's) is another Numba type, and another compile of
    # the manifold kernels (half a minute)
    margin = np.array(np.broadcast_to(np.asarray(margin, dtype=float), (n,)))
    if not np.all(np.isfinite(margin) & (margin >= 0)):
        raise ValueError(f"margin must be finite and >= 0 m for every body, got {margin.min()} .. {margin.max()}")
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    bad, in_order = _pairs_state(pairs, n)
    if bad >= 0:
        raise ValueError(f"pair {bad} must join two different bodies 0 .. {n - 1}, got {pairs[bad].tolist()}")
    if not in_order:  # a broadphase's pairs are (min, max), each once, sorted: kept as they are
        lo, hi = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
        key = np.sort(lo * n + hi)  # each pair once, as (min, max), in order
        key = key[np.diff(key, prepend=-1) != 0]
        pairs = np.column_stack([key // n, key % n])
    bodies, static = body_solids(shapes, poses), static_solids(statics)
    extent = extents(shapes, margin)
    static_pairs = static_candidates(bodies, static, extent)
    capacity = MAX_POINTS * (len(pairs) + len(static_pairs))
    slots = ManifoldPoints(np.empty(capacity, np.int64), np.empty(capacity, np.int64), np.empty((capacity, 3)),
                           np.empty((capacity, 3)), np.empty(capacity), np.empty(capacity, np.int64))
    counts, firsts = (np.empty(len(pairs) + len(static_pairs), np.int64) for _ in range(2))
    margins = (margin, extent)
    if len(counts) >= PARALLEL_PAIRS and numba.get_num_threads() > 1:
        manifold_slots(bodies, static, pairs, static_pairs, margins, slots, (counts, firsts))
    else:  # the same rows on this thread alone (a parallel region costs more than a few pairs, or one thread)
        _slots_of_chunk((bodies, static), (pairs, static_pairs), margins, slots, (counts, firsts),
                        (0, len(counts)))
    starts, rows = sorted_starts(pairs, static_pairs, counts, n)
    out = ManifoldPoints(np.empty(rows, np.int64), np.empty(rows, np.int64), np.empty((rows, 3)), np.empty((rows, 3)),
                         np.empty(rows), np.empty(rows, np.int64))
    if len(counts) >= PARALLEL_PAIRS and numba.get_num_threads() > 1:
        take_sorted(slots, (counts, firsts, starts), out, numba.get_num_threads())
    else:
        _take_sorted_of(slots, (counts, firsts, starts), out, (0, len(counts)))
    return out
