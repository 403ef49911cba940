"""Timing calls from cold caches: each timed call starts with its data in memory, none in a cache.

A memory-traffic bound is the time to move a step's bytes between memory and the core. Where
the step's data fit in the last-level cache (the bench's 25,600-particle cloth moves 5.3 MB;
the L3 here holds 32 MB), a call repeated back to back finds them in the cache and moves
nothing from memory: its time is then measured against cache bandwidth, not memory's. So the
bound and the step it bounds are both timed cold (:func:`cold_samples`): before each timed
call, :func:`evictor`'s buffer, several times the largest cache, is read through the caches,
which leaves none of the call's data in them (a read, so the evicted lines are clean and no
write-back of the buffer lands in the timed call). Each side then reads its data from memory
once and writes its results into the cache; neither side's write-back to memory is timed.
"""

from __future__ import annotations

import glob
from collections.abc import Callable

import numpy as np

from steplab.core.timing import Samples, timed_call

#: bytes assumed for the largest cache where the OS does not say (this machine's L3)
DEFAULT_CACHE_BYTES = 32 * 2**20
#: the eviction buffer, in multiples of the largest cache: on the cloth's bound (5.3 MB), 1x to 8x
#: (32 to 256 MB) gave the same cold time within the noise (minimums 0.29 to 0.31 ms, medians 0.32
#: to 0.34 ms; warm 0.09); 4x leaves a margin for caches that are not strictly least-recently-used
EVICTION_FACTOR = 4


def largest_cache_bytes() -> int:
    """The largest CPU cache's size in bytes (Linux sysfs), or DEFAULT_CACHE_BYTES where unknown."""
    sizes = []
    for path in glob.glob("/sys/devices/system/cpu/cpu0/cache/index*/size"):
        try:
            with open(path) as f:
                text = f.read().strip()
        except OSError:
            continue
        scale = {"K": 2**10, "M": 2**20, "G": 2**30}.get(text[-1:], 1)
        digits = text[:-1] if text[-1:] in "KMG" else text
        if digits.isdigit():
            sizes.append(int(digits) * scale)
    return max(sizes, default=DEFAULT_CACHE_BYTES)


def evictor(factor: int = EVICTION_FACTOR) -> Callable[[], object]:
    """A call that reads ``factor`` times the largest cache's bytes (allocated and paged in here)."""
    buffer = np.ones(factor * largest_cache_bytes() // 8)
    buffer.sum()
    return buffer.sum


def cold_samples(calls: dict[object, Callable[[], object]], rounds: int,
                 evict: Callable[[], object]) -> dict[object, Samples]:
    """Wall and CPU seconds of one call of each contender from cold caches, ``rounds`` interleaved rounds.

    Each timed call follows an ``evict()`` (untimed), and is made once: the calls must already
    be warmed up (compiled), and each must be the whole of what is compared (one step, one
    pass of the bound).
    """
    samples = {name: Samples() for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            evict()
            timed_call(call, samples[name])
    return samples
