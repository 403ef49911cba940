"""Sequential impulses on rigid bodies: the contact solver's kernels with an angular part (Numba).

The soft step of :mod:`.sequential_impulses` (substeps, warm start, biased solve, positions,
relaxation, restitution pass) over contact *points* of rigid bodies that rotate. A contact k
joins body ``a[k]`` to body ``b[k]`` (-1: a static shape) at a point with the lever arms
``ra[k]``, ``rb[k]`` from the two centres of mass (world frame, at the start of the step), along
the unit normal ``normal[k]`` from a to b. The velocity of the contact point on body i is
v_i + omega_i x r_i, and the constraint is on the relative normal velocity

    v_n = (v_b + omega_b x r_b - v_a - omega_a x r_a) . n >= -bias,

enforced by an accumulated impulse P >= 0. An impulse P at the point changes body b by
dv = P / m and d omega = I_w^-1 (r x P) (dL = r x P), and body a by the opposite; so the
impulse the solver applies to one contact exactly is dP = -m_n (v_n + bias) with the
effective mass

    m_n = 1 / (1/m_a + 1/m_b + (r_a x n) . I_a^-1 (r_a x n) + (r_b x n) . I_b^-1 (r_b x n)),

I^-1 = R diag(1/I1, 1/I2, 1/I3) R^T the world inverse inertia, both computed at the start of
the step and kept through its substeps, as Box2D keeps its effective masses. The levers the
impulses act through are those of the point now (:func:`_geometry`): both bodies receive equal
and opposite impulses at one point, so linear and angular momentum are conserved to round-off
by every body-body contact. Coulomb friction acts along two tangent directions
t1, t2 of the contact plane, each with its own effective mass; the tangential impulse, a
vector in the plane, is kept in the disc |P_t| <= mu P. Rolling resistance (optional) is an
angular impulse against the relative rolling velocity (its part across n), kept in the disc
|M| <= c_r P, c_r the coefficient times the rolling radius.

Inside the step each contact's separation is tracked from the bodies' moves, as Box3D does:

    s = s0 + n . ((dq_b + dR_b c_b - c_b) - (dq_a + dR_a c_a - c_a)),

dq the move and dR the rotation of each body since the start of the step, c the lever of the
point on the body's *core*: c_a = r_a - rho_a n, c_b = r_b + rho_b n, rho the rounding radius
of a sphere or capsule about its centre or segment (0 for a box). A box's corner rises as the
box turns, but a rolling ball's surface point only slides round it: with the surface point's
lever instead, the separation of a ball rolling at 0.24 rad per step (14 rad/s at 60 Hz) would
open by r (1 - cos 0.24) = 2.9 mm within the step, a phantom gap it would sink into.

The rotation of each substep (h = dt / substeps): the velocity stage adds the gyroscopic
term, domega/dt = -I^-1 (omega x I omega) (no torque: the scene's forces act at the centres),
by the scene's rotation method; the position stage turns the orientation by h omega
(:data:`GYROSCOPIC`, :data:`UPDATES`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .manifold_geometry import cross3
from .sphere_contacts import dot3

#: the velocity stage's gyroscopic term: omega_b += -h I^-1 (omega_b x I omega_b) (body frame),
#: the same, then omega_b rescaled to keep |I omega_b|, or one Newton step of its backward Euler
EXPLICIT, RESCALED, IMPLICIT = 0, 1, 2
GYROSCOPIC = {"explicit": EXPLICIT, "rescaled": RESCALED, "implicit": IMPLICIT}
#: the position stage's turn: q <- exp(h omega) q (exact for a constant omega over the substep), or
#: q <- normalise(q + h/2 (0, omega) q) (its first-order truncation)
EXPONENTIAL, FIRST_ORDER = 0, 1
UPDATES = {"exponential": EXPONENTIAL, "first-order": FIRST_ORDER}


class RigidBodyColumns(NamedTuple):
    """The bodies, (N, 3), (N, 4), (N, 3, 3) or (N,); every one of them, rotating or not, changed in place.

    A body that does not rotate (a point mass, a pinned body) has zero inverse inertia.
    """

    q: np.ndarray  # centres of mass, m
    v: np.ndarray  # velocities, m/s
    omega: np.ndarray  # angular velocities, world frame, rad/s
    orientation: np.ndarray  # unit quaternions [w, x, y, z], body to world
    dq: np.ndarray  # the move since the start of the step, m (zeros at the start)
    turn: np.ndarray  # the rotation since the start of the step, a unit quaternion (identity at the start)
    inverse_mass: np.ndarray  # 1/kg, 0 pinned
    inverse_inertia: np.ndarray  # world frame at the start of the step, (N, 3, 3), 1/(kg m^2)
    inverse_principal: np.ndarray  # 1/I1, 1/I2, 1/I3 in the body frame, (N, 3); 0: does not rotate
    accel: np.ndarray  # the forces' accelerations, m/s^2
    rounding: np.ndarray  # the radius of the rounded surface about the core (sphere, capsule), 0 for a box, m
    energy: np.ndarray  # (N,) kinetic energy at the start of the step, J (:func:`kinetic_energies`)


class RigidContactColumns(NamedTuple):
    """The contact points (C,), (C, 3) or (C, 2, 3); ``pn``, ``pt``, ``pr``, ``total``, ``most`` changed in place."""

    a: np.ndarray  # body a
    b: np.ndarray  # body b, -1: a static shape
    normal: np.ndarray  # from a towards b
    ra: np.ndarray  # lever arm from a's centre to the point, m
    rb: np.ndarray  # lever arm from b's centre (zeros for a static shape), m
    tangent: np.ndarray  # (C, 2, 3): t1, t2, with n an orthonormal basis
    s0: np.ndarray  # separation at the start of the step, m (negative: penetration)
    vn0: np.ndarray  # v_n at the start of the step, m/s
    hit: np.ndarray  # v_n just before the contact's first impulse in the step, m/s (+inf: not hit yet)
    mass: np.ndarray  # (C, 3): the effective masses along n, t1, t2, kg
    friction: np.ndarray  # mu
    restitution: np.ndarray  # eps
    threshold: np.ndarray  # approach speeds at or below this do not bounce, m/s
    rolling: np.ndarray  # rolling resistance: the largest |M| / P, m (0: none)
    pn: np.ndarray  # normal impulse of the last substep, N s
    pt: np.ndarray  # (C, 2) tangential impulse along t1, t2, N s
    pr: np.ndarray  # (C, 3) rolling resistance's angular impulse, N m s
    total: np.ndarray  # the step's normal impulse, N s
    most: np.ndarray  # the largest substep impulse of the step, N s


class RigidSubstep(NamedTuple):
    """One step's context: the substep, the correction's settings and the rotation's stages."""

    h: float  # the substep, s
    iterations: int
    bias_rate: float  # 1/s (:mod:`.solver_settings`)
    mass_scale: float
    impulse_scale: float
    push_speed: float  # m/s
    slop: float  # m
    gyroscopic: int  # one of EXPLICIT, RESCALED, IMPLICIT
    update: int  # EXPONENTIAL or FIRST_ORDER


