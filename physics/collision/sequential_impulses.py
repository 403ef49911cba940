"""Sequential impulses: the contact solver's compiled kernels (Numba).

One step of the solver, for the bodies and contacts of one scene (a *member* of a batch):

    for each of the substeps, h = dt / substeps:
        velocities  v += h a                      (the scene's forces)
        warm start  apply each contact's impulse of the last substep
        solve       `iterations` Gauss-Seidel sweeps, with the position correction's bias
        positions   q += h v
        relax       `iterations` sweeps without the bias (the push-out velocity removed)
    restitution     `iterations` sweeps towards v_n+ = -eps v_n-, for contacts that were hit

A contact k joins body ``ci[k]`` to body ``cj[k]`` (-1: a static shape, infinite mass) along
the unit normal ``normal[k]`` from i to j. Its separation at the start of the step is
``s0[k]`` (negative: penetration); inside the step it is tracked from the bodies' moves,
s = s0 + (dq_j - dq_i) . n, with the normal kept (it is found once per step, as in Box2D).
Its constraint is on the relative normal velocity v_n = (v_j - v_i) . n (:func:`.approach.approach_speed`
of v_j - v_i against rest: < 0 approaching):

    v_n >= -s / h  while apart (a speculative contact: close the gap, never pass it),
    v_n >= -bias   when touching (bias from the correction, :mod:`.solver_settings`),

enforced by an accumulated impulse P >= 0 (Catto's clamping of the *accumulated* impulse, which
lets an iteration take back what an earlier one gave too much). Each sweep solves one contact
at a time exactly: dP = -m_n (v_n + bias), with the effective mass m_n = 1 / (1/m_i + 1/m_j);
the impulse P n goes to j and -P n to i, so the momentum of every body-body contact is
conserved to round-off. Coulomb friction limits the tangential impulse, a vector in the
contact plane, to the disc |P_t| <= mu P (bodies are spheres without spin: the tangential
effective mass is m_n as well).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .approach import AT_REST, approach_speed
from .sphere_contacts import row3


class BodyColumns(NamedTuple):
    """The bodies of every member, joined: (N, 3) or (N,), changed in place."""

    q: np.ndarray  # positions, m
    v: np.ndarray  # velocities, m/s
    dq: np.ndarray  # the move since the start of the step, m (zeros at the start)
    inverse_mass: np.ndarray  # 1/m, 1/kg; 0 for a pinned body
    accel: np.ndarray  # the forces' accelerations, m/s^2


class ContactColumns(NamedTuple):
    """The contact constraints of every member, joined (Box2D's ``b2ContactConstraint`` array), (C,) or (C, 3).

    ``pn``, ``pt`` (the impulses, warm-started), ``total`` and ``most`` are changed in place.
    """

    i: np.ndarray  # body i
    j: np.ndarray  # body j, -1: a static shape
    normal: np.ndarray  # from i towards j
    s0: np.ndarray  # separation at the start of the step, m (negative: penetration)
    vn0: np.ndarray  # v_n at the start of the step, m/s
    mass: np.ndarray  # the effective mass m_n, kg
    friction: np.ndarray  # mu
    restitution: np.ndarray  # eps
    threshold: np.ndarray  # approach speeds at or below this do not bounce, m/s
    pn: np.ndarray  # normal impulse of the last substep, N s
    pt: np.ndarray  # tangential impulse of the last substep, N s
    total: np.ndarray  # the step's normal impulse, N s
    most: np.ndarray  # the largest substep impulse of the step, N s (zeros at the start)


class Members(NamedTuple):
    """Per member m: its bodies ``bodies[m]:bodies[m + 1]``, contacts likewise, and its step and settings."""

    bodies: np.ndarray
    contacts: np.ndarray
    dt: np.ndarray
    substeps: np.ndarray
    iterations: np.ndarray
    bias_rate: np.ndarray
    mass_scale: np.ndarray
    impulse_scale: np.ndarray
    push_speed: np.ndarray
    slop: np.ndarray


class Substep(NamedTuple):
    """One member's step context (Box2D's ``b2StepContext``): the substep and the correction's settings."""

    h: float  # the substep, s
    iterations: int
    bias_rate: float  # 1/s (:mod:`.solver_settings`)
    mass_scale: float
    impulse_scale: float
    push_speed: float  # m/s, the largest push-out speed
    slop: float  # m


@njit(cache=True, inline="always")
def _relative_velocity(v, i, j):
    if j >= 0:
        return v[j, 0] - v[i, 0], v[j, 1] - v[i, 1], v[j, 2] - v[i, 2]
    return -v[i, 0], -v[i, 1], -v[i, 2]


