"""What a force's Jacobian is made of: one 3x3 block per pair (a pair force) or per body.

Plain data, imported by the forces that describe their Jacobians by blocks (springs,
dampers, drag, central gravity) and by the assembly that adds the blocks up
(:mod:`.sparse_jacobian`, :mod:`.sparse_kernels`); it imports neither, so the forces
and the assembly do not import each other.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class PairJacobian:
    """The Jacobian of a pair force, one 3x3 block per pair.

    Parameters
    ----------
    i, j : int ndarray, shape (P,)
        The two bodies of each pair.
    dq, dv : ndarray, shape (P, 3, 3), or None
        ``d f_i / d q_j`` and ``d f_i / d v_j``; None where identically zero.
    """

    i: np.ndarray
    j: np.ndarray
    dq: np.ndarray | None
    dv: np.ndarray | None


@dataclasses.dataclass(frozen=True)
class BodyJacobian:
    """The Jacobian of a per-body force (F_i depends on q_i, v_i only): one 3x3 block per body.

    Parameters
    ----------
    dq, dv : ndarray, shape (N, 3, 3), or None
        ``d F_i / d q_i`` and ``d F_i / d v_i``; None where identically zero.
    """

    dq: np.ndarray | None
    dv: np.ndarray | None
