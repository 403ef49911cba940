"""Cells shared by the uniform grid and the spatial hash: a hierarchy of uniform grids.

Levels ``l = 0, 1, 2, ...`` have cell edges ``h_l = h_0 2^l`` (exact powers of two, so
every level is computed without extra rounding). Each sphere lives in one cell of one
level: the first level where its padded box spans at most two cells per axis (checked
on the integer cell indices, so rounding cannot break it), in its *home* cell, the
lowest cell its box touches. Spheres of equal size all share level 0; a sphere larger
than a level-0 cell simply lives on a coarser level (Ericson, *Real-Time Collision
Detection*, 7.2 "hierarchical grids"; Mirtich 1996).

Pairs, each found exactly once, with no de-duplication:

- same level: the home cells of two overlapping spheres differ by at most one per axis,
  so each sphere tests the later spheres of its own cell and every sphere of the 13
  "forward" neighbour cells (half of the 26; the other half test it);
- across levels: a sphere looks up only the coarser levels. There, the partner's home
  cell lies in [a - 1, b] per axis, where a and b are the lowest and highest cells of
  the sphere's own box on that level: at most 27 cells, usually 8.

Proof sketch of [a - 1, b]: overlapping boxes give lo_j <= hi_i and lo_i <= hi_j; the
cell index floor((x - origin) / h) is monotone in x, so a_j <= b_i and a_i <= b_j; and
b_j <= a_j + 1 because j is small on its own level.

``bits < 0`` indexes cells densely (the grid: one counter per cell of the bounding box,
level by level); ``bits >= 0`` hashes (level, x, y, z) into 2^bits buckets (the spatial
hash), where entries of other cells in the same bucket are skipped by comparing cells.

One level, by columns: when the dense grid's spheres are alike (the widest box at most
:data:`ONE_LEVEL_SPREAD` times the median), there is a single level of cells as wide as the
widest box, numbered with z fastest. The cells (x, y, z-1 .. z+1) of a column are then one
run of the sorted spheres, and the 13 forward neighbours with the own cell are 5 runs: the
own column from the sphere on, (x, y+1), and (x+1, y-1 .. y+1), each over z-1 .. z+1. The
same pairs, each once; 2 to 3 times faster than 14 cell lookups on a ball pit of 10^4.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .common import append_pair, no_pairs, padding, radix_argsort, sort_pairs, spheres_overlap

#: cell edge of level 0 over the median padded box width, 2 (r + pad); just above 1 keeps equal
#: spheres on level 0, and measured times are flat from 1.0 to 1.25
CELL_FACTOR = 1.01
#: the dense grid has at most this many level-0 cells per sphere (memory O(n), not O(volume))
MAX_CELLS_PER_BODY = 32
#: the dense grid uses one level when the widest box is at most this many times the median one
#: (cells as wide as the widest box); beyond, the hierarchy keeps outliers off the fine cells
ONE_LEVEL_SPREAD = 2.0
#: room for this many pairs per sphere in the one-level grid's buffer (more: it runs again); a pile of
#: bodies with wide speculative margins has more than 4 (the 10^4 box pit: 5.3 in its first 30
#: steps, so every step ran the grid twice), and the room costs nothing until it is written
PAIRS_PER_BODY = 8
#: the one-level grid searches the spheres on the threads it is given from this many spheres on (fewer:
#: on the calling thread, where waking the others costs more than they save)
PARALLEL_BODIES = 2048
#: the level-0 cell edge uses the median radius of at most about this many evenly strided spheres
MEDIAN_SAMPLE = 1024
#: hash buckets per sphere (rounded up to a power of two)
BUCKETS_PER_BODY = 2.0
#: hash coordinates stay below 2^50 cells (exact in float64, no int64 overflow)
MAX_CELL_INDEX = 2.0**50

#: Teschner, Heidelberger, Mueller, Pomeranets, Gross (2003), "Optimized spatial hashing", and a 4th
PRIMES = (np.uint64(73856093), np.uint64(19349663), np.uint64(83492791), np.uint64(2654435761))
#: 2^64 / golden ratio (Knuth's multiplicative hash): the top bits of key * FIBONACCI pick the bucket
FIBONACCI = np.uint64(0x9E3779B97F4A7C15)

#: the 13 neighbour offsets lexicographically after (0, 0, 0): half of the 26 neighbours
FORWARD = np.array([(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
                    if (dx, dy, dz) > (0, 0, 0)], dtype=np.int64)


class Cells(NamedTuple):
    """The hierarchy's cells: ``origin`` (3,) the lowest corner of all boxes, ``hs`` (L,) the cell
    edge of each level, and where a cell's spheres are counted: ``bits < 0``, densely, ``dims``
    (L, 3) cells per axis on each level from index ``offset[level]`` (L + 1,); ``bits >= 0``,
    in one of 2^bits hash buckets (``dims`` and ``offset`` then unused)."""

    origin: np.ndarray
    hs: np.ndarray
    dims: np.ndarray
    offset: np.ndarray
    bits: int


def hierarchy_pairs(c: np.ndarray, r: np.ndarray, hashed: bool, threads: int = 1) -> np.ndarray:
    """Overlapping pairs through the grid hierarchy, dense (``hashed=False``) or hashed; the dense
    grid's one level searched on ``threads`` of Numba's threads from :data:`PARALLEL_BODIES` spheres."""
    n = len(c)
    if n < 2:
        return no_pairs()
    pad = padding(c, r)
    origin, extent, widest = _extent(c, r, pad)
    # the median radius of an evenly strided sample: the same cells as the full median, in O(1)
    h0 = CELL_FACTOR * 2 * (float(np.median(r[:: max(1, n // MEDIAN_SAMPLE)])) + pad)
    if hashed:
        h0 = max(h0, float(extent.max()) / MAX_CELL_INDEX)
    else:
        max_cells = MAX_CELLS_PER_BODY * n + 64
        h0 = max(h0, float(extent.max()) / max_cells)
        while np.prod(np.floor(extent / h0) + 1) > max_cells:
            h0 *= 1.25
    if not hashed and widest <= ONE_LEVEL_SPREAD * h0 / CELL_FACTOR:
        # sizes alike: one level with cells as wide as the widest box, searched by columns
        h = CELL_FACTOR * widest
        while np.prod(np.floor(extent / h) + 1) > max_cells:
            h *= 1.25
        dims = (np.floor(extent / h) + 1).astype(np.int64)
        return _column_pairs(c, r, pad, (origin, h, dims), threads if n >= PARALLEL_BODIES else 1)
    # enough levels that the last one holds everything in one or two cells per axis
    n_levels = 1
    while h0 * 2.0 ** (n_levels - 1) < extent.max() + widest:
        n_levels += 1
    hs = h0 * 2.0 ** np.arange(n_levels)
    level = _levels(c, r, pad, origin, hs)
    if hashed:
        bits = max(4, int(np.ceil(np.log2(BUCKETS_PER_BODY * n))))
        dims = np.ones((n_levels, 3), dtype=np.int64)
        offset = np.zeros(n_levels + 1, dtype=np.int64)
    else:
        bits = -1
        dims = (np.floor(extent[None, :] / hs[:, None]) + 1).astype(np.int64)
        dims[np.bincount(level, minlength=n_levels) == 0] = 0  # no cells on an empty level
        offset = np.concatenate(([0], np.cumsum(np.prod(dims, axis=1))))
    pairs, k = _hierarchy_kernel(c, r, pad, level, Cells(origin, hs, dims, offset, bits))
    return sort_pairs(pairs, k, n)


@njit(cache=True, inline="always")
def _lo(c, r, pad, i, k):
    """The padded box, exactly as :func:`.common.bounds` computes it: c - (r + pad)."""
    return c[i, k] - (r[i] + pad)


@njit(cache=True, inline="always")
def _hi(c, r, pad, i, k):
    return c[i, k] + (r[i] + pad)


@njit(cache=True, inline="always")
def _cell(x, origin, h):
    return np.int64(np.floor((x - origin) / h))


@njit(cache=True)
def _extent(c, r, pad):
    """Lowest corner of all boxes, extent of their union per axis, and the widest box."""
    low = np.full(3, np.inf)
    high = np.full(3, -np.inf)
    widest = 0.0
    for i in range(c.shape[0]):
        for k in range(3):
            a, b = _lo(c, r, pad, i, k), _hi(c, r, pad, i, k)
            low[k] = min(low[k], a)
            high[k] = max(high[k], b)
            widest = max(widest, b - a)
    return low, high - low, widest


@njit(cache=True)
def _levels(c, r, pad, origin, hs):
    """Each sphere's level: the first whose cell edge is at least its box width, then up until small."""
    n = c.shape[0]
    level = np.empty(n, dtype=np.int64)
    top = hs.shape[0] - 1
    for i in range(n):
        w = 0.0
        for k in range(3):
            w = max(w, _hi(c, r, pad, i, k) - _lo(c, r, pad, i, k))
        lev = 0
        while lev < top and hs[lev] < w:
            lev += 1
        while lev < top:
            h = hs[lev]
            small = True
            for k in range(3):
                if _cell(_hi(c, r, pad, i, k), origin[k], h) - _cell(_lo(c, r, pad, i, k), origin[k], h) > 1:
                    small = False
            if small:
                break
            lev += 1
        level[i] = lev
    return level


