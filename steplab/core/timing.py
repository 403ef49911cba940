"""The one timer of the studies and the bench: warm up, then interleaved rounds, then the median.

Compiled code is timed properly: the first call compiles (its time is the compile time,
:func:`first_call_seconds`), a warm-up call follows, and every timed call blocks until
its result exists (:func:`ready`, ``block_until_ready`` for JAX), so the clock stops
when the work is done, not when it is queued. Several contenders are called in turn,
round after round (:func:`interleaved_samples`), so a burst of load from elsewhere on
the machine hits all of them alike; each one's median is its time.

Each call's CPU time is measured beside its wall time (:class:`Samples`): the CPU seconds
of this process's threads and of the child processes it waited for. On a machine others
load, a call loses wall time whenever the scheduler runs someone else, but not CPU time;
so where a contender runs on one thread (``steplab bench`` pins every side to one), its
CPU time is what its wall time would be on an idle core, and a ratio of CPU times hardly
moves with the load. The same calls' minor page faults and involuntary context switches
(preemptions) are kept too, to say why a time moves.
"""

from __future__ import annotations

import dataclasses
import os
import resource
import threading
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


class Samples(list):
    """Wall seconds per call of one contender's rounds (the list itself), with the same rounds'
    CPU seconds per call (``cpu``), minor page faults and involuntary context switches per call
    (``faults``, ``preempted``), and the calls made back to back in each round (``number``)."""

    def __init__(self, wall=(), cpu=(), faults=(), preempted=(), number: int = 1):
        super().__init__(wall)
        self.cpu, self.faults, self.preempted, self.number = list(cpu), list(faults), list(preempted), number

    def __iadd__(self, other):
        super().__iadd__(other)
        for name in ("cpu", "faults", "preempted"):
            getattr(self, name).extend(getattr(other, name, ()))
        return self


def cpu_seconds() -> float:
    """CPU seconds so far of this process's threads (``process_time``, the kernel's exact
    accounting) and of the child processes it has waited for."""
    return time.process_time() + _children_seconds()


def _children_seconds() -> float:
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


def _events() -> tuple[int, int]:
    """Minor page faults and involuntary context switches so far, this process's and its children's."""
    mine, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return mine.ru_minflt + children.ru_minflt, mine.ru_nivcsw + children.ru_nivcsw


def _others_idle(limit: float = 0.2, poll: float = 2e-4) -> None:
    """Return once no other thread of this process is running or waiting to run (or after ``limit`` s).

    JAX runs a compiled call on a worker thread, and after ``block_until_ready`` returns that
    thread may go on for milliseconds (releasing the call's buffers: up to 7 ms after a call
    on 10^6 particles, measured), which would otherwise land in the next contender's CPU
    time. The threads' states come from /proc (a preempted thread is still runnable there);
    without /proc, the others' CPU time standing still over one poll stands in.
    """
    deadline = time.perf_counter() + limit
    others = time.process_time() - time.thread_time()
    while time.perf_counter() < deadline:
        running = _others_running()
        if running is False:
            return
        time.sleep(poll)
        if running is None:
            now = time.process_time() - time.thread_time()
            if now - others < 0.1 * poll:
                return
            others = now


def _others_running() -> bool | None:
    """Whether another thread of this process is running or runnable (state R); None without /proc."""
    me = threading.get_native_id()
    try:
        for task in os.scandir("/proc/self/task"):
            if task.name != str(me):
                with open(os.path.join(task.path, "stat"), "rb") as f:
                    stat = f.read()
                if stat[stat.rindex(b")") + 2:stat.rindex(b")") + 3] == b"R":
                    return True
    except (OSError, ValueError):
        return None
    return False


def timed_call(call: Callable[[], object], samples: Samples) -> None:
    """Make ``samples.number`` calls back to back, appending the wall and CPU seconds per call,
    page faults and preemptions to ``samples``.

    Both clocks run from the first call to the last return, once the process's other threads
    are idle (:func:`_others_idle`): so the CPU seconds are those of this thread, of the threads
    it set to work (JAX's) and of the child processes it waited for, during the calls, as its
    wall seconds are. Work a thread goes on with after a call returns (JAX releasing buffers)
    is counted for no one, as it is not in the wall time either: on an idle machine it runs
    beside the next call.
    """
    _others_idle()
    faults, preempted = _events()
    cpu = cpu_seconds()
    start = time.perf_counter()
    for _ in range(samples.number):
        call()
    wall = time.perf_counter() - start
    cpu_after = cpu_seconds()
    faults_after, preempted_after = _events()
    samples.append(wall / samples.number)
    samples.cpu.append((cpu_after - cpu) / samples.number)
    samples.faults.append((faults_after - faults) / samples.number)
    samples.preempted.append((preempted_after - preempted) / samples.number)


