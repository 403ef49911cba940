"""Candidate pairs: what the broadphase hands the narrow phase.

The broadphase (``physics.broadphase``: brute force, uniform grid, sort and sweep, ...)
finds the pairs of bodies whose bounding spheres overlap; here the bounding sphere of a
body covers its whole motion over the (sub-)step, so a pair that could touch at any time
during it is a candidate.

A candidate group is vectorised over its pairs and knows how to test them: body against
body (:class:`BodyPairs`, sphere-sphere) or bodies against one static shape
(:class:`ShapePairs`).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ..broadphase import find_pairs
from ..broadphase.common import MAX_COORDINATE
from ..rules import short
from .chords import swept_bounds
from .narrow_phase import collide, collide_sphere_sphere
from .shapes import Shape, Sphere
from .time_of_impact import sphere_sphere, time_of_impact

#: the pair-finding method when a scene names none (a uniform grid, see physics.broadphase)
DEFAULT_BROADPHASE = "grid"
def _lerp(q0, q1, index, s):
    """Positions of bodies ``index`` at fraction ``s`` (per pair) along their chords."""
    p = q0[index]
    return p if s is None else p + np.asarray(s)[:, None] * (q1[index] - p)


@dataclasses.dataclass(frozen=True)
class BodyPairs:
    """Candidate pairs of bodies ``i[k] < j[k]``."""

    i: np.ndarray
    j: np.ndarray
    trigger = False

    def __len__(self):
        return len(self.i)

    def subset(self, k) -> BodyPairs:
        return BodyPairs(self.i[k], self.j[k])

    def key(self, k) -> tuple:
        return ("bodies", int(self.i[k]), int(self.j[k]))

    def contact(self, radii, q0, q1=None, s=None):
        """Contacts at the start positions ``q0``, or at fraction ``s`` (per pair) of the chords."""
        return collide_sphere_sphere(Sphere.unchecked(_lerp(q0, q1, self.i, s), radii[self.i]),
                                     Sphere.unchecked(_lerp(q0, q1, self.j, s), radii[self.j]))

    def time_of_impact(self, radii, q0, q1):
        return sphere_sphere(q0[self.i], q1[self.i], q0[self.j], q1[self.j], radii[self.i], radii[self.j])

    def velocity_b(self, v):
        return v[self.j]

    def inverse_mass_b(self, inverse_masses):
        return inverse_masses[self.j]


@dataclasses.dataclass(frozen=True)
class ShapePairs:
    """Candidate bodies ``i`` against the static shape ``shape`` (number ``index`` of the world)."""

    index: int
    shape: Shape
    i: np.ndarray

    def __len__(self):
        return len(self.i)

    @property
    def trigger(self) -> bool:
        return self.shape.trigger

    def subset(self, k) -> ShapePairs:
        return ShapePairs(self.index, self.shape, self.i[k])

    def key(self, k) -> tuple:
        return ("shape", self.index, int(self.i[k]))

    def contact(self, radii, q0, q1=None, s=None):
        return collide(Sphere.unchecked(_lerp(q0, q1, self.i, s), radii[self.i]), self.shape)

    def time_of_impact(self, radii, q0, q1):
        return time_of_impact(q0[self.i], q1[self.i], radii[self.i], self.shape)

    def velocity_b(self, v):
        return np.zeros((len(self.i), 3))

    def inverse_mass_b(self, inverse_masses):
        return np.zeros(len(self.i))


def candidates(shapes, q0, q1, radii, inverse_masses, method: str, removed=(), margin: float = 0.0) -> list:
    """The candidate groups for a sub-step in which bodies move from ``q0`` to ``q1``.

    Each body's bounding sphere is centred on the middle of its chord and reaches its
    radius plus half the chord (plus ``margin``), so it holds the body during the whole
    sub-step. Pairs of immovable bodies (both pinned) are dropped: nothing can respond.
    """
    swept = SweptSpheres.of(q0, q1, radii, inverse_masses, removed, margin)
    groups = [swept.body_pairs(method)] + near_shapes(shapes, swept)
    return [g for g in groups if len(g)]


class SweptSpheres(NamedTuple):
    """Each body's bounding sphere over a sub-step (``centers``, ``reach``), and which bodies take part.

    A NamedTuple of arrays, so the compiled kernels take it whole (:mod:`.contact_buffer`).
    """

    centers: np.ndarray
    reach: np.ndarray
    active: np.ndarray  # (N,) bool: not removed from the run
    inverse_masses: np.ndarray

    @classmethod
    def of(cls, q0, q1, radii, inverse_masses, removed=(), margin: float = 0.0) -> SweptSpheres:
        """The swept spheres of the chords ``q0 -> q1``; FloatingPointError (a run that diverged, status 1)
        when an active body's swept sphere is not finite or reaches beyond the broadphase's range,
        ``MAX_COORDINATE``: a collision scene starts inside it (:mod:`..scene`), so a step that left it blew
        up, where the broadphase would refuse the spheres as bad input (status 2) naming no step."""
        active = np.ones(len(radii), bool)
        if removed:
            active[list(removed)] = False
        centers, reach = swept_bounds(q0, q1, radii, margin)
        # the broadphase's test (..broadphase.common.as_spheres) on the active bodies: one reduction each on
        # the fast path (max propagates NaN), the culprit only on failure. A masked max (where=) costs six
        # times a plain one (65 against 11 us on 10^4 bodies), so the mask is applied only when a body is out
        kept_centers, kept_reach = (centers[active], reach[active]) if removed else (centers, reach)
        if not (np.abs(kept_centers).max(initial=0.0) <= MAX_COORDINATE
                and kept_reach.max(initial=0.0) <= MAX_COORDINATE):
            far = active & ~((np.max(np.abs(centers), axis=1) <= MAX_COORDINATE) & (reach <= MAX_COORDINATE))
            if np.any(far):
                k = int(np.argmax(far))
                raise FloatingPointError(
                    f"body {k} moved to {short(q1[k].tolist())} m in the step, beyond the {MAX_COORDINATE:g} m "
                    "the broadphase squares without overflow: the run diverged")
        return cls(centers, reach, active, inverse_masses)

    @property
    def moving(self) -> np.ndarray:
        """The active bodies that can move (not pinned), ascending."""
        return np.flatnonzero(self.active & (self.inverse_masses > 0))

    def body_pairs(self, method: str, threads: int = 1) -> BodyPairs:
        """The pairs whose swept spheres overlap, sorted, less pairs of two pinned bodies (the grid
        searched on ``threads`` of Numba's threads, :func:`..broadphase.find_pairs`)."""
        pairs = self.pair_rows(method, threads)
        return BodyPairs(np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1]))

    def pair_rows(self, method: str, threads: int = 1) -> np.ndarray:
        """:meth:`body_pairs` as rows (i, j), (K, 2) int, C order: what the narrow phase reads. Where no
        body is pinned, the broadphase's own array (the filter's indexing and a copy back to rows cost
        0.3 ms a step of the 10^4 box pit's 40,000 pairs)."""
        if self.active.all():
            pairs = (find_pairs(self.centers, self.reach, method, threads) if len(self.reach) > 1
                     else np.zeros((0, 2), int))
        else:
            index = np.flatnonzero(self.active)
            if len(index) < 2:
                return np.zeros((0, 2), int)
            pairs = index[find_pairs(self.centers[index], self.reach[index], method, threads)]
        if np.all(self.inverse_masses > 0):
            return np.ascontiguousarray(pairs)
        movable = (self.inverse_masses[pairs[:, 0]] > 0) | (self.inverse_masses[pairs[:, 1]] > 0)
        return pairs[movable]