# --- small vector algebra on tuples (what Numba keeps in registers) --------------------------

@njit(cache=True, inline="always")
def _row(x, k):
    return x[k, 0], x[k, 1], x[k, 2]


@njit(cache=True, inline="always")
def _matrix_times(m, k, x):
    """m[k] @ x for a stack m of 3 x 3 matrices."""
    return (m[k, 0, 0] * x[0] + m[k, 0, 1] * x[1] + m[k, 0, 2] * x[2],
            m[k, 1, 0] * x[0] + m[k, 1, 1] * x[1] + m[k, 1, 2] * x[2],
            m[k, 2, 0] * x[0] + m[k, 2, 1] * x[1] + m[k, 2, 2] * x[2])


@njit(cache=True, inline="always")
def _rotate_by(w, u, x):
    """(w, u) x (w, u)* for a unit quaternion: v + 2 w (u x v) + 2 u x (u x v)."""
    t = cross3(u, x)
    t = (2.0 * t[0], 2.0 * t[1], 2.0 * t[2])
    c = cross3(u, t)
    return x[0] + w * t[0] + c[0], x[1] + w * t[1] + c[1], x[2] + w * t[2] + c[2]


@njit(cache=True, inline="always")
def rotate(q, k, x):
    """q[k] x q[k]*, as :func:`steplab.physics.quaternion.rotate`."""
    return _rotate_by(q[k, 0], (q[k, 1], q[k, 2], q[k, 3]), x)


