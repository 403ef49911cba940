"""The approach speed of two bodies along a contact normal, compiled: its one definition.

v_n = (V_a - V_b) . n, with n pointing from body a to body b: positive while the bodies move
towards each other, the speed the lecture's equation 4 reverses and scales by eps. The same
projection of the relative acceleration is the pressing acceleration of a resting contact. A
static shape is a body b with V_b = 0. Vectors are 3-tuples (:mod:`.sphere_contacts`).
"""

from __future__ import annotations

from numba import njit

from .sphere_contacts import dot3, sub3

#: the velocity (and acceleration) of a static shape
AT_REST = (0.0, 0.0, 0.0)


@njit(cache=True, inline="always")
def approach_speed(v_a, v_b, normal):
    """(V_a - V_b) . n: > 0 approaching, < 0 separating (the products added left to right)."""
    return dot3(sub3(v_a, v_b), normal)
