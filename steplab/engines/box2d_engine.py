"""Box2D (pybox2d, Box2D 2.3) for scenes in a plane: circles, static boxes, distance joints.

- The scene must stay in a plane (:func:`.base.plane_axes`); its two axes become Box2D's
  x and y. Box2D computes in float32.
- Bodies are dynamic bodies with a circle fixture of their mass (a body without
  collisions has a fixture that collides with nothing); pinned bodies are static; no
  sleeping (Box2D stops integrating a body slower than 1 cm/s for half a second).
- A spring and damper on a pair is a distance joint with ``frequencyHz`` and
  ``dampingRatio``: Box2D's soft constraint, k = m_eff (2 pi f)^2 and c = 2 m_eff zeta (2 pi f)
  with m_eff = 1 / (1/m_a + 1/m_b), solved inside the velocity solver. A damper without a
  spring has no counterpart (``frequencyHz = 0`` makes the joint rigid).
- Planes become static boxes behind them (a half-space does not exist in Box2D), boxes
  static boxes; every polygon carries Box2D's skin, ``b2_polygonRadius`` = 1 cm.
- Restitution and friction: Box2D takes the larger restitution of the two fixtures and
  the geometric mean of the frictions, so static shapes get restitution 0 (each body's
  against them wins) and friction 1, and each body mu^2 (the mean is then mu).
- Rotating bodies (the scene's ``rigid_bodies``) spin about the axis out of the plane: their
  section by the plane is the fixture (a box, a circle; a capsule in the plane is a box and
  two circles) and their mass and moment about that axis are set as the body's mass data. A
  moving box's polygon is its box less the skin (``b2_polygonRadius``), so that the skin's outer
  surface is the box and a stack does not grow by two skins per contact.
  Box2D turns a body by angle += dt omega (omega constant without torque).
- Settings: ``continuous=False`` turns off Box2D's continuous physics (time of impact
  against static bodies); ``bullet=True`` makes every body a "bullet" (time of impact
  against moving bodies too); ``velocity_iterations`` and ``position_iterations`` set the
  solver's iterations (default Box2D's recommended 8 and 3).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from steplab.physics.collision import Box, Plane

from .base import PlanarRun, Setting, UnsupportedFeatureError, body_indices, require, version

ENGINE = "Box2D"
#: Box2D's recommended iterations (its testbed's): velocity and position
VELOCITY_ITERATIONS, POSITION_ITERATIONS = 8, 3


def plane_box(normal2, offset: float, reach: float):
    """The four corners of a box standing for the half-plane normal . x <= offset, in 2-D.

    The box is ``reach`` deep behind the line and 2 ``reach`` long along it, far beyond any
    body of the scene (the caller's ``reach``).
    """
    n = np.asarray(normal2, float)
    tangent = np.array([-n[1], n[0]])
    on = offset * n
    return [tuple(on + s * reach * tangent - d * reach * n) for s, d in ((-1, 0), (1, 0), (1, 1), (-1, 1))]


def box_corners(center2, half2, turn2) -> list[tuple[float, float]]:
    """Corners of a box of half-extents ``half2`` turned by the 2x2 ``turn2`` around ``center2``."""
    c, h, r = np.asarray(center2, float), np.asarray(half2, float), np.asarray(turn2, float)
    return [tuple(c + r @ (h * s)) for s in (np.array([-1, -1]), np.array([1, -1]), np.array([1, 1]),
                                             np.array([-1, 1]))]


def static_polygons(parts, axes, q0) -> list[tuple[object, list]]:
    """(shape, corners in the plane) of each static shape, for the 2-D engines."""
    a, b = axes
    reach = 100.0 * (1.0 + float(np.max(np.abs(q0[:, list(axes)])))) if len(q0) else 100.0
    out = []
    for shape in parts.shapes:
        if isinstance(shape, Plane):
            out.append((shape, plane_box(shape.normal[[a, b]], shape.offset, reach)))
        elif isinstance(shape, Box):
            out.append((shape, box_corners(shape.center[[a, b]], shape.half_extents[[a, b]], np.eye(2))))
        else:
            out.append((shape, box_corners(shape.center[[a, b]], shape.half_extents[[a, b]],
                                           shape.rotation[np.ix_([a, b], [a, b])])))
    return out


def spring_frequency(k: float, c: float, m_eff: float) -> tuple[float, float]:
    """(frequencyHz, dampingRatio) of a Box2D distance joint that is the spring k and damper c."""
    omega = math.sqrt(k / m_eff)
    return omega / (2 * math.pi), c / (2 * m_eff * omega)


#: why Box2D's bounce is not eps^2 (the drop test's explanation, from Box2D's documented rules)
BOX2D_BOUNCE = ("restitution is the larger of the two fixtures'; the floor's polygon skin (1 cm) less the linear "
                "slop (5 mm) turns the ball about 5 mm above the floor; approaches below 1 m/s do not bounce; float32")


@dataclasses.dataclass(frozen=True)
class Box2DOptions:
    """The settings of a Box2D run (the module docstring): continuous physics, bullets, and the
    solver's velocity and position iterations."""

    continuous: bool = True
    bullet: bool = False
    velocity_iterations: int = VELOCITY_ITERATIONS
    position_iterations: int = POSITION_ITERATIONS


class Box2DRun(PlanarRun):
    engine = "box2d"
    display_name = "Box2D (2-D, float32)"
    colour = "tab:green"
    precision = "float32"
    package = distribution = "Box2D"
    study_settings = (
        Setting("box2d-continuous-off", "Box2D, continuous off", {"continuous": False}, False, "implicit-euler",
                BOX2D_BOUNCE),
        Setting("box2d-default", "Box2D default", {}, True, "implicit-euler", BOX2D_BOUNCE),
        Setting("box2d-bullet", "Box2D, bullets", {"bullet": True}, True, "implicit-euler", BOX2D_BOUNCE),
    )
    rotation_settings = (
        Setting("box2d-default", "Box2D default", {}, None, "exponential-map",
                "a spin about the axis out of the plane: angle += h omega, the exact turn at constant omega (as "
                "every method that turns by the exponential map); a 3-D tumble is out of its reach"),
    )
    stack_settings = (
        Setting("box2d-default", "Box2D default", {}, None, None, "8 velocity and 3 position iterations "
                "(Box2D's recommendation)"),
        Setting("box2d-iterations", "Box2D, 30 + 10 iterations", {"velocity_iterations": 30,
                                                                   "position_iterations": 10}, None, None,
                "30 velocity and 10 position iterations: each contact of a tall stack is solved more often per step"),
    )
    velocity_attribute = "linearVelocity"
    spin_attribute = "angularVelocity"

    def __init__(self, model, collisions=None, dt: float = 0.01, y0=None, bodies=None, **options):
        """The scene in a Box2D world of its own; ``options``: the keywords of :class:`Box2DOptions`."""
        options = Box2DOptions(**options)
        continuous, bullet = options.continuous, options.bullet
        velocity_iterations, position_iterations = options.velocity_iterations, options.position_iterations
        b2 = require("Box2D", ENGINE)
        super().__init__(model, collisions, ENGINE, y0, bodies)
        self._skin = float(b2.b2_polygonRadius)
        parts, axes, y0 = self.parts, self.axes, self._y.copy()
        self.world = world = b2.b2World(gravity=tuple(parts.gravity[list(axes)]), doSleep=False)
        world.continuousPhysics = continuous
        contacts = parts.collisions is not None
        for shape, corners in static_polygons(parts, axes, y0[0]):
            ground = world.CreateStaticBody(userData=shape.name)
            ground.CreatePolygonFixture(vertices=corners, restitution=0.0, friction=1.0)
        self.bodies = []
        rigid = {shape.body: shape for shape in self.rigid}
        for i in range(parts.n):
            position = tuple(y0[0, i, list(axes)])
            if parts.pinned[i]:
                body = world.CreateStaticBody(position=position, userData=i)
            else:
                # allowSleep per body: pybox2d 2.3.10 puts bodies to sleep whatever the world's doSleep says
                body = world.CreateDynamicBody(position=position, bullet=bullet, allowSleep=False, userData=i)
            e, mu = parts.against_shapes(i)
            r = float(parts.radii[i])
            if i in rigid:
                fixtures = self._fixtures(body, rigid[i], restitution=e, friction=mu * mu)
            else:
                fixtures = [body.CreateCircleFixture(radius=r, density=float(parts.masses[i]) / (math.pi * r * r),
                                                     restitution=e, friction=mu * mu)]
            if not contacts:
                for fixture in fixtures:
                    fixture.filterData = b2.b2Filter(categoryBits=1, maskBits=0)
            if i in rigid and not parts.pinned[i]:
                # the body's own mass and moment, not those of its fixtures' areas
                body.massData = b2.b2MassData(mass=float(parts.masses[i]), center=(0.0, 0.0), I=self.moment(i, 0.0))
            self.bodies.append(body)
        for i, j, k, rest, c in parts.links:
            if rest is None or k == 0:
                raise UnsupportedFeatureError(f"a damper without a spring (bodies {parts.names[i]}, {parts.names[j]}): "
                                              f"{ENGINE}'s distance joint is rigid without a spring frequency")
            inverse = sum(0.0 if parts.pinned[b] else 1.0 / parts.masses[b] for b in (i, j))
            if inverse == 0:
                continue
            hz, ratio = spring_frequency(k, c, 1.0 / inverse)
            world.CreateDistanceJoint(bodyA=self.bodies[i], bodyB=self.bodies[j],
                                      anchorA=self.bodies[i].position, anchorB=self.bodies[j].position,
                                      frequencyHz=hz, dampingRatio=ratio, collideConnected=True, length=rest)
        self.moving = body_indices(parts)
        self.iterations = (int(velocity_iterations), int(position_iterations))
        mode = "bullets" if bullet else "continuous physics" if continuous else "continuous physics off"
        tuned = "" if self.iterations == (VELOCITY_ITERATIONS, POSITION_ITERATIONS) else \
            f", {velocity_iterations} velocity and {position_iterations} position iterations"
        self.settings = f"Box2D {version('Box2D')}, {mode}{tuned}"

    def _fixtures(self, body, shape, **material) -> list:
        """The fixtures of a rotating body's section by the plane (:meth:`.base.PlanarRun.outline`)."""
        outline = self.outline(shape)
        if outline[0] == "circle":
            return [body.CreateCircleFixture(radius=outline[1], density=1.0, **material)]
        if outline[0] == "box":  # the polygon inside its skin, so that the skin's outside is the box
            half = tuple(max(h - self._skin, h / 2) for h in outline[1])
            return [body.CreatePolygonFixture(box=half, density=1.0, **material)]
        half, r = outline[1], outline[2]
        return [body.CreatePolygonFixture(box=(max(r - self._skin, r / 2), half), density=1.0, **material),
                *(body.CreateCircleFixture(radius=r, pos=(0.0, end), density=1.0, **material) for end in (-half, half))]

    def step(self, dt: float) -> None:
        self.world.Step(dt, *self.iterations)

    def run(self, steps: int, dt: float) -> None:
        for _ in range(steps):
            self.world.Step(dt, *self.iterations)

    def touching(self) -> dict:
        out = {}
        for contact in self.world.contacts:
            if not contact.touching:
                continue
            manifold = contact.worldManifold  # kept alive while its normal is read
            self._enter_contact(out, contact.fixtureA.body.userData, contact.fixtureB.body.userData,
                                tuple(manifold.normal))  # from A to B
        return out
