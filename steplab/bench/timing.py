"""The bench's timing discipline: one thread per side, then rounds until the minimums settle.

Why (issue 27; docs/performance.md has the measurements): on a shared two-core machine XLA
ran its large loops on two threads against single-threaded NumPy, Numba and scipy, so a
ratio depended on whether the other core happened to be free; and a fixed handful of
rounds left the minimum of a noisy side to chance. So:

- :func:`pin_threads` gives every side one thread (XLA's Eigen pool and intra-op
  parallelism, Numba's threading layer, the BLAS), before JAX or Numba is imported;
  :func:`thread_settings` says what the process actually runs with.
- :func:`settled_samples` runs interleaved rounds (:func:`steplab.core.timing.interleaved_samples`)
  until no contender's minimum has dropped by more than SETTLED for PATIENCE rounds,
  within a budget of rounds and seconds.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Callable

import numpy as np

from steplab.core.timing import Times, interleaved_samples, threads_used

#: one thread everywhere: the memory bound, Numba and scipy are single-threaded, so XLA is too
PINNED_ENVIRONMENT = {
    "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1",
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}
#: a minimum has settled when PATIENCE more rounds lower it by at most this fraction
SETTLED = 0.02
PATIENCE = 3


def pin_threads() -> bool:
    """Set :data:`PINNED_ENVIRONMENT` for this process; False, changing nothing, if JAX or Numba came first.

    XLA reads its flags when its CPU backend starts and Numba its thread count at import
    (and refuses a new count once its threads run), so the pinning acts only before those
    imports (``steplab bench`` calls this first). Flags already in ``XLA_FLAGS`` are kept,
    the pinning ones appended.
    """
    if {"jax", "numba"} & set(sys.modules):
        return False
    one_core()
    for name, value in PINNED_ENVIRONMENT.items():
        if name == "XLA_FLAGS":
            current = os.environ.get(name, "")
            missing = [flag for flag in value.split() if flag not in current.split()]
            os.environ[name] = " ".join([current, *missing]).strip()
        else:
            os.environ[name] = value
    return True


def one_core() -> None:
    """Run this process (and the processes it starts) on one core, where the OS allows it.

    The flags alone do not keep XLA on one thread: on a quiet machine steplab's compiled
    loop over 10^6 particles, the cloth and 10^5 tumbling bodies spent 1.97 to 1.99 CPU
    seconds per wall second with them set (three quick runs at load 1.4 to 3.4), a two-core
    time against a one-core bound, while on a loaded machine the second thread rarely ran:
    the ratio moved with the load. On one core every thread of a side shares it, and XLA,
    seeing one core, starts one worker.
    """
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})


def thread_settings() -> dict:
    """The thread settings in effect: the environment, Numba's thread count, XLA's flags."""
    settings = {name: os.environ.get(name) for name in PINNED_ENVIRONMENT}
    if "numba" in sys.modules:
        import numba

        settings["numba_threads"] = int(numba.get_num_threads())
    settings["cores"] = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    settings["pinned"] = all(flag in (settings["XLA_FLAGS"] or "").split()
                             for flag in PINNED_ENVIRONMENT["XLA_FLAGS"].split()) and all(
        settings[name] == value for name, value in PINNED_ENVIRONMENT.items() if name != "XLA_FLAGS")
    return settings


def settled_samples(calls: dict[object, Callable[[], object]], min_rounds: int, max_rounds: int,
                    budget_seconds: float) -> dict[object, list[float]]:
    """Wall times of each call over interleaved rounds, until every contender's minimum settles.

    At least ``min_rounds`` rounds (after one warm-up call each); then one round at a
    time until the minimum of every contender has dropped by at most SETTLED over the
    last PATIENCE rounds, or ``max_rounds`` rounds are done, or ``budget_seconds`` have
    passed (a budget, not a limit: the round under way finishes).
    """
    start = time.perf_counter()
    samples = interleaved_samples(calls, min_rounds)
    while len(next(iter(samples.values()))) < max_rounds and time.perf_counter() - start < budget_seconds:
        if all(_settled(s) for s in samples.values()):
            break
        numbers = {name: s.number for name, s in samples.items()}
        for name, s in interleaved_samples(calls, 1, warm_up=False, numbers=numbers).items():
            samples[name] += s
    return samples


def _settled(samples: list[float]) -> bool:
    if len(samples) <= PATIENCE:
        return False
    before, now = min(samples[:-PATIENCE]), min(samples)
    return now >= (1.0 - SETTLED) * before


def marginal_times(once, twice, k: int):
    """Per-step cost from rounds of a k-step and a 2k-step call: (:class:`Times`, how estimated).

    The cost of k more steps, without entering and leaving the loop, and so without
    allocating (and paging in) the call's fresh output buffer, which costs more than a few
    steps of 10^6 particles. Median and max: of each round's (t(2k) - t(k)) / k, the two
    calls adjacent in time. Minimum: (min t(2k) - min t(k)) / k, the least-disturbed calls
    (the least of the rounds' differences would pick a round whose k-step call was slowed),
    at most the median. Where noise swamps it (a difference not positive), the average
    over 2k steps instead, an upper bound. Where the rounds are :class:`Samples`, the CPU
    seconds are estimated the same way, the page faults per step are the median of the
    rounds' differences over k, and the preemptions per call the median over both calls.
    """
    times, how = _marginal(once, twice, k)
    if getattr(once, "cpu", None) and getattr(twice, "cpu", None):
        cpu, _ = _marginal(once.cpu, twice.cpu, k)
        faults = float(np.median(np.subtract(twice.faults, once.faults))) / k
        preempted = float(np.median(np.add(twice.preempted, once.preempted))) / 2
        times = dataclasses.replace(times, cpu=cpu, faults=faults, preempted=preempted,
                                    threads=threads_used(once, twice))
    return times, how


def _marginal(once, twice, k: int):
    differences = np.subtract(twice, once) / k
    least = (np.min(twice) - np.min(once)) / k
    if np.min(differences) > 0 and least > 0:
        median = float(np.median(differences))
        return Times(median, min(float(least), median), len(differences), float(np.max(differences))), "marginal"
    return Times.of(np.divide(twice, 2 * k)), "average (noise swamped the marginal cost)"


def settled_times(calls: dict[object, Callable[[], object]], config, min_rounds: int | None = None) -> dict:
    """:class:`~steplab.core.timing.Times` of each call by :func:`settled_samples`, the config's rounds and budget."""
    samples = settled_samples(calls, min_rounds or config.repeats, config.max_rounds, config.round_budget_seconds)
    return {name: Times.of(s) for name, s in samples.items()}
