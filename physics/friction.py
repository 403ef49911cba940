"""Ground contact with Coulomb friction against a plane."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._array import norm, safe_unit
from .force import Force
from .rules import direction, friction_problem, number_problem, require, skip_checks
from .scene_toml import REQUIRED

#: a body whose surface is within this distance of the plane touches it, m
CONTACT_DISTANCE = 1e-6
#: tangential speeds below this count as "at rest" for static friction, m/s
REST_SPEED = 1e-6


@dataclasses.dataclass(frozen=True)
class Friction(Force):
    """The ground plane's reaction on bodies resting on it: normal support plus friction.

    A body touches the plane ``n . q = height`` when its surface is within
    ``CONTACT_DISTANCE`` of it. Let F be the sum of the other forces on the body and
    split it into normal and tangential parts, F_n = (F . n) n and F_t = F - F_n.
    When F presses into the plane the plane pushes back with -F_n, and Coulomb friction
    acts in the plane:

    - at rest (|V_t| <= REST_SPEED): F_friction = -F_t/|F_t| min(mu_s |F_n|, |F_t|), which
      cancels F_t exactly while it is below the static limit (zero when F_t = 0);
    - sliding: F_friction = -V_t/|V_t| mu_d |F_n|, against the tangential velocity.

    Bodies off the plane, or pulled away from it, feel nothing. This force is
    *reactive*: it is evaluated after all the others.

    Parameters
    ----------
    mu_static, mu_dynamic : float
        Coulomb coefficients, 0 <= mu_dynamic <= mu_static.
    normal : ndarray, shape (3,)
        Unit normal of the plane, pointing out of the ground.
    height : float
        Plane offset along the normal, m.
    radii : ndarray, shape (N,)
    """

    mu_static: float
    mu_dynamic: float
    normal: np.ndarray
    height: float
    radii: np.ndarray

    name: ClassVar[str] = "friction"
    reactive: ClassVar[bool] = True

    def __post_init__(self):
        if skip_checks(self.mu_static, self.mu_dynamic, self.normal, self.height, self.radii):
            return
        # a scene file's [forces.friction] rules: 0 <= mu_dynamic <= mu_static; the normal normalised
        # (a unit one kept to the byte), not zero; height finite
        require("Friction: mu_static", number_problem(self.mu_static, nonnegative=True))
        require("Friction: mu_dynamic", number_problem(self.mu_dynamic, nonnegative=True))
        require("Friction: mu_dynamic", friction_problem(self.mu_static, self.mu_dynamic))
        object.__setattr__(self, "normal", direction("Friction: normal", self.normal))
        require("Friction: height", number_problem(self.height))
        require("Friction: radii", number_problem(self.radii, positive=True))

    def check_bodies(self, n_bodies: int) -> None:
        if np.shape(self.radii) != (n_bodies,):
            raise ValueError(f"Friction: radii must be one per body, shape ({n_bodies},), got shape "
                             f"{np.shape(self.radii)}")

    @classmethod
    def from_scene(cls, table, bodies) -> Friction:
        """``[forces.friction]``: ``mu_static``, ``mu_dynamic``, the plane's ``normal`` (default +z)
        and ``height`` (default 0)."""
        table.allow("mu_static", "mu_dynamic", "height", "normal")
        normal = table.direction("normal", [0, 0, 1])
        mu_s = table.number("mu_static", REQUIRED, nonnegative=True)
        mu_d = table.number("mu_dynamic", REQUIRED, nonnegative=True)
        problem = friction_problem(mu_s, mu_d)
        if problem:
            table.fail(problem, "mu_dynamic")
        return cls(mu_s, mu_d, normal, table.number("height", 0.0), np.array(bodies.radii))

    def force(self, xp, q, v, m, applied):
        n = self.normal
        gap = q @ n - self.height - self.radii
        f_n = applied @ n
        # only bodies touching the plane and pressed into it get a reaction
        pressed = (gap <= CONTACT_DISTANCE) & (f_n < 0)
        support = -f_n[:, None] * n
        f_t = applied - f_n[:, None] * n
        v_t = v - (v @ n)[:, None] * n
        load = -f_n  # |F_n| where pressed

        ft_len = norm(xp, f_t)
        static = -safe_unit(xp, f_t, ft_len) * xp.minimum(self.mu_static * load, ft_len)[:, None]
        vt_len = norm(xp, v_t)
        dynamic = -safe_unit(xp, v_t, vt_len) * (self.mu_dynamic * load)[:, None]
        friction = xp.where((vt_len <= REST_SPEED)[:, None], static, dynamic)
        return xp.where(pressed[:, None], support + friction, 0)
