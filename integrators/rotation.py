"""Rotation methods: one step of a rigid body's orientation q and body angular velocity omega.

The equations (body frame, principal axes, I = diag(I1, I2, I3)):

    I domega/dt = tau - omega x I omega        (Euler's equations; omega x I omega is the
                                                gyroscopic term, the only nonlinearity)
    dq/dt = 1/2 q (0, omega)                   (the orientation, a unit quaternion)

Each method is small immutable data with its theory as class data and one
``step(model, t, q, omega, dt) -> (q, omega)`` on arrays (R, 4), (R, 3); ``model`` is a
:class:`steplab.physics.rigid_body.RotationModel` (inertia and body-frame torque). A method
never knows where the torque comes from. Every method returns a unit quaternion (the
explicit ones renormalise, as every engine does; the others keep |q| = 1 by construction and
renormalise only the round-off).

The translation of the centre of mass is a separate system (:mod:`.simulate`); ``stage_order``
says how a method interleaves with a translation integrator when forces at points couple them.
"""

from __future__ import annotations

import contextlib
import dataclasses
from typing import ClassVar

import numpy as np
from steplab.physics import quaternion as quat
from steplab.physics._array import is_numpy, norm

from .base import Integrator, check_count, check_real
from .simulate import ANY_COUNT, DIVERGENCE_FACTOR, MAX_STEPS, DivergenceError

#: Newton iterations the implicit midpoint rule may take; it converges quadratically, to
#: round-off in 3-5 iterations for h |omega| < 1, so needing more means the step is too large
MIDPOINT_MAX_ITERATIONS = 50
#: the compiled loop cannot stop early: a fixed count, enough from explicit Euler's guess
#: (error (h omega)^2, squared by each iteration) for h |omega| up to about 1 (with the
#: spring-pendulum's stiff torque NumPy takes 3-4 at dt = 1 ms, 6 at 2 ms)
MIDPOINT_COMPILED_ITERATIONS = 6
#: the midpoint's Newton stops when a correction is below this many ulps of |I omega|, or, with
#: a torque, of the torque's own round-off (:meth:`ImplicitMidpoint.step`), whichever is larger
MIDPOINT_TOLERANCE_ULPS = 4


def angular_acceleration(xp, model, t, q, omega):
    """domega/dt = I^-1 (tau - omega x I omega), body frame."""
    inertia = model.inertia
    return (model.torque(xp, t, q, omega) - quat.cross(xp, omega, inertia * omega)) / inertia


def _skew(xp, v):
    """[v]x, shape (..., 3, 3): [v]x u = v x u."""
    z = xp.zeros_like(v[..., 0])
    entries = [z, -v[..., 2], v[..., 1], v[..., 2], z, -v[..., 0], -v[..., 1], v[..., 0], z]
    return xp.stack(entries, axis=-1).reshape(v.shape[:-1] + (3, 3))


def _solve(xp, matrix, rhs):
    return xp.linalg.solve(matrix, rhs[..., None])[..., 0]


def first_order_update(xp, q, omega, dt):
    """q + h/2 q (0, omega), normalised: the linearised exponential (body-frame omega)."""
    return quat.normalize(xp, q + 0.5 * dt * quat.multiply_vector(xp, q, omega))


def exponential_update(xp, q, omega, dt):
    """q exp(h omega), normalised: exact for a constant body-frame omega over the step."""
    return quat.normalize(xp, quat.multiply(xp, q, quat.exp(xp, dt * omega)))


@dataclasses.dataclass(frozen=True)
class RotationMethod(Integrator):
    """A fixed-step method for (q, omega); the theory is class data."""

    kind: ClassVar[str] = "rotation"
    evaluations: ClassVar[int] = 1
    #: the translation integrators it composes with, by registry name
    composes_with: ClassVar[tuple[str, ...]] = ()
    #: the stages of one step with the translation, in order
    stage_order: ClassVar[str] = ""
    #: where the method comes from (paper, engine, file)
    source: ClassVar[str] = ""
    #: what it keeps exactly on a free body ("energy", "|L|"), besides |q| = 1
    conserves: ClassVar[tuple[str, ...]] = ()

    def step(self, model, t, q, omega, dt):
        raise NotImplementedError

    def describe(self) -> dict:
        return super().describe() | {"composes_with": list(self.composes_with), "stage_order": self.stage_order,
                                     "source": self.source, "conserves": list(self.conserves)}


