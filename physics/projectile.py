"""The closed-form projectile solution for a constant force."""

from __future__ import annotations

import numpy as np


def projectile(t, p_init, v_init, g, t_init=0.0):
    """Position and velocity under a constant acceleration ``g``, exactly.

    V(t) = V_init + g (t - t_init);  p(t) = p_init + V_init (t - t_init) + 1/2 g (t - t_init)^2,
    valid for any t (the lecture's projectile equations of motion).

    Parameters
    ----------
    t : float or ndarray, shape (K,)
    p_init, v_init : array, shape (..., 3)
    g : array, shape (..., 3)
        Acceleration F/m, broadcastable against ``p_init``.

    Returns
    -------
    p, v : ndarray, shape (K, ..., 3) (or (..., 3) for scalar t)
    """
    p_init, v_init, g = (np.asarray(x, dtype=float) for x in (p_init, v_init, g))
    tau = np.asarray(t, dtype=float) - t_init
    tau = tau.reshape(tau.shape + (1,) * p_init.ndim)
    return p_init + v_init * tau + 0.5 * g * tau**2, v_init + g * tau
