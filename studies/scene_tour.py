"""A tour of the built-in scenes: each run with its own integrator, on both backends.

Scenes with collisions run on NumPy only (collision detection is NumPy code), with their
collisions; the others run on NumPy and JAX, and the two final states are compared.

The backends do the same arithmetic in another order, so they differ by round-off each
step, and a chaotic scene amplifies round-off exponentially: the cloth's 1,500 steps take
a difference of 1e-15 m to centimetres. The yardstick beside each difference is how far
NumPy alone moves from a start perturbed by PERTURBATION (relative; the positions, and the
rotating bodies' angular velocities): the guarantee is that the backends differ by no more
than ten times that, or by 1e-12 where neither grows, in positions, velocities and, where the
scene has rotating bodies, their orientations and angular velocities.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from steplab.integrators import simulate
from steplab.integrators.attached import scene_stepper
from steplab.integrators.scene_rotation import run_rotation
from steplab.physics.scene import builtin_scenes, load_scene

from .runner import Study, run_tasks

BACKENDS = ("numpy", "jax")
#: relative perturbation of the initial positions (times a standard normal draw) for the
#: yardstick run: about five units in the last place of float64, a few steps' round-off
PERTURBATION = 1e-15
#: the perturbation's draw
SEED = 0
#: the runs keep their first and last states only
SAVE_EVERY = 10**9


def parameters(quick: bool) -> dict:
    return {"scenes": builtin_scenes(), "backends": list(BACKENDS), "fraction": 0.1 if quick else 1.0}


def tasks(params: dict) -> list[str]:
    """One task per scene (both its backends)."""
    return list(params["scenes"])


def task(params: dict, name: str) -> list[dict]:
    """Run one built-in scene with its declared integrator and dt on NumPy and JAX.

    Records per backend: steps, energy at the start and end (the rotating bodies' spin included,
    turned as ``steplab run`` turns them), the wall time, and the largest differences between
    the two backends' final positions (m) and velocities (m/s), beside those between NumPy's
    run and NumPy's from perturbed initial positions (the yardstick of round-off amplified by
    the scene's dynamics). ``fraction`` of the scene's duration is run.
    """
    scene = load_scene(name)
    t_end = scene.t_start + max((scene.t_end - scene.t_start) * params["fraction"], scene.dt)
    world = scene.collisions if scene.collisions is not None and scene.collisions.detector != "none" else None
    backends = ["numpy"] if world is not None else params["backends"]
    finals, rows = {}, []
    for backend in backends:
        kept = []  # the step the run built: the collision step or the attached one, which turned the bodies
        stepper = scene_stepper(scene, kept, world, save_every=SAVE_EVERY)
        traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, t_end, scene.dt,
                        backend=backend, save_every=SAVE_EVERY, stepper=stepper)
        rotation = run_rotation(scene, traj, kept[0] if kept else None, backend=backend)
        finals[backend] = _final(traj, rotation)
        # springs at body-frame points: the end's energy with their lever arms where the bodies turned them
        end_model = kept[0].final_model() if kept and hasattr(kept[0], "final_model") else scene.model
        rows.append({
            "scene": name, "integrator": scene.integrator, "backend": backend, "dt": scene.dt,
            "steps": traj.steps, "t_end": float(traj.t[-1]),
            # with the rotating bodies' 1/2 omega . I omega, as steplab run reports them
            "energy_start": float(scene.model.energy(scene.y0, scene.rigid_bodies)),
            "energy_end": float(end_model.energy(traj.y[-1], rotation.at(-1) if rotation is not None else None)),
            "wall_time": traj.wall_time,
            "detector": world.detector if world is not None else "none",
            "impacts": traj.collisions.summary()["impacts"] if traj.collisions is not None else 0,
        })
    differences = {"backend_difference": None}
    if len(finals) > 1:
        perturbed = _perturbed(scene)
        kept = []
        traj = simulate(scene.model, scene.integrator, perturbed.y0, scene.t_start, t_end, scene.dt,
                        save_every=SAVE_EVERY, stepper=scene_stepper(perturbed, kept))
        finals["perturbed"] = _final(traj, run_rotation(perturbed, traj, kept[0] if kept else None))
        # the differences from NumPy's final state: JAX's, and the perturbed start's
        jax, moved = (_differences(finals["numpy"], finals[other]) for other in ("jax", "perturbed"))
        differences = {"backend_difference": max(jax["position"], jax["velocity"])}
        differences |= {f"{kind}_difference": value for kind, value in jax.items()}
        differences |= {f"perturbed_{kind}_difference": value for kind, value in moved.items()}
    return [row | differences for row in rows]


def _perturbed(scene):
    """``scene`` with its initial positions, and its rotating bodies' angular velocities, each moved by
    PERTURBATION (relative) times a standard normal draw (SEED)."""
    rng = np.random.default_rng(SEED)
    y0 = scene.y0.copy()
    y0[0] *= 1 + PERTURBATION * rng.standard_normal(y0[0].shape)
    bodies = scene.rigid_bodies
    if bodies is not None:
        omega = np.asarray(bodies.angular_velocities, float)
        bodies = dataclasses.replace(bodies, angular_velocities=omega * (1 + PERTURBATION * rng.standard_normal(
            omega.shape)))
    return dataclasses.replace(scene, y0=y0, rigid_bodies=bodies)


def _final(traj, rotation) -> tuple[np.ndarray, ...]:
    """A run's final (positions, velocities, orientations, angular velocities); the last two (0, 4) and
    (0, 3) without rotating bodies."""
    if rotation is None:
        return (*traj.y[-1], np.zeros((0, 4)), np.zeros((0, 3)))
    return (*traj.y[-1], rotation.orientations[-1], rotation.angular_velocities[-1])


def _differences(a, b) -> dict:
    """The largest differences of two final states (:func:`_final`): positions (m), velocities (m/s),
    orientations (of the unit quaternions, q and -q being one orientation) and angular velocities
    (rad/s); the last two None without rotating bodies."""
    (qa, va, oa, wa), (qb, vb, ob, wb) = a, b
    out = {"position": float(np.max(np.abs(qa - qb))), "velocity": float(np.max(np.abs(va - vb)))}
    if not len(oa):
        return out | {"orientation": None, "angular_velocity": None}
    sign = np.where(np.sum(oa * ob, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return out | {"orientation": float(np.max(np.abs(oa - sign * ob))),
                  "angular_velocity": float(np.max(np.abs(wa - wb)))}


def reduce(params: dict, results: list) -> dict:
    return {"rows": [row for rows in results for row in rows]}


def compute(params: dict, progress=None) -> dict:
    """Every scene in turn (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


def summary(record: dict) -> list[tuple[str, str]]:
    compared = [r for r in record["rows"] if r["backend_difference"] is not None and r["backend"] == "jax"]
    worst = max(compared, key=lambda r: r["backend_difference"])
    return [("scenes run", str(len({r["scene"] for r in record["rows"]}))),
            (f"largest NumPy/JAX difference ({worst['scene']}, {worst['steps']:,} steps)",
             f"{worst['position_difference']:.2g} m, {worst['velocity_difference']:.2g} m/s; from a start "
             f"perturbed by {PERTURBATION:g} NumPy alone moves {worst['perturbed_position_difference']:.2g} m, "
             f"{worst['perturbed_velocity_difference']:.2g} m/s (round-off, amplified by the scene)")]


STUDY = Study("scenes", "Tour of the built-in scenes on NumPy and JAX", parameters, compute,
              plot=lambda record, out: [], summary=summary, tasks=tasks, task=task, reduce=reduce)