@njit(cache=True, inline="always")
def _rotate_inverse(q, k, x):
    """q[k]* x q[k]: the conjugate's rotation, world to body."""
    return _rotate_by(q[k, 0], (-q[k, 1], -q[k, 2], -q[k, 3]), x)


@njit(cache=True, inline="always")
def _turn(q, k, w, h, update):
    """q[k] <- (turn by h w, world frame) q[k], normalised (exp(h w / 2), or 1 + h w / 2)."""
    if update == EXPONENTIAL:
        x = 0.5 * h * np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])  # the half angle
        c = np.cos(x)
        s = 0.5 * h * (np.sin(x) / x if x > 1e-8 else 1.0 - x * x / 6.0)  # sin(x) / |w|, exact to round-off
    else:
        c, s = 1.0, 0.5 * h
    p0, p1, p2, p3 = c, s * w[0], s * w[1], s * w[2]
    q0, q1, q2, q3 = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
    r0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    r1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    r2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    r3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    size = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    q[k, 0], q[k, 1], q[k, 2], q[k, 3] = r0 / size, r1 / size, r2 / size, r3 / size


# --- the contact's kinematics ---------------------------------------------------------------

@njit(cache=True, inline="always")
def _geometry(bodies, contacts, k):
    """(s, la, lb) now: contact k's separation and the levers from each centre to its point.

    Each body's surface point is its core point (the lever c above) turned with the body, plus
    its rounding along n. Both bodies take the impulse at the midpoint of their two surface
    points, one point, so a body-body contact keeps angular momentum to round-off however far
    the bodies have moved since the start of the step (with the levers of the start, an
    oblique hit at 3 m/s lost 10 % of it)."""
    a, b = contacts.a[k], contacts.b[k]
    n = _row(contacts.normal, k)
    ra, rho = _row(contacts.ra, k), bodies.rounding[a]
    ca = (ra[0] - rho * n[0], ra[1] - rho * n[1], ra[2] - rho * n[2])
    ta = rotate(bodies.turn, a, ca)
    pa = (ta[0] + rho * n[0], ta[1] + rho * n[1], ta[2] + rho * n[2])
    da = (bodies.dq[a, 0] + ta[0] - ca[0], bodies.dq[a, 1] + ta[1] - ca[1], bodies.dq[a, 2] + ta[2] - ca[2])
    if b < 0:
        return contacts.s0[k] - dot3(da, n), pa, pa
    rb, rho = _row(contacts.rb, k), bodies.rounding[b]
    cb = (rb[0] + rho * n[0], rb[1] + rho * n[1], rb[2] + rho * n[2])
    tb = rotate(bodies.turn, b, cb)
    db = (bodies.dq[b, 0] + tb[0] - cb[0], bodies.dq[b, 1] + tb[1] - cb[1], bodies.dq[b, 2] + tb[2] - cb[2])
    s = contacts.s0[k] + dot3((db[0] - da[0], db[1] - da[1], db[2] - da[2]), n)
    d = (bodies.q[b, 0] - bodies.q[a, 0], bodies.q[b, 1] - bodies.q[a, 1], bodies.q[b, 2] - bodies.q[a, 2])
    pb = (tb[0] - rho * n[0], tb[1] - rho * n[1], tb[2] - rho * n[2])
    la = (0.5 * (pa[0] + d[0] + pb[0]), 0.5 * (pa[1] + d[1] + pb[1]), 0.5 * (pa[2] + d[2] + pb[2]))
    return s, la, (la[0] - d[0], la[1] - d[1], la[2] - d[2])


@njit(cache=True, inline="always")
def _relative_velocity(bodies, contacts, k, la, lb):
    """(v_b + omega_b x l_b) - (v_a + omega_a x l_a) at contact k."""
    a, b = contacts.a[k], contacts.b[k]
    wa = cross3(_row(bodies.omega, a), la)
    ua = (bodies.v[a, 0] + wa[0], bodies.v[a, 1] + wa[1], bodies.v[a, 2] + wa[2])
    if b < 0:
        return -ua[0], -ua[1], -ua[2]
    wb = cross3(_row(bodies.omega, b), lb)
    return bodies.v[b, 0] + wb[0] - ua[0], bodies.v[b, 1] + wb[1] - ua[1], bodies.v[b, 2] + wb[2] - ua[2]


