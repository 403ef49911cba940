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
from numba import njit, prange

from .contact_domains import bodies_of, groups_in, phases, rows_of, span
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
    s: np.ndarray  # the separation now, m (:func:`_geometry`)
    la: np.ndarray  # (C, 3) the lever from a's centre to the point now, m
    lb: np.ndarray  # (C, 3) the lever from b's centre to the point now, m


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
    any_rolling: bool  # whether some contact has rolling resistance (else ``pr`` stays zero and is not read)


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
    _turn_by(q, k, _half_turn(w, h, update))


@njit(cache=True, inline="always")
def _half_turn(w, h, update):
    """The quaternion of the turn by h w (world frame): exp(h w / 2), or its first-order 1 + h w / 2."""
    if update == EXPONENTIAL:
        x = 0.5 * h * np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])  # the half angle
        c = np.cos(x)
        s = 0.5 * h * (np.sin(x) / x if x > 1e-8 else 1.0 - x * x / 6.0)  # sin(x) / |w|, exact to round-off
    else:
        c, s = 1.0, 0.5 * h
    return c, s * w[0], s * w[1], s * w[2]


@njit(cache=True, inline="always")
def _turn_by(q, k, p):
    """q[k] <- p q[k], normalised."""
    p0, p1, p2, p3 = p
    q0, q1, q2, q3 = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
    r0 = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    r1 = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    r2 = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    r3 = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0
    size = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    q[k, 0], q[k, 1], q[k, 2], q[k, 3] = r0 / size, r1 / size, r2 / size, r3 / size


@njit(cache=True, inline="always")
def _world_inverse_inertia(orientation, inverse_principal, body, out):
    """out[body] = R diag(1/I1, 1/I2, 1/I3) R^T, R's columns the body's axes, the unit vectors turned
    by its quaternion (NumPy's three-operand einsum took 2-4 ms for 10^4 bodies)."""
    r0 = rotate(orientation, body, (1.0, 0.0, 0.0))
    r1 = rotate(orientation, body, (0.0, 1.0, 0.0))
    r2 = rotate(orientation, body, (0.0, 0.0, 1.0))
    d0, d1, d2 = inverse_principal[body, 0], inverse_principal[body, 1], inverse_principal[body, 2]
    for i in range(3):
        for k in range(3):
            out[body, i, k] = r0[i] * d0 * r0[k] + r1[i] * d1 * r1[k] + r2[i] * d2 * r2[k]


# --- the contact's kinematics ---------------------------------------------------------------
#
# Every kernel below takes the columns it needs out of the NamedTuples once, before its loop, and
# its inline helpers take arrays or small tuples of them: a field read from the NamedTuple inside
# the loop cost Numba a reference count taken and dropped per read, which made a sweep over the
# pyramid's 2,360 contacts 6 times slower (1.34 ms against 0.23 ms, the same numbers).

@njit(cache=True, inline="always")
def _state(bodies):
    """The columns an impulse changes and reads: (v, omega, 1/m, I_w^-1)."""
    return bodies.v, bodies.omega, bodies.inverse_mass, bodies.inverse_inertia


@njit(cache=True, inline="always")
def _geometry(moves, a, b, n, ra, rb, s0):
    """(s, la, lb) now: a contact's separation and the levers from each centre to its point.

    ``moves`` = (q, dq, turn, rounding) of the bodies. Each body's surface point is its core point
    (the lever c above) turned with the body, plus its rounding along n. Both bodies take the
    impulse at the midpoint of their two surface points, one point, so a body-body contact keeps
    angular momentum to round-off however far the bodies have moved since the start of the step
    (with the levers of the start, an oblique hit at 3 m/s lost 10 % of it)."""
    q, dq, turn, rounding = moves
    rho = rounding[a]
    ca = (ra[0] - rho * n[0], ra[1] - rho * n[1], ra[2] - rho * n[2])
    ta = rotate(turn, a, ca)
    pa = (ta[0] + rho * n[0], ta[1] + rho * n[1], ta[2] + rho * n[2])
    da = (dq[a, 0] + ta[0] - ca[0], dq[a, 1] + ta[1] - ca[1], dq[a, 2] + ta[2] - ca[2])
    if b < 0:
        return s0 - dot3(da, n), pa, pa
    rho = rounding[b]
    cb = (rb[0] + rho * n[0], rb[1] + rho * n[1], rb[2] + rho * n[2])
    tb = rotate(turn, b, cb)
    db = (dq[b, 0] + tb[0] - cb[0], dq[b, 1] + tb[1] - cb[1], dq[b, 2] + tb[2] - cb[2])
    s = s0 + dot3((db[0] - da[0], db[1] - da[1], db[2] - da[2]), n)
    d = (q[b, 0] - q[a, 0], q[b, 1] - q[a, 1], q[b, 2] - q[a, 2])
    pb = (tb[0] - rho * n[0], tb[1] - rho * n[1], tb[2] - rho * n[2])
    la = (0.5 * (pa[0] + d[0] + pb[0]), 0.5 * (pa[1] + d[1] + pb[1]), 0.5 * (pa[2] + d[2] + pb[2]))
    return s, la, (la[0] - d[0], la[1] - d[1], la[2] - d[2])


