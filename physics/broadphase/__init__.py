"""Broadphase: which pairs of bounding spheres overlap, without testing all n^2 pairs.

>>> from steplab.physics.broadphase import find_pairs
>>> find_pairs([[0, 0, 0], [1.5, 0, 0], [9, 9, 9]], [1.0, 0.5, 1.0], method="grid")
array([[0, 1]])

Every method returns exactly the same array: int64, shape (k, 2), each row i < j, rows
sorted lexicographically, the pairs with |c_i - c_j| <= r_i + r_j (touching counts).
The final test is one floating-point expression shared by all methods (see
:mod:`.common`), so they agree bit for bit, boundary cases included.

Methods (the lecture's "Reduced Collision Tests"):

- ``brute``: every pair, blocked and vectorised NumPy, O(n^2); the reference.
- ``grid``: a uniform grid over the bounding box (:mod:`.grid`).
- ``hash``: spatial hashing of the same cells, for unbounded worlds (:mod:`.spatial_hash`).
- ``sap``: sort and sweep along the axis of largest spread (:mod:`.sweep_and_prune`).
- ``sap-coherent``: :class:`CoherentSortAndSweep`, repairing last frame's order; a single
  call is a first frame (a full sort).
- ``bvh``: a median-split bounding-volume hierarchy, traversed against itself (:mod:`.bvh`).
"""

from __future__ import annotations

import numpy as np

from steplab.core.registry import Registry, function_entry

from .brute import brute_force_pairs as brute_force_pairs
from .bvh import BoundingVolumeHierarchy as BoundingVolumeHierarchy
from .bvh import bvh_pairs as bvh_pairs
from .common import as_spheres as as_spheres
from .grid import grid_pairs as grid_pairs
from .spatial_hash import hash_pairs as hash_pairs
from .sweep_and_prune import CoherentSortAndSweep as CoherentSortAndSweep
from .sweep_and_prune import sap_pairs as sap_pairs


def coherent_sap_pairs(c, r):
    """A first frame of :class:`CoherentSortAndSweep` (a full sort)."""
    return CoherentSortAndSweep().update(c, r)


#: a method that repairs last frame's answer: the broadphase study times it across frames
#: (its coherence experiment), not as a single call against n
coherent_sap_pairs.frame_coherent = True


#: every broadphase method, by name: a function of checked centres (n, 3) and radii (n,) returning
#: the pairs as :func:`find_pairs` does; then registered ones (``METHODS.register(f, name="...")``)
#: and the "steplab.broadphase" entry points
METHODS: Registry = Registry("steplab.broadphase", "broadphase method", [
    ("brute", brute_force_pairs), ("grid", grid_pairs), ("hash", hash_pairs), ("sap", sap_pairs),
    ("sap-coherent", coherent_sap_pairs), ("bvh", bvh_pairs)], function_entry("pairs(centers, radii)"))

#: the method find_pairs uses when none is named
DEFAULT_METHOD = "grid"


def find_pairs(centers, radii, method: str = DEFAULT_METHOD, threads: int = 1) -> np.ndarray:
    """The pairs of spheres that overlap or touch: |c_i - c_j| <= r_i + r_j.

    Parameters
    ----------
    centers : array_like, shape (n, 3)
        Finite sphere centres, |x| <= 1e150.
    radii : array_like, shape (n,), or a number
        Radii, finite and >= 0.
    method : str
        One of :data:`METHODS`: ``brute``, ``grid`` (default), ``hash``, ``sap``,
        ``sap-coherent``, ``bvh``, or a registered one.
    threads : int
        ``grid`` only: search on this many of Numba's threads (spheres alike in size, from
        :data:`.cells.PARALLEL_BODIES` of them; the same pairs in the same order). The other
        methods run on the calling thread.

    Returns
    -------
    pairs : ndarray of int64, shape (k, 2)
        Each row ``(i, j)`` with ``i < j``, rows in lexicographic order; the same for
        every method.

    Raises
    ------
    ValueError
        Unknown method (:class:`steplab.core.registry.UnknownNameError`), wrong shapes,
        non-finite centres, negative or non-finite radii.
    """
    pairs = METHODS.lookup(method)
    c, r = as_spheres(centers, radii)
    return grid_pairs(c, r, threads) if pairs is grid_pairs and threads > 1 else pairs(c, r)
