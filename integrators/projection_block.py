"""Eight projections of one colour at once: the constraint sweep's inner step in LLVM vector code (a Numba intrinsic).

Within a segment of the sweep (:func:`.constraint_projection.wavefront`) no two constraints
share a body, so LANES consecutive projections are independent: :func:`project_block` does
constraints k to k + LANES - 1 together, each in a lane of a vector of LANES float64. The start
positions ``x`` and the displacement ``d`` are coordinate rows, (3, M): coordinate c of body a at
[c, a] (:func:`.constraint_projection.coordinates`), so where each half of a block's bodies lies in
a run, each coordinate of its four bodies is one vector load, already in lanes:

- gather: each coordinate of the bodies a and b of the eight constraints, of d and of x, in lanes;
  u = d_b - d_a and e = (x_b - x_a) + u, |e|^2 and e . u summed left to right as the scalar code sums them;
- solve: l = sqrt |e|^2 and s from :func:`.projection_law.projection` itself, the one
  definition, evaluated here on vectors (its arithmetic emitted as vector instructions by
  :class:`_Lanes`), s = 0 where the denominator is 0; the multipliers, when carried;
- scatter: d_a += (-(w_a s)) e and d_b += (w_b s) e, coordinate by coordinate, each row read again (not
  held in registers across the solve) and stored as it was loaded.

How the bodies lie is the block's kind (:func:`.constraint_projection.block_kinds`), each its own
code: a RUN (in each half of the lanes a + l, b + l: four vector loads and stores a coordinate, two a
half) or anything else (each lane's bodies from the i and j columns, one value at a time). Where the
two ends' inverse masses are equal in every lane, one product (w s) e a lane moves both ends
(subtracted at a, added at b: the same bytes as adding -(w_a s) e). With rows of (x, y, z, 0) per
body instead, the rows had to be transposed into lanes and back: on the bench's cloth (AMD Zen 3,
AVX2) a run's block took 3.8-4.1 ns a constraint that way, 2.9-3.1 ns in coordinate rows
(docs/performance.md). Runs by 2 (a row's springs of one colour, in a grid's numbering) become runs
by 1 with the bodies laid out by :mod:`.arrangement`; a run's halves of four let two runs share a
block, so that a run leaves fewer than four constraints to the blocks by index, not eight.

Each lane is the scalar operation it replaces (IEEE add, subtract, multiply, divide and square
root, no fused multiply-add, the same order), so the bytes are those of the sequential sweep; the
plain Python :func:`project_block` is that scalar code, the projections one after another
(:func:`project_one`), which ``py_func`` runs and the tests compare against. Indices are not
bounds-checked: the caller passes constraints k to k + LANES - 1 of one segment.
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
#: how a block's bodies lie, the low bit of its kind (:func:`.constraint_projection.layouts`): 0 anywhere
RUN = 1
#: the flag in a block's kind for equal inverse masses at both ends in every lane
EQUAL_MASSES = 4
#: a RUN block's halves: each a run of its own (:func:`.constraint_projection.layouts`), one AVX2 vector
HALF = LANES // 2
_DOUBLE, _INT32 = ir.DoubleType(), ir.IntType(32)
_LANE_VECTOR, _HALF_VECTOR = ir.VectorType(_DOUBLE, LANES), ir.VectorType(_DOUBLE, HALF)


def project_block(rows, inverse_mass, sweep, lam, carried, k, kind=0):
    """Constraints k to k + LANES - 1 of ``sweep`` (one segment) projected on the coordinate rows ``rows`` =
    (d, x), (3, M) each: d the displacement, moved, x the start positions; the multipliers ``lam`` when
    ``carried``. ``kind``, a constant (:func:`.constraint_projection.block_kinds`): its low bits how the
    block's bodies lie (0 or RUN), plus EQUAL_MASSES where w_i = w_j in every lane, whose
    code makes one product a lane for both moves. In Python, one after another (:func:`project_one`),
    whatever the kind: the same bytes."""
    d, x = rows
    for p in range(k, k + LANES):
        project_one(p, d, x, inverse_mass, sweep, lam, carried)


def project_one(p, d, x, inverse_mass, sweep, lam, carried):
    """Constraint ``p`` of ``sweep`` projected on the coordinate rows ``d`` (the displacement, moved) and ``x``
    (start positions), alone: the sweep's scalar step (a segment's last few constraints; and in Python,
    :func:`project_block`'s twin); the multiplier ``lam[p]`` when ``carried``."""
    a, b = np.intp(sweep.i[p]), np.intp(sweep.j[p])
    u0, u1, u2 = d[0, b] - d[0, a], d[1, b] - d[1, a], d[2, b] - d[2, a]
    e0, e1, e2 = x[0, b] - x[0, a] + u0, x[1, b] - x[1, a] + u1, x[2, b] - x[2, a] + u2
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
    d[0, a], d[1, a], d[2, a] = d[0, a] + wa * e0, d[1, a] + wa * e1, d[2, a] + wa * e2
    d[0, b], d[1, b], d[2, b] = d[0, b] + wb * e0, d[1, b] + wb * e1, d[2, b] + wb * e2


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


