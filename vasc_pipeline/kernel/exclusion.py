"""The exclusion term's traversal: sum_v (D_v L_v)^6 over the voxels a segment crosses.

The depth map as the kernel holds it (:func:`leap_map`, :func:`depth_fields`,
:func:`exclusion_fields`), the exact Amanatides-Woo walk (:func:`segment_exclusion`, with an
early stop for rejected moves) and the recomputation of every segment's sum.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_norc, jit_norc_inline, prefetch
from ..model.physics import TABLE_EXCLUSION
from .state import EXCLUSION, _add

__all__ = [
    "LEAP_BLOCK",
    "PREFETCH_LEAD",
    "depth_fields",
    "exclusion_fields",
    "leap_map",
    "recompute_exclusion",
    "segment_exclusion",
    "segment_exclusion_capped",
]


@jit_norc_inline
def _distance3(a, b):
    dx = a[0] - b[0]
    dy = a[1] - b[1]
    dz = a[2] - b[2]
    return math.sqrt(dx * dx + dy * dy + dz * dz)


# Side of the grid-aligned blocks the traversal leaps over (a power of two).
LEAP_BLOCK = 16
_BLOCK_MASK = LEAP_BLOCK - 1
# Voxels ahead of the walk whose depth is prefetched (benchmarks/README.md, "Prefetching the depth map").
PREFETCH_LEAD = 16.0


def leap_map(distance):
    """The exclusion distance map as the traversal reads it (the kernel holds it as
    :func:`depth_fields`): the depth inside the domain; outside it -1 where the voxel's block
    (``LEAP_BLOCK`` voxels a side, aligned with the grid) holds no domain voxel, else 0. The
    walk leaps over such a block instead of visiting its voxels, which add nothing to the sum
    (in the first half of a heart run, a fifth to a half of the voxels a segment crosses;
    measured on an N = 1000 run). Blocks of 16 measured faster than 8 (more
    leaps, each ~30 ns of dependent arithmetic) and 32 (fewer empty blocks)."""
    distance = np.asarray(distance, dtype=np.float32)
    inside = distance > 0.0
    block_of = [np.arange(n) // LEAP_BLOCK for n in distance.shape]  # per axis: voxel index -> block index
    occupied_blocks = np.zeros([int(i[-1]) + 1 for i in block_of], dtype=bool)
    z, y, x = np.nonzero(inside)
    occupied_blocks[z // LEAP_BLOCK, y // LEAP_BLOCK, x // LEAP_BLOCK] = True
    leap = np.where(occupied_blocks[np.ix_(*block_of)], np.float32(0.0), np.float32(-1.0))
    np.copyto(leap, distance, where=inside)
    return leap


def depth_fields(depth_map, origin, voxel_size):
    """``Model``'s ``depth_index``, ``depth_values``, ``depth_origin`` and ``depth_voxel_size`` for
    a depth map (plain or :func:`leap_map`) on the grid of ``origin`` (voxel [0, 0, 0]'s centre,
    [x, y, z], m) and ``voxel_size`` (m): the map's distinct float32 values and, per voxel, the index of its
    value, so that ``depth_values[depth_index]`` is the map bit for bit. A distance transform
    takes few distinct values (square roots of integers: 4 361 at N = 6000), so the index
    grid is uint16, half the float32 map's bytes: the traversal's loads then miss the cache
    less on the large grids of organ-scale runs (measured in benchmarks/README.md, "A compact depth map")."""
    values, index = np.unique(np.asarray(depth_map, dtype=np.float32), return_inverse=True)
    dtype = np.uint16 if len(values) <= 1 << 16 else np.uint32
    return {
        "depth_index": np.ascontiguousarray(index.reshape(np.shape(depth_map)), dtype=dtype),
        "depth_values": values,
        "depth_origin": np.asarray(origin, dtype=np.float64),
        "depth_voxel_size": float(voxel_size),
    }


def exclusion_fields(grid) -> dict:
    """:func:`depth_fields` of an exclusion grid (:class:`vasc_pipeline.model.tissue.ExclusionGrid`:
    its ``distance``, ``origin``, ``voxel_size``) as the traversal reads it (:func:`leap_map`).
    The one way a ``Model`` gets its exclusion term's grid: the tissue's own, one fixed in
    metres (``tissue.exclusion_voxel_size``) or either coarsened (``anneal.coarse_exclusion_*``)."""
    return depth_fields(leap_map(grid.distance), grid.origin, grid.voxel_size)


@jit_norc_inline
def segment_exclusion(model, p0, p1):
    """sum_v (D_v L_v)^6 over voxels crossed by p0 -> p1 (exact Amanatides-Woo traversal).

    Voxel coordinates put voxel centres at integers; the segment is clipped to the grid.
    """
    return segment_exclusion_capped(model, p0, p1, np.inf)


@jit_norc_inline
def segment_exclusion_capped(model, p0, p1, cap):
    """:func:`segment_exclusion`, stopped at the first voxel that takes the sum above ``cap``.

    The sum then returned exceeds ``cap`` and is a prefix of the full one, so no larger than
    it (every voxel adds a term >= 0, each addition rounding monotonically): a move rejected
    on it is rejected on the full sum. At or below ``cap`` it is the full sum, bit for bit.
    """
    o = model.depth_origin
    index, values, h = model.depth_index, model.depth_values, model.depth_voxel_size
    return _traverse(
        index, values, o[0], o[1], o[2], h, p0[0], p0[1], p0[2], p1[0], p1[1], p1[2], cap, model.prefetch_lead
    )


@jit_norc
def _traverse(depth_index, depth_values, ox, oy, oz, h, p0x, p0y, p0z, p1x, p1y, p1z, cap, lead):
    """:func:`segment_exclusion_capped` on scalars: a call passes a few words, not the whole
    ``Model`` (numba passes a named tuple field by field, each array as its full descriptor).
    ``lead``: voxels ahead of the walk whose cache line is prefetched (``Model.prefetch_lead``;
    0: none); the sum does not depend on it."""
    nz, ny, nx = depth_index.shape
    flat = depth_index.reshape(-1)
    ux = (p0x - ox) / h
    uy = (p0y - oy) / h
    uz = (p0z - oz) / h
    dx = (p1x - ox) / h - ux
    dy = (p1y - oy) / h - uy
    dz = (p1z - oz) / h - uz
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return 0.0
    t0 = 0.0
    t1 = 1.0
    # Liang-Barsky clip against the grid box [-0.5, n - 0.5) on each axis.
    for u, d, n in ((ux, dx, nx), (uy, dy, ny), (uz, dz, nz)):
        if d == 0.0:
            if u < -0.5 or u >= n - 0.5:
                return 0.0
        else:
            ta = (-0.5 - u) / d
            tb = (n - 0.5 - u) / d
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
    if t0 >= t1:
        return 0.0
    ix = min(max(math.floor(ux + t0 * dx + 0.5), 0), nx - 1)
    iy = min(max(math.floor(uy + t0 * dy + 0.5), 0), ny - 1)
    iz = min(max(math.floor(uz + t0 * dz + 0.5), 0), nz - 1)
    sx = 1 if dx > 0.0 else -1
    sy = 1 if dy > 0.0 else -1
    sz = 1 if dz > 0.0 else -1
    # Parameter of the next plane crossing on each axis, computed from the plane itself
    # (not accumulated, so no drift along long segments); multiplying by the reciprocal
    # keeps the divide off the loop's critical path. (A branch-free axis choice measured
    # slower: the loop is bound by loads of the depth map, not by mispredictions.)
    rx = 1.0 / dx if dx != 0.0 else 0.0
    ry = 1.0 / dy if dy != 0.0 else 0.0
    rz = 1.0 / dz if dz != 0.0 else 0.0
    tx = (ix + 0.5 * sx - ux) * rx if dx != 0.0 else np.inf
    ty = (iy + 0.5 * sy - uy) * ry if dy != 0.0 else np.inf
    tz = (iz + 0.5 * sz - uz) * rz if dz != 0.0 else np.inf
    # The flat index is stepped by strides; the per-axis indices check the grid's bounds
    # before it moves, so it never leaves the map. Unsigned, so that numba adds no
    # negative-index fix-up to each load; a backward stride is the modulo-2^64 negative.
    idx = np.uint64((iz * ny + iy) * nx + ix)
    # The voxel ``lead`` steps ahead is, to a voxel or so, a fixed flat offset away;
    # prefetching it lets its load start before the walk's mispredicted axis choices would
    # let the core reach it. Exact position does not matter: only its cache line.
    lead_t = lead / (abs(dx) + abs(dy) + abs(dz))
    ahead = np.uint64(round(dx * lead_t) + nx * (round(dy * lead_t) + ny * round(dz * lead_t)))
    n_flat = np.uint64(flat.size) if lead > 0.0 else np.uint64(0)
    stride_x = np.uint64(1) if sx > 0 else np.uint64(-1)
    stride_y = np.uint64(nx) if sy > 0 else np.uint64(-nx)
    stride_z = np.uint64(nx * ny) if sz > 0 else np.uint64(-nx * ny)
    t = t0
    acc = 0.0
    while True:
        if idx + ahead < n_flat:
            prefetch(flat, idx + ahead)
        tn = min(tx, ty, tz, t1)
        depth = depth_values[flat[idx]]
        if depth > 0.0:
            if tn > t:
                x = depth * ((tn - t) * length)
                x3 = x * x * x
                acc += x3 * x3
                if acc > cap:
                    break
        elif depth < 0.0:
            # This voxel's block of the grid holds no domain voxel: its voxels add nothing, so
            # leap to the first voxel past the block, in the state the walk would reach there.
            # (The block's bounds follow from the indices, not from the loaded value, so the
            # next load's address does not wait on this one.)
            lx = ix | _BLOCK_MASK if sx > 0 else ix & ~_BLOCK_MASK
            ly = iy | _BLOCK_MASK if sy > 0 else iy & ~_BLOCK_MASK
            lz = iz | _BLOCK_MASK if sz > 0 else iz & ~_BLOCK_MASK
            ex = (lx + 0.5 * sx - ux) * rx if dx != 0.0 else np.inf
            ey = (ly + 0.5 * sy - uy) * ry if dy != 0.0 else np.inf
            ez = (lz + 0.5 * sz - uz) * rz if dz != 0.0 else np.inf
            t_exit = min(ex, ey, ez)
            if not t_exit < t1:  # also a NaN endpoint, which would never leave the block
                break
            if dx != 0.0:
                ix = _past_planes(ix, sx, lx, ux, dx, rx, t_exit, ex == t_exit)
                if ix < 0 or ix >= nx:
                    break
                tx = (ix + 0.5 * sx - ux) * rx
            if dy != 0.0:
                iy = _past_planes(iy, sy, ly, uy, dy, ry, t_exit, ey == t_exit)
                if iy < 0 or iy >= ny:
                    break
                ty = (iy + 0.5 * sy - uy) * ry
            if dz != 0.0:
                iz = _past_planes(iz, sz, lz, uz, dz, rz, t_exit, ez == t_exit)
                if iz < 0 or iz >= nz:
                    break
                tz = (iz + 0.5 * sz - uz) * rz
            idx = np.uint64((iz * ny + iy) * nx + ix)
            t = t_exit
            continue
        if tn >= t1:
            break
        if tx <= ty and tx <= tz:
            ix += sx
            if ix < 0 or ix >= nx:
                break
            idx += stride_x
            tx = (ix + 0.5 * sx - ux) * rx
        elif ty <= tz:
            iy += sy
            if iy < 0 or iy >= ny:
                break
            idx += stride_y
            ty = (iy + 0.5 * sy - uy) * ry
        else:
            iz += sz
            if iz < 0 or iz >= nz:
                break
            idx += stride_z
            tz = (iz + 0.5 * sz - uz) * rz
        t = tn
    return acc


@jit_norc_inline
def _past_planes(i, s, last, u, d, r, t_exit, exits):
    """The first index j from voxel i in direction s whose next plane parameter, computed as the
    walk computes it, exceeds t_exit: where the walk is on this axis once it has crossed every
    plane up to t_exit. The two loops alone decide; the start (past the block's last index on
    the axis the walk leaves the block by, a guess from the position on the others) only saves
    their iterations."""
    guess = math.floor(u + t_exit * d + 0.5)
    guess = min(max(guess, i), last) if s > 0 else max(min(guess, i), last)
    j = last + s if exits else guess
    while (j + 0.5 * s - u) * r <= t_exit:
        j += s
    while j != i and (j - 0.5 * s - u) * r > t_exit:
        j -= s
    return j


@jit
def recompute_exclusion(model, state):
    """Every segment's exclusion sum and the running exclusion cost from scratch, on the
    model's depth map (0 with the term off): also how a run changes depth maps
    (:func:`exclusion_fields`)."""
    state.costs[EXCLUSION] = 0.0
    state.compensation[EXCLUSION] = 0.0
    state.seg_exclusion[:] = 0.0
    if not model.exclusion_on:
        return
    pos = state.position
    for i in range(model.n_inlets, state.parent.size):
        s = segment_exclusion(model, pos[i], pos[state.parent[i]])
        state.seg_exclusion[i] = s
        _add(state.costs, state.compensation, EXCLUSION, model.tables[TABLE_EXCLUSION, state.n_downstream[i]] * s)