@njit(cache=True, inline="always")
def _apply(v, i, j, wi, wj, p0, p1, p2):
    """Impulse p on body j, -p on body i."""
    v[i, 0] -= p0 * wi
    v[i, 1] -= p1 * wi
    v[i, 2] -= p2 * wi
    if j >= 0:
        v[j, 0] += p0 * wj
        v[j, 1] += p1 * wj
        v[j, 2] += p2 * wj


@njit(cache=True, inline="always")
def _separation(dq, k, i, j, normal, s0):
    # One assignment per branch: written as -dq_i, then += dq_j, the whole sweep measured
    # 5x slower (Numba 0.68)
    if j >= 0:
        d0, d1, d2 = dq[j, 0] - dq[i, 0], dq[j, 1] - dq[i, 1], dq[j, 2] - dq[i, 2]
    else:
        d0, d1, d2 = -dq[i, 0], -dq[i, 1], -dq[i, 2]
    return s0[k] + d0 * normal[k, 0] + d1 * normal[k, 1] + d2 * normal[k, 2]


@njit(cache=True, inline="always")
def _sweep(bodies, contacts, c0, c1, sub, use_bias):
    """One Gauss-Seidel sweep over contacts c0..c1: the normal impulse, then friction."""
    v, dq, inverse_mass = bodies.v, bodies.dq, bodies.inverse_mass
    ci, cj, normal, s0, mass, friction, pn, pt = (contacts.i, contacts.j, contacts.normal, contacts.s0, contacts.mass,
                                                  contacts.friction, contacts.pn, contacts.pt)
    inv_h, bias_rate, slop, push_speed = 1.0 / sub.h, sub.bias_rate, sub.slop, sub.push_speed
    mass_scale, impulse_scale = sub.mass_scale, sub.impulse_scale
    for k in range(c0, c1):
        i, j = ci[k], cj[k]
        wi = inverse_mass[i]
        wj = inverse_mass[j] if j >= 0 else 0.0
        n0, n1, n2 = normal[k, 0], normal[k, 1], normal[k, 2]
        r0, r1, r2 = _relative_velocity(v, i, j)
        vn = approach_speed((r0, r1, r2), AT_REST, (n0, n1, n2))
        s = _separation(dq, k, i, j, normal, s0)
        scale, leak = 1.0, 0.0
        if s > 0.0:
            bias = s * inv_h  # speculative: may close the gap in this substep, not more
        elif use_bias:
            bias = max(bias_rate * min(s + slop, 0.0), -push_speed)
            scale, leak = mass_scale, impulse_scale
        else:
            bias = 0.0
        dp = -mass[k] * scale * (vn + bias) - leak * pn[k]
        total = max(pn[k] + dp, 0.0)
        dp = total - pn[k]
        pn[k] = total
        _apply(v, i, j, wi, wj, dp * n0, dp * n1, dp * n2)

        mu = friction[k]
        if mu > 0.0:
            r0, r1, r2 = _relative_velocity(v, i, j)
            vn = approach_speed((r0, r1, r2), AT_REST, (n0, n1, n2))
            t0, t1, t2 = r0 - vn * n0, r1 - vn * n1, r2 - vn * n2
            p0, p1, p2 = pt[k, 0] - mass[k] * t0, pt[k, 1] - mass[k] * t1, pt[k, 2] - mass[k] * t2
            limit = mu * pn[k]
            size = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            if size > limit:  # outside the friction cone: slide, at most mu P
                f = limit / size
                p0, p1, p2 = p0 * f, p1 * f, p2 * f
            d0, d1, d2 = p0 - pt[k, 0], p1 - pt[k, 1], p2 - pt[k, 2]
            pt[k, 0], pt[k, 1], pt[k, 2] = p0, p1, p2
            _apply(v, i, j, wi, wj, d0, d1, d2)


