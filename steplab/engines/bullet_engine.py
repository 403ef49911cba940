"""Bullet through pybullet (DIRECT: no GUI): spheres as rigid bodies, static planes and boxes.

- Bodies are Bullet's rigid bodies (``useMaximalCoordinates``, a game's ``btRigidBody``):
  mass, a sphere shape (none without collisions), no linear or angular damping (the
  scene has no air; pybullet's default is 0.04) and no sleeping (Bullet deactivates a body
  slower than 0.8 m/s for 2 s: a small oscillation would stop).
- pybullet has no spring between two bodies: springs and dampers are forces applied at
  the start of every step (``applyExternalForce``), evaluated from the state then, as a
  game adds a spring in Bullet's pre-tick callback.
- Restitution and friction: Bullet multiplies the two bodies' coefficients, so the static
  shapes get 1 and each body its coefficient against them; two bodies then bounce with
  eps_a eps_b, not the scene's eps (the ball pit's 0.8 becomes 0.64 between balls).
- Rotating bodies (the scene's ``rigid_bodies``) get the collision shape of their shape (box,
  capsule, cylinder, sphere; along the body z axis) and their principal moments
  (``localInertiaDiagonal``, the inertial frame at the body's origin); pybullet's orientation
  is (x, y, z, w) and its angular velocity world-frame, both converted. Bullet's
  btRigidBody applies the gyroscopic term by one implicit Newton step in the body frame
  (``BT_ENABLE_GYROSCOPIC_FORCE_IMPLICIT_BODY``, its default flag); pybullet has no switch for
  the flag (neither ``changeDynamics`` nor ``setPhysicsEngineParameter`` takes one), so only
  the default is measured.
- Settings: ``position_correction=False`` turns Bullet's penetration recovery off (the
  split impulse and the error-reduction parameters ERP, contact ERP and friction ERP);
  ``ccd=True`` turns on continuous collision detection, a swept sphere of each body's
  radius (Bullet's motion clamping); ``iterations`` sets the constraint solver's iterations
  (``numSolverIterations``, pybullet's default 50) and ``substeps`` splits each step into that
  many (``numSubSteps``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from steplab.physics import Dampers, Gravity, Springs
from steplab.physics.collision import Box, OrientedBox, Plane

from .base import EngineRun, Setting, body_indices, require, scene_parts, version

#: the body's orientation [w, x, y, z] as pybullet's (x, y, z, w) and back
TO_PYBULLET, FROM_PYBULLET = [1, 2, 3, 0], [3, 0, 1, 2]

ENGINE = "Bullet"
#: why Bullet's bounce is above eps^2 (the drop test's explanation, from Bullet's documented rules)
PENETRATION_RECOVERY = ("restitution is the product of the two bodies' (the floor gets 1); the penetration "
                        "recovery (ERP) pushes the ball out of the floor with added speed, so h/H is above eps^2")


@dataclasses.dataclass(frozen=True)
class BulletOptions:
    """The settings of a Bullet run (the module docstring): penetration recovery on or off,
    continuous collision detection, solver iterations and substeps (None: pybullet's)."""

    position_correction: bool = True
    ccd: bool = False
    iterations: int | None = None
    substeps: int | None = None


class BulletRun(EngineRun):
    engine = "bullet"
    display_name = "Bullet (pybullet)"
    colour = "tab:orange"
    precision = "float64"
    package = distribution = "pybullet"
    study_settings = (
        Setting("bullet-default", "Bullet default", {}, False, "semi-implicit-euler", PENETRATION_RECOVERY),
        Setting("bullet-no-position-correction", "Bullet, position correction off", {"position_correction": False},
                False, "semi-implicit-euler", "without the penetration recovery the bounce is eps^2 (the product "
                "rule still makes two balls bounce with eps_a eps_b)"),
        Setting("bullet-ccd", "Bullet, CCD on", {"ccd": True}, True, "semi-implicit-euler", PENETRATION_RECOVERY),
    )

    rotation_settings = (
        Setting("bullet-default", "Bullet default", {}, None, "implicit-gyroscopic",
                "BT_ENABLE_GYROSCOPIC_FORCE_IMPLICIT_BODY (btRigidBody's default; pybullet cannot change it): one "
                "Newton step on omega in the body frame, then integrateTransform's exponential map"),
    )

    stack_settings = (
        Setting("bullet-default", "Bullet default", {}, None, None, "pybullet's defaults: 50 solver iterations, "
                "split impulse"),
        Setting("bullet-substeps", "Bullet, 4 substeps", {"substeps": 4}, None, None,
                "each step as 4 substeps of dt/4: the stiffer problem per substep is what substepping buys a solver "
                "of sequential impulses"),
    )

    def __init__(self, model, collisions=None, dt: float = 0.01, y0=None, bodies=None, **options):
        """The scene in a pybullet world of its own; ``options``: the keywords of :class:`BulletOptions`."""
        options = BulletOptions(**options)
        position_correction, ccd, iterations, substeps = (options.position_correction, options.ccd,
                                                          options.iterations, options.substeps)
        pybullet = require("pybullet", ENGINE)
        super().__init__(scene_parts(model, collisions, ENGINE, forces=(Gravity, Springs, Dampers),
                                     shapes=(Plane, Box, OrientedBox)), model, bodies)
        parts = self.parts
        self._pb = pb = pybullet
        self._client = pb.connect(pb.DIRECT)
        self._p = p = {"physicsClientId": self._client}
        pb.setGravity(*parts.gravity.tolist(), **p)
        pb.setTimeStep(dt, **p)
        self._dt = dt
        if not position_correction:
            pb.setPhysicsEngineParameter(erp=0.0, contactERP=0.0, frictionERP=0.0, useSplitImpulse=0, **p)
        if iterations is not None:
            pb.setPhysicsEngineParameter(numSolverIterations=int(iterations), **p)
        if substeps is not None:
            pb.setPhysicsEngineParameter(numSubSteps=int(substeps), **p)
        y0 = np.zeros((2, parts.n, 3)) if y0 is None else np.asarray(y0, float)
        self._y = y0.copy()
        self._links = [f for f in model._source_forces if isinstance(f, (Springs, Dampers))]
        self._masses = parts.masses
        contacts = parts.collisions is not None
        self._ids: dict[int, int | str] = {}  # pybullet body id -> body index or shape name
        for shape in parts.shapes:
            self._ids[self._static(shape)] = shape.name
        self.bodies = []
        rigid = {shape.body: shape for shape in self.rigid}
        for i in range(parts.n):
            if i in rigid:
                geom = self._shape(rigid[i]) if contacts else -1
            else:
                geom = pb.createCollisionShape(pb.GEOM_SPHERE, radius=float(parts.radii[i]), **p) if contacts else -1
            mass = 0.0 if parts.pinned[i] else float(parts.masses[i])
            body = pb.createMultiBody(mass, geom, basePosition=y0[0, i].tolist(), useMaximalCoordinates=True, **p)
            e, mu = parts.against_shapes(i)
            pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, restitution=e, lateralFriction=mu,
                              activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING, **p)
            if i in rigid and not parts.pinned[i]:
                # the mass again: pybullet 3.2 sets a maximal-coordinates body's mass to 0 (static)
                # when localInertiaDiagonal comes alone, and resets the inertia when the mass does
                pb.changeDynamics(body, -1, mass=mass, localInertiaDiagonal=rigid[i].inertia.tolist(), **p)
            if ccd:
                pb.changeDynamics(body, -1, ccdSweptSphereRadius=float(parts.radii[i]), **p)
            self._ids[body] = i
            self.bodies.append(body)
        self.moving = body_indices(parts)
        self._start = pb.saveState(**p)
        options = [name for name, on in (("position correction off", not position_correction),
                                         ("continuous collision detection", ccd),
                                         (f"{iterations} iterations", iterations is not None),
                                         (f"{substeps} substeps", substeps is not None)) if on]
        self.settings = f"Bullet (pybullet {version('pybullet')})" + (", " + ", ".join(options) if options else
                                                                     ", default")

    def _shape(self, shape) -> int:
        """pybullet's collision shape of a rotating body (:class:`.base.RigidShape`)."""
        pb, p = self._pb, self._p
        if shape.shape == "box":
            return pb.createCollisionShape(pb.GEOM_BOX, halfExtents=shape.half_extents.tolist(), **p)
        if shape.shape in ("capsule", "cylinder"):
            kind = pb.GEOM_CAPSULE if shape.shape == "capsule" else pb.GEOM_CYLINDER
            return pb.createCollisionShape(kind, radius=shape.radius, height=2 * float(shape.half_extents[2]), **p)
        return pb.createCollisionShape(pb.GEOM_SPHERE, radius=shape.radius, **p)

    def _static(self, shape) -> int:
        pb, p = self._pb, self._p
        if isinstance(shape, Plane):
            geom = pb.createCollisionShape(pb.GEOM_PLANE, planeNormal=shape.normal.tolist(), **p)
            # a plane shape passes through its body's origin: put the origin on the plane
            body = pb.createMultiBody(0.0, geom, basePosition=(shape.offset * shape.normal).tolist(), **p)
        else:
            geom = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=shape.half_extents.tolist(), **p)
            turn = [0.0, 0.0, 0.0, 1.0]
            if isinstance(shape, OrientedBox):
                from scipy.spatial.transform import Rotation

                turn = Rotation.from_matrix(shape.rotation).as_quat().tolist()  # (x, y, z, w), as pybullet
            body = pb.createMultiBody(0.0, geom, basePosition=shape.center.tolist(), baseOrientation=turn, **p)
        pb.changeDynamics(body, -1, restitution=1.0, lateralFriction=1.0, **p)
        return body

    def set_state(self, y) -> None:
        pb, p = self._pb, self._p
        pb.restoreState(self._start, **p)
        self._y = np.array(y, dtype=float)
        for i in self.moving:
            pb.resetBasePositionAndOrientation(self.bodies[i], self._y[0, i].tolist(), [0.0, 0.0, 0.0, 1.0], **p)
            pb.resetBaseVelocity(self.bodies[i], self._y[1, i].tolist(), [0.0, 0.0, 0.0], **p)
        self._fresh = True

    def set_rotation(self, orientations, angular_velocities) -> None:
        pb, p = self._pb, self._p
        self._fixed = (np.array(orientations, float), np.array(angular_velocities, float))
        for j, shape in enumerate(self.rigid):
            i = shape.body
            if not self.parts.pinned[i]:
                pb.resetBasePositionAndOrientation(self.bodies[i], self._y[0, i].tolist(),
                                                   self._fixed[0][j][TO_PYBULLET].tolist(), **p)
                pb.resetBaseVelocity(self.bodies[i], self._y[1, i].tolist(), self._fixed[1][j].tolist(), **p)

    def rotation(self) -> tuple[np.ndarray, np.ndarray]:
        pb, p = self._pb, self._p
        q, omega = (a.copy() for a in self._fixed)
        for j, shape in enumerate(self.rigid):
            if not self.parts.pinned[shape.body]:
                q[j] = np.array(pb.getBasePositionAndOrientation(self.bodies[shape.body], **p)[1])[FROM_PYBULLET]
                omega[j] = pb.getBaseVelocity(self.bodies[shape.body], **p)[1]
        return q, omega

    def step(self, dt: float) -> None:
        pb, p = self._pb, self._p
        if dt != self._dt:
            pb.setTimeStep(dt, **p)
            self._dt = dt
        if self._links:
            y = self._y if self._fresh else self.state()
            with np.errstate(all="ignore"):  # a diverging state: the run's own check reports it
                f = sum(force.force(np, y[0], y[1], self._masses) for force in self._links)
            for i in self.moving:
                pb.applyExternalForce(self.bodies[i], -1, f[i].tolist(), y[0, i].tolist(), pb.WORLD_FRAME, **p)
        pb.stepSimulation(**p)
        self._fresh = False

    def run(self, steps: int) -> None:
        for _ in range(steps):
            self.step(self._dt)

    def state(self) -> np.ndarray:
        pb, p = self._pb, self._p
        for i in self.moving:
            self._y[0, i] = pb.getBasePositionAndOrientation(self.bodies[i], **p)[0]
            self._y[1, i] = pb.getBaseVelocity(self.bodies[i], **p)[0]
        self._fresh = True
        return self._y.copy()

    def touching(self) -> dict:
        out = {}
        for c in self._pb.getContactPoints(**self._p):
            a, b = self._ids.get(c[1]), self._ids.get(c[2])
            normal = -np.array(c[7])  # contactNormalOnB points from B to A
            if isinstance(a, int):
                out[(a, b)] = normal
            elif isinstance(b, int):
                out[(b, a)] = -normal
        return out

    def close(self) -> None:
        if self._client is not None and self._pb.isConnected(self._client):
            self._pb.disconnect(self._client)
        self._client = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown: pybullet may be gone already
            pass
