"""What every broadphase method shares: input checks, the padded bounds, the one overlap test.

Exactness across methods
------------------------
Every method ends with the same floating-point test, :func:`spheres_overlap`, evaluated
in the same order as brute force's NumPy expression::

    dx = c_i - c_j  (per axis);   (dx*dx + dy*dy) + dz*dz  <=  (r_i + r_j) * (r_i + r_j)

so two methods can only differ in which candidates they *look at*. (The Numba kernels
are compiled without ``fastmath``, so no multiply-add is fused and the roundings are
NumPy's.) The culling tests (cells, sorted intervals, tree boxes) use axis-aligned boxes
``c -/+ (r + pad)``, computed with exactly those operations everywhere (:func:`bounds`,
or inline in a kernel), widened by :func:`padding`, large enough that rounding can
never cull a pair the final test would accept. The argument: if the test accepts, then on each axis fl(dx^2) <= fl(s^2)
(a sum of non-negative terms is at least each term, rounding is monotone), hence the
exact per-axis |c_i - c_j| <= (r_i + r_j)(1 + 4u) with u = 2^-53; computing the box
bounds costs at most two more roundings of size u (max|c| + max r) each. ``pad`` is
32 u times that scale (about eight times what is needed), plus :data:`PAD_ABSOLUTE` for squares that
underflow (|dx| below ~1e-154, where relative error bounds no longer hold).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: |centre| and radius above this are refused: squared distances would overflow float64
MAX_COORDINATE = 1e150
#: relative widening of the culling boxes (see the module docstring: 8 times what rounding needs)
PAD_RELATIVE = 16 * np.finfo(np.float64).eps
#: digits of the pair radix sort: 2^11 counters (16 KiB) stay in the fastest cache
RADIX_BITS = 11
#: absolute widening, covering squares that underflow (sqrt of the smallest normal is ~1.5e-154)
PAD_ABSOLUTE = 1e-150


def as_spheres(centers, radii) -> tuple[np.ndarray, np.ndarray]:
    """Checked float64 copies: centres, shape (n, 3), and radii, shape (n,).

    ``radii`` may be one number for all spheres. Raises ValueError, with a one-line
    message naming the problem and what is allowed, on a wrong shape, a non-finite or
    too large coordinate, or a negative radius.
    """
    try:
        c = np.asarray(centers, dtype=np.float64)
        r = np.asarray(radii, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise ValueError(f"centers and radii must be arrays of real numbers ({err})") from None
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"centers must have shape (n, 3), got shape {c.shape}")
    n = c.shape[0]
    if r.ndim == 0:
        r = np.full(n, float(r))
    if r.shape != (n,):
        raise ValueError(f"radii must have shape ({n},) to match centers of shape {c.shape} (or be one "
                         f"number), got shape {r.shape}")
    # one pass each on the fast path (max and min propagate NaN); find the culprit only on failure
    if n and not np.abs(c).max() <= MAX_COORDINATE:
        bad = ~np.isfinite(c).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"centers must be finite, but center {i} is {c[i].tolist()}")
        i = int(np.argmax(np.abs(c).max(axis=1)))
        raise ValueError(f"centers must lie within |x| <= {MAX_COORDINATE:g} (squared distances would "
                         f"overflow), but center {i} is {c[i].tolist()}")
    if n and not (r.min() >= 0 and r.max() <= MAX_COORDINATE):
        i = int(np.argmax(~((r >= 0) & (r <= MAX_COORDINATE))))
        raise ValueError(f"radii must be finite, >= 0 and <= {MAX_COORDINATE:g}, but radius {i} is {r[i]}")
    return np.ascontiguousarray(c), np.ascontiguousarray(r)


def padding(c: np.ndarray, r: np.ndarray) -> float:
    """Widening of every culling box so that rounding never culls an overlapping pair."""
    if len(c) == 0:
        return PAD_ABSOLUTE
    return float(PAD_RELATIVE * (np.abs(c).max() + r.max()) + PAD_ABSOLUTE)


def bounds(c: np.ndarray, r: np.ndarray, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """Padded axis-aligned boxes ``(lo, hi)``, each shape (n, 3): ``c -/+ (r + pad)``."""
    extent = (r + pad)[:, None]
    return c - extent, c + extent


def no_pairs() -> np.ndarray:
    return np.empty((0, 2), dtype=np.int64)


@njit(cache=True, inline="always")
def spheres_overlap(c, r, i, j):
    """|c_i - c_j| <= r_i + r_j, squared, in exactly brute force's order of operations."""
    dx = c[i, 0] - c[j, 0]
    dy = c[i, 1] - c[j, 1]
    dz = c[i, 2] - c[j, 2]
    s = r[i] + r[j]
    return dx * dx + dy * dy + dz * dz <= s * s


