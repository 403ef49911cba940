"""Eight projections of one colour at once: the constraint sweep's inner step in LLVM vector code (a Numba intrinsic).

Within a segment of the sweep (:func:`.constraint_projection.wavefront`) no two constraints
share a body, so LANES consecutive projections are independent: :func:`project_block` does
constraints k to k + LANES - 1 together, each in a lane of a vector of LANES float64:

- gather: each constraint's bodies a, b as padded rows (x, y, z, 0) of the start positions
  ``x`` and the displacement ``d``, one four-wide load each (:mod:`.vector4` says why four), u = d_b - d_a and
  e = (x_b - x_a) + u; the rows transposed into lanes (e_x, e_y, e_z, u_x, u_y, u_z across
  the eight constraints), |e|^2 and e . u, summed left to right as the scalar code sums them;
- solve: l = sqrt |e|^2 and s from :func:`.projection_law.projection` itself, the one
  definition, evaluated here on vectors (its arithmetic emitted as vector instructions by
  :class:`_Lanes`), s = 0 where the denominator is 0; the multipliers, when carried;
- scatter: d_a += (-(w_a s)) e and d_b += (w_b s) e, each a four-wide multiply and add into the
  row, reloaded from L1 (no constraint of the block touched it since its first load; holding
  all sixteen in registers across the solve spills them).

Blocks come in kinds (:func:`.constraint_projection.block_kinds`), each its own code: where the bodies
lie at a stride s (i[k + l] = i[k] + s l, and so j; most blocks of a grid cloth), the code reads only
i[k] and j[k] and finds the sixteen rows at constant offsets from two addresses; elsewhere it loads the
eight pairs of indices and keeps sixteen row addresses, which on a 16-register AVX2 machine spill. Where
the two ends' inverse masses are equal in every lane, one product (w s) e a lane moves both ends
(subtracted at a, added at b: the same bytes as adding -(w_a s) e). The transpose is the 4 x 4 one of
AVX (:func:`_transposed`). On the bench's cloth (AMD Zen 3, AVX2) these took the sweep from 5.7-5.9 to
4.4-4.7 ns a constraint (docs/performance.md).

Per constraint that is 6 row loads and 2 row stores, against the separate gather, solve and
scatter loops' 7 row loads, 3 row stores and 3 stores and 3 to 4 loads of per-constraint
scalars through scratch arrays. Each lane is the scalar operation it replaces (IEEE add, subtract,
multiply, divide and square root, no fused multiply-add, the same order), so the bytes are
those of the sequential sweep; the plain Python :func:`project_block` is that scalar code, the
projections one after another (:func:`project_one`), which ``py_func``
runs and the tests compare against. Indices are not bounds-checked: the caller passes
constraints k to k + LANES - 1 of one segment.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from .projection_law import _projection, projection

#: constraints per block: a cache line of a float64 column, one AVX-512 register (two AVX2 ones)
LANES = 8
#: the flag in a block's kind (:func:`.constraint_projection.block_kinds`) for equal inverse masses at
#: both ends in every lane; the kind's low bits are the stride its bodies lie at (0: none)
EQUAL_MASSES = 4
_ROW = 4  # a padded row (x, y, z, 0)
_DOUBLE, _INT32 = ir.DoubleType(), ir.IntType(32)
_LANE_VECTOR = ir.VectorType(_DOUBLE, LANES)
_ROW_VECTOR = ir.VectorType(_DOUBLE, _ROW)


def project_block(rows, inverse_mass, sweep, lam, carried, k, kind=0):
    """Constraints k to k + LANES - 1 of ``sweep`` (one segment) projected on the flat padded rows ``rows`` =
    (d, x): d the displacement, moved, x the start positions; the multipliers ``lam`` when ``carried``. ``kind``, a
    constant (:func:`.constraint_projection.block_kinds`): its low bits 0, or the stride s at which the
    block's bodies lie (i[k + l] = i[k] + s l, and so j), whose code then reads only i[k] and j[k] and finds
    the rows at fixed offsets from theirs; EQUAL_MASSES where w_i = w_j in every lane, whose code makes one
    product a lane for both moves. In Python, one after another (:func:`project_one`), whatever the kind:
    the same bytes."""
    d, x = rows
    for p in range(k, k + LANES):
        project_one(p, d, x, inverse_mass, sweep, lam, carried)


def project_one(p, d, x, inverse_mass, sweep, lam, carried):
    """Constraint ``p`` of ``sweep`` projected on the flat padded rows ``d`` (the displacement, moved) and ``x``
    (start positions), alone: the sweep's scalar step (a segment's last few constraints; and in Python,
    :func:`project_block`'s twin); the multiplier ``lam[p]`` when ``carried``."""
    a, b = np.intp(sweep.i[p]), np.intp(sweep.j[p])
    ra, rb = 4 * a, 4 * b  # flat: body a's row at 4a .. 4a + 3
    u0, u1, u2 = d[rb] - d[ra], d[rb + 1] - d[ra + 1], d[rb + 2] - d[ra + 2]
    e0, e1, e2 = x[rb] - x[ra] + u0, x[rb + 1] - x[ra + 1] + u1, x[rb + 2] - x[ra + 2] + u2
    squared = e0 * e0 + e1 * e1 + e2 * e2
    length = np.sqrt(squared)
    below = sweep.denominator[p] * squared
    held = sweep.alpha_tilde[p] * lam[p] if carried else 0.0
    s = _projection(sweep.rest_length[p], length, e0 * u0 + e1 * u1 + e2 * u2, sweep.gamma[p], below, held)
    s = s if below != 0.0 else 0.0
    if carried:
        lam[p] += s * length
    # x_i -= w_i s d, x_j += w_j s d (x - y is x + (-y) exactly)
    wa, wb = -(inverse_mass[a] * s), inverse_mass[b] * s
    d[ra], d[ra + 1], d[ra + 2] = d[ra] + wa * e0, d[ra + 1] + wa * e1, d[ra + 2] + wa * e2
    d[rb], d[rb + 1], d[rb + 2] = d[rb] + wb * e0, d[rb + 1] + wb * e1, d[rb + 2] + wb * e2


