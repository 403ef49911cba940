"""The broadphase after an impact: the candidate pairs of the bodies whose motion it changed.

The step's broadphase (:func:`.pairs.candidates`) runs once, over every body's swept
bounds for the whole step. An impact changes the chords of a few bodies (the pair, or
their spring-connected groups): only their pairs can have new collisions, so only their
new swept bounds, from the point of impact to the new end of the step, are tested,
against the bounds of every other body over the rest of the step. The bounds are the
ones :func:`.pairs.candidates` builds (a sphere on the middle of the chord, reaching the
radius plus half the chord plus the margin), for an unchanged body those of its whole
step (they hold every later part of its chord, :mod:`.chords`), and the test is the
broadphase's one floating-point expression (``physics.broadphase.common.spheres_overlap``):
every pair the full broadphase would find over the rest of the step is found, and perhaps
a few more, which the exact narrow phase then clears.

The swept spheres sit in a hashed uniform grid (:class:`SweptGrid`), built once per step
and updated body by body, so a query costs O(1) per changed body, not O(N); the kernels
are compiled with ``cache=True`` like the broadphase's, so the compile is paid once per
machine.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..broadphase.common import sort_pairs, spheres_overlap

#: cell edge over the median swept reach; with :data:`LARGE_CELLS` a body of up to twice the
#: median reach is filed in a cell (measured on the crowded 2,000-ball pit, the compiled step's
#: CPU time: 0.72 s at 2 median reaches and one edge, 0.87 s at 4 and half an edge, 1.0 s at 1
#: and 2 edges; the same pairs in every case, so the same bits)
CELL_REACHES = 2.0
#: a body whose reach exceeds this many cell edges is *large*: on the list every query scans
LARGE_CELLS = 1.0
#: hash buckets per body (a power of two at least this many times N)
BUCKETS_PER_BODY = 2
#: relative widening of a query for the roundings of its bounds (far more than the few ulps needed)
ROUNDING = 1e-12
#: a query's pairs up to this many are sorted by insertion: a radix sort's passes over its
#: counters cost O(N) per query (a few microseconds at 2,000 bodies, tens at 10^4), while a
#: query finds a few dozen pairs
INSERTION_SORT_PAIRS = 64
#: cell indices stay below 2^50 (exact in float64; far bodies share the outermost cells)
MAX_CELL_INDEX = 2.0**50


class GridArrays(NamedTuple):
    """A :class:`SweptGrid`'s arrays, as its query reads them (changed in place, ``h`` fixed); passed
    as a plain tuple and unpacked in this order (:class:`.chords.ChordArrays` says why)."""

    h: float  # cell edge, m
    centers: np.ndarray  # (N, 3) swept-sphere centres, shared with the chords
    reach: np.ndarray  # (N,) swept-sphere radii
    head: np.ndarray  # (buckets,) first body of each bucket, -1: empty
    next: np.ndarray  # (N,) next body in the bucket
    cell: np.ndarray  # (N, 3) the cell of each body's centre
    large: np.ndarray  # (N,) bool: on the large list
    large_list: np.ndarray  # (N,) the large bodies, the first n_large[0]
    n_large: np.ndarray  # (1,)
    small_reach: np.ndarray  # (1,) at least the reach of every small body filed, m


class SweptGrid:
    """A hashed uniform grid of every body's swept sphere, updated body by body as chords change.

    Each body sits in the cell of its centre (a doubly linked list per bucket), except the
    *large* ones (reach over :data:`LARGE_CELLS` cell edges: fast bodies), kept on a list
    every query scans. A query of body a scans the cells within its reach plus the largest
    reach of a small body filed (``small_reach``, an upper bound kept as bodies are filed)
    of its centre: a small partner's centre lies within reach_a + reach_b of a's, so in one
    of them.

    Parameters
    ----------
    centers : ndarray, shape (N, 3)
    reach : ndarray, shape (N,)
        Shared with the :class:`.chords.Chords` that owns them, read at every call.
    """

    def __init__(self, centers, reach):
        n = len(reach)
        self.centers, self.reach = centers, reach
        median = float(np.median(reach)) if n else 1.0
        self.h = CELL_REACHES * median if median > 0 else 1.0
        buckets = 1
        while buckets < BUCKETS_PER_BODY * max(n, 1):
            buckets *= 2
        self.arrays = tuple(GridArrays(self.h, centers, reach, np.full(buckets, -1, np.int64),
                                       np.full(n, -1, np.int64), np.zeros((n, 3), np.int64), np.zeros(n, np.bool_),
                                       np.zeros(n, np.int64), np.zeros(1, np.int64), np.zeros(1)))
        #: what filing a body again needs besides: the previous body in its bucket, and the bucket
        self.links = (np.full(n, -1, np.int64), np.full(n, -1, np.int64))
        _place(self.arrays, self.links, np.arange(n))

    def moved(self, bodies) -> None:
        """``bodies`` have new swept spheres (already in ``centers`` and ``reach``): file them again."""
        _place(self.arrays, self.links, bodies)

    def pairs(self, inverse_masses, active, changed, is_changed):
        """Pairs (i < j), sorted, of a body in ``changed`` with any body whose swept spheres overlap."""
        return _query(self.arrays, inverse_masses, active, changed, is_changed)


@njit(cache=True, inline="always")
def _cell(x, h):
    """The cell index of coordinate ``x``, clamped so that it stays an exact integer."""
    return np.int64(np.floor(min(max(x / h, -MAX_CELL_INDEX), MAX_CELL_INDEX)))


@njit(cache=True, inline="always")
def _hash(x, y, z, mask):
    key = (np.uint64(x & 0x1FFFFF) * np.uint64(73856093)) ^ (np.uint64(y & 0x1FFFFF) * np.uint64(19349663)) \
        ^ (np.uint64(z & 0x1FFFFF) * np.uint64(83492791))
    return np.int64((key * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(32)) & mask


@njit(cache=True)
def _place(grid, links, bodies):
    """File ``bodies`` again: each in the bucket of its centre's cell, or on the large list."""
    h, centers, reach, head, nxt, cell, large, large_list, n_large, small_reach = grid
    prv, bucket = links
    mask = head.shape[0] - 1
    for b in bodies:
        if bucket[b] >= 0:  # unlink from its bucket
            if prv[b] >= 0:
                nxt[prv[b]] = nxt[b]
            else:
                head[bucket[b]] = nxt[b]
            if nxt[b] >= 0:
                prv[nxt[b]] = prv[b]
            bucket[b] = -1
        if reach[b] > LARGE_CELLS * h:
            if not large[b]:
                large[b] = True
                large_list[n_large[0]] = b
                n_large[0] += 1
            continue
        large[b] = False
        small_reach[0] = max(small_reach[0], reach[b])
        for k in range(3):
            cell[b, k] = _cell(centers[b, k], h)
        s = _hash(cell[b, 0], cell[b, 1], cell[b, 2], mask)
        bucket[b] = s
        prv[b] = -1
        nxt[b] = head[s]
        if head[s] >= 0:
            prv[head[s]] = b
        head[s] = b


