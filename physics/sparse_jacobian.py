"""Sparse force Jacobians: one 3x3 block per pair force or per body, assembled block-sparse.

A spring, a damper or drag couples only the bodies it acts on, so the Jacobians dF/dq
and dF/dv of N bodies under P pair forces have at most N + 2P nonzero 3x3 blocks, not
(3N)^2 entries. For the bench's cloth (25,600 particles, 101,442 springs and dampers on
the same pairs) that is 228,484 blocks, 16 MB; the dense (3N)^2 matrix of
:meth:`Model.jacobian` would take 47 GB.

Each force with a Jacobian describes it by blocks (:meth:`Force.jacobian_blocks`):

- a pair force acts on body i as f(x_j - x_i) and on body j as -f (Newton's third law),
  so one block per pair, B = d f_i / d x_j, fixes all four of its blocks: (i, j) and
  (j, i) are +B, (i, i) and (j, j) are -B (:class:`PairJacobian`). The assembled matrix
  is symmetric when every B is;
- a per-body force (drag, central gravity) has one block per body, on the diagonal
  (:class:`BodyJacobian`).

:class:`BlockPattern` knows where each block goes in a block-sparse-row (BSR) matrix
(built once per model and cached: the pairs never change) and adds them up;
:func:`sparse_jacobian` assembles the exact da/dq, da/dv (what :meth:`Model.jacobian`
gives densely). :func:`newton_matrix` assembles implicit Euler's mass-weighted Newton
matrix M - h D - h^2 K over the bodies that are not pinned
(:mod:`steplab.integrators.implicit_euler`) from the blocks' symmetric parts, so each
pair's block is stored once (:class:`NewtonPattern`, :mod:`.symmetric_blocks`: 127,042
blocks, 10.8 MB for the cloth), the springs' and dampers' through a compiled kernel
(:mod:`.sparse_kernels`); :func:`newton_system` adds the acceleration, which that
kernel computes in the same pass, as each Newton iteration needs both at its iterate
(2.5 ms on the cloth, where NumPy took 12 ms for the forces and 7 ms for the matrix), and
:func:`acceleration` the forces alone (1 ms). NumPy, Numba and scipy.sparse; no JAX path.
"""

from __future__ import annotations

import dataclasses
import weakref

import numpy as np
from numba import njit

from .jacobian_blocks import BodyJacobian as BodyJacobian
from .jacobian_blocks import PairJacobian as PairJacobian
from .sparse_kernels import NewtonTerms, has_kernel, pair_groups


@njit(cache=True)
def _add_pair_blocks(data, slots, block, coefficient):  # pragma: no cover - compiled
    # The four blocks of each pair, sequentially (a deterministic sum): +B at (i, j) and
    # (j, i), -B at (i, i) and (j, j); a slot of -1 is a block outside the matrix.
    for p in range(block.shape[0]):
        for k in range(4):
            slot = slots[p, k]
            if slot < 0:
                continue
            sign = coefficient if k < 2 else -coefficient
            for r in range(3):
                for c in range(3):
                    data[slot, r, c] += sign * block[p, r, c]


