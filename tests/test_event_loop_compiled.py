"""The incremental event loop's compiled step against its Python loop, bit for bit.

The compiled step (:mod:`steplab.physics.collision.compiled_loop`, ``compiled_loop=True``,
the default) and the Python loop (``compiled_loop=False``) must log the same collisions and
give the same trajectories, to the last bit: the same kernels in the same order.
"""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import INTEGRATORS, simulate
from steplab.physics import Gravity, Model
from steplab.physics.ball_pit import ball_pit
from steplab.physics.collision import CollisionWorld, ImpactCapError, PairProperties, Plane
from steplab.physics.collision.events import remove_on_impact
from steplab.physics.collision.response import DEFAULT_MATERIAL
from steplab.physics.scene import load_scene
from test_event_loop import balls_in_room, room

SIE = INTEGRATORS["semi-implicit-euler"]


def both_loops(model, y0, world, steps, dt=1 / 60, integrator="semi-implicit-euler"):
    """The run through the compiled step and through the Python loop (each asserted to be taken)."""
    runs = []
    for compiled in (True, False):
        w = dataclasses.replace(world, event_loop="incremental", compiled_loop=compiled)
        runs.append(simulate(model, integrator, y0, 0.0, dt=dt, n_steps=steps, collisions=w))
    return runs


def assert_same_bits(compiled, python):
    assert np.array_equal(compiled.y, python.y)
    assert compiled.collisions.summary() == python.collisions.summary()
    assert compiled.collisions.to_csv() == python.collisions.to_csv()
    assert [(e.friction, e.trigger, e.body, e.other) for e in compiled.collisions.events] == \
        [(e.friction, e.trigger, e.body, e.other) for e in python.collisions.events]


def test_the_compiled_step_is_taken_where_it_applies_and_only_there():
    n = 6
    model = Model(np.ones(n), np.full(n, 0.1), [Gravity()])
    world = CollisionWorld("swept", room(0.8), event_loop="incremental")
    assert world.stepper(model, SIE).compiled_loop
    assert not dataclasses.replace(world, compiled_loop=False).stepper(model, SIE).compiled_loop
    assert not world.stepper(model, INTEGRATORS["velocity-verlet"]).compiled_loop  # not linear along the chord
    assert not dataclasses.replace(world, detector="overlap").stepper(model, SIE).compiled_loop
    assert not dataclasses.replace(world, epilogues=(remove_on_impact("floor"),)).stepper(model, SIE).compiled_loop
    trigger = (*room(0.8), Plane(np.array([0.0, 0.0, 1.0]), 0.5, "sensor", trigger=True))
    assert not dataclasses.replace(world, shapes=trigger).stepper(model, SIE).compiled_loop


#: the built-in scenes the compiled step runs, and the steps compared: past the first bounces
SCENE_STEPS = {"billiards": 400, "drop": 600, "n-balls": 200}


@pytest.mark.parametrize("name", sorted(SCENE_STEPS))
def test_the_built_in_collision_scenes_give_the_python_loops_bits(name):
    scene = load_scene(name)
    assert scene.collisions.stepper(scene.model, INTEGRATORS[scene.integrator]).compiled_loop
    steps = SCENE_STEPS[name]
    compiled, python = both_loops(scene.model, scene.y0, scene.collisions, steps, scene.dt, scene.integrator)
    assert compiled.collisions.count() > 0
    assert_same_bits(compiled, python)


@settings(max_examples=5, deadline=None)
@given(n=st.integers(5, 25), seed=st.integers(0, 2**16), speed=st.sampled_from([0.5, 3.0, 10.0]),
       eps=st.sampled_from([0.3, 0.9, 1.0]), friction=st.sampled_from([0.0, 0.4]), half=st.sampled_from([0.6, 1.0]))
def test_random_rooms_give_the_python_loops_bits(n, seed, speed, eps, friction, half):
    # materials: the floor is "rubber", every third ball "steel", each pair its own eps and mu
    y0 = balls_in_room(n, half, seed, speed)
    model = Model(np.ones(n) + np.arange(n) % 2, np.full(n, 0.1), [Gravity()])
    shapes = (dataclasses.replace(room(half)[0], material="rubber"), *room(half)[1:])
    table = {frozenset(("rubber", DEFAULT_MATERIAL)): (0.5 * eps, friction), frozenset(("steel",)): (1.0, 0.0)}
    materials = tuple("steel" if b % 3 == 0 else DEFAULT_MATERIAL for b in range(n))
    world = CollisionWorld("swept", shapes, materials, PairProperties(eps, friction, table))
    compiled, python = both_loops(model, y0, world, 25)
    assert compiled.collisions.count() > 0
    assert_same_bits(compiled, python)


