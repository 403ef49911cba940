"""Four-wide float64 loads and stores for the constraint sweep's gather and scatter (Numba intrinsics).

The sweep keeps each body's position and displacement as a padded row of four float64
(x, y, z, 0; 32 bytes), so that a body's three coordinates move in one 256-bit load or
store instead of three scalar ones. Numba does not emit those by itself: its loop
vectoriser leaves the gather and scatter (indirect, one body pair at a time) scalar, and
the SLP vectoriser that would pair the three coordinates is off in Numba (disabled for
miscompilations, numba/numba#8852). So the two operations the sweep needs are written
here as LLVM vector operations:

- :func:`gather4` ``(out, k, x, d, a, b)``: ``out[k:k+4] = (x[b:b+4] - x[a:a+4]) + (d[b:b+4] - d[a:a+4])``
  and returns ``(e0 e0 + e1 e1 + e2 e2, e0 u0 + e1 u1 + e2 u2)`` with e that difference and
  u = d[b:b+4] - d[a:a+4], summed left to right;
- :func:`axpy4` ``(y, i, x, j, w)``: ``y[i:i+4] += w x[j:j+4]``;
- :func:`prefetch` ``(a, k)``: a software prefetch of the cache line holding ``a.flat[k]``
  (LLVM's ``llvm.prefetch``, x86 ``prefetcht0``), which moves nothing the program sees.

Each lane is the scalar operation it replaces (IEEE add, subtract and multiply, no fused
multiply-add, the sums in the scalar order), so the bytes are those of the scalar code; the
plain Python functions here are that scalar code, which ``py_func`` runs and the tests
compare against (``prefetch``'s is a no-op). Indices are element offsets (4 * body); nothing is
bounds-checked (a prefetch past an array's end is harmless: it never faults).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload

_LANES = 4
_VECTOR = ir.VectorType(ir.DoubleType(), _LANES)


def gather4(out, k, x, d, a, b):
    """out[k:k+4] = e = (x[b:b+4] - x[a:a+4]) + u, u = d[b:b+4] - d[a:a+4]; returns (|e|^2, e . u) over lanes 0-2."""
    u = d[b:b + 4] - d[a:a + 4]
    e = x[b:b + 4] - x[a:a + 4] + u
    out[k:k + 4] = e
    return e[0] * e[0] + e[1] * e[1] + e[2] * e[2], e[0] * u[0] + e[1] * u[1] + e[2] * u[2]


def axpy4(y, i, x, j, w):
    """y[i:i+4] += w x[j:j+4]."""
    y[i:i + 4] += w * x[j:j + 4]


def prefetch(a, k):
    """Ask for the cache line holding element ``k`` of ``a`` (flat), ahead of its use; in Python, nothing."""


def _pointer(context, builder, array_type, array, index):
    """The address of element ``index`` of a Numba array, as a pointer to four float64."""
    data = context.make_array(array_type)(context, builder, array).data
    return builder.bitcast(builder.gep(data, [index]), _VECTOR.as_pointer())


def _load(builder, pointer):
    return builder.load(pointer, align=8)  # 8: rows need not be 32-byte aligned (vmovupd)


def _lane(builder, vector, lane: int):
    return builder.extract_element(vector, ir.Constant(ir.IntType(32), lane))


def _dot3(builder, p, q):
    """p0 q0 + p1 q1 + p2 q2, left to right, as the scalar code sums it."""
    products = builder.fmul(p, q)
    total = builder.fadd(_lane(builder, products, 0), _lane(builder, products, 1))
    return builder.fadd(total, _lane(builder, products, 2))


def _float64_arrays(*arrays) -> bool:
    return all(isinstance(a, types.Array) and a.dtype == types.float64 and a.layout == "C" for a in arrays)


@intrinsic
def _gather4(typingctx, out, k, x, d, a, b):
    if not _float64_arrays(out, x, d):
        return None

    def codegen(context, builder, signature, args):
        out_, k_, x_, d_, a_, b_ = args
        array_of = dict(zip(("out", "x", "d"), (signature.args[0], signature.args[2], signature.args[3])))
        u = builder.fsub(_load(builder, _pointer(context, builder, array_of["d"], d_, b_)),
                         _load(builder, _pointer(context, builder, array_of["d"], d_, a_)))
        e = builder.fsub(_load(builder, _pointer(context, builder, array_of["x"], x_, b_)),
                         _load(builder, _pointer(context, builder, array_of["x"], x_, a_)))
        e = builder.fadd(e, u)
        builder.store(e, _pointer(context, builder, array_of["out"], out_, k_), align=8)
        return context.make_tuple(builder, signature.return_type, [_dot3(builder, e, e), _dot3(builder, e, u)])

    return types.UniTuple(types.float64, 2)(out, k, x, d, a, b), codegen


@intrinsic
def _axpy4(typingctx, y, i, x, j, w):
    if not _float64_arrays(y, x):
        return None

    def codegen(context, builder, signature, args):
        y_, i_, x_, j_, w_ = args
        target = _pointer(context, builder, signature.args[0], y_, i_)
        weight = cgutils.get_null_value(_VECTOR)
        for lane in range(_LANES):
            weight = builder.insert_element(weight, w_, ir.Constant(ir.IntType(32), lane))
        moved = builder.fmul(weight, _load(builder, _pointer(context, builder, signature.args[2], x_, j_)))
        builder.store(builder.fadd(_load(builder, target), moved), target, align=8)
        return context.get_dummy_value()

    return types.void(y, i, x, j, w), codegen


#: llvm.prefetch's arguments: a read (0, not a write), kept in every cache level (locality 3: prefetcht0), data (1)
_READ, _LOCALITY, _DATA = 0, 3, 1


@intrinsic
def _prefetch(typingctx, a, k):
    if not (isinstance(a, types.Array) and a.layout == "C" and isinstance(k, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        a_, k_ = args
        data = context.make_array(signature.args[0])(context, builder, a_).data
        # no `inbounds`: k may lie past the end, which a prefetch (an x86 hint) allows
        address = builder.bitcast(builder.gep(data, [k_]), ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [address.type, i32, i32, i32]), "llvm.prefetch.p0")
        builder.call(function, [address] + [ir.Constant(i32, n) for n in (_READ, _LOCALITY, _DATA)])
        return context.get_dummy_value()

    return types.void(a, k), codegen


@overload(gather4, inline="always")
def _gather4_compiled(out, k, x, d, a, b):
    return lambda out, k, x, d, a, b: _gather4(out, k, x, d, a, b)


@overload(axpy4, inline="always")
def _axpy4_compiled(y, i, x, j, w):
    return lambda y, i, x, j, w: _axpy4(y, i, x, j, w)


@overload(prefetch, inline="always")
def _prefetch_compiled(a, k):
    return lambda a, k: _prefetch(a, k)