def _dot3(builder, p, q):
    """p_x q_x + p_y q_y + p_z q_z lane by lane, left to right (the scalar code's order)."""
    products = [builder.fmul(p[c], q[c]) for c in range(3)]
    return builder.fadd(builder.fadd(products[0], products[1]), products[2])


class _Block(NamedTuple):
    """Where a block's data lie: the coordinate rows of ``d`` and ``x`` (pointers to their first float64), the
    rows' length ``m`` (intp), the inverse masses, the multipliers and the sweep's columns by name
    (pointers to their elements), the first constraint ``k`` (intp)."""

    d: ir.Value
    x: ir.Value
    m: ir.Value
    inverse_mass: ir.Value
    lam: ir.Value
    column: dict
    k: ir.Value


def _bodies(builder, block: _Block, layout: int) -> list:
    """Each lane's bodies, [[a_0 .. a_7], [b_0 .. b_7]] (intp): in a RUN i[k] and j[k] plus the lane, two loads
    and constant offsets; elsewhere the i and j columns' LANES entries from k."""
    i64 = ir.IntType(64)
    if layout == RUN:  # each half of the lanes a run of its own: i[k] and i[k + HALF] plus the lane
        at = [block.k, builder.add(block.k, ir.Constant(block.k.type, HALF))]
        firsts = [[builder.zext(builder.load(builder.gep(block.column[name], [k])), i64) for k in at] for name in "ij"]
        return [[builder.add(half[lane // HALF], ir.Constant(i64, lane % HALF)) for lane in range(LANES)]
                for half in firsts]
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


class _Coordinate:
    """One coordinate row of ``d`` or ``x`` as a block reads and writes it: ``ends`` (a's lanes, b's lanes) as
    gathered, and :meth:`move` adding each end's moves into the row (RUN: a vector of HALF a half of each
    end; by index: a value a lane)."""

    def __init__(self, builder, row, bodies, layout):
        self.builder, self.row, self.bodies, self.layout = builder, row, bodies, layout
        if layout == RUN:  # two vectors of HALF a end, from its halves' first bodies
            self.ends = [self._run(row, ends) for ends in bodies]
            return
        self.ends = []
        for ends in bodies:
            lanes = ir.Constant(_LANE_VECTOR, None)
            for lane, body in enumerate(ends):
                lanes = builder.insert_element(lanes, builder.load(builder.gep(row, [body])), ir.Constant(_INT32, lane))
            self.ends.append(lanes)

    def _run(self, row, ends):
        """The lanes of ``ends`` (a RUN's: two halves of HALF consecutive bodies) from ``row``, two vector loads."""
        halves = [_load(self.builder, row, ends[h * HALF], _HALF_VECTOR) for h in range(2)]
        return self.builder.shuffle_vector(*halves, _constant(range(LANES), LANES))

    def move(self, operations, steps):
        """Each end's row r becomes ``operation(r, step)`` lane by lane (``operations`` and ``steps`` = [a's, b's]),
        stored where it was read. The rows are read again here, through a pointer LLVM cannot see is the
        same row (an empty inline asm): the gathered ends would otherwise stay live across the solve, and
        on AVX2's sixteen registers they were spilled to the stack and reloaded (a RUN block 8 % slower)."""
        builder = self.builder
        row = builder.asm(ir.FunctionType(self.row.type, [self.row.type]), "", "=r,0", [self.row], False, "row")
        for operation, step, ends in zip(operations, steps, self.bodies):
            if self.layout == RUN:
                lanes = operation(self._run(row, ends), step)
                for h in range(2):
                    half = builder.shuffle_vector(lanes, lanes, _constant(range(h * HALF, (h + 1) * HALF), HALF))
                    _store(builder, half, row, ends[h * HALF])
                continue
            for lane, body in enumerate(ends):
                at = builder.gep(row, [body])
                builder.store(operation(builder.load(at), builder.extract_element(step, ir.Constant(_INT32, lane))), at)


def _emit(builder, block: _Block, carried: bool, layout: int, equal: bool) -> None:
    """The block's code, for multipliers ``carried`` or held at 0 (each its own code: no branch inside), its
    bodies lying as ``layout`` says, its ends' inverse masses ``equal`` in every lane or not."""
    def lanes(name, data=None):
        return _load(builder, block.column[name] if data is None else data, block.k, _LANE_VECTOR)

    # gather: each coordinate of both ends, of d and x, in lanes; u = d_b - d_a and e = (x_b - x_a) + u
    bodies = _bodies(builder, block, layout)
    row = lambda data, c: builder.gep(data, [builder.mul(block.m, ir.Constant(block.m.type, c))])
    d = [_Coordinate(builder, row(block.d, c), bodies, layout) for c in range(3)]
    x = [_Coordinate(builder, row(block.x, c), bodies, layout) for c in range(3)]
    u = [builder.fsub(d[c].ends[1], d[c].ends[0]) for c in range(3)]
    e = [builder.fadd(builder.fsub(x[c].ends[1], x[c].ends[0]), u[c]) for c in range(3)]
    squared, approach = _dot3(builder, e, e), _dot3(builder, e, u)
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
    # scatter: d_a += (-(w_a s)) e, d_b += (w_b s) e; with w_a = w_b in every lane, d_a + (-(w s)) e =
    # d_a - (w s) e exactly: one product a lane
    if equal:
        weight = builder.fmul(_masses(builder, block, bodies[0]), s)
        for c in range(3):
            step = builder.fmul(weight, e[c])
            d[c].move((builder.fsub, builder.fadd), (step, step))
        return
    weights = [builder.fmul(_masses(builder, block, ends), s) for ends in bodies]
    weights[0] = builder.fneg(weights[0])
    for c in range(3):
        d[c].move((builder.fadd, builder.fadd), [builder.fmul(weights[n], e[c]) for n in range(2)])


@intrinsic(prefer_literal=True)
def _project_block(typingctx, rows, inverse_mass, sweep, lam, carried, k, kind):
    if not isinstance(rows, types.UniTuple) or rows.count != 2:
        return None
    floats = (rows.dtype, inverse_mass, lam)
    if not (all(isinstance(a, types.Array) and a.dtype == types.float64 and a.layout == "C" for a in floats)
            and rows.dtype.ndim == 2
            and isinstance(sweep, types.BaseNamedTuple) and isinstance(k, types.Integer)
            and isinstance(kind, types.IntegerLiteral)):
        return None
    layout, equal = kind.literal_value & ~EQUAL_MASSES, bool(kind.literal_value & EQUAL_MASSES)

    def codegen(context, builder, signature, args):
        rows_, mass_, sweep_, lam_, carried_, k_, _ = args
        arrays = [context.make_array(rows.dtype)(context, builder, builder.extract_value(rows_, n)) for n in range(2)]
        data = [a.data for a in arrays] + [builder.extract_value(arrays[0].shape, 1)]
        data += [_data(context, builder, t, a) for t, a in ((inverse_mass, mass_), (lam, lam_))]
        column = {name: _data(context, builder, sweep.types[n], builder.extract_value(sweep_, n))
                  for n, name in enumerate(sweep.fields) if name not in ("segments", "kinds")}
        block = _Block(*data, column, context.cast(builder, k_, k, types.intp))
        with builder.if_else(carried_) as (carrying, holding):
            with carrying:
                _emit(builder, block, True, layout, equal)
            with holding:
                _emit(builder, block, False, layout, equal)
        return context.get_dummy_value()

    return types.void(rows, inverse_mass, sweep, lam, carried, k, kind), codegen


@overload(project_block, inline="always", prefer_literal=True)
def _project_block_compiled(rows, inverse_mass, sweep, lam, carried, k, kind=0):
    if not isinstance(kind, types.IntegerLiteral):
        return None
    return lambda rows, inverse_mass, sweep, lam, carried, k, kind=0: _project_block(
        rows, inverse_mass, sweep, lam, carried, k, kind)
