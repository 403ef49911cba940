"""Aerodynamic (quadratic) drag."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._array import block_diagonal, norm, speed
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
        density = table.number("density", AIR_DENSITY, positive=True)
        drag_coefficient = table.number("drag_coefficient", 0.4, nonnegative=True)
        beta = _beta(bodies.radii, density, drag_coefficient, mask)
        problem = _beta_problem(beta, bodies.radii, density, drag_coefficient, bodies.names)
        if problem:
            table.fail(problem)
        return cls(beta=beta)

    @classmethod
    def from_coefficients(cls, radii, density=AIR_DENSITY, drag_coefficient=0.4, mask=None):
        """Drag on spheres of the given radii in a fluid of ``density`` (kg/m^3)."""
        # a scene file's [forces.drag] rules: density > 0, drag_coefficient >= 0; radii as a model's
        require("Drag: density", number_problem(density, positive=True))
        require("Drag: drag_coefficient", number_problem(drag_coefficient, nonnegative=True))
        require("Drag: radii", number_problem(radii, positive=True))
        radii = np.asarray(radii, dtype=float)
        beta = _beta(radii, density, drag_coefficient, mask)
        require("Drag", _beta_problem(beta, radii, density, drag_coefficient))
        return cls(beta=beta)

    def force(self, xp, q, v, m):
        return -(self.beta * speed(xp, v))[:, None] * v

    def jacobian(self, xp, q, v, m):
        return None, block_diagonal(xp, self.jacobian_blocks(xp, q, v, m).dv)

    def jacobian_blocks(self, xp, q, v, m, definite=False):
        """One block per body, d F_i / d v_i = -beta (|v| I + v v^T / |v|): symmetric, negative semidefinite."""
        from .sparse_jacobian import BodyJacobian

        # d(-beta |v| v)/dv = -beta (|v| I + v v^T / |v|), which tends to 0 as v -> 0.
        v_norm = norm(xp, v)
        vhat_v = xp.where(
            (v_norm > 0)[:, None, None],
            v[:, :, None] * v[:, None, :] / xp.where(v_norm > 0, v_norm, 1)[:, None, None],
            0,
        )
        block = -self.beta[:, None, None] * (v_norm[:, None, None] * xp.eye(3, dtype=v.dtype) + vhat_v)
        return BodyJacobian(None, block)


def _beta(radii, density, drag_coefficient, mask):
    """beta = 1/2 rho C_D pi r^2 per body (0 where ``mask`` is False, and where rho C_D is 0 however
    large r: 0 x inf would be NaN)."""
    coefficient = 0.5 * density * drag_coefficient * np.pi
    with np.errstate(over="ignore", invalid="ignore"):
        beta = np.where(coefficient == 0, 0.0, coefficient * np.asarray(radii, dtype=float)**2)
    return beta if mask is None else np.where(mask, beta, 0.0)


def _beta_problem(beta, radii, density, drag_coefficient, names=None) -> str | None:
    """Why beta cannot be drag's factor: it overflowed (a radius of 1e300 m squares to inf), or None."""
    bad = ~np.isfinite(beta)
    if not np.any(bad):
        return None
    k = int(np.argmax(bad))
    body = f"body {names[k]!r}" if names is not None else f"body {k}"
    return (f"the drag factor 1/2 rho C_D pi r^2 of {body} (radius {float(radii[k]):g} m, density {float(density):g} "
            f"kg/m^3, drag_coefficient {float(drag_coefficient):g}) is {float(beta[k])} kg/m, beyond float64: "
            "a smaller radius, density or drag_coefficient")
