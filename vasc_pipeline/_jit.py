"""Numba flags in one place (STYLE: one switch for cache/nogil/fastmath), and the one
intrinsic the kernel needs that numba lacks (a cache prefetch).

``nogil=True`` keeps Dask worker heartbeats alive during long kernel calls;
``fastmath`` stays off so that incremental and full costs agree and runs are bit-identical.
"""

import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

_FLAGS = dict(nogil=True, cache=True, fastmath=False, error_model="numpy")

jit = numba.njit(**_FLAGS)

# Small helpers called per voxel or per row: inlined by numba itself, since calls between
# separately compiled functions cost more than the helpers' own work.
jit_inline = numba.njit(**_FLAGS, inline="always")

# Without reference counting (numba's ``_nrt=False``): for functions that take arrays (also
# inside named tuples) but never allocate or return one. Numba increfs every array argument
# on entry to a function that calls another and decrefs it on exit, an atomic operation
# each: with the kernel's Model and State (29 arrays) that was a third of the time per
# move. The caller keeps every array alive for the call, so the counts are not needed.
jit_norc = numba.njit(**_FLAGS, _nrt=False)
jit_norc_inline = numba.njit(**_FLAGS, _nrt=False, inline="always")


@intrinsic
def prefetch(typingctx, array, index):
    """Ask the CPU to bring ``array[index]`` towards the cache (LLVM's prefetch: read,
    high locality). Only a hint: no value changes, and an address past the array may be
    given without a fault, though callers keep inside it."""

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        address = builder.gep(data, [args[1]])
        i32 = ir.IntType(32)
        fnty = ir.FunctionType(ir.VoidType(), [address.type, i32, i32, i32])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.prefetch.p0")
        builder.call(fn, [address, i32(0), i32(3), i32(1)])  # read, keep in all levels, data
        return context.get_dummy_value()

    return types.void(array, index), codegen
