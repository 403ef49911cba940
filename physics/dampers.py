"""Viscous dampers (dashpots) acting along the axis between two bodies."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from . import attachments
from ._array import dot, inverse_length, norm, rows, safe_unit, scatter_pair_blocks, scatter_pairs
from .force import Force
from .jacobian_blocks import PairJacobian
from .pair_laws import damper_position_block, damper_tension, damper_velocity_block
from .rules import require_indices, require_pairs, skip_checks
from .scene_toml import REQUIRED


@dataclasses.dataclass(frozen=True)
class Dampers(Force):
    """Dampers: F = c ((V_2 - V_1) . d) d on the first body, -F on the second.

    Only the relative velocity along the axis ``d`` (unit vector from body 1 to body 2)
    is resisted: if body 2 moves away, body 1 is drawn after it. Dissipative, so no
    potential. Coincident bodies have no axis and feel no damping force.

    Parameters
    ----------
    i, j : int ndarray, shape (P,)
    damping : ndarray, shape (P,)
        c, N s/m.
    attachment : physics.attachments.Attachment, optional
        Body-frame points of rotating bodies where the ends act (None: the centres); ``d`` and
        the relative velocity are then those of the points.
    """

    i: np.ndarray
    j: np.ndarray
    damping: np.ndarray
    attachment: attachments.Attachment | None = None

    name: ClassVar[str] = "dampers"
    array_of_tables: ClassVar[bool] = True

    def __post_init__(self):
        if not skip_checks(self.i, self.j, self.damping):  # a scene file's rules: two different bodies, damping >= 0
            require_pairs("Dampers", self.i, self.j, damping=(self.damping, {"nonnegative": True}))

    def check_bodies(self, n_bodies: int) -> None:
        require_indices("Dampers", self.i, n_bodies)
        require_indices("Dampers", self.j, n_bodies)

    @classmethod
    def from_scene(cls, tables, bodies) -> Dampers:
        """``[[forces.dampers]]``: ``bodies = ["a", "b"]``, ``damping`` (N s/m) and ``offsets``
        (body-frame points of the two ends, m, on rotating bodies: :mod:`.attachments`)."""
        for d in tables:
            d.allow("bodies", "damping", "offsets")
        pairs = [bodies.pair(d) for d in tables]
        offsets = attachments.read_offsets(tables, bodies, pairs)
        c = [d.number("damping", REQUIRED, nonnegative=True) for d in tables]
        i, j = np.array([a for a, _ in pairs]), np.array([b for _, b in pairs])
        return cls(i, j, np.array(c), attachments.initial_attachment(offsets, i, j, bodies))

    def _terms(self, xp, q, v):
        delta = rows(xp, q, self.j) - rows(xp, q, self.i)
        u = rows(xp, v, self.j) - rows(xp, v, self.i)
        if self.attachment is not None:  # between the points, which move with v + omega x R r
            delta = delta + (self.attachment.arms[:, 1] - self.attachment.arms[:, 0])
            u = u + (self.attachment.velocities[:, 1] - self.attachment.velocities[:, 0])
        length = norm(xp, delta)
        d = safe_unit(xp, delta, length)
        return d, length, u

    def pair_force(self, xp, q, v):
        """The force on each damper's first end, (P, 3), N (the second gets minus it)."""
        d, _, u = self._terms(xp, q, v)
        return damper_tension(self.damping, dot(xp, u, d))[:, None] * d

    def force(self, xp, q, v, m):
        return scatter_pairs(xp, q.shape[0], self.i, self.j, self.pair_force(xp, q, v))

    def jacobian(self, xp, q, v, m):
        blocks, n = self.jacobian_blocks(xp, q, v, m), q.shape[0]
        return (scatter_pair_blocks(xp, n, self.i, self.j, blocks.dq),
                scatter_pair_blocks(xp, n, self.i, self.j, blocks.dv))

    def jacobian_blocks(self, xp, q, v, m, definite=False):
        """One block per damper: d f_i / d v_j = c d d^T and d f_i / d q_j = c [(d . u) P + d u^T P] / l.

        ``u`` is the relative velocity, P = I - d d^T (the laws: :mod:`.pair_laws`). With
        ``definite``, the position block (not symmetric, and indefinite) is left out, as Baraff
        and Witkin do with their damping forces (1998, section 5).
        """
        d, length, u = self._terms(xp, q, v)
        ddT = d[:, :, None] * d[:, None, :]
        dv_block = damper_velocity_block(self.damping, 1.0)[:, None, None] * ddT
        if definite:
            return PairJacobian(self.i, self.j, None, dv_block)
        e, b = damper_position_block(self.damping, inverse_length(xp, length), dot(xp, u, d), 1.0)
        proj = xp.eye(3, dtype=q.dtype) - ddT
        w = (u[:, None, :] @ proj)[:, 0]  # P u, the relative velocity across the pair
        dq_block = b[:, None, None] * proj + e[:, None, None] * (d[:, :, None] * w[:, None, :])
        return PairJacobian(self.i, self.j, dq_block, dv_block)