class Explicit(RotationMethod):
    """Explicit Euler on (q, omega): order 1; gains energy on every step of a tumbling body.

    omega1 = omega + h I^-1 (tau - omega x I omega) and q1 = normalise(q + h/2 q (0, omega)),
    both from the start of the step. Energy grows by h^2/2 alpha . I alpha > 0 per step on a
    free body (alpha . I omega = 0), so a tumbler spins up and eventually explodes (ODE's
    explicit gyroscopic term, Catto 2015).
    """

    name: ClassVar[str] = "explicit"
    style: ClassVar[tuple[str, str]] = ("tab:red", "o")
    order: ClassVar[int] = 1
    composes_with: ClassVar[tuple[str, ...]] = ("euler",)
    stage_order: ClassVar[str] = "forces and torques at t; then v, x, omega, q all from the values at t"
    source: ClassVar[str] = "Catto, 'Numerical Methods', GDC 2015 (the explicit gyroscopic term); ODE before patch 185"

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        alpha = angular_acceleration(xp, model, t, q, omega)
        q1 = first_order_update(xp, q, omega, dt)
        return q1, omega + dt * alpha


class FirstOrderQuaternion(RotationMethod):
    """omega first (explicit gyroscopic), then q += h/2 q (0, omega1), normalised: order 1.

    The linearised exponential: the rotation it applies has angle 2 atan(h|omega|/2), which
    lags the exact h|omega| by about (h|omega|)^3/12 per step.
    """

    name: ClassVar[str] = "first-order-quaternion"
    style: ClassVar[tuple[str, str]] = ("tab:orange", "s")
    order: ClassVar[int] = 1
    composes_with: ClassVar[tuple[str, ...]] = ("semi-implicit-euler",)
    stage_order: ClassVar[str] = "forces and torques at t; v and omega; then x and q with the new v and omega"
    source: ClassVar[str] = "Box2D v3 and Box3D b3IntegrateRotation (src/solver.c)"

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        omega1 = omega + dt * angular_acceleration(xp, model, t, q, omega)
        return first_order_update(xp, q, omega1, dt), omega1


class ExponentialMap(RotationMethod):
    """omega first (explicit gyroscopic), then q1 = q exp(h omega1) in the body frame: order 1.

    The orientation update is exact for the constant omega1 over the step; the error is
    that of the explicit gyroscopic term.
    """

    name: ClassVar[str] = "exponential-map"
    style: ClassVar[tuple[str, str]] = ("tab:green", "^")
    order: ClassVar[int] = 1
    composes_with: ClassVar[tuple[str, ...]] = ("semi-implicit-euler",)
    stage_order: ClassVar[str] = "forces and torques at t; v and omega; then x and q with the new v and omega"
    source: ClassVar[str] = "MuJoCo mj_integratePos (Euler), Bullet, PhysX, Jolt Body::AddRotationStep"

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        omega1 = omega + dt * angular_acceleration(xp, model, t, q, omega)
        return exponential_update(xp, q, omega1, dt), omega1


