"""Narrow phase: one exact test per pair of shape kinds, looked up in a table.

Each test ``collide_<a>_<b>(a, b) -> Contact`` says whether the shapes touch and gives the
contact normal (from A to B), the penetration depth and the closest points. The table
:data:`PAIR_TESTS` is indexed by both kinds; :func:`register` enters a test once and
files it under both orders, the reversed one returning the flipped contact, so
``collide(wall, ball)`` and ``collide(ball, wall)`` agree.

The sphere tests are vectorised: A may be a batch of K spheres (``center`` (K, 3)).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .contact import Contact
from .shapes import Box, OrientedBox, Plane, Shape, Sphere
from .sphere_contacts import sphere_plane_rows, sphere_sphere_rows

#: (kind of A, kind of B) -> test(a, b) -> Contact
PAIR_TESTS: dict[tuple[str, str], Callable[[Shape, Shape], Contact]] = {}


def register(kind_a: str, kind_b: str, test: Callable[[Shape, Shape], Contact]) -> None:
    """File ``test`` under (kind_a, kind_b), and its mirror image under (kind_b, kind_a)."""
    PAIR_TESTS[(kind_a, kind_b)] = test
    if kind_a != kind_b:
        PAIR_TESTS[(kind_b, kind_a)] = lambda b, a: test(a, b).flipped()


def collide(a: Shape, b: Shape) -> Contact:
    """Test shape ``a`` against shape ``b`` with the pair test for their kinds."""
    try:
        test = PAIR_TESTS[(a.kind, b.kind)]
    except KeyError:
        raise NotImplementedError(f"no narrow-phase test for {a.kind} against {b.kind}") from None
    return test(a, b)


def _dot(x, y):
    return (x * y).sum(axis=-1)


def collide_sphere_sphere(a: Sphere, b: Sphere) -> Contact:
    """Two spheres: the normal joins the centres (the lecture's Case B).

    depth = r_a + r_b - |c_b - c_a|; concentric spheres get the normal +x by convention
    (:func:`.sphere_contacts.sphere_sphere`, the one definition, row by row).
    """
    d = np.asarray(b.center, dtype=float) - a.center
    r_a, r_b = np.asarray(a.radius), np.asarray(b.radius)
    normal, depth = sphere_sphere_rows(np.ascontiguousarray(d.reshape(-1, 3)),
                                       np.broadcast_to(r_a + r_b, d.shape[:-1]).reshape(-1).astype(float))
    normal, depth = normal.reshape(d.shape), depth.reshape(d.shape[:-1])
    return Contact.make(normal, depth, a.center + normal * r_a[..., None], b.center - normal * r_b[..., None])


def collide_sphere_plane(a: Sphere, b: Plane) -> Contact:
    """A sphere against the half-space ``n . x <= offset``: depth = r - (n . c - offset), normal -n
    (:func:`.sphere_contacts.sphere_plane`, row by row)."""
    center = np.asarray(a.center, dtype=float)
    r = np.asarray(a.radius)
    normal, depth, height = sphere_plane_rows(np.ascontiguousarray(center.reshape(-1, 3)),
                                              np.broadcast_to(r, center.shape[:-1]).reshape(-1).astype(float),
                                              np.asarray(b.normal, dtype=float), float(b.offset))
    normal, depth, height = normal.reshape(center.shape), depth.reshape(center.shape[:-1]), height.reshape(
        center.shape[:-1])
    return Contact.make(normal, depth, center - b.normal * r[..., None], center - b.normal * height[..., None])


def _sphere_aabb(center, radius, lo, hi) -> Contact:
    """A sphere against the box [lo, hi]: the closest point of the box to the centre.

    Outside the box the normal runs from the centre to that point. With the centre inside
    the box, the sphere leaves through the nearest face: the normal is minus that face's
    outward normal and the depth is r plus the centre's distance to the face.
    """
    radius = np.asarray(radius)
    closest = np.clip(center, lo, hi)
    d = closest - center
    dist = np.sqrt(_dot(d, d))
    outside = dist > 0
    # inside: distance to each of the six faces, -x, -y, -z faces first
    to_faces = np.concatenate([center - lo, hi - center], axis=-1)
    face = np.argmin(to_faces, axis=-1)
    axis, side = face % 3, np.where(face < 3, -1.0, 1.0)
    face_normal = np.eye(3)[axis] * side[..., None]  # outward normal of the nearest face
    face_dist = np.take_along_axis(to_faces, face[..., None], axis=-1)[..., 0]
    on_face = center + face_normal * face_dist[..., None]

    normal = np.where(outside[..., None], d / np.where(outside, dist, 1.0)[..., None], -face_normal)
    depth = np.where(outside, radius - dist, radius + face_dist)
    point_b = np.where(outside[..., None], closest, on_face)
    return Contact.make(normal, depth, center + normal * radius[..., None], point_b)


def collide_sphere_box(a: Sphere, b: Box) -> Contact:
    """A sphere against an axis-aligned box (closest point by clamping the centre)."""
    return _sphere_aabb(a.center, a.radius, b.lo, b.hi)


def collide_sphere_oriented_box(a: Sphere, b: OrientedBox) -> Contact:
    """A sphere against an oriented box: the axis-aligned test in the box's own frame."""
    local = _sphere_aabb(b.to_local(a.center), a.radius, -b.half_extents, b.half_extents)
    return Contact(local.touching, b.to_world_vector(local.normal), local.penetration_depth,
                   b.to_world_point(local.point_a), b.to_world_point(local.point_b))


def collide_box_box(a: Box, b: Box) -> Contact:
    """Two axis-aligned boxes.

    Per axis the intervals overlap by ``min(hi) - max(lo)``. Overlapping on every axis,
    the boxes are pushed apart along the axis of least overlap (the penetration depth).
    Otherwise the closest points are the near faces on separated axes and the middle of
    the shared interval on the others; the gap is their distance.
    """
    overlap = np.minimum(a.hi, b.hi) - np.maximum(a.lo, b.lo)
    middle = 0.5 * (np.maximum(a.lo, b.lo) + np.minimum(a.hi, b.hi))
    b_above = b.center >= a.center
    near_a = np.where(b_above, a.hi, a.lo)
    near_b = np.where(b_above, b.lo, b.hi)
    if np.all(overlap >= 0):
        k = int(np.argmin(overlap))
        sign = 1.0 if b_above[k] else -1.0
        normal = np.eye(3)[k] * sign
        point_a, point_b = middle.copy(), middle.copy()
        point_a[k], point_b[k] = near_a[k], near_b[k]
        return Contact.make(normal, overlap[k], point_a, point_b)
    apart = overlap < 0
    point_a = np.where(apart, near_a, middle)
    point_b = np.where(apart, near_b, middle)
    gap = point_b - point_a
    dist = float(np.sqrt(gap @ gap))
    return Contact.make(gap / dist, -dist, point_a, point_b)


register("sphere", "sphere", collide_sphere_sphere)
register("sphere", "plane", collide_sphere_plane)
register("sphere", "box", collide_sphere_box)
register("sphere", "oriented-box", collide_sphere_oriented_box)
register("box", "box", collide_box_box)
