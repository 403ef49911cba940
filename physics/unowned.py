"""Arrays viewed at an address, with no owner: binding one in compiled code counts no reference.

Numba counts a reference up and down every time a loop binds an array (a NamedTuple's field, a
tuple unpacked, an inlined function's argument): an atomic operation on the array's owner. An
array made by ``numba.carray`` over a raw pointer has no owner, so those counts cost a test of a
null pointer instead. The memory must outlive the view: the caller keeps the array it points into.
"""

from __future__ import annotations

from llvmlite import ir
from numba import carray, njit, types
from numba.extending import intrinsic


@intrinsic
def pointer(typingctx, address):
    """The int64 ``address`` as a pointer (LLVM's inttoptr), for ``numba.carray``."""
    if not isinstance(address, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], ir.IntType(8).as_pointer())

    return types.voidptr(address), codegen


@njit(inline="always")
def unowned(address, shape, dtype):
    """The array of ``shape`` and ``dtype`` at ``address`` (a view, no copy, no owner)."""
    return carray(pointer(address), shape, dtype)