@njit(cache=True)
def _geometry_rows(bodies, contacts, rows):
    """Each contact's separation and levers now (:func:`_geometry`) into ``s``, ``la``, ``lb``, for the
    contacts ``rows`` = (first, end) (at the start of the step: :func:`prepare`; after each position
    stage the first relax sweep computes them, :func:`_sweep_rows`)."""
    moves = (bodies.q, bodies.dq, bodies.turn, bodies.rounding)
    a_, b_, normal, ra, rb, s0 = contacts.a, contacts.b, contacts.normal, contacts.ra, contacts.rb, contacts.s0
    separation, lever_a, lever_b = contacts.s, contacts.la, contacts.lb
    for k in range(rows[0], rows[1]):
        separation[k], la, lb = _geometry(moves, a_[k], b_[k], _row(normal, k), _row(ra, k), _row(rb, k), s0[k])
        for x in range(3):
            lever_a[k, x], lever_b[k, x] = la[x], lb[x]


@njit(cache=True, inline="always")
def _bodies(state, a, b):
    """Bodies a and b's (v, omega) as tuples, which a point's impulses then change in registers
    (:func:`_sweep_rows`); b < 0, a static shape: zeros. ``state`` = :func:`_state`."""
    v, omega = state[0], state[1]
    zero = (0.0, 0.0, 0.0)
    return (_row(v, a), _row(omega, a)), ((_row(v, b), _row(omega, b)) if b >= 0 else (zero, zero))


@njit(cache=True, inline="always")
def _store(state, i, body):
    """Body i's (v, omega) back from registers."""
    v, omega = state[0], state[1]
    v[i, 0], v[i, 1], v[i, 2] = body[0]
    omega[i, 0], omega[i, 1], omega[i, 2] = body[1]


@njit(cache=True, inline="always")
def _relative(ba, bb, b, la, lb):
    """(v_b + omega_b x l_b) - (v_a + omega_a x l_a) at a contact of bodies ``ba`` and ``bb``
    (:func:`_bodies`; b < 0: a static shape)."""
    va, wa = ba[0], cross3(ba[1], la)
    ua = (va[0] + wa[0], va[1] + wa[1], va[2] + wa[2])
    if b < 0:
        return -ua[0], -ua[1], -ua[2]
    vb, wb = bb[0], cross3(bb[1], lb)
    return vb[0] + wb[0] - ua[0], vb[1] + wb[1] - ua[1], vb[2] + wb[2] - ua[2]


@njit(cache=True, inline="always")
def _relative_velocity(v, omega, a, b, la, lb):
    """:func:`_relative` of bodies a and b read from the arrays."""
    pair = _bodies((v, omega), a, b)
    return _relative(pair[0], pair[1], b, la, lb)


@njit(cache=True, inline="always")
def _apply(pair, state, a, b, la, lb, p):
    """``pair`` = bodies a and b's (v, omega) after the impulse p on body b, -p on body a: dv = p / m,
    d omega = I^-1 (l x p), 1/m and I^-1 from ``state``."""
    (va, wa), (vb, wb) = pair
    inverse_mass, inverse_inertia = state[2], state[3]
    ma, ja = inverse_mass[a], _matrix_times(inverse_inertia, a, cross3(la, p))
    ba = ((va[0] - ma * p[0], va[1] - ma * p[1], va[2] - ma * p[2]), (wa[0] - ja[0], wa[1] - ja[1], wa[2] - ja[2]))
    if b < 0:
        return ba, pair[1]
    mb, jb = inverse_mass[b], _matrix_times(inverse_inertia, b, cross3(lb, p))
    return ba, ((vb[0] + mb * p[0], vb[1] + mb * p[1], vb[2] + mb * p[2]),
                (wb[0] + jb[0], wb[1] + jb[1], wb[2] + jb[2]))


@njit(cache=True, inline="always")
def _apply_angular(pair, state, a, b, m):
    """``pair`` after the angular impulse m on body b, -m on body a."""
    (va, wa), (vb, wb) = pair
    inverse_inertia = state[3]
    ja = _matrix_times(inverse_inertia, a, m)
    ba = (va, (wa[0] - ja[0], wa[1] - ja[1], wa[2] - ja[2]))
    if b < 0:
        return ba, pair[1]
    jb = _matrix_times(inverse_inertia, b, m)
    return ba, (vb, (wb[0] + jb[0], wb[1] + jb[1], wb[2] + jb[2]))


# --- the stages -----------------------------------------------------------------------------

@njit(cache=True, parallel=True)
def prepare(bodies, contacts, layout):
    """Each contact's effective masses along n, t1, t2 (into ``contacts.mass``), v_n at the start,
    and its separation and levers (:func:`_geometry_rows`); each contact's own, group by group as the
    sweep takes them (:func:`_sweep`), so each row is left in the cache of the thread that sweeps it."""
    for phase in range(phases(layout)):
        for g in prange(groups_in(layout, phase)):
            rows = rows_of(layout, phase, g)
            _prepare_rows(bodies, contacts, rows)
            _geometry_rows(bodies, contacts, rows)


