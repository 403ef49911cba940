"""Frame-rate independence: fixed physics steps consuming variable frame times."""

from __future__ import annotations

import hashlib
from fractions import Fraction

import numpy as np
import pytest
from helpers import soft_tetrahedron
from numpy.testing import assert_allclose
from steplab.integrators import INTEGRATORS, GameLoop
from steplab.integrators.game_loop import interpolate
from steplab.physics import Model

DT = 2.0**-6  # 15.625 ms, a binary fraction: multiples of it are exact in floating point


class Physics:
    """A deterministic physics state advanced one fixed step per ``step()`` call, recording
    a hash of the state bytes after every step."""

    def __init__(self, dt=DT, integrator="semi-implicit-euler"):
        forces, self.y, masses = soft_tetrahedron(stiffness=80.0, damping=0.3)
        self.model = Model(masses, np.full(4, 0.05), forces)
        self.method = INTEGRATORS[integrator]
        self.carry = self.method.init(self.model, 0.0, self.y)
        self.dt, self.t = dt, 0.0
        self.hashes = [self.digest()]

    def digest(self):
        return hashlib.sha256(np.ascontiguousarray(self.y).tobytes()).hexdigest()

    def step(self):
        self.y, self.carry = self.method.step(self.model, self.t, self.y, self.dt, self.carry)
        self.t += self.dt
        self.hashes.append(self.digest())


def run_frames(frames, dt=DT, **kw):
    physics = Physics(dt)
    loop = GameLoop(physics.step, dt, **kw)
    alphas = [loop.advance(f) for f in frames]
    return loop, physics, alphas


def test_fixed_steps_from_variable_frames():
    frames = [0.5 * DT, 2.25 * DT, 0.0, 3 * DT, 0.25 * DT]
    loop, physics, alphas = run_frames(frames)
    # time owed after each frame: 0.5, 2.75 -> 0.75, 0.75, 3.75 -> 0.75, 1.0 -> 0
    assert loop.steps == 6 == len(physics.hashes) - 1
    assert alphas == [0.5, 0.75, 0.75, 0.75, 0.0]


def test_remainder_carries_over():
    count = []
    loop = GameLoop(lambda: count.append(1), DT)
    assert loop.advance(0.6 * DT) == pytest.approx(0.6)
    assert loop.steps == 0
    assert loop.advance(0.6 * DT) == pytest.approx(0.2)  # 1.2 dt owed: one step, 0.2 left
    assert loop.steps == 1 == len(count)


def test_alpha_in_unit_interval_and_exact(rng):
    loop = GameLoop(lambda: None, 0.02)
    total = Fraction(0)
    for frame in rng.uniform(0.0, 0.07, size=300):
        alpha = loop.advance(float(frame))
        total += Fraction(float(frame))
        assert 0.0 <= alpha < 1.0
        owed = total - loop.steps * Fraction(0.02)
        assert loop.steps == total // Fraction(0.02)  # every whole step owed was taken
        assert alpha == float(owed / Fraction(0.02))


