"""The small geometry the rigid narrow phase is built from, compiled: vectors, frames, segments.

Vectors are 3-tuples of floats (as in :mod:`.sphere_contacts`, whose ``dot3`` and ``sub3``
these build on); a frame is the tuple of a body's three axes in world coordinates, the
columns of its rotation matrix, so a world vector v has body coordinates (v . R0, v . R1, v . R2).
The contact of two round cores (points or segments, thickened by radii) is the one formula of
:func:`.sphere_contacts.sphere_sphere`, called here by :func:`round_contact`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..unowned import unowned
from .sphere_contacts import dot3, sphere_sphere, sub3


class Scratch(NamedTuple):
    """Where one pair's kernel writes its points (rows 0..count-1), and its clipping buffers."""

    normal: np.ndarray      # (8, 3) from a towards b
    point: np.ndarray       # (8, 3)
    separation: np.ndarray  # (8,)
    feature: np.ndarray     # (8,) int64
    polygon: np.ndarray     # (2, 8, 3) the clipped face, in and out of one clipping plane
    label: np.ndarray       # (2, 8, 2) int64 the two lines meeting at each of its vertices


#: one :class:`Scratch`'s 8-byte words: normal, point, separation, feature, polygon, label
SCRATCH_WORDS = 24 + 24 + 8 + 8 + 48 + 32


@njit(cache=True, inline="always", error_model="numpy")
def scratch_in(store):
    """A :class:`Scratch` over ``store``, an int64 array of :data:`SCRATCH_WORDS` words, whose views have
    no owner (:mod:`steplab.physics.unowned`): the narrow phase's loop binds them at every pair, which
    counted references on arrays of their own. A quadrilateral clipped by 4 planes has at most 8
    vertices: every buffer holds 8. The caller keeps ``store``."""
    at = store.ctypes.data
    return Scratch(unowned(at, (8, 3), np.float64), unowned(at + 8 * 24, (8, 3), np.float64),
                   unowned(at + 8 * 48, 8, np.float64), unowned(at + 8 * 56, 8, np.int64),
                   unowned(at + 8 * 64, (2, 8, 3), np.float64), unowned(at + 8 * 112, (2, 8, 2), np.int64))


@njit(cache=True, inline="always", error_model="numpy")
def add3(x, y):
    return x[0] + y[0], x[1] + y[1], x[2] + y[2]


@njit(cache=True, inline="always", error_model="numpy")
def scale3(x, s):
    return x[0] * s, x[1] * s, x[2] * s


@njit(cache=True, inline="always", error_model="numpy")
def madd3(x, s, y):
    """x + s y."""
    return x[0] + s * y[0], x[1] + s * y[1], x[2] + s * y[2]


@njit(cache=True, inline="always", error_model="numpy")
def cross3(x, y):
    return x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]


@njit(cache=True, inline="always", error_model="numpy")
def to_local(frame, v):
    """A world vector in the body's coordinates: (v . R0, v . R1, v . R2)."""
    return dot3(v, frame[0]), dot3(v, frame[1]), dot3(v, frame[2])


@njit(cache=True, inline="always", error_model="numpy")
def to_world(frame, p):
    """A body-frame vector in world coordinates: p0 R0 + p1 R1 + p2 R2."""
    return (p[0] * frame[0][0] + p[1] * frame[1][0] + p[2] * frame[2][0],
            p[0] * frame[0][1] + p[1] * frame[1][1] + p[2] * frame[2][1],
            p[0] * frame[0][2] + p[1] * frame[1][2] + p[2] * frame[2][2])


@njit(cache=True, inline="always", error_model="numpy")
def sign_of(x):
    """+1 for x >= 0, else -1: a side, never 0, so that a tie picks one feature consistently."""
    return 1.0 if x >= 0 else -1.0


@njit(cache=True, inline="always", error_model="numpy")
def clamp01(x):
    return min(max(x, 0.0), 1.0)


@njit(cache=True, error_model="numpy")
def segment_segment(p, d, q, e):
    """Closest points of the segments p + s d and q + t e, s, t in [0, 1]: ``(s, t)``.

    Minimises |p + s d - q - t e|^2, a convex quadratic: the unconstrained s of the two lines
    (b f - c e2) / (d2 e2 - b^2), clamped, then t for that s, clamped, and s again for a clamped t
    (Ericson, Real-Time Collision Detection, 5.1.9). Parallel lines (zero denominator) take s = 0;
    a segment of length 0 is a point.
    """
    r = sub3(p, q)
    d2, e2, f = dot3(d, d), dot3(e, e), dot3(e, r)
    if d2 == 0 and e2 == 0:
        return 0.0, 0.0
    if d2 == 0:
        return 0.0, clamp01(f / e2)
    c = dot3(d, r)
    if e2 == 0:
        return clamp01(-c / d2), 0.0
    b = dot3(d, e)
    denominator = d2 * e2 - b * b
    s = clamp01((b * f - c * e2) / denominator) if denominator > 0 else 0.0
    t = (b * s + f) / e2
    if t < 0:
        return clamp01(-c / d2), 0.0
    if t > 1:
        return clamp01((b - c) / d2), 1.0
    return s, t