@njit(cache=True)
def _prepare_rows(bodies, contacts, rows):
    """:func:`prepare`'s masses and v_n of the contacts ``rows`` = (first, end)."""
    a_, b_, ra, rb, normal = contacts.a, contacts.b, contacts.ra, contacts.rb, contacts.normal
    tangent, mass, vn0 = contacts.tangent, contacts.mass, contacts.vn0
    v, omega, inverse_mass, inverse_inertia = _state(bodies)
    for k in range(rows[0], rows[1]):
        a, b = a_[k], b_[k]
        for d in range(3):
            axis = _row(normal, k) if d == 0 else (tangent[k, d - 1, 0], tangent[k, d - 1, 1], tangent[k, d - 1, 2])
            ca = cross3(_row(ra, k), axis)
            inverse = inverse_mass[a] + dot3(ca, _matrix_times(inverse_inertia, a, ca))
            if b >= 0:
                cb = cross3(_row(rb, k), axis)
                inverse += inverse_mass[b] + dot3(cb, _matrix_times(inverse_inertia, b, cb))
            mass[k, d] = 1.0 / inverse if inverse > 0.0 else 0.0
        vn0[k] = dot3(_relative_velocity(v, omega, a, b, _row(ra, k), _row(rb, k)), _row(normal, k))


@njit(cache=True, inline="always")
def _gyroscopic(spin, body, h, kind):
    """omega of one body after the gyroscopic term over h (body frame, principal axes);
    ``spin`` = (omega, orientation, 1/I principal)."""
    omega, orientation, inverse_principal = spin
    inverse = _row(inverse_principal, body)
    w = _rotate_inverse(orientation, body, _row(omega, body))
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
        rhs = np.array([h * g[0], h * g[1], h * g[2]])
        if np.all(np.isfinite(jacobian)) and np.all(np.isfinite(rhs)):
            step = np.linalg.solve(jacobian, rhs)
        else:  # a spin that overflowed: NaN on, for the step's check to name the body (solve would raise)
            step = np.full(3, np.nan)
        w1 = (w[0] - step[0], w[1] - step[1], w[2] - step[2])
    else:
        w1 = (w[0] - h * inverse[0] * g[0], w[1] - h * inverse[1] * g[1], w[2] - h * inverse[2] * g[2])
        if kind == RESCALED:  # |I omega| kept: the explicit step's growth of |L| undone
            before = np.sqrt(dot3(momentum, momentum))
            m1 = (inertia[0] * w1[0], inertia[1] * w1[1], inertia[2] * w1[2])
            after = np.sqrt(dot3(m1, m1))
            f = before / after if after > 0.0 else 1.0
            w1 = (w1[0] * f, w1[1] * f, w1[2] * f)
    return rotate(orientation, body, w1)


@njit(cache=True, parallel=True)
def integrate_velocities(bodies, sub, layout):
    """v += h a for every movable body; the gyroscopic term for every rotating one (each body its
    own: the domains in parallel, each on the thread that sweeps its contacts)."""
    for domain in prange(len(layout.body_start) - 1):
        _velocities_of(bodies, sub, layout.bodies, bodies_of(layout, domain))


@njit(cache=True)
def _velocities_of(bodies, sub, order, span_):
    """:func:`integrate_velocities` of the bodies ``order[span_[0]:span_[1]]``."""
    v, omega, inverse_mass, accel, h = bodies.v, bodies.omega, bodies.inverse_mass, bodies.accel, sub.h
    inverse_principal, kind = bodies.inverse_principal, sub.gyroscopic
    spin = (omega, bodies.orientation, inverse_principal)
    for i in range(span_[0], span_[1]):
        body = order[i]
        if inverse_mass[body] > 0.0:
            for x in range(3):
                v[body, x] += h * accel[body, x]
        if inverse_principal[body, 0] > 0.0:
            w = _gyroscopic(spin, body, h, kind)
            omega[body, 0], omega[body, 1], omega[body, 2] = w


@njit(cache=True, parallel=True)
def integrate_positions(bodies, sub, layout):
    """q += h v and the orientation turned by h omega; the move and the turn since the step's start
    kept (each body its own: the domains in parallel, as :func:`integrate_velocities`)."""
    for domain in prange(len(layout.body_start) - 1):
        _positions_of(bodies, sub, layout.bodies, bodies_of(layout, domain))


@njit(cache=True)
def _positions_of(bodies, sub, order, span_):
    """:func:`integrate_positions` of the bodies ``order[span_[0]:span_[1]]``."""
    q, v, dq, omega, h, update = bodies.q, bodies.v, bodies.dq, bodies.omega, sub.h, sub.update
    orientation, turn, inverse_principal = bodies.orientation, bodies.turn, bodies.inverse_principal
    for i in range(span_[0], span_[1]):
        body = order[i]
        for x in range(3):
            q[body, x] += h * v[body, x]
            dq[body, x] += h * v[body, x]
        if inverse_principal[body, 0] > 0.0:
            p = _half_turn(_row(omega, body), h, update)  # one sine and cosine for both
            _turn_by(orientation, body, p)
            _turn_by(turn, body, p)