@njit(cache=True, inline="always")
def boxes_overlap(lo, hi, i, j):
    """The padded boxes of ``i`` and ``j`` overlap on all three axes (touching counts)."""
    return (lo[j, 0] <= hi[i, 0] and lo[i, 0] <= hi[j, 0] and lo[j, 1] <= hi[i, 1] and lo[i, 1] <= hi[j, 1]
            and lo[j, 2] <= hi[i, 2] and lo[i, 2] <= hi[j, 2])


@njit(cache=True)
def grow(pairs):
    """``pairs`` (m, 2) copied into a buffer twice as long (amortised O(1) appends)."""
    bigger = np.empty((max(2 * pairs.shape[0], 16), 2), dtype=np.int64)
    bigger[: pairs.shape[0]] = pairs
    return bigger


@njit(cache=True, inline="always")
def append_pair(pairs, k, i, j):
    """Store the pair as (min, max) in row ``k``, growing the buffer when full; returns (pairs, k + 1)."""
    if k == pairs.shape[0]:
        pairs = grow(pairs)
    if i < j:
        pairs[k, 0] = i
        pairs[k, 1] = j
    else:
        pairs[k, 0] = j
        pairs[k, 1] = i
    return pairs, k + 1


@njit(cache=True)
def radix_argsort(key, limit):
    """Stable sort of non-negative ``key`` (all < ``limit``): returns (order, sorted keys).

    Least-significant digit first, in passes of at most :data:`RADIX_BITS` bits, so the
    counters stay in cache and every pass reads in sequence: O(n) per pass.
    """
    n = key.shape[0]
    bits = 1
    while (1 << bits) < limit:
        bits += 1
    passes = (bits + RADIX_BITS - 1) // RADIX_BITS
    width = (bits + passes - 1) // passes
    mask = (1 << width) - 1
    key = key.copy()
    order = np.arange(n)
    other_key = np.empty(n, dtype=np.int64)
    other_order = np.empty(n, dtype=np.int64)
    count = np.empty((1 << width) + 1, dtype=np.int64)
    for step in range(passes):
        shift = step * width
        count[:] = 0
        for p in range(n):
            count[((key[p] >> shift) & mask) + 1] += 1
        for d in range(1 << width):
            count[d + 1] += count[d]
        for p in range(n):
            d = (key[p] >> shift) & mask
            other_key[count[d]] = key[p]
            other_order[count[d]] = order[p]
            count[d] += 1
        key, other_key = other_key, key
        order, other_order = other_order, order
    return order, key


@njit(cache=True)
def sort_pairs(pairs, k, n):
    """The first ``k`` rows of ``pairs`` (each i < j, all < ``n``) sorted lexicographically.

    A radix sort (:func:`radix_argsort`) of the keys i n + j: O(k) per pass where a
    comparison sort would take O(k log k).
    """
    key = np.empty(k, dtype=np.int64)
    for p in range(k):
        key[p] = pairs[p, 0] * n + pairs[p, 1]
    _, key = radix_argsort(key, n * n)
    out = np.empty((k, 2), dtype=np.int64)
    for p in range(k):
        out[p, 0] = key[p] // n
        out[p, 1] = key[p] % n
    return out
