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

import importlib.metadata
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: the engines the bench knows, in the order it runs them
ENGINES = ("mujoco", "pybullet")


@dataclass(frozen=True)
class EngineRun:
    """One engine set up on one scene: ``run(steps)`` steps it from the scene's start."""

    name: str
    settings: str
    run: Callable[[int], np.ndarray]


def engine_runs(scene, engines=ENGINES) -> tuple[list[EngineRun], dict[str, str]]:
    """The engines of ``engines`` set up on ``scene``, and a note for each one not installed."""
    runs, missing = [], {}
    for name in engines:
        try:
            version = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            missing[name] = f"{name} is not installed (pip install {name}): not compared"
            continue
        runs.append(BUILDERS[name](scene, version))
    return runs, missing


def mujoco_run(scene, version: str) -> EngineRun:
    """MuJoCo on the scene's MJCF (:func:`.ball_pit_scene.mujoco_model`): ``run`` returns the centres."""
    from steplab.engines import build_scene

    engine = build_scene("mujoco", scene, integrator="Euler", solver="PGS", iterations=10, jacobian="sparse")

    def run(steps: int) -> np.ndarray:
        engine.set_state(scene.y0)
        engine.run(steps)
        return engine.state()[0]

    return EngineRun("mujoco", f"MuJoCo {version}, PGS, sparse Jacobian, 10 iterations", run)


def pybullet_run(scene, version: str) -> EngineRun:
    """pybullet (DIRECT, no GUI) with its default solver: rigid spheres and five static planes."""
    from steplab.engines import build_scene

    engine = build_scene("bullet", scene)

    def run(steps: int) -> np.ndarray:
        engine.set_state(scene.y0)
        engine.run(steps)
        return engine.state()[0]

    return EngineRun("pybullet", f"pybullet {version}, default solver", run)


BUILDERS = {"mujoco": mujoco_run, "pybullet": pybullet_run}
