"""The contact solver's sweep order: manifolds coloured so that a colour's can be solved in parallel.

A Gauss–Seidel sweep solves one contact after another, each seeing the velocities its
predecessors left. Two manifolds that share no dynamic body do not read or write each other's
velocities, so among a set of such manifolds the order does not matter: a *colour*. The sweep
visits the colours in turn and the manifolds of one colour in any order, or at once on several
threads, and gets the same bytes either way, since each body's velocity is changed by at most
one manifold of a colour, and the points of one manifold are solved one after the other in one
thread. This is Box2D v3's constraint graph (``constraint_graph.c``): static shapes (b < 0) touch
no velocity and are left out of the colouring, so a box on the floor and on a neighbour needs
one colour less.

Colouring is greedy, in the manifolds' sorted order (a, b): each takes the lowest colour that
neither of its bodies has yet (at most 2 d - 1 colours, d the most manifolds at one body; the
edge colouring of :func:`steplab.integrators.colouring.greedy_edge_colouring`, here compiled,
for it runs every step). A manifold that finds all :data:`COLOURS` colours taken goes to the
*overflow*, swept last on one thread, as Box2D's overflow constraints are.

On two threads a colour is cut in two at a plane that halves the pile (:func:`sides`), not at its
middle manifold: each thread then sweeps the same side's bodies in every colour, and integrates
them, so a body's velocity stays in the cache of the core that changes it.

Which order a scene is swept in depends on the scene alone (:data:`.rigid_solver_step.COLOURED_BODIES`
bodies or more: coloured), never on the number of threads, and the coloured order gives the same
bytes on one thread or many. Smaller scenes keep the sorted order (a, b) (:func:`in_sorted_order`),
for two reasons. It is the order their results were always computed in, byte for byte. And it is
the better order for a stack: bodies numbered from the bottom up are swept from the bottom up, so
one sweep carries the support up the stack; the coloured order interleaves the rows, and the
20-row pyramid's top box, which moves 7.2 mm from 1 s to 10 s in the sorted order, moved 15.6 mm
(9.0 mm with the colours visited in reverse), against the 1 cm that "stands" allows.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.cpython.unsafe.numbers import trailing_zeros

#: colours a body's 64-bit mask can hold; a manifold finding them all taken goes to the overflow
COLOURS = 64
#: a colour of fewer manifolds than this is swept on one thread (``Colours.serial_below``): a parallel
#: region ends when its slowest thread does, and a step opened one per colour and pass (6 to 21
#: colours, 12 passes); the 10^4 box pit's last colours hold a few hundred manifolds down to one,
#: tens of microseconds of work at most, against a wait of up to a time slice for a thread that
#: another process holds
SERIAL_MANIFOLDS = 512


class Colours(NamedTuple):
    """The sweep order of contacts laid out colour by colour (:func:`colour_contacts`): manifold m is
    rows ``rows[m] .. rows[m + 1] - 1``; colour c is manifolds ``colour_start[c] .. colour_start[c + 1] - 1``,
    those of the bodies on side 0 of the step's cut first, side 1's from ``side_start[c]``; the groups
    from ``parallel`` on (the overflow, if any) are swept on one thread, the colours cut into ``threads``
    parts. The bodies, side 0's then side 1's from ``body_cut``, are ``bodies``.
    (The thread count is handed in, not read in the kernels: a kernel that calls
    ``numba.get_num_threads`` cannot be cached.)"""

    rows: np.ndarray          # (B + 1,) int64 each manifold's first row, then the row count
    colour_start: np.ndarray  # (G + 1,) int64 each non-empty colour's first manifold, then B
    side_start: np.ndarray    # (G,) int64 each colour's first manifold of side 1 (its end: none)
    parallel: int             # how many of the G groups are colours (the rest, the overflow, serial)
    threads: int              # the parts a colour is cut into: Numba's thread count (the bytes do not depend on it)
    serial_below: int         # a colour of fewer manifolds is swept on one thread (:func:`next_groups`)
    bodies: np.ndarray        # (N,) int64 the bodies, side 0's then side 1's, each side ascending
    body_cut: int             # where side 1's start among ``bodies``


@njit(cache=True)
def manifold_rows(a, b):
    """Where each manifold's points start among contacts sorted by (a, b, ...), and their count
    last: (manifolds + 1,), the points of manifold m at rows[m]:rows[m + 1]."""
    count = len(a)
    rows = np.empty(count + 1, np.int64)
    blocks = 0
    for k in range(count):
        if k == 0 or a[k] != a[k - 1] or b[k] != b[k - 1]:
            rows[blocks] = k
            blocks += 1
    rows[blocks] = count
    return rows[:blocks + 1]


@njit(cache=True)
def colour_contacts(a, b, side, threads):
    """(order, :class:`Colours`) of contacts sorted by (a, b, ...) between the bodies of ``side`` (b < 0:
    a static shape), to be swept on ``threads`` threads.

    ``order`` (C,) lists the rows colour by colour, the manifolds of one colour in their sorted
    order and the points of one manifold together, in theirs; the colours' rows and manifolds are
    those of the contacts taken in that order, which the sweep streams through. Within a colour the
    manifolds whose body a is on side 0 of the step's cut come first (``side`` (N,) 0 or 1 for each
    body, :func:`sides`), so that a colour's two parts on two threads are its two sides: each thread
    then finds the bodies it changes where it left them, in its own cache (a colour cut at its middle
    handed 12 % of the 10^4 box pit's body visits from one core's cache to the other's; cut at the
    sides, 0.6 %). Reordering a colour's manifolds changes no byte: they share no body.

    Two passes: one over the points, which finds the manifolds and colours each (its colour the
    lowest bit clear in its bodies' masks, one count of trailing zeros), and one over the
    manifolds, which lays each out after those of its colour and side before it (a counting sort:
    stable, so each colour's side keeps the sorted order)."""
    count, n = len(a), len(side)
    used = np.zeros(n, np.uint64)  # the colours each body has, as bits
    colour = np.empty(count, np.int64)  # bucket 2 c + side of each manifold (at most one per point)
    start = np.empty(count + 1, np.int64)  # each manifold's first point
    sizes = np.zeros(2 * (COLOURS + 1), np.int64)  # manifolds of each colour and side (COLOURS: the overflow)
    points = np.zeros(2 * (COLOURS + 1), np.int64)  # and their points
    blocks, c, one = 0, 0, np.uint64(1)
    for k in range(count):
        if k == 0 or a[k] != a[k - 1] or b[k] != b[k - 1]:
            i, j = a[k], b[k]
            free = ~(used[i] | used[j] if j >= 0 else used[i])
            if free:
                c = np.int64(trailing_zeros(free))
                bit = one << np.uint64(c)  # the lowest bit clear in both masks, taken
                used[i] |= bit
                if j >= 0:
                    used[j] |= bit
            else:
                c = COLOURS
            c = 2 * c + side[i]
            colour[blocks], start[blocks] = c, k
            sizes[c] += 1
            blocks += 1
        points[c] += 1
    start[blocks] = count
    groups, parallel = 0, 0
    first = np.zeros(2 * (COLOURS + 1), np.int64)  # each bucket's next place among the manifolds
    row = np.zeros(2 * (COLOURS + 1), np.int64)  # and its next row
    colour_start = np.zeros(COLOURS + 2, np.int64)
    side_start = np.zeros(COLOURS + 1, np.int64)
    rows = 0
    for c in range(COLOURS + 1):
        if sizes[2 * c] + sizes[2 * c + 1] > 0:
            first[2 * c], row[2 * c] = colour_start[groups], rows
            first[2 * c + 1] = side_start[groups] = colour_start[groups] + sizes[2 * c]
            row[2 * c + 1] = rows + points[2 * c]
            colour_start[groups + 1] = side_start[groups] + sizes[2 * c + 1]
            rows += points[2 * c] + points[2 * c + 1]
            groups += 1
            if c < COLOURS:
                parallel = groups
    laid = np.empty(blocks + 1, np.int64)
    laid[blocks] = count
    order = np.empty(count, np.int64)
    for m in range(blocks):
        c = colour[m]
        laid[first[c]] = row[c]
        first[c] += 1
        for k in range(start[m], start[m + 1]):
            order[row[c]] = k
            row[c] += 1
    bodies = np.argsort(side, kind="mergesort")  # stable: side 0's bodies, then side 1's, each ascending
    return order, Colours(laid, colour_start[:groups + 1], side_start[:groups], parallel, max(threads, 1),
                          SERIAL_MANIFOLDS, bodies, n - np.sum(side))


def sides(q, movable):
    """Each body's side, 0 or 1 (int64), of a plane that halves the ``movable`` bodies' centres ``q``
    (N, 3) across one of their wide extents: the two halves of a pile touch along the plane alone (the
    10^4 box pit's step 30: 0.6 % of its manifolds join the two sides), so two threads that each take
    one side hand few bodies to each other. Pinned bodies are on the side of their centre.

    Of the extents at least :data:`WIDE` of the widest, the plane is across the one whose sides cut
    the bodies' numbering into the fewest runs. A body's rows of v, omega and the other body columns
    share cache lines with its neighbours in the numbering (a line holds 2.7 rows of v), and where
    two neighbours are on two sides, the two threads write one line: each write takes the line
    from the other core's cache. The 10^4 box pit is numbered along x, then y, then layer by layer;
    across x (as wide as y) its sides changed 364 times along the numbering, 317 of v's 3,750 lines
    written by both threads; across y 62 to 80 times. In the machine's slow state, which hands a line
    between the cores more slowly, that took its 2-thread step from 16.7 to 18.1 ms to 14.7 to 16.7 ms
    (medians 17.1 and 15.5; docs/performance.md); the bytes do not depend on the sides."""
    if not movable.any():
        return np.zeros(len(q), np.int64)
    moving = q[movable]
    # a column at a time: NumPy's reductions along the first axis of an (N, 3) array took 0.43 ms of
    # the 10^4 pit's step, against 0.13 ms for the whole of this
    extent = [np.ptp(moving[:, k]) for k in range(3)]
    chosen, fewest = None, -1
    for axis in (k for k in range(3) if extent[k] >= WIDE * max(extent)):
        side = (q[:, axis] >= np.median(moving[:, axis])).astype(np.int64)
        runs = np.count_nonzero(side[1:] != side[:-1])
        if chosen is None or runs < fewest:
            chosen, fewest = side, runs
    return chosen


#: an extent of the pile this fraction of its widest is wide enough to be cut across (:func:`sides`): the
#: plane's section, where the two sides' bodies touch, is then at most 1 / WIDE the narrowest possible
WIDE = 0.75


@njit(cache=True)
def in_sorted_order(a, b, n):
    """(order, :class:`Colours`) that sweep contacts sorted by (a, b, ...) between ``n`` bodies in that
    order, on one thread: the identity order, all manifolds in one serial group."""
    rows = manifold_rows(a, b)
    blocks = len(rows) - 1
    colour_start = np.zeros(2 if blocks else 1, np.int64)
    colour_start[-1] = blocks
    return np.arange(len(a)), Colours(rows, colour_start, colour_start[1:].copy(), 0, 1, SERIAL_MANIFOLDS,
                                      np.arange(n), n)


@njit(cache=True, inline="always")
def span(start, end, part, parts):
    """Part ``part`` of ``parts`` nearly equal parts of start .. end - 1: (its first, its end)."""
    return start + (end - start) * part // parts, start + (end - start) * (part + 1) // parts


@njit(cache=True, inline="always")
def piece(bounds, part, parts):
    """Part ``part`` of ``parts`` of the manifolds ``bounds`` = (first, side 1's first, end) (or of the
    bodies, :attr:`Colours.bodies`): an even number of parts takes half of them from each side, nearly
    equal; an odd number cuts first .. end - 1 into nearly equal parts, whatever the sides."""
    first, middle, end = bounds
    if parts % 2:
        return span(first, end, part, parts)
    half = parts // 2
    return span(first, middle, part, half) if part < half else span(middle, end, part - half, half)


@njit(cache=True, inline="always")
def rows_of(colours, group, part, parts):
    """(first, end) rows of part ``part`` of ``parts`` of group ``group``'s manifolds (:func:`piece`): the
    rows that part's thread sweeps when the group is cut into parts, for the passes over each
    contact alone (gathering, effective masses) to leave each row in that thread's cache."""
    start = colours.colour_start
    first, end = piece((start[group], colours.side_start[group], start[group + 1]), part, parts)
    return colours.rows[first], colours.rows[end]


@njit(cache=True, inline="always")
def bodies_of(colours, part):
    """(first, end) in ``colours.bodies`` of part ``part`` of ``colours.threads`` (:func:`piece`): the bodies
    that part's thread integrates and starts, those of the side it sweeps."""
    return piece((0, colours.body_cut, len(colours.bodies)), part, colours.threads)


@njit(cache=True, inline="always")
def next_groups(colours, group):
    """((first, side 1's first, end) manifolds, parts, the group after them) of the sweep from group
    ``group`` of ``colours`` on: a colour of at least ``colours.serial_below`` manifolds alone, cut into
    ``colours.threads`` parts (:func:`piece`); or the run of groups from ``group`` up to the next such
    colour (small colours, the overflow, the sorted order's one group), whose manifolds are
    consecutive, in one part: one parallel region on one thread instead of one per group. (Calling
    the sweep's kernel outside a parallel region instead made it 1.5 times slower: Numba's code for
    the loop's body is faster.) The bytes do not depend on it."""
    start, groups = colours.colour_start, len(colours.colour_start) - 1

    def cut(g):  # whether group g is a colour swept in parts
        return colours.threads > 1 and g < colours.parallel and start[g + 1] - start[g] >= colours.serial_below

    if cut(group):
        return (start[group], colours.side_start[group], start[group + 1]), colours.threads, group + 1
    last = group + 1
    while last < groups and not cut(last):
        last += 1
    return (start[group], start[last], start[last]), 1, last