class ImplicitGyroscopic(RotationMethod):
    """One Newton step on I(omega2 - omega1) + h omega2 x I omega2 = 0, then the exponential map: order 1.

    The torque is applied explicitly first (omega1 = omega + h I^-1 tau). From omega1 the
    Newton step is omega2 = omega1 - J^-1 f with f = h omega1 x I omega1 and
    J = I + h ([omega1]x I - [I omega1]x). The backward-Euler flavour damps the tumbling
    (energy falls, |L| too), so it never explodes.
    """

    name: ClassVar[str] = "implicit-gyroscopic"
    style: ClassVar[tuple[str, str]] = ("tab:brown", "X")
    order: ClassVar[int] = 1
    implicit: ClassVar[bool] = True
    scheme: ClassVar[str] = "linearly implicit"  # one Newton step: one 3 x 3 solve, no iteration
    composes_with: ClassVar[tuple[str, ...]] = ("semi-implicit-euler",)
    stage_order: ClassVar[str] = ("forces and torques at t; v and omega (torque explicit, gyroscopic term "
                                  "by one Newton step); then x and q with the new v and omega")
    source: ClassVar[str] = ("Catto, GDC 2015; Box3D src/solver.c; Bullet "
                             "btRigidBody::computeGyroscopicImpulseImplicit_Body")

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        inertia = model.inertia
        omega1 = omega + dt * model.torque(xp, t, q, omega) / inertia
        momentum = inertia * omega1
        f = dt * quat.cross(xp, omega1, momentum)
        jacobian = (xp.eye(3) * inertia[..., None, :]
                    + dt * (_skew(xp, omega1) * inertia[..., None, :] - _skew(xp, momentum)))
        omega2 = omega1 - _solve(xp, jacobian, f)
        return exponential_update(xp, q, omega2, dt), omega2


class MomentumRescaled(RotationMethod):
    """Explicit gyroscopic term, omega rescaled to keep |I omega|, torque, then the exponential map: order 1.

    |L| is kept exactly on a free body but the energy is not: the rescaled omega has the
    right length of L and a drifting direction in the body, so a body spun about its stable
    major axis slowly turns into a tumbler.
    """

    name: ClassVar[str] = "momentum-rescaled"
    style: ClassVar[tuple[str, str]] = ("tab:pink", "P")
    order: ClassVar[int] = 1
    conserves: ClassVar[tuple[str, ...]] = ("|L|",)
    composes_with: ClassVar[tuple[str, ...]] = ("semi-implicit-euler",)
    stage_order: ClassVar[str] = ("forces and torques at t; v and omega (rescaled); then x and q with the new "
                                  "v and omega")
    source: ClassVar[str] = "Jolt MotionProperties (angular momentum kept on the gyroscopic step), PhysX; avian PR 993"

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        inertia = model.inertia
        gyro = omega - dt * quat.cross(xp, omega, inertia * omega) / inertia
        before, after = norm(xp, inertia * omega), norm(xp, inertia * gyro)
        gyro = gyro * xp.where(after > 0, before / xp.where(after > 0, after, 1.0), 1.0)[..., None]
        omega1 = gyro + dt * model.torque(xp, t, q, omega) / inertia
        return exponential_update(xp, q, omega1, dt), omega1


def _free_rotation_about_axis(xp, q, momentum, inertia, axis: int, h):
    """The exact flow for time h of H_k = pi_k^2 / (2 I_k): a rotation about body axis k.

    pi_k is constant; omega = (pi_k / I_k) e_k, so the body turns by a = h pi_k / I_k about
    e_k (q1 = q exp(a e_k)) while pi, fixed in space, turns by -a in the body frame.
    """
    i, j = (axis + 1) % 3, (axis + 2) % 3
    angle = h * momentum[..., axis] / inertia[..., axis]
    c, s = xp.cos(angle), xp.sin(angle)
    parts = [None] * 3
    parts[axis] = momentum[..., axis]
    parts[i] = c * momentum[..., i] + s * momentum[..., j]
    parts[j] = -s * momentum[..., i] + c * momentum[..., j]
    half = 0.5 * angle
    zero = xp.zeros_like(angle)
    axis_quaternion = [xp.cos(half), zero, zero, zero]
    axis_quaternion[1 + axis] = xp.sin(half)
    return quat.multiply(xp, q, xp.stack(axis_quaternion, axis=-1)), xp.stack(parts, axis=-1)