def interleaved_samples(calls: dict[object, Callable[[], object]], repeats: int, warm_up: bool = True,
                        numbers: dict[object, int] | None = None) -> dict[object, Samples]:
    """Wall (and CPU) times of each call: one warm-up call each, then ``repeats`` rounds in turn.

    Every call must block until its result exists (:func:`ready` for JAX). A call whose
    warm-up took less than SAMPLE_SECONDS is made ``number`` times back to back in each
    round (:func:`calls_per_sample`), and its sample is the mean: a 30 µs compiled call
    timed alone carries the timer's own cost and a cold start after the other contenders
    (44 µs median against 30 µs back to back, at load 9). ``numbers`` fixes them
    (as later rounds of the same contenders must; each :class:`Samples` keeps its
    ``number``). ``warm_up=False`` leaves out the warm-up calls, for calls too long to make
    twice that the caller has warmed up on a smaller case (a collision run compiled on one
    step): one call per sample.
    """
    numbers = dict(numbers or {})
    for name, call in calls.items():
        if warm_up:
            start = time.perf_counter()
            call()
            numbers.setdefault(name, calls_per_sample(time.perf_counter() - start))
    samples = {name: Samples(number=numbers.get(name, 1)) for name in calls}
    for _ in range(repeats):
        for name, call in calls.items():
            timed_call(call, samples[name])
    return samples


#: calls shorter than this are made several times per sample (:func:`interleaved_samples`), s
SAMPLE_SECONDS = 1e-3


def calls_per_sample(seconds: float) -> int:
    """Back-to-back calls per sample of a call that took ``seconds``: enough to fill SAMPLE_SECONDS, at most 1000."""
    return int(min(max(np.ceil(SAMPLE_SECONDS / max(seconds, 1e-6)), 1), 1000))


def threads_used(*samples: Samples) -> float:
    """The largest CPU seconds per wall second of any round: at most about 1 on one thread,
    whatever the load (a preempted call loses wall and CPU time alike, or only CPU time),
    and about n on n busy threads in any round the scheduler left them alone."""
    return max(float(np.max(np.divide(s.cpu, np.maximum(s, 1e-9)))) for s in samples)


@dataclasses.dataclass(frozen=True)
class Times:
    """Seconds of one contender over the interleaved rounds: the median, the minimum and the maximum.

    On a shared machine a call the scheduler preempts loses whole time slices (4 ms at
    250 Hz), so times cluster at the true cost plus multiples of the slice. The median is
    the headline; the minimum is the least-disturbed round. Where the rounds were
    :class:`Samples`, ``cpu`` holds the same of their CPU seconds, and ``faults`` and
    ``preempted`` the median minor page faults and involuntary context switches per call.
    """

    median: float
    minimum: float
    rounds: int
    #: the slowest round (None where the rounds were not kept)
    maximum: float | None = None
    cpu: Times | None = None
    faults: float | None = None
    preempted: float | None = None
    #: the largest CPU seconds per wall second of a round (:func:`threads_used`)
    threads: float | None = None

    @classmethod
    def of(cls, samples) -> Times:
        cpu, faults, preempted, threads = None, None, None, None
        if getattr(samples, "cpu", None):
            cpu = cls.of(samples.cpu)
            faults, preempted = float(np.median(samples.faults)), float(np.median(samples.preempted))
            threads = threads_used(samples)
        return cls(float(np.median(samples)), float(np.min(samples)), len(samples), float(np.max(samples)),
                   cpu, faults, preempted, threads)

    def scaled(self, factor: float) -> Times:
        """The same times (and page faults) times ``factor``: a call's as per step, say."""
        return dataclasses.replace(
            self, median=self.median * factor, minimum=self.minimum * factor,
            maximum=None if self.maximum is None else self.maximum * factor,
            cpu=None if self.cpu is None else self.cpu.scaled(factor),
            faults=None if self.faults is None else self.faults * factor)


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
