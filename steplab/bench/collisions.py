"""The collision section of ``steplab bench``: ball pits of 10^3 to 10^5 spheres (issue 13).

Each pit (:mod:`.ball_pit_scene`) runs from its start for the configured steps of dt = 1/60 s
with semi-implicit Euler and the swept event loop, as ``steplab run`` runs its scene
file; the engines (:mod:`.engines`) run the same bodies from the same state for the same
steps. A small pit runs first, to compile steplab's Numba kernels; every contender is set
up and takes one step before timing, then the contenders run in turn, round after round. Reported: the wall
time per step, the simulated seconds per wall second (the real-time factor; 1 is real
time) and, where an engine ran, the ratio steplab / engine of the wall times.

The engines' contacts are not steplab's (soft contacts, no restitution), so their final
states differ wherever balls touched; each one is checked for keeping every ball in the
box (``balls_inside``), and the median distance of its balls to steplab's is recorded
(``median_distance_to_steplab``): over the first steps, while most balls fly free and
move alike in every engine, it shows that they started from the same state.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from steplab.core.timing import interleaved_times

from .ball_pit_scene import ball_pit, box_side
from .config import REAL_TIME_TARGETS, SOLVER_ENGINE_TARGETS, SOLVER_REAL_TIME_TARGETS, Config
from .engines import engine_runs, peer_names
from .record import Record, size_label

#: the crowded pit's targets (issue 27): microseconds per impact of the event loop, and its wall time over MuJoCo's
CROWDED_US_PER_IMPACT, CROWDED_VS_MUJOCO = 20.0, 3.0

#: the pit run first, to compile every kernel of the event loop: (balls, steps); Numba
#: compiles a kernel per type signature, not size, and in 30 steps these balls fall onto
#: the floor and hit each other, so every path of the loop has been taken
WARM_UP_PIT = (50, 30)


def ball_pits(config: Config, record: Record, progress) -> None:
    """Every ball pit of ``config.collision_runs``: steplab, and the engines installed."""
    from steplab.integrators import simulate

    start = time.perf_counter()
    scene = ball_pit(WARM_UP_PIT[0])
    simulate(scene.model, scene.integrator, scene.y0, scene.t_start, dt=scene.dt, n_steps=WARM_UP_PIT[1],
             collisions=scene.collisions)
    record.data["compile_seconds"]["collisions, warm-up pit"] = time.perf_counter() - start
    for balls, steps in config.collision_runs:
        _ball_pit(balls, steps, config, record)
        progress(f"collisions, {balls:,} balls: done")
    if config.crowded_pit:
        crowded_pit(config, record)
        progress(f"collisions, crowded pit of {config.crowded_pit[0]:,} balls: done")


def crowded_pit(config: Config, record: Record) -> None:
    """The crowded pit: the event loop (its compiled step), the contact solver and MuJoCo, interleaved in one run.

    ``config.crowded_pit`` = (balls, side, steps): the full run's 2,000 balls in a 6 m box pile up
    and come to rest, 59,312 impacts in their first simulated second.

    Recorded: the impacts, the wall time per impact, and the ratio ``vs_mujoco_crowded_pit_2000``
    of the wall times (MuJoCo's soft contacts cost the same whatever the impacts; the event loop
    resolves each one at its time), with the issue's targets; the contact solver at its defaults
    beside them (``steplab_solver``), its kernels compiled by one step before the rounds (a first
    call compiles them: 34 s of wall time at load 20, which an earlier, unwarmed measurement
    reported as the solver's 55 s on this pit).
    """
    from steplab.integrators import simulate

    balls, side, steps = config.crowded_pit
    scene = ball_pit(balls, side=side)
    label, finals = f"crowded_pit_{size_label(balls)}", {}
    what = (f"{balls:,} balls falling into a {side:g} m box (crowded), {scene.integrator}, {steps} steps of "
            f"dt = 1/{round(1 / scene.dt)} s, {scene.collisions.detector} event loop (compiled step)")
    solver_world = dataclasses.replace(scene.collisions, method="solver")  # the contact solver, default settings

    def steplab(name="steplab", collisions=scene.collisions, k=steps):
        finals[name] = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, dt=scene.dt,
                                n_steps=k, save_every=k, collisions=collisions)

    steplab("steplab_solver", solver_world, 1)  # compiles the solver's kernels
    calls = {"steplab": steplab, "steplab_solver": lambda: steplab("steplab_solver", solver_world)}
    engines, not_compared = engine_runs(scene, ("mujoco",))
    for engine in engines:
        engine.run(1)
        calls[engine.name] = lambda engine=engine: engine.run(steps)
    t = interleaved_times(calls, config.collision_repeats, warm_up=False)
    log = finals["steplab"].collisions
    impacts = log.count()
    per_impact = t["steplab"].minimum / max(impacts, 1)
    settings = {"steplab": "steplab, compiled event loop",
                "steplab_solver": f"steplab, contact solver, {solver_world.solver.describe()}",
                **{engine.name: engine.settings for engine in engines}}
    record.data["collisions"][label] = {
        "what": what, "balls": balls, "steps": steps, "box_side": side, "impacts": impacts,
        "seconds_per_impact": per_impact, "not_compared": not_compared,
        "contenders": {name: {"settings": settings[name], **_speed(times, steps, scene.dt)}
                       for name, times in t.items()}}
    record.data["targets"][f"{label}_us_per_impact"] = {
        "target": CROWDED_US_PER_IMPACT, "us_per_impact": 1e6 * per_impact,
        "met": 1e6 * per_impact <= CROWDED_US_PER_IMPACT, "what": f"event loop, wall microseconds per impact, {what}"}
    for engine in engines:
        name = f"vs_{engine.name}_{label}"
        record.compare(name, "collisions", what, engine.settings, t["steplab"], t[engine.name], None,
                       impacts=impacts, steplab_seconds_per_impact=per_impact)
        ratio = record.data["ratios"][name]
        record.data["targets"][name] = {"target": CROWDED_VS_MUJOCO, "ratio": ratio, "met": ratio <= CROWDED_VS_MUJOCO}


def balls_inside(q, side: float) -> int:
    """Balls whose centres are inside the box of floor ``side`` (none fell through a wall)."""
    q = np.asarray(q)
    return int(np.sum(np.all(np.abs(q[:, :2]) <= side / 2, axis=1) & (q[:, 2] >= 0.0)))


def _ball_pit(balls: int, steps: int, config: Config, record: Record) -> None:
    from steplab.integrators import simulate

    scene = ball_pit(balls)
    world, side, dt = scene.collisions, box_side(balls), scene.dt
    simulated = steps * dt
    label = f"ball_pit_{size_label(balls)}"
    what = (f"{balls:,} balls falling into a {side:g} m box, {scene.integrator}, "
            f"{steps} steps of dt = 1/{round(1 / dt)} s")
    # what each of steplab's contenders ran, in the comparisons' words
    event_what, solver_what = f"{what}, {world.detector} event loop", f"{what}, contact solver"
    finals, setup = {}, {}

    solver_world = dataclasses.replace(world, method="solver")  # the contact solver, default settings

    def steplab(k: int, name="steplab", collisions=world):
        traj = simulate(scene.model, scene.integrator, scene.y0, scene.t_start, dt=dt, n_steps=k, save_every=k,
                        collisions=collisions)  # keeps the first and the last state only
        finals[name] = traj
        return traj

    start = time.perf_counter()
    steplab(1)  # the scene's first step (the kernels are compiled: WARM_UP_PIT)
    setup["steplab"] = time.perf_counter() - start
    start = time.perf_counter()
    steplab(1, "steplab_solver", solver_world)
    setup["steplab_solver"] = time.perf_counter() - start
    if balls <= config.collision_peer_max_balls:
        start = time.perf_counter()
        engines, not_compared = engine_runs(scene)
        for engine in engines:
            engine.run(1)
        setup["engines"] = time.perf_counter() - start
    else:
        engines = []
        not_compared = {name: f"{name}: not set up above {config.collision_peer_max_balls:,} balls "
                              "(collision_peer_max_balls)" for name in peer_names()}
    calls = {"steplab": lambda: steplab(steps),
             "steplab_solver": lambda: steplab(steps, "steplab_solver", solver_world)}
    for engine in engines:
        calls[engine.name] = lambda engine=engine: finals.__setitem__(engine.name, engine.run(steps))
    t = interleaved_times(calls, config.collision_repeats, warm_up=False)

    log = finals["steplab"].collisions
    loop = getattr(world, "event_loop", "")  # the event loop's variant, where there are several
    contenders = {"steplab": {"settings": f"steplab, {world.detector} detector, {loop} event loop".replace(" , ", ", "),
                              "max_impacts_per_step": world.max_impacts_per_step,
                              **_speed(t["steplab"], steps, dt),
                              "balls_inside": balls_inside(finals["steplab"].y[-1][0], side),
                              **log.summary()}}
    solver = finals["steplab_solver"].collisions
    contenders["steplab_solver"] = {
        "settings": f"steplab, contact solver, {solver_world.solver.describe()}",
        **_speed(t["steplab_solver"], steps, dt),
        "balls_inside": balls_inside(finals["steplab_solver"].y[-1][0], side),
        "median_distance_to_steplab": float(np.median(np.linalg.norm(
            finals["steplab_solver"].y[-1][0] - finals["steplab"].y[-1][0], axis=1))), **solver.summary()}
    record.compare(f"solver_vs_event_loop_{label}", "collisions", solver_what, "steplab's event loop",
                   t["steplab_solver"], t["steplab"], None,
                   steplab_real_time_factor=contenders["steplab_solver"]["real_time_factor"],
                   peer_real_time_factor=contenders["steplab"]["real_time_factor"])
    q = finals["steplab"].y[-1][0]
    for engine in engines:
        # bodies in free flight move alike in every engine (each steps semi-implicit Euler)
        distance = np.linalg.norm(finals[engine.name] - q, axis=1)
        contenders[engine.name] = {"settings": engine.settings, **_speed(t[engine.name], steps, dt),
                                   "balls_inside": balls_inside(finals[engine.name], side),
                                   "median_distance_to_steplab": float(np.median(distance))}
    record.data["collisions"][label] = {
        "what": what, "balls": balls, "steps": steps, "dt": dt, "simulated_seconds": simulated, "box_side": side,
        "setup_seconds": setup, "contenders": contenders, "not_compared": not_compared}
    for engine in engines:
        record.compare(f"vs_{engine.name}_{label}", "collisions", event_what, engine.settings, t["steplab"],
                       t[engine.name], None, steplab_real_time_factor=contenders["steplab"]["real_time_factor"],
                       peer_real_time_factor=contenders[engine.name]["real_time_factor"])
        name = f"solver_vs_{engine.name}_{label}"
        record.compare(name, "collisions", solver_what, engine.settings, t["steplab_solver"], t[engine.name], None,
                       steplab_real_time_factor=contenders["steplab_solver"]["real_time_factor"],
                       peer_real_time_factor=contenders[engine.name]["real_time_factor"])
        if (engine.name, balls) in SOLVER_ENGINE_TARGETS:
            target, ratio = SOLVER_ENGINE_TARGETS[(engine.name, balls)], record.data["ratios"][name]
            record.data["targets"][name] = {"target": target, "ratio": ratio, "met": ratio <= target}
    for name, targets, key in (("steplab", REAL_TIME_TARGETS, f"real_time_{label}"),
                               ("steplab_solver", SOLVER_REAL_TIME_TARGETS, f"solver_real_time_{label}")):
        if balls in targets:
            # a target on the wall time per simulated second, so that "met" reads as every
            # other target's, value <= target: at least x times real time is at most 1/x s
            factor, seconds = targets[balls], t[name].median / simulated
            record.data["targets"][key] = {
                "target": 1.0 / factor, "seconds": seconds, "met": seconds <= 1.0 / factor,
                "real_time_target": factor, "real_time_factor": contenders[name]["real_time_factor"],
                "what": f"wall seconds per simulated second, {contenders[name]['settings']}"}


def _speed(times, steps: int, dt: float) -> dict:
    """Wall times of a run of ``steps`` steps, per step, and simulated seconds per wall second."""
    return {"wall_seconds": times.median, "wall_seconds_min": times.minimum, "rounds": times.rounds,
            "per_step_seconds": times.median / steps, "real_time_factor": steps * dt / times.median}
