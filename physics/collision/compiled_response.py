"""The response to one collision, compiled: :func:`.response.resolve` for a single pair.

The incremental event loop resolves one pair per collision, thousands of times per
step in a crowded scene; :func:`.response.resolve` is vectorised over pairs and pays
NumPy's per-call cost on arrays of one row. This kernel is the same arithmetic for
one pair, written out in NumPy's order of operations and compiled without
``fastmath``, so its numbers are the NumPy function's bit for bit
(tests/test_event_loop.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def resolve_pair(y, i, j, inverse_masses, normal, depth, restitution, friction):
    """:func:`.response.resolve` for one pair: body ``i`` against body ``j`` (``j < 0``: a static shape).

    ``y`` (2, N, 3) is changed in place; ``normal`` (3,) points from i towards j.
    Returns Lambda (3,), the impulse on body i.
    """
    inv_a = inverse_masses[i]
    inv_b = inverse_masses[j] if j >= 0 else 0.0
    inv_sum = inv_a + inv_b
    push = (depth if (depth > 0 and inv_sum > 0) else 0.0) / (inv_sum if inv_sum > 0 else 1.0)
    for k in range(3):
        y[0, i, k] = y[0, i, k] - normal[k] * (push * inv_a)
    # impulse(): the normal part with restitution, then Coulomb friction
    v_rel = np.empty(3)
    for k in range(3):
        v_rel[k] = y[1, i, k] - (y[1, j, k] if j >= 0 else 0.0)
    v_n = v_rel[0] * normal[0] + v_rel[1] * normal[1] + v_rel[2] * normal[2]
    approaching = v_n > 0 and inv_sum > 0
    safe_sum = inv_sum if inv_sum > 0 else 1.0
    lambda_s = -(1 + restitution) * v_n / safe_sum if approaching else 0.0
    lam = np.empty(3)
    for k in range(3):
        lam[k] = lambda_s * normal[k]
    if friction > 0:
        v_t = np.empty(3)
        for k in range(3):
            v_t[k] = v_rel[k] - v_n * normal[k]
        speed_t = np.sqrt(v_t[0] * v_t[0] + v_t[1] * v_t[1] + v_t[2] * v_t[2])
        stop = speed_t / safe_sum  # the tangential impulse that ends the sliding
        j_t = min(stop, friction * abs(lambda_s)) if approaching else 0.0
        scale = j_t / (speed_t if speed_t > 0 else 1.0)
        for k in range(3):
            lam[k] = lam[k] - scale * v_t[k]
    for k in range(3):
        y[1, i, k] = y[1, i, k] + lam[k] * inv_a
    if j >= 0:
        for k in range(3):
            y[0, j, k] = y[0, j, k] + normal[k] * (push * inv_b)
            y[1, j, k] = y[1, j, k] - lam[k] * inv_b
    return lam


@njit(cache=True)
def impact_terms(y, i, j, radii, accelerations, normals, offsets):
    """The contact and approach of one pair at its impact, as the NumPy path computes them.

    Body ``i`` against body ``j`` (:func:`.narrow_phase.collide_sphere_sphere`) or, for
    ``j < 0``, the plane ``-1 - j`` (:func:`.narrow_phase.collide_sphere_plane`), in state
    ``y`` (2, N, 3); the approach speed and the pressing acceleration are
    :func:`.response.normal_speed` of the velocities and of the ``accelerations`` along
    the normal. Returns ``(normal (3,), depth, speed, pressing)``.
    """
    normal = np.empty(3)
    if j >= 0:
        d0, d1, d2 = y[0, j, 0] - y[0, i, 0], y[0, j, 1] - y[0, i, 1], y[0, j, 2] - y[0, i, 2]
        dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if dist > 0:
            normal[0], normal[1], normal[2] = d0 / dist, d1 / dist, d2 / dist
        else:
            normal[0], normal[1], normal[2] = 1.0, 0.0, 0.0
        depth = radii[i] + radii[j] - dist
        w0, w1, w2 = y[1, i, 0] - y[1, j, 0], y[1, i, 1] - y[1, j, 1], y[1, i, 2] - y[1, j, 2]
        g0 = accelerations[i, 0] - accelerations[j, 0]
        g1 = accelerations[i, 1] - accelerations[j, 1]
        g2 = accelerations[i, 2] - accelerations[j, 2]
    else:
        plane = -1 - j
        height = (y[0, i, 0] * normals[plane, 0] + y[0, i, 1] * normals[plane, 1]
                  + y[0, i, 2] * normals[plane, 2]) - offsets[plane]
        for k in range(3):
            normal[k] = 0.0 - normals[plane, k]
        depth = radii[i] - height
        w0, w1, w2 = y[1, i, 0] - 0.0, y[1, i, 1] - 0.0, y[1, i, 2] - 0.0
        g0, g1, g2 = accelerations[i, 0] - 0.0, accelerations[i, 1] - 0.0, accelerations[i, 2] - 0.0
    speed = w0 * normal[0] + w1 * normal[1] + w2 * normal[2]
    pressing = g0 * normal[0] + g1 * normal[1] + g2 * normal[2]
    return normal, depth, speed, pressing
