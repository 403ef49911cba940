"""The bench's position-based step as one compiled call on one argument: a table of its arrays' addresses.

:func:`.position_based.cloth_benchmark_step` steps a cloth in place with the kernel every pbd
and xpbd step runs (:func:`.constraint_projection.advance`). Called from Python, that kernel's
compiled entry point first unboxes its seven arguments, thirteen arrays in three NamedTuples,
one C-API call after another, which a game engine calling native code with pointers does not
pay: from cold caches, a step of a 16-particle cloth costs 31 us that way and 23 us through the
table (an empty Python call, 11), and the bench's step 15 to 25 us less (docs/performance.md).
So the bench's step calls :func:`advance_at` instead, on one int64 array, :func:`table`: the
sizes, the substeps and the addresses of the arrays, which it views again in place
(``numba.carray``, no copy) and passes to the same kernel. The arrays must outlive the table
(the caller keeps them). :func:`stream_at` moves the same bytes through the same table and call,
computing nothing: the bench's tighter memory-traffic bound.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from steplab.physics.unowned import unowned

from .constraint_projection import Substeps, Sweep, Workspace, advance, row_length

#: the table's slots: sizes and settings, then one address per array (in this order)
_BODIES, _CONSTRAINTS, _SEGMENTS, _BLOCKS, _SUBSTEPS, _ITERATIONS, _CARRIED, _H, _ROW = range(9)
_ARRAYS = ("state", "external", "inverse_mass", "i", "j", "rest_length", "alpha_tilde", "gamma", "denominator",
           "segments", "kinds", "lam")
_STATE, _EXTERNAL, _INVERSE_MASS, _I, _J, _REST, _ALPHA, _GAMMA, _DENOMINATOR, _STARTS, _KINDS, _LAM = range(
    9, 9 + len(_ARRAYS))


def table(external, inverse_mass, sweep: Sweep, steps: Substeps, work: Workspace) -> np.ndarray:
    """The int64 table :func:`advance_at` reads: the sizes, ``steps`` (h as its float64 bits) and the addresses
    of ``work.state`` (2, 3, M), ``external`` (3, M), ``inverse_mass`` (N,), the sweep's columns and ``work.lam``,
    each C-contiguous and of the dtype :func:`.constraint_projection.advance` is compiled for (checked)."""
    arrays = {"state": work.state, "external": external, "inverse_mass": inverse_mass, "lam": work.lam,
              **{name: getattr(sweep, name) for name in Sweep._fields}}
    kinds = dict.fromkeys(_ARRAYS, np.float64) | {"i": np.uint32, "j": np.uint32, "segments": np.int64,
                                                  "kinds": np.uint8}
    for name, a in arrays.items():
        if a.dtype != kinds[name] or not a.flags.c_contiguous:
            raise ValueError(f"advance_at: {name} must be C-contiguous {np.dtype(kinds[name])}, got {a.dtype}")
    n, p = len(inverse_mass), len(sweep.i)
    m = row_length(n)
    if work.state.shape != (2, 3, m) or external.shape != (3, m) or len(work.lam) < p:
        raise ValueError(f"advance_at: state {work.state.shape}, external {external.shape} and lam "
                         f"{work.lam.shape} do not fit {n} bodies and {p} constraints")
    t = np.zeros(9 + len(_ARRAYS), np.int64)
    t[[_BODIES, _CONSTRAINTS, _SEGMENTS, _BLOCKS, _SUBSTEPS, _ITERATIONS, _CARRIED, _ROW]] = (
        n, p, len(sweep.segments), len(sweep.kinds), steps.substeps, steps.iterations, steps.carried, m)
    t[_H] = np.float64(steps.h).view(np.int64)
    for slot, name in enumerate(_ARRAYS, start=_STATE):
        t[slot] = arrays[name].ctypes.data
    return t


@njit(inline="always")
def _at(t, slot, shape, dtype):
    """The array of ``shape`` and ``dtype`` at the address in slot ``slot`` of ``t`` (a view, no copy)."""
    return unowned(t[slot], shape, dtype)


@njit(cache=True, error_model="numpy")
def advance_at(t):
    """:func:`.constraint_projection.advance` on the arrays :func:`table` ``t`` holds, in place."""
    n, p, s, b = t[_BODIES], t[_CONSTRAINTS], t[_SEGMENTS], t[_BLOCKS]
    state = _at(t, _STATE, (2, 3, t[_ROW]), np.float64)
    sweep = Sweep(_at(t, _I, p, np.uint32), _at(t, _J, p, np.uint32), _at(t, _REST, p, np.float64),
                  _at(t, _ALPHA, p, np.float64), _at(t, _GAMMA, p, np.float64), _at(t, _DENOMINATOR, p, np.float64),
                  _at(t, _STARTS, s, np.int64), _at(t, _KINDS, b, np.uint8))
    h = t[_H:_H + 1].view(np.float64)[0]
    steps = Substeps(h, t[_SUBSTEPS], t[_ITERATIONS], t[_CARRIED] != 0)
    external = _at(t, _EXTERNAL, (3, t[_ROW]), np.float64)
    advance(state[0], state[1], external, _at(t, _INVERSE_MASS, n, np.float64), sweep, steps,
            Workspace(state, _at(t, _LAM, p, np.float64)))


@njit(cache=True)
def stream_at(t, factor):
    """The bytes one step of :func:`advance_at` ``t`` must move, moved in one compiled pass and nothing computed:
    the state q, v (2, 3, N) read and written in place (multiplied by ``factor``; 1.0 leaves it unchanged), and
    read once the external field (3, N), the inverse masses and the sweep's columns (``alpha_tilde`` only where
    the multipliers are carried), summed as integers (which vectorise, where a float sum's order may not
    change). Returns the sum, which keeps the reads from being optimised away.

    The same call on the same table as the step, so both pay the same fixed cost of a call; NumPy's
    two passes (``steplab.peers.memory_stream``) take longer on the same bytes (docs/performance.md).
    """
    n, p, s, b = t[_BODIES], t[_CONSTRAINTS], t[_SEGMENTS], t[_BLOCKS]
    state = _at(t, _STATE, (6, t[_ROW]), np.float64)
    for r in range(6):
        row = state[r]
        for k in range(n):
            row[k] = row[k] * factor
    total = np.uint64(0)
    external = _at(t, _EXTERNAL, (3, t[_ROW]), np.uint64)
    for r in range(3):
        total += _summed(external[r, :n])
    for slot, length in ((_INVERSE_MASS, n), (_REST, p), (_GAMMA, p), (_DENOMINATOR, p), (_STARTS, s),
                         (_ALPHA, p if t[_CARRIED] != 0 else 0)):
        total += _summed(_at(t, slot, length, np.uint64))
    for slot in (_I, _J):
        total += _summed(_at(t, slot, p, np.uint32))
    return total + _summed(_at(t, _KINDS, b, np.uint8))


@njit(inline="always")
def _summed(a):
    total = np.uint64(0)
    for k in range(a.shape[0]):
        total += a[k]
    return total
