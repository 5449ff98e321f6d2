"""The annealing kernel: incremental costs of translate and swap moves (numba, nogil).

The kernel sees only two named tuples of arrays and scalars (built by
:mod:`vasc_pipeline.engine`):

``Model`` (read-only): the cost tables, the voxel grids, weights, switches and schedule.
``State`` (mutated in place): the tree arrays, per-segment caches (length, exclusion
traversal sum), the supply count map, running cost sums with their Neumaier compensation,
the generator state, counters and step sizes. Everything a resumed run needs is in
``State``; the ``scratch_*`` arrays are not.

:func:`anneal_block` runs a block of proposed moves from ``state`` and returns; the
temperature and every random draw depend only on the step number and the saved state, so
S steps in one block or any split of blocks give bit-identical trees.

Cost term order in ``costs``: :data:`vasc_pipeline.costs.COST_TERMS` (unscaled).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from ._jit import jit, jit_norc, jit_norc_inline, prefetch
from .costs import COST_TERMS
from .physics import TABLE_EXCLUSION, TABLE_FLOW, TABLE_POWER, TABLE_RESISTANCE, TABLE_VOLUME
from .rng import next_below, next_double

Model = namedtuple(
    "Model",
    [
        "n_inlets",
        "n_terminals",
        "tables",  # float64 (5, N + 1): volume, power, exclusion, resistance, flow factors by n
        "mask",  # uint8 (nz, ny, nx)
        "depth_index",  # uint16 (uint32 beyond 65536 values) (nz, ny, nx): the traversal's depth map as
        # indices into depth_values (kernel.depth_fields)
        "depth_values",  # float32: exclusion depth in voxel units inside; 0 outside, or -1 where the
        # traversal may leap the voxel's whole block (kernel.leap_map; never a signed distance)
        "depth_origin",
        "depth_voxel_size",  # the depth map's grid: float64 (3,) [x, y, z] of voxel [0, 0, 0] centre, and
        # edge, m (the exclusion grid's: the tissue's, one fixed in metres, or either coarsened early in a run)
        "origin",  # float64 (3,) [x, y, z] of voxel [0, 0, 0] centre, m
        "voxel_size",  # float, m
        "box_lo",
        "box_hi",  # float64 (3,) grid box, m
        "supply_rho",  # float, supply radius in voxel units
        "w_exclusion",
        "w_pressure",
        "w_supply",  # scaled weights A_x / A_wv
        "supply_on",
        "exclusion_on",
        "pressure_on",
        "move_terminals",
        "planar",
        "pressure_inlet",
        "pressure_terminal",  # Pa
        "total_steps",  # proposals of the run; the exponential schedule (ends in State.schedule) runs
        # from pack_steps to total_steps
        "cold_steps",  # tree anneal steps before the schedule's cold part ...
        "cold_path",  # ... and the share of log(T_end / T_start) covered by then: the schedule is
        # exponential on each side of that point (cold_steps = all tree steps, cold_path = 1: one
        # exponential)
        "pack_steps",  # proposals of the packing phase (vasc_pipeline.packing; 0: none)
        "pack_T_start",
        "pack_T_end",  # its temperatures, C_s units
        "p_swap",  # probability that a proposal is a swap
        "p_local",  # probability that a swap partner is drawn from the neighbour cells (0: uniform only)
        "cell_lo",
        "cell_size",
        "cell_shape",  # neighbour cell grid: lower corner (m), edge (m), int64 (3,) [x, y, z]
        "supply_T_start",
        "supply_T_end",
        "supply_steps",  # supply's own schedule (C_s units) over the first
        # supply_steps proposals; supply_steps = 0: off, the supply weight is w_supply throughout
        "adapt_steps",  # adapt translation half-widths to keep acceptance near acceptance_target
        "full_width_steps",  # with adapt_steps, the tree anneal's steps in which half of the terminal
        # moves keep the full width (step_max[0])
        "acceptance_target",
        "adapt_window",
        "step_max",  # step_max float64 (2,) m: the configured half-widths
        "early_reject",  # skip the exclusion traversals when a lower bound of ΔC fails Metropolis
        # (same decisions and random stream either way; False only to test that)
        "fixed_inlet_counts",  # tissue.inlet_share: a swap between inlet trees must keep their terminal counts
        "bifurcation_region",  # uint8 (nz, ny, nx): where a bifurcation may lie (tissue.bifurcation_reach);
        # shape (0, 0, 0): anywhere in the grid's box
        "supply_shell_width",  # float, voxels: the widest supply shell a terminal keeps (SHELL_WIDTH;
        # 0: none, every supply change row by row; the same sums either way)
        "prefetch_lead",  # float, voxels: how far ahead of a traversal the depth map is prefetched
        # (PREFETCH_LEAD; 0: not at all; the same sums either way)
        "prefetch_supply",  # bool: prefetch the count map's rows under both spheres before a
        # terminal move's supply change is computed row by row (the same sums either way)
    ],
)

State = namedtuple(
    "State",
    [
        "parent",
        "children",
        "position",
        "n_downstream",
        "seg_length",  # float64 (2N,) m
        "seg_exclusion",  # float64 (2N,) sum_v (D_v L_v)^6 of the segment's centre-line
        "supply",  # int16 (int32 for N > 32767; engine.supply_dtype) (nz, ny, nx): supply count per
        # tissue voxel, -1 outside tissue
        "costs",
        "compensation",  # float64 (5,) running sums and their Neumaier compensation
        "rng",  # uint64 (4,)
        "counters",  # int64 (N_COUNTERS,) see COUNTER_*
        "step_size",  # float64 (2,) translation half-width for terminals, bifurcations [m]
        "schedule",  # float64 (2,) T_start, T_end (configured, or calibrated at step 0)
        "cell_of",
        "cell_head",
        "cell_next",
        "cell_prev",  # int64: neighbour cell lists of non-inlet nodes
        "scratch_mark",
        "scratch_stack",
        "scratch_pressure",
        "scratch_cell_count",  # int64: nodes per neighbour cell (derived from cell_of, so never checkpointed)
        "scratch_shell_voxels",  # int16 (N, shell_capacity, 3) [x, y, z]: per terminal, the tissue voxels
        # near its supply sphere's surface (_shell_build; derived from positions, never checkpointed)
        "scratch_shell_bands",  # int64 (N, SHELL_BANDS): where each band of the shell's voxels ends
        "scratch_shell_frame",  # float64 (N, 4): the shell's centre (voxel coordinates x, y, z) and
        # width; width 0: no shell
    ],
)

(
    COUNTER_STEP,
    COUNTER_TERMINAL_PROPOSED,
    COUNTER_TERMINAL_ACCEPTED,
    COUNTER_BIFURCATION_PROPOSED,
    COUNTER_BIFURCATION_ACCEPTED,
    COUNTER_SWAP_PROPOSED,
    COUNTER_SWAP_ACCEPTED,
    COUNTER_LOCAL_SWAP_PROPOSED,
    COUNTER_WINDOW_TERMINAL_PROPOSED,
    COUNTER_WINDOW_TERMINAL_ACCEPTED,
    COUNTER_WINDOW_BIFURCATION_PROPOSED,
    COUNTER_WINDOW_BIFURCATION_ACCEPTED,
) = range(12)
N_COUNTERS = 12
# Per translation class (row 0 terminals, 1 bifurcations) the counters of its proposals
# (column N_PROPOSED) and acceptances (N_ACCEPTED): all moves, and the current adaptation window.
N_PROPOSED, N_ACCEPTED = 0, 1
MOVE_COUNTERS = np.array(
    [
        [COUNTER_TERMINAL_PROPOSED, COUNTER_TERMINAL_ACCEPTED],
        [COUNTER_BIFURCATION_PROPOSED, COUNTER_BIFURCATION_ACCEPTED],
    ]
)
WINDOW_COUNTERS = np.array(
    [
        [COUNTER_WINDOW_TERMINAL_PROPOSED, COUNTER_WINDOW_TERMINAL_ACCEPTED],
        [COUNTER_WINDOW_BIFURCATION_PROPOSED, COUNTER_WINDOW_BIFURCATION_ACCEPTED],
    ]
)

# Indices into State.costs: the order of costs.COST_TERMS (their one home); rows of
# Model.tables: physics.TABLE_*.
VOLUME, POWER, SUPPLY, EXCLUSION, PRESSURE = (
    COST_TERMS.index(term) for term in ("volume", "power", "supply", "exclusion", "pressure")
)
ILLEGAL, REJECTED, ACCEPTED = -1, 0, 1  # outcomes of a proposal


@jit_norc_inline
def _add(costs, compensation, k, x):
    """Neumaier-compensated running sum: long runs drift by O(eps), not O(steps * eps)."""
    s = costs[k]
    t = s + x
    if abs(s) >= abs(x):
        compensation[k] += (s - t) + x
    else:
        compensation[k] += (x - t) + s
    costs[k] = t


@jit_norc_inline
def weighted_total(model, vascular, exclusion, pressure, w_supply, supply):
    """The annealed total (or a change of it) from its terms: the kernel's one copy of
    :func:`vasc_pipeline.costs.total_cost`, C = (C_w + C_v) + w_o C_o + w_p C_p + w_s C_s,
    with ``vascular`` = C_w + C_v and the supply weight passed in (it follows its own
    schedule, :func:`supply_weight`). Same operations in the same order as the reference."""
    return vascular + model.w_exclusion * exclusion + model.w_pressure * pressure + w_supply * supply


@jit_norc
def temperature(model, state, step):
    """Schedule ``state.schedule`` = (T_start, T_end) from pack_steps to total_steps, T_end afterwards:
    exponential in the step, with its rate changed once where the cold part starts (cold_steps,
    cold_path; without a cold part, one exponential)."""
    tree_step = max(step - model.pack_steps, 0.0)
    tree_steps = model.total_steps - model.pack_steps
    if tree_step >= tree_steps:
        frac = 1.0
    elif tree_step < model.cold_steps:
        frac = model.cold_path * (tree_step / model.cold_steps)
    else:
        frac = model.cold_path + (1.0 - model.cold_path) * (
            (tree_step - model.cold_steps) / (tree_steps - model.cold_steps)
        )
    t_start = state.schedule[0]
    return t_start * math.exp(math.log(state.schedule[1] / t_start) * frac)


@jit_norc_inline
def _tree_step(model, state):
    """The tree anneal's own step: proposals since the packing phase ended."""
    return state.counters[COUNTER_STEP] - model.pack_steps


