"""A scene's rotating bodies along a run: the rotation method stepped beside the translation.

A scene's forces that act at the bodies' centres (gravity, drag, springs and dampers between
centres) exert no torque: each rotating body is then a free rigid body while its centre
moves as a point mass, and the two systems are integrated side by side with the same dt,
saved at the same times. The translation is untouched, bit for bit, and a scene without
rotating bodies does no rotation work at all. Springs and dampers at body-frame points
(``offsets``) couple the two and feed their torques to the rotation: such a scene is stepped
by :mod:`.attached`, and :func:`rotate_scene` refuses it.

``steplab run`` and the scenes study call :func:`run_rotation` after :func:`.simulate`; ``run`` then
:func:`rotation_summary` for its JSON fields and :func:`rotation_arrays` for the NPZ file.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from steplab.physics import quaternion as quat
from steplab.physics.attachments import attached_forces
from steplab.physics.rigid_body import RigidBodies, RotationModel, total_angular_momentum

from .rotation import DEFAULT_ROTATION, RotationMethod, simulate_rotation
from .rotation_reference import rotation_reference


@dataclasses.dataclass(frozen=True)
class RotationTrajectory:
    """The rotating bodies at a run's saved times.

    Attributes
    ----------
    t : ndarray, shape (K,)
        The translation trajectory's saved times.
    orientations : ndarray, shape (K, R, 4)
    angular_velocities : ndarray, shape (K, R, 3)
        World frame, rad/s.
    method : str
        The rotation method (or the reference, for a reference solve).
    bodies : RigidBodies
        The initial state (index, inertia, shapes).
    """

    t: np.ndarray
    orientations: np.ndarray
    angular_velocities: np.ndarray
    method: str
    bodies: RigidBodies

    def at(self, k: int) -> RigidBodies:
        """The rotating bodies at the k-th saved time."""
        return dataclasses.replace(self.bodies, orientations=self.orientations[k],
                                   angular_velocities=self.angular_velocities[k])


def rotate_scene(scene, trajectory, rotation: str | None = None, backend: str = "numpy") -> RotationTrajectory | None:
    """Integrate the rotation of ``scene``'s rotating bodies at the saved times of ``trajectory``.

    Parameters
    ----------
    scene : physics.scene.Scene
    trajectory : integrators.Trajectory
        The run of the scene's translation; a fixed-step run gives the steps (its ``dt``),
        a reference solve (``steps == 0``) is matched by the rotation reference (DOP853 at
        1e-13) at the same times.
    rotation : str, optional
        A rotation method's name (``--rotation``); default the scene's ``[simulation]
        rotation``, else :data:`.rotation.DEFAULT_ROTATION`.

    Returns
    -------
    RotationTrajectory, or None for a scene without rotating bodies.

    Raises
    ------
    UnknownIntegratorError
        An unknown rotation method (one line naming the valid ones).
    DivergenceError
        The rotation diverged.
    """
    from . import get_rotation

    bodies = scene.rigid_bodies
    method = get_rotation(rotation or scene.rotation or DEFAULT_ROTATION)  # checked even without rotating bodies
    if bodies is None:
        return None
    if attached_forces(scene.model):
        raise ValueError(f"scene {scene.name}: its springs or dampers at body-frame points turn the bodies; step "
                         "its translation and rotation together (steplab.integrators.attached)")
    model = RotationModel(bodies.inertia)
    q, omega = bodies.orientations, bodies.body_angular_velocities()
    t = np.asarray(trajectory.t, float)
    dtype = np.asarray(trajectory.y).dtype  # the run's precision: its state after every step, the rotation's too
    if trajectory.steps == 0:  # an adaptive reference solves in float64 and stores in the run's precision
        qs, omegas = rotation_reference(model, q, omega, t, method="scipy-dop853")
        name = "scipy-dop853"
    else:
        if dtype != np.float64:
            method = InPrecision(method, dtype)
        steps = np.diff(np.rint((t - t[0]) / trajectory.dt).astype(int))
        qs, omegas = [q[None]], [omega[None]]
        # the saved states every n steps as one run (on JAX one compiled loop), the last
        # (shorter) segment of a run that keeps its final state on its own
        n, uniform = (steps[0], np.sum(np.cumprod(steps == steps[0]))) if len(steps) else (0, 0)
        segments = ([(n, uniform)] if uniform and n > 0 else []) + [(k, 1) for k in steps[uniform:]]
        t0 = t[0]
        for n, count in segments:
            if n > 0:
                _, q_k, omega_k = simulate_rotation(method, model, q, omega, trajectory.dt, n * count, t0=t0,
                                                    save_every=n, backend=backend)
                q, omega = q_k[-1], omega_k[-1]
                qs.append(q_k[1:])
                omegas.append(omega_k[1:])
            else:  # a repeated saved time
                qs.append(q[None])
                omegas.append(omega[None])
            t0 = t0 + n * count * trajectory.dt
        qs, omegas, name = np.concatenate(qs), np.concatenate(omegas), method.name
    qs, omegas = np.asarray(qs, dtype), np.asarray(omegas, dtype)
    return RotationTrajectory(t, qs, quat.rotate(np, qs, omegas), name, bodies)


class InPrecision(RotationMethod):
    """``method`` whose state (q, omega) is rounded to ``dtype`` after every step: a float32 run's
    free bodies, as :func:`.attached.in_precision` keeps a coupled step's. The rotation methods compute
    with float64 moments (:class:`.rigid_body.RotationModel`) and :func:`.rotation.simulate_rotation`
    starts from float64, so without it a float32 run would turn its bodies in float64. The rounded
    state keeps the array type it came in (a compiled loop's carry keeps its dtype)."""

    def __init__(self, method: RotationMethod, dtype):
        self.method, self.dtype, self.name = method, np.dtype(dtype), method.name

    def step(self, model, t, q, omega, dt):
        q1, omega1 = self.method.step(model, t, q, omega, dt)
        return q1.astype(self.dtype).astype(q1.dtype), omega1.astype(self.dtype).astype(omega1.dtype)


def run_rotation(scene, trajectory, step=None, rotation: str | None = None,
                 backend: str = "numpy") -> RotationTrajectory | None:
    """The rotating bodies at ``trajectory``'s saved times, however the run turned them.

    ``step`` is the step :func:`.simulate` built for the run (None: the integrator's own): an
    attached step (springs at body-frame points) stepped the rotation with the translation,
    the contact solver's turned the bodies with their contacts (the orientations it recorded);
    otherwise the bodies are free and :func:`rotate_scene` integrates them beside the translation
    with ``rotation``. None for a scene without rotating bodies.
    """
    bodies = scene.rigid_bodies
    if bodies is None:
        return None
    if step is not None and hasattr(step, "rotation_trajectory"):
        return step.rotation_trajectory(trajectory)
    if step is not None and hasattr(step, "rotation_at"):
        return solved_rotation(bodies, trajectory, step)
    return rotate_scene(scene, trajectory, rotation, backend=backend)


def solved_rotation(bodies: RigidBodies, trajectory, step) -> RotationTrajectory:
    """``bodies`` at ``trajectory``'s saved times as the collision ``step`` turned them with their
    contacts (the orientations it recorded, :meth:`rotation_at`: the contact solver's, the event
    loop's spinning spheres')."""
    orientations, angular_velocities = step.rotation_at(np.rint((trajectory.t - trajectory.t[0]) / trajectory.dt)
                                                        .astype(int))
    return RotationTrajectory(trajectory.t, orientations[:, bodies.index], angular_velocities[:, bodies.index],
                              step.world.rigid.rotation, bodies)


def keeping(make_step, kept: list, save_every: int = 1):
    """``make_step`` (a stepper factory for :func:`.simulate`) that also appends the step it builds to
    ``kept``, for :func:`run_rotation` after the run (a step that records the rotation, the contact
    solver's, records it at the saved steps only)."""
    def stepper(model, integrator):
        step = make_step(model, integrator)
        if hasattr(step, "record_every"):
            step.record_every = save_every
        kept.append(step)
        return step

    return stepper


def angular_momentum(positions, velocities, masses, bodies: RigidBodies | None) -> np.ndarray:
    """What ``steplab run`` reports: one body's spin about its centre of mass; a scene's total about the origin."""
    if len(masses) == 1:
        return bodies.angular_momenta()[0] if bodies is not None else np.zeros(3)
    return total_angular_momentum(positions, velocities, masses, bodies)


def rotation_summary(scene, trajectory, rotation: RotationTrajectory | None) -> dict:
    """The ``steplab run --json`` fields of the rotation: one entry per body (a point mass keeps
    the identity orientation and zero angular velocity), and the angular momentum at both ends."""
    masses = scene.model.masses
    n = len(masses)
    if rotation is None:
        final = {"orientations": np.broadcast_to(quat.IDENTITY, (1, n, 4)), "angular_velocities": np.zeros((1, n, 3))}
    else:
        final = rotation_arrays(rotation, n)
    return {
        "rotation": rotation.method if rotation is not None else None,
        "rotating_bodies": [scene.model.names[i] for i in rotation.bodies.index] if rotation is not None else [],
        "final_orientations": final["orientations"][-1].tolist(),
        "final_angular_velocities": final["angular_velocities"][-1].tolist(),
        "angular_momentum_start": angular_momentum(scene.y0[0], scene.y0[1], masses, scene.rigid_bodies).tolist(),
        "angular_momentum_end": angular_momentum(trajectory.positions[-1], trajectory.velocities[-1], masses,
                                                 rotation.at(-1) if rotation is not None else None).tolist(),
    }


def rotation_arrays(rotation: RotationTrajectory, n_bodies: int) -> dict:
    """The NPZ arrays ``orientations`` (K, N, 4) and ``angular_velocities`` (K, N, 3, world frame)
    for all N bodies (identity and zero for a point mass); a scene without rotating bodies adds none."""
    k = len(rotation.t)
    dtype = np.result_type(rotation.orientations, rotation.angular_velocities)  # the run's precision
    orientations = np.broadcast_to(quat.IDENTITY, (k, n_bodies, 4)).astype(dtype)
    angular_velocities = np.zeros((k, n_bodies, 3), dtype)
    orientations[:, rotation.bodies.index] = rotation.orientations
    angular_velocities[:, rotation.bodies.index] = rotation.angular_velocities
    return {"orientations": orientations, "angular_velocities": angular_velocities}
