"""Springs and dampers at body-frame points: a scene's translation and rotation stepped together.

A force at a point couples the two systems (:mod:`steplab.physics.attachments`): the force on a
centre depends on the orientations, through the lever arms R(q) r, and the torque on a body
depends on the positions. :class:`AttachedStep` advances both with the same dt, in one of two
stage orders:

- velocity Verlet with ``dlm``: the Strang splitting of H = T + V that both methods are. Half
  kicks of v and of the body-frame momentum pi with the forces and torques at (x, q); the drift of
  x and the free rotation of q (dlm's, without torque) by h; half kicks at the new (x, q).
  Symplectic and second order, so the energy error stays bounded.
- every other pair: the forces and torques at the start of the step. The translation
  integrator steps with the orientations held there, the rotation method with the positions
  and velocities held there. The coupling is then first order. For semi-implicit Euler with a
  method that updates omega first (``exponential-map``, ``first-order-quaternion``,
  ``implicit-gyroscopic``, ``momentum-rescaled``) this is their declared stage order, "forces and
  torques at t; v and omega; then x and q".

NumPy only (each stage rebuilds the model at the new lever arms, :func:`.attachments.model_at`).
A scene without attachments never comes here: :func:`.scene_rotation.rotate_scene` runs its free
rotation beside the translation.
"""

from __future__ import annotations

import numpy as np
from steplab.physics import attachments
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import RigidBodies, RotationModel

from .scene_rotation import RotationTrajectory
from .simulate import DivergenceError


class AttachedStep:
    """``step(t, y, dt, carry) -> (y, carry)`` of a model with attached forces, its rotating
    ``bodies`` stepped by ``rotation`` beside ``integrator``; the rotation after every step is kept.

    Parameters
    ----------
    model : physics.Model
        NumPy; its attached forces carry their body-frame offsets.
    bodies : physics.rigid_body.RigidBodies
        The rotating bodies at the start.
    integrator : integrators.base.Stepper
    rotation : integrators.rotation.RotationMethod
    """

    def __init__(self, model, bodies: RigidBodies, integrator, rotation):
        if model.xp is not np:
            raise ValueError("springs and dampers at body-frame points (offsets) run on the NumPy backend; "
                             "use --backend numpy")
        self.model, self.bodies, self.integrator, self.rotation = model, bodies, integrator, rotation
        self.q, self.omega = bodies.orientations, bodies.body_angular_velocities()
        self.strang = integrator.name == "velocity-verlet" and rotation.name == "dlm"
        self.free = RotationModel(bodies.inertia)  # dlm without torque: its free rotation
        self.saved = [(self.q, self.omega)]
        self.log = None  # no collisions
        self._kept = None  # velocity Verlet's last acceleration and torque, for the next first kick

    def model_at(self, q, omega):
        """The model with its lever arms at the rotating bodies' ``q`` (R, 4) and body-frame ``omega`` (R, 3);
        with the orientations (N, 4) of all bodies."""
        n = self.model.n_bodies
        orientations, angular_velocities = np.zeros((n, 4)), np.zeros((n, 3))
        orientations[:, 0] = 1.0
        orientations[self.bodies.index] = q
        angular_velocities[self.bodies.index] = quat.rotate(np, q, omega)
        return attachments.model_at(self.model, orientations, angular_velocities), orientations

    def final_model(self):
        """The model with its lever arms at the last step's orientations (for the energy at the end)."""
        return self.model_at(self.q, self.omega)[0]

    def _accelerations(self, t, x, v, q, omega):
        """The centres' acceleration (N, 3) and the rotating bodies' body-frame torque (R, 3) at one state."""
        model, orientations = self.model_at(q, omega)
        torque = attachments.torques(model, x, v, orientations)[self.bodies.index]
        return model.acceleration(t, x, v), quat.rotate_inverse(np, q, torque)

    def __call__(self, t, y, dt, carry):
        y = self._strang(t, y, dt) if self.strang else self._held(t, y, dt)
        if not (np.all(np.isfinite(self.q)) and np.all(np.isfinite(self.omega))):
            raise DivergenceError(f"{self.integrator.name} with {self.rotation.name}", dt, len(self.saved),
                                  t + dt)
        self.saved.append((self.q, self.omega))
        return y, carry

    def _held(self, t, y, dt):
        # each system steps with the other held at the start of the step
        model, orientations = self.model_at(self.q, self.omega)
        y1, _ = self.integrator.step(model, t, y, dt, self.integrator.init(model, t, y))
        torque = _HeldTorque(self, y[0], y[1], (self.q, self.omega, model, orientations))
        self.q, self.omega = self.rotation.step(RotationModel(self.bodies.inertia, (torque,)), t, self.q, self.omega,
                                                dt)
        return y1

    def _strang(self, t, y, dt):
        # kick (h/2), drift and free rotation (h), kick (h/2): velocity Verlet and dlm at once
        inertia = self.bodies.inertia
        x, v = y
        a0, tau0 = self._kept or self._accelerations(t, x, v, self.q, self.omega)
        v_half = v + 0.5 * dt * a0
        x1 = x + dt * v_half
        q1, omega_free = self.rotation.step(self.free, t, self.q, self.omega + 0.5 * dt * tau0 / inertia, dt)
        # the second kick's velocities as each method estimates them: v + h a0 (Verlet), the rotated pi (dlm)
        a1, tau1 = self._accelerations(t + dt, x1, v + dt * a0, q1, omega_free)
        self._kept = (a1, tau1)
        self.q, self.omega = q1, omega_free + 0.5 * dt * tau1 / inertia
        return np.stack([x1, v_half + 0.5 * dt * a1])

    def rotation_trajectory(self, trajectory) -> RotationTrajectory:
        """The rotating bodies at ``trajectory``'s saved times (a run of this step)."""
        t = np.asarray(trajectory.t, float)
        k = np.rint((t - t[0]) / trajectory.dt).astype(int)
        qs = np.array([self.saved[i][0] for i in k])
        omegas = np.array([self.saved[i][1] for i in k])
        name = f"{self.rotation.name} (with {self.integrator.name}, coupled)"
        return RotationTrajectory(t, qs, quat.rotate(np, qs, omegas), name, self.bodies)


class _HeldTorque:
    """The attached forces' torque at positions ``x`` and velocities ``v`` held over a rotation step;
    ``start`` is (q, omega, model, orientations) at the step's start, which most methods ask for."""

    def __init__(self, step: AttachedStep, x, v, start):
        self.step, self.x, self.v, self.start = step, x, v, start

    def torque(self, xp, t, q, omega_body):
        q0, omega0, model, orientations = self.start
        if q is not q0 or omega_body is not omega0:  # a stage inside the step (rk4, dlm's second kick)
            model, orientations = self.step.model_at(q, omega_body)
        return attachments.torques(model, self.x, self.v, orientations)[self.step.bodies.index]


def attached_stepper(bodies: RigidBodies, rotation, kept: list | None = None):
    """``stepper(model, integrator)`` for :func:`.simulate` (its ``stepper`` argument): an
    :class:`AttachedStep`, appended to ``kept`` so that the caller reads its rotation after the run."""

    def build(model, integrator):
        step = AttachedStep(model, bodies, integrator, rotation)
        if kept is not None:
            kept.append(step)
        return step

    return build