@njit(cache=True)
def _query(grid, inverse_masses, active, changed, is_changed):
    """:meth:`SweptGrid.pairs`, compiled: :func:`query_into` a new buffer, sorted."""
    out = np.empty((16, 2), dtype=np.int64)
    k = query_into(grid, inverse_masses, active, changed, is_changed, out)
    if k > out.shape[0]:  # more pairs than rows: the query again, into room for all
        out = np.empty((k, 2), dtype=np.int64)
        query_into(grid, inverse_masses, active, changed, is_changed, out)
    return sorted_pairs(out, k, grid[1].shape[0])


@njit(cache=True)
def query_into(grid, inverse_masses, active, changed, is_changed, out):
    """The pairs of :meth:`SweptGrid.pairs`, unsorted, written into the rows of ``out`` (k, 2) while
    they last; returns how many there are (more than its rows: call again with room for them).

    ``out`` is never replaced inside the loops: an array variable reassigned in a loop costs
    its reference count up and down at every iteration (an atomic operation each), which was
    most of the query's time when a full buffer was grown in place.
    """
    h, centers, reach, head, nxt, cell, large, large_list, n_large, small_reach = grid
    n = centers.shape[0]
    mask = head.shape[0] - 1
    k = 0
    for a in changed:
        if not active[a]:
            continue
        movable = inverse_masses[a] != 0.0
        # a small partner's centre is within reach_a + reach_b <= reach_a + small_reach of a's
        # (widened for rounding)
        r = reach[a] + small_reach[0] + ROUNDING * (abs(centers[a, 0]) + reach[a] + h)
        lo0, hi0 = _cell(centers[a, 0] - r, h), _cell(centers[a, 0] + r, h)
        r = reach[a] + small_reach[0] + ROUNDING * (abs(centers[a, 1]) + reach[a] + h)
        lo1, hi1 = _cell(centers[a, 1] - r, h), _cell(centers[a, 1] + r, h)
        r = reach[a] + small_reach[0] + ROUNDING * (abs(centers[a, 2]) + reach[a] + h)
        lo2, hi2 = _cell(centers[a, 2] - r, h), _cell(centers[a, 2] + r, h)
        # candidates: the small bodies in the cells around a (all of them for a huge query), and the large ones
        if (hi0 - lo0 + 1) * (hi1 - lo1 + 1) * (hi2 - lo2 + 1) > n:
            for b in range(n):
                if not large[b]:
                    if (_may_pair(a, b, active[b], is_changed[b], movable, inverse_masses[b])
                            and spheres_overlap(centers, reach, a, b)):
                        k = _put_pair(out, k, a, b)
        else:
            for x in range(lo0, hi0 + 1):
                for y in range(lo1, hi1 + 1):
                    for z in range(lo2, hi2 + 1):
                        b = head[_hash(x, y, z, mask)]
                        while b >= 0:
                            if cell[b, 0] == x and cell[b, 1] == y and cell[b, 2] == z:
                                if (_may_pair(a, b, active[b], is_changed[b], movable, inverse_masses[b])
                                        and spheres_overlap(centers, reach, a, b)):
                                    k = _put_pair(out, k, a, b)
                            b = nxt[b]
        for p in range(n_large[0]):
            b = large_list[p]
            if large[b]:
                if (_may_pair(a, b, active[b], is_changed[b], movable, inverse_masses[b])
                        and spheres_overlap(centers, reach, a, b)):
                    k = _put_pair(out, k, a, b)
    return k


