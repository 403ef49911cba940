"""Springs and dampers at body-frame points: a scene's translation and rotation stepped together.

A force at a point couples the two systems (:mod:`steplab.physics.attachments`): the force on a
centre depends on the orientations, through the lever arms R(q) r, and the torque on a body
depends on the positions. :class:`AttachedStep` advances both with the same dt. A pair composes
when the rotation method names the integrator among those it composes with (``composes_with``,
:func:`composes`); its stage order is then one method on the whole system:

- velocity Verlet with ``dlm`` or ``implicit-midpoint``: the Strang splitting of H = T + V. Half
  kicks of v and of the body-frame momentum pi with the forces and torques at (x, q); the drift of
  x and the free rotation of q (the method's, without torque) by h; half kicks at the new (x, q).
  Symplectic and second order, so the energy error stays bounded.
- ``rk4`` with ``rk4``: the four stages on (x, v, q, omega) together (the translation's tableau),
  the lever arms at each stage's q, q normalised after the step: fourth order.
- semi-implicit Euler with a method that updates omega first (``exponential-map``,
  ``first-order-quaternion``, ``implicit-gyroscopic``, ``momentum-rescaled``), and explicit Euler
  with ``explicit``: the forces and torques at the start of the step, each system stepped with the
  other held there (:func:`held_step`), which is these pairs' declared order, "forces and torques
  at t; v and omega; then x and q" (symplectic Euler on the whole system), or all from the values
  at t (explicit Euler on it).

Any other pair takes the held step too, but then the two systems see each other at different
stages: the coupling is first order and not symplectic, and on a stiff attachment it gains energy
at every dt (semi-implicit Euler with ``dlm`` on spring-pendulum multiplies a perturbation by 1.021
a step at dt = 1 ms). :mod:`.coupled_stability` measures that growth before a run.

Each stage takes the model at its lever arms (:func:`model_at`): on NumPy the one model of
:class:`.attachments.LeverArms`, its arms turned in place (a new Model per stage was some 90 us of
spring-pendulum's 360 us step with exponential-map, 300 of 1170 us with rk4), on JAX a new one (a
traced step rewrites nothing in place). A model held across a later stage's turn
(:func:`held_step`'s start model, over the rotation's stages) is then not read after that turn:
:class:`_HeldTorque` turns it back should a method ask for the start again. On NumPy
:class:`AttachedStep` is the step of :func:`.simulate`'s Python loop; on JAX the same stage
functions, traced, are the step of the one compiled loop (:func:`.loop.compiled_loop`), which
carries the translation and the rotation packed into one flat state (:class:`_Packed`), so that
its divergence check covers both. A scene without attachments never comes here:
:func:`.scene_rotation.rotate_scene` runs its free rotation beside the translation, and a scene
without rotating bodies does no rotation work at all.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from steplab.physics import attachments
from steplab.physics import quaternion as quat
from steplab.physics.rigid_body import RigidBodies, RotationModel

from .base import Stepper
from .loop import compiled_loop, run_once
from .scene_rotation import RotationTrajectory
from .simulate import DivergenceError, Trajectory, saved_steps


class Coupling(NamedTuple):
    """What a coupled step needs, fixed over a run.

    model : physics.Model
        NumPy, float64 (:func:`.attachments.model_at` rebuilds it on ``xp`` at each state); its
        attached forces carry their body-frame offsets.
    bodies : physics.rigid_body.RigidBodies
        The rotating bodies at the start (their ``index`` and ``inertia``).
    integrator : integrators.base.Stepper
    rotation : integrators.rotation.RotationMethod
    xp, dtype : the run's array namespace and precision
    lever_arms : physics.attachments.LeverArms, optional
        On NumPy, the one model whose lever arms :func:`model_at` turns in place (:meth:`turning`);
        None: a new model at each state (JAX, and a coupling that lets its models out).
    """

    model: object
    bodies: RigidBodies
    integrator: object
    rotation: object
    xp: object = np
    dtype: object = np.dtype(np.float64)
    lever_arms: object = None

    def turning(self, q, omega) -> Coupling:
        """This coupling, on NumPy with one model whose lever arms :func:`model_at` turns in place
        (:class:`.attachments.LeverArms`, first at ``q`` and ``omega``); on JAX itself."""
        if self.xp is not np:
            return self
        return self._replace(lever_arms=attachments.LeverArms(self.model, *frames(self, q, omega), self.dtype))

    def fresh(self) -> Coupling:
        """This coupling building a new model at each state (for a model that leaves the step)."""
        return self._replace(lever_arms=None)

    @property
    def composes(self) -> bool:
        """Whether the rotation method composes with the integrator (:func:`composes`)."""
        return composes(self.integrator, self.rotation)

    @property
    def strang(self) -> bool:
        """Velocity Verlet with a rotation method whose free step sits inside its Strang splitting (dlm,
        implicit-midpoint): see the module."""
        return self.composes and self.integrator.name == "velocity-verlet"

    @property
    def joint(self) -> bool:
        """An explicit Runge-Kutta integrator with the rotation method of its stages (rk4 with rk4):
        one tableau on the whole state."""
        return self.composes and hasattr(self.integrator, "tableau")

    def rotation_model(self, torques=()) -> RotationModel:
        return RotationModel(self.bodies.inertia, tuple(torques), self.xp)


def composes(integrator, rotation) -> bool:
    """Whether the coupled step of ``integrator`` and the rotation method ``rotation`` is one method on the
    whole system (the rotation method's ``composes_with`` names the integrator); else the held step of a
    pair whose stages do not match (see the module)."""
    return integrator.name in rotation.composes_with


def frames(c: Coupling, q, omega):
    """All the bodies' orientations (N, 4) and world angular velocities (N, 3) at the rotating bodies'
    ``q`` (R, 4) and body-frame ``omega`` (R, 3) (a point mass's the identity and zero), in the run's
    precision: a rotation method's inner stages compute in float64 (:func:`in_precision`), and the lever
    arms, the forces and the torques take the orientations' precision."""
    xp, n, index, dtype = c.xp, c.model.n_bodies, c.bodies.index, c.dtype
    q, omega = in_precision(xp, dtype, q, omega)
    identity = np.broadcast_to(quat.IDENTITY, (n, 4))
    world = quat.rotate(xp, q, omega)
    if xp is np:
        orientations, angular_velocities = identity.astype(dtype), np.zeros((n, 3), dtype)
        orientations[index], angular_velocities[index] = q, world
        return orientations, angular_velocities
    return (xp.asarray(identity, dtype=dtype).at[index].set(q), xp.zeros((n, 3), dtype=dtype).at[index].set(world))


def model_at(c: Coupling, q, omega):
    """The model with its lever arms at the rotating bodies' ``q`` (R, 4) and body-frame ``omega`` (R, 3)
    (a point mass's at the identity and zero). With ``c.lever_arms`` (NumPy) the one model, turned in
    place: the model an earlier call gave turns too (see the module)."""
    orientations, angular_velocities = frames(c, q, omega)
    if c.lever_arms is not None:
        return c.lever_arms.turn(orientations, angular_velocities)
    return attachments.model_at(c.model, orientations, angular_velocities, c.xp, c.dtype)


def accelerations(c: Coupling, t, x, v, q, omega):
    """The centres' acceleration (N, 3) and the rotating bodies' body-frame torque (R, 3) at one state."""
    model = model_at(c, q, omega)
    torque = attachments.torques(model, x, v)[c.bodies.index]
    return model.acceleration(t, x, v), quat.rotate_inverse(c.xp, q, torque)


def held_step(c: Coupling, t, y, q, omega, dt):
    """One step in which each system steps with the other held at the start of the step: (y, q, omega).

    The translation's step reads the start model before the rotation's stages turn its lever arms
    (with ``c.lever_arms``); :class:`_HeldTorque` reads it only until then."""
    model = model_at(c, q, omega)
    y1, _ = c.integrator.step(model, t, y, dt, c.integrator.init(model, t, y))
    torque = _HeldTorque(c, y[0], y[1], (q, omega, model))
    q1, omega1 = in_precision(c.xp, y.dtype, *c.rotation.step(c.rotation_model((torque,)), t, q, omega, dt))
    return y1, q1, omega1


def in_precision(xp, dtype, *arrays):
    """``arrays`` in the run's precision ``dtype``: the rotation methods compute with float64 moments
    (:class:`.rigid_body.RotationModel`), and in a float32 run their orientations would carry float64
    into the lever arms, the forces and the translation (on NumPy the whole run computed in float64
    after its first step; JAX's compiled loop refused its float64 carry)."""
    return tuple(xp.asarray(a, dtype=dtype) for a in arrays)


def strang_step(c: Coupling, t, y, q, omega, kept, dt):
    """Kick (h/2), drift and free rotation (h), kick (h/2): velocity Verlet and dlm at once.

    ``kept`` is the acceleration and torque at the start of the step (the last step's second
    kick's); returns (y, q, omega, kept for the next step)."""
    xp = c.xp
    inertia = xp.asarray(c.bodies.inertia, dtype=y.dtype)
    x, v = y[0], y[1]
    a0, tau0 = kept
    v_half = v + 0.5 * dt * a0
    x1 = x + dt * v_half
    q1, omega_free = c.rotation.step(c.rotation_model(), t, q, omega + 0.5 * dt * tau0 / inertia, dt)
    q1, omega_free = in_precision(xp, y.dtype, q1, omega_free)
    # the second kick's velocities as each method estimates them: v + h a0 (Verlet), the rotated pi (dlm)
    a1, tau1 = accelerations(c, t + dt, x1, v + dt * a0, q1, omega_free)
    return xp.stack([x1, v_half + 0.5 * dt * a1]), q1, omega_free + 0.5 * dt * tau1 / inertia, (a1, tau1)


def joint_step(c: Coupling, t, y, q, omega, dt):
    """One step of the integrator's Butcher tableau on (x, v, q, omega) together: every stage takes the
    forces and the torques at its own positions and lever arms. q is normalised after the step (its
    stages leave the unit sphere by O(h^2), the derivative's smooth extension there)."""
    from .runge_kutta import rk_step

    xp = c.xp
    packed = _Packed(c, y.shape, y.dtype)
    inertia = xp.asarray(c.bodies.inertia, dtype=y.dtype)

    def rate(t, z):
        y, q, omega = packed.unpack(xp, z)
        model = model_at(c, q, omega)
        torque = quat.rotate_inverse(xp, q, attachments.torques(model, y[0], y[1])[c.bodies.index])
        alpha = (torque - quat.cross(xp, omega, inertia * omega)) / inertia  # Euler's equations
        return packed.pack(xp, model.vector_field(t, y), 0.5 * quat.multiply_vector(xp, q, omega), alpha)

    y1, q1, omega1 = packed.unpack(xp, rk_step(rate, t, packed.pack(xp, y, q, omega), dt, c.integrator.tableau))
    return y1, quat.normalize(xp, q1), omega1


def first_kept(c: Coupling, t, y, q, omega):
    """What the coupled step carries into its first step: the Strang splitting's acceleration and torque at
    the start, else nothing."""
    return accelerations(c, t, y[0], y[1], q, omega) if c.strang else ()


def coupled_step(c: Coupling, t, y, q, omega, kept, dt):
    """One coupled step in the pair's stage order (see the module): (y, q, omega, kept for the next step)."""
    if c.strang:
        return strang_step(c, t, y, q, omega, kept, dt)
    return *(joint_step if c.joint else held_step)(c, t, y, q, omega, dt), kept


def check_attached_integrator(integrator) -> None:
    """Refuse, in one line, an ``integrator`` that cannot step springs and dampers at body-frame points: one
    that is no fixed-step Stepper (a position-based or adaptive method evaluates no force at the lever arms)."""
    if not isinstance(integrator, Stepper):
        raise ValueError(f"springs and dampers at body-frame points (offsets) need a fixed-step integrator that "
                         f"evaluates their forces, not {integrator.name!r} (use semi-implicit-euler or "
                         "velocity-verlet)")


class AttachedStep:
    """``step(t, y, dt, carry) -> (y, carry)`` of a model with attached forces, its rotating
    ``bodies`` stepped by ``rotation`` beside ``integrator``; the rotation at the saved steps is kept.

    On NumPy it is the step of :func:`.simulate`'s loop, the rotation kept after every step; on
    JAX, :func:`.simulate` calls :meth:`compiled` instead, which runs the whole loop compiled.

    Parameters
    ----------
    model : physics.Model
        On the run's backend; its attached forces carry their body-frame offsets.
    bodies : physics.rigid_body.RigidBodies
        The rotating bodies at the start.
    integrator : integrators.base.Stepper
    rotation : integrators.rotation.RotationMethod
    """

    def __init__(self, model, bodies: RigidBodies, integrator, rotation):
        check_attached_integrator(integrator)
        self.bodies = bodies
        self.q, self.omega = in_precision(np, model.dtype, bodies.orientations, bodies.body_angular_velocities())
        # on NumPy one model whose lever arms each stage turns in place (none leaves the step)
        self.coupling = Coupling(model.cast(np, np.float64), bodies, integrator, rotation, model.xp,
                                 model.dtype).turning(self.q, self.omega)
        self.saved = {0: (self.q, self.omega)}  # by step
        self.log = None  # no collisions
        self._kept = None  # the Strang splitting's last acceleration and torque, for the next first kick

    def model_at(self, q, omega):
        """:func:`model_at` of this run: a new model with its lever arms at ``q`` (R, 4) and body-frame
        ``omega`` (R, 3) (not the one the steps turn)."""
        return model_at(self.coupling.fresh(), q, omega)

    def final_model(self):
        """The model with its lever arms at the last step's orientations (for the energy at the end)."""
        return self.model_at(self.q, self.omega)

    def __call__(self, t, y, dt, carry):
        c = self.coupling
        kept = first_kept(c, t, y, self.q, self.omega) if self._kept is None else self._kept
        y, self.q, self.omega, self._kept = coupled_step(c, t, y, self.q, self.omega, kept, dt)
        if not (np.all(np.isfinite(self.q)) and np.all(np.isfinite(self.omega))):
            raise DivergenceError(_name(c), dt, len(self.saved), t + dt)
        self.saved[len(self.saved)] = (self.q, self.omega)
        return y, carry

    def compiled(self, y0, t_start: float, dt: float, n: int, save_every: int, limit: float):
        """The run on JAX as one compiled loop (:func:`.loop.compiled_loop`): the :class:`.simulate.Trajectory`.

        ``y0`` (2, N, 3) in the run's precision; ``n`` steps of ``dt``, every ``save_every``-th
        state kept (and the last), ``limit`` the divergence limit of every component, the
        rotation's included. Compilation is timed apart, as :func:`.simulate` does.
        """
        packed = _Packed(self.coupling, y0.shape, y0.dtype)
        saves = saved_steps(n, save_every)
        loop = compiled_loop(None, packed, chunks=len(saves) - 1, save_every=save_every)
        z0 = packed.pack(np, y0, self.q, self.omega)
        zs, bad, compile_time, wall = run_once(loop, z0, t_start, dt, n, limit)
        if bad >= 0:
            raise DivergenceError(packed.name, dt, bad, t_start + bad * dt)
        ys, qs, omegas = packed.unpack(np, np.concatenate([z0[None], np.asarray(zs)]))
        self.saved = {int(k): (q, omega) for k, q, omega in zip(saves, qs, omegas)}
        self.q, self.omega = qs[-1], omegas[-1]
        return Trajectory(t_start + saves * dt, ys, self.coupling.integrator.name, dt, n, "jax", wall, compile_time)

    def rotation_trajectory(self, trajectory) -> RotationTrajectory:
        """The rotating bodies at ``trajectory``'s saved times (a run of this step)."""
        t = np.asarray(trajectory.t, float)
        k = np.rint((t - t[0]) / trajectory.dt).astype(int)
        qs = np.array([self.saved[i][0] for i in k])
        omegas = np.array([self.saved[i][1] for i in k])
        c = self.coupling
        name = f"{c.rotation.name} (with {c.integrator.name}, coupled)"
        return RotationTrajectory(t, qs, quat.rotate(np, qs, omegas), name, self.bodies)


def _name(c: Coupling) -> str:
    return f"{c.integrator.name} with {c.rotation.name}"


class _Packed:
    """The coupled step as a stepper of :func:`.loop.fixed_step_loop` on one flat state.

    The loop carries, checks and saves one array: here the positions and velocities (2, N, 3),
    the orientations (R, 4) and the body-frame angular velocities (R, 3), flattened one after
    the other. Its carry is the Strang step's kept acceleration and torque (nothing otherwise).
    """

    partitioned = False

    def __init__(self, coupling: Coupling, shape, dtype):
        self.coupling, self.shape, self.dtype = coupling, tuple(shape), dtype
        self.rotating = len(coupling.bodies.index)
        self.name = _name(coupling)

    def pack(self, xp, y, q, omega):
        return xp.concatenate([xp.ravel(y), xp.ravel(q), xp.ravel(omega)]).astype(self.dtype)

    def unpack(self, xp, z):
        """(y, q, omega) of a flat state, or of a stack of them (K, size)."""
        lead, r = z.shape[:-1], self.rotating
        cut = int(np.prod(self.shape))
        return (z[..., :cut].reshape(lead + self.shape), z[..., cut:cut + 4 * r].reshape(lead + (r, 4)),
                z[..., cut + 4 * r:].reshape(lead + (r, 3)))

    def init(self, model, t, z):  # the loop's model is not used: the coupling rebuilds it at each state
        return first_kept(self.coupling, t, *self.unpack(self.coupling.xp, z))

    def step(self, model, t, z, dt, kept):
        y, q, omega, kept = coupled_step(self.coupling, t, *self.unpack(self.coupling.xp, z), kept, dt)
        return self.pack(self.coupling.xp, y, q, omega), kept


class _HeldTorque:
    """The attached forces' torque at positions ``x`` and velocities ``v`` held over a rotation step;
    ``start`` is (q, omega, model) at the step's start, which most methods ask for (first).

    With ``c.lever_arms`` a stage's :func:`model_at` turns the start's model too: it is dropped
    then, and a later ask at the start turns the arms back (no method here asks so)."""

    def __init__(self, c: Coupling, x, v, start):
        self.coupling, self.x, self.v, self.start = c, x, v, start

    def torque(self, xp, t, q, omega_body):
        c = self.coupling
        q0, omega0, model = self.start
        if q is not q0 or omega_body is not omega0 or model is None:  # a stage inside the step (rk4, dlm's second kick)
            model = model_at(c, q, omega_body)
            if c.lever_arms is not None:  # the start's model, turned
                self.start = (q0, omega0, None)
        return attachments.torques(model, self.x, self.v)[c.bodies.index]


def scene_stepper(scene, kept: list | None = None, world=None, rotation=None, save_every: int = 1):
    """The step :func:`.simulate` needs for a run of ``scene`` (its ``stepper`` argument), appended to
    ``kept`` when it is built, so that the caller reads the rotation it turned after the run
    (:func:`.scene_rotation.run_rotation`).

    With collisions (``world``, a physics.collision.CollisionWorld) the world's step, recording the
    rotation at every ``save_every``-th step (the contact solver turns the lever arms of springs at
    body-frame points itself; the other collision methods refuse them, one line). Without, the
    attached step with ``rotation`` (default the scene's rotation method) where springs or dampers
    act at body-frame points (their lever arms turn with the bodies); else None (the integrator's
    own step).
    """
    from .rotation import DEFAULT_ROTATION
    from .rotation_registry import get_rotation
    from .scene_rotation import keeping

    if world is not None:
        world.check_attachments(scene.model)
        return keeping(world.stepper, [] if kept is None else kept, save_every)
    if not attachments.attached_forces(scene.model):
        return None
    return attached_stepper(scene.rigid_bodies, rotation or get_rotation(scene.rotation or DEFAULT_ROTATION), kept)


def attached_stepper(bodies: RigidBodies, rotation, kept: list | None = None):
    """``stepper(model, integrator)`` for :func:`.simulate` (its ``stepper`` argument): an
    :class:`AttachedStep`, appended to ``kept`` so that the caller reads its rotation after the run."""

    def build(model, integrator):
        step = AttachedStep(model, bodies, integrator, rotation)
        if kept is not None:
            kept.append(step)
        return step

    return build
