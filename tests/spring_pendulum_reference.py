"""spring-pendulum's coupled equations solved independently of steplab: DOP853 at rtol 1e-12.

Typed from physics/scenes/spring-pendulum.toml: a 1 kg cube of side 0.1 m hung at its corner r (body
frame) from a pinned anchor by a spring of stiffness K and rest length 0, under gravity. The
equations are written here from Newton's and Euler's laws, not taken from steplab.
"""

import functools

import numpy as np
from scipy.integrate import solve_ivp

K = 1e5
MASS = 1.0
INERTIA = np.full(3, MASS * 0.1**2 / 6)  # a cube about its centre
CORNER = np.array([0.05, 0.05, 0.05])
ANCHOR = np.array([0.0, 0.0, 1.0])
GRAVITY = np.array([0.0, 0.0, -9.81])


def rotation_matrix(q):
    """Body to world of the quaternion [w, x, y, z] (normalised here)."""
    w, x, y, z = np.asarray(q) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quaternion_product(p, q):
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def coupled_rhs(t, s):
    """d/dt of (x, v, q, omega_body) of the cube: gravity and the spring's force at the corner x + R(q) r on the
    centre; its torque (R r) x F, in the body frame, in Euler's equations; q' = 1/2 q (0, omega_body)."""
    x, v, q, omega = s[:3], s[3:6], s[6:10], s[10:]
    rot = rotation_matrix(q)
    arm = rot @ CORNER
    force = -K * (x + arm - ANCHOR)
    torque = rot.T @ np.cross(arm, force)
    return np.concatenate([v, GRAVITY + force / MASS, 0.5 * quaternion_product(q, np.concatenate([[0.0], omega])),
                           (torque - np.cross(omega, INERTIA * omega)) / INERTIA])


@functools.cache
def coupled_solution(s0: tuple, t0: float, t1: float):
    """DOP853 at rtol 1e-12 from ``s0`` over [t0, t1], its dense output: solved once for every run of the same
    start and span (its steps do not depend on the times it is read at; solve_ivp's t_eval reads these
    interpolants)."""
    sol = solve_ivp(coupled_rhs, (t0, t1), np.array(s0), method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
    assert sol.success, sol.message
    return sol.sol


def independent_solution(scene, t):
    """The cube's centre (K, 3) and corner lever arm R(q) r (K, 3) at the times ``t``: DOP853 at rtol 1e-12."""
    q0 = scene.rigid_bodies.orientations[0]
    omega0 = rotation_matrix(q0).T @ scene.rigid_bodies.angular_velocities[0]  # world to body
    s0 = np.concatenate([scene.y0[0, 1], scene.y0[1, 1], q0, omega0])
    y = coupled_solution(tuple(s0.tolist()), float(t[0]), float(t[-1]))(t)
    return y[:3].T, np.array([rotation_matrix(q) @ CORNER for q in y[6:10].T])


def independent_errors(scene, integrator, rotation, n, t_end):
    """The largest centre and lever-arm errors, m, of the coupled run that ``steplab run`` takes in ``n`` steps."""
    from steplab.integrators import simulate
    from steplab.integrators.attached import attached_stepper
    from steplab.integrators.rotation_registry import get_rotation
    from steplab.integrators.simulate import DivergenceError

    kept = []
    try:
        with np.errstate(all="ignore"):
            traj = simulate(scene.model, integrator, scene.y0, 0.0, dt=t_end / n, n_steps=n,
                            stepper=attached_stepper(scene.rigid_bodies, get_rotation(rotation), kept))
    except DivergenceError:
        return np.inf, np.inf
    centres, arms = independent_solution(scene, traj.t)
    q = kept[0].rotation_trajectory(traj).orientations[:, 0]
    run_arms = np.array([rotation_matrix(qk) @ CORNER for qk in q])
    return (float(np.max(np.linalg.norm(traj.y[:, 0, 1] - centres, axis=-1))),
            float(np.max(np.linalg.norm(run_arms - arms, axis=-1))))
