"""The response to a collision, compiled: the one definition of the lecture's impulse.

The incremental event loop resolves one pair per collision, thousands of times per step
in a crowded scene, through :func:`resolve_pair`; the NumPy functions of
:mod:`.response` (:func:`.response.impulse`, :func:`.response.resolve`) run these same
kernels row by row, so both paths have the same numbers bit for bit
(tests/test_event_loop.py, tests/test_collisions.py). Compiled without ``fastmath``:
the order of operations is the order written.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed
from .sphere_contacts import dot3, row3, row3_of, sphere_plane, sphere_sphere, sub3


@njit(cache=True, inline="always")
def impulse_of(v_rel, inverse_sum, normal, restitution, friction):
    """The impulse Lambda on body A, a 3-tuple (:func:`.response.impulse` for one pair).

    ``v_rel`` = V_A- - V_B-, ``inverse_sum`` = 1/m_A + 1/m_B. Equation 4 along the normal,
    Lambda_s = -(1 + eps) v_n / (1/m_A + 1/m_B) while approaching (v_n > 0), then Coulomb
    friction against the sliding velocity v_t: just enough to stop it, at most mu |Lambda_s|.
    """
    v_n = approach_speed(v_rel, AT_REST, normal)
    approaching = v_n > 0 and inverse_sum > 0
    safe_sum = inverse_sum if inverse_sum > 0 else 1.0
    lambda_s = -(1 + restitution) * v_n / safe_sum if approaching else 0.0
    lam = (lambda_s * normal[0], lambda_s * normal[1], lambda_s * normal[2])
    if friction > 0:
        v_t = (v_rel[0] - v_n * normal[0], v_rel[1] - v_n * normal[1], v_rel[2] - v_n * normal[2])
        speed_t = np.sqrt(dot3(v_t, v_t))
        stop = speed_t / safe_sum  # the tangential impulse that ends the sliding
        j_t = min(stop, friction * abs(lambda_s)) if approaching else 0.0
        scale = j_t / (speed_t if speed_t > 0 else 1.0)
        lam = (lam[0] - scale * v_t[0], lam[1] - scale * v_t[1], lam[2] - scale * v_t[2])
    return lam


@njit(cache=True)
def impulse_rows(v_rel, inverse_sum, normal, restitution, friction):
    """:func:`impulse_of` of each row: v_rel, normal (K, 3); inverse_sum, restitution, friction (K,)."""
    lam = np.empty_like(v_rel)
    for k in range(len(v_rel)):
        lam[k, 0], lam[k, 1], lam[k, 2] = impulse_of(row3(v_rel, k), inverse_sum[k], row3(normal, k),
                                                     restitution[k], friction[k])
    return lam


@njit(cache=True)
def resolve_pair(y, i, j, inverse_masses, normal, depth, restitution, friction):
    """:func:`.response.resolve` for one pair: body ``i`` against body ``j`` (``j < 0``: a static shape).

    ``y`` (2, N, 3) is changed in place; ``normal`` (3,) points from i towards j.
    Returns Lambda (3,), the impulse on body i.
    """
    lam = np.empty(3)
    lam[0], lam[1], lam[2] = respond(y, i, j, inverse_masses, (normal[0], normal[1], normal[2]), depth,
                                     restitution, friction)
    return lam


@njit(cache=True, inline="always")
def respond(y, i, j, inverse_masses, normal, depth, restitution, friction):
    """:func:`resolve_pair` with the normal a 3-tuple, returning Lambda as one (no array made: the
    event loop's compiled step calls it at every impact)."""
    inv_a = inverse_masses[i]
    inv_b = inverse_masses[j] if j >= 0 else 0.0
    inv_sum = inv_a + inv_b
    # moved apart along the normal, each in proportion to its inverse mass
    push = (depth if (depth > 0 and inv_sum > 0) else 0.0) / (inv_sum if inv_sum > 0 else 1.0)
    for k in range(3):
        y[0, i, k] = y[0, i, k] - normal[k] * (push * inv_a)
    v_b = row3_of(y, 1, j) if j >= 0 else AT_REST
    v_rel = sub3(row3_of(y, 1, i), v_b)
    lam = impulse_of(v_rel, inv_sum, normal, restitution, friction)
    for k in range(3):
        y[1, i, k] = y[1, i, k] + lam[k] * inv_a
    if j >= 0:
        for k in range(3):
            y[0, j, k] = y[0, j, k] + normal[k] * (push * inv_b)
            y[1, j, k] = y[1, j, k] - lam[k] * inv_b
    return lam


@njit(cache=True)
def resolve_rows(y, i, j, inverse_masses, normal, depth, restitution, friction):
    """:func:`resolve_pair` of each pair k (``j[k] < 0``: a static shape), in order; Lambda (K, 3)."""
    lam = np.empty((len(i), 3))
    for k in range(len(i)):
        lam[k] = resolve_pair(y, i[k], j[k], inverse_masses, normal[k], depth[k], restitution[k], friction[k])
    return lam


@njit(cache=True)
def impact_terms(y, i, j, radii, accelerations, planes):
    """The contact and approach of one pair at its impact, as the NumPy path computes them.

    Body ``i`` against body ``j`` (:func:`.sphere_contacts.sphere_sphere`) or, for ``j < 0``,
    the plane ``-1 - j`` of ``planes`` (a :class:`.retest.Planes`, as a tuple;
    :func:`.sphere_contacts.sphere_plane`), in state ``y`` (2, N, 3); the approach speed and
    the pressing acceleration are :func:`.approach.approach_speed` of the velocities and of the
    ``accelerations`` along the normal. Returns ``(normal (3,), depth, speed, pressing)``.
    """
    normal = np.empty(3)
    n, depth, speed, pressing = contact_terms(y, i, j, radii, accelerations, planes)
    normal[0], normal[1], normal[2] = n
    return normal, depth, speed, pressing


@njit(cache=True, inline="always")
def contact_terms(y, i, j, radii, accelerations, planes):
    """:func:`impact_terms` with the normal a 3-tuple (no array made: the event loop's compiled step)."""
    q_a, v_a, a_a = row3_of(y, 0, i), row3_of(y, 1, i), row3(accelerations, i)
    if j >= 0:
        q_b, v_b, a_b = row3_of(y, 0, j), row3_of(y, 1, j), row3(accelerations, j)
        n, depth = sphere_sphere(sub3(q_b, q_a), radii[i] + radii[j])
    else:
        plane = -1 - j
        v_b = a_b = AT_REST
        normals, offsets = planes[0], planes[1]
        n, depth, _ = sphere_plane(q_a, radii[i], row3(normals, plane), offsets[plane])
    return n, depth, approach_speed(v_a, v_b, n), approach_speed(a_a, a_b, n)
