"""The approach speed of two bodies along a contact normal, compiled: its one definition.

v_n = (V_a - V_b) . n, with n pointing from body a to body b: positive while the bodies move
towards each other, the speed the lecture's equation 4 reverses and scales by eps. The same
projection of the relative acceleration is the pressing acceleration of a resting contact. A
static shape is a body b with V_b = 0. Vectors are 3-tuples (:mod:`.sphere_contacts`).
:func:`approach_speeds` is the same kernel on NumPy arrays of vectors, row by row.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .sphere_contacts import dot3, row3, sub3

#: the velocity (and acceleration) of a static shape
AT_REST = (0.0, 0.0, 0.0)


@njit(cache=True, inline="always")
def approach_speed(v_a, v_b, normal):
    """(V_a - V_b) . n: > 0 approaching, < 0 separating (the products added left to right)."""
    return dot3(sub3(v_a, v_b), normal)


@njit(cache=True)
def _approach_speed_rows(v_a, v_b, normal):
    out = np.empty(v_a.shape[0])
    for k in range(v_a.shape[0]):
        out[k] = approach_speed(row3(v_a, k), row3(v_b, k), row3(normal, k))
    return out


def approach_speeds(v_a, v_b, normal):
    """:func:`approach_speed` of arrays of vectors (..., 3), broadcast against each other: shape (...)."""
    v_a, v_b, normal = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (v_a, v_b, normal)))
    rows = [np.array(x.reshape(-1, 3)) for x in (v_a, v_b, normal)]  # writeable copies: one Numba type
    return _approach_speed_rows(*rows).reshape(v_a.shape[:-1])[()]
