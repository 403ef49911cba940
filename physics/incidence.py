"""Pair forces on JAX: gathers of rows by constant indices, and each body's pairs as a table.

A pair force (a spring, a damper) pushes the first body of pair p with +f_p and the
second with -f_p. NumPy sums these per body with ``bincount``. A scatter-add is what
JAX would write (``.at[i].add(f).at[j].add(-f)``), but XLA:CPU runs a scatter element
by element, and at cloth scale it is most of a step. The same sums as a *gather*
vectorize and fuse into the velocity update that consumes them. The incidence table
lists, for each body b, the pairs it belongs to, padded to the largest count K:

    F_b = sum_k sign[b, k] f[pair[b, k]],   sign +1 where b is the pair's first body, -1 its second,

and 0 in the padding slots (where body b has fewer than K pairs). A body's slots list
its pairs as first body, then as second body, each by pair index: the order in which
the scatter-add adds them, so the sums are the same ones. The table pays where bodies
have similar numbers of pairs (a cloth: at most 8, on average 7.9); one hub with many
pairs would make it mostly padding, and then the scatter-add is kept.

The rows of a pair, q[i] and q[j], are gathered with one ready-made index constant per
index array (:func:`take_rows`). ``x[i]`` traces index arithmetic (wrapping negative
indices, narrowing to int32) that XLA hoists out of the compiled loop once for every
use, before it merges common subexpressions, so a damper on every spring of a cloth
would gather the positions a second time; with one index constant XLA computes each
pair's separation once for both forces. Equal index arrays are made one array when a
force is cast to JAX (:func:`shared_indices`), so that the constants are the same.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import hashlib
import threading

import numpy as np

#: the largest slot count K for which the sums are a gather (the K terms are added in turn)
MAX_SLOTS = 32
#: the gather reads n K slots for the 2P incidences; beyond this ratio the scatter is kept
MAX_PADDING = 3


@dataclasses.dataclass(frozen=True, eq=False)
class Incidence:
    """The pairs of each body: ``pair`` (n, K, 1) int32 gather indices, ``sign`` (n, K, 1) floats."""

    pair: object
    sign: object

    @property
    def slots(self) -> int:
        return self.pair.shape[1]


def _concrete(*arrays) -> bool:
    import jax

    return not any(isinstance(a, jax.core.Tracer) for a in arrays)


#: constants made from index arrays, by a digest of their contents (most recent last)
_CONSTANTS: collections.OrderedDict = collections.OrderedDict()
#: how many the cache keeps
CACHE_SIZE = 64
_LOCK = threading.Lock()
_MISSING = object()


def _constant(kind: str, make, *arrays, **options):
    """``make(*arrays, **options)``, made once for equal contents (and x64 mode) and kept.

    Keyed by a digest, not by the bytes, so a cache of 10^6-pair arrays holds no copies
    of them. ``make`` builds JAX arrays from NumPy ones; it runs outside any trace
    (``ensure_compile_time_eval``), so what it returns is concrete even when first made
    while a step is being traced.
    """
    import jax

    digest = hashlib.blake2b(digest_size=20)
    for a in arrays:
        digest.update(f"{a.dtype.str}{a.shape}".encode())
        digest.update(np.ascontiguousarray(a).data)
    # x64 is part of the key: without it jnp.asarray makes int64 into int32
    key = (kind, digest.digest(), tuple(sorted(options.items())), bool(jax.config.jax_enable_x64))
    with _LOCK:  # studies may trace steps in threads
        value = _CONSTANTS.pop(key, _MISSING)
        if value is _MISSING:
            with jax.ensure_compile_time_eval():
                value = make(*arrays, **options)
        _CONSTANTS[key] = value
        while len(_CONSTANTS) > CACHE_SIZE:
            _CONSTANTS.popitem(last=False)
    return value


def take_rows(x, index):
    """``x[index]`` on JAX for a constant index array (M,) into the rows of ``x`` (N, ...)."""
    if not _concrete(index) or x.shape[0] >= 2**31:
        return x[index]
    constant = _constant("gather", _gather_index, np.asarray(index), n=x.shape[0])
    return x[index] if constant is None else _gather(x, constant)


def _gather(x, index):
    """Rows of ``x`` at ``index`` (..., 1) int32, known to be in range."""
    from jax import lax

    batch = index.ndim - 1
    dims = lax.GatherDimensionNumbers(offset_dims=tuple(range(batch, batch + x.ndim - 1)),
                                      collapsed_slice_dims=(0,), start_index_map=(0,))
    return lax.gather(x, index, dims, slice_sizes=(1,) + x.shape[1:],
                      mode=lax.GatherScatterMode.PROMISE_IN_BOUNDS)


def _gather_index(index, n: int):
    """The gather's index constant, or None for indices out of range (left to ``x[index]``)."""
    import jax.numpy as jnp

    if index.size and (index.min() < 0 or index.max() >= n):
        return None
    return jnp.asarray(index.astype(np.int32)[..., None])


def incidence(i, j, n: int, dtype) -> Incidence | None:
    """The incidence table of pairs (i[p], j[p]) on n bodies, cached by content.

    ``None`` when the pairs are traced (not known when the step is compiled), or when the
    table would be mostly padding (more than ``MAX_SLOTS`` slots, or more than
    ``MAX_PADDING`` times the incidences); the caller then scatter-adds.
    """
    if not _concrete(i, j) or n >= 2**31:
        return None
    return _constant("incidence", _table, np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64),
                     n=int(n), dtype=np.dtype(dtype).str)


def _table(i, j, n: int, dtype: str) -> Incidence | None:
    import jax.numpy as jnp

    p = i.size
    bodies = np.concatenate([i, j])
    if p == 0 or bodies.min() < 0 or bodies.max() >= n:
        return None
    counts = np.bincount(bodies, minlength=n)
    k = int(counts.max())
    if k > MAX_SLOTS or n * k > MAX_PADDING * 2 * p:
        return None
    # incidences sorted by body; a stable sort keeps first-body ones (the first half)
    # before second-body ones, each in pair order
    order = np.argsort(bodies, kind="stable")
    body = bodies[order]
    slot = np.arange(2 * p) - (np.cumsum(counts) - counts)[body]
    pair = np.zeros((n, k, 1), dtype=np.int32)  # padding: pair 0, with sign 0
    sign = np.zeros((n, k, 1))
    pair[body, slot, 0] = np.concatenate([np.arange(p), np.arange(p)])[order]
    sign[body, slot, 0] = np.where(order < p, 1.0, -1.0)
    return Incidence(jnp.asarray(pair), jnp.asarray(sign, dtype=dtype))


def sum_pair_forces(table: Incidence, f):
    """Net force on each body, shape (n, 3), from the force ``f`` (P, 3) on each pair's first body."""
    import jax.numpy as jnp

    # a padding slot adds 0 f[0], zero for any finite f (a non-finite f means a
    # non-finite state, which the step's divergence check reports anyway)
    terms = table.sign * _gather(f, table.pair)  # (n, K, 3)
    # the K slots added in turn, as elementwise adds XLA fuses into the consumer (a
    # length-K reduction would be a separate kernel, and add in another order)
    return functools.reduce(jnp.add, [terms[:, k] for k in range(table.slots)])


def shared_indices(xp, a):
    """``xp.asarray(a)`` for an integer array, one array object for equal contents on JAX.

    Forces on the same pairs (a damper on every spring) then hold the same index array,
    which a compiled step closes over once.
    """
    if xp is np:
        return np.asarray(a)
    import jax.numpy as jnp

    return _constant("indices", jnp.asarray, np.asarray(a))
