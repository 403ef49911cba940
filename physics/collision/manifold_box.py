"""Box manifolds, compiled: box–box by the separating-axis test and face clipping, box–plane.

Two boxes are convex polyhedra: they are disjoint exactly when the projections on one of 15
axes are (the 3 face normals of each and the 9 cross products of an edge of one with an edge
of the other), and for boxes that overlap the axis of least overlap is one of the 15, its
overlap the penetration depth (Gottschalk, Lin and Manocha 1996; Ericson 4.4). The manifold is
built on the best axis as Box2D's ``b2ClipPolygons`` and Box3D's hull manifolds build it: on a
face axis the *reference* face (the face of that normal) clips the *incident* face (the other
box's face most opposed to it) by its four side planes, and each clipped vertex below the
margin is a point; on an edge axis the point is the closest points of the two edges.

Faces are preferred to edges, and the first box's face to the second's, unless the other
separates by :data:`AXIS_TOLERANCE` more: the choice then does not flicker between steps for a
box resting on another, and the feature ids stay those of the same faces (warm starting).

A box is (centre, frame, half): its centre, the tuple of its axes in world coordinates and its
three half edges. Faces are numbered 2k + (outward normal along +axis k), corners by the bits of
their signs along x, y, z.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .manifold_geometry import (
    add3,
    cross3,
    madd3,
    reduce_to_four,
    scale3,
    segment_segment,
    sign_of,
    to_local,
    to_world,
    write_point,
)
from .sphere_contacts import dot3, sphere_plane, sub3

#: m, Box2D's b2_linearSlop: the contact distance below which nothing a player can see changes
LINEAR_SLOP = 0.005
#: m, how much better another axis must separate the boxes to be taken: a tenth of the slop,
#: as Box2D's polygon manifold (below it the two axes are the same contact to the eye)
AXIS_TOLERANCE = 0.1 * LINEAR_SLOP
#: m, a clipped vertex less than this outside a side plane is kept as it is, not cut: two equal
#: boxes stacked edge on edge keep their 4 corners (and their ids) through round-off jitter
#: instead of trading them for intersection points on alternate steps
CLIP_TOLERANCE = 0.1 * LINEAR_SLOP
#: sin of the angle below which two edges count as parallel: their cross product has no
#: direction, and the face axes already measure that overlap
EDGE_PARALLEL = 1e-6
#: feature ids: a face contact is ((reference box * 6 + reference face) * 6 + incident face) * 64
#: + the pair of clipping lines at the point (8 x 8); edge contacts come after them all
EDGE_FEATURE = 2 * 6 * 6 * 64


# inlined into the narrow phase's loop: a call costs more than the 15 axes (300 ns a pair against 20)
@njit(cache=True, inline="always", error_model="numpy")
def box_box(box_a, box_b, margin, out):
    """The manifold of box a and box b (up to 4 points with separation < margin) into ``out``: its count.

    Each box is (centre, frame, half); ``margin`` m is the speculative distance; the normal points
    from a to b. (Boxes whose bounding spheres are ``margin`` apart never come here:
    :func:`.manifolds.manifold_slots` passes them over.)
    """
    ca, fa, ha = box_a
    cb, fb, hb = box_b
    t = to_local(fa, sub3(cb, ca))  # b's centre in a's frame
    # c[i][j] = a_i . b_j, b's axes in a's frame by columns (a tuple: kept in registers)
    c = ((dot3(fa[0], fb[0]), dot3(fa[0], fb[1]), dot3(fa[0], fb[2])),
         (dot3(fa[1], fb[0]), dot3(fa[1], fb[1]), dot3(fa[1], fb[2])),
         (dot3(fa[2], fb[0]), dot3(fa[2], fb[1]), dot3(fa[2], fb[2])))
    # the face axes of a: |t_i| against the two boxes' reaches h_i and sum_j |c_ij| hb_j
    # the faces int64 from the start: Numba types a call while the loop's variables are still being
    # resolved, and a literal 0 here compiled face_contact once more for Literal[int](0), never called
    sep_a, face_a = -np.inf, np.int64(0)
    for i in range(3):
        s = abs(t[i]) - (ha[i] + abs(c[i][0]) * hb[0] + abs(c[i][1]) * hb[1] + abs(c[i][2]) * hb[2])
        if s > sep_a:
            sep_a, face_a = s, i
    sep_b, face_b = -np.inf, np.int64(0)
    for j in range(3):
        s = (abs(t[0] * c[0][j] + t[1] * c[1][j] + t[2] * c[2][j])
             - (abs(c[0][j]) * ha[0] + abs(c[1][j]) * ha[1] + abs(c[2][j]) * ha[2] + hb[j]))
        if s > sep_b:
            sep_b, face_b = s, j
    if max(sep_a, sep_b) >= margin:
        return 0
    # the edge axes a_i x b_j, in a's frame (|a_i x b_j| = sin of the angle between the edges)
    sep_e, edge_a, edge_b = -np.inf, -1, -1
    for i in range(3):
        for j in range(3):
            bj = (c[0][j], c[1][j], c[2][j])
            axis = cross3((1.0 if i == 0 else 0.0, 1.0 if i == 1 else 0.0, 1.0 if i == 2 else 0.0), bj)
            length = np.sqrt(dot3(axis, axis))
            if length < EDGE_PARALLEL:
                continue
            reach_a = ha[0] * abs(axis[0]) + ha[1] * abs(axis[1]) + ha[2] * abs(axis[2])
            reach_b = 0.0
            for m in range(3):
                reach_b += hb[m] * abs(axis[0] * c[0][m] + axis[1] * c[1][m] + axis[2] * c[2][m])
            s = (abs(dot3(t, axis)) - reach_a - reach_b) / length
            if s > sep_e:
                sep_e, edge_a, edge_b = s, i, j
    if sep_e >= margin:
        return 0
    if sep_e > max(sep_a, sep_b) + AXIS_TOLERANCE:
        return edge_contact((box_a, edge_a), (box_b, edge_b), sep_e, margin, out)
    # one call of face_contact for either reference face, its box number an int64 (a call with the literal
    # 0 or 1 compiled face_contact once for each: Numba specialises a call on its literal arguments)
    reference = np.int64(sep_b > sep_a + AXIS_TOLERANCE)
    box1, axis, box2 = (box_b, face_b, box_a) if reference else (box_a, face_a, box_b)
    count = face_contact(box1, axis, box2, reference, margin, out)
    if reference:
        normal = out.normal
        for k in range(count):  # the reference normal points from b to a
            for m in range(3):
                normal[k, m] = -normal[k, m]
    return count


@njit(cache=True, error_model="numpy")
def face_contact(box1, axis, box2, reference, margin, out):
    """Box 1's face on ``axis`` (the side facing box 2) clips box 2's most opposed face: the points below margin.

    The incident face's 4 corners, in box 1's frame, are clipped by the reference face's side
    planes |x_u| <= h1_u (Sutherland–Hodgman, 8 vertices at most); each vertex keeps the two
    lines meeting there (incident edges 0..3, side planes 4..7), so its id names the same
    features as long as they touch. A vertex's separation is its height above the reference
    face; its point lies halfway down to it. The normal points from box 1 to box 2.
    """
    c1, f1, h1 = box1
    c2, f2, h2 = box2
    out_normal, out_point, out_separation, out_feature = out.normal, out.point, out.separation, out.feature
    side = sign_of(dot3(sub3(c2, c1), f1[axis]))
    normal = scale3(f1[axis], side)
    j, most = 0, -1.0
    for k in range(3):
        if abs(dot3(normal, f2[k])) > most:
            j, most = k, abs(dot3(normal, f2[k]))
    side2 = -sign_of(dot3(normal, f2[j]))
    u, v = (j + 1) % 3, (j + 2) % 3
    centre = madd3(c2, side2 * h2[j], f2[j])
    polygon, label = out.polygon, out.label
    for k in range(4):  # corners (+, +), (-, +), (-, -), (+, -) along (u, v): a cycle
        su = 1.0 if k == 0 or k == 3 else -1.0
        sv = 1.0 if k < 2 else -1.0
        corner = madd3(madd3(centre, su * h2[u], f2[u]), sv * h2[v], f2[v])
        local = to_local(f1, sub3(corner, c1))
        polygon[0, k, 0], polygon[0, k, 1], polygon[0, k, 2] = local
        label[0, k, 0], label[0, k, 1] = (k + 3) % 4, k  # arriving along edge k-1, leaving along edge k
    count, now = 4, 0
    for plane in range(4):
        along = (axis + 1 + plane // 2) % 3
        sense = 1.0 if plane % 2 == 0 else -1.0
        count = clip((polygon, label), (now, count), (along, sense, h1[along], 4 + plane))
        now = 1 - now
        if count == 0:
            return 0
    reference_face = 2 * axis + (1 if side > 0 else 0)
    incident_face = 2 * j + (1 if side2 > 0 else 0)
    base = ((reference * 6 + reference_face) * 6 + incident_face) * 64
    kept = np.int64(0)  # not the literal 0: reduce_to_four compiled once more for it (as box_box's faces)
    for k in range(count):
        x = (polygon[now, k, 0], polygon[now, k, 1], polygon[now, k, 2])
        height = side * x[axis] - h1[axis]
        if height >= margin:
            continue
        point = add3(c1, to_world(f1, x))
        out_point[kept, 0], out_point[kept, 1], out_point[kept, 2] = madd3(point, -0.5 * height, normal)
        out_normal[kept, 0], out_normal[kept, 1], out_normal[kept, 2] = normal
        out_separation[kept] = height
        out_feature[kept] = base + label[now, k, 0] * 8 + label[now, k, 1]
        kept += 1
    if kept > 4:  # every normal is the reference face's: only the points need choosing
        kept = reduce_to_four(out_point, out_separation, out_feature, kept)
    return kept


@njit(cache=True, inline="always", error_model="numpy")
def clip(buffers, source, cut):
    """Sutherland–Hodgman: the part of the polygon ``buffers`` = (vertices, labels) [now] with
    sense * x_along <= limit, ``source`` = (now, its vertex count), ``cut`` = (along, sense, limit,
    the plane's line id), written into the buffers' other half [1 - now]; its vertex count.

    A vertex less than :data:`CLIP_TOLERANCE` outside the plane is kept as it is; an edge
    leaving the kept side is cut where it crosses the plane itself. The cut vertex lies on the
    edge's line and on the plane: leaving the kept side it is named (that line, plane), entering
    it (plane, that line), so each vertex is named by the line the boundary arrives along and
    the one it leaves along. (Element by element: a row slice of the buffers would be a view made
    and freed per vertex, which made the clipping most of the narrow phase's time.)
    """
    polygon, label = buffers
    now, count = source
    along, sense, limit, plane = cut
    out = 1 - now
    kept = 0
    for k in range(count):
        q = k + 1 if k + 1 < count else 0  # (k + 1) % count without a division per vertex
        dp = sense * polygon[now, k, along] - limit
        dq = sense * polygon[now, q, along] - limit
        if dp <= CLIP_TOLERANCE:
            for m in range(3):
                polygon[out, kept, m] = polygon[now, k, m]
            label[out, kept, 0], label[out, kept, 1] = label[now, k, 0], label[now, k, 1]
            kept += 1
        if (dp <= CLIP_TOLERANCE) != (dq <= CLIP_TOLERANCE):
            s = dp / (dp - dq)
            if 0 < s < 1:  # not where a vertex kept within the tolerance already stands
                for m in range(3):
                    polygon[out, kept, m] = polygon[now, k, m] + s * (polygon[now, q, m] - polygon[now, k, m])
                if dp <= CLIP_TOLERANCE:
                    label[out, kept, 0], label[out, kept, 1] = label[now, k, 1], plane
                else:
                    label[out, kept, 0], label[out, kept, 1] = plane, label[now, k, 1]
                kept += 1
    return kept


@njit(cache=True, inline="always", error_model="numpy")
def support_edge(box, axis, normal, sense):
    """The edge of a box (centre, frame, half) along ``axis`` farthest along sense * normal: (its start, its
    direction, its id 0..11)."""
    centre, frame, half = box
    middle, bits = centre, 0
    for n in range(2):
        k = (axis + 1 + n) % 3
        side = sense * sign_of(dot3(normal, frame[k]))
        middle = madd3(middle, side * half[k], frame[k])
        bits = bits * 2 + (1 if side > 0 else 0)
    return madd3(middle, -half[axis], frame[axis]), scale3(frame[axis], 2.0 * half[axis]), axis * 4 + bits


@njit(cache=True, inline="always", error_model="numpy")
def edge_contact(edge_a, edge_b, separation, margin, out):
    """Edge a_i of box a against edge b_j of box b, ``edge_a`` = (box a, i) and ``edge_b`` = (box b, j):
    the closest points of the two support edges, one point.

    Both edges are perpendicular to the axis n = a_i x b_j, so their distance along n is the
    axis's separation wherever the closest points fall. For boxes apart the point's gap is the
    distance of the closest points themselves, and its normal joins them: the gap those two
    edges actually have (never less than the boxes' distance, so no contact is reported early).
    """
    (box_a, i), (box_b, j) = edge_a, edge_b
    ca, fa = box_a[0], box_a[1]
    cb, fb = box_b[0], box_b[1]
    normal = cross3(fa[i], fb[j])
    normal = scale3(normal, 1.0 / np.sqrt(dot3(normal, normal)))
    if dot3(normal, sub3(cb, ca)) < 0:
        normal = scale3(normal, -1.0)
    pa, da, id_a = support_edge(box_a, i, normal, 1.0)
    pb, db, id_b = support_edge(box_b, j, normal, -1.0)
    s, t = segment_segment(pa, da, pb, db)
    xa, xb = madd3(pa, s, da), madd3(pb, t, db)
    if separation > 0:  # apart: the gap of the closest points, along the line joining them
        gap = sub3(xb, xa)
        separation = np.sqrt(dot3(gap, gap))
        if separation >= margin:
            return 0
        normal = scale3(gap, 1.0 / separation)
    write_point(out, 0, normal, separation, scale3(add3(xa, xb), 0.5), EDGE_FEATURE + id_a * 12 + id_b)
    return 1


@njit(cache=True, error_model="numpy")
def box_plane(c, frame, half, plane_normal, offset, margin, out):
    """A box against the half-space n . x <= offset: the corners of its face most opposed to n below the margin.

    Each corner's separation is its height n . x - offset; its point lies halfway down to the
    plane, its id is the corner's (so a box tipping from one face to the next keeps the ids of
    the corners it stands on). A box lying flat gives its 4 bottom corners. The normal is -n.
    """
    j, most = 0, -1.0
    for k in range(3):
        if abs(dot3(plane_normal, frame[k])) > most:
            j, most = k, abs(dot3(plane_normal, frame[k]))
    side = -sign_of(dot3(plane_normal, frame[j]))
    u, v = (j + 1) % 3, (j + 2) % 3
    kept = 0
    out_normal, out_point, out_separation, out_feature = out.normal, out.point, out.separation, out.feature
    for k in range(4):
        su, sv = 1.0 if k % 2 == 0 else -1.0, 1.0 if k < 2 else -1.0
        corner = madd3(madd3(madd3(c, side * half[j], frame[j]), su * half[u], frame[u]), sv * half[v], frame[v])
        normal, _, height = sphere_plane(corner, 0.0, plane_normal, offset)  # the corner as a sphere of radius 0
        if height >= margin:
            continue
        out_point[kept, 0], out_point[kept, 1], out_point[kept, 2] = madd3(corner, -0.5 * height, plane_normal)
        out_normal[kept, 0], out_normal[kept, 1], out_normal[kept, 2] = normal
        out_separation[kept] = height
        # the corner's id: bit 4 >> k set where it lies on the + side of axis k
        out_feature[kept] = (4 >> j if side > 0 else 0) + (4 >> u if su > 0 else 0) + (4 >> v if sv > 0 else 0)
        kept += 1
    return kept
