"""Sort and sweep (sweep and prune): sorted interval bounds, swept; and its coherent form.

Fresh (:func:`sap_pairs`), the lecture's "plane sweep": along the axis with the largest
spread of centres each sphere is the interval [lo, hi] of its padded box. Sorted by lo,
sphere ``p`` can only overlap the spheres after it that start before it ends, so its
sweep stops at the first start beyond its end; survivors are checked on the other two
axes, then by the exact sphere test. Cost: the sort, O(n log n), plus one step per
interval overlap *along the sweep axis*. In 3-D that second term dominates: n spheres
spread uniformly in a cube overlap ~n^(2/3) others along any one axis, so the sweep is
O(n^(5/3)) although the answer is O(n).

Coherent (:class:`CoherentSortAndSweep`), as in Bullet's ``btAxisSweep3`` (Baraff 1992;
Cohen, Lin, Manocha, Ponamgi 1995, I-COLLIDE): keep the sorted bounds of *all three*
axes between frames and the set of pairs whose boxes overlap. Bodies move little, so
last frame's order is nearly sorted and insertion sort repairs it in O(n + swaps);
each swap of a lower bound past an upper bound is exactly the moment two intervals
start (or stop) overlapping on that axis, so the pair set is updated at the swaps and
no sweep is needed at all. A frame then costs O(n + swaps + pairs).

The lecture: "Time consuming part is sorting bounds ... use Bubblesort to repair -
nearly O(n)". Insertion sort, not bubble sort, is the one with the O(n + inversions)
bound; and with one axis sorted afresh each frame the sort is *not* the time-consuming
part in 3-D (the sweep is, see above). The coherence pays off only when the pairs are
kept across frames too, as here.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .common import append_pair, as_spheres, bounds, boxes_overlap, no_pairs, padding, sort_pairs, spheres_overlap

#: a repair of more than this many swaps per bound and log2(n) is abandoned for a full sort
MAX_SWAPS_PER_BOUND_LOG_N = 4
#: the pair table is rebuilt larger when more than this fraction of its slots is taken
MAX_TABLE_LOAD = 0.5
EMPTY, DELETED = -1, -2


def sweep_axis(c: np.ndarray) -> int:
    """The axis (0, 1 or 2) along which the centres are most spread out (largest variance)."""
    return int(np.argmax(c.var(axis=0))) if len(c) else 0


def sap_pairs(c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Overlapping pairs by a fresh sort and sweep; ``c`` (n, 3), ``r`` (n,) checked. Sorted (k, 2)."""
    n = len(c)
    if n < 2:
        return no_pairs()
    lo, hi = bounds(c, r, padding(c, r))
    axis = sweep_axis(c)
    order = np.argsort(lo[:, axis])
    pairs, k = _sweep(c, r, lo, hi, order, axis, True)
    return sort_pairs(pairs, k, n)