@njit(cache=True, inline="always")
def _bias(sub, s, use_bias):
    """(bias, mass scale, impulse scale) of a contact at separation s: speculative (s > 0, it
    may close the gap in this substep, not more), the soft push out of a penetration (biased
    sweeps), or none (relax)."""
    if s > 0.0:
        return s / sub.h, 1.0, 0.0
    if use_bias:
        return max(sub.bias_rate * min(s + sub.slop, 0.0), -sub.push_speed), sub.mass_scale, sub.impulse_scale
    return 0.0, 1.0, 0.0


@njit(cache=True, inline="always")
def _solve_friction(pair, state, tangential, k, a, b, la, lb):
    """``pair`` (:func:`_apply`) after both tangential impulses, the pair kept in the disc |P_t| <= mu P;
    ``tangential`` = (tangent, pt, mass, friction, pn)."""
    tangent, pt, mass, friction, pn = tangential
    u = _relative(pair[0], pair[1], b, la, lb)
    t1 = (tangent[k, 0, 0], tangent[k, 0, 1], tangent[k, 0, 2])
    t2 = (tangent[k, 1, 0], tangent[k, 1, 1], tangent[k, 1, 2])
    p1 = pt[k, 0] - mass[k, 1] * dot3(u, t1)
    p2 = pt[k, 1] - mass[k, 2] * dot3(u, t2)
    limit = friction[k] * pn[k]
    size = np.sqrt(p1 * p1 + p2 * p2)
    if size > limit:  # outside the friction cone: slide, at most mu P
        f = limit / size
        p1, p2 = p1 * f, p2 * f
    d1, d2 = p1 - pt[k, 0], p2 - pt[k, 1]
    pt[k, 0], pt[k, 1] = p1, p2
    p = (d1 * t1[0] + d2 * t2[0], d1 * t1[1] + d2 * t2[1], d1 * t1[2] + d2 * t2[2])
    return _apply(pair, state, a, b, la, lb, p)


@njit(cache=True, inline="always")
def _solve_rolling(pair, state, rolls, k, a, b, n):
    """``pair`` (:func:`_apply`) after an angular impulse against the relative rolling velocity (across n),
    |M| <= c_r P; ``rolls`` = (pr, rolling, pn).

    Its effective mass is taken from the trace of I_a^-1 + I_b^-1 (exact when both inverse
    inertias are multiples of the identity, as a sphere's; a fair scale otherwise)."""
    pr, rolling, pn = rolls
    inverse_inertia = state[3]
    trace = inverse_inertia[a, 0, 0] + inverse_inertia[a, 1, 1] + inverse_inertia[a, 2, 2]
    w = pair[0][1]
    w = (-w[0], -w[1], -w[2])
    if b >= 0:
        wb = pair[1][1]
        trace += inverse_inertia[b, 0, 0] + inverse_inertia[b, 1, 1] + inverse_inertia[b, 2, 2]
        w = (w[0] + wb[0], w[1] + wb[1], w[2] + wb[2])
    if trace <= 0.0:
        return pair
    along = dot3(w, n)
    m = 3.0 / trace
    p = (pr[k, 0] - m * (w[0] - along * n[0]), pr[k, 1] - m * (w[1] - along * n[1]),
         pr[k, 2] - m * (w[2] - along * n[2]))
    limit = rolling[k] * pn[k]
    size = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    f = limit / size if size > limit else 1.0
    d = (p[0] * f - pr[k, 0], p[1] * f - pr[k, 1], p[2] * f - pr[k, 2])
    for x in range(3):
        pr[k, x] += d[x]
    return _apply_angular(pair, state, a, b, d)


@njit(cache=True, inline="always")
def _holds_nothing(pt, pr, k, any_rolling):
    """Whether contact k holds no tangential and no rolling impulse. ``pr`` is read only where
    ``any_rolling`` (:attr:`RigidSubstep.any_rolling`; else it is zero): left unread, its 24 bytes a
    point made the 10^4 box pit's two sweeps of a substep 7 % faster (the sweeps wait on memory)."""
    held = pt[k, 0] != 0.0 or pt[k, 1] != 0.0
    return not held and not (any_rolling and (pr[k, 0] != 0.0 or pr[k, 1] != 0.0 or pr[k, 2] != 0.0))


@njit(cache=True, parallel=True)
def _sweep(bodies, contacts, sub, use_bias, layout, geometry):
    """One Gauss-Seidel sweep over the contacts, phase by phase (:mod:`.contact_domains`): each
    contact's normal impulse, then friction and rolling. The groups of a phase share no body: each
    is swept by one thread, all at once, the same bytes as one after the other. (Calling the sweep's
    kernel outside a parallel region for a phase of one group made it 1.5 times slower: Numba's code
    for a parallel loop's body is faster.)"""
    for phase in range(phases(layout)):
        for g in prange(groups_in(layout, phase)):
            _sweep_rows(bodies, contacts, (sub, use_bias, geometry), rows_of(layout, phase, g))


