"""Numba flags in one place (STYLE: one switch for cache/nogil/fastmath).

``nogil=True`` keeps Dask worker heartbeats alive during long kernel calls (SPEC section 8);
``fastmath`` stays off so that incremental and full costs agree and runs are bit-identical.
"""

import numba

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
