"""Manifolds of the round shapes, compiled: spheres and capsules against each other, boxes and planes.

A sphere is a point thickened by its radius, a capsule a segment (its body z axis, from
-half_z to +half_z) thickened by its radius; their contact is that of the closest points of the
two cores (:func:`.manifold_geometry.round_contact`, the sphere–sphere formula). A sphere and a
box: the closest point of the box to the centre (the centre clamped to the box in its frame).
Each kernel writes its points into ``out`` (:class:`.manifold_geometry.Scratch`) and returns how
many it wrote; the normal points from the first shape to the second.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .manifold_box import LINEAR_SLOP
from .manifold_geometry import (
    add3,
    clamp01,
    madd3,
    round_contact,
    scale3,
    segment_segment,
    sign_of,
    to_local,
    to_world,
    write_point,
)
from .sphere_contacts import dot3, sphere_plane, sub3


@njit(cache=True, inline="always", error_model="numpy")
def segment_of(centre, frame, half):
    """A capsule's core: (its -z end, the vector to its +z end)."""
    return madd3(centre, -half[2], frame[2]), scale3(frame[2], 2.0 * half[2])


@njit(cache=True, error_model="numpy")
def round_points(pa, radius_a, pb, radius_b, margin, feature, out):
    """The one point of two round cores' closest points ``pa`` and ``pb``, if its separation < margin."""
    normal, separation, point = round_contact(pa, radius_a, pb, radius_b)
    if separation >= margin:
        return 0
    write_point(out, 0, normal, separation, point, feature)
    return 1


@njit(cache=True, error_model="numpy")
def sphere_capsule(ca, ra, cb, fb, hb, rb, margin, out):
    """A sphere against a capsule: the centre against the segment's closest point, t = (c - p) . d / |d|^2 clamped."""
    p, d = segment_of(cb, fb, hb)
    length2 = dot3(d, d)
    t = clamp01(dot3(sub3(ca, p), d) / length2) if length2 > 0 else 0.0
    return round_points(ca, ra, madd3(p, t, d), rb, margin, 0, out)


@njit(cache=True, error_model="numpy")
def capsule_capsule(capsule_a, capsule_b, margin, out):
    """Two capsules, each (centre, frame, half, radius): the closest points of their segments; 2 points
    when they lie side by side.

    Segments whose common stretch (b's ends projected on a's segment, clamped to it) is longer
    than :data:`.LINEAR_SLOP` and whose gaps at its two ends exceed the least gap by less than
    the slop lie side by side: one point at each end of the stretch (ids 1 and 2), so the pair cannot roll
    about a single point. Otherwise the one point of the closest points (id 0).
    """
    ca, fa, ha, ra = capsule_a
    cb, fb, hb, rb = capsule_b
    p, d = segment_of(ca, fa, ha)
    q, e = segment_of(cb, fb, hb)
    s, t = segment_segment(p, d, q, e)
    normal, separation, point = round_contact(madd3(p, s, d), ra, madd3(q, t, e), rb)
    d2, e2 = dot3(d, d), dot3(e, e)
    if d2 > 0 and e2 > 0:
        s0, s1 = dot3(sub3(q, p), d) / d2, dot3(sub3(add3(q, e), p), d) / d2
        lo, hi = max(0.0, min(s0, s1)), min(1.0, max(s0, s1))
        if (hi - lo) * np.sqrt(d2) > LINEAR_SLOP:
            x0, x1 = madd3(p, lo, d), madd3(p, hi, d)
            n0, sep0, point0 = round_contact(x0, ra, madd3(q, clamp01(dot3(sub3(x0, q), e) / e2), e), rb)
            n1, sep1, point1 = round_contact(x1, ra, madd3(q, clamp01(dot3(sub3(x1, q), e) / e2), e), rb)
            if max(sep0, sep1) < separation + LINEAR_SLOP:  # the whole stretch is as close as the closest points
                kept = 0
                if sep0 < margin:
                    write_point(out, kept, n0, sep0, point0, 1)
                    kept += 1
                if sep1 < margin:
                    write_point(out, kept, n1, sep1, point1, 2)
                    kept += 1
                return kept
    if separation >= margin:
        return 0
    write_point(out, 0, normal, separation, point, 0)
    return 1


@njit(cache=True, error_model="numpy")
def sphere_box(ca, ra, cb, fb, hb, margin, out):
    """A sphere against a box: the closest point of the box to the centre, or the nearest face from inside.

    Outside the box the contact is the centre's against the clamped centre (a core of radius
    0). With the centre inside, the sphere leaves through the nearest face: the normal is that
    face's inward normal, the separation -(r + the centre's depth below the face).
    """
    local = to_local(fb, sub3(ca, cb))
    clamped = (min(max(local[0], -hb[0]), hb[0]), min(max(local[1], -hb[1]), hb[1]),
               min(max(local[2], -hb[2]), hb[2]))
    if clamped[0] != local[0] or clamped[1] != local[1] or clamped[2] != local[2]:
        return round_points(ca, ra, add3(cb, to_world(fb, clamped)), 0.0, margin, 0, out)
    axis, depth = 0, np.inf
    for k in range(3):
        if hb[k] - abs(local[k]) < depth:
            axis, depth = k, hb[k] - abs(local[k])
    outward = scale3(fb[axis], sign_of(local[axis]))
    separation = -(ra + depth)
    if separation >= margin:
        return 0
    normal = scale3(outward, -1.0)
    surface_a, surface_b = madd3(ca, ra, normal), madd3(ca, depth, outward)
    write_point(out, 0, normal, separation, scale3(add3(surface_a, surface_b), 0.5), 0)
    return 1


@njit(cache=True, error_model="numpy")
def sphere_plane_points(c, radius, plane_normal, offset, margin, feature, out, row):
    """A sphere (or a capsule's end) against the half-space n . x <= offset (:func:`.sphere_contacts.sphere_plane`).

    Its point, written at ``row`` if its separation is below the margin, lies halfway between
    the sphere's lowest point c - r n and the plane's c - h n. Returns the points written (0 or 1).
    """
    normal, depth, height = sphere_plane(c, radius, plane_normal, offset)
    if -depth >= margin:
        return 0
    write_point(out, row, normal, -depth, madd3(c, -0.5 * (radius + height), plane_normal), feature)
    return 1


@njit(cache=True, error_model="numpy")
def capsule_plane(c, frame, half, radius, plane_normal, offset, margin, out):
    """A capsule against a plane: each end of its segment (ids 0 and 1) as a sphere; one end if its length is 0."""
    p, d = segment_of(c, frame, half)
    kept = sphere_plane_points(p, radius, plane_normal, offset, margin, 0, out, 0)
    if half[2] > 0:
        kept += sphere_plane_points(add3(p, d), radius, plane_normal, offset, margin, 1, out, kept)
    return kept
