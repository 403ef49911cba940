"""The collision-heavy scene of the bench: N spheres falling into a walled box (issue 13).

``n`` balls of radius 0.1 m start at random in a layer 2 m deep above the floor of a box
(a floor and four walls, all planes), thrown in random directions at up to 2 m/s, and fall
under gravity, bouncing with eps = 0.8 off the walls, the floor and each other. The floor
is sized for the issue's "sparse" scenes, 0.2 m^2 per ball (2,000 balls in a 20 m box,
10^4 in a 44.7 m one), so the density, and the impacts per ball and step, stay the same
from 10^3 to 10^5 balls: the cost per ball is what grows or not.

The scene is written as a scene file (one ``[[particles]]`` block, a few hundred bytes
whatever ``n``) and read back by the scene loader, so ``steplab run`` on the file
(``benchmarks/scenes/ball-pit-*.toml``, written by :func:`write_scene_files`, which a
test checks they still are) runs exactly what the bench times. :func:`mujoco_model` is the same box for MuJoCo.
"""

from __future__ import annotations

import math

from .config import SEED

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
#: the ball pits written as scene files (``benchmarks/scenes/``), for ``steplab run``
SCENE_FILE_SIZES = (1_000, 2_000, 10_000, 100_000)
#: MuJoCo's arena per thousand balls, MB (enough for each ball on the floor touching a few others)
MEGABYTES_PER_1000_BALLS = 20


def box_side(n: int) -> float:
    """Side of the square floor for ``n`` balls, m, to 0.1 m (20.0 for 2,000)."""
    return round(math.sqrt(FLOOR_AREA_PER_BALL * n), 1)


def ball_pit_toml(n: int, seed: int = SEED, t_end: float = 1.0, detector: str = "swept") -> str:
    """The scene file of ``n`` balls falling into a box, one simulated second at dt = 1/60 s."""
    if n < 1:
        raise ValueError(f"a ball pit needs at least one ball, got n = {n}")
    half = box_side(n) / 2
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


def scene_file_name(n: int) -> str:
    """The name of the scene file of ``n`` balls in ``benchmarks/scenes/`` (``ball-pit-1e4.toml``)."""
    from .record import size_label

    return f"ball-pit-{size_label(n)}.toml"


def write_scene_files(folder, sizes=SCENE_FILE_SIZES) -> None:
    """Write the scene file of each size of ``sizes`` into ``folder``."""
    from pathlib import Path

    for n in sizes:
        (Path(folder) / scene_file_name(n)).write_text(ball_pit_toml(n))


def ball_pit(n: int, seed: int = SEED, t_end: float = 1.0, detector: str = "swept"):
    """The scene of :func:`ball_pit_toml`, loaded (a :class:`steplab.physics.scene.Scene`)."""
    from steplab.physics.scene import parse_scene

    return parse_scene(ball_pit_toml(n, seed, t_end, detector), label=f"<ball pit of {n}>", name=f"ball-pit-{n}")


def mujoco_model(scene, iterations: int = 10) -> str:
    """MJCF of a ball pit for MuJoCo: free-joint spheres in a box of planes, PGS, sparse Jacobian.

    The issue's settings: the PGS solver with ``iterations`` sweeps, the sparse Jacobian,
    dt = the scene's, gravity, no air. Restitution has no direct counterpart in MuJoCo's
    soft contacts; the contacts keep MuJoCo's defaults. The initial state is the scene's
    (positions in ``qpos``, velocities in ``qvel``: :func:`mujoco_state`).
    """
    half = -scene.collisions.shapes[1].offset
    r = float(scene.model.radii[0])
    m = float(scene.model.masses[0])
    walls = "".join(f'<geom type="plane" size="0 0 1" pos="{x} {y} 0" zaxis="{nx} {ny} 0"/>'
                    for x, y, nx, ny in ((-half, 0, 1, 0), (half, 0, -1, 0), (0, -half, 0, 1), (0, half, 0, -1)))
    balls = "".join(f'<body><freejoint/><geom type="sphere" size="{r!r}" mass="{m!r}"/></body>'
                    for _ in range(scene.model.n_bodies))
    # MuJoCo's arena is allocated once, at a default size too small for 10^4 spheres: its
    # broadphase takes 2 bytes per pair of bodies (200 MB for 10^4, 20 GB for 10^5), and
    # the contacts and constraint rows MEGABYTES_PER_1000_BALLS for each thousand balls
    n = scene.model.n_bodies
    memory = 64 + (2 * n * n) // 2**20 + MEGABYTES_PER_1000_BALLS * n // 1000
    return (f'<mujoco><size memory="{memory}M"/>'
            f'<option timestep="{scene.dt!r}" solver="PGS" jacobian="sparse" iterations="{iterations}"/>'
            f'<worldbody><geom type="plane" size="0 0 1"/>{walls}{balls}</worldbody></mujoco>')