@njit(cache=True, inline="always")
def _apply(bodies, contacts, k, la, lb, p):
    """The impulse p at contact k on body b, -p on body a: dv = p / m, d omega = I^-1 (l x p)."""
    a, b = contacts.a[k], contacts.b[k]
    v, omega, inverse_mass, inverse_inertia = bodies.v, bodies.omega, bodies.inverse_mass, bodies.inverse_inertia
    wa = inverse_mass[a]
    ja = _matrix_times(inverse_inertia, a, cross3(la, p))
    for x in range(3):
        v[a, x] -= wa * p[x]
        omega[a, x] -= ja[x]
    if b >= 0:
        wb = inverse_mass[b]
        jb = _matrix_times(inverse_inertia, b, cross3(lb, p))
        for x in range(3):
            v[b, x] += wb * p[x]
            omega[b, x] += jb[x]


@njit(cache=True, inline="always")
def _apply_angular(bodies, contacts, k, m):
    """The angular impulse m on body b, -m on body a."""
    a, b = contacts.a[k], contacts.b[k]
    ja = _matrix_times(bodies.inverse_inertia, a, m)
    for x in range(3):
        bodies.omega[a, x] -= ja[x]
    if b >= 0:
        jb = _matrix_times(bodies.inverse_inertia, b, m)
        for x in range(3):
            bodies.omega[b, x] += jb[x]


# --- the stages -----------------------------------------------------------------------------

@njit(cache=True)
def prepare(bodies, contacts):
    """Each contact's effective masses along n, t1, t2 (into ``contacts.mass``) and v_n at the start."""
    a_, b_, ra, rb, tangent, mass = contacts.a, contacts.b, contacts.ra, contacts.rb, contacts.tangent, contacts.mass
    inverse_mass, inverse_inertia = bodies.inverse_mass, bodies.inverse_inertia
    for k in range(len(a_)):
        a, b = a_[k], b_[k]
        for d in range(3):
            axis = _row(contacts.normal, k) if d == 0 else (tangent[k, d - 1, 0], tangent[k, d - 1, 1],
                                                            tangent[k, d - 1, 2])
            ca = cross3(_row(ra, k), axis)
            inverse = inverse_mass[a] + dot3(ca, _matrix_times(inverse_inertia, a, ca))
            if b >= 0:
                cb = cross3(_row(rb, k), axis)
                inverse += inverse_mass[b] + dot3(cb, _matrix_times(inverse_inertia, b, cb))
            mass[k, d] = 1.0 / inverse if inverse > 0.0 else 0.0
        contacts.vn0[k] = dot3(_relative_velocity(bodies, contacts, k, _row(ra, k), _row(rb, k)),
                               _row(contacts.normal, k))


@njit(cache=True, inline="always")
def _gyroscopic(bodies, body, h, kind):
    """omega of one body after the gyroscopic term over h (body frame, principal axes)."""
    inverse = _row(bodies.inverse_principal, body)
    w = _rotate_inverse(bodies.orientation, body, _row(bodies.omega, body))
    inertia = (1.0 / inverse[0], 1.0 / inverse[1], 1.0 / inverse[2])
    momentum = (inertia[0] * w[0], inertia[1] * w[1], inertia[2] * w[2])
    g = cross3(w, momentum)  # omega x I omega
    if kind == IMPLICIT:
        # one Newton step on f(w2) = I (w2 - w) + h w2 x I w2 = 0 from w2 = w:
        # J = I + h ([w]x I - [I w]x), w2 = w - J^-1 h (w x I w)
        jacobian = np.empty((3, 3))
        for r in range(3):
            for c in range(3):
                jacobian[r, c] = inertia[c] if r == c else 0.0
        jacobian[0, 1] += h * (-w[2] * inertia[1] + momentum[2])
        jacobian[0, 2] += h * (w[1] * inertia[2] - momentum[1])
        jacobian[1, 0] += h * (w[2] * inertia[0] - momentum[2])
        jacobian[1, 2] += h * (-w[0] * inertia[2] + momentum[0])
        jacobian[2, 0] += h * (-w[1] * inertia[0] + momentum[1])
        jacobian[2, 1] += h * (w[0] * inertia[1] - momentum[0])
        step = np.linalg.solve(jacobian, np.array([h * g[0], h * g[1], h * g[2]]))
        w1 = (w[0] - step[0], w[1] - step[1], w[2] - step[2])
    else:
        w1 = (w[0] - h * inverse[0] * g[0], w[1] - h * inverse[1] * g[1], w[2] - h * inverse[2] * g[2])
        if kind == RESCALED:  # |I omega| kept: the explicit step's growth of |L| undone
            before = np.sqrt(dot3(momentum, momentum))
            m1 = (inertia[0] * w1[0], inertia[1] * w1[1], inertia[2] * w1[2])
            after = np.sqrt(dot3(m1, m1))
            f = before / after if after > 0.0 else 1.0
            w1 = (w1[0] * f, w1[1] * f, w1[2] * f)
    return rotate(bodies.orientation, body, w1)


