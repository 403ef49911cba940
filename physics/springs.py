"""Linear springs between body pairs (Hooke's law)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from . import attachments
from ._array import inverse_length, norm, rows, safe_unit, scatter_pair_blocks, scatter_pairs
from .force import Force
from .jacobian_blocks import PairJacobian
from .pair_laws import spring_block, spring_potential, spring_tension, spring_transverse
from .rules import require_indices, require_pairs, skip_checks
from .scene_toml import REQUIRED


@dataclasses.dataclass(frozen=True)
class Springs(Force):
    """Hooke springs: F = k (l - l_rest) d on the first body, -F on the second.

    ``d`` is the unit vector from the first body to the second, ``l`` the current length.
    A stretched spring (l > l_rest) pulls the bodies together, a compressed one pushes
    them apart.

    A spring of zero length has no direction: it exerts no force (an unstable
    equilibrium when ``rest_length > 0``) instead of producing a NaN.

    Parameters
    ----------
    i, j : int ndarray, shape (P,)
        The two bodies of each spring.
    stiffness : ndarray, shape (P,)
        k, N/m.
    rest_length : ndarray, shape (P,)
        l_rest, m.
    attachment : physics.attachments.Attachment, optional
        Body-frame points of rotating bodies where the ends act (None: the centres); ``d`` and
        ``l`` are then those of the points.
    """

    i: np.ndarray
    j: np.ndarray
    stiffness: np.ndarray
    rest_length: np.ndarray
    attachment: attachments.Attachment | None = None

    name: ClassVar[str] = "springs"
    array_of_tables: ClassVar[bool] = True

    def __post_init__(self):
        # a scene file's rules: two different bodies, stiffness > 0 (here also 0, and inf: an
        # inextensible constraint, as a soft body's), rest_length >= 0
        if not skip_checks(self.i, self.j, self.stiffness, self.rest_length):
            require_pairs("Springs", self.i, self.j,
                          stiffness=(self.stiffness, {"nonnegative": True, "infinite": True}),
                          rest_length=(self.rest_length, {"nonnegative": True}))

    def check_bodies(self, n_bodies: int) -> None:
        require_indices("Springs", self.i, n_bodies)
        require_indices("Springs", self.j, n_bodies)

    @classmethod
    def from_scene(cls, tables, bodies) -> Springs:
        """``[[forces.springs]]``: ``bodies = ["a", "b"]``, ``stiffness`` (N/m), ``rest_length``
        (m; default: the initial distance, so the spring starts relaxed) and ``offsets``
        (body-frame points of the two ends, m, on rotating bodies: :mod:`.attachments`)."""
        for s in tables:
            s.allow("bodies", "stiffness", "rest_length", "offsets")
        pairs = [bodies.pair(s) for s in tables]
        offsets = attachments.read_offsets(tables, bodies, pairs)
        k = [s.number("stiffness", REQUIRED, positive=True) for s in tables]
        rest = [s.number("rest_length", attachments.point_distance(offsets, n, pair, bodies), nonnegative=True)
                for n, (s, pair) in enumerate(zip(tables, pairs))]
        i, j = np.array([a for a, _ in pairs]), np.array([b for _, b in pairs])
        springs = cls(i, j, np.array(k), np.array(rest), attachments.initial_attachment(offsets, i, j, bodies))
        springs._refuse_no_direction(tables, bodies)
        return springs

    def _refuse_no_direction(self, tables, bodies) -> None:
        """A spring with rest_length > 0 whose ends start at one point (its length, as the model computes
        it, 0: equal points, or points so close that the squared distance underflows) has no direction:
        it exerts no force there (an unstable equilibrium, held for ever) and its stiffness across the
        pair, -k (L / l - 1), has no bound, so no stable dt can be predicted. Refused at its table."""
        q = np.asarray(bodies.positions, dtype=float)
        delta = q[self.j] - q[self.i]
        if self.attachment is not None:
            delta = delta + (self.attachment.arms[:, 1] - self.attachment.arms[:, 0])
        _, length = self._geometry(np, q)
        for n in np.flatnonzero((length == 0) & (self.rest_length > 0)):
            a, b = (bodies.names[int(k)] for k in (self.i[n], self.j[n]))
            points = "ends (at their offsets)" if self.attachment is not None else "ends"
            apart = float(np.max(np.abs(delta[n])))
            where = (f"start {apart:.3g} m apart, too close for their distance to be computed (its square "
                     "underflows to 0)" if apart > 0 else "start at the same point")
            tables[n].fail(f"the spring's {points}, bodies {a!r} and {b!r}, {where}, so it has no direction, and "
                           f"rest_length = {self.rest_length[n]:g} m > 0 would push them apart along none (its "
                           "stiffness across them is unbounded): place the ends apart, or give rest_length = 0")

    def _geometry(self, xp, q):
        delta = rows(xp, q, self.j) - rows(xp, q, self.i)
        if self.attachment is not None:  # between the points: x_j + R_j r_j - (x_i + R_i r_i)
            delta = delta + (self.attachment.arms[:, 1] - self.attachment.arms[:, 0])
        length = norm(xp, delta)
        return safe_unit(xp, delta, length), length

    def pair_force(self, xp, q, v):
        """The force on each spring's first end, (P, 3), N (the second gets minus it)."""
        d, length = self._geometry(xp, q)
        return spring_tension(self.stiffness, length, self.rest_length)[:, None] * d

    def force(self, xp, q, v, m):
        return scatter_pairs(xp, q.shape[0], self.i, self.j, self.pair_force(xp, q, v))

    def jacobian(self, xp, q, v, m):
        return scatter_pair_blocks(xp, q.shape[0], self.i, self.j, self.jacobian_blocks(xp, q, v, m).dq), None

    def jacobian_blocks(self, xp, q, v, m, definite=False):
        """One block per spring, B = d f_i / d q_j = k [d d^T + (1 - L / l) (I - d d^T)], symmetric.

        With ``definite``, a compressed spring's transverse term, negative where
        l < L (a compressed spring buckles sideways), is left out, so that every block is
        positive semidefinite (Choi and Ko, "Stable but responsive cloth", 2002). The laws:
        :mod:`.pair_laws`.
        """
        d, length = self._geometry(xp, q)
        transverse = spring_transverse(self.rest_length, inverse_length(xp, length))
        if definite:
            transverse = xp.maximum(transverse, 0)
        axial, across = spring_block(self.stiffness, transverse, 1.0)
        ddT = d[:, :, None] * d[:, None, :]
        block = axial[:, None, None] * ddT + across[:, None, None] * xp.eye(3, dtype=q.dtype)
        return PairJacobian(self.i, self.j, block, None)

    def potential(self, xp, q, m):
        _, length = self._geometry(xp, q)
        return xp.sum(spring_potential(self.stiffness, length, self.rest_length))
