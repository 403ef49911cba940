"""Uniform gravity, W = m g."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .force import Force
from .rules import require, skip_checks, vector_problem

#: standard gravity on Earth with +z up, m/s^2 (the lecture's g)
EARTH_GRAVITY = (0.0, 0.0, -9.81)


@dataclasses.dataclass(frozen=True)
class Gravity(Force):
    """Uniform gravitational field: the weight W = m g of every body.

    Parameters
    ----------
    g : ndarray, shape (3,)
        Gravitational acceleration, m/s^2.
    """

    g: np.ndarray = dataclasses.field(default_factory=lambda: np.array(EARTH_GRAVITY))

    name: ClassVar[str] = "gravity"
    constant: ClassVar[bool] = True

    def __post_init__(self):
        if not skip_checks(self.g):  # as a scene file's g: 3 finite numbers
            require("Gravity: g", vector_problem(self.g))

    @classmethod
    def from_scene(cls, table, bodies) -> Gravity:
        """``[forces.gravity]`` with ``g = [x, y, z]`` (default: Earth's, -z)."""
        table.allow("g")
        return cls(table.vector("g", list(EARTH_GRAVITY)))

    def force(self, xp, q, v, m):
        return m[:, None] * self.g

    def constant_acceleration(self, m) -> np.ndarray:
        # a field: g itself, not m g / m (which would round)
        return np.asarray(self.g, dtype=float)

    def potential(self, xp, q, m):
        # W = -grad U with U = -m g . q
        return -xp.sum(m * (q @ self.g))