class CoherentSortAndSweep:
    """Sort and sweep across frames: three sorted axes and the overlapping boxes, repaired.

    >>> sweep = CoherentSortAndSweep()
    >>> pairs = sweep.update(centers, radii)      # first frame: sorts and sweeps
    >>> pairs = sweep.update(centers + v * dt, radii)
    >>> sweep.swaps                               # the repair's work this frame

    ``update`` returns exactly :func:`find_pairs`'s pairs for that frame. A change in
    the number of bodies, or a repair needing more than
    ``MAX_SWAPS_PER_BOUND_LOG_N * 2n * log2(n)`` swaps on an axis (bodies that jumped),
    starts again from a full sort; so does :meth:`reset`.

    Attributes
    ----------
    swaps : int
        Adjacent exchanges the last repair made, over the three axes: the number of
        bound orderings the motion changed. 0 on a frame that sorted from scratch.
    box_pairs : int
        Pairs whose padded boxes overlap, kept between frames (a superset of the result).
    total_swaps, full_sorts, frames : int
        Swaps summed over all frames, frames sorted from scratch, frames updated.
    """

    def __init__(self):
        self.swaps = 0
        self.total_swaps = 0
        self.full_sorts = 0
        self.frames = 0
        self.reset()

    def reset(self) -> None:
        """Forget the order and the pairs: the next frame sorts from scratch."""
        self._bounds = None  # (3, 2n) body * 2 + (0 for lo, 1 for hi), sorted per axis
        self._table = None   # open-addressing hash set of overlapping boxes, key i * n + j

    @property
    def box_pairs(self) -> int:
        return 0 if self._table is None else int(np.count_nonzero(self._table >= 0))

    def update(self, centers, radii) -> np.ndarray:
        """This frame's overlapping pairs, int64 (k, 2), rows i < j, sorted."""
        c, r = as_spheres(centers, radii)
        n = len(c)
        lo, hi = bounds(c, r, padding(c, r))
        self.frames += 1
        self.swaps = 0
        if self._bounds is None or self._bounds.shape[1] != 2 * n:
            self._start(lo, hi)
        else:
            limit = int(MAX_SWAPS_PER_BOUND_LOG_N * 2 * n * max(1.0, np.log2(max(n, 2))))
            table, swaps = _repair(self._bounds, lo, hi, np.hstack((lo, hi)), self._table, limit)
            if swaps < 0:
                self._start(lo, hi)
            else:
                self._table = table
                self.swaps = swaps
                self.total_swaps += swaps
        if n < 2:
            return no_pairs()
        pairs, k = _table_pairs(self._table, c, r, lo, hi)
        return sort_pairs(pairs, k, n)

    def _start(self, lo, hi):
        """Sort all three axes from scratch and find the overlapping boxes by one sweep."""
        n = len(lo)
        self.full_sorts += 1
        ident = np.arange(2 * n, dtype=np.int64)
        self._bounds = np.empty((3, 2 * n), dtype=np.int64)
        for axis in range(3):
            value = np.empty(2 * n)
            value[0::2], value[1::2] = lo[:, axis], hi[:, axis]
            # at equal values lower bounds first, so touching boxes count as overlapping
            self._bounds[axis] = ident[np.lexsort((ident & 1, value))]
        axis = int(np.argmax(np.ptp(lo, axis=0))) if n else 0
        starts = self._bounds[axis][self._bounds[axis] % 2 == 0] // 2
        box, k = _sweep(np.empty((0, 3)), np.empty(0), lo, hi, starts, axis, False)
        self._table = _table_from_pairs(box, k, n)


@njit(cache=True)
def _sweep(c, r, lo, hi, order, axis, spheres):
    """Pairs whose boxes overlap (and, if ``spheres``, whose spheres do), sweeping ``order`` along ``axis``."""
    n = order.shape[0]
    u, v = (axis + 1) % 3, (axis + 2) % 3
    # the bounds in sweep order, contiguous: the inner loop reads memory in sequence
    start = np.empty(n)
    end = np.empty(n)
    box = np.empty((n, 4))
    for p in range(n):
        i = order[p]
        start[p] = lo[i, axis]
        end[p] = hi[i, axis]
        box[p, 0] = lo[i, u]
        box[p, 1] = hi[i, u]
        box[p, 2] = lo[i, v]
        box[p, 3] = hi[i, v]
    pairs = np.empty((n + 16, 2), dtype=np.int64)
    k = 0
    for p in range(n):
        stop = end[p]
        for q in range(p + 1, n):
            if start[q] > stop:
                break
            if (box[q, 0] <= box[p, 1] and box[p, 0] <= box[q, 1] and box[q, 2] <= box[p, 3]
                    and box[p, 2] <= box[q, 3]):
                i, j = order[p], order[q]
                if not spheres or spheres_overlap(c, r, i, j):
                    pairs, k = append_pair(pairs, k, i, j)
    return pairs, k


# --- the pair set: open addressing, linear probing, keys i * n + j -----------------------


@njit(cache=True, inline="always")
def _home(key, mask):
    return np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(32)) & mask


@njit(cache=True)
def _new_table(count):
    size = 16
    while size * MAX_TABLE_LOAD < 1.5 * count + 16:  # room to grow by half before a rehash
        size *= 2
    return np.full(size, EMPTY, dtype=np.int64)


@njit(cache=True)
def _insert(table, key):
    """Add ``key`` (the caller keeps the table at most half full, so an empty slot exists)."""
    mask = table.shape[0] - 1
    s = _home(key, mask)
    free = -1
    while table[s] != EMPTY:
        if table[s] == key:
            return
        if table[s] == DELETED and free < 0:
            free = s
        s = (s + 1) & mask
    table[free if free >= 0 else s] = key