@njit(cache=True)
def integrate_velocities(bodies, sub):
    """v += h a for every movable body; the gyroscopic term for every rotating one."""
    v, omega, inverse_mass, accel, h = bodies.v, bodies.omega, bodies.inverse_mass, bodies.accel, sub.h
    for body in range(len(inverse_mass)):
        if inverse_mass[body] > 0.0:
            for x in range(3):
                v[body, x] += h * accel[body, x]
        if bodies.inverse_principal[body, 0] > 0.0:
            w = _gyroscopic(bodies, body, h, sub.gyroscopic)
            omega[body, 0], omega[body, 1], omega[body, 2] = w


@njit(cache=True)
def integrate_positions(bodies, sub):
    """q += h v and the orientation turned by h omega; the move and the turn since the step's start kept."""
    q, v, dq, omega, h = bodies.q, bodies.v, bodies.dq, bodies.omega, sub.h
    for body in range(len(q)):
        for x in range(3):
            q[body, x] += h * v[body, x]
            dq[body, x] += h * v[body, x]
        if bodies.inverse_principal[body, 0] > 0.0:
            w = _row(omega, body)
            _turn(bodies.orientation, body, w, h, sub.update)
            _turn(bodies.turn, body, w, h, sub.update)


@njit(cache=True, inline="always")
def _solve_normal(bodies, contacts, k, sub, use_bias, s, la, lb):
    n = _row(contacts.normal, k)
    vn = dot3(_relative_velocity(bodies, contacts, k, la, lb), n)
    scale, leak = 1.0, 0.0
    if s > 0.0:
        bias = s / sub.h  # speculative: may close the gap in this substep, not more
    elif use_bias:
        bias = max(sub.bias_rate * min(s + sub.slop, 0.0), -sub.push_speed)
        scale, leak = sub.mass_scale, sub.impulse_scale
    else:
        bias = 0.0
    pn = contacts.pn
    dp = -contacts.mass[k, 0] * scale * (vn + bias) - leak * pn[k]
    total = max(pn[k] + dp, 0.0)
    dp = total - pn[k]
    pn[k] = total
    if dp > 0.0 and contacts.hit[k] == np.inf:  # the impact: the speed it bounces back from
        contacts.hit[k] = vn
    _apply(bodies, contacts, k, la, lb, (dp * n[0], dp * n[1], dp * n[2]))


@njit(cache=True, inline="always")
def _solve_friction(bodies, contacts, k, la, lb):
    """Both tangential impulses, then the pair kept in the disc |P_t| <= mu P."""
    tangent, pt, mass = contacts.tangent, contacts.pt, contacts.mass
    u = _relative_velocity(bodies, contacts, k, la, lb)
    t1 = (tangent[k, 0, 0], tangent[k, 0, 1], tangent[k, 0, 2])
    t2 = (tangent[k, 1, 0], tangent[k, 1, 1], tangent[k, 1, 2])
    p1 = pt[k, 0] - mass[k, 1] * dot3(u, t1)
    p2 = pt[k, 1] - mass[k, 2] * dot3(u, t2)
    limit = contacts.friction[k] * contacts.pn[k]
    size = np.sqrt(p1 * p1 + p2 * p2)
    if size > limit:  # outside the friction cone: slide, at most mu P
        f = limit / size
        p1, p2 = p1 * f, p2 * f
    d1, d2 = p1 - pt[k, 0], p2 - pt[k, 1]
    pt[k, 0], pt[k, 1] = p1, p2
    _apply(bodies, contacts, k, la, lb, (d1 * t1[0] + d2 * t2[0], d1 * t1[1] + d2 * t2[1], d1 * t1[2] + d2 * t2[2]))