@njit(cache=True)
def _sweep_rows(bodies, contacts, how, rows_):
    """:func:`_sweep` over the contacts ``rows_`` = (first, end); ``how`` = (the substep, whether the bias
    pushes, whether to compute each point's separation and levers first).

    The separation and levers depend on the bodies' moves alone, which change only in the position
    stage: the first relax sweep after it computes them (:func:`_geometry`) and keeps them for the
    other relax sweeps of that substep, the warm start and the biased sweeps of the next, and the end
    of the step. (A pass of their own over the contacts took 1.3 ms of the 10^4 box pit's step on 2
    threads, most of it reading the contacts' columns that the sweep then reads again.)

    Each point reads its two bodies' velocities into registers, applies its impulses there and
    writes them back once: the same arithmetic in the same order as changing the arrays impulse by
    impulse (which the compiler cannot do itself: it cannot prove the arrays apart), and measured
    alike (the 10^4 box pit's warm start at step 20, one thread: 0.43 against 0.45 ms). Keeping them
    in registers over all of a manifold's points was slower (0.54 ms): it reads the bodies of
    manifolds none of whose points holds an impulse.

    A contact whose impulse does not change applies none, and one that ends the pass unpressed
    (P = 0) and holding no friction or rolling impulse skips them: both are clamped to zero, so
    the step is the same numbers without them (a zero impulse can at most turn a velocity of -0.0
    into +0.0). Most points of a falling pile are such, speculative points that are never pressed:
    75 to 100 % of the 10^4 box pit's in its first 30 steps, which made the skip halve its sweeps."""
    sub, use_bias, geometry = how
    state = _state(bodies)
    moves = (bodies.q, bodies.dq, bodies.turn, bodies.rounding)
    ra, rb, s0 = contacts.ra, contacts.rb, contacts.s0
    a_, b_, normal, separation = contacts.a, contacts.b, contacts.normal, contacts.s
    lever_a, lever_b, pn, mass, hit = contacts.la, contacts.lb, contacts.pn, contacts.mass, contacts.hit
    friction, rolling, pt, pr = contacts.friction, contacts.rolling, contacts.pt, contacts.pr
    tangential = (contacts.tangent, pt, mass, friction, pn)
    rolls, any_rolling = (pr, rolling, pn), sub.any_rolling
    for k in range(rows_[0], rows_[1]):
        a, b = a_[k], b_[k]
        n = _row(normal, k)
        if geometry:  # as _geometry_rows; written out: a helper taking the columns as a tuple made the
            # solver 3 % slower (in one process, alternating with the separate pass it replaces)
            separation[k], la, lb = _geometry(moves, a, b, n, _row(ra, k), _row(rb, k), s0[k])
            for x in range(3):
                lever_a[k, x], lever_b[k, x] = la[x], lb[x]
        else:
            la = _row(lever_a, k)
            lb = _row(lever_b, k)
        pair, moved = _bodies(state, a, b), False
        vn = dot3(_relative(pair[0], pair[1], b, la, lb), n)
        bias, scale, leak = _bias(sub, separation[k], use_bias)
        dp = -mass[k, 0] * scale * (vn + bias) - leak * pn[k]
        total = max(pn[k] + dp, 0.0)
        dp = total - pn[k]
        pn[k] = total
        if dp > 0.0 and hit[k] == np.inf:  # the impact: the speed it bounces back from
            hit[k] = vn
        if dp != 0.0:
            pair, moved = _apply(pair, state, a, b, la, lb, (dp * n[0], dp * n[1], dp * n[2])), True
        if total != 0.0 or not _holds_nothing(pt, pr, k, any_rolling):
            # (else friction and rolling: clamped to |P_t| <= mu 0 and |M| <= c_r 0, they stay zero)
            if friction[k] > 0.0:
                pair, moved = _solve_friction(pair, state, tangential, k, a, b, la, lb), True
            if any_rolling and rolling[k] > 0.0:
                pair, moved = _solve_rolling(pair, state, rolls, k, a, b, n), True
        if moved:
            _store_pair(state, a, b, pair)


@njit(cache=True, inline="always")
def _store_pair(state, a, b, pair):
    """Bodies a and b's velocities back from registers (b < 0: a static shape, unchanged)."""
    _store(state, a, pair[0])
    if b >= 0:
        _store(state, b, pair[1])


@njit(cache=True, parallel=True)
def warm_start(bodies, contacts, any_rolling, layout):
    """Each contact's impulses of the last substep applied again: a good first guess. Phase by phase, as
    :func:`_sweep`: a body's impulses are added in the one order, whatever the threads. ``any_rolling``: as
    :attr:`RigidSubstep.any_rolling`."""
    for phase in range(phases(layout)):
        for g in prange(groups_in(layout, phase)):
            _warm_rows(bodies, contacts, any_rolling, rows_of(layout, phase, g))


@njit(cache=True)
def _warm_rows(bodies, contacts, any_rolling, rows_):
    """:func:`warm_start` of the contacts ``rows_`` = (first, end) (each point's bodies changed in
    registers, as in :func:`_sweep_rows`)."""
    state = _state(bodies)
    a_, b_, n, t, lever_a, lever_b = contacts.a, contacts.b, contacts.normal, contacts.tangent, contacts.la, contacts.lb
    pn_, pt, pr, rolling = contacts.pn, contacts.pt, contacts.pr, contacts.rolling
    for k in range(rows_[0], rows_[1]):
        if pn_[k] == 0.0 and _holds_nothing(pt, pr, k, any_rolling):
            continue  # no impulse to apply again (a speculative point not yet pressed)
        a, b = a_[k], b_[k]
        pn, p1, p2 = pn_[k], pt[k, 0], pt[k, 1]
        p = (pn * n[k, 0] + p1 * t[k, 0, 0] + p2 * t[k, 1, 0], pn * n[k, 1] + p1 * t[k, 0, 1] + p2 * t[k, 1, 1],
             pn * n[k, 2] + p1 * t[k, 0, 2] + p2 * t[k, 1, 2])
        pair = _apply(_bodies(state, a, b), state, a, b, _row(lever_a, k), _row(lever_b, k), p)
        if any_rolling and rolling[k] > 0.0:
            pair = _apply_angular(pair, state, a, b, _row(pr, k))
        _store_pair(state, a, b, pair)


