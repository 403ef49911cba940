"""Where the position-based sweep keeps each body: the rows of its coordinate arrays (a permutation).

The sweep (:mod:`.constraint_projection`) projects eight constraints of one colour at once, and
where their ends lie in runs (i + l and j + l for the eight lanes l) it reads each coordinate of
the sixteen bodies as two vector loads; elsewhere it loads sixteen scattered values. Only the
order in which each body receives its projections fixes the result, and relabelling the bodies
changes no projection's arithmetic, so the bodies may be kept in any rows: the same bytes.

On a cloth in its grid numbering the vertical and shear springs of a colour already lie in runs,
but a row's horizontal springs do not: the chain 0 - 1 - 2 - ... is coloured alternately, so a
colour holds (0, 1), (2, 3), (4, 5), ..., whose ends advance by 2. Laying each chain out with its
even places first and its odd places after, (0, 2, 4, ..., 1, 3, 5, ...), turns both of a chain's
colours into runs, (k, h + k) and (h + k, k + 1) with h the number of even places, and keeps the
vertical and shear springs in runs, since every row of a grid is laid out alike. A chain is a
maximal sequence of bodies b, b + 1, ... joined by constraints between neighbours in number (a
cloth's row, a rope), cut into pieces of at most :data:`CHAIN` bodies so that no constraint
reaches far (the sweep's bands, :func:`.constraint_projection.wavefront`, keep a window of
bodies in the caches that grows with the reach). :func:`arranged` keeps the model's own numbering
where the chains' layout would put fewer constraints in runs (a numbering with no chains).

On the bench's 160 x 160 cloth (101,442 springs): in the grid numbering 47 % of the blocks of
eight lie in runs by 1, 45 % by 2; with the chains laid out, 97.5 % in runs by 1, a block's two
halves of four each a run (docs/performance.md).
"""

from __future__ import annotations

import numpy as np

#: the longest piece of a chain laid out evens-then-odds: a constraint within it reaches at most half
#: of it, so the sweep's bands stay in the core's L2 cache (a 160-body cloth row is one piece)
CHAIN = 1024


def chain_rows(i: np.ndarray, j: np.ndarray, n_bodies: int, longest: int = CHAIN) -> np.ndarray:
    """Each body's row (N,) int64 with every chain of constraints (b, b + 1) laid out even places first.

    Pieces of a chain are at most ``longest`` bodies; a body in no chain keeps its number.
    """
    low, high = np.minimum(i, j).astype(np.int64), np.maximum(i, j).astype(np.int64)
    linked = np.zeros(n_bodies, bool)  # linked[b]: a constraint joins b and b + 1
    linked[low[high == low + 1]] = True
    starts = np.ones(n_bodies, bool)
    starts[1:] = ~linked[:-1]
    chain = np.cumsum(starts) - 1
    first = np.flatnonzero(starts)
    place = np.arange(n_bodies) - first[chain]
    length = np.diff(np.append(first, n_bodies))[chain]
    piece_start = place // longest * longest
    evens = (np.minimum(length - piece_start, longest) + 1) // 2  # even places in the body's piece
    within = place - piece_start
    return first[chain] + piece_start + np.where(within % 2 == 0, within // 2, evens + within // 2)


def relabelled(constraints, rows: np.ndarray):
    """``constraints`` with their bodies as rows: i -> rows[i], j -> rows[j] (same dtype)."""
    return constraints._replace(i=rows[constraints.i].astype(constraints.i.dtype),
                                j=rows[constraints.j].astype(constraints.j.dtype))


def in_rows(a: np.ndarray, rows: np.ndarray, axis: int = 0) -> np.ndarray:
    """A per-body array in the sweep's rows: out[rows[b]] = a[b] along ``axis``."""
    out = np.empty_like(a)
    index = [slice(None)] * a.ndim
    index[axis] = rows
    out[tuple(index)] = a
    return out


def arranged(constraints, colours, n_bodies: int):
    """The bodies' rows and the constraints as the sweep visits them: (rows (N,) int64, constraints relabelled
    and in :func:`.constraint_projection.wavefront`'s order, segment starts).

    ``constraints`` in colour order (:func:`.constraint_projection.ordered`, ``colours`` its colour
    starts). Of the model's numbering and the chains' layout (:func:`chain_rows`), the one whose
    sweep reads more blocks as runs by 1 (:func:`.constraint_projection.layouts`); the model's on a tie.
    """
    from .constraint_projection import RUN, layouts, wavefront

    best = None
    for rows in (np.arange(n_bodies), chain_rows(constraints.i, constraints.j, n_bodies)):
        swept, segments = wavefront(relabelled(constraints, rows), colours)
        runs = np.count_nonzero(layouts(swept.i, swept.j, segments) == RUN)
        if best is None or runs > best[0]:
            best = (runs, rows, swept, segments)
    return best[1:]
