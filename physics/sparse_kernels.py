"""Compiled springs and dampers for implicit Euler: their forces and Newton blocks in one pass.

Every Newton iteration of implicit Euler's conjugate-gradient step needs, at the same
state (q1, v1), the acceleration (for the residual) and the symmetric (or definite)
part of the springs' and dampers' Jacobians, added into the Newton matrix with the
coefficients -h^2 (positions) and -h (velocities) (:func:`.sparse_jacobian.newton_system`).
Through NumPy that is 12 ms for the forces of the bench's 101,442 springs and dampers and
a dozen (P, 3, 3) temporaries per force for the blocks (:meth:`Springs.jacobian_blocks`,
25 ms); here one loop over the pairs computes each pair's separation, length and
direction once and from them its force and its 3x3 block, added where they go
(2.5 ms for both; 0.9 ms for the forces alone, without the blocks' 27 scattered
additions per pair). The kernel evaluates the laws the NumPy forces evaluate, compiled
(:mod:`.pair_laws`); ``tests/test_implicit_sparse.py`` holds it equal to the NumPy forces
and blocks.

Springs and dampers on the same pairs (a cloth's, from :func:`.soft_body.connect`) are
one group and share the pass; a spring or damper force alone is a group of its own.
A group adds ``sign S`` to ``data[slot]`` for the pair's three blocks (``slots[p]``:
the pair's stored block with +, (i, i) and (j, j) with -, -1 where the block is not in
the matrix), as :func:`.sparse_jacobian._add_symmetric_pair_blocks` does.
"""

from __future__ import annotations

import dataclasses
import weakref
from typing import NamedTuple

import numpy as np
from numba import njit

from . import pair_laws
from .dampers import Dampers
from .springs import Springs

_spring_tension = pair_laws.compiled(pair_laws.spring_tension)
_spring_transverse = pair_laws.compiled(pair_laws.spring_transverse)
_spring_block = pair_laws.compiled(pair_laws.spring_block)
_damper_tension = pair_laws.compiled(pair_laws.damper_tension)
_damper_velocity_block = pair_laws.compiled(pair_laws.damper_velocity_block)
_damper_position_block = pair_laws.compiled(pair_laws.damper_position_block)


class PairColumns(NamedTuple):
    """A group's pairs (P,) and their springs' and dampers' constants (size 0: none of that kind)."""

    i: np.ndarray
    j: np.ndarray
    stiffness: np.ndarray  # k, N/m
    rest_length: np.ndarray  # L, m
    damping: np.ndarray  # c, N s/m


class NewtonTerms(NamedTuple):
    """What one pass adds: the blocks' coefficients in the Newton matrix, and which parts."""

    coefficient_q: float  # of the position blocks (-h^2)
    coefficient_v: float  # of the velocity blocks (-h)
    definite: bool  # the positive semidefinite parts only
    with_force: bool
    with_blocks: bool


@njit(cache=True, inline="always")
def _add(data, slots, p, s):  # pragma: no cover - compiled
    # the symmetric block S (its six entries s = (s00, s11, s22, s01, s02, s12)): +S at the
    # pair's stored block, -S at (i, i) and (j, j); a slot of -1 is a block outside the matrix
    s00, s11, s22, s01, s02, s12 = s
    for k in range(3):
        slot = slots[p, k]
        if slot < 0:
            continue
        sign = 1.0 if k == 0 else -1.0
        block = data[slot]
        block[0, 0] += sign * s00
        block[1, 1] += sign * s11
        block[2, 2] += sign * s22
        block[0, 1] += sign * s01
        block[1, 0] += sign * s01
        block[0, 2] += sign * s02
        block[2, 0] += sign * s02
        block[1, 2] += sign * s12
        block[2, 1] += sign * s12