class DLM(RotationMethod):
    """The symplectic splitting of Dullweber, Leimkuhler and McLachlan: order 2, |L| exact.

    A Strang splitting of H = T + V: a half kick of the torque (pi += h/2 tau_body), the
    free rotation as the symmetric composition R1(h/2) R2(h/2) R3(h) R2(h/2) R1(h/2) of the
    exact flows of H_k = pi_k^2/(2 I_k) (each a rotation about one principal axis), and a
    second half kick. Every sub-flow is a rotation, so |L| is exact on a free body; the
    energy error stays bounded (O(h^2), no drift), the mark of a symplectic method.
    """

    name: ClassVar[str] = "dlm"
    style: ClassVar[tuple[str, str]] = ("tab:blue", "*")
    order: ClassVar[int] = 2
    symplectic: ClassVar[bool] = True
    evaluations: ClassVar[int] = 1
    conserves: ClassVar[tuple[str, ...]] = ("|L|",)
    composes_with: ClassVar[tuple[str, ...]] = ("velocity-verlet",)
    stage_order: ClassVar[str] = ("kick v and pi by h/2 with the forces and torques at t; drift x by h and "
                                  "rotate by the splitting; forces and torques at t + h; kick by h/2")
    source: ClassVar[str] = ("Dullweber, Leimkuhler and McLachlan, 'Symplectic splitting methods for rigid "
                             "body molecular dynamics', J. Chem. Phys. 107, 5840 (1997)")

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        inertia = model.inertia
        momentum = inertia * omega + 0.5 * dt * model.torque(xp, t, q, omega)
        for axis, fraction in ((0, 0.5), (1, 0.5), (2, 1.0), (1, 0.5), (0, 0.5)):
            q, momentum = _free_rotation_about_axis(xp, q, momentum, inertia, axis, fraction * dt)
        q = quat.normalize(xp, q)
        momentum = momentum + 0.5 * dt * model.torque(xp, t + dt, q, momentum / inertia)
        return q, momentum / inertia


