"""The stiffest mode of a model: its highest natural frequency, found without the dense Jacobian.

Near a state ``(q0, 0)`` the model is linear: ``a ~ a0 + J_q dq + J_v dv`` with
``J_q = -M^-1 K`` (K the stiffness of the springs, the Hessian of their potential) and
``J_v = -M^-1 C`` (C the dampers'). Its modes solve ``K x = omega^2 M x``; an explicit
integrator's largest stable dt is set by the largest omega (the lecture's "stiff
springs": omega_max grows as sqrt(k / m)).

``M^-1 K`` is not symmetric, but ``S = D K D`` with ``D = M^-1/2`` is, and has the same
nonzero eigenvalues (``AB`` and ``BA`` share them, with ``A = D``, ``B = D K``). A pinned
body has inverse mass 0, so its rows and columns of S vanish: it takes no part in any
mode. S is applied without ever being formed: one forward-mode derivative
(:func:`jax.jvp`) of the model's own acceleration per product, ``S z = -sqrt(M) J_q (D z)``,
and Lanczos iteration (:func:`scipy.sparse.linalg.eigsh`) finds its largest eigenvalue.
The cost is a few dozen force evaluations, whatever the number of bodies; the dense
(3N)^2 Jacobian of :meth:`Model.jacobian` would not fit in memory at cloth sizes.

The damping ratio of that mode is its Rayleigh quotient ``zeta = x^T C x / (2 omega x^T M x)``;
exact when the damping is proportional to the stiffness in that mode (the soft bodies'
dampers sit on the springs' pairs, so C = (c / k) K at rest).
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: below this many degrees of freedom S is formed column by column and solved densely
#: (ARPACK wants several more dimensions than the one eigenvalue it is asked for)
DENSE_SIZE = 60
#: relative accuracy of the Lanczos eigenvalue (far below the 1 % a stability prediction needs)
LANCZOS_RTOL = 1e-10
#: central-difference step, relative to the positions' scale (see _difference_derivatives)
DIFFERENCE_STEP = 1e-6
#: above this many degrees of freedom J_q and J_v are the forces' sparse Jacobian
#: (:mod:`.sparse_jacobian`) wherever it is the whole Jacobian: a product then costs a
#: sparse matrix-vector product, not two force evaluations (the bench's 25,600-particle
#: cloth: 1 ms instead of 46, and about 2,000 products)
SPARSE_SIZE = 1500


class NonFiniteModelError(ValueError):
    """No stiffest mode can be computed: the forces overflow at the state, or Lanczos failed."""


@dataclasses.dataclass(frozen=True)
class StiffestMode:
    """The highest-frequency mode of a model linearised at a state.

    Attributes
    ----------
    omega : float or None
        Its natural frequency, rad/s; ``None`` when nothing oscillates (no restoring
        force: no springs, or only constant forces).
    damping_ratio : float
        zeta of that mode (0 without dampers; 1 is critical damping).
    pattern : ndarray, shape (N, 3)
        Its displacement shape, largest entry 1 (zero on pinned bodies).
    """

    omega: float | None
    damping_ratio: float
    pattern: np.ndarray


def stiffest_mode(model, q, v=None, derivative: str = "jvp") -> StiffestMode:
    """The highest-frequency mode of ``model`` linearised at positions ``q`` (N, 3).

    Parameters
    ----------
    model : steplab.physics.Model
        Any backend and precision (the derivatives are taken in float64).
    q : array, shape (N, 3)
        Where to linearise: a scene's initial positions (its rest state for a soft body).
    v : array, shape (N, 3), optional
        Velocities there (default 0: the dampers' stiffness in q vanishes at rest).
    derivative : {"jvp", "difference"}
        How ``J_q dq`` is evaluated: ``"jvp"`` exactly, by forward-mode autodiff of a JAX
        copy of the model (``steplab check``); ``"difference"`` by central differences on
        the NumPy model, relative error about 1e-9 and no compilation, so that the check
        ``steplab run`` makes before a run costs milliseconds, not the JIT's ~0.3 s. Either
        way, above SPARSE_SIZE degrees of freedom, the sparse Jacobian where it is exact.
    """
    from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, LinearOperator, eigsh

    q0 = np.asarray(q, dtype=float)
    v0 = np.zeros_like(q0) if v is None else np.asarray(v, dtype=float)
    shape, size = q0.shape, q0.size
    if derivative not in ("jvp", "difference"):
        raise ValueError(f"derivative must be 'jvp' or 'difference', got {derivative!r}")
    if size > SPARSE_SIZE and _sparse_is_exact(model):
        derivatives = _sparse_derivatives(model, q0, v0)
    elif derivative == "jvp":
        derivatives = _finite_or_difference(_autodiff_derivatives(model, q0, v0), model, q0, v0)
    else:
        derivatives = _difference_derivatives(model, q0, v0)
    inverse_masses = np.asarray(model.inverse_masses, dtype=float)
    d = np.broadcast_to(np.sqrt(inverse_masses)[:, None], shape)  # D = M^-1/2, 0 where pinned
    sqrt_m = np.where(d > 0, 1 / np.where(d > 0, d, 1), 0.0)  # sqrt(M), 0 where pinned
    zero = np.zeros(shape)

    def weighted(x, which):
        """-sqrt(M) J x (``which``: 0, J_q; 1, J_v), and J of x scaled. J is linear: applied to x scaled by
        a power of two near 1 / max |x|, then sqrt(M) and the scale back, so that a light body's large D (a
        mass of 1e-300 kg: 1e150) does not overflow on the way while the product is finite; a power of two
        changes no bit of a product that never overflowed."""
        exponent = int(np.frexp(np.max(np.abs(x)))[1]) if np.any(x) else 0
        dx = np.ldexp(x, -exponent)
        scaled = derivatives(dx, zero)[0] if which == 0 else derivatives(zero, dx)[1]
        return np.ldexp(-sqrt_m * scaled, exponent), scaled

    def stiffness(z):  # S z = D K D z = -sqrt(M) J_q (D z)
        product, accelerations = weighted(d * np.reshape(z, shape), 0)
        product = product.ravel()
        if not np.all(np.isfinite(product)):
            raise NonFiniteModelError(_not_finite(model, inverse_masses, accelerations, product))
        return product

    if size <= DENSE_SIZE:
        s = np.column_stack([stiffness(e) for e in np.eye(size)])
        values, vectors = np.linalg.eigh(symmetric_part(s))  # symmetric up to round-off
        omega2, z = float(values[-1]), vectors[:, -1]
    else:
        # a fixed start, so that a scene's prediction is reproducible; S of a model without
        # restoring forces maps it to zero, and then nothing oscillates
        start = np.random.default_rng(0).standard_normal(size)
        if not np.any(stiffness(start)):
            return StiffestMode(None, 0.0, np.zeros(shape))
        operator = LinearOperator((size, size), matvec=stiffness, dtype=float)
        try:
            values, vectors = eigsh(operator, k=1, which="LA", tol=LANCZOS_RTOL, v0=start)
        except ArpackNoConvergence as err:  # a cluster of equal top eigenvalues: take what converged
            if not len(err.eigenvalues):
                raise NonFiniteModelError(f"Lanczos iteration did not converge: {err}") from None
            values, vectors = err.eigenvalues, err.eigenvectors
        except ArpackError as err:
            raise NonFiniteModelError(f"Lanczos iteration failed: {err}") from None
        omega2, z = float(values[0]), vectors[:, 0]
    z = np.reshape(z, shape)
    pattern = d * z
    if not omega2 > 0:
        return StiffestMode(None, 0.0, pattern)
    omega = float(np.sqrt(omega2))
    # zeta = x^T C x / (2 omega x^T M x) with x = D z, |z| = 1: x^T M x = 1, D C D z = -sqrt(M) J_v (D z)
    zeta = float(np.sum(z * weighted(pattern, 1)[0]) / (2 * omega))
    check_finite_mode(omega, zeta)
    scale = np.max(np.abs(pattern))
    return StiffestMode(omega, zeta if zeta > 0 else 0.0, pattern / scale)


def symmetric_part(a):
    """(A + A^T) / 2, each half taken before the sum: 1e308 + 1e308 would overflow where A's entries do not."""
    return 0.5 * a + 0.5 * a.T


