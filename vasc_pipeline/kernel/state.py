"""The kernel's data: the ``Model`` and ``State`` named tuples, counters, cost indices, running sums.

``Model`` (read-only): the cost tables, the voxel grids, weights, switches and schedule.
``State`` (mutated in place): the tree arrays, per-segment caches (length, exclusion
traversal sum), the supply count map, running cost sums with their Neumaier compensation,
the generator state, counters and step sizes. Everything a resumed run needs is in
``State``; the ``scratch_*`` arrays are not.

Cost term order in ``costs``: :data:`vasc_pipeline.model.costs.COST_TERMS` (unscaled).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from .._jit import jit_norc_inline
from ..model.costs import COST_TERMS

__all__ = [
    "ACCEPTED",
    "COUNTER_BIFURCATION_ACCEPTED",
    "COUNTER_BIFURCATION_PROPOSED",
    "COUNTER_LOCAL_SWAP_PROPOSED",
    "COUNTER_STEP",
    "COUNTER_SWAP_ACCEPTED",
    "COUNTER_SWAP_PROPOSED",
    "COUNTER_TERMINAL_ACCEPTED",
    "COUNTER_TERMINAL_PROPOSED",
    "COUNTER_WINDOW_BIFURCATION_ACCEPTED",
    "COUNTER_WINDOW_BIFURCATION_PROPOSED",
    "COUNTER_WINDOW_TERMINAL_ACCEPTED",
    "COUNTER_WINDOW_TERMINAL_PROPOSED",
    "EXCLUSION",
    "ILLEGAL",
    "MOVE_COUNTERS",
    "Model",
    "N_ACCEPTED",
    "N_COUNTERS",
    "N_PROPOSED",
    "POWER",
    "PRESSURE",
    "REJECTED",
    "SUPPLY",
    "State",
    "VOLUME",
    "WINDOW_COUNTERS",
]

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
        "pressure_inlet",  # float64 (n_inlets,) Pa: each inlet's (a part's pseudo-inlets: their pressure in the tree)
        "pressure_terminal",  # Pa
        "total_steps",  # proposals of the run; the exponential schedule (ends in State.schedule) runs
        # from pack_steps to total_steps
        "cold_steps",  # tree anneal steps before the schedule's cold part ...
        "cold_path",  # ... and the share of log(T_end / T_start) covered by then: the schedule is
        # exponential on each side of that point (cold_steps = all tree steps, cold_path = 1: one
        # exponential)
        "pack_steps",  # proposals of the packing phase (vasc_pipeline.kernel.packing; 0: none)
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
        "inlet_count_bounds",  # int64 (K, 2): the fewest and most terminals each inlet's tree may feed
        # (tissue.inlet_share_tolerance); shape (0, 2): no bounds
        "bifurcation_region",  # uint8 (nz, ny, nx): where a bifurcation may lie (tissue.bifurcation_reach);
        # shape (0, 0, 0): anywhere in the grid's box
        "supply_shell_width",  # float, voxels: the widest supply shell a terminal keeps (SHELL_WIDTH;
        # 0: none, every supply change row by row; the same sums either way)
        "prefetch_lead",  # float, voxels: how far ahead of a traversal the depth map is prefetched
        # (PREFETCH_LEAD; 0: not at all; the same sums either way)
        "prefetch_supply",  # bool: prefetch the count map's rows under both spheres before a
        # terminal move's supply change is computed row by row (the same sums either way)
        "supply_target",  # uint8 (nz, ny, nx): each tissue voxel's coverage target t (tissue.demand_path;
        # s = 10 (t - b) below it, else (b - t)^2); shape (0, 0, 0): t = 1 everywhere, read by no loop
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
        "scratch_drop_moment",  # float64 (2N,): per node, Σ over its strict descendants u of n_u times
        # the pressure drop along u's segment [Pa] (kernel.pressure; derived from the tree, never
        # checkpointed; filled only with the pressure term on)
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
def _breadth_first(model, state):
    """Every node breadth-first from the inlets into scratch_stack (reversed, children come
    before their parents); returns how many."""
    order = state.scratch_stack
    n = 0
    for r in range(model.n_inlets):
        order[n] = r
        n += 1
    head = 0
    while head < n:
        node = order[head]
        head += 1
        for s in range(2):
            c = state.children[node, s]
            if c >= 0:
                order[n] = c
                n += 1
    return n