@njit(cache=True)
def _rehash(table):
    """The live keys in a fresh table sized for them (drops the DELETED markers)."""
    live = 0
    for s in range(table.shape[0]):
        if table[s] >= 0:
            live += 1
    fresh = _new_table(live)
    for s in range(table.shape[0]):
        if table[s] >= 0:
            _insert(fresh, table[s])
    return fresh


@njit(cache=True)
def _table_from_pairs(pairs, k, n):
    table = _new_table(k)
    for p in range(k):
        _insert(table, pairs[p, 0] * n + pairs[p, 1])
    return table


@njit(cache=True)
def _table_pairs(table, c, r, lo, hi):
    """The kept pairs whose spheres overlap; pairs whose boxes no longer overlap are dropped."""
    n = c.shape[0]
    pairs = np.empty((n + 16, 2), dtype=np.int64)
    k = 0
    for s in range(table.shape[0]):
        key = table[s]
        if key >= 0:
            i, j = key // n, key % n
            if not boxes_overlap(lo, hi, i, j):
                table[s] = DELETED
            elif spheres_overlap(c, r, i, j):
                pairs, k = append_pair(pairs, k, i, j)
    return pairs, k


@njit(cache=True, inline="always")
def _boxes6_overlap(boxes, i, j):
    return (boxes[j, 0] <= boxes[i, 3] and boxes[i, 0] <= boxes[j, 3] and boxes[j, 1] <= boxes[i, 4]
            and boxes[i, 1] <= boxes[j, 4] and boxes[j, 2] <= boxes[i, 5] and boxes[i, 2] <= boxes[j, 5])


@njit(cache=True)
def _repair(sorted_bounds, lo, hi, boxes, table, max_swaps):
    """Insertion-sort each axis's bounds to the new values, adding pairs at the swaps.

    A lower bound of i moving left past an upper bound of j: the intervals start to
    overlap on this axis, and the pair joins the set if the boxes (new values) overlap
    on all three axes. Every pair that overlaps now either overlapped last frame (and is
    in the set) or made such a swap on some axis (and joins it). Pairs that stopped
    overlapping (an upper bound passing a lower bound) are not looked up here: the
    output scan drops them (:func:`_table_pairs`), which costs nothing extra.
    ``boxes`` is (lo, hi) side by side, shape (n, 6): one body's box in one cache line.
    Returns (table, swaps), swaps = -1 when an axis needed more than ``max_swaps``.
    """
    n = lo.shape[0]
    used = 0
    for s in range(table.shape[0]):
        if table[s] != EMPTY:
            used += 1
    swaps = 0
    value = np.empty(2 * n)
    for axis in range(3):
        bound = sorted_bounds[axis]
        for p in range(2 * n):
            e = bound[p]
            value[p] = hi[e >> 1, axis] if e & 1 else lo[e >> 1, axis]
        axis_swaps = 0
        for p in range(1, 2 * n):
            e, v = bound[p], value[p]
            q = p - 1
            # move e left past every bound that belongs after it (at a tie, lower bounds first)
            while q >= 0 and (value[q] > v or (value[q] == v and (bound[q] & 1) == 1 and (e & 1) == 0)):
                f = bound[q]
                # (a lower bound never passes its own upper bound: lo <= hi, and ties put lower first)
                if (e & 1) == 0 and (f & 1) == 1 and _boxes6_overlap(boxes, e >> 1, f >> 1):
                    if used + 1 > MAX_TABLE_LOAD * table.shape[0]:
                        table = _rehash(table)
                        used = 0
                        for s in range(table.shape[0]):
                            if table[s] != EMPTY:
                                used += 1
                    i, j = e >> 1, f >> 1
                    _insert(table, min(i, j) * n + max(i, j))
                    used += 1
                bound[q + 1], value[q + 1] = f, value[q]
                q -= 1
            axis_swaps += p - 1 - q
            bound[q + 1], value[q + 1] = e, v
            if axis_swaps > max_swaps:
                return table, -1
        swaps += axis_swaps
    return table, swaps