class ImplicitMidpoint(RotationMethod):
    """The implicit midpoint rule on (q, I omega): order 2; keeps E and |L| exactly on a free body.

    pi1 = pi0 + h (pi_m x I^-1 pi_m + tau(q_m)) with pi_m = (pi0 + pi1)/2, solved by Newton's
    method to round-off, and q1 = q0 + h/2 q_m (0, omega_m), whose solution is the Cayley
    transform q1 = q0 cayley(h omega_m / 4). The midpoint rule keeps every quadratic
    invariant: |pi|^2 = |L|^2, pi . I^-1 pi = 2E and |q|^2. The torque is taken at the
    normalised midpoint orientation.

    Newton's matrix is d residual / d pi1 = 1 - h/2 ([pi_m]x I^-1 - [omega_m]x) - h d tau(q_m,
    omega_m) / d pi1, the torque's part by forward differences (3 more torque evaluations an
    iteration, only with a torque). Without it the iteration is a fixed point in the torque,
    contracting only by about h^2 |d tau / d theta| / (4 I): 0.11 at dt = 1 ms on
    spring-pendulum's spring (16 iterations), past 1 near 3 ms. With a torque the iteration also
    stops at the torque's round-off: the midpoint orientation turns by h / (4 I) per unit of
    pi1, so its last ulp moves h tau by eps (4 I / h) |d (h tau) / d pi1|, which on a stiff
    spring is far above 4 ulps of |pi0| (the corrections cycled at 8e-17 against a tolerance of
    8e-19 at dt = 1 ms). eps is the state's precision, which is the torque's: a float32 run's
    lever arms and forces are float32.
    """

    name: ClassVar[str] = "implicit-midpoint"
    style: ClassVar[tuple[str, str]] = ("tab:purple", "D")
    order: ClassVar[int] = 2
    implicit: ClassVar[bool] = True
    scheme: ClassVar[str] = "implicit"  # Newton iterated to round-off
    symplectic: ClassVar[bool] = True
    conserves: ClassVar[tuple[str, ...]] = ("energy", "|L|")
    composes_with: ClassVar[tuple[str, ...]] = ("velocity-verlet",)
    stage_order: ClassVar[str] = ("kick v and pi by h/2 with the forces and torques at t; drift x by h and "
                                  "rotate freely by the implicit midpoint rule; forces and torques at t + h; "
                                  "kick by h/2 (dlm's Strang splitting)")
    source: ClassVar[str] = ("Hairer, Lubich and Wanner, Geometric Numerical Integration, IV.1 and VII.5 "
                             "(quadratic invariants; the rigid body)")

    def step(self, model, t, q, omega, dt):
        xp = model.xp
        inertia = model.inertia
        pi0 = inertia * omega
        pi1 = pi0 + dt * quat.cross(xp, pi0, omega)  # explicit Euler's guess: Newton then needs 2-3 iterations
        size = xp.max(xp.abs(pi0), axis=-1)
        tolerance = MIDPOINT_TOLERANCE_ULPS * np.finfo(float).eps * size
        if model.torques:
            eps = float(np.finfo(np.result_type(q.dtype, omega.dtype)).eps)  # the torque's precision (see above)
            turn = 4 * xp.max(inertia, axis=-1) / dt  # the change of pi1 that turns q_m by 1 rad
        # NumPy stops once every body has converged; the compiled loop takes a fixed count
        iterations = MIDPOINT_MAX_ITERATIONS if is_numpy(xp) else MIDPOINT_COMPILED_ITERATIONS
        for _ in range(iterations):
            pi_m = 0.5 * (pi0 + pi1)
            omega_m = pi_m / inertia
            residual = pi1 - pi0 - dt * quat.cross(xp, pi_m, omega_m)
            # d residual / d pi1 = 1 - h/2 ([pi_m]x I^-1 - [omega_m]x) - h d tau / d pi1
            jacobian = xp.eye(3) - 0.5 * dt * (_skew(xp, pi_m) / inertia[..., None, :] - _skew(xp, omega_m))
            if model.torques:
                kick = _midpoint_kick(model, t, q, pi0, pi1, dt)
                residual = residual - kick
                # forward differences, a step of sqrt(eps) rad of q_m (or sqrt(eps) |pi1| when larger)
                delta = np.sqrt(eps) * xp.maximum(xp.max(xp.abs(pi1), axis=-1), turn)[..., None]
                torque_jacobian = xp.stack([(_midpoint_kick(model, t, q, pi0, pi1 + delta * unit, dt) - kick) / delta
                                            for unit in xp.eye(3)], axis=-1)
                jacobian = jacobian - torque_jacobian
                # the torque's round-off: the last ulp of q_m moves h tau by eps turn |d (h tau) / d pi1|
                floor = turn * xp.max(xp.abs(torque_jacobian), axis=(-2, -1))
                tolerance = MIDPOINT_TOLERANCE_ULPS * eps * xp.maximum(size, floor)
            correction = _solve(xp, jacobian, residual)
            pi1 = pi1 - correction
            converged = xp.max(xp.abs(correction), axis=-1) <= tolerance  # False on NaN
            if is_numpy(xp) and np.all(converged | ~np.isfinite(pi1).all(axis=-1)):  # diverged bodies stay NaN
                break
        # no convergence: the step is too large, reported by the driver as a divergence
        pi1 = xp.where(converged[..., None], pi1, np.nan)
        omega1 = pi1 / inertia
        q1 = quat.multiply(xp, q, quat.cayley(xp, 0.25 * dt * 0.5 * (omega + omega1)))
        return quat.normalize(xp, q1), omega1


def _midpoint_kick(model, t, q, pi0, pi1, dt):
    """h tau at the implicit midpoint: the normalised midpoint orientation of q0 and q1 = q0 cayley(h omega_m / 4),
    and omega_m = (pi0 + pi1) / (2 I)."""
    xp = model.xp
    omega_m = 0.5 * (pi0 + pi1) / model.inertia
    q1 = quat.multiply(xp, q, quat.cayley(xp, 0.25 * dt * omega_m))
    return dt * model.torque(xp, t + 0.5 * dt, quat.normalize(xp, 0.5 * (q + q1)), omega_m)