@njit(cache=True)
def substep(bodies, contacts, sub, layout):
    """One substep of ``sub.h``: velocities, warm start, solve, positions, relax; the contacts in
    the order of ``layout`` (:func:`.contact_domains.lay_out`)."""
    integrate_velocities(bodies, sub, layout)
    warm_start(bodies, contacts, sub.any_rolling, layout)
    for _ in range(sub.iterations):
        _sweep(bodies, contacts, sub, True, layout, False)
    integrate_positions(bodies, sub, layout)
    for iteration in range(sub.iterations):  # the first computes the separations and levers now
        _sweep(bodies, contacts, sub, False, layout, iteration == 0)
    pn, total, most = contacts.pn, contacts.total, contacts.most
    for k in range(len(pn)):
        total[k] += pn[k]
        most[k] = max(most[k], pn[k])


@njit(cache=True, inline="always")
def _energy_line(inertias, body, v, w, dv, dw):
    """(e, g, c): body's kinetic energy along v + x dv, w + x dw is e + x g + x^2 c / 2, J;
    ``inertias`` = (1/m, 1/I principal, orientation).

    The spin's energy is 1/2 sum I_j s_j^2, s = R^T omega in the body frame of the orientation now."""
    inverse_mass, inverse_principal, orientation = inertias
    m = 1.0 / inverse_mass[body] if inverse_mass[body] > 0.0 else 0.0
    e, g, c = 0.5 * m * dot3(v, v), m * dot3(v, dv), m * dot3(dv, dv)
    if inverse_principal[body, 0] > 0.0:
        s = _rotate_inverse(orientation, body, w)
        ds = _rotate_inverse(orientation, body, dw)
        for x in range(3):
            inertia = 1.0 / inverse_principal[body, x]
            e += 0.5 * inertia * s[x] * s[x]
            g += inertia * s[x] * ds[x]
            c += inertia * ds[x] * ds[x]
    return e, g, c


@njit(cache=True, parallel=True)
def start_bodies(bodies, layout):
    """The bodies at the start of a step: no move yet (``dq`` zero, ``turn`` the identity), each one's
    world inverse inertia R diag(1/I1, 1/I2, 1/I3) R^T and kinetic energy 1/2 m v^2 + 1/2 omega . I omega
    (J); each body its own, the domains in parallel, as :func:`integrate_velocities`."""
    for domain in prange(len(layout.body_start) - 1):
        _start_of(bodies, layout.bodies, bodies_of(layout, domain))


@njit(cache=True)
def _start_of(bodies, order, span_):
    """:func:`start_bodies` of the bodies ``order[span_[0]:span_[1]]``."""
    v, omega, dq, turn, energy = bodies.v, bodies.omega, bodies.dq, bodies.turn, bodies.energy
    orientation, inverse_principal = bodies.orientation, bodies.inverse_principal
    inertias = (bodies.inverse_mass, inverse_principal, orientation)
    zero = (0.0, 0.0, 0.0)
    for i in range(span_[0], span_[1]):
        body = order[i]
        for x in range(3):
            dq[body, x] = 0.0
        turn[body, 0], turn[body, 1], turn[body, 2], turn[body, 3] = 1.0, 0.0, 0.0, 0.0
        _world_inverse_inertia(orientation, inverse_principal, body, bodies.inverse_inertia)
        energy[body] = _energy_line(inertias, body, _row(v, body), _row(omega, body), zero, zero)[0]


@njit(cache=True)
def _island(parent, body):
    """The root of body's island (union-find with path halving)."""
    while parent[body] != body:
        parent[body] = parent[parent[body]]
        body = parent[body]
    return body


@njit(cache=True, parallel=True)
def _restitution(bodies, contacts, sub, layout):
    """The restitution pass's extra normal impulses, applied; returns them, (C,), and whether each
    body was given one (N,) (if only a zero).

    v_n is driven to -eps v_n- for the contacts hit in the step (an impulse in some substep) whose
    approach v_n- is faster than their threshold, the accumulated impulse kept >= 0. v_n- is the
    slower of the approach at the step's start (``vn0``) and just before the contact's first impulse
    (``hit``): the first alone is wrong for a tumbling box's corner, which strikes at another
    speed than it had at the step's start; the second alone is wrong in a chain (a cradle), where
    the speed just before a contact's first impulse was raised by its neighbour's impulse in the
    same step: bouncing that back too gave the cradle 1.31 times its energy.

    One Gauss-Seidel pass per iteration in the sweep's order, phase by phase as :func:`_sweep` (a
    phase's groups share no body: each on one thread, all at once, the same bytes as on one)."""
    extra, touched = np.zeros(len(contacts.a)), np.zeros(len(bodies.v), np.bool_)
    for _ in range(sub.iterations):
        for phase in range(phases(layout)):
            for g in prange(groups_in(layout, phase)):
                _restitution_rows(bodies, contacts, (extra, touched), rows_of(layout, phase, g))
    return extra, touched