class BlockPattern:
    """Where the blocks of a model's forces go in a BSR matrix over some of its bodies.

    The block rows and columns are the kept bodies (all of them, or those not pinned), in
    order; there is a block on the diagonal for each, and one on either side of it for
    every pair of two different kept bodies that some pair force connects (a pair listed
    by several forces, the springs and the dampers of a cloth, shares its blocks). A pair
    with one body dropped adds to the diagonal block of the other only; a pair of a body
    with itself adds nothing (its four blocks cancel).

    Parameters
    ----------
    n_bodies : int
    keep : bool ndarray, shape (N,)
    pairs : sequence of (i, j) int ndarrays
        Each pair force's bodies, in the order of its blocks.
    """

    def __init__(self, n_bodies: int, keep, pairs):
        size, self.index, self.kept, ends, keys, both, unique = _kept_pairs(n_bodies, keep, pairs)
        self.size = size
        self.n_pairs = unique.size
        lo, hi = unique // max(size, 1), unique % max(size, 1)
        diagonal = np.arange(size)
        rows = np.concatenate([diagonal, lo, hi])
        cols = np.concatenate([diagonal, hi, lo])
        order = np.lexsort((cols, rows))  # BSR: block rows in order, columns sorted within each
        slot = np.empty_like(order)
        slot[order] = np.arange(order.size)
        self.indices, self.block_rows = cols[order], rows[order]
        self.indptr = np.searchsorted(self.block_rows, np.arange(size + 1))
        self.diagonal_slots = slot[:size]
        upper, lower = slot[size:size + unique.size], slot[size + unique.size:]
        # per pair force, the slots of each pair's (i, j), (j, i), (i, i), (j, j) blocks
        self._slots = []
        for (a, b), key, w in zip(ends, keys, both):
            u = np.searchsorted(unique, key[w])
            above = a[w] < b[w]  # the (i, j) block is above the diagonal
            slots = np.full((a.size, 4), -1, np.int64)
            slots[w, 0] = np.where(above, upper[u], lower[u])
            slots[w, 1] = np.where(above, lower[u], upper[u])
            distinct = a != b
            slots[:, 2] = np.where((a >= 0) & distinct, self.diagonal_slots[np.maximum(a, 0)], -1)
            slots[:, 3] = np.where((b >= 0) & distinct, self.diagonal_slots[np.maximum(b, 0)], -1)
            self._slots.append(slots)

    @property
    def n_blocks(self) -> int:
        return self.size + 2 * self.n_pairs

    def assemble(self, blocks, coefficient_q: float, coefficient_v: float):
        """``coefficient_q dF/dq + coefficient_v dF/dv`` of ``blocks``, a (3 size, 3 size) scipy BSR array.

        ``blocks`` are those the pattern was built from (its pair forces' in the same
        order); the per-body ones of dropped bodies are ignored.
        """
        from scipy.sparse import bsr_array

        data = np.zeros((self.n_blocks, 3, 3))
        pair = iter(self._slots)
        for b in blocks:
            if isinstance(b, PairJacobian):
                slots = next(pair)
                for block, coefficient in ((b.dq, coefficient_q), (b.dv, coefficient_v)):
                    if block is not None and coefficient != 0:
                        _add_pair_blocks(data, slots, np.ascontiguousarray(block, dtype=np.float64), coefficient)
            else:
                for block, coefficient in ((b.dq, coefficient_q), (b.dv, coefficient_v)):
                    if block is not None and coefficient != 0:
                        data[self.diagonal_slots] += coefficient * np.asarray(block)[self.kept]
        shape = (3 * self.size, 3 * self.size)
        return bsr_array((data, self.indices, self.indptr), shape=shape, copy=False)


@njit(cache=True)
def _add_symmetric_pair_blocks(data, slots, block, coefficient):  # pragma: no cover - compiled
    # The symmetric part S = (B + B^T) / 2 of each pair's block, once: +S at the pair's
    # stored block, -S at (i, i) and (j, j); a slot of -1 is a block outside the matrix.
    for p in range(block.shape[0]):
        for k in range(3):
            slot = slots[p, k]
            if slot < 0:
                continue
            sign = 0.5 * coefficient if k == 0 else -0.5 * coefficient
            for r in range(3):
                for c in range(3):
                    data[slot, r, c] += sign * (block[p, r, c] + block[p, c, r])


