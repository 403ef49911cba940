"""Unit quaternions q = [w, x, y, z] for orientations, row-wise over (..., 4) arrays.

Convention (Hamilton's product, as Box3D and MuJoCo): q maps body-frame vectors to the
world frame, v_world = q v_body q*, so the orientation's rate is dq/dt = 1/2 q (0, omega_body)
= 1/2 (0, omega_world) q. Every function takes the array namespace ``xp`` (``numpy`` or
``jax.numpy``, as :mod:`._array`) and uses only elementwise arithmetic, so the same formula
runs on both backends and XLA fuses it.
"""

from __future__ import annotations

import math

import numpy as np

from ._array import is_numpy

#: the identity orientation
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def hamilton(pw, px, py, pz, qw, qx, qy, qz):
    """The four components of the Hamilton product p q from the eight of p and q (numbers or arrays).

    The one formula that :func:`multiply` stacks and the compiled rotation kernel
    (:mod:`steplab.integrators.rotation_compiled`) evaluates body by body.
    """
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


def multiply(xp, p, q):
    """Hamilton product p q, shape (..., 4)."""
    return xp.stack(hamilton(p[..., 0], p[..., 1], p[..., 2], p[..., 3], q[..., 0], q[..., 1], q[..., 2], q[..., 3]),
                    axis=-1)


def multiply_vector(xp, q, v):
    """q (0, v): the product with a pure quaternion, shape (..., 4) (the rate 2 dq/dt for v = omega_body)."""
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    return xp.stack([-qx * vx - qy * vy - qz * vz,
                     qw * vx + qy * vz - qz * vy,
                     qw * vy - qx * vz + qz * vx,
                     qw * vz + qx * vy - qy * vx], axis=-1)


def conjugate(xp, q):
    """q* = [w, -x, -y, -z]: the inverse of a unit quaternion."""
    return q * xp.asarray([1.0, -1.0, -1.0, -1.0], dtype=q.dtype)


def norm(xp, q):
    """|q|, shape (...)."""
    return xp.sqrt(q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2] + q[..., 3] * q[..., 3])


def normalize(xp, q):
    """q / |q| (the caller guarantees q != 0: the integrators only renormalise near-unit quaternions)."""
    return q / norm(xp, q)[..., None]


def cross_components(ax, ay, az, bx, by, bz):
    """The three components of a x b (numbers or arrays): :func:`cross` and the compiled kernel."""
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


def cross(xp, a, b):
    """a x b row-wise, shape (..., 3) (elementwise, so XLA fuses it)."""
    return xp.stack(cross_components(a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]), axis=-1)


def rotate(xp, q, v):
    """q v q*: a body-frame vector in the world frame, shape (..., 3).

    With u the vector part of q: v + 2 w (u x v) + 2 u x (u x v), 18 multiplications
    instead of two quaternion products, and exact for the identity.
    """
    u = q[..., 1:]
    t = 2.0 * cross(xp, u, v)
    return v + q[..., :1] * t + cross(xp, u, t)


def rotate_inverse(xp, q, v):
    """q* v q: a world-frame vector in the body frame."""
    return rotate(xp, conjugate(xp, q), v)


#: |r|/2 up to which :func:`exp` sums the Taylor series of cos and sin(x)/x instead of calling
#: them: the first term left out, x^16/16! <= 0.5^16/16! = 7e-19, is below half an ulp of
#: either (both >= 0.87 there). It covers h |omega| <= 1 rad, far past the explicit methods'
#: stable omega dt (0.16 and below, ``steplab study rotation``)
EXP_SERIES_HALF_ANGLE = 0.5
#: the series' coefficients in x^2: cos x = sum (-1)^k x^2k / (2k)!, sin x / x = sum (-1)^k x^2k / (2k + 1)!
_COS_SERIES = tuple((-1) ** k / math.factorial(2 * k) for k in range(8))
_SINC_SERIES = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(8))


def half_angle_squared(rx, ry, rz):
    """x^2 = |r|^2 / 4 of the rotation vector r = (rx, ry, rz): what :func:`exp`'s two formulas take."""
    return 0.25 * (rx ** 2 + ry ** 2 + rz ** 2)


