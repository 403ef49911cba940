"""What a narrow-phase pair test returns: touching, normal, penetration depth, closest points."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Contact:
    """The result of testing shape A against shape B (arrays when A is a batch of spheres).

    Attributes
    ----------
    touching : bool array, shape (K,) or ()
        ``penetration_depth >= 0``: the shapes touch or overlap.
    normal : array, shape (K, 3) or (3,)
        Unit contact normal, pointing from A towards B (the lecture's n: along it A
        pushes B, and B pushes A back along -n).
    penetration_depth : array, shape (K,) or ()
        How far the shapes overlap along the normal, m; negative: the gap between them.
    point_a, point_b : array, shape (K, 3) or (3,)
        The closest points, on A's surface and on B's surface. Overlapping, they are the
        deepest points: ``point_b - point_a = -penetration_depth * normal``.
    """

    touching: np.ndarray
    normal: np.ndarray
    penetration_depth: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray

    @classmethod
    def make(cls, normal, penetration_depth, point_a, point_b) -> Contact:
        depth = np.asarray(penetration_depth)
        return cls(depth >= 0, normal, depth, point_a, point_b)

    def flipped(self) -> Contact:
        """The same contact seen from B: normal reversed, closest points swapped."""
        return Contact(self.touching, -self.normal, self.penetration_depth, self.point_b, self.point_a)
