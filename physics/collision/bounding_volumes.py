"""Bounding volumes: cheap shapes around complex ones, and a two-level hierarchy of them.

A bounding volume completely encloses its object, so when two bounding volumes do not
overlap the objects cannot touch and no finer test is needed; when they do overlap the
objects *could* touch. The three the lecture names:

- :class:`BoundingSphere`: overlap when the distance between the centres is *at most*
  the sum of the radii. (The lecture's slide says "if distance between centers less than
  sum of radii then no collision", which is backwards: two unit spheres 1 m apart share
  the point halfway between them.)
- :class:`AABB`, axis-aligned (a loose fit, the cheapest test: overlap on every axis);
- :class:`OBB`, oriented (a tighter fit; separating-axis test over 15 axes).

Overlap tests are looked up by both kinds, each pair filed under both orders, like the
narrow phase. :class:`Hierarchy` is the lecture's avatar: a large sphere around the whole
object, refined by boxes and spheres around its parts only when the large spheres meet.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import ClassVar

import numpy as np

#: relative tolerance of the separating-axis test (OBB axes parallel to each other)
SAT_TOLERANCE = 1e-12


@dataclasses.dataclass(frozen=True)
class BoundingSphere:
    center: np.ndarray
    radius: float
    kind: ClassVar[str] = "sphere"

    @classmethod
    def around(cls, points) -> BoundingSphere:
        """Ritter's sphere: grown from the two far points until it holds every point.

        Within about 5-20 % of the smallest enclosing sphere, in two passes.
        """
        points = np.atleast_2d(np.asarray(points, dtype=float))
        x = points[0]
        y = points[np.argmax(np.sum((points - x) ** 2, axis=1))]
        z = points[np.argmax(np.sum((points - y) ** 2, axis=1))]
        center, radius = 0.5 * (y + z), 0.5 * float(np.linalg.norm(z - y))
        for p in points:
            dist = float(np.linalg.norm(p - center))
            if dist > radius:  # grow to hold p, keeping the far side fixed
                radius_new = 0.5 * (radius + dist)
                center = center + (dist - radius_new) / dist * (p - center)
                radius = radius_new
        return cls(center, radius * (1 + 1e-12))

    def contains(self, points) -> np.ndarray:
        return np.linalg.norm(np.atleast_2d(points) - self.center, axis=1) <= self.radius


@dataclasses.dataclass(frozen=True)
class AABB:
    lo: np.ndarray
    hi: np.ndarray
    kind: ClassVar[str] = "aabb"

    @classmethod
    def around(cls, points) -> AABB:
        points = np.atleast_2d(np.asarray(points, dtype=float))
        return cls(points.min(axis=0), points.max(axis=0))

    def contains(self, points) -> np.ndarray:
        points = np.atleast_2d(points)
        return np.all((points >= self.lo) & (points <= self.hi), axis=1)

    def as_obb(self) -> OBB:
        return OBB(0.5 * (self.lo + self.hi), 0.5 * (self.hi - self.lo), np.eye(3))


@dataclasses.dataclass(frozen=True)
class OBB:
    """``half_extents`` along the columns of ``axes`` (orthonormal, (3, 3)) around ``center``."""

    center: np.ndarray
    half_extents: np.ndarray
    axes: np.ndarray
    kind: ClassVar[str] = "obb"

    @classmethod
    def around(cls, points) -> OBB:
        """Axes from the principal components of the points (their covariance), then the extents."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        mean = points.mean(axis=0)
        _, axes = np.linalg.eigh(np.cov((points - mean).T) if len(points) > 1 else np.eye(3))
        local = (points - mean) @ axes
        lo, hi = local.min(axis=0), local.max(axis=0)
        return cls(mean + (0.5 * (lo + hi)) @ axes.T, 0.5 * (hi - lo), axes)

    def contains(self, points) -> np.ndarray:
        local = (np.atleast_2d(points) - self.center) @ self.axes
        return np.all(np.abs(local) <= self.half_extents * (1 + 1e-12) + 1e-15, axis=1)


Volume = BoundingSphere | AABB | OBB

#: (kind of a, kind of b) -> overlap test(a, b) -> bool
OVERLAP_TESTS: dict[tuple[str, str], Callable[[Volume, Volume], bool]] = {}