@njit(cache=True)
def _restitution_rows(bodies, contacts, given, rows_):
    """:func:`_restitution` over the contacts ``rows_`` = (first, end); ``given`` = (extra, touched)
    (each point's bodies changed in registers, as in :func:`_sweep_rows`)."""
    state = _state(bodies)
    a_, b_, normal, lever_a, lever_b = contacts.a, contacts.b, contacts.normal, contacts.la, contacts.lb
    vn0, hit, threshold, mass, restitution, pn = (contacts.vn0, contacts.hit, contacts.threshold, contacts.mass,
                                                  contacts.restitution, contacts.pn)
    extra, touched = given
    for k in range(rows_[0], rows_[1]):
        approach = max(vn0[k], hit[k])  # +inf: never hit in the step
        if approach >= -threshold[k]:
            continue
        a, b, n, la, lb = a_[k], b_[k], _row(normal, k), _row(lever_a, k), _row(lever_b, k)
        pair = _bodies(state, a, b)
        vn = dot3(_relative(pair[0], pair[1], b, la, lb), n)
        dp = -mass[k, 0] * (vn + restitution[k] * approach)
        accumulated = max(pn[k] + extra[k] + dp, 0.0)
        dp = accumulated - pn[k] - extra[k]
        extra[k] += dp
        _store_pair(state, a, b, _apply(pair, state, a, b, la, lb, (dp * n[0], dp * n[1], dp * n[2])))
        touched[a] = True
        if b >= 0:
            touched[b] = True


