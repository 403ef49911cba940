"""The stiffest mode of a model whose springs or dampers act at body-frame points: translation and rotation together.

A spring at a point r of a rotating body pulls the point x + R(q) r, so a small turn theta of
the body moves the point by theta x (R r) as a translation of the centre moves it: the body's
rotation is a degree of freedom of the spring's modes as much as its position. Linearised
about a state, the generalised coordinates z = (x of every free body, theta of every free
rotating body) obey M z'' = -K z - C z', M = diag(m I3, I_world), and the stiffest mode is the
largest omega^2 of K phi = omega^2 M phi (:func:`.modes.stiffest_mode` holds the lever arms, and so
the rotation, fixed: for a cube hung at its corner by a spring of rest length 0 it finds
sqrt(k / m), where the transverse mode is sqrt(k (1/m + |r|^2 / I)), 2.3 times faster).

K and C come from central differences of the generalised forces (the centres' forces, the
bodies' world torques; :func:`.attachments.model_at`, :func:`.attachments.torques`) in x and
theta, and in v and omega. Scenes with attachments are small (the bodies a designer hangs by
their corners); the eigenproblem is dense.
"""

from __future__ import annotations

import numpy as np

from . import attachments
from . import quaternion as quat
from .modes import NonFiniteModelError, StiffestMode, check_finite_mode, symmetric_part

#: central differences' step, relative to the scale of what is moved (positions, 1 rad, speeds)
STEP = 1e-6
#: the most generalised coordinates the dense eigenproblem takes (4 force evaluations each, an eigh
#: of their square): a few hundred bodies. Above it :func:`.modes.stiffest_mode` of the translation
#: alone answers (its lever arms held), as before attachments counted their turns
COUPLED_SIZE = 600


def coupled_stiffest_mode(model, bodies, q, v=None) -> StiffestMode:
    """The highest-frequency mode of ``model`` (with attached forces) about positions ``q`` (N, 3)
    and velocities ``v`` (default 0), its rotating ``bodies`` (physics.rigid_body.RigidBodies) at
    their orientations and angular velocities: omega (rad/s, None without one), its damping ratio
    and its translation's pattern (N, 3) (zero for a mode of the rotation alone)."""
    from scipy.linalg import eigh

    q0 = np.asarray(q, dtype=float)
    v0 = np.zeros_like(q0) if v is None else np.asarray(v, dtype=float)
    n = model.n_bodies
    free = np.asarray(model.inverse_masses, dtype=float) > 0
    turning = np.asarray(bodies.index)[free[bodies.index]]  # a pinned body neither moves nor turns
    rows = {int(b): k for k, b in enumerate(bodies.index)}
    orientations, omega0 = bodies.of_all(n)
    moved = np.flatnonzero(free)
    size = 3 * (len(moved) + len(turning))
    if size > COUPLED_SIZE:
        from .modes import stiffest_mode

        return stiffest_mode(model, q0, v0, derivative="difference")

    def forces(dz, dw):
        """The generalised forces (forces on the moved centres, torques on the turning bodies) with the
        coordinates moved by ``dz`` and the velocities by ``dw`` (each ``size``)."""
        x, u = q0.copy(), v0.copy()
        x[moved] += dz[:3 * len(moved)].reshape(-1, 3)
        u[moved] += dw[:3 * len(moved)].reshape(-1, 3)
        turned, omega = orientations.copy(), omega0.copy()
        turned[turning] = quat.multiply(np, quat.exp(np, dz[3 * len(moved):].reshape(-1, 3)), orientations[turning])
        omega[turning] += dw[3 * len(moved):].reshape(-1, 3)
        at = attachments.model_at(model, turned, omega)
        force = np.asarray(at.acceleration(0.0, x, u), dtype=float) / np.where(free, at.inverse_masses, 1.0)[:, None]
        torque = attachments.torques(at, x, u)
        return np.concatenate([force[moved].ravel(), np.asarray(torque, dtype=float)[turning].ravel()])

    scale = np.concatenate([np.full(3 * len(moved), max(1.0, float(np.max(np.abs(q0))))), np.ones(3 * len(turning))])
    speed = np.concatenate([np.full(3 * len(moved), max(1.0, float(np.max(np.abs(v0))))),
                            np.full(3 * len(turning), max(1.0, float(np.max(np.abs(omega0)))))])
    zero = np.zeros(size)
    stiffness, damping = np.empty((size, size)), np.empty((size, size))
    for k in range(size):
        e = np.zeros(size)
        e[k] = STEP * scale[k]
        stiffness[:, k] = -(forces(e, zero) - forces(-e, zero)) / (2 * e[k])
        e[k] = STEP * speed[k]
        damping[:, k] = -(forces(zero, e) - forces(zero, -e)) / (2 * e[k])
    if not (np.all(np.isfinite(stiffness)) and np.all(np.isfinite(damping))):
        raise NonFiniteModelError("the model's stiffness, with its bodies turned, is not finite at its initial "
                                  "state: no stable dt can be predicted")
    mass = np.zeros((size, size))
    masses = np.asarray(model.masses, dtype=float)
    for k, body in enumerate(moved):
        mass[3 * k:3 * k + 3, 3 * k:3 * k + 3] = masses[body] * np.eye(3)
    for k, body in enumerate(turning):
        rotation = quat.to_matrix(np, orientations[body])
        s = 3 * (len(moved) + k)
        mass[s:s + 3, s:s + 3] = rotation @ np.diag(np.asarray(bodies.inertia, float)[rows[int(body)]]) @ rotation.T
    try:
        values, vectors = eigh(symmetric_part(stiffness), mass)
    except np.linalg.LinAlgError:  # LAPACK's reduction overflowed (a spring of 1e308 N/m on a small inertia)
        raise NonFiniteModelError("the model's stiffness, with its bodies turned, has no eigenvalues LAPACK can "
                                  "compute in float64 (they overflow): no stable dt can be predicted") from None
    pattern = np.zeros((n, 3))
    if not len(values) or values[-1] <= 0:
        return StiffestMode(None, 0.0, pattern)
    omega, phi = float(np.sqrt(values[-1])), vectors[:, -1]  # phi^T M phi = 1
    zeta = float(phi @ symmetric_part(damping) @ phi / (2 * omega))
    check_finite_mode(omega, zeta)
    pattern[moved] = phi[:3 * len(moved)].reshape(-1, 3)
    peak = np.max(np.abs(pattern))
    return StiffestMode(omega, zeta if zeta > 0 else 0.0, pattern / peak if peak > 0 else pattern)