@njit(cache=True, inline="always")
def _put_pair(out, k, a, b):
    """Row k of ``out`` is the pair (min, max); returns k + 1. Past the last row, the last row is written
    over (the query is made again with room): no branch, so no reference count (:func:`_may_pair`)."""
    row = min(k, out.shape[0] - 1)
    out[row, 0], out[row, 1] = min(a, b), max(a, b)
    return k + 1


@njit(cache=True)
def sorted_pairs(pairs, k, n):
    """The first ``k`` rows of ``pairs`` (distinct, each i < j < n) in lexicographic order: in place by
    insertion up to :data:`INSERTION_SORT_PAIRS` (``pairs[:k]`` returned), else a radix sort's new array."""
    if k > INSERTION_SORT_PAIRS:
        return sort_pairs(pairs, k, n)
    for p in range(1, k):
        i, j = pairs[p, 0], pairs[p, 1]
        q = p - 1
        while q >= 0 and (pairs[q, 0] > i or (pairs[q, 0] == i and pairs[q, 1] > j)):
            pairs[q + 1, 0], pairs[q + 1, 1] = pairs[q, 0], pairs[q, 1]
            q -= 1
        pairs[q + 1, 0], pairs[q + 1, 1] = i, j
    return pairs[:k]


@njit(cache=True, inline="always")
def _may_pair(a, b, b_active, b_changed, a_movable, b_inverse_mass):
    """Whether (a, b) may be a new candidate pair, its swept spheres aside: b active, the pair found once
    (from its smaller changed body), and not two immovable bodies (nothing could respond).

    It takes numbers, not the arrays they come from: an inlined function handed an array and
    left by several returns costs that array's reference count up and down at every call (two
    atomic operations), which in the query's innermost loop was most of its time."""
    return b != a and b_active and not (b_changed and b < a) and (a_movable or b_inverse_mass != 0.0)