@njit(cache=True, parallel=True)
def _limit_to_the_energy_taken(bodies, contacts, given, start, layout):
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
    keep the island's momenta. A step whose forces change within it counts each kick's work into E0
    instead and passes a = 0 (``rigid_solver_step._kick_work``).

    ``given`` = (the pass's impulses, whether each body was given one); ``start`` = (v, omega) before
    the pass. An island none of whose bodies was given an impulse has E(a) = E1 for every a (its
    velocities did not change: G = C = 0), so a = 1: its energies are not computed. The others'
    bodies' terms are computed domain by domain in parallel, and summed per island in the bodies' order.
    """
    v, omega, v1, w1 = bodies.v, bodies.omega, start[0], start[1]
    extra, touched = given
    a_, b_ = contacts.a, contacts.b
    n = len(v)
    parent = np.arange(n)
    for k in range(len(extra)):
        if extra[k] != 0.0 and b_[k] >= 0:
            parent[_island(parent, a_[k])] = _island(parent, b_[k])
    root, live = np.empty(n, np.int64), np.zeros(n, np.bool_)
    for body in range(n):
        root[body] = _island(parent, body)
        live[root[body]] |= touched[body]
    terms = np.empty((n, 3))  # each body's part of its island's budget D, slope G and curvature C
    for domain in prange(len(layout.body_start) - 1):
        _energy_terms(bodies, (v1, w1), (root, live), terms, layout.bodies, bodies_of(layout, domain))
    budget, slope, curve = np.zeros(n), np.zeros(n), np.zeros(n)
    for body in range(n):
        if live[root[body]]:
            budget[root[body]] += terms[body, 0]
            slope[root[body]] += terms[body, 1]
            curve[root[body]] += terms[body, 2]
    scale = np.ones(n)
    for r in range(n):
        allowed = max(budget[r], 0.0)
        if not live[r] or parent[r] != r or slope[r] + 0.5 * curve[r] <= allowed:
            continue
        if curve[r] > 0.0:  # the positive root of a^2 C / 2 + a G - allowed
            scale[r] = (-slope[r] + np.sqrt(slope[r] ** 2 + 2.0 * curve[r] * allowed)) / curve[r]
        else:
            scale[r] = allowed / slope[r]
    for body in range(n):
        f = scale[root[body]]
        if f < 1.0:
            for x in range(3):
                v[body, x] = v1[body, x] + f * (v[body, x] - v1[body, x])
                omega[body, x] = w1[body, x] + f * (omega[body, x] - w1[body, x])
    for k in range(len(extra)):
        extra[k] *= scale[root[a_[k]]]


@njit(cache=True)
def _energy_terms(bodies, start, islands, terms, order, span_):
    """:func:`_limit_to_the_energy_taken`'s terms of the bodies ``order[span_[0]:span_[1]]`` in live
    islands: E0 + W - E1, G and C of each."""
    v, omega, inverse_mass, accel, dq, energy = (bodies.v, bodies.omega, bodies.inverse_mass, bodies.accel, bodies.dq,
                                                 bodies.energy)
    inertias = (inverse_mass, bodies.inverse_principal, bodies.orientation)
    v1, w1 = start
    root, live = islands
    for i in range(span_[0], span_[1]):
        body = order[i]
        if not live[root[body]]:
            continue
        vb, wb = _row(v1, body), _row(w1, body)
        dv = (v[body, 0] - vb[0], v[body, 1] - vb[1], v[body, 2] - vb[2])
        dw = (omega[body, 0] - wb[0], omega[body, 1] - wb[1], omega[body, 2] - wb[2])
        e1, g, c = _energy_line(inertias, body, vb, wb, dv, dw)
        m = 1.0 / inverse_mass[body] if inverse_mass[body] > 0.0 else 0.0
        terms[body, 0] = energy[body] + m * dot3(_row(accel, body), _row(dq, body)) - e1
        terms[body, 1], terms[body, 2] = g, c


@njit(cache=True)
def finish(bodies, contacts, sub, layout):
    """The end of a step: the largest residual, then the restitution pass; returns the residual.

    The residual of contact k is |min(v_n + max(s, 0) / h, P / m_n)| (m/s), the natural residual
    of its complementarity condition, as in :func:`.sequential_impulses.finish` (each contact its
    own: group by group in parallel, the largest of theirs). The restitution
    pass (:func:`_restitution`) then bounces the contacts hit, each island's impulses limited to
    the energy the step took from it (:func:`_limit_to_the_energy_taken`): with eps <= 1 no
    island ends a step with more kinetic energy than it started with plus the forces' work.
    """
    residual = _largest_residual(bodies, contacts, sub, layout)
    start = (bodies.v.copy(), bodies.omega.copy())
    given = _restitution(bodies, contacts, sub, layout)
    _limit_to_the_energy_taken(bodies, contacts, given, start, layout)
    total, extra = contacts.total, given[0]
    for k in range(len(total)):
        total[k] += extra[k]
    return residual


@njit(cache=True, parallel=True)
def _largest_residual(bodies, contacts, sub, layout):
    """The largest of :func:`finish`'s residuals, group by group as the sweep takes them (the largest of
    a set, whatever the order; each thread reads the rows it swept: threads that read a contiguous
    half of the rows each took half of theirs, 4 MB of columns on the 10^4 box pit, from the other
    core's cache)."""
    largest = np.zeros(len(layout.group_rows) - 1)
    for phase in range(phases(layout)):
        for g in prange(groups_in(layout, phase)):
            largest[layout.phase_start[phase] + g] = _residual_of(bodies, contacts, sub, rows_of(layout, phase, g))
    return largest.max()


@njit(cache=True)
def _residual_of(bodies, contacts, sub, rows):
    """The largest residual of the contacts ``rows`` = (first, end), or 0."""
    v, omega = bodies.v, bodies.omega
    a_, b_, normal, separation, lever_a, lever_b = (contacts.a, contacts.b, contacts.normal, contacts.s, contacts.la,
                                                    contacts.lb)
    mass_, pn = contacts.mass, contacts.pn
    residual = 0.0
    for k in range(rows[0], rows[1]):
        vn = dot3(_relative_velocity(v, omega, a_[k], b_[k], _row(lever_a, k), _row(lever_b, k)), _row(normal, k))
        mass = mass_[k, 0]
        residual = max(residual, abs(min(vn + max(separation[k], 0.0) / sub.h, pn[k] / mass if mass > 0 else 0.0)))
    return residual


@njit(cache=True)
def step(bodies, contacts, sub, substeps, layout):
    """A whole step under constant accelerations: ``substeps`` substeps, then :func:`finish`."""
    for _ in range(substeps):
        substep(bodies, contacts, sub, layout)
    return finish(bodies, contacts, sub, layout)


@njit(cache=True, parallel=True)
def previous_rows(old, new, place, threads):
    """Each new point's contact among the last step's, matched by (a, b, feature), or -1.

    ``old`` and ``new`` are the columns (a, b, feature), int64, each sorted lexicographically; the
    last step's point p was its contact ``place[p]``. One merge, cut into ``threads`` parts, each
    starting where bisection puts its first key among the old ones: the rows of a one-part merge."""
    rows = np.empty(len(new[0]), np.int64)
    for part in prange(threads):
        _merge(old, new, place, rows, span(0, len(rows), part, threads))
    return rows


@njit(cache=True)
def _merge(old, new, place, rows, part):
    """:func:`previous_rows` of the new points ``part`` = (first, end)."""
    oa, ob, of = old  # the arrays out of their tuples first: an item read in a loop costs a reference count
    na, nb, nf = new
    first, end = part
    count = len(oa)
    lo, hi = 0, count
    # the key comparison is written out in both loops: as a helper (inlined or not, its columns passed
    # together or one by one) the merge of 65,000 points took 2.6 to 2.9 ms against 0.8
    while lo < hi and first < end:  # the first old key not below the part's first
        p = (lo + hi) // 2
        if oa[p] < na[first] or (oa[p] == na[first] and (ob[p] < nb[first] or (
                ob[p] == nb[first] and of[p] < nf[first]))):
            lo = p + 1
        else:
            hi = p
    p = lo
    for k in range(first, end):
        while p < count and (oa[p] < na[k] or (oa[p] == na[k] and (ob[p] < nb[k] or (
                ob[p] == nb[k] and of[p] < nf[k])))):
            p += 1
        found = p < count and oa[p] == na[k] and ob[p] == nb[k] and of[p] == nf[k]
        rows[k] = place[p] if found else -1