@njit(cache=True)
def substep(bodies, contacts, b0, b1, c0, c1, sub):
    """One substep of ``sub.h`` for bodies b0..b1 and contacts c0..c1."""
    q, v, dq, inverse_mass, accel = bodies
    ci, cj, normal, pn, pt = contacts.i, contacts.j, contacts.normal, contacts.pn, contacts.pt
    h = sub.h
    for b in range(b0, b1):
        if inverse_mass[b] > 0.0:
            v[b, 0] += h * accel[b, 0]
            v[b, 1] += h * accel[b, 1]
            v[b, 2] += h * accel[b, 2]
    for k in range(c0, c1):  # warm start: last substep's impulses, a good first guess
        i, j = ci[k], cj[k]
        wj = inverse_mass[j] if j >= 0 else 0.0
        _apply(v, i, j, inverse_mass[i], wj, pn[k] * normal[k, 0] + pt[k, 0], pn[k] * normal[k, 1] + pt[k, 1],
               pn[k] * normal[k, 2] + pt[k, 2])
    for _ in range(sub.iterations):
        _sweep(bodies, contacts, c0, c1, sub, True)
    for b in range(b0, b1):
        for a in range(3):
            q[b, a] += h * v[b, a]
            dq[b, a] += h * v[b, a]
    for _ in range(sub.iterations):
        _sweep(bodies, contacts, c0, c1, sub, False)
    total, most = contacts.total, contacts.most
    for k in range(c0, c1):
        total[k] += pn[k]
        most[k] = max(most[k], pn[k])


@njit(cache=True)
def finish(bodies, contacts, c0, c1, sub):
    """The end of a step: the largest residual, then the restitution pass; returns the residual.

    The residual of contact k is |min(v_n + max(s, 0) / h, P / m_n)| (m/s), the natural
    residual of its complementarity condition (zero exactly when either the constraint is
    active or its impulse is zero, both non-negative). Restitution acts on the contacts
    hit in this step (an impulse in some substep) that approached faster than their
    threshold at its start: it drives v_n to -eps v_n- with a further impulse, the
    accumulated total (the last substep's plus this) kept >= 0. That is the lecture's
    equation 3 on the velocities at the start of the step, as Box2D applies it.
    """
    v, dq, inverse_mass = bodies.v, bodies.dq, bodies.inverse_mass
    ci, cj, normal, s0, vn0, mass, restitution, threshold, pn = (
        contacts.i, contacts.j, contacts.normal, contacts.s0, contacts.vn0, contacts.mass, contacts.restitution,
        contacts.threshold, contacts.pn)
    inv_h = 1.0 / sub.h
    residual = 0.0
    for k in range(c0, c1):
        i, j = ci[k], cj[k]
        r0, r1, r2 = _relative_velocity(v, i, j)
        vn = approach_speed((r0, r1, r2), AT_REST, row3(normal, k))
        s = _separation(dq, k, i, j, normal, s0)
        residual = max(residual, abs(min(vn + max(s, 0.0) * inv_h, pn[k] / mass[k])))
    extra = np.zeros(c1 - c0)
    for _ in range(sub.iterations):
        for k in range(c0, c1):
            if vn0[k] >= -threshold[k] or contacts.most[k] <= 0.0:
                continue
            i, j = ci[k], cj[k]
            wj = inverse_mass[j] if j >= 0 else 0.0
            r0, r1, r2 = _relative_velocity(v, i, j)
            vn = approach_speed((r0, r1, r2), AT_REST, row3(normal, k))
            dp = -mass[k] * (vn + restitution[k] * vn0[k])
            accumulated = max(pn[k] + extra[k - c0] + dp, 0.0)
            dp = accumulated - pn[k] - extra[k - c0]
            extra[k - c0] += dp
            _apply(v, ci[k], j, inverse_mass[i], wj, dp * normal[k, 0], dp * normal[k, 1], dp * normal[k, 2])
    for k in range(c0, c1):
        contacts.total[k] += extra[k - c0]
    return residual


def _step_members(bodies, contacts, members, residual):
    """A whole step of every member m (a :class:`Members` row) under constant accelerations, its
    residual into ``residual[m]``; each member has its own dt and settings."""
    for m in prange(len(members.dt)):
        b0, b1, c0, c1 = members.bodies[m], members.bodies[m + 1], members.contacts[m], members.contacts[m + 1]
        sub = Substep(members.dt[m] / members.substeps[m], members.iterations[m], members.bias_rate[m],
                      members.mass_scale[m], members.impulse_scale[m], members.push_speed[m], members.slop[m])
        for _ in range(members.substeps[m]):
            substep(bodies, contacts, b0, b1, c0, c1, sub)
        residual[m] = finish(bodies, contacts, c0, c1, sub)


#: one member (a run): serial, as Gauss-Seidel is (Numba's parallel loop only slows it, 3x here)
step_members = njit(cache=True)(_step_members)
#: a batch of members (a sweep of scenes or settings), the members spread over the cores
step_members_parallel = njit(cache=True, parallel=True)(_step_members)
