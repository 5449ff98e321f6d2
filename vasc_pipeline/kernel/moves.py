"""The translate move and the per-segment helpers both moves share (the swap is :mod:`~vasc_pipeline.kernel.swaps`).

Each move computes its cost change from the per-segment caches, rejects early on lower
bounds of ΔC where it can (the same decisions and random stream as the full test) and
commits the accepted change to the running sums.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit_norc, jit_norc_inline
from ..model.physics import TABLE_EXCLUSION, TABLE_POWER, TABLE_VOLUME
from ..model.rng import next_below, next_double
from .cells import _cell_update
from .exclusion import _distance3, segment_exclusion, segment_exclusion_capped
from .pressure import _translation_pressure_change, _update_moments
from .schedule import _accept_with, _bounds_apply, _early_reject, _tree_step, supply_weight, weighted_total
from .state import (
    ACCEPTED,
    EXCLUSION,
    ILLEGAL,
    MOVE_COUNTERS,
    N_ACCEPTED,
    N_PROPOSED,
    POWER,
    PRESSURE,
    REJECTED,
    SUPPLY,
    VOLUME,
    WINDOW_COUNTERS,
    _add,
)
from .supply import _in_voxels, _shell_reach, _terminal_supply_change, _voxel_coords, in_tissue

__all__ = [
    "legal_position",
]

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
def _new_exclusion(model, p0, p1, n, temp, rng, u, bound, vascular, pre, mid, old_exc, d_pre, w_sup, d_sup, swap):
    """Traversal sum of a move's new segment p0 -> p1 (n terminals downstream), or a rejection.

    The traversal stops once its sum passes :func:`_exclusion_cap`; the move is then checked
    on a lower bound of ΔC with that partial sum, written as the move's final ΔC writes it
    (so no larger than it in floating point): exclusion change (pre + (mid + x)) - old_exc
    for a translation, pre + ((mid + x) - old_exc) for a swap (``swap``), x this segment's
    cost, ``mid`` the new segments' costs before it that the final sum groups with it,
    ``pre`` the others, later new segments at 0. If the bound does not reject, the full sum
    is traversed. ``bound``: ΔC with this and later new segments at 0; ``d_pre``: the move's
    ΔC_p. Returns (sum, rejected, u), ``u`` as in :func:`_early_reject`.
    """
    cap = _exclusion_cap(model, temp, u, bound, n)
    s = segment_exclusion_capped(model, p0, p1, cap)
    if s > cap:
        x = _exclusion_cost(model, n, s)
        d_exc = pre + ((mid + x) - old_exc) if swap else (pre + (mid + x)) - old_exc
        rejected, u = _early_reject(weighted_total(model, vascular, d_exc, d_pre, w_sup, d_sup), temp, rng, u)
        if rejected:
            return s, True, u
        s = segment_exclusion(model, p0, p1)
    return s, False, u


@jit_norc_inline
def _translation(model, state, new):
    """Draw the node and the position of a translation as the move loop proposes them: a random
    non-inlet node, displaced uniformly (into ``new``, scratch (3,)).

    Returns (node, class, adapt): node -1 when no node may move; class 0 for a terminal, 1 for
    a bifurcation; adapt, whether the proposal counts towards its class's step adaptation.
    """
    rng = state.rng
    pos = state.position
    k_in = model.n_inlets
    first_bif = k_in + model.n_terminals
    n_nodes = state.parent.size
    if model.move_terminals:
        i = k_in + next_below(rng, n_nodes - k_in)
    else:
        if n_nodes == first_bif:
            return -1, 1, False
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
    return i, cls, model.adapt_steps and not full_width


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
def _translate_node(model, state, i, new, temp):
    """:func:`translate_node`, inlined into the move loop (``kernel.loop._moves``).

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
    # pressure: exact, and cheap next to the exclusion, so it enters every bound
    d_pre = 0.0
    if model.pressure_on:
        d_pre = _translation_pressure_change(model, state, i, len_i, c0, len_c0, c1, len_c1)
    # early rejection on a lower bound
    u = -1.0
    check = _bounds_apply(model)
    vascular = d_vol + d_pow
    bound = 0.0
    if check:
        bound = weighted_total(model, vascular, -old_exc, d_pre, w_sup, d_sup)  # new exclusion taken as 0
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
            model, new, pos[p], n_i, temp, rng, u, bound, vascular, 0.0, 0.0, old_exc, d_pre, w_sup, d_sup, False
        )
        if rejected:
            return REJECTED
        d_exc = _exclusion_cost(model, n_i, exc_i)
        if not is_terminal:
            n_c0 = state.n_downstream[c0]
            n_c1 = state.n_downstream[c1]
            if check:  # the children's exclusion still taken as 0
                bound = weighted_total(model, vascular, d_exc - old_exc, d_pre, w_sup, d_sup)
                rejected, u = _early_reject(bound, temp, rng, u)
                if rejected:
                    return REJECTED
            exc_c0, rejected, u = _new_exclusion(
                model,
                pos[c0],
                new,
                n_c0,
                temp,
                rng,
                u,
                bound,
                vascular,
                d_exc,
                0.0,
                old_exc,
                d_pre,
                w_sup,
                d_sup,
                False,
            )
            if rejected:
                return REJECTED
            cost_c0 = _exclusion_cost(model, n_c0, exc_c0)
            if check:  # c1's exclusion still taken as 0
                bound = weighted_total(model, vascular, (d_exc + (cost_c0 + 0.0)) - old_exc, d_pre, w_sup, d_sup)
                rejected, u = _early_reject(bound, temp, rng, u)
                if rejected:
                    return REJECTED
            exc_c1, rejected, u = _new_exclusion(
                model,
                pos[c1],
                new,
                n_c1,
                temp,
                rng,
                u,
                bound,
                vascular,
                d_exc,
                cost_c0,
                old_exc,
                d_pre,
                w_sup,
                d_sup,
                False,
            )
            if rejected:
                return REJECTED
            d_exc += cost_c0 + _exclusion_cost(model, n_c1, exc_c1)
        d_exc -= old_exc
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
    if model.pressure_on:
        _update_moments(model, state, i)
    _commit(model, state, d_vol, d_pow, d_exc, d_sup, d_pre)
    return ACCEPTED


@jit_norc
def _commit(model, state, d_vol, d_pow, d_exc, d_sup, d_pre):
    """Add an accepted move's deltas to the running sums."""
    costs = state.costs
    comp = state.compensation
    _add(costs, comp, VOLUME, d_vol)
    _add(costs, comp, POWER, d_pow)
    if model.exclusion_on:
        _add(costs, comp, EXCLUSION, d_exc)
    costs[SUPPLY] += d_sup  # integer-valued: exact in float64
    if model.pressure_on:
        _add(costs, comp, PRESSURE, d_pre)
