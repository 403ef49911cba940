"""The exponential-map step of free rigid bodies as one compiled loop over a structure of arrays.

What ``steplab bench`` times against the memory-traffic bound (``vs_memory_bound_rotation_1e5``),
and :func:`.rotation.simulate_rotation`'s ``backend="numba"``. One step of one body is the
``exponential-map`` method of :mod:`.rotation` on a torque-free body, operation for operation:

    omega1 = omega + h (-(omega x I omega) / I),   q1 = normalise(q exp(h omega1))

with the cross product, the Hamilton product and the exponential's series taken from
:mod:`steplab.physics.quaternion` (one definition, compiled here by Numba). No fast-math: every
operation is IEEE-rounded in the same order as on NumPy, so the two agree bit for bit.

Why a kernel of its own: XLA's CPU code for the step (the rows (R, 4) and (R, 3), one fused
loop) runs at about 3x the bytes' bound, its per-body quaternion arithmetic scalar. Here the
state is a structure of arrays, q as (4, R) and omega as (3, R), so that each component is
contiguous, and the loop over bodies is a ``prange``: Numba compiles it into a function whose
arrays are declared not to alias, which LLVM vectorises (8 bodies per AVX-512 instruction, the
four divisions and the square root included). With one thread it is an ordinary loop.

The exponential's series holds to round-off for h |omega| <= 1 rad (:data:`.quaternion.EXP_SERIES_HALF_ANGLE`),
far past every explicit method's stable omega dt. A body beyond it is left for a second, scalar
pass that takes libm's sin and cos, body by body. (The NumPy and JAX steps switch all bodies to
libm at once when one is beyond; the two differ by the series' round-off, 4e-16, on the others.)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange
from steplab.physics import quaternion as quat

#: the largest x^2 = (h |omega| / 2)^2 the series covers
SERIES_LIMIT = quat.EXP_SERIES_HALF_ANGLE**2

_hamilton = njit(inline="always")(quat.hamilton)
_cross = njit(inline="always")(quat.cross_components)
_half_angle_squared = njit(inline="always")(quat.half_angle_squared)
_series = njit(inline="always")(quat.exp_series)
_trigonometric = njit(inline="always")(quat.exp_trigonometric)


class FreeBodies(NamedTuple):
    """R free rigid bodies as a structure of arrays, float64, C-contiguous.

    q : (4, R) unit quaternions [w, x, y, z]; omega : (3, R) body-frame angular velocities, rad/s;
    inertia : (3, R) principal moments, kg m^2.
    """

    q: np.ndarray
    omega: np.ndarray
    inertia: np.ndarray


def free_bodies(q, omega, inertia) -> FreeBodies:
    """The bodies of rows q (R, 4), omega (R, 3) and inertia (R, 3) (or (3,), the same for all), transposed."""
    inertia = np.broadcast_to(np.asarray(inertia, float), np.shape(omega))
    return FreeBodies(*(np.ascontiguousarray(np.asarray(a, float).T) for a in (q, omega, inertia)))


@njit(cache=True, inline="always")
def _turn(q, b, w0, w1, w2, h, c, half_sinc):
    """q[:, b] <- normalise(q[:, b] exp(h omega1)), with exp's (cos, sin / (2x)) given."""
    e1, e2, e3 = half_sinc * (h * w0), half_sinc * (h * w1), half_sinc * (h * w2)
    r0, r1, r2, r3 = _hamilton(q[0, b], q[1, b], q[2, b], q[3, b], c, e1, e2, e3)
    size = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    q[0, b], q[1, b], q[2, b], q[3, b] = r0 / size, r1 / size, r2 / size, r3 / size


@njit(cache=True, parallel=True)
def _series_pass(q, omega, inertia, h):
    """One step of every body, the exponential by its series; the number of bodies beyond it (left unturned)."""
    beyond = 0
    for b in prange(q.shape[1]):
        w0, w1, w2 = omega[0, b], omega[1, b], omega[2, b]
        i0, i1, i2 = inertia[0, b], inertia[1, b], inertia[2, b]
        g0, g1, g2 = _cross(w0, w1, w2, i0 * w0, i1 * w1, i2 * w2)  # omega x I omega
        w0, w1, w2 = w0 + h * ((0.0 - g0) / i0), w1 + h * ((0.0 - g1) / i1), w2 + h * ((0.0 - g2) / i2)
        omega[0, b], omega[1, b], omega[2, b] = w0, w1, w2
        x2 = _half_angle_squared(h * w0, h * w1, h * w2)
        if x2 <= SERIES_LIMIT:
            c, half_sinc = _series(x2)
            _turn(q, b, w0, w1, w2, h, c, half_sinc)
        else:  # also NaN
            beyond += 1
    return beyond


@njit(cache=True)
def _trigonometric_pass(q, omega, h):
    """The bodies the series pass left: their turn by libm's sin and cos."""
    for b in range(q.shape[1]):
        w0, w1, w2 = omega[0, b], omega[1, b], omega[2, b]
        x2 = _half_angle_squared(h * w0, h * w1, h * w2)
        if not x2 <= SERIES_LIMIT:
            c, half_sinc = _trigonometric(np, x2)
            _turn(q, b, w0, w1, w2, h, c, half_sinc)


@njit(cache=True)
def _steps(q, omega, inertia, h, n):
    for _ in range(n):
        if _series_pass(q, omega, inertia, h):
            _trigonometric_pass(q, omega, h)


def exponential_map_steps(bodies: FreeBodies, dt: float, n: int) -> None:
    """``n`` exponential-map steps of ``dt`` of the free ``bodies``, in place."""
    _steps(bodies.q, bodies.omega, bodies.inertia, float(dt), int(n))


@njit(cache=True, parallel=True)
def _stream(q, omega, inertia):
    total = 0.0
    for b in prange(q.shape[1]):
        for c in range(4):
            q[c, b] *= 1.0
        for c in range(3):
            omega[c, b] *= 1.0
            total += inertia[c, b]
    return total


def stream_pass(bodies: FreeBodies) -> None:
    """Read q, omega and the moments and write q and omega back, computing nothing: the least one
    step of ``bodies`` must move, in one compiled pass (the bench's tighter memory bound)."""
    _stream(bodies.q, bodies.omega, bodies.inertia)