@njit(cache=True, inline="always")
def _slot(lev, x, y, z, dims, offset, bits):
    """The counter a cell's spheres are sorted under: its dense index, or its hash bucket."""
    if bits < 0:
        return offset[lev] + (x * dims[lev, 1] + y) * dims[lev, 2] + z
    # +1: query cells reach one below the lowest home cell, and the unsigned hash wants x >= 0
    key = (np.uint64(lev) * PRIMES[3]) ^ (np.uint64(x + 1) * PRIMES[0]) ^ (np.uint64(y + 1) * PRIMES[1]) \
        ^ (np.uint64(z + 1) * PRIMES[2])
    return np.int64((key * FIBONACCI) >> np.uint64(64 - bits))


@njit(cache=True)
def _starts(slots, n_slots):
    """start[s]: the first of the sorted ``slots`` in slot s, start[s + 1] the end (one sequential
    sweep); int32, half the memory of a dense grid's counters (n < 2^31)."""
    start = np.empty(n_slots + 1, dtype=np.int32)
    s = 0
    for p in range(len(slots)):
        while s <= slots[p]:
            start[s] = p
            s += 1
    start[s:] = len(slots)
    return start


@njit(cache=True)
def _hierarchy_kernel(c, r, pad, level, cells):
    """Every overlapping pair of the spheres ``c, r``, each in its ``level``'s home cell (module docstring)."""
    origin, hs, dims, offset, bits = cells
    n = c.shape[0]
    hashed = bits >= 0
    n_slots = (1 << bits) if hashed else offset[-1]
    # each sphere's slot (from its home cell), and the spheres sorted by slot
    slot = np.empty(n, dtype=np.int64)
    for i in range(n):
        h = hs[level[i]]
        slot[i] = _slot(level[i], _cell(_lo(c, r, pad, i, 0), origin[0], h), _cell(_lo(c, r, pad, i, 1), origin[1], h),
                        _cell(_lo(c, r, pad, i, 2), origin[2], h), dims, offset, bits)
    order, slots = radix_argsort(slot, n_slots)
    start = _starts(slots, n_slots)
    # everything in slot order: spheres near in space are near in memory
    cs = np.empty((n, 3))
    rs = np.empty(n)
    levels = np.empty(n, dtype=np.int64)
    for p in range(n):
        i = order[p]
        for k in range(3):
            cs[p, k] = c[i, k]
        rs[p], levels[p] = r[i], level[i]
    homes = np.empty((n, 3), dtype=np.int64)
    stop = np.empty(n, dtype=np.int64)  # end of the sphere's slot in sorted order
    for p in range(n):
        h = hs[levels[p]]
        for k in range(3):
            homes[p, k] = _cell(_lo(cs, rs, pad, p, k), origin[k], h)
        stop[p] = start[slots[p] + 1]
    top = 0
    for p in range(n):
        top = max(top, levels[p])
    occupied = np.zeros(top + 1, dtype=np.bool_)
    for p in range(n):
        occupied[levels[p]] = True

    pairs = np.empty((n + 16, 2), dtype=np.int64)
    k = 0
    for p in range(n):
        lev = levels[p]
        x0, y0, z0 = homes[p, 0], homes[p, 1], homes[p, 2]
        # The partner scan below is written out at all three places on purpose: as a shared
        # inline function (same arguments) Numba's kernel measured 1.6x (grid) to 2x (hash)
        # slower at n = 10^5.
        # own cell: the spheres after p
        for q in range(p + 1, stop[p]):
            if hashed and not (levels[q] == lev and homes[q, 0] == x0 and homes[q, 1] == y0
                               and homes[q, 2] == z0):
                continue
            if spheres_overlap(cs, rs, p, q):
                pairs, k = append_pair(pairs, k, order[p], order[q])
        # the 13 forward neighbours on the same level
        for d in range(13):
            x, y, z = x0 + FORWARD[d, 0], y0 + FORWARD[d, 1], z0 + FORWARD[d, 2]
            if not hashed and not (0 <= x < dims[lev, 0] and 0 <= y < dims[lev, 1] and 0 <= z < dims[lev, 2]):
                continue
            s = _slot(lev, x, y, z, dims, offset, bits)
            for q in range(start[s], start[s + 1]):
                if hashed and not (levels[q] == lev and homes[q, 0] == x and homes[q, 1] == y
                                   and homes[q, 2] == z):
                    continue
                if spheres_overlap(cs, rs, p, q):
                    pairs, k = append_pair(pairs, k, order[p], order[q])
        # coarser levels: partners' home cells lie in [a - 1, b] of p's box there
        for up in range(lev + 1, top + 1):
            if not occupied[up]:
                continue
            h = hs[up]
            ax, bx = _cell(_lo(cs, rs, pad, p, 0), origin[0], h) - 1, _cell(_hi(cs, rs, pad, p, 0), origin[0], h)
            ay, by = _cell(_lo(cs, rs, pad, p, 1), origin[1], h) - 1, _cell(_hi(cs, rs, pad, p, 1), origin[1], h)
            az, bz = _cell(_lo(cs, rs, pad, p, 2), origin[2], h) - 1, _cell(_hi(cs, rs, pad, p, 2), origin[2], h)
            if not hashed:
                ax, ay, az = max(ax, 0), max(ay, 0), max(az, 0)
                bx, by, bz = min(bx, dims[up, 0] - 1), min(by, dims[up, 1] - 1), min(bz, dims[up, 2] - 1)
            for x in range(ax, bx + 1):
                for y in range(ay, by + 1):
                    for z in range(az, bz + 1):
                        s = _slot(up, x, y, z, dims, offset, bits)
                        for q in range(start[s], start[s + 1]):
                            if hashed and not (levels[q] == up and homes[q, 0] == x and homes[q, 1] == y
                                               and homes[q, 2] == z):
                                continue
                            if spheres_overlap(cs, rs, p, q):
                                pairs, k = append_pair(pairs, k, order[p], order[q])
    return pairs, k


