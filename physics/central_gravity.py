"""Newtonian gravity of a fixed point mass: the Kepler problem."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._array import block_diagonal, norm
from .force import Force
from .rules import number_problem, require, skip_checks, vector_problem
from .scene_toml import REQUIRED


@dataclasses.dataclass(frozen=True)
class CentralGravity(Force):
    """Attraction towards a fixed point mass: F = -mu m r / |r|^3, r = q - center.

    ``mu = G M`` is the standard gravitational parameter of the attracting mass (which
    does not move: the bodies are test masses). Orbits are the conic sections of
    Kepler's problem, with energy E = m |v|^2 / 2 - mu m / |r| and angular momentum
    conserved exactly, which makes it the classic long-run test of an integrator.

    A body exactly at the centre (|r| = 0) feels no force rather than a NaN: the
    singularity has no direction.

    Parameters
    ----------
    mu : float
        G M, m^3/s^2.
    center : ndarray, shape (3,)
        Position of the attracting mass, m.
    """

    mu: np.ndarray
    center: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))

    name: ClassVar[str] = "central_gravity"

    @classmethod
    def from_scene(cls, table, bodies) -> CentralGravity:
        """``[forces.central_gravity]`` with ``mu`` (m^3/s^2) and ``center`` (default the origin)."""
        table.allow("mu", "center")
        return cls(table.number("mu", REQUIRED, positive=True), table.vector("center", [0.0, 0.0, 0.0]))

    def __post_init__(self):
        if not skip_checks(self.mu, self.center):  # a scene file's rules: mu > 0, the center 3 finite numbers
            require("CentralGravity: mu", number_problem(self.mu, positive=True))
            require("CentralGravity: center", vector_problem(self.center))
        for field in ("mu", "center"):  # plain numbers become arrays, so cast() changes their precision
            if not hasattr(getattr(self, field), "dtype"):
                object.__setattr__(self, field, np.asarray(getattr(self, field), dtype=float))

    def _geometry(self, xp, q):
        r = q - self.center
        length = norm(xp, r)
        inverse = xp.where(length > 0, 1 / xp.where(length > 0, length, 1), 0)
        return r, inverse

    def force(self, xp, q, v, m):
        r, inverse = self._geometry(xp, q)
        return -(self.mu * m * inverse**3)[:, None] * r

    def jacobian(self, xp, q, v, m):
        return block_diagonal(xp, self.jacobian_blocks(xp, q, v, m).dq), None

    def jacobian_blocks(self, xp, q, v, m, definite=False):
        """One block per body, d F_i / d q_i = -mu m (I - 3 rhat rhat^T) / |r|^3, symmetric.

        With ``definite``, its radial eigenvalue, +2 mu m / |r|^3 (the tide
        that pulls a body off a circular orbit) is left out: -mu m (I - rhat rhat^T) / |r|^3.
        """
        from .sparse_jacobian import BodyJacobian

        # d(-mu m r / |r|^3)/dr = -mu m (I - 3 rhat rhat^T) / |r|^3 (the tidal tensor)
        r, inverse = self._geometry(xp, q)
        rhat = r * inverse[:, None]
        weight = 1.0 if definite else 3.0  # the radial eigenvalue is -mu m (1 - weight) / |r|^3
        radial = weight * rhat[:, :, None] * rhat[:, None, :]
        block = -(self.mu * m * inverse**3)[:, None, None] * (xp.eye(3, dtype=q.dtype) - radial)
        return BodyJacobian(block, None)

    def potential(self, xp, q, m):
        # F = -grad U with U = -mu m / |r|
        _, inverse = self._geometry(xp, q)
        return -xp.sum(self.mu * m * inverse)


def kepler_orbit(t, q_init, v_init, mu, t_init=0.0, center=(0.0, 0.0, 0.0)):
    """Position and velocity on a bound Kepler orbit at time(s) ``t``, exactly.

    The orbit's elements come from the initial state: semi-major axis a from the energy
    (vis-viva, 1/a = 2/|r| - |v|^2/mu), the eccentricity vector e = v x h / mu - r/|r|,
    and the plane from h = r x v. Kepler's equation M = E - e sin E is solved for the
    eccentric anomaly by Newton's method to round-off; then, with n = sqrt(mu / a^3),
    r = a (cos E - e) P + b sin E Q,  v = n a / (1 - e cos E) (-sin E P + sqrt(1 - e^2) cos E Q).

    Raises ValueError for an unbound (parabolic or hyperbolic) or degenerate (radial or
    circular, whose periapsis direction is undefined) orbit.
    """
    r0 = np.asarray(q_init, dtype=float) - np.asarray(center, dtype=float)
    v0 = np.asarray(v_init, dtype=float)
    h = np.cross(r0, v0)
    inverse_a = 2 / np.linalg.norm(r0) - v0 @ v0 / mu
    e_vector = np.cross(v0, h) / mu - r0 / np.linalg.norm(r0)
    e = np.linalg.norm(e_vector)
    if inverse_a <= 0 or not 1e-8 < e < 1 or np.linalg.norm(h) == 0:
        raise ValueError(f"kepler_orbit needs a bound, non-circular, non-radial orbit (1/a = {inverse_a:g}, e = {e:g})")
    a, n = 1 / inverse_a, np.sqrt(mu * inverse_a**3)
    p_hat = e_vector / e
    q_hat = np.cross(h / np.linalg.norm(h), p_hat)
    # initial eccentric anomaly: r = a (1 - e cos E); r . v > 0 while moving away from periapsis
    cos_e0 = np.clip((1 - np.linalg.norm(r0) / a) / e, -1, 1)
    e0 = np.arccos(cos_e0) * (1 if r0 @ v0 >= 0 else -1)
    mean = e0 - e * np.sin(e0) + n * (np.asarray(t, dtype=float) - t_init)
    anomaly = mean + e * np.sin(mean)  # Newton from a start that converges for all e < 1
    for _ in range(50):
        correction = (anomaly - e * np.sin(anomaly) - mean) / (1 - e * np.cos(anomaly))
        anomaly = anomaly - correction
        if np.all(np.abs(correction) < 1e-15 * np.maximum(1, np.abs(mean))):
            break
    cos_e, sin_e = np.cos(anomaly)[..., None], np.sin(anomaly)[..., None]
    b = a * np.sqrt(1 - e**2)
    q = np.asarray(center, dtype=float) + a * (cos_e - e) * p_hat + b * sin_e * q_hat
    v = n * a / (1 - e * cos_e) * (-sin_e * p_hat + np.sqrt(1 - e**2) * cos_e * q_hat)
    return q, v
