"""The collision-heavy scene of the bench, N spheres falling into a walled box (issue 13):
:mod:`steplab.physics.ball_pit` with the bench's seed.

Its scene files (``benchmarks/scenes/ball-pit-*.toml``, written by :func:`write_scene_files`,
which a test checks they still are) run with ``steplab run`` exactly what the bench times;
:func:`mujoco_model` is the same box for MuJoCo.
"""

from __future__ import annotations

from steplab.physics import ball_pit as _physics
from steplab.physics.ball_pit import DT as DT
from steplab.physics.ball_pit import LAYER as LAYER
from steplab.physics.ball_pit import MASS as MASS
from steplab.physics.ball_pit import RADIUS as RADIUS
from steplab.physics.ball_pit import RESTITUTION as RESTITUTION
from steplab.physics.ball_pit import SPEED as SPEED
from steplab.physics.ball_pit import box_side as box_side

from .config import SEED

#: the ball pits written as scene files (``benchmarks/scenes/``), for ``steplab run``
SCENE_FILE_SIZES = (1_000, 2_000, 10_000, 100_000)


def ball_pit_toml(n: int, seed: int = SEED, t_end: float = 1.0, detector: str = "swept") -> str:
    """The scene file of ``n`` balls falling into a box (:func:`steplab.physics.ball_pit.ball_pit_toml`)."""
    return _physics.ball_pit_toml(n, seed, t_end, detector)


def scene_file_name(n: int) -> str:
    """The name of the scene file of ``n`` balls in ``benchmarks/scenes/`` (``ball-pit-1e4.toml``)."""
    from .record import size_label

    return f"ball-pit-{size_label(n)}.toml"


def write_scene_files(folder, sizes=SCENE_FILE_SIZES) -> None:
    """Write the scene file of each size of ``sizes`` into ``folder``."""
    from pathlib import Path

    for n in sizes:
        (Path(folder) / scene_file_name(n)).write_text(ball_pit_toml(n))


def ball_pit(n: int, seed: int = SEED, t_end: float = 1.0, detector: str = "swept", side: float | None = None):
    """The scene of :func:`ball_pit_toml`, loaded (a :class:`steplab.physics.scene.Scene`); ``side``
    the box's, m (default :func:`box_side`)."""
    return _physics.ball_pit(n, seed, t_end, detector, side)


def mujoco_model(scene, iterations: int = 10) -> str:
    """MJCF of a ball pit for MuJoCo: free-joint spheres in a box of planes, PGS, sparse Jacobian.

    The issue's settings: the PGS solver with ``iterations`` sweeps, the sparse Jacobian,
    dt = the scene's, gravity, no air; restitution becomes the damping ratio of MuJoCo's
    soft contact (:mod:`steplab.engines.mjcf`, which writes the file; its keyframe holds
    the initial state).
    """
    from steplab.engines.mjcf import MujocoOption, mjcf

    return mjcf(scene.model, scene.y0, scene.dt, scene.collisions,
                MujocoOption("Euler", solver="PGS", iterations=iterations, jacobian="sparse"), name=scene.name)
