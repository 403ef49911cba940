"""The response to a collision, compiled: the one definition of the lecture's impulse.

The incremental event loop resolves one pair per collision, thousands of times per step
in a crowded scene, through :func:`respond`; the NumPy functions of :mod:`.response`
(:func:`.response.impulse`, :func:`.response.resolve`) run these same kernels row by row,
so both paths have the same numbers bit for bit (tests/test_event_loop.py,
tests/test_collisions.py). Compiled without ``fastmath``: the order of operations is the
order written.

Spheres with spin
-----------------
The lecture's impulse (equations 1 to 4) is a point mass's: Lambda changes V only. A sphere
that spins (it declares ``angular_velocity`` or ``inertia`` in its scene) is a rigid body, and
the impulse acts at the contact point, r_A = R_A n from A's centre and r_B = -R_B n from B's
(n the unit normal from A to B). Integrated over the impact, as the lecture integrates
m dV/dt = F into equation 1, the torque r x F gives its angular part:

    m_A V_A+ = m_A V_A- + Lambda,       I_A omega_A+ = I_A omega_A- + r_A x Lambda,
    m_B V_B+ = m_B V_B- - Lambda,       I_B omega_B+ = I_B omega_B- - r_B x Lambda.

The contact point's relative velocity is u = (V_A + omega_A x r_A) - (V_B + omega_B x r_B).
Its normal part is (V_A - V_B) . n, since omega x r is perpendicular to r and r lies along n:
for spheres the normal impulse, equation 4, does not see the spin, and spin alone never
changes the bounce. Its tangential part, the slip u_t, changes under a tangential impulse
Lambda_t by (1/m_A + 1/m_B + R_A^2/I_A + R_B^2/I_B) Lambda_t, since
(I^-1 (R n x Lambda_t)) x R n = R^2 / I Lambda_t for a sphere (one moment of inertia I); the
tangential effective mass is the inverse of that sum, m / (1 + m R^2 / I) = 2/7 m for a solid
ball on a static plane. The lever terms R^2 / I are the ``lever_sum`` of :func:`impulse_of`.

Coulomb friction in the impact (the lecture's "Surface Friction" slides, with its static and
dynamic coefficients one mu, integrated over the impact): the tangential impulse that stops the
slip is -u_t / (that sum). If it is at most mu |Lambda_s| the contact sticks (u_t+ = 0);
otherwise it slides, Lambda_t = -mu |Lambda_s| u_t / |u_t|. Because a sphere's tangential
compliance is the same in every direction and does not couple to the normal one, the slip
keeps its direction through the impact and Routh's integration of Coulomb's law over the
impact gives exactly this algebraic rule (and Poisson's restitution is Newton's). The
impulse acts at the contact point, so it keeps each body's angular momentum about that
point (m r x V + I omega changes by r x Lambda - r x Lambda = 0), and a pair's linear and
angular momentum about any fixed point; the kinetic energy, with its 1/2 I omega^2, never
grows for eps <= 1 (tests/test_spin.py).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .approach import AT_REST, approach_speed
from .manifold_geometry import cross3
from .rigid_solver import EXPONENTIAL, _turn
from .sphere_contacts import dot3, row3, row3_of, sphere_plane, sphere_sphere, sub3


class Spin(NamedTuple):
    """The spheres' spin in the event loop, (N, 3), (N,) and (N, 4); every field empty (:func:`no_spin`)
    where no sphere spins or friction acts on none, so the kernels take the point-mass path.

    ``omega`` is the angular velocity (world frame, rad/s), constant between contacts (a sphere of
    one moment of inertia turns freely about a fixed axis); ``inverse_inertia`` 1/I (0 for a body
    that does not turn: a point mass, a pinned body); ``radii`` the lever arm R; ``orientation``
    each body's unit quaternion at the time ``turned`` (s), turned on by omega to each contact's
    time and to the step's end (:func:`turn_to`), so it is exact: exp(omega t) between contacts.
    """

    omega: np.ndarray
    inverse_inertia: np.ndarray
    radii: np.ndarray
    orientation: np.ndarray
    turned: np.ndarray


def no_spin() -> Spin:
    """Point masses: no body turns (the kernels' tests of ``spinning`` are then false)."""
    return Spin(np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros((0, 4)), np.zeros(0))


@njit(cache=True, inline="always")
def spinning(spin):
    """Whether some body of the scene turns (the spin's arrays are not empty)."""
    return spin[1].shape[0] > 0


@njit(cache=True, inline="always")
def turn_to(spin, body, t):
    """Body ``body``'s orientation turned on by its (constant) omega from ``spin.turned`` to ``t``."""
    omega, inverse_inertia, _, orientation, turned = spin
    if spinning(spin) and body >= 0 and inverse_inertia[body] > 0 and t != turned[body]:
        _turn(orientation, body, row3(omega, body), t - turned[body], EXPONENTIAL)
        turned[body] = t


@njit(cache=True)
def turn_all_to(spin, t):
    """Every turning body's orientation turned on to ``t`` (the end of the step)."""
    if spinning(spin):
        for body in range(spin[1].shape[0]):
            turn_to(spin, body, t)


#: the ``turning`` of a pair that does not turn (point masses, or no friction): :func:`impulse_of` then
#: takes the point-mass path
NO_TURN = (AT_REST, 0.0)


@njit(cache=True, inline="always")
def contact_spin(spin, i, j, normal):
    """What the spin adds to the slip of the pair (i, j) (``j < 0``: a static shape) at its contact,
    ``(omega_i x r_i - omega_j x r_j, R_i^2 / I_i + R_j^2 / I_j)`` with r_i = R_i n, r_j = -R_j n
    (``spin`` not empty)."""
    omega, inverse_inertia, radii, _, _ = spin
    w_i = cross3(row3(omega, i), normal)
    r_i = radii[i]
    lever = r_i * r_i * inverse_inertia[i]
    w = (r_i * w_i[0], r_i * w_i[1], r_i * w_i[2])
    if j >= 0:
        w_j = cross3(row3(omega, j), normal)
        r_j = radii[j]
        lever += r_j * r_j * inverse_inertia[j]
        w = (w[0] + r_j * w_j[0], w[1] + r_j * w_j[1], w[2] + r_j * w_j[2])
    return w, lever


@njit(cache=True, inline="always")
def impulse_of(v_rel, inverse_sum, normal, restitution, friction, turning):
    """The impulse Lambda on body A, a 3-tuple (:func:`.response.impulse` for one pair).

    ``v_rel`` = V_A- - V_B-, ``inverse_sum`` = 1/m_A + 1/m_B. Equation 4 along the normal,
    Lambda_s = -(1 + eps) v_n / (1/m_A + 1/m_B) while approaching (v_n > 0), then Coulomb
    friction against the slip: just enough to stop it, at most mu |Lambda_s|. ``turning`` =
    (w, lever_sum) of :func:`contact_spin`: the spin's part of the contact point's relative
    velocity and of the tangential inverse mass ((0, 0) for point masses: the slip is v_t).
    """
    v_n = approach_speed(v_rel, AT_REST, normal)
    approaching = v_n > 0 and inverse_sum > 0
    safe_sum = inverse_sum if inverse_sum > 0 else 1.0
    lambda_s = -(1 + restitution) * v_n / safe_sum if approaching else 0.0
    lam = (lambda_s * normal[0], lambda_s * normal[1], lambda_s * normal[2])
    if friction > 0:
        v_t = (v_rel[0] - v_n * normal[0], v_rel[1] - v_n * normal[1], v_rel[2] - v_n * normal[2])
        w, lever_sum = turning
        tangential_sum = safe_sum
        if lever_sum > 0:  # the contact point's slip: v_t + (omega x r)'s tangential part
            w_n = dot3(w, normal)
            v_t = (v_t[0] + (w[0] - w_n * normal[0]), v_t[1] + (w[1] - w_n * normal[1]),
                   v_t[2] + (w[2] - w_n * normal[2]))
            tangential_sum = safe_sum + lever_sum
        speed_t = np.sqrt(dot3(v_t, v_t))
        stop = speed_t / tangential_sum  # the tangential impulse that ends the sliding
        j_t = min(stop, friction * abs(lambda_s)) if approaching else 0.0
        scale = j_t / (speed_t if speed_t > 0 else 1.0)
        lam = (lam[0] - scale * v_t[0], lam[1] - scale * v_t[1], lam[2] - scale * v_t[2])
    return lam


@njit(cache=True)
def impulse_rows(v_rel, inverse_sum, normal, restitution, friction):
    """:func:`impulse_of` of each row (point masses): v_rel, normal (K, 3); inverse_sum, restitution, friction (K,)."""
    lam = np.empty_like(v_rel)
    for k in range(len(v_rel)):
        lam[k, 0], lam[k, 1], lam[k, 2] = impulse_of(row3(v_rel, k), inverse_sum[k], row3(normal, k),
                                                     restitution[k], friction[k], NO_TURN)
    return lam


@njit(cache=True)
def resolve_pair(y, pair, inverse_masses, normal, depth, material, spin):
    """:func:`.response.resolve` for one pair: body ``i`` against body ``j`` (``j < 0``: a static shape).

    ``pair`` = (i, j), ``material`` = (restitution, friction), ``spin`` a :class:`Spin`
    (:func:`no_spin` for point masses). ``y`` (2, N, 3) and the spin's ``omega`` are changed in
    place; ``normal`` (3,) points from i towards j. Returns Lambda (3,), the impulse on body i.
    """
    lam = np.empty(3)
    lam[0], lam[1], lam[2] = respond_spinning(y, pair, inverse_masses, (normal[0], normal[1], normal[2]), depth,
                                              material, spin)
    return lam


@njit(cache=True, inline="always")
def respond_spinning(y, pair, inverse_masses, normal, depth, material, spin):
    """:func:`respond` with the spin: its part of the slip, and omega changed by the impulse's
    angular part (:func:`spin_up`). The event loop's hot paths call :func:`respond` alone where no
    body spins: handing the spin's arrays to an inlined function costs Numba reference counts."""
    turning = contact_spin(spin, pair[0], pair[1], normal) if spinning(spin) and material[1] > 0 else NO_TURN
    lam = respond(y, pair, inverse_masses, normal, depth, material, turning)
    if turning[1] > 0:
        spin_up(spin, pair, normal, lam)
    return lam


@njit(cache=True, inline="always")
def respond(y, pair, inverse_masses, normal, depth, material, turning):
    """:func:`resolve_pair` with the normal a 3-tuple, returning Lambda as one (no array made: the
    event loop's compiled step calls it at every impact); ``turning`` as :func:`impulse_of` takes it
    (:data:`NO_TURN` for point masses), omega changed by the caller (:func:`respond_spinning`)."""
    i, j = pair
    restitution, friction = material
    inv_a = inverse_masses[i]
    inv_b = inverse_masses[j] if j >= 0 else 0.0
    inv_sum = inv_a + inv_b
    # moved apart along the normal, each in proportion to its inverse mass
    push = (depth if (depth > 0 and inv_sum > 0) else 0.0) / (inv_sum if inv_sum > 0 else 1.0)
    for k in range(3):
        y[0, i, k] = y[0, i, k] - normal[k] * (push * inv_a)
    v_b = row3_of(y, 1, j) if j >= 0 else AT_REST
    v_rel = sub3(row3_of(y, 1, i), v_b)
    lam = impulse_of(v_rel, inv_sum, normal, restitution, friction, turning)
    for k in range(3):
        y[1, i, k] = y[1, i, k] + lam[k] * inv_a
    if j >= 0:
        for k in range(3):
            y[0, j, k] = y[0, j, k] + normal[k] * (push * inv_b)
            y[1, j, k] = y[1, j, k] - lam[k] * inv_b
    return lam


@njit(cache=True, inline="always")
def spin_up(spin, pair, normal, lam):
    """The impulse's angular part, I domega = r x Lambda: omega_i += (R_i / I_i) n x Lambda (r_i = R_i n),
    and the same on j, whose (-R_j n) x (-Lambda) is R_j n x Lambda (0 for a body that does not turn)."""
    omega, inverse_inertia, radii, _, _ = spin
    turn = cross3(normal, lam)
    for body in pair:
        if body >= 0:
            scale = radii[body] * inverse_inertia[body]
            for k in range(3):
                omega[body, k] = omega[body, k] + scale * turn[k]


@njit(cache=True)
def resolve_rows(y, pairs, inverse_masses, normal, depth, material, spin):
    """:func:`resolve_pair` of each pair k (``pairs`` = (i, j) columns, ``j[k] < 0``: a static shape;
    ``material`` = (restitution, friction) columns), in order; Lambda (K, 3)."""
    i, j = pairs
    restitution, friction = material
    lam = np.empty((len(i), 3))
    for k in range(len(i)):
        lam[k, 0], lam[k, 1], lam[k, 2] = respond_spinning(y, (i[k], j[k]), inverse_masses, row3(normal, k),
                                                           depth[k], (restitution[k], friction[k]), spin)
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
