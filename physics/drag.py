"""Aerodynamic (quadratic) drag."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._array import block_diagonal, norm
from .force import Force
from .rules import number_problem, require, skip_checks

#: density of air at sea level and 15 C, kg/m^3
AIR_DENSITY = 1.225


@dataclasses.dataclass(frozen=True)
class Drag(Force):
    """Quadratic drag: F = -1/2 rho |V|^2 C_D S_ref V/|V|.

    ``S_ref`` is the cross-section of the bounding sphere, pi r^2. Written as
    ``-beta |V| V`` with ``beta = 1/2 rho C_D S_ref`` the formula has no division, so a
    body at rest (|V| = 0) feels exactly zero drag instead of 0/0.

    Parameters
    ----------
    beta : ndarray, shape (N,)
        1/2 rho C_D S_ref per body, kg/m (zero for bodies the drag does not act on).
    """

    beta: np.ndarray

    name: ClassVar[str] = "drag"

    def __post_init__(self):
        if not skip_checks(self.beta):
            require("Drag: beta", number_problem(self.beta, nonnegative=True))
            if np.ndim(self.beta) != 1:
                raise ValueError(f"Drag: beta must be one value per body, shape (N,), got shape {np.shape(self.beta)}")

    def check_bodies(self, n_bodies: int) -> None:
        if np.shape(self.beta) != (n_bodies,):
            raise ValueError(f"Drag: beta must be one value per body, shape ({n_bodies},), got shape "
                             f"{np.shape(self.beta)}")

    @classmethod
    def from_scene(cls, table, bodies) -> Drag:
        """``[forces.drag]``: ``density`` (kg/m^3, default air), ``drag_coefficient`` (default 0.4)
        and ``bodies`` (default: all)."""
        table.allow("density", "drag_coefficient", "bodies")
        mask = bodies.mask(table, "bodies")
        return cls.from_coefficients(bodies.radii, table.number("density", AIR_DENSITY, positive=True),
                                     table.number("drag_coefficient", 0.4, nonnegative=True), mask)

    @classmethod
    def from_coefficients(cls, radii, density=AIR_DENSITY, drag_coefficient=0.4, mask=None):
        """Drag on spheres of the given radii in a fluid of ``density`` (kg/m^3)."""
        # a scene file's [forces.drag] rules: density > 0, drag_coefficient >= 0; radii as a model's
        require("Drag: density", number_problem(density, positive=True))
        require("Drag: drag_coefficient", number_problem(drag_coefficient, nonnegative=True))
        require("Drag: radii", number_problem(radii, positive=True))
        radii = np.asarray(radii, dtype=float)
        beta = 0.5 * density * drag_coefficient * np.pi * radii**2
        if mask is not None:
            beta = np.where(mask, beta, 0.0)
        return cls(beta=beta)

    def force(self, xp, q, v, m):
        return -(self.beta * norm(xp, v))[:, None] * v

    def jacobian(self, xp, q, v, m):
        return None, block_diagonal(xp, self.jacobian_blocks(xp, q, v, m).dv)

    def jacobian_blocks(self, xp, q, v, m, definite=False):
        """One block per body, d F_i / d v_i = -beta (|v| I + v v^T / |v|): symmetric, negative semidefinite."""
        from .sparse_jacobian import BodyJacobian

        # d(-beta |v| v)/dv = -beta (|v| I + v v^T / |v|), which tends to 0 as v -> 0.
        speed = norm(xp, v)
        vhat_v = xp.where(
            (speed > 0)[:, None, None],
            v[:, :, None] * v[:, None, :] / xp.where(speed > 0, speed, 1)[:, None, None],
            0,
        )
        block = -self.beta[:, None, None] * (speed[:, None, None] * xp.eye(3, dtype=v.dtype) + vhat_v)
        return BodyJacobian(None, block)