def dyadic_frames(rng, total_units, unit=2.0**-10):
    """Random frame times, multiples of ``unit``, summing exactly to total_units * unit."""
    cuts = np.sort(rng.choice(np.arange(1, total_units), size=total_units // 20, replace=False))
    sizes = np.diff(np.concatenate([[0], cuts, [total_units]]))
    return [float(s) * unit for s in sizes]


def irregular_split(frames, rng):
    """Split every frame time c into x and c - x with x uniform in [c/2, c]: irregular
    floats whose pairwise sums are exact (Sterbenz), so the exact total is unchanged."""
    out = []
    for c in frames:
        x = float(rng.uniform(c / 2, c))
        assert Fraction(x) + Fraction(c - x) == Fraction(c)
        out += [x, c - x]
    return out


def test_same_total_gives_same_steps_and_bit_identical_states(rng):
    total_units = 2048  # 2 s in units of 2^-10 s: 128 steps of 2^-6 s
    a = dyadic_frames(rng, total_units)
    b = dyadic_frames(rng, total_units)
    c = irregular_split(b, rng)
    assert a != b and len(c) == 2 * len(b)
    assert sum(map(Fraction, a)) == sum(map(Fraction, b)) == sum(map(Fraction, c)) == 2

    runs = [run_frames(frames) for frames in (a, b, c)]
    for loop, _, alphas in runs:
        assert loop.steps == 128
        assert alphas[-1] == 0.0
    hashes = [physics.hashes for _, physics, _ in runs]
    assert hashes[0] == hashes[1] == hashes[2]
    assert len(set(hashes[0])) == len(hashes[0])  # the state really changes every step


def test_common_step_counts_agree_for_different_totals(rng):
    """Different totals: every state reached by both runs is bit-identical."""
    short = run_frames(dyadic_frames(rng, 1000))[1].hashes
    long = run_frames(irregular_split(dyadic_frames(rng, 1900), rng))[1].hashes
    assert len(short) < len(long)
    assert long[: len(short)] == short


def test_float_accumulator_loses_owed_steps():
    """The control for exact bookkeeping: a float lag accumulator (even with ``>=``)
    rounds away a step that is owed, and GameLoop does not."""
    dt = 0.02

    def float_loop(frames):
        lag, steps = 0.0, 0
        for f in frames:
            lag += f
            while lag >= dt:
                lag -= dt
                steps += 1
        return steps

    frames = [0.1] * 10
    owed = sum(map(Fraction, frames)) // Fraction(dt)
    assert owed == 50  # the binary 0.1 holds five binary 0.02 (with room to spare)
    assert float_loop(frames) < owed
    loop = GameLoop(lambda: None, dt)
    assert [loop.advance(f) < 1 for f in frames] == [True] * 10
    assert loop.steps == owed


def test_max_steps_per_frame_drops_the_excess():
    count = []
    loop = GameLoop(lambda: count.append(1), DT, max_steps_per_frame=3)
    alpha = loop.advance(10.5 * DT)
    assert loop.steps == 3 == len(count)
    assert loop.dropped == 7 * Fraction(DT)  # whole steps dropped, the fraction kept
    assert alpha == 0.5
    assert loop.advance(DT) == 0.5 and loop.steps == 4


def test_invalid_arguments():
    for dt in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError):
            GameLoop(lambda: None, dt)
    loop = GameLoop(lambda: None, DT)
    for frame in (-DT, float("nan")):
        with pytest.raises(ValueError):
            loop.advance(frame)
    assert loop.steps == 0


def lecture_loop(frame_times, delta_t, step):
    """The lecture's frame-rate-independence loop, transcribed (``lag > delta_t``)."""
    physics_lag_time = 0.0
    for frame_time in frame_times:
        physics_lag_time += frame_time
        while physics_lag_time > delta_t:
            step()
            physics_lag_time -= delta_t


def test_lecture_loop_skips_a_step_on_exact_frame_times_ours_does_not():
    frames = [DT] * 10  # one step's worth of time per frame, exactly
    lecture_steps, ours_steps = [], []
    lecture_loop(frames, DT, lambda: lecture_steps.append(1))
    loop = GameLoop(lambda: ours_steps.append(1), DT)
    per_frame = []
    for f in frames:
        before = loop.steps
        loop.advance(f)
        per_frame.append(loop.steps - before)
    assert len(lecture_steps) == 9  # lag == dt is not > dt: a frame behind
    assert len(ours_steps) == 10 and per_frame == [1] * 10


def test_interpolate():
    previous, current = np.array([0.0, 2.0]), np.array([4.0, 6.0])
    assert_allclose(interpolate(previous, current, 0.0), previous)
    assert_allclose(interpolate(previous, current, 0.25), [1.0, 3.0])
