"""A tour of the built-in scenes: each run with its own integrator, on both backends.

Scenes with collisions run on NumPy only (collision detection is NumPy code), with their
collisions; the others run on NumPy and JAX, and the two final states are compared.
"""

from __future__ import annotations

import numpy as np
from steplab.integrators import simulate
from steplab.physics.scene import builtin_scenes, load_scene

from .runner import Study, run_tasks

BACKENDS = ("numpy", "jax")


def parameters(quick: bool) -> dict:
    return {"scenes": builtin_scenes(), "backends": list(BACKENDS), "fraction": 0.1 if quick else 1.0}


def tasks(params: dict) -> list[str]:
    """One task per scene (both its backends)."""
    return list(params["scenes"])


def task(params: dict, name: str) -> list[dict]:
    """Run one built-in scene with its declared integrator and dt on NumPy and JAX.

    Records per backend: steps, energy at the start and end, the largest difference
    between the two backends' final states, and the wall time. ``fraction`` of the
    scene's duration is run.
    """
    scene = load_scene(name)
    t_end = scene.t_start + max((scene.t_end - scene.t_start) * params["fraction"], scene.dt)
    world = scene.collisions if scene.collisions is not None and scene.collisions.detector != "none" else None
    backends = ["numpy"] if world is not None else params["backends"]
    finals, rows = {}, []
    for backend in backends:
        traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, t_end, scene.dt,
                        backend=backend, save_every=10**9, collisions=world)
        finals[backend] = traj.y[-1]
        rows.append({
            "scene": name, "integrator": scene.integrator, "backend": backend, "dt": scene.dt,
            "steps": traj.steps, "t_end": float(traj.t[-1]),
            "energy_start": float(scene.model.energy(scene.y0)),
            "energy_end": float(scene.model.energy(traj.y[-1])),
            "wall_time": traj.wall_time,
            "detector": world.detector if world is not None else "none",
            "impacts": traj.collisions.summary()["impacts"] if traj.collisions is not None else 0,
        })
    difference = float(np.max(np.abs(finals["numpy"] - finals["jax"]))) if len(finals) > 1 else None
    return [row | {"backend_difference": difference} for row in rows]


def reduce(params: dict, results: list) -> dict:
    return {"rows": [row for rows in results for row in rows]}


def compute(params: dict, progress=None) -> dict:
    """Every scene in turn (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


def summary(record: dict) -> list[tuple[str, str]]:
    worst = max(r["backend_difference"] for r in record["rows"] if r["backend_difference"] is not None)
    return [("scenes run", str(len({r["scene"] for r in record["rows"]}))),
            ("largest NumPy/JAX difference", f"{worst:.2g}")]


STUDY = Study("scenes", "Tour of the built-in scenes on NumPy and JAX", parameters, compute,
              plot=lambda record, out: [], summary=summary, tasks=tasks, task=task, reduce=reduce)
