"""What a run of a scene says about itself: the summary ``steplab run`` prints and writes as JSON.

Assembled here, beside :func:`~steplab.integrators.simulate`, from the scene, the
trajectory and the collision world that made it; the command line only prints it. Every
number carries its unit in its key's documentation: times in s, positions in m,
velocities in m/s, energies in J, ``wall_time`` in s.
"""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class RunSettings:
    """What a run of ``scene`` was asked to be: both summaries below start from it.

    ``world`` is its collision world (None: without collisions), ``energy_start`` (J) the
    scene's initial energy, ``warnings`` every warning line of the run."""

    scene: object
    integrator: object
    dt: float
    world: object
    precision: str
    energy_start: float
    warnings: list[str]


def run_summary(run: RunSettings, traj, rotation=None) -> dict:
    """The summary of ``traj``, the finished ``run``.

    ``rotation`` (a :class:`.scene_rotation.RotationTrajectory`, None for a scene without rotating
    bodies) adds the rotating bodies' kinetic energy 1/2 omega . I omega to ``energy_end`` and the
    fields of :func:`.scene_rotation.rotation_summary`: orientations [w, x, y, z], angular
    velocities in rad/s (world frame), angular momenta in kg m^2/s.
    """
    scene, world, energy_start = run.scene, run.world, run.energy_start
    energy_end = float(scene.model.energy(traj.y[-1].astype(float), rotation.at(-1) if rotation is not None else None))
    fields = {}
    if rotation is not None:
        from .scene_rotation import rotation_summary

        fields = rotation_summary(scene, traj, rotation)
    return {
        "scene": scene.name, "integrator": run.integrator.name, "dt": run.dt, "steps": traj.steps,
        "t_start": scene.t_start, "t_end": float(traj.t[-1]), "backend": traj.backend,
        "precision": run.precision, "bodies": list(scene.model.names),
        "final_positions": traj.positions[-1].tolist(), "final_velocities": traj.velocities[-1].tolist(),
        "energy_start": energy_start, "energy_end": energy_end,
        "energy_change": energy_end - energy_start,
        "energy_relative_change": (energy_end - energy_start) / abs(energy_start) if energy_start else None,
        "wall_time": traj.wall_time, "detector": world.detector if world is not None else "none",
        "method": world.method if world is not None else None,
        "solver": dataclasses.asdict(world.solver) if world is not None and world.method == "solver" else None,
        "collisions": traj.collisions.summary() if traj.collisions is not None else None, "warnings": run.warnings,
    } | fields


def stopped_summary(run: RunSettings, error, log=None) -> dict:
    """The summary of ``run`` stopped by ``error`` at ``error.t`` (s), before a step that held more
    impacts than the cap; ``log``: the collisions up to there."""
    return {"scene": run.scene.name, "integrator": run.integrator.name, "dt": run.dt, "detector": run.world.detector,
            "error": str(error), "stopped_at": error.t, "warnings": [*run.warnings, str(error)],
            "energy_start": run.energy_start, "collisions": log.summary() if log is not None else None}
