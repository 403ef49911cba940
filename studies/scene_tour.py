"""A tour of the built-in scenes: each run with its own integrator, on both backends."""

from __future__ import annotations

import numpy as np

from integrators import simulate
from physics.scene import builtin_scenes, load_scene

BACKENDS = ("numpy", "jax")


def scene_tour(quick: bool = False, progress=None) -> dict:
    """Run every built-in scene with its declared integrator and dt on NumPy and JAX.

    Records per scene and backend: steps, energy at the start and end, the largest
    difference between the two backends' final states, and the wall time. ``quick``
    runs a tenth of each scene's duration.
    """
    rows = []
    for name in builtin_scenes():
        scene = load_scene(name)
        t_end = scene.t_start + (scene.t_end - scene.t_start) * (0.1 if quick else 1.0)
        finals = {}
        for backend in BACKENDS:
            traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, t_end, scene.dt,
                            backend=backend, save_every=10**9)
            finals[backend] = traj.y[-1]
            rows.append({
                "scene": name, "integrator": scene.integrator, "backend": backend, "dt": scene.dt,
                "steps": traj.steps, "t_end": float(traj.t[-1]),
                "energy_start": float(scene.model.energy(scene.y0)),
                "energy_end": float(scene.model.energy(traj.y[-1])),
                "wall_time": traj.wall_time,
            })
            if progress is not None:
                progress()
        rows[-1]["backend_difference"] = rows[-2]["backend_difference"] = float(
            np.max(np.abs(finals["numpy"] - finals["jax"])))
    return {"study": "scenes", "quick": quick, "rows": rows}


def count(quick: bool = False) -> int:
    """Progress ticks the tour makes."""
    return len(builtin_scenes()) * len(BACKENDS)
