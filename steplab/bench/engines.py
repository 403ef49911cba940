"""Game-physics engines as peers of the collision bench: MuJoCo and pybullet, when installed.

Neither is a dependency of steplab (they are the extra ``pip install -e ".[engines]"``):
each is imported when the bench asks for it, and :func:`engine_runs` names the ones that
are missing instead (the record says so). Each peer is an adapter of
:mod:`steplab.engines` built once from a ball-pit scene (:mod:`.ball_pit_scene`) with the
scene's initial state, step, gravity and restitution, and gives a call that puts the
bodies back at the start and takes ``steps`` steps: the timed work is the stepping alone.

- MuJoCo: the issue's settings, the PGS solver, the sparse Jacobian, 10 iterations
  (MuJoCo's default Newton solver did not finish 61 steps of 2,000 spheres in 5 minutes).
- pybullet: its default solver (sequential impulses) on rigid bodies
  (:mod:`steplab.engines.bullet_engine`); pybullet multiplies the two bodies'
  restitutions, so the walls' eps = 0.8 becomes 0.64 between two balls.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: the engines the bench compares with, by key of :data:`steplab.engines.ENGINES`, in the order it
#: runs them: the adapter's options, and the record's line on them ({version}: the engine's)
PEERS = {
    "mujoco": ({"integrator": "Euler", "solver": "PGS", "iterations": 10, "jacobian": "sparse"},
               "MuJoCo {version}, PGS, sparse Jacobian, 10 iterations"),
    "bullet": ({}, "pybullet {version}, default solver"),
}


@dataclass(frozen=True)
class Peer:
    """One engine set up on one scene: ``run(steps)`` steps it from the scene's start and
    returns the centres; ``name`` is the record's, the engine's distribution ("pybullet")."""

    name: str
    settings: str
    run: Callable[[int], np.ndarray]


def peer_names(engines=tuple(PEERS)) -> list[str]:
    """The record's names of ``engines``: their distributions."""
    from steplab.engines import ENGINES

    return [ENGINES[key].distribution for key in engines]


def engine_runs(scene, engines=tuple(PEERS)) -> tuple[list[Peer], dict[str, str]]:
    """The engines of ``engines`` set up on ``scene``, and a note for each one not installed."""
    from steplab.engines import ENGINES, build_scene
    from steplab.engines.base import version

    runs, missing = [], {}
    for key in engines:
        name = ENGINES[key].distribution
        if not ENGINES[key].available():
            missing[name] = f"{name} is not installed (pip install {name}): not compared"
            continue
        options, settings = PEERS[key]
        engine = build_scene(key, scene, **options)

        def run(steps: int, engine=engine) -> np.ndarray:
            engine.set_state(scene.y0)
            engine.run(steps)
            return engine.state()[0]

        runs.append(Peer(name, settings.format(version=version(name)), run))
    return runs, missing