@jit_norc_inline
def supply_weight(model, state, temp):
    """Weight of ΔC_s in the Metropolis test at ``temp``.

    While the supply schedule runs, uphill supply moves are accepted with probability
    exp(-ΔC_s / T_s) (T_s falling exponentially from supply_T_start to supply_T_end): the
    weight is temp / T_s, never above w_supply. Afterwards (and when off) it is w_supply,
    so the run ends on the true cost.
    """
    step = _tree_step(model, state)
    if step >= model.supply_steps:
        return model.w_supply
    frac = step / model.supply_steps
    t_s = model.supply_T_start * math.exp(math.log(model.supply_T_end / model.supply_T_start) * frac)
    return min(model.w_supply, temp / t_s)


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
    """:func:`depth_fields` of an exclusion grid (:class:`vasc_pipeline.tissue.ExclusionGrid`:
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


@jit_norc_inline
def _inside(i, u, d2, e2, rho2):
    """The coverage test of voxel i, written exactly as the NumPy reference writes it."""
    dx = i - u
    return (dx * dx + d2) + e2 <= rho2


_ROUNDING = 1e-9  # an interval end this close to a voxel centre is settled by the exact test ...
_TANGENT = 1e-12  # ... and every voxel of a row this close to tangent (r^2 below it times rho^2)


@jit_norc_inline
def _row_interval(u, d2, e2, rho2, n):
    """Voxels i of one grid row whose centre lies within a sphere, clipped to [0, n).

    ``d2``, ``e2``: squared offsets of the row from the centre in the other two axes; ``u``
    the centre's coordinate along the row. The square root gives the ends; where an end
    falls within rounding of a voxel centre, or the row is nearly tangent to the sphere, the
    exact test settles it, so the result equals a voxel-by-voxel test. Returns (lo, hi),
    empty when lo > hi.
    """
    rem = (rho2 - e2) - d2
    if rem < -_ROUNDING * rho2:
        return 1, 0
    r = math.sqrt(max(rem, 0.0))
    # The test's sums round by under 1e-15 rho^2, which moves an end by under 1e-15 rho^2 / (2 r):
    # within the window below unless the row is nearly tangent (r < 1e-6 rho).
    window = _ROUNDING * (1.0 + rho2)
    tangent = rem < _TANGENT * rho2
    x = u - r
    lo = math.ceil(x)
    if tangent or lo - x < window or x - (lo - 1) < window:
        c = math.floor(u + 0.5)  # nearest voxel centre: inside if any is
        if not _inside(c, u, d2, e2, rho2):
            return 1, 0
        lo = min(lo, c)
        while _inside(lo - 1, u, d2, e2, rho2):
            lo -= 1
        while not _inside(lo, u, d2, e2, rho2):
            lo += 1
    x = u + r
    hi = math.floor(x)
    if tangent or x - hi < window or (hi + 1) - x < window:
        c = math.floor(u + 0.5)
        if not _inside(c, u, d2, e2, rho2):
            return 1, 0
        hi = max(hi, c)
        while _inside(hi + 1, u, d2, e2, rho2):
            hi += 1
        while not _inside(hi, u, d2, e2, rho2):
            hi -= 1
    return max(lo, 0), min(hi, n - 1)


@jit_norc_inline
def _voxel_coords(model, x, y, z):
    h = model.voxel_size
    return (x - model.origin[0]) / h, (y - model.origin[1]) / h, (z - model.origin[2]) / h


@jit_norc_inline
def _in_voxels(model, grid, p):
    """True when the point p [m] lies in a nonzero voxel of ``grid`` (a uint8 map of the tissue's grid)."""
    nz, ny, nx = grid.shape
    ux, uy, uz = _voxel_coords(model, p[0], p[1], p[2])
    ix = math.floor(ux + 0.5)
    iy = math.floor(uy + 0.5)
    iz = math.floor(uz + 0.5)
    return 0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz and grid[iz, iy, ix] != 0


@jit_norc_inline
def in_tissue(model, p):
    """True when the point p [m] lies in a tissue voxel (where a terminal may be)."""
    return _in_voxels(model, model.mask, p)


@jit_norc_inline
def _gain_change(b):
    """C_s change when a tissue voxel covered b times gains a sphere: s(0) = 10,
    s(b) = (b - 1)^2, so s(b + 1) - s(b) = 2b - 1 - 9 [b = 0]."""
    return (2 * b - 1) - 9 * (b == 0)


@jit_norc_inline
def _loss_change(b):
    """C_s change when a tissue voxel covered b times loses a sphere: s(b - 1) - s(b) = 3 - 2b + 9 [b = 1]."""
    return (3 - 2 * b) + 9 * (b == 1)


@jit_norc_inline
def _range_change(supply, k, j, lo, hi, sign, write):
    """C_s change when voxels lo..hi of row (k, j) gain ``sign`` (:func:`_gain_change`,
    :func:`_loss_change`); non-tissue voxels hold -1 and contribute 0."""
    # The loops exit early on a count below -1 (none is): LLVM does not vectorise loops
    # with two exits, and these are a few voxels long, where a vectorised loop's set-up
    # and remainder cost more than they save (measured: -25 % time per supply delta).
    delta = 0
    if sign > 0:
        for i in range(lo, hi + 1):
            b = np.int64(supply[k, j, i])
            if b < -1:
                break
            delta += (b >= 0) * _gain_change(b)
    else:
        for i in range(lo, hi + 1):
            b = np.int64(supply[k, j, i])
            if b < -1:
                break
            delta += (b >= 0) * _loss_change(b)
    if write:
        for i in range(lo, hi + 1):
            if supply[k, j, i] >= 0:
                supply[k, j, i] += sign
    return delta


@jit_norc_inline
def _row_change(supply, k, j, lo, hi, other_lo, other_hi, sign, write):
    """C_s change when voxels lo..hi of row (k, j), except other_lo..other_hi, gain ``sign``."""
    if other_lo > other_hi or other_hi < lo or other_lo > hi:  # nothing to exclude
        return _range_change(supply, k, j, lo, hi, sign, write)
    return _range_change(supply, k, j, lo, other_lo - 1, sign, write) + _range_change(
        supply, k, j, other_hi + 1, hi, sign, write
    )


@jit_norc_inline
def _sphere_change(model, supply, old, new, write):
    """Change of C_s when a supply sphere moves from ``old`` to ``new`` (either may be NaN: absent).

    Only voxels in one sphere but not the other change; with ``write`` the counts are
    updated. ``supply`` holds -1 outside tissue.
    """
    ox, oy, oz = _voxel_coords(model, old[0], old[1], old[2])  # NaN stays NaN: absent
    nx_, ny_, nz_ = _voxel_coords(model, new[0], new[1], new[2])
    return _sphere_rows(supply, model.supply_rho, ox, oy, oz, nx_, ny_, nz_, write)


@jit_norc
def _sphere_rows(supply, rho, ox, oy, oz, nx_, ny_, nz_, write):
    """:func:`_sphere_change` on the spheres' centres in voxel coordinates: a call passes a
    few words, not the whole ``Model`` (numba passes a named tuple field by field)."""
    nz, ny, nx = supply.shape
    rho2 = rho * rho
    has_old = not math.isnan(ox)
    has_new = not math.isnan(nx_)
    z_lo = nz
    z_hi = -1
    if has_old:
        z_lo = min(z_lo, math.floor(oz - rho))
        z_hi = max(z_hi, math.ceil(oz + rho))
    if has_new:
        z_lo = min(z_lo, math.floor(nz_ - rho))
        z_hi = max(z_hi, math.ceil(nz_ + rho))
    delta = 0
    for k in range(max(z_lo, 0), min(z_hi, nz - 1) + 1):
        do2 = (k - oz) * (k - oz) if has_old else np.inf
        dn2 = (k - nz_) * (k - nz_) if has_new else np.inf
        if do2 > rho2 and dn2 > rho2:
            continue
        y_lo = ny
        y_hi = -1
        if do2 <= rho2:
            ry = math.sqrt(rho2 - do2)
            y_lo = min(y_lo, math.floor(oy - ry) - 1)
            y_hi = max(y_hi, math.ceil(oy + ry) + 1)
        if dn2 <= rho2:
            ry = math.sqrt(rho2 - dn2)
            y_lo = min(y_lo, math.floor(ny_ - ry) - 1)
            y_hi = max(y_hi, math.ceil(ny_ + ry) + 1)
        for j in range(max(y_lo, 0), min(y_hi, ny - 1) + 1):
            o_lo, o_hi = 1, 0
            n_lo, n_hi = 1, 0
            if do2 <= rho2:
                o_lo, o_hi = _row_interval(ox, (j - oy) * (j - oy), do2, rho2, nx)
            if dn2 <= rho2:
                n_lo, n_hi = _row_interval(nx_, (j - ny_) * (j - ny_), dn2, rho2, nx)
            if o_lo <= o_hi:
                delta += _row_change(supply, k, j, o_lo, o_hi, n_lo, n_hi, -1, write)
            if n_lo <= n_hi:
                delta += _row_change(supply, k, j, n_lo, n_hi, o_lo, o_hi, 1, write)
    return float(delta)


_NO_SPHERE = np.array([np.nan, np.nan, np.nan])


@jit_norc
def supply_sphere(model, supply, p, sign):
    """Add (sign = +1) or remove (-1) one supply sphere centred at p; return the change of C_s."""
    if sign > 0:
        return _sphere_change(model, supply, _NO_SPHERE, p, True)
    return _sphere_change(model, supply, p, _NO_SPHERE, True)


@jit_norc_inline
def supply_move_delta(model, supply, old, new):
    """Change of C_s if a sphere moved from ``old`` to ``new``; reads only voxels that change."""
    return _sphere_change(model, supply, old, new, False)


@jit_norc_inline
def supply_move(model, supply, old, new):
    """Move a sphere from ``old`` to ``new`` in the count map."""
    _sphere_change(model, supply, old, new, True)


# Supply shells. Once the adapted terminal steps are a small fraction of a voxel (the second
# half of a run), a move changes the coverage of only the few voxels whose centres lie that
# close to the sphere's surface, yet the rows of both spheres cost ~1 us to compute. So a
# terminal keeps its shell: the tissue voxels within a width of its sphere's surface, listed
# once around a centre, in bands of their distance to the surface. While the terminal and its
# proposed position both stay closer to that centre than the width (less a margin far above
# the distances' rounding), no voxel outside the shell can change coverage, nor any of a band
# farther from the surface than the two positions' distance to the centre; testing the
# others with the row code's own expression gives the same change, bit for bit
# (benchmarks/README.md, "Supply shells").
SHELL_WIDTH = 0.3  # the widest shell, voxels: ~120 voxels at the default supply radius of 4 voxels
SHELL_BANDS = 8
_SHELL_STEPS = 4.0  # a new shell's width, in the longest adapted terminal step (sqrt(3) half-widths)
_SHELL_MARGIN = 1e-6  # voxels


def shell_capacity(rho, width):
    """Voxels a terminal's shell array holds: 1.5 times a shell's volume (8 pi rho^2 width), plus 32.
    Lattice points in such shells stay within 1.2 times it (rho 2 to 6, width 0.3); a shell
    that does not fit is not used (its supply changes are computed row by row)."""
    return int(math.ceil(1.5 * 8.0 * math.pi * rho * rho * width)) + 32


@jit_norc
def _shell_voxels(supply, rho, cx, cy, cz, width, voxels, bands, place):
    """Visit every tissue voxel whose centre lies within ``width`` of the sphere's surface (and
    perhaps a few more), in row order, each in band min(B |distance - rho| / width, B - 1) of
    the B = ``bands.size``. Counting (``place`` False): adds each to its band's count in ``bands``.
    Placing: writes [x, y, z] to ``voxels`` at its band's entry of ``bands`` and advances it.
    Returns the number visited."""
    nz, ny, nx = supply.shape
    n_bands = bands.size
    inner2 = max(rho - width, 0.0) ** 2
    outer = rho + width
    outer2 = outer * outer
    n = 0
    for k in range(max(math.floor(cz - outer), 0), min(math.ceil(cz + outer), nz - 1) + 1):
        e2 = (k - cz) * (k - cz)
        for j in range(max(math.floor(cy - outer), 0), min(math.ceil(cy + outer), ny - 1) + 1):
            q = (j - cy) * (j - cy) + e2
            if q > outer2:
                continue
            # |i - cx| in [a, b]: a run on either side of the centre (one run where a <= 0)
            a = math.sqrt(max(inner2 - q, 0.0)) - _SHELL_MARGIN
            b = math.sqrt(outer2 - q) + _SHELL_MARGIN
            left_hi = min(math.floor(cx - a), nx - 1)
            for lo, hi in (
                (max(math.ceil(cx - b), 0), left_hi),
                (max(math.ceil(cx + a), left_hi + 1, 0), min(math.floor(cx + b), nx - 1)),
            ):
                for i in range(lo, hi + 1):
                    if supply[k, j, i] < 0:
                        continue
                    dx = i - cx
                    band = min(int(abs(math.sqrt(dx * dx + q) - rho) * n_bands / width), n_bands - 1)
                    if place:
                        slot = bands[band]
                        voxels[slot, 0] = i
                        voxels[slot, 1] = j
                        voxels[slot, 2] = k
                        bands[band] = slot + 1
                    else:
                        bands[band] += 1
                    n += 1
    return n


@jit_norc
def _shell_build(supply, rho, cx, cy, cz, width, voxels, bands):
    """List into ``voxels`` (int16 (capacity, 3), [x, y, z]) every tissue voxel of ``supply``
    whose centre lies within ``width`` of the surface of the sphere of radius ``rho`` centred
    at (cx, cy, cz) (all in voxel units), and perhaps a few more, band by band: band b (of
    B = ``bands.size``, distances to the surface from b width / B) ends before ``bands[b]``.
    Returns their number, or -1 when they do not fit (or the grid is too large for int16)."""
    if max(supply.shape) > 32767:
        return -1
    bands[:] = 0
    if _shell_voxels(supply, rho, cx, cy, cz, width, voxels, bands, False) > voxels.shape[0]:
        return -1
    total = 0
    for b in range(bands.size):  # counts to each band's first entry
        count = bands[b]
        bands[b] = total
        total += count
    _shell_voxels(supply, rho, cx, cy, cz, width, voxels, bands, True)  # each band's entry to its end
    return total


@jit_norc
def _shell_change(supply, rho, voxels, bands, width, reach, ox, oy, oz, px, py, pz, write):
    """:func:`_sphere_rows` for a sphere moving from o to p (voxel coordinates) when no voxel
    can change coverage but those of the shell (``voxels``, ``bands``, ``width``) within
    ``reach`` of the surface: each voxel of the bands that reach is tested as the row code
    tests a voxel (:func:`_inside`), and its count change is the rows' (:func:`_gain_change`, :func:`_loss_change`)."""
    rho2 = rho * rho
    n_bands = bands.size
    delta = 0
    first = 0
    for band in range(n_bands):
        if band * width / n_bands > reach:  # this band's voxels and the later ones lie farther
            break
        for t in range(first, bands[band]):
            i = np.int64(voxels[t, 0])
            j = np.int64(voxels[t, 1])
            k = np.int64(voxels[t, 2])
            was = _inside(i, ox, (j - oy) * (j - oy), (k - oz) * (k - oz), rho2)
            now = _inside(i, px, (j - py) * (j - py), (k - pz) * (k - pz), rho2)
            if was == now:
                continue
            b = np.int64(supply[k, j, i])
            delta += _gain_change(b) if now else _loss_change(b)
            if write:
                supply[k, j, i] += 1 if now else -1
        first = bands[band]
    return float(delta)


@jit_norc_inline
def _shell_reach(model, state, t, ox, oy, oz, px, py, pz):
    """How far from its sphere's surface a voxel may lie and still change coverage when terminal
    t moves from o to p (voxel coordinates), if its shell can evaluate the move; else -1.

    A shell around centre c of width w lists every voxel whose centre's distance to the sphere's
    surface is at most w; with the sphere at o or p that distance changes by at most |o - c| +
    |p - o|, the reach, and a voxel farther than that from the surface keeps its coverage. A
    new shell, around o, is listed when the adapted terminal steps allow one no wider than
    ``supply_shell_width`` (or the present one is twice as wide as they need).
    """
    if model.supply_shell_width <= 0.0:
        return -1.0
    step = math.sqrt((px - ox) ** 2 + (py - oy) ** 2 + (pz - oz) ** 2)
    width = _SHELL_STEPS * math.sqrt(3.0) * state.step_size[0] / model.voxel_size
    frame = state.scratch_shell_frame[t]  # centre, width (0: no shell)
    if frame[3] <= 2.0 * width:
        reach = math.sqrt((ox - frame[0]) ** 2 + (oy - frame[1]) ** 2 + (oz - frame[2]) ** 2) + step
        if reach < frame[3] - _SHELL_MARGIN:
            return reach + _SHELL_MARGIN
    if width > model.supply_shell_width or step >= width - _SHELL_MARGIN:
        return -1.0
    n = _shell_build(
        state.supply, model.supply_rho, ox, oy, oz, width, state.scratch_shell_voxels[t], state.scratch_shell_bands[t]
    )
    frame[0] = ox
    frame[1] = oy
    frame[2] = oz
    frame[3] = width if n >= 0 else 0.0
    return step + _SHELL_MARGIN if n >= 0 else -1.0


@jit_norc_inline
def _terminal_supply_change(model, state, t, ox, oy, oz, px, py, pz, reach, write):
    """C_s change of terminal t's sphere moving from o to p (voxel coordinates): on its shell
    when :func:`_shell_reach` gave a reach (>= 0), else row by row; with ``write`` the counts
    are updated."""
    if reach >= 0.0:
        voxels, bands, width = (
            state.scratch_shell_voxels[t],
            state.scratch_shell_bands[t],
            state.scratch_shell_frame[t, 3],
        )
        return _shell_change(state.supply, model.supply_rho, voxels, bands, width, reach, ox, oy, oz, px, py, pz, write)
    if model.prefetch_supply and not write:  # the rows' cache misses in flight together, not one by one
        _prefetch_sphere(state.supply, model.supply_rho, ox, oy, oz)
        _prefetch_sphere(state.supply, model.supply_rho, px, py, pz)
    return _sphere_rows(state.supply, model.supply_rho, ox, oy, oz, px, py, pz, write)


@jit_norc
def _prefetch_sphere(supply, rho, cx, cy, cz):
    """Prefetch the count map's rows under the sphere of radius ``rho`` at (cx, cy, cz) (voxel
    coordinates): both ends of each row, so all of it while a row's counts fit in 64 bytes."""
    nz, ny, nx = supply.shape
    flat = supply.reshape(-1)
    x_lo = max(math.floor(cx - rho), 0)
    x_hi = min(math.ceil(cx + rho), nx - 1)
    if x_lo > x_hi:
        return
    rho2 = rho * rho
    for k in range(max(math.floor(cz - rho), 0), min(math.ceil(cz + rho), nz - 1) + 1):
        e2 = (k - cz) * (k - cz)
        if e2 > rho2:
            continue
        ry = math.sqrt(rho2 - e2)
        for j in range(max(math.floor(cy - ry), 0), min(math.ceil(cy + ry), ny - 1) + 1):
            row = (k * ny + j) * nx
            prefetch(flat, row + x_lo)
            prefetch(flat, row + x_hi)


@jit_norc
def pressure_cost(model, state):
    """C_p from scratch: Poiseuille drops down every inlet's tree (O(N), depth-first)."""
    tables = model.tables
    parent = state.parent
    children = state.children
    n_down = state.n_downstream
    pressure = state.scratch_pressure
    stack = state.scratch_stack
    top = 0
    for k in range(model.n_inlets):
        pressure[k] = model.pressure_inlet
        stack[top] = children[k, 0]
        top += 1
    total = 0.0
    first_bif = model.n_inlets + model.n_terminals
    while top > 0:
        top -= 1
        x = stack[top]
        n = n_down[x]
        pressure[x] = pressure[parent[x]] - tables[TABLE_FLOW, n] * tables[TABLE_RESISTANCE, n] * state.seg_length[x]
        if x >= first_bif:
            stack[top] = children[x, 0]
            stack[top + 1] = children[x, 1]
            top += 2
        elif x >= model.n_inlets:
            d = pressure[x] - model.pressure_terminal
            total += d * d
    return total


# --- Neighbour cells (swap partners biased towards spatial neighbours) -------------------
# Linked lists of non-inlet nodes per cell of a grid over the box. They live in State (the
# list order decides which partner a draw picks, so it is checkpointed, not rebuilt).


@jit_norc_inline
def _cell_coords(model, p):
    """Cell (cx, cy, cz) of a point, clipped to the cell grid."""
    h = model.cell_size
    cx = min(max(math.floor((p[0] - model.cell_lo[0]) / h), 0), model.cell_shape[0] - 1)
    cy = min(max(math.floor((p[1] - model.cell_lo[1]) / h), 0), model.cell_shape[1] - 1)
    cz = min(max(math.floor((p[2] - model.cell_lo[2]) / h), 0), model.cell_shape[2] - 1)
    return cx, cy, cz


@jit_norc_inline
def _cell_of_point(model, p):
    cx, cy, cz = _cell_coords(model, p)
    return (cz * model.cell_shape[1] + cy) * model.cell_shape[0] + cx


@jit_norc_inline
def _cell_insert(state, i, c):
    state.scratch_cell_count[c] += 1
    head = state.cell_head[c]
    state.cell_next[i] = head
    state.cell_prev[i] = -1
    if head >= 0:
        state.cell_prev[head] = i
    state.cell_head[c] = i
    state.cell_of[i] = c


@jit_norc_inline
def _cell_remove(state, i):
    c = state.cell_of[i]
    state.scratch_cell_count[c] -= 1
    nxt = state.cell_next[i]
    prv = state.cell_prev[i]
    if prv >= 0:
        state.cell_next[prv] = nxt
    else:
        state.cell_head[c] = nxt
    if nxt >= 0:
        state.cell_prev[nxt] = prv


@jit_norc_inline
def _cell_update(model, state, i, p):
    """Move node i's entry to the cell of its new position p."""
    c = _cell_of_point(model, p)
    if c != state.cell_of[i]:
        _cell_remove(state, i)
        _cell_insert(state, i, c)


@jit_norc
def build_cells(model, state):
    """Fill the cell lists from the node positions (inlets are never swap partners)."""
    state.cell_head[:] = -1
    state.scratch_cell_count[:] = 0
    state.cell_of[:] = -1
    state.cell_next[:] = -1
    state.cell_prev[:] = -1
    for i in range(model.n_inlets, state.parent.size):
        _cell_insert(state, i, _cell_of_point(model, state.position[i]))


@jit_norc
def neighbour_partner(model, state, a, rng):
    """A node drawn uniformly from those in a's cell and the cells around it (a excluded); -1 if none.

    The relation "in adjacent cells" is symmetric and a swap moves no node, so the forward
    and reverse proposals of a swap have the same probability: detailed balance holds.
    The draw counts the candidates from the cells' node counts and walks only the list of
    the cell that holds the drawn one, in the order a walk of every list would meet them.
    """
    ax, ay, az = _cell_coords(model, state.position[a])
    nx_, ny_, nz_ = model.cell_shape[0], model.cell_shape[1], model.cell_shape[2]
    count = state.scratch_cell_count
    z0, z1 = max(az - 1, 0), min(az + 1, nz_ - 1)
    y0, y1 = max(ay - 1, 0), min(ay + 1, ny_ - 1)
    x0, x1 = max(ax - 1, 0), min(ax + 1, nx_ - 1)
    total = -1  # a itself, in its own cell
    for cz in range(z0, z1 + 1):
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                total += count[(cz * ny_ + cy) * nx_ + cx]
    if total <= 0:
        return -1
    pick = next_below(rng, total)
    own = state.cell_of[a]
    for cz in range(z0, z1 + 1):
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                c = (cz * ny_ + cy) * nx_ + cx
                here = count[c] - (1 if c == own else 0)
                if pick >= here:
                    pick -= here
                    continue
                x = state.cell_head[c]
                while x >= 0:
                    if x != a:
                        if pick == 0:
                            return x
                        pick -= 1
                    x = state.cell_next[x]
    return -1


@jit  # once per run; np.count_nonzero needs the reference-counted runtime
def initialise(model, state):
    """Fill the per-segment caches, the supply map and the running sums from the tree."""
    tables = model.tables
    pos = state.position
    state.costs[:] = 0.0
    state.compensation[:] = 0.0
    state.seg_length[:] = 0.0
    supply = state.supply
    state.scratch_shell_frame[:, 3] = 0.0  # no shell of a grid this model may not share
    nz, ny, nx = supply.shape
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                supply[k, j, i] = 0 if model.mask[k, j, i] != 0 else -1
    for i in range(model.n_inlets, state.parent.size):
        p = state.parent[i]
        n = state.n_downstream[i]
        length = _distance3(pos[i], pos[p])
        state.seg_length[i] = length
        _add(state.costs, state.compensation, VOLUME, tables[TABLE_VOLUME, n] * length)
        _add(state.costs, state.compensation, POWER, tables[TABLE_POWER, n] * length)
    recompute_exclusion(model, state)
    if model.supply_on:
        c_s = 10.0 * np.count_nonzero(model.mask)
        for t in range(model.n_inlets, model.n_inlets + model.n_terminals):
            c_s += supply_sphere(model, supply, pos[t], 1)
        state.costs[SUPPLY] = c_s
    if model.pressure_on:
        state.costs[PRESSURE] = pressure_cost(model, state)
    build_cells(model, state)


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


@jit_norc
def _accept(d_cost, temp, rng):
    if d_cost <= 0.0:
        return True
    return next_double(rng) < math.exp(-d_cost / temp)


@jit_norc_inline
def _early_reject(lower_bound, temp, rng, u):
    """Metropolis on a lower bound of ΔC, before (all of) the costly terms are evaluated.

    ``u``: the uniform an earlier check of the same move drew, or -1 (none yet). Returns
    (rejected, u): if the bound is uphill and no uniform was drawn, u is drawn now (the
    full test would draw it too, since ΔC >= bound > 0), and the move is rejected when
    even the bound fails; otherwise u is returned as given. The decision then equals the
    full test's with the same u, so the random stream is unchanged by the shortcut; a move
    may be checked again as its bound tightens.
    """
    if lower_bound <= 0.0:
        return False, u
    if u < 0.0:
        u = next_double(rng)
    return u >= math.exp(-lower_bound / temp), u


@jit_norc_inline
def _bounds_apply(model):
    """Whether a move is checked on lower bounds of ΔC before its dear terms (the pressure term,
    recomputed in full, has no cheap bound; ``Model.early_reject`` False turns them off to test)."""
    return model.early_reject and not model.pressure_on


# A traversal is stopped where ΔC reaches this many temperatures when the move has drawn no
# uniform yet: the uniform it then draws rejects it unless below e^-20.
_REJECT_HORIZON = 20.0


@jit_norc_inline
def _exclusion_cap(model, temp, u, bound, n):
    """The traversal sum of a new segment (n terminals downstream) past which its move is
    rejected. ``bound``: the move's ΔC with this and the later new segments' exclusion taken
    as 0; ``u``: its uniform, or -1 when none is drawn yet (then the sum at which ΔC reaches
    _REJECT_HORIZON temperatures). Infinite when the early rejection is off."""
    slope = model.w_exclusion * model.tables[TABLE_EXCLUSION, n]
    if not (_bounds_apply(model) and slope > 0.0):
        return np.inf
    limit = -temp * math.log(u) if u >= 0.0 else temp * _REJECT_HORIZON
    return (limit - bound) / slope


@jit_norc_inline
def _new_exclusion(model, p0, p1, n, temp, rng, u, bound, vascular, pre, mid, old_exc, w_sup, d_sup, swap):
    """Traversal sum of a move's new segment p0 -> p1 (n terminals downstream), or a rejection.

    The traversal stops once its sum passes :func:`_exclusion_cap`; the move is then checked
    on a lower bound of ΔC with that partial sum, written as the move's final ΔC writes it
    (so no larger than it in floating point): exclusion change (pre + (mid + x)) - old_exc
    for a translation, pre + ((mid + x) - old_exc) for a swap (``swap``), x this segment's
    cost, ``mid`` the new segments' costs before it that the final sum groups with it,
    ``pre`` the others, later new segments at 0. If the bound does not reject, the full sum
    is traversed. ``bound``: ΔC with this and later new segments at 0. Returns
    (sum, rejected, u), ``u`` as in :func:`_early_reject`.
    """
    cap = _exclusion_cap(model, temp, u, bound, n)
    s = segment_exclusion_capped(model, p0, p1, cap)
    if s > cap:
        x = _exclusion_cost(model, n, s)
        d_exc = pre + ((mid + x) - old_exc) if swap else (pre + (mid + x)) - old_exc
        rejected, u = _early_reject(weighted_total(model, vascular, d_exc, 0.0, w_sup, d_sup), temp, rng, u)
        if rejected:
            return s, True, u
        s = segment_exclusion(model, p0, p1)
    return s, False, u


@jit_norc_inline
def _accept_with(d_cost, temp, rng, u):
    """:func:`_accept`, reusing the uniform ``u`` when :func:`_early_reject` drew one."""
    if d_cost <= 0.0:
        return True
    if u < 0.0:
        u = next_double(rng)
    return u < math.exp(-d_cost / temp)


@jit_norc_inline
def _translate(model, state, temp, new):
    """Propose moving a random non-inlet node by a uniform random displacement (``new``: scratch (3,))."""
    rng = state.rng
    pos = state.position
    k_in = model.n_inlets
    first_bif = k_in + model.n_terminals
    n_nodes = state.parent.size
    if model.move_terminals:
        i = k_in + next_below(rng, n_nodes - k_in)
    else:
        if n_nodes == first_bif:
            return ILLEGAL
        i = first_bif + next_below(rng, n_nodes - first_bif)
    cls = 0 if i < first_bif else 1
    half = state.step_size[cls]
    # With adapted steps, half of the terminal moves keep the full width: the supply term
    # is optimised by downhill search over moves of voxel scale, which narrowed steps
    # (sub-voxel, accepted for their vascular gain) would stop. Once the packing has jammed
    # such moves are never accepted (from a quarter of a `fast` run on) and cost more than
    # adapted ones, so they stop after full_width_steps; the uniform is drawn either way.
    full_width = model.adapt_steps and cls == 0 and next_double(rng) < 0.5 and _full_width_on(model, state)
    if full_width:
        half = model.step_max[0]
    for a in range(3):
        new[a] = pos[i, a] + (2.0 * next_double(rng) - 1.0) * half
    if model.planar:
        new[2] = pos[i, 2]
    outcome = _translate_node(model, state, i, new, temp)
    if model.adapt_steps and not full_width:
        _adapt_step(model, state, cls, outcome == ACCEPTED)
    return outcome


@jit_norc_inline
def _full_width_on(model, state):
    """Whether terminal moves may still take the full width (the tree anneal's first
    ``full_width_steps`` steps)."""
    return _tree_step(model, state) < model.full_width_steps


@jit_norc_inline
def _adapt_step(model, state, cls, accepted):
    """Scale a class's translation half-width after every window of its proposals.

    Acceptance above the target widens the step, below narrows it (factor exp(2 (rate -
    target))), so steps shrink as the temperature falls; capped at the configured width.
    Counts live in the state's counters: block splits and resumes do not change it.
    """
    c = state.counters
    i_proposed = WINDOW_COUNTERS[cls, N_PROPOSED]
    i_accepted = WINDOW_COUNTERS[cls, N_ACCEPTED]
    c[i_proposed] += 1
    if accepted:
        c[i_accepted] += 1
    n = c[i_proposed]
    if n >= model.adapt_window:
        rate = c[i_accepted] / n
        width = state.step_size[cls] * math.exp(2.0 * (rate - model.acceptance_target))
        state.step_size[cls] = min(max(width, 1e-9 * model.step_max[cls]), model.step_max[cls])
        c[i_proposed] = 0
        c[i_accepted] = 0


@jit_norc
def translate_node(model, state, i, new, temp):
    """Propose moving node i to ``new``; Metropolis at ``temp``. Returns ILLEGAL, REJECTED or ACCEPTED.

    A terminal must land in tissue, a bifurcation inside the grid's box and its region.
    """
    return _translate_node(model, state, i, new, temp)


@jit_norc_inline
def _segment_change(model, state, x, length):
    """(ΔC_v, ΔC_w) when segment x gets ``length`` [m] at its current n (costs.full_costs:
    volume[n] * L, power[n] * L)."""
    n = state.n_downstream[x]
    d_len = length - state.seg_length[x]
    return model.tables[TABLE_VOLUME, n] * d_len, model.tables[TABLE_POWER, n] * d_len


@jit_norc_inline
def _exclusion_cost(model, n, traversal):
    """C_o of one segment with n terminals downstream and traversal sum ``traversal``
    (costs.full_costs: exclusion[n] * exclusion_sum)."""
    return model.tables[TABLE_EXCLUSION, n] * traversal


@jit_norc_inline
def _segment_exclusion_cost(model, state, x):
    """The current C_o of segment x (from its cached traversal sum)."""
    return _exclusion_cost(model, state.n_downstream[x], state.seg_exclusion[x])


@jit_norc_inline
def _set_segment(state, x, length, exclusion):
    state.seg_length[x] = length
    state.seg_exclusion[x] = exclusion


@jit_norc_inline
def legal_position(model, is_terminal, p):
    """A terminal must lie in tissue, a bifurcation inside the grid's box (and its
    ``bifurcation_region`` when one is set)."""
    if is_terminal:
        return in_tissue(model, p)
    for a in range(3):
        if p[a] < model.box_lo[a] or p[a] > model.box_hi[a]:
            return False
    return model.bifurcation_region.shape[0] == 0 or _in_voxels(model, model.bifurcation_region, p)


@jit_norc_inline
def _pressure_with_lengths(model, state, a, len_a, b, len_b, c, len_c):
    """C_p (costs.node_pressures) with segments a, b, c (-1: none) tentatively at the given
    lengths; the lengths are restored. C_p reads no position, so none is moved."""
    old_a = state.seg_length[a]
    state.seg_length[a] = len_a
    old_b = 0.0
    if b >= 0:
        old_b = state.seg_length[b]
        state.seg_length[b] = len_b
    old_c = 0.0
    if c >= 0:
        old_c = state.seg_length[c]
        state.seg_length[c] = len_c
    pressure = pressure_cost(model, state)
    state.seg_length[a] = old_a
    if b >= 0:
        state.seg_length[b] = old_b
    if c >= 0:
        state.seg_length[c] = old_c
    return pressure


@jit_norc_inline
def _translate_node(model, state, i, new, temp):
    """:func:`translate_node`, inlined into the move loop (:func:`_anneal_steps`).

    The moved node's own segment (to its parent p) and, for a bifurcation, its children's
    segments (c0, c1) change length; n does not change. Cheap terms first: unless
    ``model.early_reject`` is off, the exclusion traversals are skipped when a lower bound
    of ΔC (new segments' exclusion taken as 0) already fails Metropolis, and the children's
    when the bound with the moved node's own segment fails.
    """
    rng = state.rng
    pos = state.position
    is_terminal = i < model.n_inlets + model.n_terminals
    cls = 0 if is_terminal else 1
    state.counters[MOVE_COUNTERS[cls, N_PROPOSED]] += 1
    if not legal_position(model, is_terminal, new):
        return ILLEGAL
    p = state.parent[i]
    c0 = state.children[i, 0]  # -1, -1 for a terminal
    c1 = state.children[i, 1]
    # volume and power
    len_i = _distance3(new, pos[p])
    d_vol, d_pow = _segment_change(model, state, i, len_i)
    old_exc = _segment_exclusion_cost(model, state, i)
    len_c0 = 0.0
    len_c1 = 0.0
    if not is_terminal:
        len_c0 = _distance3(pos[c0], new)
        len_c1 = _distance3(pos[c1], new)
        v0, w0 = _segment_change(model, state, c0, len_c0)
        v1, w1 = _segment_change(model, state, c1, len_c1)
        d_vol += v0 + v1
        d_pow += w0 + w1
        old_exc += _segment_exclusion_cost(model, state, c0) + _segment_exclusion_cost(model, state, c1)
    # supply (terminals only)
    d_sup = 0.0
    supply_moves = is_terminal and model.supply_on
    if supply_moves:
        t = i - model.n_inlets
        ox, oy, oz = _voxel_coords(model, pos[i, 0], pos[i, 1], pos[i, 2])
        px, py, pz = _voxel_coords(model, new[0], new[1], new[2])
        reach = _shell_reach(model, state, t, ox, oy, oz, px, py, pz)
        d_sup = _terminal_supply_change(model, state, t, ox, oy, oz, px, py, pz, reach, False)
    w_sup = supply_weight(model, state, temp) if d_sup != 0.0 else model.w_supply
    # early rejection on a lower bound
    u = -1.0
    check = _bounds_apply(model)
    vascular = d_vol + d_pow
    bound = 0.0
    if check:
        bound = weighted_total(model, vascular, -old_exc, 0.0, w_sup, d_sup)  # new exclusion taken as 0
        rejected, u = _early_reject(bound, temp, rng, -1.0)
        if rejected:
            return REJECTED
    # exclusion: each new segment's traversal stops once its sum rejects the move; the bounds
    # on a partial sum are the final ΔC's expression with the missing terms at 0
    d_exc = 0.0
    exc_i = 0.0
    exc_c0 = 0.0
    exc_c1 = 0.0
    if model.exclusion_on:
        n_i = state.n_downstream[i]
        exc_i, rejected, u = _new_exclusion(
            model, new, pos[p], n_i, temp, rng, u, bound, vascular, 0.0, 0.0, old_exc, w_sup, d_sup, False
        )
        if rejected:
            return REJECTED
        d_exc = _exclusion_cost(model, n_i, exc_i)
        if not is_terminal:
            n_c0 = state.n_downstream[c0]
            n_c1 = state.n_downstream[c1]
            if check:  # the children's exclusion still taken as 0
                bound = weighted_total(model, vascular, d_exc - old_exc, 0.0, w_sup, d_sup)
                rejected, u = _early_reject(bound, temp, rng, u)
                if rejected:
                    return REJECTED
            exc_c0, rejected, u = _new_exclusion(
                model, pos[c0], new, n_c0, temp, rng, u, bound, vascular, d_exc, 0.0, old_exc, w_sup, d_sup, False
            )
            if rejected:
                return REJECTED
            cost_c0 = _exclusion_cost(model, n_c0, exc_c0)
            if check:  # c1's exclusion still taken as 0
                bound = weighted_total(model, vascular, (d_exc + (cost_c0 + 0.0)) - old_exc, 0.0, w_sup, d_sup)
                rejected, u = _early_reject(bound, temp, rng, u)
                if rejected:
                    return REJECTED
            exc_c1, rejected, u = _new_exclusion(
                model, pos[c1], new, n_c1, temp, rng, u, bound, vascular, d_exc, cost_c0, old_exc, w_sup, d_sup, False
            )
            if rejected:
                return REJECTED
            d_exc += cost_c0 + _exclusion_cost(model, n_c1, exc_c1)
        d_exc -= old_exc
    # pressure (recomputed in full on the tentative lengths)
    new_pressure = 0.0
    d_pre = 0.0
    if model.pressure_on:
        new_pressure = _pressure_with_lengths(model, state, i, len_i, c0, len_c0, c1, len_c1)
        d_pre = new_pressure - state.costs[PRESSURE]
    # Metropolis, then commit
    d_cost = weighted_total(model, vascular, d_exc, d_pre, w_sup, d_sup)
    if not _accept_with(d_cost, temp, rng, u):
        return REJECTED
    state.counters[MOVE_COUNTERS[cls, N_ACCEPTED]] += 1
    if supply_moves:
        _terminal_supply_change(model, state, t, ox, oy, oz, px, py, pz, reach, True)
    if model.p_local > 0.0:
        _cell_update(model, state, i, new)
    pos[i, 0] = new[0]
    pos[i, 1] = new[1]
    pos[i, 2] = new[2]
    _set_segment(state, i, len_i, exc_i)
    if not is_terminal:
        _set_segment(state, c0, len_c0, exc_c0)
        _set_segment(state, c1, len_c1, exc_c1)
    _commit(model, state, d_vol, d_pow, d_exc, d_sup, new_pressure)
    return ACCEPTED


@jit_norc
def _commit(model, state, d_vol, d_pow, d_exc, d_sup, new_pressure):
    """Add an accepted move's deltas to the running sums."""
    costs = state.costs
    comp = state.compensation
    _add(costs, comp, VOLUME, d_vol)
    _add(costs, comp, POWER, d_pow)
    if model.exclusion_on:
        _add(costs, comp, EXCLUSION, d_exc)
    costs[SUPPLY] += d_sup  # integer-valued: exact in float64
    if model.pressure_on:  # recomputed in full for the move: take it as is, no drift
        costs[PRESSURE] = new_pressure
        comp[PRESSURE] = 0.0


@jit_norc
def _path_delta(model, state, start, stop, dn):
    """Volume, power and exclusion change when n changes by dn on the path start .. stop (exclusive)."""
    tables = model.tables
    d_vol = 0.0
    d_pow = 0.0
    d_exc = 0.0
    x = start
    while x != stop:
        if state.parent[x] >= 0:  # inlets have no segment
            n0 = state.n_downstream[x]
            n1 = n0 + dn
            length = state.seg_length[x]
            d_vol += (tables[TABLE_VOLUME, n1] - tables[TABLE_VOLUME, n0]) * length
            d_pow += (tables[TABLE_POWER, n1] - tables[TABLE_POWER, n0]) * length
            if model.exclusion_on:
                d_exc += (tables[TABLE_EXCLUSION, n1] - tables[TABLE_EXCLUSION, n0]) * state.seg_exclusion[x]
        x = state.parent[x]
    return d_vol, d_pow, d_exc


@jit_norc
def _exchange_parents(state, a, b, lca):
    """Hang a where b hung and b where a hung; fix the downstream counts up to the LCA.

    Applying it twice restores the tree, which is how a tentative swap is undone.
    """
    pa = state.parent[a]
    pb = state.parent[b]
    dn = state.n_downstream[b] - state.n_downstream[a]
    for s in range(2):
        if state.children[pa, s] == a:
            state.children[pa, s] = b
        if state.children[pb, s] == b:
            state.children[pb, s] = a
    state.parent[a] = pb
    state.parent[b] = pa
    x = pa
    while x != lca:
        state.n_downstream[x] += dn
        x = state.parent[x]
    x = pb
    while x != lca:
        state.n_downstream[x] -= dn
        x = state.parent[x]


@jit_norc_inline
def _swap(model, state, temp):
    """Propose exchanging the parents of two distinct random non-inlet nodes."""
    rng = state.rng
    k_in = model.n_inlets
    n_movable = state.parent.size - k_in
    a = k_in + next_below(rng, n_movable)
    # The paper's uniform partner draws no extra number, so its random stream is unchanged.
    if model.p_local > 0.0 and next_double(rng) < model.p_local:
        state.counters[COUNTER_LOCAL_SWAP_PROPOSED] += 1
        b = neighbour_partner(model, state, a, rng)
        if b < 0:
            state.counters[COUNTER_SWAP_PROPOSED] += 1
            return ILLEGAL
    else:
        b = k_in + next_below(rng, n_movable - 1)
        if b >= a:
            b += 1
    return _swap_nodes(model, state, a, b, temp)


@jit_norc
def swap_random(model, state, temp):
    """Propose a swap of a random pair (:func:`_swap`), for callers outside the move loop."""
    return _swap(model, state, temp)


@jit_norc
def swap_nodes(model, state, a, b, temp):
    """Propose hanging a where b hangs and b where a hangs (SPEC section 2).

    Siblings, and pairs where one is an ancestor of the other, are ILLEGAL. Returns
    ILLEGAL, REJECTED or ACCEPTED.
    """
    return _swap_nodes(model, state, a, b, temp)


@jit_norc_inline
def _swap_nodes(model, state, a, b, temp):
    """:func:`swap_nodes`, inlined into the move loop (:func:`_anneal_steps`)."""
    rng = state.rng
    pos = state.position
    parent = state.parent
    state.counters[COUNTER_SWAP_PROPOSED] += 1
    pa = parent[a]
    pb = parent[b]
    if pa == pb:  # siblings: the swap changes nothing
        return ILLEGAL
    # Mark a's ancestors; b among them, or a among b's, would close a loop. The stamp is
    # unique per proposal (also for direct calls within one step), so stale marks never match.
    stamp = state.counters[COUNTER_SWAP_PROPOSED]
    mark = state.scratch_mark
    x = pa
    while x >= 0:
        if x == b:
            return ILLEGAL
        mark[x] = stamp
        x = parent[x]
    lca = -1  # stays -1 when a and b hang from different inlets
    x = pb
    while x >= 0:
        if x == a:
            return ILLEGAL
        if mark[x] == stamp:
            lca = x
            break
        x = parent[x]
    if lca == -1 and model.fixed_inlet_counts and state.n_downstream[a] != state.n_downstream[b]:
        return ILLEGAL
    # volume and power: n changes on the paths from the old parents up to the LCA, and the
    # two moved segments change length (their own n does not change)
    na = state.n_downstream[a]
    nb = state.n_downstream[b]
    d_vol = 0.0
    d_pow = 0.0
    d_exc = 0.0
    if na != nb:
        v, w, e = _path_delta(model, state, pa, lca, nb - na)
        d_vol += v
        d_pow += w
        d_exc += e
        v, w, e = _path_delta(model, state, pb, lca, na - nb)
        d_vol += v
        d_pow += w
        d_exc += e
    new_len_a = _distance3(pos[a], pos[pb])
    new_len_b = _distance3(pos[b], pos[pa])
    va, wa = _segment_change(model, state, a, new_len_a)
    vb, wb = _segment_change(model, state, b, new_len_b)
    d_vol += va + vb
    d_pow += wa + wb
    old_exc = _segment_exclusion_cost(model, state, a) + _segment_exclusion_cost(model, state, b)
    # early rejection on a lower bound (new segments' exclusion taken as 0)
    u = -1.0
    check = _bounds_apply(model)
    vascular = d_vol + d_pow
    bound = 0.0
    if check:
        bound = weighted_total(model, vascular, d_exc - old_exc, 0.0, 0.0, 0.0)
        rejected, u = _early_reject(bound, temp, rng, -1.0)
        if rejected:
            return REJECTED
    # exclusion, each traversal stopped once its sum rejects the move (as in _translate_node)
    new_exc_a = 0.0
    new_exc_b = 0.0
    if model.exclusion_on:
        new_exc_a, rejected, u = _new_exclusion(
            model, pos[a], pos[pb], na, temp, rng, u, bound, vascular, d_exc, 0.0, old_exc, 0.0, 0.0, True
        )
        if rejected:
            return REJECTED
        cost_a = _exclusion_cost(model, na, new_exc_a)
        if check:  # b's new exclusion still taken as 0
            bound = weighted_total(model, vascular, d_exc + (cost_a - old_exc), 0.0, 0.0, 0.0)
            rejected, u = _early_reject(bound, temp, rng, u)
            if rejected:
                return REJECTED
        new_exc_b, rejected, u = _new_exclusion(
            model, pos[b], pos[pa], nb, temp, rng, u, bound, vascular, d_exc, cost_a, old_exc, 0.0, 0.0, True
        )
        if rejected:
            return REJECTED
        d_exc += (cost_a + _exclusion_cost(model, nb, new_exc_b)) - old_exc
    # pressure (recomputed in full on the tentatively swapped tree)
    d_pre = 0.0
    new_pressure = 0.0
    if model.pressure_on:
        _exchange_parents(state, a, b, lca)
        new_pressure = _pressure_with_lengths(model, state, a, new_len_a, b, new_len_b, -1, 0.0)
        _exchange_parents(state, a, b, lca)
        d_pre = new_pressure - state.costs[PRESSURE]
    # Metropolis, then commit
    d_cost = weighted_total(model, vascular, d_exc, d_pre, 0.0, 0.0)  # a swap leaves C_s alone
    if not _accept_with(d_cost, temp, rng, u):
        return REJECTED
    state.counters[COUNTER_SWAP_ACCEPTED] += 1
    _exchange_parents(state, a, b, lca)
    _set_segment(state, a, new_len_a, new_exc_a)
    _set_segment(state, b, new_len_b, new_exc_b)
    _commit(model, state, d_vol, d_pow, d_exc, 0.0, new_pressure)
    return ACCEPTED


@jit
def anneal_block(model, state, n_steps):
    """Propose ``n_steps`` moves from ``state`` (in place), continuing its step count."""
    _anneal_steps(model, state, n_steps, np.empty(3))


@jit_norc
def _anneal_steps(model, state, n_steps, new):
    """The move loop of :func:`anneal_block` (``new``: scratch (3,)).

    Compiled without reference counting (see ``_jit.jit_norc``), as is every function
    it calls, and the moves are inlined here.
    """
    for _ in range(n_steps):
        step = state.counters[COUNTER_STEP]
        temp = temperature(model, state, step)
        if next_double(state.rng) < model.p_swap:
            _swap(model, state, temp)
        else:
            _translate(model, state, temp, new)
        state.counters[COUNTER_STEP] = step + 1


@jit_norc
def scaled_total_without_supply(model, state):
    """The annealed total C of the running sums less its supply term [W].

    The supply term (weight 1e26 by default) would swamp every other term's rounding in
    a difference of totals; moves that leave the supply alone are compared on this.
    """
    c = state.costs
    e = state.compensation
    return weighted_total(
        model,
        (c[VOLUME] + e[VOLUME]) + (c[POWER] + e[POWER]),
        c[EXCLUSION] + e[EXCLUSION],
        c[PRESSURE] + e[PRESSURE],
        0.0,
        0.0,
    )


@jit
def sample_uphill(model, state, n_samples, out):
    """Random walk at infinite temperature; store the uphill ΔC of its moves in ``out``.

    Swaps and bifurcation translations only: they leave the supply term alone, whose weight
    (A_s / A_wv = 1e26) makes it a constraint, not part of the temperature scale. Run it
    on a copy of a state: every legal proposal is accepted. Returns how many ΔC > 0
    were stored (at most ``out.size``).
    """
    return _sample_uphill(model, state, n_samples, out, np.empty(3))


@jit_norc
def _sample_uphill(model, state, n_samples, out, new):
    first_bif = model.n_inlets + model.n_terminals
    n_bif = state.parent.size - first_bif
    stored = 0
    for _ in range(n_samples):
        before = scaled_total_without_supply(model, state)
        if n_bif == 0 or next_double(state.rng) < 0.5:
            swap_random(model, state, np.inf)
        else:
            i = first_bif + next_below(state.rng, n_bif)
            half = state.step_size[1]
            for a in range(3):
                new[a] = state.position[i, a] + (2.0 * next_double(state.rng) - 1.0) * half
            if model.planar:
                new[2] = state.position[i, 2]
            translate_node(model, state, i, new, np.inf)
        d = scaled_total_without_supply(model, state) - before
        if d > 0.0 and stored < out.size:
            out[stored] = d
            stored += 1
    return stored
