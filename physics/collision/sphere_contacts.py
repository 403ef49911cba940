"""The sphere's contacts and times of impact, compiled: the one definition of each formula.

Box2D keeps one ``b2CollideCircles`` and MuJoCo one ``mjc_SphereSphere``, called from
everywhere; here each formula below is written once, as a Numba kernel on one pair, and
every path calls it: the narrow phase's NumPy tests (through the ``*_rows`` kernels), the
contact solver's contact buffer (:mod:`.contact_buffer`), the event loop's re-test
(:mod:`.retest`) and its compiled response (:mod:`.compiled_response`). Vectors are
3-tuples of floats, which Numba keeps in registers. The kernels are compiled without
``fastmath``: the order of operations is the order written, so every path gets the same
numbers bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def dot3(x, y):
    """x . y, added left to right as NumPy's ``(x * y).sum(axis=-1)`` adds three products."""
    return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]


@njit(cache=True, inline="always")
def sub3(x, y):
    """x - y, component by component."""
    return x[0] - y[0], x[1] - y[1], x[2] - y[2]


@njit(cache=True, inline="always")
def row3(x, k):
    """Row k of an (N, 3) array as a 3-tuple, the vectors of these kernels."""
    return x[k, 0], x[k, 1], x[k, 2]


@njit(cache=True, inline="always")
def row3_of(x, d, k):
    """Row (d, k) of a (2, N, 3) state as a 3-tuple (d = 0: positions, 1: velocities)."""
    return x[d, k, 0], x[d, k, 1], x[d, k, 2]


@njit(cache=True, inline="always")
def sphere_sphere(d, radius_sum):
    """Two spheres whose centres are ``d = c_b - c_a`` apart: ``(normal, penetration_depth)``.

    The normal joins the centres, d / |d| (the lecture's Case B); depth = r_a + r_b - |d|.
    Concentric spheres have no direction between them: the normal is then +x by convention.
    """
    dist = np.sqrt(dot3(d, d))
    if dist > 0:
        normal = (d[0] / dist, d[1] / dist, d[2] / dist)
    else:
        normal = (1.0, 0.0, 0.0)
    return normal, radius_sum - dist


@njit(cache=True, inline="always")
def plane_height(c, plane_normal, offset):
    """Signed distance of the point ``c`` above the plane ``n . x = offset``: n . c - offset."""
    return dot3(c, plane_normal) - offset


@njit(cache=True, inline="always")
def sphere_plane(c, radius, plane_normal, offset):
    """A sphere (centre ``c``) against the half-space n . x <= offset: ``(normal, depth, height)``.

    The normal is -n (from the sphere into the half-space; written 0 - n, so a zero
    component is +0), depth = r - height with the centre's height n . c - offset.
    """
    height = plane_height(c, plane_normal, offset)
    normal = (0.0 - plane_normal[0], 0.0 - plane_normal[1], 0.0 - plane_normal[2])
    return normal, radius - height, height


@njit(cache=True, inline="always")
def first_entry_of(a, b, c):
    """First root in [0, 1] of a s^2 + 2 b s + c = 0 for a point starting outside (c > 0).

    The rationalised root s = c / (-b + sqrt(b^2 - a c)), free of the cancellation in
    (-b - sqrt(b^2 - a c)) / a; ``inf`` when the point moves away (b >= 0), misses
    (negative discriminant) or arrives after the step.
    """
    disc = b * b - a * c
    if c > 0 and b < 0 and disc >= 0:
        s = c / (-b + np.sqrt(disc))
        if s <= 1:
            return s
    return np.inf


@njit(cache=True, inline="always")
def sphere_sphere_entry(start, chord, radius_sum):
    """Fraction of the step at which two spheres first touch, their centres moving linearly.

    ``start`` = c_a - c_b at the start, ``chord`` = (move of a) - (move of b); |start + s chord|
    = r_a + r_b is a s^2 + 2 b s + c = 0 (:func:`first_entry_of`). Already touching (c <= 0),
    the impact is now (0) if they approach (b < 0), else none (inf).
    """
    a, b = dot3(chord, chord), dot3(start, chord)
    c = dot3(start, start) - radius_sum * radius_sum
    if c <= 0:
        return 0.0 if b < 0 else np.inf
    return first_entry_of(a, b, c)


@njit(cache=True, inline="always")
def sphere_plane_entry_of(h0, h1):
    """Fraction of the step at which a sphere reaches a plane: its height less r goes h0 -> h1 linearly.

    Crossing zero (h0 > 0 >= h1) at s = h0 / (h0 - h1). Already touching (h0 <= 0), now (0)
    if it moves in (h1 < h0), else none (inf).
    """
    if h0 <= 0:
        return 0.0 if h1 < h0 else np.inf
    if h1 <= 0:
        return h0 / (h0 - h1)
    return np.inf


# --- the NumPy paths' vectorised forms: the kernels above, row by row ----------------------


@njit(cache=True)
def sphere_sphere_rows(d, radius_sum):
    """:func:`sphere_sphere` of each row: d (K, 3), radius_sum (K,) -> normal (K, 3), depth (K,)."""
    normal, depth = np.empty_like(d), np.empty(len(d))
    for k in range(len(d)):
        (normal[k, 0], normal[k, 1], normal[k, 2]), depth[k] = sphere_sphere((d[k, 0], d[k, 1], d[k, 2]),
                                                                             radius_sum[k])
    return normal, depth


@njit(cache=True)
def sphere_plane_rows(c, radius, plane_normal, offset):
    """:func:`sphere_plane` of each row: c (K, 3), radius (K,), one plane -> normal (K, 3), depth, height (K,)."""
    normal, depth, height = np.empty_like(c), np.empty(len(c)), np.empty(len(c))
    n = (plane_normal[0], plane_normal[1], plane_normal[2])
    for k in range(len(c)):
        (normal[k, 0], normal[k, 1], normal[k, 2]), depth[k], height[k] = sphere_plane(
            (c[k, 0], c[k, 1], c[k, 2]), radius[k], n, offset)
    return normal, depth, height


@njit(cache=True)
def first_entry_rows(a, b, c):
    """:func:`first_entry_of` of each element: a, b, c (K,) -> s (K,)."""
    s = np.empty(len(a))
    for k in range(len(a)):
        s[k] = first_entry_of(a[k], b[k], c[k])
    return s


@njit(cache=True)
def sphere_plane_entry_rows(h0, h1):
    """:func:`sphere_plane_entry_of` of each element: h0, h1 (K,) -> s (K,)."""
    s = np.empty(len(h0))
    for k in range(len(h0)):
        s[k] = sphere_plane_entry_of(h0[k], h1[k])
    return s


@njit(cache=True)
def sphere_sphere_entry_rows(start, chord, radius_sum):
    """:func:`sphere_sphere_entry` of each row: start, chord (K, 3), radius_sum (K,) -> s (K,)."""
    s = np.empty(len(start))
    for k in range(len(start)):
        s[k] = sphere_sphere_entry((start[k, 0], start[k, 1], start[k, 2]),
                                   (chord[k, 0], chord[k, 1], chord[k, 2]), radius_sum[k])
    return s