@njit(cache=True, inline="always")
def _solve_rolling(bodies, contacts, k):
    """An angular impulse against the relative rolling velocity (across n), |M| <= c_r P.

    Its effective mass is taken from the trace of I_a^-1 + I_b^-1 (exact when both inverse
    inertias are multiples of the identity, as a sphere's; a fair scale otherwise)."""
    a, b = contacts.a[k], contacts.b[k]
    inverse_inertia, pr = bodies.inverse_inertia, contacts.pr
    trace = inverse_inertia[a, 0, 0] + inverse_inertia[a, 1, 1] + inverse_inertia[a, 2, 2]
    w = _row(bodies.omega, a)
    w = (-w[0], -w[1], -w[2])
    if b >= 0:
        trace += inverse_inertia[b, 0, 0] + inverse_inertia[b, 1, 1] + inverse_inertia[b, 2, 2]
        w = (w[0] + bodies.omega[b, 0], w[1] + bodies.omega[b, 1], w[2] + bodies.omega[b, 2])
    if trace <= 0.0:
        return
    n = _row(contacts.normal, k)
    along = dot3(w, n)
    m = 3.0 / trace
    p = (pr[k, 0] - m * (w[0] - along * n[0]), pr[k, 1] - m * (w[1] - along * n[1]),
         pr[k, 2] - m * (w[2] - along * n[2]))
    limit = contacts.rolling[k] * contacts.pn[k]
    size = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    f = limit / size if size > limit else 1.0
    d = (p[0] * f - pr[k, 0], p[1] * f - pr[k, 1], p[2] * f - pr[k, 2])
    for x in range(3):
        pr[k, x] += d[x]
    _apply_angular(bodies, contacts, k, d)


@njit(cache=True)
def _sweep(bodies, contacts, sub, use_bias):
    """One Gauss-Seidel sweep over the contacts: the normal impulse, then friction and rolling."""
    for k in range(len(contacts.a)):
        s, la, lb = _geometry(bodies, contacts, k)
        _solve_normal(bodies, contacts, k, sub, use_bias, s, la, lb)
        if contacts.friction[k] > 0.0:
            _solve_friction(bodies, contacts, k, la, lb)
        if contacts.rolling[k] > 0.0:
            _solve_rolling(bodies, contacts, k)


@njit(cache=True)
def warm_start(bodies, contacts):
    """Each contact's impulses of the last substep applied again: a good first guess."""
    for k in range(len(contacts.a)):
        pn, p1, p2 = contacts.pn[k], contacts.pt[k, 0], contacts.pt[k, 1]
        n, t = contacts.normal, contacts.tangent
        p = (pn * n[k, 0] + p1 * t[k, 0, 0] + p2 * t[k, 1, 0], pn * n[k, 1] + p1 * t[k, 0, 1] + p2 * t[k, 1, 1],
             pn * n[k, 2] + p1 * t[k, 0, 2] + p2 * t[k, 1, 2])
        _, la, lb = _geometry(bodies, contacts, k)
        _apply(bodies, contacts, k, la, lb, p)
        _apply_angular(bodies, contacts, k, (contacts.pr[k, 0], contacts.pr[k, 1], contacts.pr[k, 2]))


@njit(cache=True)
def substep(bodies, contacts, sub):
    """One substep of ``sub.h``: velocities, warm start, solve, positions, relax."""
    integrate_velocities(bodies, sub)
    warm_start(bodies, contacts)
    for _ in range(sub.iterations):
        _sweep(bodies, contacts, sub, True)
    integrate_positions(bodies, sub)
    for _ in range(sub.iterations):
        _sweep(bodies, contacts, sub, False)
    for k in range(len(contacts.a)):
        contacts.total[k] += contacts.pn[k]
        contacts.most[k] = max(contacts.most[k], contacts.pn[k])