@pytest.mark.parametrize("balls, side, steps", [(100, 0.9, 25),
                                                pytest.param(300, 1.6, 40, marks=pytest.mark.slow)])
def test_a_crowded_pit_gives_the_python_loops_bits(balls, side, steps):
    # balls dropped into a small box pile up and come to rest: hundreds of impacts in a step
    scene = ball_pit(balls, seed=7, side=side)
    compiled, python = both_loops(scene.model, scene.y0, scene.collisions, steps)
    assert compiled.collisions.most_impacts_in_a_step > balls
    assert_same_bits(compiled, python)


def test_no_impact_is_lost_when_a_step_holds_ten_times_the_default_cap_and_the_log_grows():
    # 1,200 balls side by side, 1 mm above the floor at 1 m/s, no force: 1,200 impacts in the first
    # step, ten times a cap of 120 and more than the compiled log's first rows (it grows by doubling)
    n, gap, v = 1200, 1e-3, 1.0
    y0 = np.zeros((2, n, 3))
    y0[0, :, 0], y0[0, :, 2], y0[1, :, 2] = 0.5 * np.arange(n), 0.1 + gap, -v
    model = Model(np.ones(n), np.full(n, 0.1))
    world = CollisionWorld("swept", (Plane(np.array([0.0, 0.0, 1.0]), 0.0, "floor"),), max_impacts_per_step=n // 10)
    step = world.stepper(model, SIE)
    assert step.compiled_loop and len(step._logged) < n
    with pytest.raises(ImpactCapError) as err:
        simulate(model, "semi-implicit-euler", y0, 0.0, dt=0.01, n_steps=3, collisions=world)
    assert (err.value.t, err.value.impacts, err.value.cap) == (0.0, n // 10, n // 10)
    compiled, python = both_loops(model, y0, dataclasses.replace(world, max_impacts_per_step=None), 3, dt=0.01)
    log = compiled.collisions
    assert log.count() == n and sorted(e.body for e in log.events) == list(range(n))
    assert all(e.t == pytest.approx(gap / v, rel=1e-9) and e.impact_speed == pytest.approx(v) for e in log.events)
    np.testing.assert_allclose(compiled.velocities[-1, :, 2], v)  # eps = 1: each rises at 1 m/s
    assert_same_bits(compiled, python)


def test_a_killed_run_leaves_whole_collision_logs(tmp_path):
    # steplab run killed at random moments: its collision log is either absent or whole
    # (written atomically), and then the same bytes as an uninterrupted run's
    out = tmp_path / "clean.npz"
    command = [sys.executable, "-c", "import sys; from steplab.cli import main; sys.exit(main())", "run", "n-balls",
               "--t-end", "1.0"]
    subprocess.run([*command, "--out", str(out)], check=True, capture_output=True)
    clean = out.with_name("clean.collisions.csv").read_bytes()
    assert clean.count(b"\n") > 10
    rng = np.random.default_rng(3)
    for k in range(1):
        target = tmp_path / f"killed{k}.npz"
        process = subprocess.Popen([*command, "--out", str(target)], stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(0.5, 3.0)))
        os.kill(process.pid, signal.SIGKILL)
        process.wait()
        log = target.with_name(f"killed{k}.collisions.csv")
        assert not log.exists() or log.read_bytes() == clean


def test_the_bench_times_a_crowded_pit_beside_mujoco():
    from steplab.bench.collisions import crowded_pit
    from steplab.bench.config import QUICK
    from steplab.bench.record import Record

    pytest.importorskip("mujoco")
    config = dataclasses.replace(QUICK, crowded_pit=(60, 0.6, 4), collision_repeats=1)
    record = Record(config, quick=True)
    crowded_pit(config, record)
    pit = record.data["collisions"]["crowded_pit_60"]
    assert pit["impacts"] > 0 and pit["seconds_per_impact"] > 0
    assert set(pit["contenders"]) == {"steplab", "steplab_solver", "mujoco"}
    assert pit["contenders"]["steplab_solver"]["settings"].startswith("steplab, contact solver")
    assert record.data["ratios"]["vs_mujoco_crowded_pit_60"] > 0
    assert set(record.data["targets"]) >= {"crowded_pit_60_us_per_impact", "vs_mujoco_crowded_pit_60"}