@overload(project_one, inline="always")
def _project_one_compiled(p, d, x, inverse_mass, sweep, lam, carried):
    return project_one  # compiled, the same code


class _Lanes:
    """An LLVM vector value whose Python arithmetic emits the vector instruction: so the one
    projection formula, plain arithmetic, evaluated on these, is that formula in vector code."""

    def __init__(self, builder, value):
        self.builder, self.value = builder, value

    def _emit(self, operation, other):
        return _Lanes(self.builder, operation(self.value, other.value))

    def __add__(self, other):
        return self._emit(self.builder.fadd, other)

    def __sub__(self, other):
        return self._emit(self.builder.fsub, other)

    def __mul__(self, other):
        return self._emit(self.builder.fmul, other)

    def __truediv__(self, other):
        return self._emit(self.builder.fdiv, other)


def _constant(value, count):
    return ir.Constant(ir.VectorType(_INT32, count), [ir.Constant(_INT32, n) for n in value])


def _data(context, builder, array_type, array):
    return context.make_array(array_type)(context, builder, array).data


def _load(builder, data, index, vector_type, align=8):
    """The vector of ``vector_type`` starting at element ``index`` of ``data``."""
    return builder.load(builder.bitcast(builder.gep(data, [index]), vector_type.as_pointer()), align=align)


def _store(builder, value, data, index):
    builder.store(value, builder.bitcast(builder.gep(data, [index]), value.type.as_pointer()), align=8)


def _transposed(builder, rows):
    """The x, y and z lanes of LANES padded rows, three vectors of LANES (the rows' transpose), four rows at a
    time as a 4 x 4 transpose of float64 is done on AVX: pairs of rows interleaved within 128-bit halves
    (unpcklpd, unpckhpd), then the halves joined (vperm2f128): seven shuffles per four rows."""
    def shuffle(a, b, mask):
        return builder.shuffle_vector(a, b, _constant(mask, len(mask)))

    columns = [[], [], []]
    for r in range(0, LANES, _ROW):
        r0, r1, r2, r3 = rows[r:r + _ROW]
        low01, high01 = shuffle(r0, r1, [0, 4, 2, 6]), shuffle(r0, r1, [1, 5, 3, 7])  # x0 x1 z0 z1, y0 y1 . .
        low23, high23 = shuffle(r2, r3, [0, 4, 2, 6]), shuffle(r2, r3, [1, 5, 3, 7])
        columns[0].append(shuffle(low01, low23, [0, 1, 4, 5]))
        columns[1].append(shuffle(high01, high23, [0, 1, 4, 5]))
        columns[2].append(shuffle(low01, low23, [2, 3, 6, 7]))
    while len(columns[0]) > 1:  # the groups of four end to end (registers side by side: no instruction)
        columns = [[shuffle(c[n], c[n + 1], list(range(2 * c[n].type.count))) for n in range(0, len(c), 2)]
                   for c in columns]
    return [c[0] for c in columns]


