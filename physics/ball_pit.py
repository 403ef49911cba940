"""A ball pit: N spheres falling into a walled box, the collision-heavy scene of the bench.

``n`` balls of radius 0.1 m start at random in a layer 2 m deep above the floor of a box
(a floor and four walls, all planes), thrown in random directions at up to 2 m/s, and fall
under gravity, bouncing with eps = 0.8 off the walls, the floor and each other. The floor
is sized for the "sparse" scenes of the collisions-at-scale benchmarks, 0.2 m^2 per ball
(2,000 balls in a 20 m box, 10^4 in a 44.7 m one), so the density, and the impacts per
ball and step, stay the same from 10^3 to 10^5 balls: the cost per ball is what grows or not.

The scene is a scene file (one ``[[particles]]`` block, a few hundred bytes whatever ``n``)
read back by the scene loader, so ``steplab run`` on the file runs exactly what the bench
(``steplab.bench``) and the contacts study time.
"""

from __future__ import annotations

import math

from .scene import parse_scene

#: m, the issue's spheres
RADIUS = 0.1
#: kg
MASS = 1.0
#: m^2 of floor per ball: the issue's sparse scenes (2,000 balls in a 20 m box)
FLOOR_AREA_PER_BALL = 0.2
#: m, the depth of the layer the centres start in (above one radius off the floor)
LAYER = 2.0
#: m/s, largest initial speed (random directions, as in the built-in n-balls)
SPEED = 2.0
#: the issue's coefficient of restitution
RESTITUTION = 0.8
#: s, one frame at 60 Hz
DT = 1.0 / 60.0


def box_side(n: int) -> float:
    """Side of the square floor for ``n`` balls, m, to 0.1 m (20.0 for 2,000)."""
    return round(math.sqrt(FLOOR_AREA_PER_BALL * n), 1)


def ball_pit_toml(n: int, seed: int, t_end: float = 1.0, detector: str = "swept", side: float | None = None) -> str:
    """The scene file of ``n`` balls falling into a box, one simulated second at dt = 1/60 s.

    ``side``: the floor's side, m (default :func:`box_side`: the sparse pits; 6 m for 2,000
    balls is the crowded pit, 12 % of the layer's volume filled)."""
    if n < 1:
        raise ValueError(f"a ball pit needs at least one ball, got n = {n}")
    half = (box_side(n) if side is None else side) / 2
    inner = half - RADIUS  # centres start at least one radius inside the walls
    walls = "".join(
        f'\n[[collisions.planes]]\nname = "{name}"\nnormal = {normal}\noffset = {-half!r}\n'
        for name, normal in (("wall -x", "[1.0, 0.0, 0.0]"), ("wall +x", "[-1.0, 0.0, 0.0]"),
                             ("wall -y", "[0.0, 1.0, 0.0]"), ("wall +y", "[0.0, -1.0, 0.0]")))
    description = (f"{n:,} balls (r = {RADIUS:g} m) falling into a {2 * half:g} m box with a floor and four "
                   f"walls, bouncing with eps = {RESTITUTION:g} (the collision benchmark of steplab bench).")
    return f'''description = "{description}"

[simulation]
integrator = "semi-implicit-euler"
dt = {DT!r}
t_end = {t_end!r}

[[particles]]
name = "ball"
count = {n}
seed = {seed}
mass = {MASS!r}
radius = {RADIUS!r}
box_min = [{-inner!r}, {-inner!r}, {RADIUS!r}]
box_max = [{inner!r}, {inner!r}, {RADIUS + LAYER!r}]
speed = {SPEED!r}

[forces.gravity]

[collisions]
detector = "{detector}"
restitution = {RESTITUTION!r}

[[collisions.planes]]
name = "floor"
normal = [0.0, 0.0, 1.0]
offset = 0.0
{walls}'''


def ball_pit(n: int, seed: int, t_end: float = 1.0, detector: str = "swept", side: float | None = None):
    """The scene of :func:`ball_pit_toml`, loaded (a :class:`steplab.physics.scene.Scene`)."""
    return parse_scene(ball_pit_toml(n, seed, t_end, detector, side), label=f"<ball pit of {n}>",
                       name=f"ball-pit-{n}")
