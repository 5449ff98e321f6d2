"""Numba flags in one place (STYLE: one switch for cache/nogil/fastmath).

``nogil=True`` keeps Dask worker heartbeats alive during long kernel calls (SPEC section 8);
``fastmath`` stays off so that incremental and full costs agree and runs are bit-identical.
"""

import numba

jit = numba.njit(nogil=True, cache=True, fastmath=False, error_model="numpy")

# Small helpers called per voxel or per row: inlined by numba itself, since calls between
# separately compiled functions cost more than the helpers' own work.
jit_inline = numba.njit(nogil=True, cache=True, fastmath=False, error_model="numpy", inline="always")