def _dot3(builder, p, q):
    """p_x q_x + p_y q_y + p_z q_z lane by lane, left to right (the scalar code's order)."""
    products = [builder.fmul(p[c], q[c]) for c in range(3)]
    return builder.fadd(builder.fadd(products[0], products[1]), products[2])


def _splat(builder, vector, lane):
    """Lane ``lane`` of ``vector`` in every lane of a padded row."""
    return builder.shuffle_vector(vector, ir.Constant(vector.type, None), _constant([lane] * _ROW, _ROW))


class _Block(NamedTuple):
    """Where a block's data lie: the padded rows of ``d`` and ``x`` (pointers to four float64), the inverse
    masses, the multipliers and the sweep's columns by name (pointers to their elements), the first
    constraint ``k`` (intp)."""

    d: ir.Value
    x: ir.Value
    inverse_mass: ir.Value
    lam: ir.Value
    column: dict
    k: ir.Value


def _bodies(builder, block: _Block, stride: int) -> list:
    """Each lane's bodies, [[a_0 .. a_7], [b_0 .. b_7]] (intp): the i and j columns' LANES entries from k; at a
    ``stride`` s > 0, i[k] + s l and j[k] + s l, two loads and constant offsets (which the row addresses
    absorb: no index is loaded, shifted or kept per lane)."""
    i64 = ir.IntType(64)
    if stride:
        firsts = [builder.zext(builder.load(builder.gep(block.column[name], [block.k])), i64) for name in "ij"]
        return [[builder.add(first, ir.Constant(i64, stride * lane)) for lane in range(LANES)] for first in firsts]
    ends = [_load(builder, block.column[name], block.k, ir.VectorType(_INT32, LANES), align=4) for name in "ij"]
    return [[builder.zext(builder.extract_element(end, ir.Constant(_INT32, lane)), i64) for lane in range(LANES)]
            for end in ends]


def _masses(builder, block: _Block, bodies) -> ir.Value:
    """The inverse masses of ``bodies`` (one a lane), in lanes."""
    masses = ir.Constant(_LANE_VECTOR, None)
    for lane, body in enumerate(bodies):
        masses = builder.insert_element(masses, builder.load(builder.gep(block.inverse_mass, [body])),
                                        ir.Constant(_INT32, lane))
    return masses