@njit(cache=True, inline="always", error_model="numpy")
def round_contact(pa, radius_a, pb, radius_b):
    """Contact of the balls of ``radius_a`` around ``pa`` and ``radius_b`` around ``pb``: (normal, separation, point).

    The closest points of two round shapes' cores (a sphere's centre, a capsule's segment, a box
    with radius 0) make the contact of the shapes: the normal joins them
    (:func:`.sphere_contacts.sphere_sphere`), the separation is their distance less both radii,
    and the point lies midway between the two surfaces, pa + ra n and pb - rb n.
    """
    normal, depth = sphere_sphere(sub3(pb, pa), radius_a + radius_b)
    surface_a, surface_b = madd3(pa, radius_a, normal), madd3(pb, -radius_b, normal)
    return normal, -depth, scale3(add3(surface_a, surface_b), 0.5)


@njit(cache=True, inline="always", error_model="numpy")
def write_point(out, k, normal, separation, point, feature):
    """Point k of a manifold into ``out`` (a :class:`Scratch`)."""
    out.normal[k, 0], out.normal[k, 1], out.normal[k, 2] = normal
    out.point[k, 0], out.point[k, 1], out.point[k, 2] = point
    out.separation[k] = separation
    out.feature[k] = feature


@njit(cache=True, error_model="numpy")
def reduce_to_four(point, separation, feature, count):
    """Keep 4 of ``count`` > 4 coplanar contact points, in place: those that hold the body best.

    The deepest point first (it carries the largest impulse); then the point farthest from
    it; then the one making the largest triangle with those two; then the one adding the
    largest area outside that triangle, so the four span the largest quadrilateral of the set
    (the reduction of Box2D and Box3D's manifolds, which keeps the support polygon a stack
    stands on). The kept points are moved to rows 0..3; returns 4. (Rows and indices as
    scalars and tuples: the arrays and copies it made cost more than the choice.)
    """
    k0 = 0
    for k in range(1, count):
        if separation[k] < separation[k0]:
            k0 = k
    p0 = _point(point, k0)
    best, k1 = -1.0, 0
    for k in range(count):
        d = sub3(_point(point, k), p0)
        if dot3(d, d) > best:
            best, k1 = dot3(d, d), k
    p1 = _point(point, k1)
    edge = sub3(p1, p0)
    best, normal, k2 = -1.0, (0.0, 0.0, 0.0), 0
    for k in range(count):
        c = cross3(edge, sub3(_point(point, k), p0))
        if dot3(c, c) > best:
            best, k2, normal = dot3(c, c), k, c
    p2 = _point(point, k2)
    # the fourth: the most negative signed area against the triangle's normal, over its three edges
    best, k3 = np.inf, 0
    corners = (p0, p1, p2)
    for k in range(count):
        if k == k0 or k == k1 or k == k2:
            continue
        q = _point(point, k)
        for i in range(3):
            u, w = corners[i], corners[(i + 1) % 3]
            area = dot3(cross3(sub3(w, u), sub3(q, u)), normal)
            if area < best:
                best, k3 = area, k
    p3 = _point(point, k3)
    s0, s1, s2, s3 = separation[k0], separation[k1], separation[k2], separation[k3]
    f0, f1, f2, f3 = feature[k0], feature[k1], feature[k2], feature[k3]
    _put(point, separation, feature, 0, (p0, s0, f0))
    _put(point, separation, feature, 1, (p1, s1, f1))
    _put(point, separation, feature, 2, (p2, s2, f2))
    _put(point, separation, feature, 3, (p3, s3, f3))
    return 4


@njit(cache=True, inline="always", error_model="numpy")
def _point(point, k):
    return point[k, 0], point[k, 1], point[k, 2]


@njit(cache=True, inline="always", error_model="numpy")
def _put(point, separation, feature, k, row):
    """Row k of the points := ``row`` = (point, separation, feature)."""
    (point[k, 0], point[k, 1], point[k, 2]), separation[k], feature[k] = row