class NewtonPattern:
    """Where the blocks of the Newton matrix go: a :class:`SymmetricBlockMatrix` over the kept bodies.

    As :class:`BlockPattern`, but each pair's block is stored once (all the blocks the
    Newton matrix gets are symmetric, so the one at (j, i) is the one at (i, j)): the
    kept bodies in order, a diagonal block each, and a block for each pair of two
    different kept bodies that some pair force connects. A pair with one body dropped
    adds to the other's diagonal block only, a pair of a body with itself adds nothing.

    Parameters
    ----------
    n_bodies : int
    keep : bool ndarray, shape (N,)
    pairs : sequence of (i, j) int ndarrays
        Each pair force's bodies, in the order of its blocks.
    """

    def __init__(self, n_bodies: int, keep, pairs):
        from .symmetric_blocks import PairIndex

        size, self.index, self.kept, ends, keys, both, unique = _kept_pairs(n_bodies, keep, pairs)
        self.size = size
        # sorted keys lo * size + hi are the pairs sorted by (lo, hi), PairIndex's order
        self.pairs = PairIndex.of(size, unique // max(size, 1), unique % max(size, 1))
        # per pair force, the slots of each pair's stored block, (i, i) and (j, j)
        self._slots = []
        for (a, b), key, w in zip(ends, keys, both):
            slots = np.full((a.size, 3), -1, np.int64)
            slots[w, 0] = size + np.searchsorted(unique, key[w])
            distinct = a != b
            slots[:, 1] = np.where((a >= 0) & distinct, a, -1)
            slots[:, 2] = np.where((b >= 0) & distinct, b, -1)
            self._slots.append(slots)

    def assemble(self, blocks, coefficient_q: float, coefficient_v: float):
        """``coefficient_q dF/dq + coefficient_v dF/dv`` of ``blocks``' symmetric parts: a SymmetricBlockMatrix.

        ``blocks`` are those the pattern was built from (its pair forces' in the same
        order); the per-body ones of dropped bodies are ignored.
        """
        from .symmetric_blocks import SymmetricBlockMatrix

        data = np.zeros((self.size + self.pairs.n_pairs, 3, 3))
        pair = iter(self._slots)
        for b in blocks:
            if isinstance(b, _CompiledPairs):
                b.add(data, next(pair), coefficient_q, coefficient_v)
            elif isinstance(b, PairJacobian):
                slots = next(pair)
                for block, coefficient in ((b.dq, coefficient_q), (b.dv, coefficient_v)):
                    if block is not None and coefficient != 0:
                        _add_symmetric_pair_blocks(data, slots, np.ascontiguousarray(block, dtype=np.float64),
                                                   coefficient)
            else:
                for block, coefficient in ((b.dq, coefficient_q), (b.dv, coefficient_v)):
                    if block is not None and coefficient != 0:
                        block = np.asarray(block, dtype=float)[self.kept]
                        data[:self.size] += (0.5 * coefficient) * (block + block.transpose(0, 2, 1))
        return SymmetricBlockMatrix(data, self.pairs)


def _kept_pairs(n_bodies: int, keep, pairs):
    """The numbering of the kept bodies and the pairs between two different ones, for a pattern.

    Returns (size, index: body -> kept number or -1, kept bodies, per pair force its ends
    renumbered (a, b), their keys min * size + max, whether both are kept and different,
    the sorted unique keys of those).
    """
    keep = np.asarray(keep, bool)
    size = int(keep.sum())
    index = np.full(n_bodies, -1, np.int64)
    index[keep] = np.arange(size)
    ends = [(index[np.asarray(i)], index[np.asarray(j)]) for i, j in pairs]
    keys = [np.minimum(a, b) * size + np.maximum(a, b) for a, b in ends]
    both = [(a >= 0) & (b >= 0) & (a != b) for a, b in ends]
    unique = np.unique(np.concatenate([k[w] for k, w in zip(keys, both)] + [np.zeros(0, np.int64)]))
    return size, index, np.flatnonzero(keep), ends, keys, both, unique


#: each model's patterns, built on first use (the pairs never change): {model: {key: pattern}}
_PATTERNS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclasses.dataclass(frozen=True)
class _CompiledPairs:
    """Springs and dampers whose symmetric (or definite) blocks and forces a kernel adds (:mod:`.sparse_kernels`)."""

    group: object
    q: np.ndarray
    v: np.ndarray
    definite: bool
    force: np.ndarray | None

    @property
    def i(self):
        return self.group.i

    @property
    def j(self):
        return self.group.j

    def add(self, data, slots, coefficient_q, coefficient_v):
        with_force = self.force is not None
        force = self.force if with_force else np.zeros_like(self.q)
        self.group.add(force, data, slots, self.q, self.v, NewtonTerms(float(coefficient_q), float(coefficient_v),
                                                                      bool(self.definite), with_force, True))


def block_pattern(model, blocks, free_only: bool):
    """The (cached) pattern of ``blocks``' pair forces: a :class:`BlockPattern` over all of
    ``model``'s bodies, or with ``free_only`` a :class:`NewtonPattern` over the free ones."""
    pairs = tuple((b.i, b.j) for b in blocks if isinstance(b, PairJacobian | _CompiledPairs))
    cache = _PATTERNS.setdefault(model, {})
    key = (free_only, tuple((id(i), id(j)) for i, j in pairs))
    if key not in cache:
        if free_only:
            cache[key] = NewtonPattern(model.n_bodies, ~np.asarray(model.pinned), pairs)
        else:
            cache[key] = BlockPattern(model.n_bodies, np.ones(model.n_bodies, bool), pairs)
    return cache[key]


def is_complete(model) -> bool:
    """Whether the blocks are ``model``'s whole Jacobian: every force that depends on the
    state provides them (:meth:`Force.jacobian_blocks`), and none is reactive."""
    from .force import Force

    return all(f.constant or (not f.reactive and type(f).jacobian_blocks is not Force.jacobian_blocks)
               for f in model.forces)


def _require_numpy(model, what: str) -> None:
    if model.xp is not np:
        raise ValueError(f"{what} is assembled with scipy.sparse on the NumPy backend; this model is on "
                         f"{model.xp.__name__} (use model.cast(numpy))")


def sparse_jacobian(model, t, q, v):
    """``(da/dq, da/dv)`` of ``model`` at (q, v), each a (3N, 3N) :class:`scipy.sparse.bsr_array`.

    The sparse counterpart of :meth:`Model.jacobian` (equal to it to round-off): the
    forces' exact blocks, each row divided by its body's mass (zero for a pinned body).
    Forces without :meth:`Force.jacobian_blocks` and reactive forces are left out, as
    the dense Jacobian leaves out the reactive ones.
    """
    _require_numpy(model, "the sparse Jacobian")
    blocks = model.jacobian_blocks(t, q, v)
    pattern = block_pattern(model, blocks, free_only=False)
    row_scale = np.asarray(model.inverse_masses, dtype=float)[pattern.block_rows][:, None, None]
    out = []
    for a, b in ((1.0, 0.0), (0.0, 1.0)):
        matrix = pattern.assemble(blocks, a, b)
        matrix.data *= row_scale
        out.append(matrix)
    return tuple(out)


def newton_matrix(model, t, q, v, h: float, definite: bool = False, compiled: bool = True):
    """Implicit Euler's Newton matrix A = M - h D - h^2 K over the free bodies, mass-weighted.

    K = dF/dq and D = dF/dv are the symmetric part of the forces' Jacobians, (J + J^T) / 2
    block by block, so that A is symmetric; it is also positive definite, what conjugate
    gradients need, unless the indefinite terms (a compressed spring's negative
    stiffness, a damper's dependence on positions) outweigh the masses,
    h^2 k (L / l - 1) ~ m. With ``definite``, K and D are the forces' definite parts
    instead (:meth:`Force.jacobian_blocks`), and A is positive definite at any h. The
    rows and columns of pinned bodies are left out (their velocity never changes).
    Springs and dampers add their blocks through a compiled kernel (:mod:`.sparse_kernels`,
    the same numbers as their ``jacobian_blocks``; ``compiled=False``: through those).

    Returns
    -------
    A : SymmetricBlockMatrix, shape (3 F, 3 F)
        F free bodies, in order; each pair's block stored once (:mod:`.symmetric_blocks`;
        ``A.tobsr()`` is the scipy BSR array).
    pattern : NewtonPattern
        Its ``kept`` bodies (the free ones: A's block rows).
    """
    _, matrix, pattern = _newton_system(model, t, q, v, h, definite, compiled, with_acceleration=False)
    return matrix, pattern


def newton_system(model, t, q, v, h: float, definite: bool = False):
    """``(a, A, pattern)``: the acceleration ``model.acceleration(t, q, v)`` and :func:`newton_matrix`'s A and pattern.

    What each Newton iteration of implicit Euler needs at its iterate, in one pass over
    the springs and dampers: their kernel computes each pair's force with its block
    (:mod:`.sparse_kernels`). ``a`` is the model's acceleration to round-off (the same
    forces, added in another order); a model with a reactive force (ground contact) gets
    ``model.acceleration`` itself.
    """
    return _newton_system(model, t, q, v, h, definite, True, with_acceleration=True)


def _newton_system(model, t, q, v, h, definite, compiled, with_acceleration):
    _require_numpy(model, "implicit Euler's sparse Newton matrix")
    model.require_forces()  # stiffness = inf springs refused, as model.acceleration refuses them
    q, v = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(v, dtype=float)
    force = np.zeros_like(q) if with_acceleration and compiled else None
    blocks = [_CompiledPairs(group, q, v, definite, force) for group in (pair_groups(model) if compiled else ())]
    for f in model.forces:
        if f.reactive or (compiled and has_kernel(f)):
            continue
        b = f.jacobian_blocks(np, q, v, model.masses, definite)
        if b is not None:
            blocks.append(b)
    pattern = block_pattern(model, blocks, free_only=True)
    matrix = pattern.assemble(blocks, -h * h, -h)  # -(h^2 K + h D) ...
    masses = np.asarray(model.masses, dtype=float)[pattern.kept]
    for c in range(3):
        matrix.diagonal[:, c, c] += masses  # ... + M
    acceleration = None
    if with_acceleration:
        acceleration = _acceleration(model, t, q, v, force)
    return acceleration, matrix, pattern


def acceleration(model, t, q, v):
    """``model.acceleration(t, q, v)`` with the springs' and dampers' forces from the compiled kernel (NumPy).

    The same forces added in another order (equal to round-off), 1 ms instead of 12 for
    the bench's cloth; a model with a reactive force gets ``model.acceleration`` itself.
    """
    _require_numpy(model, "the compiled acceleration")
    q, v = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(v, dtype=float)
    if model.reactive_forces:
        return np.array(model.acceleration(t, q, v), dtype=float)
    force = np.zeros_like(q)
    for group in pair_groups(model):
        group.add_forces(force, q, v)
    return _acceleration(model, t, q, v, force)


def _acceleration(model, t, q, v, pair_force):
    """The model's acceleration from the kernel's spring and damper forces ``pair_force`` and the other forces'.

    F / m plus the constant forces' field (zero on pinned bodies), as :class:`Model`
    sums it (in ``pair_force``'s place); where a reactive force needs the sum of all the
    others, a copy of the model's own. Either way an array of its own, the caller's to change.
    """
    if model.reactive_forces or pair_force is None:
        return np.array(model.acceleration(t, q, v), dtype=float)
    for f in model.varying_forces:
        if not has_kernel(f):
            pair_force += f.force(np, q, v, model.masses)
    pair_force *= np.asarray(model.inverse_masses)[:, None]
    if model.constant_field is not None:
        pair_force += model.constant_field
    return pair_force