def changed_candidates(shapes, chords, grid, inverse_masses, removed, changed) -> list:
    """The candidate groups of the bodies ``changed`` (int array, ascending) after an impact.

    Their swept spheres (``chords.centers``, ``chords.reach``, :class:`.chords.Chords`) are
    tested against every other body's (through ``grid``, a :class:`.changed_pairs.SweptGrid`)
    and every static shape.
    """
    active = np.ones(len(inverse_masses), bool)
    if removed:
        active[list(removed)] = False
    is_changed = np.zeros(len(inverse_masses), bool)
    is_changed[changed] = True
    pairs = grid.pairs(inverse_masses, active, changed, is_changed)
    groups = [BodyPairs(pairs[:, 0], pairs[:, 1])]
    moving = changed[active[changed] & (inverse_masses[changed] > 0)]
    groups += _near_shapes(enumerate(shapes), chords.centers[moving], chords.reach[moving], moving)
    return [g for g in groups if len(g)]


def near_shapes(shapes, swept: SweptSpheres, numbers=None) -> list:
    """One :class:`ShapePairs` per static shape of ``shapes`` (world numbers ``numbers``, by
    default 0, 1, ...): the moving bodies whose swept spheres reach it."""
    if not len(shapes):
        return []
    moving = swept.moving
    numbered = enumerate(shapes) if numbers is None else zip(numbers, shapes)
    return _near_shapes(numbered, swept.centers[moving], swept.reach[moving], moving)


def _near_shapes(numbered, c, r, moving) -> list:
    """One :class:`ShapePairs` per (number, static shape): the bodies ``moving`` whose swept spheres (c, r) reach it."""
    groups = []
    for k, shape in numbered:
        bounds = shape.bounds()
        if bounds is None:  # a plane: the sphere reaches down to it
            near = c @ shape.normal - shape.offset <= r
        else:
            d = np.clip(c, bounds[0], bounds[1]) - c
            near = np.sum(d * d, axis=1) <= r * r
        groups.append(ShapePairs(k, shape, moving[near]))
    return groups
