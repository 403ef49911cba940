"""The state of N point masses (spheres), and the lecture's momentum view of it.

Integrators work on the array ``y`` of shape (2, N, 3): ``y[0]`` the positions ``q``,
``y[1]`` the velocities ``v``. The lecture writes the same state as
S = (m1 V1, p1, m2 V2, p2, ...) with dS/dt = (F1, V1, F2, V2, ...); since the masses
are constant the two are the same system, and :func:`lecture_state` converts.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class State:
    """Positions (N, 3) m, velocities (N, 3) m/s, masses (N,) kg and radii (N,) m."""

    positions: np.ndarray
    velocities: np.ndarray
    masses: np.ndarray
    radii: np.ndarray

    @property
    def y(self) -> np.ndarray:
        """The integrators' view, shape (2, N, 3)."""
        return np.stack([self.positions, self.velocities])

    def lecture(self) -> np.ndarray:
        """The lecture's S = (m1 V1, p1, m2 V2, p2, ...), shape (2N, 3)."""
        return lecture_state(self.y, self.masses)


def lecture_state(y, masses) -> np.ndarray:
    """S of shape (2N, 3): row 2i is the momentum m_i V_i, row 2i+1 the position p_i."""
    y = np.asarray(y)
    s = np.empty((2 * y.shape[1], 3), dtype=y.dtype)
    s[0::2] = np.asarray(masses)[:, None] * y[1]
    s[1::2] = y[0]
    return s


def from_lecture_state(s, masses) -> np.ndarray:
    """Inverse of :func:`lecture_state`: y = (q, v) from S = (mV, p)."""
    s = np.asarray(s)
    return np.stack([s[1::2], s[0::2] / np.asarray(masses)[:, None]])


def lecture_derivative(model, t, y) -> np.ndarray:
    """dS/dt = (F1, V1, F2, V2, ...), shape (2N, 3), with F the net force."""
    y = np.asarray(y)
    ds = np.empty((2 * y.shape[1], 3), dtype=y.dtype)
    ds[0::2] = model.net_force(t, y[0], y[1])
    ds[1::2] = y[1]
    return ds
