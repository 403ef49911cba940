"""Chipmunk2D through pymunk, for scenes in a plane: circles, static polygons, damped springs.

- The scene must stay in a plane (:func:`.base.plane_axes`); Chipmunk computes in float64.
- Bodies are dynamic bodies of their mass (the moment of a disc), with a circle shape when
  the scene has collisions; pinned bodies are static. Chipmunk does not sleep by default.
- A spring and damper on a pair is a ``DampedSpring``: Hooke's force from the positions at
  the start of the step, and the damping applied inside the solver as an exact
  exponential decay of the relative speed along the spring.
- Planes become static polygons behind them, boxes static polygons. Chipmunk has no
  continuous collision detection.
- Restitution ("elasticity") and friction: Chipmunk multiplies the two shapes'
  coefficients, so static shapes get 1 and each body its coefficient against them.
- Rotating bodies (the scene's ``rigid_bodies``) spin about the axis out of the plane, with
  their moment about it; their section by the plane is the shape (a box polygon, a circle,
  a capsule as a segment with a radius). Chipmunk turns a body by angle += dt omega.
- ``iterations``: the solver's iterations (Chipmunk's default 10).
- ``collision_slop``: the overlap Chipmunk leaves uncorrected; its default, 0.1, is meant
  for pixels: in metres it lets a golf ball sink 10 cm into the floor. The adapter uses
  5 mm, Box2D's linear slop (:data:`COLLISION_SLOP`).
"""

from __future__ import annotations

import numpy as np

from .base import PlanarRun, Setting, body_indices, require, version
from .box2d_engine import static_polygons

ENGINE = "Chipmunk"
#: m, the overlap Chipmunk leaves to its position correction (Box2D's linear slop)
COLLISION_SLOP = 0.005


class ChipmunkRun(PlanarRun):
    engine = "chipmunk"
    display_name = "Chipmunk2D (pymunk, 2-D)"
    colour = "tab:purple"
    precision = "float64"
    package = distribution = "pymunk"
    study_settings = (
        Setting("chipmunk", "Chipmunk", {}, False, "exponential-damping-euler",
                "elasticity is the product of the two shapes'; with the collision slop at 5 mm the bounce is eps^2"),
    )
    rotation_settings = (
        Setting("chipmunk", "Chipmunk", {}, None, "exponential-map",
                "a spin about the axis out of the plane: angle += h omega, the exact turn at constant omega (as "
                "every method that turns by the exponential map); a 3-D tumble is out of its reach"),
    )
    stack_settings = (
        Setting("chipmunk", "Chipmunk default", {}, None, None, "10 iterations (Chipmunk's default)"),
        Setting("chipmunk-iterations", "Chipmunk, 30 iterations", {"iterations": 30}, None, None,
                "30 iterations: each contact of a tall stack is solved more often per step"),
    )

    def __init__(self, model, collisions=None, dt: float = 0.01, collision_slop: float = COLLISION_SLOP,
                 iterations: int | None = None, y0=None, bodies=None):
        pymunk = require("pymunk", ENGINE)
        super().__init__(model, collisions, ENGINE, y0, bodies)
        parts, axes, y0 = self.parts, self.axes, self._y.copy()
        self.space = space = pymunk.Space()
        space.gravity = tuple(float(g) for g in parts.gravity[list(axes)])
        space.collision_slop = collision_slop
        if iterations is not None:
            space.iterations = int(iterations)
        contacts = parts.collisions is not None
        self._owner = {}  # shape -> body index or static shape name
        for shape, corners in static_polygons(parts, axes, y0[0]):
            poly = pymunk.Poly(space.static_body, corners)
            poly.elasticity, poly.friction = 1.0, 1.0
            space.add(poly)
            self._owner[poly] = shape.name
        self.bodies = []
        rigid = {shape.body: shape for shape in self.rigid}
        for i in range(parts.n):
            m, r = float(parts.masses[i]), float(parts.radii[i])
            if parts.pinned[i]:
                body = pymunk.Body(body_type=pymunk.Body.STATIC)
            else:
                body = pymunk.Body(m, self.moment(i, pymunk.moment_for_circle(m, 0.0, r)))
            body.position = tuple(float(x) for x in y0[0, i, list(axes)])
            space.add(body)
            if contacts:
                shape = self._shape(pymunk, body, rigid[i]) if i in rigid else pymunk.Circle(body, r)
                shape.elasticity, shape.friction = parts.against_shapes(i)
                space.add(shape)
                self._owner[shape] = i
            self.bodies.append(body)
        for i, j, k, rest, c in parts.links:
            if parts.pinned[i] and parts.pinned[j]:
                continue
            length = rest if rest is not None else float(np.linalg.norm(y0[0, j] - y0[0, i]))
            space.add(pymunk.DampedSpring(self.bodies[i], self.bodies[j], (0, 0), (0, 0), length, k, c))
        self.moving = body_indices(parts)
        self.settings = (f"Chipmunk (pymunk {version('pymunk')}), collision slop {collision_slop * 1e3:g} mm"
                         + (f", {iterations} iterations" if iterations is not None else ""))

    def _shape(self, pymunk, body, shape):
        """The shape of a rotating body's section by the plane (:meth:`.base.PlanarRun.outline`)."""
        outline = self.outline(shape)
        if outline[0] == "circle":
            return pymunk.Circle(body, outline[1])
        if outline[0] == "box":
            return pymunk.Poly.create_box(body, (2 * outline[1][0], 2 * outline[1][1]))
        return pymunk.Segment(body, (0.0, -outline[1]), (0.0, outline[1]), outline[2])

    def step(self, dt: float) -> None:
        self.space.step(dt)

    def run(self, steps: int, dt: float) -> None:
        for _ in range(steps):
            self.space.step(dt)

    def touching(self) -> dict:
        out = {}

        def record(arbiter):
            s1, s2 = arbiter.shapes  # the normal runs from the first shape to the second
            self._enter_contact(out, self._owner.get(s1), self._owner.get(s2), arbiter.normal)

        for i in self.moving:
            self.bodies[i].each_arbiter(record)
        return out
