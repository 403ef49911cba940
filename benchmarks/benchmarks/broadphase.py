"""Broadphase pair finding: method x number of spheres x distribution, time and peak memory.

Written against ``physics.broadphase.find_pairs``; where that module is absent (an
older commit), ``setup`` raises ``NotImplementedError`` and asv records the benchmark
as skipped.
"""

from __future__ import annotations

import numpy as np

try:
    from steplab.physics.broadphase import METHODS, find_pairs
except ImportError:  # not in this version of steplab
    METHODS, find_pairs = {}, None

from .common import SEED

#: the brute-force reference tests all n^2 / 2 pairs: only up to this many spheres
BRUTE_MAX = 1_000


def spheres(n: int, distribution: str):
    """n sphere centres in the unit cube and radii giving about 0.2 neighbours per sphere."""
    rng = np.random.default_rng(SEED)
    if distribution == "uniform":
        centers = rng.uniform(0.0, 1.0, (n, 3))
    else:  # 20 tight clusters: many spheres in few cells, the case grids handle worst
        middles = rng.uniform(0.1, 0.9, (20, 3))
        centers = middles[rng.integers(0, 20, n)] + rng.normal(0.0, 0.03, (n, 3))
    r = 0.004 * (1e5 / n) ** (1 / 3)
    return centers, rng.uniform(0.5 * r, 1.5 * r, n)


def _setup(bench, method, n, distribution):
    if find_pairs is None:
        raise NotImplementedError("physics.broadphase is not available")
    if method == "brute" and n > BRUTE_MAX:
        raise NotImplementedError("O(n^2)")
    bench.centers, bench.radii = spheres(n, distribution)
    find_pairs(bench.centers[:256], bench.radii[:256], method)  # compile any Numba kernels


class Broadphase:
    """Time to find the pairs."""

    params = (list(METHODS) or ["grid"], [1_000, 100_000], ["uniform", "clustered"])
    param_names = ["method", "n", "distribution"]
    timeout = 300
    setup = _setup

    def time_find_pairs(self, method, n, distribution):
        find_pairs(self.centers, self.radii, method)


class BroadphaseMemory:
    """Peak memory at 10^5 spheres, where the methods differ (asv reports the whole process's, JAX included)."""

    params = (list(METHODS) or ["grid"], [100_000], ["uniform", "clustered"])
    param_names = ["method", "n", "distribution"]
    timeout = 300
    setup = _setup

    def peakmem_find_pairs(self, method, n, distribution):
        find_pairs(self.centers, self.radii, method)
