"""Bounding-volume hierarchy: a binary tree of boxes, median split, self-traversal, refit.

Build (top down): a node's spheres are split in half at the median centre along the
axis where the centres spread most (quickselect, O(size)), until at most
:data:`LEAF_SIZE` spheres remain. Every level costs O(n), so the build is O(n log n)
and the tree is balanced (depth ceil(log2(n / LEAF_SIZE)) + 1).

Self-traversal (the tree against itself): start from the pair (root, root). A node
against itself descends into (left, left), (right, right) and (left, right); two
different nodes whose boxes do not overlap are dropped with all their descendants;
otherwise the node with more spheres is split. Leaf against leaf tests every pair
with the exact sphere test. Each unordered pair of spheres is met exactly once.

Refit: moving spheres keep the tree's topology; only the boxes are recomputed, bottom
up, in O(n). The tree is then looser than a fresh build (the overlap tests cull less),
so a game refits for a few frames and rebuilds when the queries slow down.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .common import append_pair, as_spheres, no_pairs, padding, sort_pairs, spheres_overlap

#: spheres per leaf: fewer means a deeper tree, more means more exact tests per leaf pair
LEAF_SIZE = 4


class Topology(NamedTuple):
    """The tree without its boxes (what a refit keeps): the bodies in leaf order, each node's
    children (-1 for a leaf; children have larger indices than parents) and its run of ``order``."""

    order: np.ndarray
    left: np.ndarray
    right: np.ndarray
    first: np.ndarray
    count: np.ndarray


class BoundingVolumeHierarchy:
    """A median-split BVH over spheres, with a self-traversal for all overlapping pairs.

    >>> tree = BoundingVolumeHierarchy(centers, radii)
    >>> pairs = tree.pairs()                  # == find_pairs(centers, radii)
    >>> tree.refit(centers + v * dt, radii)   # same bodies, new places: boxes only
    >>> pairs = tree.pairs()                  # still exact, the tree is only looser

    Attributes
    ----------
    topology : Topology
        ``order, left, right, first, count`` below, as the kernels take them.
    order : ndarray, shape (n,)
        The bodies in leaf order (each leaf a contiguous run).
    left, right : ndarray, shape (m,)
        Children of each node (-1 for a leaf); children have larger indices than parents.
    first, count : ndarray, shape (m,)
        Each node's run of ``order``.
    box_lo, box_hi : ndarray, shape (m, 3)
        Each node's box (the union of its spheres' padded boxes).
    """

    def __init__(self, centers, radii, leaf_size: int = LEAF_SIZE):
        if not (isinstance(leaf_size, int | np.integer) and leaf_size >= 1):
            raise ValueError(f"leaf_size must be an integer >= 1, got {leaf_size!r}")
        c, r = as_spheres(centers, radii)
        self.leaf_size = int(leaf_size)
        self.topology = _build(c, self.leaf_size)
        self.order, self.left, self.right, self.first, self.count = self.topology
        self.refit(c, r)

    @property
    def n(self) -> int:
        return len(self.order)

    def refit(self, centers, radii) -> None:
        """New positions and radii for the same bodies: recompute every box, bottom up, O(n)."""
        c, r = as_spheres(centers, radii)
        if len(c) != self.n:
            raise ValueError(f"refit needs the same {self.n} bodies the hierarchy was built for, got {len(c)}; "
                             "build a new BoundingVolumeHierarchy")
        # bodies in leaf order: leaf tests read memory in sequence
        self._c, self._r, self.box_lo, self.box_hi = _refit(c, r, padding(c, r), self.topology)

    def pairs(self) -> np.ndarray:
        """All overlapping pairs, int64 (k, 2), rows i < j, sorted lexicographically."""
        if self.n < 2:
            return no_pairs()
        pairs, k = _self_pairs(self._c, self._r, self.topology, self.box_lo, self.box_hi)
        return sort_pairs(pairs, k, self.n)


def bvh_pairs(c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Overlapping pairs by building a BVH and traversing it against itself. Sorted, int64 (k, 2)."""
    return BoundingVolumeHierarchy(c, r).pairs()


