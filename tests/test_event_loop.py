"""The incremental event loop against the full re-test, the impact cap, and a closed box that holds.

The full loop (``event_loop="full"``) re-integrates and re-tests the whole scene after
every collision; the incremental one re-tests only what the collision changed. Under
semi-implicit Euler and gravity they must give the same collision log, to round-off.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from steplab.integrators import INTEGRATORS, Stepper, simulate
from steplab.physics import Gravity, Model
from steplab.physics.collision import EVENT_LOOPS, CollisionWorld, ImpactCapError, PairProperties, Plane

X, Y, Z = np.eye(3)
FIXED_STEP = [name for name, m in INTEGRATORS.items() if isinstance(m, Stepper)]


def room(half: float):
    """A closed box: a floor, four walls at +-half and a ceiling at 2 half."""
    return (Plane(Z, 0.0, "floor"), Plane(X, -half, "wall -x"), Plane(-X, -half, "wall +x"),
            Plane(Y, -half, "wall -y"), Plane(-Y, -half, "wall +y"), Plane(-Z, -2 * half, "ceiling"))


def balls_in_room(n, half, seed, speed, radius=0.1):
    """``n`` balls of radius ``radius`` at random non-overlapping places in the room, random velocities."""
    rng = np.random.default_rng(seed)
    q = []
    while len(q) < n:
        p = rng.uniform([-half + radius, -half + radius, radius], [half - radius, half - radius, 2 * half - radius])
        if all(np.linalg.norm(p - o) > 2 * radius for o in q):
            q.append(p)
    v = rng.normal(size=(n, 3)) * speed
    return np.stack([np.array(q), v])


@settings(max_examples=10)
@given(n=st.integers(5, 30), seed=st.integers(0, 2**16), speed=st.sampled_from([0.5, 3.0]),
       eps=st.sampled_from([0.5, 0.9, 1.0]), detector=st.sampled_from(["swept", "overlap"]))
def test_incremental_loop_logs_the_same_collisions_as_the_full_retest(n, seed, speed, eps, detector):
    y0 = balls_in_room(n, 0.8, seed, speed)
    model = Model(np.ones(n), np.full(n, 0.1), [Gravity()])
    runs = {}
    for loop in EVENT_LOOPS:
        world = CollisionWorld(detector, room(0.8), pair_properties=PairProperties(eps), event_loop=loop)
        runs[loop] = simulate(model, "semi-implicit-euler", y0, 0.0, dt=1 / 60, n_steps=30, collisions=world)
    full, incremental = runs["full"].collisions, runs["incremental"].collisions
    assert full.count() > 0
    assert [(e.kind, e.body, e.other) for e in incremental.events] == [(e.kind, e.body, e.other) for e in full.events]
    times = np.array([[e.t, f.t] for e, f in zip(incremental.events, full.events)])
    speeds = np.array([[e.impact_speed, f.impact_speed] for e, f in zip(incremental.events, full.events)])
    assert np.abs(times[:, 0] - times[:, 1]).max() <= 1e-9
    assert np.abs(speeds[:, 0] - speeds[:, 1]).max() <= 1e-9 * max(1.0, np.abs(speeds).max())
    assert incremental.resting_corrections == full.resting_corrections
    # relative to the state's size, as the speeds: the loops round differently, and each impact between
    # balls multiplies a difference by about distance / radius (HYPOTHESIS_PROFILE=explore found 17 elastic
    # balls at 3 m/s whose states, equal to 2e-16 after one step, were 2.2e-9 apart after 30, speeds of 8 m/s)
    ys = runs["incremental"].y, runs["full"].y
    assert np.abs(ys[0] - ys[1]).max() <= 1e-9 * max(1.0, np.abs(ys[1]).max())


@pytest.mark.parametrize("event_loop", EVENT_LOOPS)
def test_no_impact_is_lost_in_a_step_holding_ten_times_the_cap(event_loop):
    # 100 balls side by side, 1 mm above the floor, falling at 1 m/s with no force: all hit it
    # at t = 1 ms, in the first step
    n, gap, v = 100, 1e-3, 1.0
    y0 = np.zeros((2, n, 3))
    y0[0, :, 0], y0[0, :, 2], y0[1, :, 2] = 0.5 * np.arange(n), 0.1 + gap, -v
    model = Model(np.ones(n), np.full(n, 0.1))
    world = CollisionWorld("swept", (Plane(Z, 0.0, "floor"),), max_impacts_per_step=n // 10, event_loop=event_loop)
    with pytest.raises(ImpactCapError) as err:
        simulate(model, "semi-implicit-euler", y0, 0.0, dt=0.01, n_steps=3, collisions=world)
    assert (err.value.t, err.value.impacts, err.value.cap) == (0.0, n // 10, n // 10)
    traj = simulate(model, "semi-implicit-euler", y0, 0.0, dt=0.01, n_steps=3,
                    collisions=dataclasses.replace(world, max_impacts_per_step=n))
    log = traj.collisions
    assert log.count() == n and sorted(e.body for e in log.events) == list(range(n))
    assert all(e.t == pytest.approx(gap / v, rel=1e-9) and e.impact_speed == pytest.approx(v) for e in log.events)
    # eps = 1: every ball rises again at 1 m/s and is back at its height after the 3 steps' 30 ms
    np.testing.assert_allclose(traj.velocities[-1, :, 2], v)
    np.testing.assert_allclose(traj.positions[-1, :, 2], 0.1 + v * (0.03 - gap / v), rtol=1e-12)


def _closed_box_holds(n, steps, half):
    y0 = balls_in_room(n, half, seed=n, speed=2.0)
    model = Model(np.ones(n), np.full(n, 0.1), [Gravity()])
    world = CollisionWorld("swept", room(half), pair_properties=PairProperties(0.8))
    traj = simulate(model, "semi-implicit-euler", y0, 0.0, dt=1 / 60, n_steps=steps, save_every=10, collisions=world)
    q = traj.positions
    slack = 1e-9  # the contact slop: touching within a few hundred rounding errors
    assert traj.collisions.count() > n
    assert np.all(np.abs(q[..., :2]) <= half - 0.1 + slack)
    assert np.all((q[..., 2] >= 0.1 - slack) & (q[..., 2] <= 2 * half - 0.1 + slack))


def test_a_closed_box_keeps_every_ball_inside():
    _closed_box_holds(200, 300, 2.5)


@pytest.mark.slow
def test_a_closed_box_of_a_thousand_balls_keeps_every_ball_inside_for_a_thousand_steps():
    _closed_box_holds(1000, 1000, 4.0)


@pytest.mark.parametrize("name", FIXED_STEP)
def test_auto_runs_the_incremental_loop_exactly_where_it_agrees_with_the_full_one(name):
    """Under a constant force, a step from a point of the chord lands on the step's end only for
    methods linear along the step (semi-implicit Euler); 'auto' picks the incremental loop there."""
    n = 12
    y0 = balls_in_room(n, 0.6, seed=3, speed=2.0)
    model = Model(np.ones(n), np.full(n, 0.1), [Gravity()])
    world = CollisionWorld("swept", room(0.6), pair_properties=PairProperties(0.9))
    step = world.stepper(model, INTEGRATORS[name])
    assert step.event_loop == ("incremental" if name == "semi-implicit-euler" else "full")
    runs = [simulate(model, name, y0, 0.0, dt=1 / 60, n_steps=20,
                     collisions=dataclasses.replace(world, event_loop=loop)) for loop in ("auto", "full")]
    if step.event_loop == "full":
        assert np.array_equal(runs[0].y, runs[1].y)
    else:
        assert [e.t for e in runs[0].collisions.events] == pytest.approx([e.t for e in runs[1].collisions.events],
                                                                         abs=1e-9)
        assert np.abs(runs[0].y - runs[1].y).max() <= 1e-9


def test_the_compiled_retest_gives_the_numpy_numbers_bit_for_bit():
    n = 25
    y0 = balls_in_room(n, 0.8, seed=1, speed=3.0)
    model = Model(np.ones(n), np.full(n, 0.1), [Gravity()])
    world = CollisionWorld("swept", room(0.8), pair_properties=PairProperties(0.9), event_loop="incremental")
    runs = []
    for compiled in (True, False):
        step = world.stepper(model, INTEGRATORS["semi-implicit-euler"])
        assert step.compiled_retest
        step.compiled_retest = compiled
        runs.append(simulate(model, "semi-implicit-euler", y0, 0.0, dt=1 / 60, n_steps=40,
                             stepper=lambda m, i, step=step: step))
    assert runs[0].collisions.count() > 50
    assert np.array_equal(runs[0].y, runs[1].y)
    assert [e.as_row() for e in runs[0].collisions.events] == [e.as_row() for e in runs[1].collisions.events]


@settings(max_examples=30)
@given(seed=st.integers(0, 2**16), eps=st.floats(0, 1), friction=st.sampled_from([0.0, 0.3, 5.0]),
       static=st.booleans())
def test_the_compiled_response_moves_apart_and_applies_equation_4(seed, eps, friction, static):
    # resolve_pair (what the event loop calls; response.resolve runs it pair by pair) against
    # the lecture's collision step written out here: apart by depth in proportion to 1/m,
    # then Lambda = -(1 + eps) v_n / (1/m_i + 1/m_j) n with Coulomb friction on the slide
    from steplab.physics.collision.compiled_response import no_spin, resolve_pair

    rng = np.random.default_rng(seed)
    y, inverse_masses = rng.normal(size=(2, 3, 3)), rng.uniform(0.1, 2, 3)
    normal, depth = rng.normal(size=3), float(rng.uniform(-0.01, 0.01))
    normal /= np.linalg.norm(normal)
    j = -1 if static else 2
    w_i, w_j = inverse_masses[0], 0.0 if static else inverse_masses[2]
    v_rel = y[1, 0] - (0.0 if static else y[1, 2])
    v_n = v_rel @ normal
    lam_s = -(1 + eps) * v_n / (w_i + w_j) if v_n > 0 else 0.0
    v_t = v_rel - v_n * normal
    slide = min(np.linalg.norm(v_t) / (w_i + w_j), friction * abs(lam_s)) if v_n > 0 else 0.0
    expected = lam_s * normal - slide * v_t / np.linalg.norm(v_t)
    push = max(depth, 0.0) / (w_i + w_j)
    y_expected = y.copy()
    y_expected[0, 0] -= push * w_i * normal
    y_expected[1, 0] += expected * w_i
    if not static:
        y_expected[0, 2] += push * w_j * normal
        y_expected[1, 2] -= expected * w_j
    lam = resolve_pair(y, (0, j), inverse_masses, normal, depth, (eps, friction), no_spin())
    np.testing.assert_allclose(lam, expected, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(y, y_expected, rtol=1e-12, atol=1e-14)