@njit(cache=True, inline="always")
def _near(x, y, z, radius, cs, rs, q):
    """:func:`.common.spheres_overlap` of the sphere (x, y, z, radius) and sorted sphere q, same operations."""
    dx = x - cs[q, 0]
    dy = y - cs[q, 1]
    dz = z - cs[q, 2]
    s = radius + rs[q]
    return dx * dx + dy * dy + dz * dz <= s * s


def _column_pairs(c, r, pad, cells, threads):
    """The dense grid with one level of cells ``cells`` = (origin, edge h >= every box's width, dims),
    searched by columns (the module docstring): the pairs, sorted. The spheres are cut into
    ``threads`` parts searched in parallel, each into its own rows of the buffer; the pairs are
    then sorted by their first sphere (counting) and each sphere's partners by insertion: the same
    pairs in the same order on any number of threads. (Three compiled calls from Python: the
    parallel search called from inside a compiled function ran 4 times slower.)"""
    grid = _column_grid(c, r, pad, cells)
    n = len(c)
    # part t's rows begin at first[t]: room for PAIRS_PER_BODY a sphere; more found, searched again with room for all
    first = np.array([PAIRS_PER_BODY * (n * t // threads) + 16 * t for t in range(threads + 1)])
    found = np.empty(threads, np.int64)
    while True:
        pairs = np.empty((first[threads], 2), dtype=np.int64)
        if threads > 1:
            _search_parts(grid, pairs, first, found)
        else:
            found[0] = _column_search(grid, (0, n), pairs, (0, first[1]))
        if np.all(found <= np.diff(first)):
            break
        first = np.concatenate(([0], np.cumsum(found)))
    out, begin = _by_first(pairs, (first, found), n)
    if threads > 1:
        _sort_partners_parts(out, begin, threads)
    else:
        _sort_partners(out, begin, (0, n))
    return out


@njit(cache=True)
def _column_grid(c, r, pad, cells):
    """The spheres sorted by their cells (``cells`` as :func:`_column_pairs`): (centres, radii, the
    spheres' numbers, their cells, where each cell's run starts, the grid's dims)."""
    origin, h, dims = cells
    n = c.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    n_slots = nx * ny * nz
    slot = np.empty(n, dtype=np.int64)
    for i in range(n):
        slot[i] = ((_cell(_lo(c, r, pad, i, 0), origin[0], h) * ny + _cell(_lo(c, r, pad, i, 1), origin[1], h)) * nz
                   + _cell(_lo(c, r, pad, i, 2), origin[2], h))
    order, slots = radix_argsort(slot, n_slots)
    start = _starts(slots, n_slots)
    cs = np.empty((n, 3))
    rs = np.empty(n)
    for p in range(n):  # in cell order: spheres near in space are near in memory
        i = order[p]
        cs[p, 0], cs[p, 1], cs[p, 2] = c[i, 0], c[i, 1], c[i, 2]
        rs[p] = r[i]
    return cs, rs, order, slots, start, dims


@njit(cache=True, parallel=True)
def _search_parts(grid, pairs, first, found):
    """:func:`_column_search` of the ``len(found)`` parts of the spheres in parallel, part t into
    the rows ``first[t]`` .. ``first[t + 1]`` of ``pairs``, its count into ``found[t]``."""
    threads = len(found)
    n = len(grid[0])
    for t in prange(threads):
        found[t] = _column_search(grid, (n * t // threads, n * (t + 1) // threads), pairs, (first[t], first[t + 1]))


@njit(cache=True)
def _column_search(grid, spheres, pairs, rows):
    """The pairs of the sorted spheres ``spheres`` = (first, end) with their partners (the 13 forward
    cells and their own), as (min, max) in ``pairs`` rows ``rows`` = (first, end) while they fit;
    how many were found (a buffer grown inside the loop measured 25% slower)."""
    cs, rs, order, slots, start, dims = grid
    nx, ny, nz = dims[0], dims[1], dims[2]
    k, capacity = rows[0], rows[1]
    for p in range(spheres[0], spheres[1]):
        i = order[p]
        z0 = slots[p] % nz
        y0 = (slots[p] // nz) % ny
        x0 = slots[p] // (ny * nz)
        x, y, z, radius = cs[p, 0], cs[p, 1], cs[p, 2], rs[p]
        z_low, z_top = max(z0 - 1, 0), min(z0 + 1, nz - 1)
        for run in range(5):  # the own column from p on, then (x, y+1), (x+1, y-1 .. y+1)
            if run == 0:
                first, last = p + 1, start[slots[p] + z_top - z0 + 1]
            else:
                cx, cy = (x0, y0 + 1) if run == 1 else (x0 + 1, y0 + run - 3)
                if cx >= nx or cy < 0 or cy >= ny:
                    continue
                base = (cx * ny + cy) * nz
                first, last = start[base + z_low], start[base + z_top + 1]
            for q in range(first, last):
                if _near(x, y, z, radius, cs, rs, q):
                    if k < capacity:
                        j = order[q]
                        pairs[k, 0], pairs[k, 1] = min(i, j), max(i, j)
                    k += 1
    return k - rows[0]


@njit(cache=True)
def _by_first(pairs, parts, n):
    """The pairs of ``parts`` = (first rows, counts) of ``pairs`` (each (i, j), i < j < ``n``) laid out
    by i (a counting sort), and where each i's begin (n + 1,). With each i's few j then sorted by
    insertion (:func:`_sort_partners`), the pairs are in lexicographic order: one pass fewer than the
    radix sort of the keys i n + j (:func:`.common.sort_pairs`), and the insertion in parallel."""
    first, found = parts
    begin = np.zeros(n + 1, np.int64)
    for t in range(len(found)):
        for row in range(first[t], first[t] + found[t]):
            begin[pairs[row, 0] + 1] += 1
    for i in range(n):
        begin[i + 1] += begin[i]
    out = np.empty((begin[n], 2), dtype=np.int64)
    fill = begin[:n].copy()
    for t in range(len(found)):
        for row in range(first[t], first[t] + found[t]):
            i = pairs[row, 0]
            out[fill[i], 0], out[fill[i], 1] = i, pairs[row, 1]
            fill[i] += 1
    return out, begin


@njit(cache=True, parallel=True)
def _sort_partners_parts(out, begin, threads):
    """:func:`_sort_partners` of all the spheres, in ``threads`` parts in parallel."""
    n = len(begin) - 1
    for t in prange(threads):
        _sort_partners(out, begin, (n * t // threads, n * (t + 1) // threads))


@njit(cache=True)
def _sort_partners(out, begin, spheres):
    """Each sphere i of ``spheres`` = (first, end): its partners ``out[begin[i]:begin[i + 1], 1]`` sorted
    (insertion: a few each)."""
    for i in range(spheres[0], spheres[1]):
        for k in range(begin[i] + 1, begin[i + 1]):
            j, m = out[k, 1], k
            while m > begin[i] and out[m - 1, 1] > j:
                out[m, 1] = out[m - 1, 1]
                m -= 1
            out[m, 1] = j