class RK4(RotationMethod):
    """Classical RK4 on (q, omega), q normalised after the step: order 4."""

    name: ClassVar[str] = "rk4"
    style: ClassVar[tuple[str, str]] = ("black", "v")
    order: ClassVar[int] = 4
    evaluations: ClassVar[int] = 4
    composes_with: ClassVar[tuple[str, ...]] = ("rk4",)
    stage_order: ClassVar[str] = "the four stages on (x, v, q, omega) together, q normalised after the step"
    source: ClassVar[str] = "MuJoCo mj_RungeKutta (RK4 integrator), which normalises the quaternion after the step"

    def step(self, model, t, q, omega, dt):
        xp = model.xp

        def rate(t, q, omega):
            return 0.5 * quat.multiply_vector(xp, q, omega), angular_acceleration(xp, model, t, q, omega)

        k1 = rate(t, q, omega)
        k2 = rate(t + 0.5 * dt, q + 0.5 * dt * k1[0], omega + 0.5 * dt * k1[1])
        k3 = rate(t + 0.5 * dt, q + 0.5 * dt * k2[0], omega + 0.5 * dt * k2[1])
        k4 = rate(t + dt, q + dt * k3[0], omega + dt * k3[1])
        q1 = q + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        omega1 = omega + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        return quat.normalize(xp, q1), omega1


#: steplab's rotation methods, in the order ``steplab integrators`` lists them
METHODS = (Explicit(), FirstOrderQuaternion(), ExponentialMap(), ImplicitGyroscopic(), MomentumRescaled(),
           DLM(), ImplicitMidpoint(), RK4())

DEFAULT_ROTATION = "exponential-map"


def simulate_rotation(method: RotationMethod, model, q0, omega0, dt: float, n_steps: int, *, t0: float = 0.0,
                      save_every: int = 1, backend: str = "numpy", check: bool = True):
    """Run ``method`` for ``n_steps`` fixed steps of ``dt`` from (q0, omega0 in the body frame).

    ``backend="jax"`` runs the same ``step`` as one compiled loop (``jax.lax.scan`` over the
    saved states, ``fori_loop`` inside; ``n_steps`` a multiple of ``save_every``); it agrees with
    NumPy to round-off. ``backend="numba"`` runs ``exponential-map`` on free bodies only, as the
    vectorised kernel of :mod:`.rotation_compiled`, bit for bit NumPy's. ``check=False`` lets
    bodies diverge (a stability scan of many bodies at once): their states become non-finite
    and the others run on.

    Returns
    -------
    t : ndarray, shape (K,)
    q : ndarray, shape (K, R, 4)
    omega : ndarray, shape (K, R, 3)
        Body frame, at t0 and every ``save_every`` steps (and the last step).

    Raises
    ------
    DivergenceError
        omega became non-finite or grew beyond :data:`.simulate.DIVERGENCE_FACTOR` times
        its start (or 1 rad/s).
    """
    if not isinstance(method, RotationMethod):  # the registry imports this module: a name is the caller's to look up
        raise TypeError(f"simulate_rotation: method must be a RotationMethod (get_rotation({method!r}) for a name), "
                        f"got a {type(method).__name__}")
    if backend not in ("numpy", "jax", "numba"):
        raise ValueError(f"simulate_rotation: backend must be 'numpy', 'jax' or 'numba', got {backend!r}")
    check_count("simulate_rotation", "n_steps", n_steps, MAX_STEPS, "steplab.integrators.simulate.MAX_STEPS")
    check_count("simulate_rotation", "save_every", save_every, ANY_COUNT, "a 64-bit integer")
    check_real("simulate_rotation", "dt", dt, lambda h: h > 0, "a step > 0 s")
    q, omega = np.asarray(q0, float), np.asarray(omega0, float)
    if q.ndim != 2 or q.shape[1:] != (4,) or omega.shape != (len(q), 3):
        raise ValueError(f"simulate_rotation: q0 must have shape (R, 4) (unit quaternions) and omega0 (R, 3), "
                         f"got {q.shape} and {omega.shape}")
    limit = DIVERGENCE_FACTOR * max(1.0, float(np.max(np.abs(omega), initial=0.0)))
    if backend == "jax":
        ts, qs, omegas = _compiled_rotation(method, model, q, omega, dt, n_steps, t0, save_every)
    elif backend == "numba":
        ts, qs, omegas = _numba_rotation(method, model, q, omega, dt, n_steps, t0, save_every)
    else:
        ts, qs, omegas = [t0], [q], [omega]
        errors = np.errstate(all="ignore") if not check else contextlib.nullcontext()
        with errors:
            for k in range(1, n_steps + 1):
                q, omega = method.step(model, t0 + (k - 1) * dt, q, omega, dt)
                if k % save_every == 0 or k == n_steps:
                    if check and not (np.all(np.isfinite(omega)) and np.all(np.isfinite(q))
                                      and np.max(np.abs(omega)) < limit):
                        raise DivergenceError(method.name, dt, k, t0 + k * dt)
                    ts.append(t0 + k * dt)
                    qs.append(q)
                    omegas.append(omega)
        ts, qs, omegas = np.array(ts), np.array(qs), np.array(omegas)
    bad = ~(np.all(np.isfinite(qs), axis=(1, 2)) & np.all(np.abs(omegas) < limit, axis=(1, 2)))
    if check and np.any(bad):  # the compiled loop runs to the end: the first bad saved state names the step
        k = int(np.argmax(bad))
        raise DivergenceError(method.name, dt, int(round((ts[k] - t0) / dt)), float(ts[k]))
    return ts, qs, omegas


