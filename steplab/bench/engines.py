"""Game-physics engines as peers of the collision bench: MuJoCo and pybullet, when installed.

Neither is a dependency of steplab: each is imported when the bench asks for it, and
:func:`engine_runs` names the ones that are missing instead (the record says so). Each
peer is built once from a ball-pit scene (:mod:`.ball_pit_scene`) with the scene's initial
state, step and gravity, and gives a call that puts the bodies back at the start and
takes ``steps`` steps: the timed work is the stepping alone.

- MuJoCo: the issue's settings, the PGS solver, the sparse Jacobian, 10 iterations
  (MuJoCo's default Newton solver did not finish 61 steps of 2,000 spheres in 5 minutes).
- pybullet: its defaults (sequential impulses, 10 iterations), as the issue measured; its
  restitution stays at the default 0 (pybullet multiplies the two bodies' coefficients, so
  no one setting gives the scene's eps = 0.8 for both balls and walls).
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .ball_pit_scene import mujoco_model

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
    import mujoco

    model = mujoco.MjModel.from_xml_string(mujoco_model(scene))
    data = mujoco.MjData(model)
    n = scene.model.n_bodies
    # a free joint's qpos is the position and a unit quaternion (w, x, y, z); its qvel is
    # the linear and the angular velocity
    qpos = np.zeros((n, 7))
    qpos[:, :3], qpos[:, 3] = scene.y0[0], 1.0
    qvel = np.zeros((n, 6))
    qvel[:, :3] = scene.y0[1]

    def run(steps: int) -> np.ndarray:
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = qpos.ravel(), qvel.ravel()
        mujoco.mj_step(model, data, nstep=steps)
        return data.qpos.reshape(n, 7)[:, :3].copy()

    return EngineRun("mujoco", f"MuJoCo {version}, PGS, sparse Jacobian, 10 iterations", run)


def pybullet_run(scene, version: str) -> EngineRun:
    """pybullet (DIRECT, no GUI) with its default solver: spheres and five static planes."""
    import pybullet

    client = pybullet.connect(pybullet.DIRECT)
    p = {"physicsClientId": client}
    pybullet.setGravity(0.0, 0.0, -9.81, **p)
    pybullet.setTimeStep(scene.dt, **p)
    for plane in scene.collisions.shapes:
        shape = pybullet.createCollisionShape(pybullet.GEOM_PLANE, planeNormal=list(plane.normal), **p)
        # a plane shape passes through its body's origin: put the origin on the plane
        pybullet.createMultiBody(0.0, shape, basePosition=list(plane.offset * plane.normal), **p)
    sphere = pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=float(scene.model.radii[0]), **p)
    positions, velocities = scene.y0[0], scene.y0[1]
    bodies = pybullet.createMultiBody(float(scene.model.masses[0]), sphere, batchPositions=positions.tolist(), **p)
    for body, v in zip(bodies, velocities):
        pybullet.resetBaseVelocity(body, v.tolist(), [0.0, 0.0, 0.0], **p)
    start = pybullet.saveState(**p)

    def run(steps: int) -> np.ndarray:
        pybullet.restoreState(start, **p)
        for _ in range(steps):
            pybullet.stepSimulation(**p)
        return np.array([pybullet.getBasePositionAndOrientation(b, **p)[0] for b in bodies])

    return EngineRun("pybullet", f"pybullet {version}, default solver", run)


BUILDERS = {"mujoco": mujoco_run, "pybullet": pybullet_run}