def check_finite_mode(omega: float, zeta: float) -> None:
    """NonFiniteModelError when the stiffest mode's omega or damping ratio overflowed float64 though the
    forces' derivatives are finite (a spring of 1e308 N/m or a damper of 1e308 N s/m on light bodies): no
    stable dt can be predicted, where a report would print inf."""
    for what, value in (("omega_max", omega), ("damping ratio", zeta)):
        if not np.isfinite(value):
            raise NonFiniteModelError(f"the model's stiffest mode at its initial state has no finite {what} "
                                      f"({value:g}: it overflows float64): a stiffness or damping too large for the "
                                      "masses and moments of inertia it acts on; no stable dt can be predicted")


def _not_finite(model, inverse_masses, accelerations, product) -> str:
    """Why S z is not finite, one line naming the body: the lightest of those whose rows are not finite."""
    bad = np.unique(np.flatnonzero(~np.isfinite(product)) // 3)
    body = int(bad[np.argmax(inverse_masses[bad])])
    name = model.names[body] if getattr(model, "names", None) else f"body{body}"
    mass = f"mass {1 / inverse_masses[body]:.3g} kg" if inverse_masses[body] > 0 else "pinned"
    if np.any(np.isnan(accelerations[body])):
        why = ("a force's derivative there is undefined (NaN): a spring on it with its ends at one point and a "
               "rest length > 0 has no direction")
    else:
        why = (f"the stiffness of its forces over its mass, k / m, overflows float64 (beyond "
               f"{np.finfo(float).max:.3g} s^-2): a mass too small for the stiffness of its springs, or a "
               "stiffness too large")
    return (f"the model's stiffness at its initial state is not finite at body {name!r} ({mass}): {why}; "
            "no stable dt can be predicted")


def _sparse_is_exact(model) -> bool:
    """The forces' sparse Jacobian covers every force of ``model`` (compiled with Numba: imported
    only for a model this large, so a small run never loads Numba for its stability check)."""
    from . import sparse_jacobian

    return sparse_jacobian.is_complete(model)


def _sparse_derivatives(model, q0, v0):
    """``(dq, dv) -> (J_q dq, J_v dv)`` at (q0, v0), exact: the forces' sparse Jacobian."""
    from . import sparse_jacobian

    jq, jv = sparse_jacobian.sparse_jacobian(model.cast(np, np.float64), 0.0, q0, v0)

    def derivatives(dq, dv):
        return (jq @ np.ravel(dq)).reshape(np.shape(dq)), (jv @ np.ravel(dv)).reshape(np.shape(dv))

    return derivatives


def _autodiff_derivatives(model, q0, v0):
    """``(dq, dv) -> (J_q dq, J_v dv)`` at (q0, v0), exact: jax.jvp of the model's acceleration."""
    import jax
    import jax.numpy as jnp

    jmodel = model.cast(jnp, np.float64)
    q0, v0 = jnp.asarray(q0), jnp.asarray(v0)

    @jax.jit
    def derivatives(dq, dv):
        position = jax.jvp(lambda x: jmodel.acceleration(0.0, x, v0), (q0,), (dq,))[1]
        velocity = jax.jvp(lambda u: jmodel.acceleration(0.0, q0, u), (v0,), (dv,))[1]
        return position, velocity

    return lambda dq, dv: tuple(np.asarray(j) for j in derivatives(jnp.asarray(dq), jnp.asarray(dv)))


def _finite_or_difference(exact, model, q0, v0):
    """``exact`` (jax.jvp), or central differences where its product is NaN and theirs finite: jvp
    differentiates a spring's length |x| as x / |x|, NaN at length 0, where the force k (l - L) x / l of a
    spring of rest length L = 0 (a body resting on its anchor) is k x, smooth. Else the exact product, for
    :func:`_not_finite` to say why it is not finite."""
    difference = None

    def derivatives(dq, dv):
        nonlocal difference
        product = exact(dq, dv)
        if not any(np.any(np.isnan(p)) for p in product):
            return product
        difference = difference or _difference_derivatives(model, q0, v0)
        approximate = difference(dq, dv)
        return approximate if all(np.all(np.isfinite(p)) for p in approximate) else product

    return derivatives


def _difference_derivatives(model, q0, v0):
    """``(dq, dv) -> (J_q dq, J_v dv)`` by central differences of the NumPy float64 model.

    The step is DIFFERENCE_STEP of the positions' scale: the truncation error (h / l)^2
    of a spring of length l and the round-off eps |q| / h then both stay near 1e-9.
    """
    numpy_model = model.cast(np, np.float64)
    h = DIFFERENCE_STEP * max(1.0, float(np.max(np.abs(q0))))

    def central(f, x0, dx):
        size = float(np.max(np.abs(dx)))
        if size == 0:
            return np.zeros_like(x0)
        step = h / size
        return (f(x0 + step * dx) - f(x0 - step * dx)) / (2 * step)

    def derivatives(dq, dv):
        return (central(lambda x: numpy_model.acceleration(0.0, x, v0), q0, dq),
                central(lambda u: numpy_model.acceleration(0.0, q0, u), v0, dv))

    return derivatives
