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

from ..rules import direction, number_problem, numeric, require, rotation_problem, short, skip_checks, vector_problem

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

    @classmethod
    def unchecked(cls, center, radius) -> Sphere:
        """``Sphere(center, radius)`` without the checks, for the collision code's own spheres: a run's
        positions, built every bisection iteration and every swept test, where the checks (18 us a
        sphere) would nearly triple a contact test (21 -> 58 us), and where a diverging run's
        non-finite positions are the run's to report, not a Sphere's. The other fields keep their
        defaults (the class's attributes)."""
        sphere = object.__new__(cls)
        object.__setattr__(sphere, "center", center)
        object.__setattr__(sphere, "radius", radius)
        return sphere

    def __post_init__(self):
        if skip_checks(self.center, self.radius):
            return
        # the shapes the narrow phase broadcasts: one sphere, or a batch of K of one radius each
        center = numeric(self.center)
        if center is None or center.shape != (3,) and (center.ndim != 2 or center.shape[1] != 3):
            shown = f"shape {center.shape}" if center is not None else short(self.center)
            raise ValueError(f"Sphere: center must be one point [x, y, z], shape (3,), or K of them, shape (K, 3), "
                             f"got {shown}")
        require("Sphere: center", number_problem(center))
        require("Sphere: radius", number_problem(self.radius, positive=True))
        if np.shape(self.radius) != center.shape[:-1]:
            one = "one radius, shape ()" if center.ndim == 1 else f"one radius per center, shape {center.shape[:-1]}"
            raise ValueError(f"Sphere: radius must be {one} for a center of shape {center.shape}, got shape "
                             f"{np.shape(self.radius)}")

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
        # halved first: lo + hi of a box near the float range overflows (an MJCF pos of -inf); the same bits otherwise
        return 0.5 * self.lo + 0.5 * self.hi

    @property
    def half_extents(self) -> np.ndarray:
        return 0.5 * self.hi - 0.5 * self.lo

    def bounds(self):
        return self.lo, self.hi


@dataclasses.dataclass(frozen=True)
class OrientedBox(Shape):
    """A box of ``half_extents`` (3,) around ``center``, turned by ``rotation``.

    ``rotation`` (3, 3) is a rotation (orthonormal, det +1); its columns are the box's own x, y
    and z axes in world coordinates, so a world point p has box coordinates ``(p - center) @ rotation``.
    A reflection (det -1) is refused: it would describe the same box as the rotation with one column
    negated, but the engines compared against (pybullet, through a quaternion) take no left-handed frame.
    """

    center: np.ndarray
    half_extents: np.ndarray
    rotation: np.ndarray
    name: str = "oriented-box"
    material: str = DEFAULT_MATERIAL
    trigger: bool = False

    kind: ClassVar[str] = "oriented-box"

    def __post_init__(self):
        if skip_checks(self.center, self.half_extents, self.rotation):
            return
        # a scene file's [[collisions.boxes]] with an angle: center, size / 2 and rotation_matrix(axis, angle)
        require("OrientedBox: center", vector_problem(self.center))
        require("OrientedBox: half_extents", vector_problem(self.half_extents, positive=True))
        require("OrientedBox: rotation", rotation_problem(self.rotation))

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
