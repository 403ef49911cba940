"""Collision shapes: spheres (the bodies), and the static geometry of a scene.

Every body of a scene is a sphere of its own radius; the static geometry a body can hit
is made of planes (floors, walls), axis-aligned boxes (thin walls, "paper") and oriented
boxes. A shape is small immutable data; the pair tests (:mod:`.narrow_phase`) and the
swept tests (:mod:`.time_of_impact`) look it up by its ``kind``.

A :class:`Sphere` may hold a *batch* of spheres (``center`` of shape (K, 3), ``radius``
of shape (K,)): the pair tests are vectorised over the batch, so one call tests every
body against a wall.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ..rules import direction, number_problem, require, short, vector_problem

#: the material of a body or shape that declares none
DEFAULT_MATERIAL = "default"


@dataclasses.dataclass(frozen=True)
class Shape:
    """What every static shape has: a name, a material, and whether it is a trigger.

    A *trigger* (a ghost wall, a goal area) only reports that something entered it: the
    collision is cancelled in the prologue and no body is pushed or bounced.
    """

    kind: ClassVar[str] = "shape"

    def bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Axis-aligned bounds (lo, hi) of the shape, or ``None`` if unbounded."""
        raise NotImplementedError


@dataclasses.dataclass(frozen=True)
class Sphere(Shape):
    """Sphere(s): ``center`` (3,) or (K, 3) m, ``radius`` () or (K,) m."""

    center: np.ndarray
    radius: np.ndarray
    name: str = "sphere"
    material: str = DEFAULT_MATERIAL
    trigger: bool = False

    kind: ClassVar[str] = "sphere"

    def bounds(self):
        r = np.asarray(self.radius)[..., None]
        return self.center - r, self.center + r


@dataclasses.dataclass(frozen=True)
class Plane(Shape):
    """The half-space ``normal . x <= offset``: solid below the plane, free above it.

    ``normal`` is a unit vector pointing out of the solid (up, for a floor).
    """

    normal: np.ndarray
    offset: float = 0.0
    name: str = "plane"
    material: str = DEFAULT_MATERIAL
    trigger: bool = False

    kind: ClassVar[str] = "plane"

    def __post_init__(self):
        # as a scene file's [[collisions.planes]] normal: 3 finite numbers, not zero, normalised
        # (a unit normal is kept as it is, to the byte)
        object.__setattr__(self, "normal", direction("Plane: normal", self.normal))
        require("Plane: offset", number_problem(self.offset))

    def bounds(self):
        return None


@dataclasses.dataclass(frozen=True)
class Box(Shape):
    """An axis-aligned box from ``lo`` to ``hi`` (each (3,), m, ``hi > lo``)."""

    lo: np.ndarray
    hi: np.ndarray
    name: str = "box"
    material: str = DEFAULT_MATERIAL
    trigger: bool = False

    kind: ClassVar[str] = "box"

    def __post_init__(self):
        require("Box: lo", vector_problem(self.lo))
        require("Box: hi", vector_problem(self.hi))
        if not np.all(np.asarray(self.hi) > np.asarray(self.lo)):
            raise ValueError(f"Box: hi must exceed lo in every component, got lo = {short(self.lo)}, "
                             f"hi = {short(self.hi)}")

    @classmethod
    def from_center(cls, center, size, **kwargs) -> Box:
        center, half = np.asarray(center, float), 0.5 * np.asarray(size, float)
        return cls(center - half, center + half, **kwargs)

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.lo + self.hi)

    @property
    def half_extents(self) -> np.ndarray:
        return 0.5 * (self.hi - self.lo)

    def bounds(self):
        return self.lo, self.hi


@dataclasses.dataclass(frozen=True)
class OrientedBox(Shape):
    """A box of ``half_extents`` (3,) around ``center``, turned by ``rotation``.

    ``rotation`` (3, 3) is orthonormal; its columns are the box's own x, y and z axes in
    world coordinates, so a world point p has box coordinates ``(p - center) @ rotation``.
    """

    center: np.ndarray
    half_extents: np.ndarray
    rotation: np.ndarray
    name: str = "oriented-box"
    material: str = DEFAULT_MATERIAL
    trigger: bool = False

    kind: ClassVar[str] = "oriented-box"

    def to_local(self, p):
        return (p - self.center) @ self.rotation

    def to_world_point(self, p):
        return self.center + p @ self.rotation.T

    def to_world_vector(self, d):
        return d @ self.rotation.T

    def bounds(self):
        # the box's extent along world axis k is sum_i |R_ki| h_i
        reach = np.abs(self.rotation) @ self.half_extents
        return self.center - reach, self.center + reach


def rotation_matrix(axis, degrees: float) -> np.ndarray:
    """The rotation by ``degrees`` about ``axis`` (Rodrigues' formula), shape (3, 3)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    angle = np.radians(degrees)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)