def _emit(builder, block: _Block, carried: bool, stride: int, equal: bool) -> None:
    """The block's code, for multipliers ``carried`` or held at 0 (each its own code: no branch inside), its
    bodies at ``stride`` (0: read from the i and j columns lane by lane), its ends' inverse masses ``equal``
    in every lane or not."""
    def lanes(name, data=None):
        return _load(builder, block.column[name] if data is None else data, block.k, _LANE_VECTOR)

    # gather: each lane's bodies, their rows, u = d_b - d_a and e = (x_b - x_a) + u, then transposed
    bodies = _bodies(builder, block, stride)
    e_rows, u_rows = [], []
    for a, b in zip(*bodies):
        da, db = (builder.load(builder.gep(block.d, [body]), align=8) for body in (a, b))
        u = builder.fsub(db, da)
        xa, xb = (builder.load(builder.gep(block.x, [body]), align=8) for body in (a, b))
        e_rows.append(builder.fadd(builder.fsub(xb, xa), u))
        u_rows.append(u)
    e_lanes, u_lanes = _transposed(builder, e_rows), _transposed(builder, u_rows)
    squared, approach = _dot3(builder, e_lanes, e_lanes), _dot3(builder, e_lanes, u_lanes)
    # solve: the one projection, on the lanes
    sqrt = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_LANE_VECTOR, [_LANE_VECTOR]),
                                          f"llvm.sqrt.v{LANES}f64")
    length = builder.call(sqrt, [squared])
    below = builder.fmul(lanes("denominator"), squared)
    zero = ir.Constant(_LANE_VECTOR, [0.0] * LANES)
    held = builder.fmul(lanes("alpha_tilde"), lanes(None, block.lam)) if carried else zero
    arguments = (lanes("rest_length"), length, approach, lanes("gamma"), below, held)
    s = projection(*(_Lanes(builder, v) for v in arguments)).value
    s = builder.select(builder.fcmp_unordered("!=", below, zero), s, zero)
    if carried:
        _store(builder, builder.fadd(lanes(None, block.lam), builder.fmul(s, length)), block.lam, block.k)
    # scatter: d_a += (-(w_a s)) e, d_b += (w_b s) e, reloading the rows (from L1: keeping all sixteen
    # in registers across the solve spills them)
    if equal:  # w_a = w_b in every lane: d_a + (-(w_a s)) e = d_a - (w s) e exactly, one product a lane
        weight = builder.fmul(_masses(builder, block, bodies[0]), s)
        for lane in range(LANES):
            step = builder.fmul(_splat(builder, weight, lane), e_rows[lane])
            for ends_, move in zip(bodies, (builder.fsub, builder.fadd)):
                row = builder.gep(block.d, [ends_[lane]])
                builder.store(move(builder.load(row, align=8), step), row, align=8)
        return
    weights = [builder.fmul(_masses(builder, block, ends_), s) for ends_ in bodies]
    weights[0] = builder.fneg(weights[0])
    for lane in range(LANES):
        for weight, ends_ in zip(weights, bodies):
            row = builder.gep(block.d, [ends_[lane]])
            step = builder.fmul(_splat(builder, weight, lane), e_rows[lane])
            builder.store(builder.fadd(builder.load(row, align=8), step), row, align=8)


@intrinsic(prefer_literal=True)
def _project_block(typingctx, rows, inverse_mass, sweep, lam, carried, k, kind):
    if not isinstance(rows, types.UniTuple) or rows.count != 2:
        return None
    floats = (rows.dtype, inverse_mass, lam)
    if not (all(isinstance(a, types.Array) and a.dtype == types.float64 and a.layout == "C" for a in floats)
            and isinstance(sweep, types.BaseNamedTuple) and isinstance(k, types.Integer)
            and isinstance(kind, types.IntegerLiteral)):
        return None
    stride, equal = kind.literal_value & ~EQUAL_MASSES, bool(kind.literal_value & EQUAL_MASSES)

    def codegen(context, builder, signature, args):
        rows_, mass_, sweep_, lam_, carried_, k_, _ = args
        data = [_data(context, builder, rows.dtype, builder.extract_value(rows_, n)) for n in range(2)]
        data += [_data(context, builder, t, a) for t, a in ((inverse_mass, mass_), (lam, lam_))]
        padded = [builder.bitcast(pointer, _ROW_VECTOR.as_pointer()) for pointer in data[:2]]
        column = {name: _data(context, builder, sweep.types[n], builder.extract_value(sweep_, n))
                  for n, name in enumerate(sweep.fields) if name not in ("segments", "kinds")}
        block = _Block(*padded, data[2], data[3], column, context.cast(builder, k_, k, types.intp))
        with builder.if_else(carried_) as (carrying, holding):
            with carrying:
                _emit(builder, block, True, stride, equal)
            with holding:
                _emit(builder, block, False, stride, equal)
        return context.get_dummy_value()

    return types.void(rows, inverse_mass, sweep, lam, carried, k, kind), codegen


@overload(project_block, inline="always", prefer_literal=True)
def _project_block_compiled(rows, inverse_mass, sweep, lam, carried, k, kind=0):
    if not isinstance(kind, types.IntegerLiteral):
        return None
    return lambda rows, inverse_mass, sweep, lam, carried, k, kind=0: _project_block(
        rows, inverse_mass, sweep, lam, carried, k, kind)