def register(kind_a: str, kind_b: str, test: Callable[[Volume, Volume], bool]) -> None:
    """File an overlap test under (kind_a, kind_b) and, arguments swapped, (kind_b, kind_a)."""
    OVERLAP_TESTS[(kind_a, kind_b)] = test
    if kind_a != kind_b:
        OVERLAP_TESTS[(kind_b, kind_a)] = lambda b, a: test(a, b)


def overlaps(a: Volume, b: Volume) -> bool:
    """Whether two bounding volumes overlap (touching counts)."""
    return bool(OVERLAP_TESTS[(a.kind, b.kind)](a, b))


def sphere_sphere(a: BoundingSphere, b: BoundingSphere) -> bool:
    """Overlap when |c_a - c_b| <= r_a + r_b (the lecture's slide has the inequality reversed)."""
    d = np.asarray(a.center) - b.center
    return float(d @ d) <= (a.radius + b.radius) ** 2


def aabb_aabb(a: AABB, b: AABB) -> bool:
    """Overlap on every axis."""
    return bool(np.all((a.lo <= b.hi) & (b.lo <= a.hi)))


def sphere_aabb(a: BoundingSphere, b: AABB) -> bool:
    """The box's closest point to the centre is within the radius."""
    d = np.clip(a.center, b.lo, b.hi) - a.center
    return float(d @ d) <= a.radius**2


def sphere_obb(a: BoundingSphere, b: OBB) -> bool:
    local = (np.asarray(a.center) - b.center) @ b.axes
    return sphere_aabb(BoundingSphere(local, a.radius), AABB(-b.half_extents, b.half_extents))


def obb_obb(a: OBB, b: OBB) -> bool:
    """Separating-axis test: convex boxes are apart iff some axis separates their shadows.

    The candidate axes are the 3 face normals of each box and the 9 cross products of
    their edges. On an axis L the shadows are apart when |(c_b - c_a) . L| exceeds the
    sum of the boxes' projected radii, r = sum_i h_i |u_i . L|.
    """
    d = np.asarray(b.center) - a.center
    axes = [a.axes[:, i] for i in range(3)] + [b.axes[:, j] for j in range(3)]
    axes += [np.cross(a.axes[:, i], b.axes[:, j]) for i in range(3) for j in range(3)]
    scale = 1 + float(np.sum(a.half_extents) + np.sum(b.half_extents) + np.linalg.norm(d))
    for axis in axes:
        if axis @ axis < SAT_TOLERANCE:  # parallel edges: their cross product is no axis
            continue
        reach_a = np.sum(a.half_extents * np.abs(axis @ a.axes))
        reach_b = np.sum(b.half_extents * np.abs(axis @ b.axes))
        if abs(d @ axis) > reach_a + reach_b + SAT_TOLERANCE * scale:
            return False
    return True


register("sphere", "sphere", sphere_sphere)
register("aabb", "aabb", aabb_aabb)
register("obb", "obb", obb_obb)
register("sphere", "aabb", sphere_aabb)
register("sphere", "obb", sphere_obb)
register("aabb", "obb", lambda a, b: obb_obb(a.as_obb(), b))


@dataclasses.dataclass(frozen=True)
class Hierarchy:
    """A two-level bounding hierarchy: a coarse sphere around finer volumes of the parts."""

    coarse: BoundingSphere
    parts: tuple[Volume, ...]

    @classmethod
    def around(cls, parts: Sequence[Volume], part_points: Sequence[np.ndarray]) -> Hierarchy:
        """The coarse sphere around all the parts' points, over the given part volumes."""
        return cls(BoundingSphere.around(np.concatenate([np.atleast_2d(p) for p in part_points])), tuple(parts))


def hierarchy_overlaps(a: Hierarchy, b: Hierarchy) -> tuple[list[tuple[int, int]], int]:
    """The pairs of parts (i of a, j of b) whose volumes overlap, and the tests it took.

    One test when the coarse spheres are apart; otherwise one plus one per pair of parts.
    """
    if not overlaps(a.coarse, b.coarse):
        return [], 1
    pairs = [(i, j) for i, pa in enumerate(a.parts) for j, pb in enumerate(b.parts) if overlaps(pa, pb)]
    return pairs, 1 + len(a.parts) * len(b.parts)
