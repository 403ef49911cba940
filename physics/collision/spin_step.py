"""The event loop with spheres that spin: the step that carries their angular velocity and orientation.

A sphere that declares ``angular_velocity`` or ``inertia`` in its scene is a rigid body. Where
friction can act on it (some pair of materials has mu > 0), the event loop runs this step:
:class:`.step.CollisionStep` with a :class:`.compiled_response.Spin` beside the state ``y``, so
that every impact's friction changes omega with the impulse's angular part (the lecture's
equation 1 at the contact point, :mod:`.compiled_response`) and every resting contact slides or
rolls with kinetic friction and its torque, in closed form over the step (:mod:`.resting`). The
same stages, the same kernels, on the NumPy and the compiled paths alike. Without friction a
contact never turns a sphere, so a scene without it keeps the plain step, bit for bit, and turns
its bodies beside the translation as before (:mod:`steplab.integrators.scene_rotation`).

Between contacts nothing torques a sphere of one moment of inertia I (gravity acts at its centre),
so omega is constant and its orientation turns exactly, exp(omega t): each body's is turned on
to each of its impacts and to the end of each step (:func:`.compiled_response.turn_to`). The
scene's rotation method is not used: for these bodies it would only approximate that turn. A
sphere whose three principal moments differ, or a cylinder, is refused in one line naming the
contact solver, which steps them.

The rotation is recorded at the end of every ``record_every``-th step and of the last
(:meth:`SpinningCollisionStep.rotation_at`), as the contact solver records its own, so ``steplab
run`` and the studies read it the same way.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .. import quaternion as quat
from .compiled_response import Spin
from .step import CollisionStep

#: principal moments closer than this, relative, are one moment of inertia
ONE_MOMENT = 1e-12


def has_friction(world) -> bool:
    """Whether some pair of materials has Coulomb friction (mu > 0): only then can a contact turn a sphere."""
    properties = world.pair_properties
    return properties.friction > 0 or any(mu > 0 for _, mu in properties.table.values())


def spin_of(world, model) -> Spin:
    """The spin of the world's rotating spheres at the start of a run (the others: point masses).

    ValueError, one line naming the body and the contact solver, for a body that is not a sphere
    of one moment of inertia."""
    bodies, n = world.rigid.bodies, len(model.radii)
    omega, inverse_inertia = np.zeros((n, 3)), np.zeros(n)
    orientation = np.tile(quat.IDENTITY, (n, 1)).astype(float)
    inverse_masses = np.asarray(model.inverse_masses, dtype=float)
    for row, body in enumerate(np.asarray(bodies.index)):
        name, shape, inertia = model.names[body], bodies.shapes[row], np.asarray(bodies.inertia[row], float)
        if shape != "sphere":
            raise ValueError(f'the event loop steps spheres only: body {name!r} is a {shape}; use [collisions] '
                             f'method = "solver"')
        if np.ptp(inertia) > ONE_MOMENT * np.max(inertia):
            raise ValueError(f"the event loop turns spheres of one moment of inertia (I1 = I2 = I3) between "
                             f"contacts: body {name!r} has inertia {inertia.tolist()} kg m^2; use [collisions] "
                             f'method = "solver"')
        orientation[body] = bodies.orientations[row]
        if inverse_masses[body] > 0:  # a pinned body neither moves nor turns (as in the contact solver)
            omega[body] = bodies.angular_velocities[row]
            inverse_inertia[body] = 1.0 / inertia[0]
    return Spin(omega, inverse_inertia, np.ascontiguousarray(model.radii, dtype=float), orientation, np.zeros(n))


@dataclasses.dataclass
class SpinningCollisionStep(CollisionStep):
    """:class:`.step.CollisionStep` with spheres that spin: ``step(t, y, dt, carry) -> (y, carry)``.

    ``spin`` (a :class:`.compiled_response.Spin`) holds every body's omega (world frame) and
    orientation beside ``y``; ``history`` holds them at the end of every ``record_every``-th step
    and of the last (:meth:`rotation_at`).
    """

    record_every: int = 1

    def __post_init__(self):
        self.spin = spin_of(self.world, self.model)
        super().__post_init__()
        self._steps = 0
        self.history = {0: self._rotation()}

    def __call__(self, t, y, dt, carry):
        if self._steps == 0:
            self.spin.turned[:] = t  # the orientations given are those at the run's start
        y, carry = super().__call__(t, y, dt, carry)
        if not np.all(np.isfinite(self.spin.omega)):
            raise FloatingPointError(f"the spheres' spin became non-finite in the step from t = {t:g} s")
        self._steps += 1
        if (self._steps - 1) % self.record_every:  # the last step's record was kept only while it was the last
            self.history.pop(self._steps - 1)
        self.history[self._steps] = self._rotation()
        return y, carry

    def _rotation(self):
        return self.spin.orientation.copy(), self.spin.omega.copy()

    def rotation_at(self, steps: np.ndarray):
        """(orientations (K, N, 4), angular velocities (K, N, 3)) after each of ``steps`` steps (recorded ones)."""
        missing = [int(k) for k in steps if int(k) not in self.history]
        if missing:
            raise ValueError(f"the event loop recorded its spheres' spin every {self.record_every} steps, not "
                             f"after step {missing[0]}")
        return (np.array([self.history[int(k)][0] for k in steps]),
                np.array([self.history[int(k)][1] for k in steps]))
