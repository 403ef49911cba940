"""Spatial hashing: grid cells without the grid, for unbounded worlds.

The same cells as :mod:`.grid` (edge from the radii, coarser levels for larger
spheres, each sphere testing its own cell and 13 neighbours), but a cell's integer
coordinates (level, x, y, z) are hashed into a table of about two buckets per sphere
instead of indexing a dense array over the bounding box. Memory is O(n) however far
apart the spheres are, and the cells never grow to fit the world. Different cells can
share a bucket; spheres are paired only when their cells match, so a collision costs
time, never correctness.

Hash: Teschner et al. (2003), ``(x p1) xor (y p2) xor (z p3)`` with large primes (and
a fourth for the level), then Knuth's multiplicative hash, whose top bits pick the bucket.
"""

from __future__ import annotations

import numpy as np

from .cells import hierarchy_pairs


def hash_pairs(c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Overlapping pairs by spatial hashing; ``c`` (n, 3), ``r`` (n,) checked. Sorted, int64 (k, 2)."""
    return hierarchy_pairs(c, r, hashed=True)
