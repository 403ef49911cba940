"""Uniform gravity, W = m g."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .force import Force

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

    def force(self, xp, q, v, m):
        return m[:, None] * self.g

    def potential(self, xp, q, m):
        # W = -grad U with U = -m g . q
        return -xp.sum(m * (q @ self.g))
