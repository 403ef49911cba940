"""The one timer of the studies and the bench: warm up, then interleaved rounds, then the median.

Compiled code is timed properly: the first call compiles (its time is the compile time,
:func:`first_call_seconds`), a warm-up call follows, and every timed call blocks until
its result exists (:func:`ready`, ``block_until_ready`` for JAX), so the clock stops
when the work is done, not when it is queued. Several contenders are called in turn,
round after round (:func:`interleaved_samples`), so a burst of load from elsewhere on
the machine hits all of them alike; each one's median is its time.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np


def ready(x):
    """``x`` once every JAX array in it is computed (``jax.block_until_ready``)."""
    import jax

    return jax.block_until_ready(x)


def first_call_seconds(call: Callable[[], object]) -> float:
    """Seconds of the first call of a compiled function: its compilation and one run."""
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def interleaved_samples(calls: dict[object, Callable[[], object]], repeats: int,
                        warm_up: bool = True) -> dict[object, list[float]]:
    """Wall times of each call: one warm-up call each, then ``repeats`` rounds in turn.

    Every call must block until its result exists (:func:`ready` for JAX). ``warm_up=False``
    leaves out the warm-up calls, for calls too long to make twice that the caller has
    warmed up on a smaller case (a collision run compiled on one step).
    """
    if warm_up:
        for call in calls.values():
            call()
    samples = {name: [] for name in calls}
    for _ in range(repeats):
        for name, call in calls.items():
            start = time.perf_counter()
            call()
            samples[name].append(time.perf_counter() - start)
    return samples


@dataclasses.dataclass(frozen=True)
class Times:
    """Seconds of one contender over the interleaved rounds: the median, the minimum and the maximum.

    On a shared machine a call the scheduler preempts loses whole time slices (4 ms at
    250 Hz), so times cluster at the true cost plus multiples of the slice. The median is
    the headline; the minimum is the least-disturbed round.
    """

    median: float
    minimum: float
    rounds: int
    #: the slowest round (None where the rounds were not kept)
    maximum: float | None = None

    @classmethod
    def of(cls, samples) -> Times:
        return cls(float(np.median(samples)), float(np.min(samples)), len(samples), float(np.max(samples)))

    @classmethod
    def exactly(cls, seconds: float) -> Times:
        return cls(seconds, seconds, 1, seconds)


def interleaved_times(calls: dict[object, Callable[[], object]], repeats: int,
                      warm_up: bool = True) -> dict[object, Times]:
    """:class:`Times` of each call, the calls interleaved (see :func:`interleaved_samples`)."""
    return {name: Times.of(s) for name, s in interleaved_samples(calls, repeats, warm_up).items()}


def interleaved_medians(calls: dict[object, Callable[[], object]], repeats: int) -> dict[object, float]:
    """Median wall time of each call, the calls interleaved (see :func:`interleaved_samples`)."""
    return {name: t.median for name, t in interleaved_times(calls, repeats).items()}


def median_time(call: Callable[[], object], repeats: int) -> float:
    """Median wall time of one warmed-up call that blocks until its result is ready."""
    return interleaved_medians({"call": call}, repeats)["call"]