@njit(cache=True)
def _select(order, centre, s, e, kth, axis):
    """Hoare quickselect on ``centre[axis]``: afterwards positions before ``kth`` are <= it, after are >=.

    ``centre`` (3, n) is permuted along with ``order``, so every pass reads memory in sequence.
    """
    lo, hi = s, e - 1
    key = centre[axis]
    while lo < hi:
        pivot = key[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while key[i] < pivot:
                i += 1
            while key[j] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                for a in range(3):
                    centre[a, i], centre[a, j] = centre[a, j], centre[a, i]
                i += 1
                j -= 1
        if kth <= j:
            hi = j
        elif kth >= i:
            lo = i
        else:
            break


@njit(cache=True)
def _build(c, leaf_size):
    n = c.shape[0]
    order = np.arange(n)
    capacity = max(1, 2 * n)
    left = np.full(capacity, -1, dtype=np.int64)
    right = np.full(capacity, -1, dtype=np.int64)
    first = np.zeros(capacity, dtype=np.int64)
    count = np.zeros(capacity, dtype=np.int64)
    centre = np.ascontiguousarray(c.T)  # (3, n), kept in the order of ``order``
    # depth-first with an explicit stack; median splits keep the depth below 64 for any n
    stack = np.empty((128, 3), dtype=np.int64)
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, 0, n
    top, m = 1, 1
    while top > 0:
        top -= 1
        node, s, e = stack[top, 0], stack[top, 1], stack[top, 2]
        first[node], count[node] = s, e - s
        if e - s <= leaf_size:
            continue
        axis, spread = 0, -1.0
        for a in range(3):
            low, high = np.inf, -np.inf
            for p in range(s, e):
                low, high = min(low, centre[a, p]), max(high, centre[a, p])
            if high - low > spread:
                axis, spread = a, high - low
        mid = (s + e) // 2
        _select(order, centre, s, e, mid, axis)
        left[node], right[node] = m, m + 1
        stack[top, 0], stack[top, 1], stack[top, 2] = m + 1, mid, e
        stack[top + 1, 0], stack[top + 1, 1], stack[top + 1, 2] = m, s, mid
        top += 2
        m += 2
    return Topology(order, left[:m].copy(), right[:m].copy(), first[:m].copy(), count[:m].copy())


@njit(cache=True)
def _refit(c, r, pad, topology):
    """Bodies gathered into leaf order, and every node's box, bottom up."""
    order, left, right, first, count = topology
    n, m = order.shape[0], left.shape[0]
    cl = np.empty((n, 3))
    rl = np.empty(n)
    for p in range(n):
        rl[p] = r[order[p]]
        for a in range(3):
            cl[p, a] = c[order[p], a]
    box_lo = np.empty((m, 3))
    box_hi = np.empty((m, 3))
    for node in range(m - 1, -1, -1):  # children have larger indices: bottom up
        for a in range(3):
            if left[node] < 0:
                low, high = np.inf, -np.inf
                for p in range(first[node], first[node] + count[node]):
                    # the padded box exactly as common.bounds computes it: c -/+ (r + pad)
                    low, high = min(low, cl[p, a] - (rl[p] + pad)), max(high, cl[p, a] + (rl[p] + pad))
            else:
                low = min(box_lo[left[node], a], box_lo[right[node], a])
                high = max(box_hi[left[node], a], box_hi[right[node], a])
            box_lo[node, a], box_hi[node, a] = low, high
    return cl, rl, box_lo, box_hi


@njit(cache=True)
def _self_pairs(c, r, topology, box_lo, box_hi):
    """Every overlapping pair of the leaf-ordered spheres ``c, r``, by the self-traversal (module docstring)."""
    order, left, right, first, count = topology
    n = order.shape[0]
    pairs = np.empty((n + 16, 2), dtype=np.int64)
    k = 0
    stack = np.empty((256, 2), dtype=np.int64)
    stack[0, 0], stack[0, 1] = 0, 0
    top = 1
    while top > 0:
        top -= 1
        a, b = stack[top, 0], stack[top, 1]
        if top + 3 > stack.shape[0]:
            bigger = np.empty((2 * stack.shape[0], 2), dtype=np.int64)
            bigger[: stack.shape[0]] = stack
            stack = bigger
        if a == b:
            if left[a] < 0:
                for p in range(first[a], first[a] + count[a]):
                    for q in range(p + 1, first[a] + count[a]):
                        if spheres_overlap(c, r, p, q):
                            pairs, k = append_pair(pairs, k, order[p], order[q])
            else:
                stack[top, 0], stack[top, 1] = left[a], right[a]
                stack[top + 1, 0], stack[top + 1, 1] = right[a], right[a]
                stack[top + 2, 0], stack[top + 2, 1] = left[a], left[a]
                top += 3
            continue
        if not (box_lo[b, 0] <= box_hi[a, 0] and box_lo[a, 0] <= box_hi[b, 0] and box_lo[b, 1] <= box_hi[a, 1]
                and box_lo[a, 1] <= box_hi[b, 1] and box_lo[b, 2] <= box_hi[a, 2] and box_lo[a, 2] <= box_hi[b, 2]):
            continue
        if left[a] < 0 and left[b] < 0:
            for p in range(first[a], first[a] + count[a]):
                for q in range(first[b], first[b] + count[b]):
                    if spheres_overlap(c, r, p, q):
                        pairs, k = append_pair(pairs, k, order[p], order[q])
        elif left[b] < 0 or (left[a] >= 0 and count[a] >= count[b]):
            stack[top, 0], stack[top, 1] = left[a], b
            stack[top + 1, 0], stack[top + 1, 1] = right[a], b
            top += 2
        else:
            stack[top, 0], stack[top, 1] = a, left[b]
            stack[top + 1, 0], stack[top + 1, 1] = a, right[b]
            top += 2
    return pairs, k
