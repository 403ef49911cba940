"""Greedy graph colouring: the independent sets a vertex-parallel Gauss-Seidel sweep visits in turn.

Two vertices joined by a spring read each other's positions, so a sweep that updates a set of
vertices at once (vertex block descent) needs sets with no spring inside: the colours of a
proper colouring. Greedy colouring in vertex order gives each vertex the smallest colour that
none of its already-coloured neighbours has, so it uses at most (largest degree + 1) colours
(Welsh and Powell, 1967); on steplab's cloth grids (8 neighbours inside) that is at most 9.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Adjacency(NamedTuple):
    """The spring graph in compressed rows: vertex a's incident springs are ``spring[offsets[a]:offsets[a + 1]]``,
    each with the vertex at its other end ``other`` (int64 ndarrays; offsets shape (N + 1,), the others (2P,))."""

    offsets: np.ndarray
    other: np.ndarray
    spring: np.ndarray


def adjacency(n: int, i: np.ndarray, j: np.ndarray) -> Adjacency:
    """Each of the ``n`` vertices' incident springs (spring p joins ``i[p]`` and ``j[p]``), in spring order.

    A spring joining a body to itself is refused in one line: no colouring separates its ends.
    """
    i, j = np.asarray(i, np.int64), np.asarray(j, np.int64)
    if np.any(i == j):
        p = int(np.flatnonzero(i == j)[0])
        raise ValueError(f"spring {p} joins body {i[p]} to itself: no colouring separates its ends")
    ends = np.concatenate([i, j])
    order = np.argsort(ends, kind="stable")
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(ends, minlength=n), out=offsets[1:])
    p = np.arange(len(i), dtype=np.int64)
    return Adjacency(offsets, np.concatenate([j, i])[order], np.concatenate([p, p])[order])


def greedy_colouring(graph: Adjacency) -> np.ndarray:
    """A proper colouring of ``graph``: colour (int64, shape (N,)), no spring joining two vertices of
    one colour. Vertices are coloured in index order, each with the smallest colour its neighbours lack."""
    colour = np.full(len(graph.offsets) - 1, -1, np.int64)
    for a in range(len(colour)):
        taken = set(colour[graph.other[graph.offsets[a]:graph.offsets[a + 1]]].tolist())
        c = 0
        while c in taken:
            c += 1
        colour[a] = c
    return colour


def greedy_edge_colouring(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """A proper edge colouring of the graph of ``n`` vertices and edges (i[p], j[p]): colour (int64, shape
    (P,)), no two edges of one colour sharing a vertex. Edges are coloured in order, each with the
    smallest colour neither end has yet: at most 2 (largest degree) - 1 colours (8 on steplab's cloths).

    What the constraint sweep of the position-based methods is ordered by: the projections of one
    colour move disjoint pairs, so consecutive projections do not wait on each other's results.
    """
    used = [0] * n  # per vertex, the colours of its edges so far, as the bits of an (unbounded) int
    colour = np.empty(len(i), np.int64)
    for p, (a, b) in enumerate(zip(np.asarray(i).tolist(), np.asarray(j).tolist())):
        taken = used[a] | used[b]
        lowest_free = ~taken & (taken + 1)
        colour[p] = lowest_free.bit_length() - 1
        used[a] |= lowest_free
        used[b] |= lowest_free
    return colour