def _numba_rotation(method, model, q, omega, dt, n_steps, t0, save_every):
    from .rotation_compiled import exponential_map_steps, free_bodies
    from .simulate import saved_steps

    if method.name != "exponential-map" or model.torques:
        raise ValueError(f"the numba rotation backend runs exponential-map on free bodies, not {method.name}"
                         f"{' with torques' if model.torques else ''}: use backend numpy or jax")
    bodies = free_bodies(q, omega, model.inertia)
    saves = saved_steps(n_steps, save_every)
    qs, omegas = [q], [omega]
    for n in np.diff(saves):
        exponential_map_steps(bodies, dt, n)
        qs.append(bodies.q.T.copy())
        omegas.append(bodies.omega.T.copy())
    return t0 + saves * dt, np.array(qs), np.array(omegas)


def compiled_steps(method, model, dt: float, n_steps: int, t0: float = 0.0):
    """``n_steps`` steps of ``method`` from t0 as one jitted ``run(q, omega) -> (q, omega)``, the
    loop :func:`simulate_rotation` compiles between two saved states (for benchmarks)."""
    import jax
    import jax.numpy as jnp

    model = dataclasses.replace(model, xp=jnp)
    return jax.jit(lambda q, omega: jax.lax.fori_loop(
        0, n_steps, lambda i, state: method.step(model, t0 + i * dt, *state, dt), (q, omega)))


def _compiled_rotation(method, model, q, omega, dt, n_steps, t0, save_every):
    import jax
    import jax.numpy as jnp

    if n_steps % save_every:
        raise ValueError(f"the compiled rotation loop needs n_steps ({n_steps}) to be a multiple of save_every "
                         f"({save_every})")
    model = dataclasses.replace(model, xp=jnp)

    def chunk(state, k):
        def one_step(i, state):
            return method.step(model, t0 + (k * save_every + i) * dt, *state, dt)

        state = jax.lax.fori_loop(0, save_every, one_step, state)
        return state, state

    @jax.jit
    def run(q, omega):
        return jax.lax.scan(chunk, (q, omega), jnp.arange(n_steps // save_every))[1]

    qs, omegas = run(jnp.asarray(q), jnp.asarray(omega))
    ts = t0 + dt * save_every * np.arange(n_steps // save_every + 1)
    return ts, np.concatenate([q[None], np.asarray(qs)]), np.concatenate([omega[None], np.asarray(omegas)])