@njit(cache=True)
def _pair_system(pairs, q, v, terms, force, data, slots):  # pragma: no cover - compiled
    # Springs where stiffness is given (size > 0), dampers where damping is (the laws: pair_laws).
    # With d the unit vector from i to j, l the length, u = v_j - v_i:
    #   force on i (-it on j): [k (l - L) + c (d . u)] d
    #   spring block d f_i / d q_j = k [d d^T + t (I - d d^T)], t = 1 - L / l (definite: t >= 0)
    #   damper blocks: d f_i / d v_j = c d d^T, and the symmetric part of d f_i / d q_j,
    #   c [(d . u) (I - d d^T) + (d w^T + w d^T) / 2] / l with w = u - (d . u) d (definite: none)
    # all in one symmetric S = a d d^T + b I + e (d w^T + w d^T) / 2.
    i, j, stiffness, rest_length, damping = pairs
    coefficient_q, coefficient_v, definite, with_force, with_blocks = terms
    springs, dampers = stiffness.size > 0, damping.size > 0
    for p in range(i.size):
        bi, bj = i[p], j[p]
        d0, d1, d2 = q[bj, 0] - q[bi, 0], q[bj, 1] - q[bi, 1], q[bj, 2] - q[bi, 2]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        # at l = 0 (no direction) 1 / l is taken as 0: d = 0, so no force, a spring's block
        # k I (t = 1) and a damper's zero, as the forces define them (one path, no branch:
        # a second one doubles the kernel's time)
        inverse_length = 1.0 / length if length > 0 else 0.0
        d0, d1, d2 = d0 * inverse_length, d1 * inverse_length, d2 * inverse_length
        s = a = b = e = 0.0
        w0 = w1 = w2 = 0.0
        if springs:
            s += _spring_tension(stiffness[p], length, rest_length[p])
            t = _spring_transverse(rest_length[p], inverse_length)
            if definite and t < 0:
                t = 0.0
            axial, across = _spring_block(stiffness[p], t, coefficient_q)
            a += axial
            b += across
        if dampers:
            u0, u1, u2 = v[bj, 0] - v[bi, 0], v[bj, 1] - v[bi, 1], v[bj, 2] - v[bi, 2]
            du = d0 * u0 + d1 * u1 + d2 * u2
            s += _damper_tension(damping[p], du)
            a += _damper_velocity_block(damping[p], coefficient_v)
            if not definite:
                e, along = _damper_position_block(damping[p], inverse_length, du, coefficient_q)
                a -= along
                b += along
                w0, w1, w2 = u0 - du * d0, u1 - du * d1, u2 - du * d2
        if with_force:
            force[bi, 0] += s * d0
            force[bi, 1] += s * d1
            force[bi, 2] += s * d2
            force[bj, 0] -= s * d0
            force[bj, 1] -= s * d1
            force[bj, 2] -= s * d2
        if not with_blocks:
            continue
        _add(data, slots, p, (a * d0 * d0 + b + e * d0 * w0, a * d1 * d1 + b + e * d1 * w1,
                              a * d2 * d2 + b + e * d2 * w2, a * d0 * d1 + 0.5 * e * (d0 * w1 + w0 * d1),
                              a * d0 * d2 + 0.5 * e * (d0 * w2 + w0 * d2), a * d1 * d2 + 0.5 * e * (d1 * w2 + w1 * d2)))


_NONE = np.zeros(0)
_NO_BLOCKS = np.zeros((0, 3, 3))
_NO_SLOTS = np.zeros((0, 3), np.int64)


@dataclasses.dataclass(frozen=True, eq=False)
class PairGroup:
    """Springs and/or dampers on the same pairs, whose forces and blocks one kernel pass adds."""

    springs: Springs | None
    dampers: Dampers | None

    @property
    def i(self):
        return (self.springs or self.dampers).i

    @property
    def j(self):
        return (self.springs or self.dampers).j

    @property
    def columns(self) -> PairColumns:
        springs, dampers = self.springs, self.dampers
        return PairColumns(np.asarray(self.i), np.asarray(self.j),
                           _NONE if springs is None else np.asarray(springs.stiffness, float),
                           _NONE if springs is None else np.asarray(springs.rest_length, float),
                           _NONE if dampers is None else np.asarray(dampers.damping, float))

    def add(self, force, data, slots, q, v, terms: NewtonTerms) -> None:
        """Add the group's Newton blocks into ``data`` and, ``terms.with_force``, its forces into ``force`` (N, 3)."""
        _pair_system(self.columns, q, v, terms, force, data, slots)

    def add_forces(self, force, q, v) -> None:
        """Add the group's forces into ``force`` (N, 3), without any blocks."""
        _pair_system(self.columns, q, v, NewtonTerms(0.0, 0.0, False, True, False), force, _NO_BLOCKS, _NO_SLOTS)


def has_kernel(force) -> bool:
    """Whether ``force`` (exactly a Springs or a Dampers, not a subclass, between centres) has a compiled kernel here.

    Forces attached at body-frame points (:mod:`.attachments`) go through their NumPy blocks.
    """
    return type(force) in (Springs, Dampers) and force.attachment is None


#: each model's groups, found on first use: {model: tuple of PairGroup}
_GROUPS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def pair_groups(model) -> tuple[PairGroup, ...]:
    """``model``'s springs and dampers as groups: each damper force with the first spring force on the same pairs.

    Only forces with a kernel (:func:`has_kernel`); a force without a partner is a group alone.
    """
    if model not in _GROUPS:
        springs = [f for f in model.forces if type(f) is Springs and has_kernel(f)]
        dampers = [f for f in model.forces if type(f) is Dampers and has_kernel(f)]
        groups = []
        for s in springs:
            partner = next((d for d in dampers if np.array_equal(d.i, s.i) and np.array_equal(d.j, s.j)), None)
            if partner is not None:  # by identity: the forces' == compares arrays
                dampers = [d for d in dampers if d is not partner]
            groups.append(PairGroup(s, partner))
        groups.extend(PairGroup(None, d) for d in dampers)
        _GROUPS[model] = tuple(groups)
    return _GROUPS[model]
