"""A constant applied force: a steady wind, a thrust, a push."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .force import Force
from .rules import number_problem, require, skip_checks
from .scene_toml import REQUIRED


@dataclasses.dataclass(frozen=True)
class ConstantForce(Force):
    """A force F_i on each body that never changes: a steady wind, a thrust.

    Independent of state and time, so its Jacobian is zero and, like gravity, the model
    folds it into one constant acceleration field F_i / m_i (the ``exact`` integrator's
    closed form p0 + v0 t + F/(2m) t^2 then covers it). It is conservative: F = -grad U
    with U = -sum_i F_i . q_i, so energy studies see the work it does.

    Parameters
    ----------
    f : ndarray, shape (N, 3)
        The force on each body, N (zero on the bodies it does not act on).
    """

    f: np.ndarray

    name: ClassVar[str] = "constant"
    constant: ClassVar[bool] = True
    array_of_tables: ClassVar[bool] = True

    def __post_init__(self):
        if not skip_checks(self.f):  # a scene file's rule: finite forces, one [x, y, z] a body
            require("ConstantForce: f", number_problem(self.f))
            if np.ndim(self.f) != 2 or np.shape(self.f)[1] != 3:
                raise ValueError(f"ConstantForce: f must be one force [x, y, z] a body, shape (N, 3), got shape "
                                 f"{np.shape(self.f)}")

    def check_bodies(self, n_bodies: int) -> None:
        if np.shape(self.f)[0] != n_bodies:
            raise ValueError(f"ConstantForce: f must be one force a body, shape ({n_bodies}, 3), got shape "
                             f"{np.shape(self.f)}")

    @classmethod
    def from_scene(cls, tables, bodies) -> ConstantForce:
        """``[[forces.constant]]``: ``force = [x, y, z]`` (N) on each of ``bodies`` (default: all).

        The elements add up: a wind on every body plus a thrust on one is two elements.
        """
        f = np.zeros((bodies.n, 3))
        for t in tables:
            t.allow("force", "bodies")
            force = t.vector("force", REQUIRED)
            chosen = bodies.indices(t, "bodies", required=False)
            f[slice(None) if chosen is None else chosen] += force
            if not np.all(np.isfinite(f)):  # two elements of 1e308 N on one body
                t.fail("the constant forces on a body add up to more than the largest float", "force")
        return cls(f)

    def force(self, xp, q, v, m):
        # a read-only view: no caller can change the force by writing into the result
        return xp.broadcast_to(self.f, q.shape)

    def jacobian(self, xp, q, v, m):
        # dF/dq = dF/dv = 0
        return None, None

    def potential(self, xp, q, m):
        # F = -grad U with U = -sum_i F_i . q_i
        return -xp.sum(self.f * q)