@njit(cache=True, inline="always")
def _energy_line(bodies, body, v, w, dv, dw):
    """(e, g, c): body's kinetic energy along v + x dv, w + x dw is e + x g + x^2 c / 2, J.

    The spin's energy is 1/2 sum I_j s_j^2, s = R^T omega in the body frame of the orientation now."""
    m = 1.0 / bodies.inverse_mass[body] if bodies.inverse_mass[body] > 0.0 else 0.0
    e, g, c = 0.5 * m * dot3(v, v), m * dot3(v, dv), m * dot3(dv, dv)
    if bodies.inverse_principal[body, 0] > 0.0:
        s = _rotate_inverse(bodies.orientation, body, w)
        ds = _rotate_inverse(bodies.orientation, body, dw)
        for x in range(3):
            inertia = 1.0 / bodies.inverse_principal[body, x]
            e += 0.5 * inertia * s[x] * s[x]
            g += inertia * s[x] * ds[x]
            c += inertia * ds[x] * ds[x]
    return e, g, c


@njit(cache=True)
def kinetic_energies(bodies):
    """(N,) each body's kinetic energy, 1/2 m v^2 + 1/2 omega . I omega, J."""
    out = np.zeros(len(bodies.q))
    zero = (0.0, 0.0, 0.0)
    for body in range(len(out)):
        out[body] = _energy_line(bodies, body, _row(bodies.v, body), _row(bodies.omega, body), zero, zero)[0]
    return out


@njit(cache=True)
def _island(parent, body):
    """The root of body's island (union-find with path halving)."""
    while parent[body] != body:
        parent[body] = parent[parent[body]]
        body = parent[body]
    return body


@njit(cache=True)
def _restitution(bodies, contacts, sub):
    """The restitution pass's extra normal impulses, applied; returns them, (C,).

    v_n is driven to -eps v_n- for the contacts hit in the step (an impulse in some substep) whose
    approach v_n- is faster than their threshold, the accumulated impulse kept >= 0. v_n- is the
    slower of the approach at the step's start (``vn0``) and just before the contact's first impulse
    (``hit``): the first alone is wrong for a tumbling box's corner, which strikes at another
    speed than it had at the step's start; the second alone is wrong in a chain (a cradle), where
    the speed just before a contact's first impulse was raised by its neighbour's impulse in the
    same step: bouncing that back too gave the cradle 1.31 times its energy."""
    count = len(contacts.a)
    extra = np.zeros(count)
    for _ in range(sub.iterations):
        for k in range(count):
            approach = max(contacts.vn0[k], contacts.hit[k])  # +inf: never hit in the step
            if approach >= -contacts.threshold[k]:
                continue
            n = _row(contacts.normal, k)
            _, la, lb = _geometry(bodies, contacts, k)
            vn = dot3(_relative_velocity(bodies, contacts, k, la, lb), n)
            dp = -contacts.mass[k, 0] * (vn + contacts.restitution[k] * approach)
            accumulated = max(contacts.pn[k] + extra[k] + dp, 0.0)
            dp = accumulated - contacts.pn[k] - extra[k]
            extra[k] += dp
            _apply(bodies, contacts, k, la, lb, (dp * n[0], dp * n[1], dp * n[2]))
    return extra


