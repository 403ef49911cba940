"""The constraint sweep's software prefetch (a Numba intrinsic).

The sweep (:mod:`.constraint_projection`) reads its columns once a step, from memory when the
caches are cold; it asks for them a little ahead of their use, so that those reads overlap its
work (the hardware prefetcher alone leaves them mostly unoverlapped, docs/performance.md).

- :func:`prefetch` ``(a, k)``: a software prefetch of the cache line holding ``a.flat[k]``
  (LLVM's ``llvm.prefetch``, x86 ``prefetcht0``), which moves nothing the program sees; its
  plain Python twin is a no-op. Nothing is bounds-checked: a prefetch past an array's end is
  harmless (it never faults).
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, overload


def prefetch(a, k):
    """Ask for the cache line holding element ``k`` of ``a`` (flat), ahead of its use; in Python, nothing."""


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


@overload(prefetch, inline="always")
def _prefetch_compiled(a, k):
    return lambda a, k: _prefetch(a, k)
