"""The box–capsule manifold, compiled: the segment's exact distance to the box, then a face or an edge.

The squared distance of the segment's point p + t d to the box is a sum of per-axis squared
excesses, each a quadratic in t between the parameters where the point crosses a face plane:
a piecewise quadratic, convex, whose minimum is found exactly interval by interval. A capsule
apart from the box touches it where those closest points are; one that lies along a face (the
closest point of the box inside that face) touches it along the face, and gets the segment
clipped to the face's side planes: 2 points, so that it lies still instead of rocking. A segment
inside the box is pushed out along the best of the 6 axes of the separating-axis test (the
box's 3 face normals and the 3 cross products of the segment with the box's edges).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .manifold_box import AXIS_TOLERANCE, CLIP_TOLERANCE, EDGE_PARALLEL, support_edge
from .manifold_geometry import add3, cross3, madd3, scale3, segment_segment, sign_of, to_local, to_world, write_point
from .manifold_round import round_points, segment_of
from .sphere_contacts import dot3, sub3

#: feature ids: a face contact is face * 6 + (the end 0 or 1, or 2 + the side plane that cut it);
#: an edge of the box against the segment, inside it, is EDGE_FEATURE + the edge's id; the one
#: point of a capsule apart from the box, off its faces, is CORNER_FEATURE
EDGE_FEATURE, CORNER_FEATURE = 36, 48


@njit(cache=True, error_model="numpy")
def excess2(y, half):
    """Squared distance of the box-frame point y to the box [-half, half]."""
    total = 0.0
    for k in range(3):
        e = max(abs(y[k]) - half[k], 0.0)
        total += e * e
    return total


@njit(cache=True, error_model="numpy")
def segment_box_closest(p, d, half):
    """The parameter t in [0, 1] of the point of p + t d (box frame) closest to the box, and its squared distance.

    Between consecutive crossings of the six face planes each axis is above, inside or below
    its slab, so the squared distance there is A t^2 + B t + C from the axes outside it: its
    minimum -B / 2A, clamped to the interval, is that interval's best.
    """
    ts = np.empty(8)
    ts[0], ts[1], n = 0.0, 1.0, 2
    for k in range(3):
        if d[k] != 0:
            for bound in (-half[k], half[k]):
                t = (bound - p[k]) / d[k]
                if 0 < t < 1:
                    ts[n] = t
                    n += 1
    ts = np.sort(ts[:n])
    best_t, best = 0.0, np.inf
    for i in range(n - 1):
        lo, hi = ts[i], ts[i + 1]
        middle = 0.5 * (lo + hi)
        a = b = 0.0
        inside = True
        for k in range(3):
            y = p[k] + middle * d[k]
            if abs(y) > half[k]:
                e0 = p[k] - sign_of(y) * half[k]
                a += d[k] * d[k]
                b += 2 * e0 * d[k]
                inside = False
        if inside:  # within every slab from lo to hi: the distance is 0, though p + lo d, on a face's
            # plane, may round to a hair outside it, which would send a segment through the box to the
            # outside's face test (and a nudge of 1e-9 to another face)
            t, f = lo, 0.0
        else:
            t = min(max(-b / (2 * a), lo), hi) if a > 0 else lo
            f = excess2(madd3(p, t, d), half)
        if f < best:
            best_t, best = t, f
    return best_t, best


@njit(cache=True, error_model="numpy")
def face_points(box, face, segment, radius, margin, out):
    """The segment (box frame p + t d, ``segment`` = (p, d)) clipped to the prism over the box's face
    ``face`` = (axis, side): its ends below margin; ``box`` = (centre, frame, half).

    Each end's gap is its height above the face less the radius; the point lies halfway between
    the capsule's surface and the face. Ids: face * 6 + 0 or 1 for an end of the segment, 2 + the
    side plane for an end the clipping made.
    """
    cb, fb, hb = box
    axis, side = face
    p, d = segment
    t0, t1, label0, label1 = 0.0, 1.0, 0, 1
    for n in range(2):
        k = (axis + 1 + n) % 3
        for sense in (1.0, -1.0):  # sense * (p_k + t d_k) <= h_k, each end kept within the tolerance
            plane = 2 + 2 * n + (0 if sense > 0 else 1)
            out0, out1 = sense * p[k] - hb[k], sense * (p[k] + d[k]) - hb[k]
            if out0 > CLIP_TOLERANCE and out1 > CLIP_TOLERANCE:
                return 0
            if out1 > CLIP_TOLERANCE and out0 < out1 and out0 / (out0 - out1) < t1:
                t1, label1 = out0 / (out0 - out1), plane
            elif out0 > CLIP_TOLERANCE and out1 < out0 and out0 / (out0 - out1) > t0:
                t0, label0 = out0 / (out0 - out1), plane
    if t0 > t1:
        return 0
    normal = scale3(fb[axis], side)
    face_id = 2 * axis + (1 if side > 0 else 0)
    ends = 1 if t1 == t0 or (d[0] == 0 and d[1] == 0 and d[2] == 0) else 2  # a point, or a stretch
    kept = 0
    for end in range(ends):
        t, label = (t0, label0) if end == 0 else (t1, label1)
        y = madd3(p, t, d)
        height = side * y[axis] - hb[axis]
        if height - radius >= margin:
            continue
        point = add3(cb, to_world(fb, y))
        write_point(out, kept, normal, height - radius, madd3(point, -0.5 * (radius + height), normal),
                    face_id * 6 + label)
        kept += 1
    return kept


@njit(cache=True, error_model="numpy")
def box_capsule(box, capsule, margin, out):
    """The manifold of a box (centre, frame, half) and a capsule (centre, frame, half, radius): up to 2
    points, the normal from the box to the capsule."""
    cb, fb, hb = box
    cc, fc, hc, radius = capsule
    start, d = segment_of(cc, fc, hc)
    p, dl = to_local(fb, sub3(start, cb)), to_local(fb, d)
    t, distance2 = segment_box_closest(p, dl, hb)
    y = madd3(p, t, dl)
    if distance2 > 0:
        outside, axis = 0, np.int64(0)  # int64, not a literal 0: face_points compiled once (box_box's faces)
        for k in range(3):
            if abs(y[k]) > hb[k]:
                outside, axis = outside + 1, k
        if outside == 1:  # the closest point is inside a face: along that face
            return face_points(box, (axis, sign_of(y[axis])), (p, dl), radius, margin, out)
        clamped = (min(max(y[0], -hb[0]), hb[0]), min(max(y[1], -hb[1]), hb[1]), min(max(y[2], -hb[2]), hb[2]))
        return round_points(add3(cb, to_world(fb, clamped)), 0.0, add3(start, scale3(d, t)), radius, margin,
                            CORNER_FEATURE, out)
    # the segment meets the box: the separating axes, from the segment's middle h = p + d/2
    middle, half_d = madd3(p, 0.5, dl), scale3(dl, 0.5)
    best_face, face = -np.inf, np.int64(0)
    for k in range(3):
        s = abs(middle[k]) - hb[k] - abs(half_d[k]) - radius
        if s > best_face:
            best_face, face = s, k
    best_edge, edge, edge_axis = -np.inf, 0, (0.0, 0.0, 0.0)
    for k in range(3):
        axis = cross3((1.0 if k == 0 else 0.0, 1.0 if k == 1 else 0.0, 1.0 if k == 2 else 0.0), dl)
        length = np.sqrt(dot3(axis, axis))
        if length < EDGE_PARALLEL * np.sqrt(dot3(dl, dl)) or length == 0:
            continue
        axis = scale3(axis, 1.0 / length)
        reach = hb[0] * abs(axis[0]) + hb[1] * abs(axis[1]) + hb[2] * abs(axis[2])
        s = abs(dot3(middle, axis)) - reach - abs(dot3(half_d, axis)) - radius
        if s > best_edge:
            best_edge, edge, edge_axis = s, k, scale3(axis, sign_of(dot3(middle, axis)))
    if max(best_face, best_edge) >= margin:
        return 0
    if best_edge > best_face + AXIS_TOLERANCE:
        normal = to_world(fb, edge_axis)
        pa, da, edge_id = support_edge(box, edge, normal, 1.0)
        s, u = segment_segment(pa, da, start, d)
        xa, xb = madd3(pa, s, da), madd3(madd3(start, u, d), -radius, normal)
        write_point(out, 0, normal, best_edge, scale3(add3(xa, xb), 0.5), EDGE_FEATURE + edge_id)
        return 1
    count = face_points(box, (face, sign_of(middle[face])), (p, dl), radius, margin, out)
    if count == 0:  # the segment crosses the box's middle outside the face's prism: its deepest point alone
        normal = scale3(fb[face], sign_of(middle[face]))
        point = add3(cb, to_world(fb, y))
        write_point(out, 0, normal, best_face, point, CORNER_FEATURE)
        count = 1
    return count