def exp_series(x2):
    """(cos x, sin x / (2x)) of x^2 = |r|^2 / 4 by the series (x <= :data:`EXP_SERIES_HALF_ANGLE`), by Horner's rule.

    An index loop over module constants, which Numba compiles too."""
    c, s = _COS_SERIES[-1], _SINC_SERIES[-1]
    for k in range(len(_COS_SERIES) - 2, -1, -1):
        c = c * x2 + _COS_SERIES[k]
        s = s * x2 + _SINC_SERIES[k]
    return c, 0.5 * s


def exp_trigonometric(xp, x2):
    """(cos x, sin x / (2x)) of x^2 = |r|^2 / 4 by libm: sin(|r|/2) / |r| = sinc(|r| / (2 pi)) / 2, exact at 0."""
    angle = 2.0 * xp.sqrt(x2)
    return xp.cos(0.5 * angle), 0.5 * xp.sinc(angle / (2 * np.pi))


def exp(xp, rotation_vector):
    """The unit quaternion of a rotation by angle |r| about r/|r|: exp(r/2) = [cos(|r|/2), sin(|r|/2) r/|r|].

    When every |r|/2 <= :data:`EXP_SERIES_HALF_ANGLE` (a step's rotation, the usual case), cos x
    and sin x / x (x = |r|/2) are their Taylor series in x^2, summed to round-off: eight
    multiply-adds each, no square root, exact at r = 0. float64 sin and cos are not vectorised
    on XLA's CPU backend (one libm call per element, about 9 ns): the series takes the
    exponential-map step of 10^5 bodies from 6.0 to 1.6 ms in the compiled loop (14.3 to 1.5 ms
    jitted alone). Otherwise sin(|r|/2)/|r| is
    sinc(|r|/(2 pi))/2, exact at 0 (numpy's and jax's sinc switch to the series near 0).
    """
    x2 = half_angle_squared(rotation_vector[..., 0], rotation_vector[..., 1], rotation_vector[..., 2])
    small = xp.max(x2, initial=0.0) <= EXP_SERIES_HALF_ANGLE**2  # NaN: the trigonometric branch, NaN out
    if is_numpy(xp):
        c, half_sinc = exp_series(x2) if small else exp_trigonometric(xp, x2)
    else:  # one branch for all bodies: a where() would compute both
        import jax

        c, half_sinc = jax.lax.cond(small, exp_series, lambda x2: exp_trigonometric(xp, x2), x2)
    return xp.concatenate([c[..., None], half_sinc[..., None] * rotation_vector], axis=-1)


def cayley(xp, u):
    """(1 + u)(1 - u)^-1 for a pure quaternion u = (0, u): the unit quaternion (1 - |u|^2, 2u) / (1 + |u|^2).

    It is the implicit midpoint rule's map on dq/dt = 1/2 q (0, omega): q1 = q0 cayley(h omega / 4),
    a rotation by 4 atan(|u|) about u (2 atan(h|omega|/4), which is h|omega| to third order).
    """
    uu = u[..., 0] ** 2 + u[..., 1] ** 2 + u[..., 2] ** 2
    return xp.concatenate([(1.0 - uu)[..., None], 2.0 * u], axis=-1) / (1.0 + uu)[..., None]


def from_axis_angle(xp, axis, angle):
    """The rotation by ``angle`` (rad) about the unit vector ``axis`` (right-handed)."""
    return exp(xp, axis * xp.asarray(angle)[..., None])


def matrix_components(w, x, y, z):
    """The rotation matrix of the unit quaternion (w, x, y, z) as three rows of three (numbers or
    arrays): :func:`to_matrix` and the compiled narrow phase."""
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def to_matrix(xp, q):
    """The rotation matrix R (..., 3, 3) of a unit quaternion: v_world = R v_body."""
    rows = matrix_components(q[..., 0], q[..., 1], q[..., 2], q[..., 3])
    return xp.stack([xp.stack(row, axis=-1) for row in rows], axis=-2)


def angle_between(xp, p, q):
    """The angle (rad, in [0, pi]) of the rotation taking orientation p to q; q and -q are the same.

    2 atan2(|v|, |w|) of p* q = (w, v), accurate for small and for large angles alike
    (2 acos |p . q| loses half the digits near zero).
    """
    d = multiply(xp, conjugate(xp, p), q)
    v = xp.sqrt(d[..., 1] ** 2 + d[..., 2] ** 2 + d[..., 3] ** 2)
    return 2.0 * xp.arctan2(v, xp.abs(d[..., 0]))
