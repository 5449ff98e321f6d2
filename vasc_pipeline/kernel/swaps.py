"""The swap move: two subtrees exchange their parents; its exact incremental ΔC and commit.

A swap changes n on the paths from the two old parents up to their lowest common ancestor
and the lengths of the two moved segments; it shares the translate move's per-segment
helpers (:mod:`~vasc_pipeline.kernel.moves`: segment change, capped exclusion, commit).
"""

from __future__ import annotations

from .._jit import jit_norc, jit_norc_inline
from ..model.physics import TABLE_EXCLUSION, TABLE_POWER, TABLE_VOLUME
from ..model.rng import next_below, next_double
from .cells import neighbour_partner
from .exclusion import _distance3
from .moves import _commit, _exclusion_cost, _new_exclusion, _segment_change, _segment_exclusion_cost, _set_segment
from .pressure import _swap_pressure_change, _update_moments
from .schedule import _accept_with, _bounds_apply, _early_reject, weighted_total
from .state import (
    ACCEPTED,
    COUNTER_LOCAL_SWAP_PROPOSED,
    COUNTER_SWAP_ACCEPTED,
    COUNTER_SWAP_PROPOSED,
    ILLEGAL,
    REJECTED,
)

__all__ = [
    "swap_nodes",
    "swap_random",
]


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

    Applying it twice restores the tree.
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
    """Propose a swap of a random pair (:func:`_swap`), for callers outside the move loop.

    Its own compiled copy of the swap: the calibration uses the move loop's
    (``kernel.loop._moves``)."""
    return _swap(model, state, temp)


@jit_norc
def swap_nodes(model, state, a, b, temp):
    """Propose hanging a where b hangs and b where a hangs (a swap of two subtrees).

    Siblings, and pairs where one is an ancestor of the other, are ILLEGAL. Returns
    ILLEGAL, REJECTED or ACCEPTED.
    """
    return _swap_nodes(model, state, a, b, temp)


@jit_norc_inline
def _swap_nodes(model, state, a, b, temp):
    """:func:`swap_nodes`, inlined into the move loop (``kernel.loop._moves``)."""
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
    top_a = pa  # a's inlet, once the walk ends
    while x >= 0:
        if x == b:
            return ILLEGAL
        mark[x] = stamp
        top_a = x
        x = parent[x]
    lca = -1  # stays -1 when a and b hang from different inlets
    x = pb
    top_b = pb
    while x >= 0:
        if x == a:
            return ILLEGAL
        if mark[x] == stamp:
            lca = x
            break
        top_b = x
        x = parent[x]
    # volume and power: n changes on the paths from the old parents up to the LCA, and the
    # two moved segments change length (their own n does not change)
    na = state.n_downstream[a]
    nb = state.n_downstream[b]
    if lca == -1 and na != nb:  # the swap moves na - nb terminals from a's inlet tree to b's
        if model.fixed_inlet_counts:
            return ILLEGAL
        bounds = model.inlet_count_bounds
        if bounds.shape[0] > 0:
            new_a = state.n_downstream[top_a] - na + nb
            new_b = state.n_downstream[top_b] - nb + na
            ia = top_a
            ib = top_b
            if not (bounds[ia, 0] <= new_a <= bounds[ia, 1] and bounds[ib, 0] <= new_b <= bounds[ib, 1]):
                return ILLEGAL
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
    # pressure: exact, and cheap next to the exclusion, so it enters every bound
    d_pre = 0.0
    if model.pressure_on:
        d_pre = _swap_pressure_change(model, state, a, b, lca, new_len_a, new_len_b)
    # early rejection on a lower bound (new segments' exclusion taken as 0)
    u = -1.0
    check = _bounds_apply(model)
    vascular = d_vol + d_pow
    bound = 0.0
    if check:
        bound = weighted_total(model, vascular, d_exc - old_exc, d_pre, 0.0, 0.0)
        rejected, u = _early_reject(bound, temp, rng, -1.0)
        if rejected:
            return REJECTED
    # exclusion, each traversal stopped once its sum rejects the move (as in _translate_node)
    new_exc_a = 0.0
    new_exc_b = 0.0
    if model.exclusion_on:
        new_exc_a, rejected, u = _new_exclusion(
            model, pos[a], pos[pb], na, temp, rng, u, bound, vascular, d_exc, 0.0, old_exc, d_pre, 0.0, 0.0, True
        )
        if rejected:
            return REJECTED
        cost_a = _exclusion_cost(model, na, new_exc_a)
        if check:  # b's new exclusion still taken as 0
            bound = weighted_total(model, vascular, d_exc + (cost_a - old_exc), d_pre, 0.0, 0.0)
            rejected, u = _early_reject(bound, temp, rng, u)
            if rejected:
                return REJECTED
        new_exc_b, rejected, u = _new_exclusion(
            model, pos[b], pos[pa], nb, temp, rng, u, bound, vascular, d_exc, cost_a, old_exc, d_pre, 0.0, 0.0, True
        )
        if rejected:
            return REJECTED
        d_exc += (cost_a + _exclusion_cost(model, nb, new_exc_b)) - old_exc
    # Metropolis, then commit
    d_cost = weighted_total(model, vascular, d_exc, d_pre, 0.0, 0.0)  # a swap leaves C_s alone
    if not _accept_with(d_cost, temp, rng, u):
        return REJECTED
    state.counters[COUNTER_SWAP_ACCEPTED] += 1
    _exchange_parents(state, a, b, lca)
    _set_segment(state, a, new_len_a, new_exc_a)
    _set_segment(state, b, new_len_b, new_exc_b)
    if model.pressure_on:
        _update_moments(model, state, pa)
        _update_moments(model, state, pb)
    _commit(model, state, d_vol, d_pow, d_exc, 0.0, d_pre)
    return ACCEPTED
