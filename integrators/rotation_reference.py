"""The adaptive reference on (q, omega): diffrax (or scipy) on Euler's equations with torque.

The same :func:`.references.solve_adaptive` the translation references call, on the state
y = [q, omega] of shape (R, 7) (omega in the body frame); with diffrax the vector field runs on
``jax.numpy``, which the rotation model's ``xp`` style allows.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from steplab.physics import quaternion as quat

from .references import ReferenceFailedError, solve_adaptive
from .rotation import angular_acceleration

#: the tolerances of the rotation reference (the exact torque-free motion agrees to ~1e-11)
REFERENCE_RTOL = REFERENCE_ATOL = 1e-13


def rotation_reference(model, q0, omega0, ts, method: str = "diffrax-dopri8", rtol: float = REFERENCE_RTOL,
                       atol: float = REFERENCE_ATOL):
    """q (K, R, 4) and omega (K, R, 3, body frame) at the times ``ts`` from (q0, omega0).

    Raises
    ------
    ReferenceFailedError
        The adaptive solver did not reach ``ts[-1]``.
    """
    if method.startswith("diffrax"):
        import jax.numpy as xp

        model = dataclasses.replace(model, xp=xp)
    else:
        xp = np
    ts = np.asarray(ts, float)

    def vector_field(t, y):
        q, omega = y[..., :4], y[..., 4:]
        return xp.concatenate([0.5 * quat.multiply_vector(xp, q, omega),
                               angular_acceleration(xp, model, t, q, omega)], axis=-1)

    y0 = np.concatenate([np.asarray(q0, float), np.asarray(omega0, float)], axis=-1)
    sol = solve_adaptive(vector_field, xp.asarray(ts), xp.asarray(y0), method, rtol, atol)
    if not bool(np.all(np.asarray(sol.success))):
        raise ReferenceFailedError(f"rotation reference {method} failed: {sol.message}")
    ys = np.asarray(sol.ys)
    return ys[..., :4], ys[..., 4:]