@njit(cache=True)
def _limit_to_the_energy_taken(bodies, contacts, extra, v1, w1):
    """Each island's restitution impulses scaled by the largest a in [0, 1] that gives back no more
    kinetic energy than the step took from it.

    An island is a set of bodies joined by contacts the pass pushed. Its kinetic energy along the
    pass's impulses scaled by a is E(a) = E1 + a G + a^2 C / 2 (C >= 0), E1 before the pass; the
    step took D = E0 + W - E1 from it, E0 its energy at the step's start and W = sum m a . dq the
    forces' work (exact for constant forces). Why a limit is needed at all: a pass that brings the
    closing contacts from v_n = 0 to the targets u_k = -eps_k v_k- returns 1/2 u^T A^-1 u (A = J M^-1
    J^T, the Delassus matrix), while the substeps took 1/2 w^T A^-1 w from the approach w = J v0 of
    one velocity state. The targets are not that state's (each contact's v_k- is its own, taken
    at its own time through its own levers), and A^-1 has off-diagonal terms of either sign, so
    |u_k| <= |w_k| for every k does not give u^T A^-1 u <= w^T A^-1 w: a box's corners on the
    floor gave back up to 2.6 % more than they took in a step (seeded piles, eps = 1). Limiting
    E(a) - E1 to max(D, 0) keeps E_end <= E0 + W, what eps <= 1 promises; where the pass stays
    within it (the cradle, a lone contact) a = 1 and nothing changes. Impulses scaled together
    keep the island's momenta."""
    n = len(bodies.q)
    parent = np.arange(n)
    for k in range(len(extra)):
        a, b = contacts.a[k], contacts.b[k]
        if extra[k] != 0.0 and b >= 0:
            parent[_island(parent, a)] = _island(parent, b)
    budget, slope, curve = np.zeros(n), np.zeros(n), np.zeros(n)
    for body in range(n):
        v, w = _row(v1, body), _row(w1, body)
        dv = (bodies.v[body, 0] - v[0], bodies.v[body, 1] - v[1], bodies.v[body, 2] - v[2])
        dw = (bodies.omega[body, 0] - w[0], bodies.omega[body, 1] - w[1], bodies.omega[body, 2] - w[2])
        e1, g, c = _energy_line(bodies, body, v, w, dv, dw)
        m = 1.0 / bodies.inverse_mass[body] if bodies.inverse_mass[body] > 0.0 else 0.0
        root = _island(parent, body)
        budget[root] += bodies.energy[body] + m * dot3(_row(bodies.accel, body), _row(bodies.dq, body)) - e1
        slope[root] += g
        curve[root] += c
    scale = np.ones(n)
    for root in range(n):
        allowed = max(budget[root], 0.0)
        if parent[root] != root or slope[root] + 0.5 * curve[root] <= allowed:
            continue
        if curve[root] > 0.0:  # the positive root of a^2 C / 2 + a G - allowed
            scale[root] = (-slope[root] + np.sqrt(slope[root] ** 2 + 2.0 * curve[root] * allowed)) / curve[root]
        else:
            scale[root] = allowed / slope[root]
    for body in range(n):
        f = scale[_island(parent, body)]
        if f < 1.0:
            for x in range(3):
                bodies.v[body, x] = v1[body, x] + f * (bodies.v[body, x] - v1[body, x])
                bodies.omega[body, x] = w1[body, x] + f * (bodies.omega[body, x] - w1[body, x])
    for k in range(len(extra)):
        extra[k] *= scale[_island(parent, contacts.a[k])]


@njit(cache=True)
def finish(bodies, contacts, sub):
    """The end of a step: the largest residual, then the restitution pass; returns the residual.

    The residual of contact k is |min(v_n + max(s, 0) / h, P / m_n)| (m/s), the natural residual
    of its complementarity condition, as in :func:`.sequential_impulses.finish`. The restitution
    pass (:func:`_restitution`) then bounces the contacts hit, each island's impulses limited to
    the energy the step took from it (:func:`_limit_to_the_energy_taken`): with eps <= 1 no
    island ends a step with more kinetic energy than it started with plus the forces' work.
    """
    count = len(contacts.a)
    residual = 0.0
    for k in range(count):
        s, la, lb = _geometry(bodies, contacts, k)
        vn = dot3(_relative_velocity(bodies, contacts, k, la, lb), _row(contacts.normal, k))
        mass = contacts.mass[k, 0]
        residual = max(residual, abs(min(vn + max(s, 0.0) / sub.h, contacts.pn[k] / mass if mass > 0 else 0.0)))
    v1, w1 = bodies.v.copy(), bodies.omega.copy()
    extra = _restitution(bodies, contacts, sub)
    _limit_to_the_energy_taken(bodies, contacts, extra, v1, w1)
    for k in range(count):
        contacts.total[k] += extra[k]
    return residual


@njit(cache=True)
def step(bodies, contacts, sub, substeps):
    """A whole step under constant accelerations: ``substeps`` substeps, then :func:`finish`."""
    for _ in range(substeps):
        substep(bodies, contacts, sub)
    return finish(bodies, contacts, sub)


@njit(cache=True)
def previous_rows(old, new):
    """Each new contact's row among the last step's, matched by (a, b, feature), or -1.

    ``old`` and ``new`` are (C, 3) int64 keys sorted lexicographically: one merge."""
    rows = np.full(len(new), -1, dtype=np.int64)
    p = 0
    for k in range(len(new)):
        while p < len(old) and (old[p, 0] < new[k, 0] or (old[p, 0] == new[k, 0] and (
                old[p, 1] < new[k, 1] or (old[p, 1] == new[k, 1] and old[p, 2] < new[k, 2])))):
            p += 1
        if p < len(old) and old[p, 0] == new[k, 0] and old[p, 1] == new[k, 1] and old[p, 2] == new[k, 2]:
            rows[k] = p
    return rows
