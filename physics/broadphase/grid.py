"""Uniform grid: dense cells over the scene's bounding box, one counter per cell.

Spheres are counting-sorted by cell (count per cell, prefix sum, fill: O(n + cells),
no hashing, no comparison sort); each sphere then tests its own cell and 13 of its 26
neighbours. The cell edge comes from the radii: just over the median padded box width,
2 (r + pad), so equal spheres fill cells about 0.36 each at the study's density and
every overlapping pair sits in the same or adjacent cells.

Spheres larger than a cell live on coarser grids of 2, 4, 8... times the edge (the
hierarchy is in :mod:`.cells`): a sphere spanning many cells is neither entered in all
of them nor forces the whole grid to its size. Spheres all alike (the widest at most twice
the median) share one level of cells as wide as the widest, searched a column of three
cells at a time.

A dense grid needs a bounded world: when the bounding box would hold more than
:data:`~.cells.MAX_CELLS_PER_BODY` cells per sphere (a far outlier, or tiny spheres
spread wide), the cells are made larger, and in the limit the grid degrades to one
cell, brute force. The spatial hash (:mod:`.spatial_hash`) has no such limit.
"""

from __future__ import annotations

import numpy as np

from .cells import hierarchy_pairs


def grid_pairs(c: np.ndarray, r: np.ndarray, threads: int = 1) -> np.ndarray:
    """Overlapping pairs by a uniform grid; ``c`` (n, 3), ``r`` (n,) checked. Sorted, int64 (k, 2).

    Spheres alike in size, from :data:`~.cells.PARALLEL_BODIES` of them, are searched on ``threads``
    of Numba's threads (the rigid solver's ``threads`` setting): the same pairs in the same order."""
    return hierarchy_pairs(c, r, hashed=False, threads=threads)
