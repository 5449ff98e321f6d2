"""The pressure term C_p: Poiseuille pressure drops down every inlet's tree, squared deviations at terminals.

A changed drop shifts the pressure of every terminal below it by the same amount, and the
change of Σ (P_t - P_term)^2 over a subtree under a uniform shift s is 2 s S1 + n s^2, with
S1 = Σ (P_t - P_term) over its n terminals. S1 of the subtree below node x is
n_x (P_x - P_term) - H_x, with the drop moment H_x = Σ over the strict descendants u of x
of n_u drop_u: a translation's ΔC_p needs the pressure above the moved node (a walk up the
path) and the moments of the subtrees below it, a swap's the pressures along its two paths
and the moments of the subtrees hanging off them. O(depth) per move, not O(N).

The moments (``State.scratch_drop_moment``) are a cache derived from the tree: each is
computed from its children's, and every accepted move recomputes those of the nodes above
its changed segments in the same way, so they equal a fresh bottom-up pass bit for bit and
are never checkpointed.
"""

from __future__ import annotations

from .._jit import jit_norc, jit_norc_inline
from ..model.physics import TABLE_FLOW, TABLE_RESISTANCE
from .state import _breadth_first

__all__ = [
    "pressure_cost",
    "pressure_moments",
]


@jit_norc
def pressure_cost(model, state):
    """C_p from scratch: Poiseuille drops down every inlet's tree (O(N), depth-first); leaves
    the node pressures in scratch_pressure."""
    parent = state.parent
    children = state.children
    pressure = state.scratch_pressure
    stack = state.scratch_stack
    top = 0
    for k in range(model.n_inlets):
        pressure[k] = model.pressure_inlet[k]
        for s in range(2):  # a part's pseudo-inlet may hold two of its subtrees
            if children[k, s] >= 0:
                stack[top] = children[k, s]
                top += 1
    total = 0.0
    first_bif = model.n_inlets + model.n_terminals
    while top > 0:
        top -= 1
        x = stack[top]
        pressure[x] = pressure[parent[x]] - _segment_drop(model, state, x)
        if x >= first_bif:
            stack[top] = children[x, 0]
            stack[top + 1] = children[x, 1]
            top += 2
        elif x >= model.n_inlets:
            d = pressure[x] - model.pressure_terminal
            total += d * d
    return total


@jit_norc
def pressure_moments(model, state):
    """Fill scratch_drop_moment for every node, children before parents (O(N))."""
    m = _breadth_first(model, state)
    order = state.scratch_stack
    for j in range(m - 1, -1, -1):
        x = order[j]
        state.scratch_drop_moment[x] = _moment(model, state, x)


@jit_norc_inline
def _drop(model, n, length):
    """Poiseuille pressure drop [Pa] along a segment of ``length`` with n terminals downstream."""
    return model.tables[TABLE_FLOW, n] * model.tables[TABLE_RESISTANCE, n] * length


@jit_norc_inline
def _segment_drop(model, state, x):
    """The drop along segment x (the one ending at node x)."""
    return _drop(model, state.n_downstream[x], state.seg_length[x])


@jit_norc_inline
def _moment(model, state, x):
    """H_x from the children's segments and moments (0 at a terminal)."""
    h = 0.0
    for s in range(2):
        c = state.children[x, s]
        if c >= 0:
            h += state.n_downstream[c] * _segment_drop(model, state, c) + state.scratch_drop_moment[c]
    return h


@jit_norc
def _update_moments(model, state, x):
    """Recompute the moments of node x and of every node above it, after a change below x."""
    while x >= 0:
        state.scratch_drop_moment[x] = _moment(model, state, x)
        x = state.parent[x]


@jit_norc_inline
def _node_pressure(model, state, x):
    """Pressure [Pa] at node x: its inlet's less the drops on the path up to it (O(depth))."""
    drops = 0.0
    while state.parent[x] >= 0:
        drops += _segment_drop(model, state, x)
        x = state.parent[x]
    return model.pressure_inlet[x] - drops


@jit_norc_inline
def _shift_change(model, state, x, pressure_x, shift):
    """Change of Σ (P_t - P_term)^2 over the terminals below node x (pressure ``pressure_x``
    now) when all their pressures change by ``shift``."""
    n = state.n_downstream[x]
    s1 = n * (pressure_x - model.pressure_terminal) - state.scratch_drop_moment[x]
    return shift * (2.0 * s1 + n * shift)


@jit_norc_inline
def _translation_pressure_change(model, state, i, len_i, c0, len_c0, c1, len_c1):
    """ΔC_p when segment i takes length ``len_i``, and for a bifurcation (c0 >= 0) its
    children's segments c0 and c1 theirs."""
    old_i = _segment_drop(model, state, i)
    d_i = _drop(model, state.n_downstream[i], len_i) - old_i
    pressure_i = _node_pressure(model, state, state.parent[i]) - old_i
    if c0 < 0:
        return _shift_change(model, state, i, pressure_i, -d_i)
    old_c0 = _segment_drop(model, state, c0)
    old_c1 = _segment_drop(model, state, c1)
    d_c0 = _drop(model, state.n_downstream[c0], len_c0) - old_c0
    d_c1 = _drop(model, state.n_downstream[c1], len_c1) - old_c1
    return _shift_change(model, state, c0, pressure_i - old_c0, -(d_i + d_c0)) + _shift_change(
        model, state, c1, pressure_i - old_c1, -(d_i + d_c1)
    )


@jit_norc_inline
def _path_drops(model, state, start, stop, dn):
    """Drops on the path start .. stop (exclusive; up to the inlet when stop is -1) now, and
    with n changed by dn on it, and the node where it ends (stop, or the inlet)."""
    old = 0.0
    new = 0.0
    x = start
    while x != stop and state.parent[x] >= 0:
        old += _segment_drop(model, state, x)
        new += _drop(model, state.n_downstream[x] + dn, state.seg_length[x])
        x = state.parent[x]
    return old, new, x


@jit_norc_inline
def _path_side_change(model, state, moved, start, stop, dn, pressure_start, new_pressure_start):
    """ΔC_p of the subtrees hanging off the path start .. stop (exclusive) when n changes by dn
    on it; ``moved``, the child of ``start`` that leaves, is not one of them."""
    change = 0.0
    below = moved
    x = start
    pressure_x = pressure_start
    new_pressure_x = new_pressure_start
    while x != stop and state.parent[x] >= 0:
        s = state.children[x, 0]
        if s == below:
            s = state.children[x, 1]
        change += _shift_change(
            model, state, s, pressure_x - _segment_drop(model, state, s), new_pressure_x - pressure_x
        )
        pressure_x += _segment_drop(model, state, x)
        new_pressure_x += _drop(model, state.n_downstream[x] + dn, state.seg_length[x])
        below = x
        x = state.parent[x]
    return change


@jit_norc_inline
def _swap_pressure_change(model, state, a, b, lca, new_len_a, new_len_b):
    """ΔC_p when a and b exchange parents (LCA ``lca``, -1 for different inlet trees) and their
    segments take the given lengths: the two moved subtrees and those hanging off the paths
    from the old parents up to the LCA shift; nothing else does."""
    pa = state.parent[a]
    pb = state.parent[b]
    dn = state.n_downstream[b] - state.n_downstream[a]
    old_a, new_a, end_a = _path_drops(model, state, pa, lca, dn)
    old_b, new_b, end_b = _path_drops(model, state, pb, lca, -dn)
    if lca >= 0:
        top_a = top_b = _node_pressure(model, state, lca)
    else:  # each path's own inlet (a part's pseudo-inlets differ in pressure)
        top_a = model.pressure_inlet[end_a]
        top_b = model.pressure_inlet[end_b]
    pressure_pa = top_a - old_a
    pressure_pb = top_b - old_b
    new_pressure_pa = top_a - new_a
    new_pressure_pb = top_b - new_b
    change = _path_side_change(model, state, a, pa, lca, dn, pressure_pa, new_pressure_pa)
    change += _path_side_change(model, state, b, pb, lca, -dn, pressure_pb, new_pressure_pb)
    drop_a = _segment_drop(model, state, a)
    drop_b = _segment_drop(model, state, b)
    pressure_a = pressure_pa - drop_a
    pressure_b = pressure_pb - drop_b
    new_pressure_a = new_pressure_pb - _drop(model, state.n_downstream[a], new_len_a)
    new_pressure_b = new_pressure_pa - _drop(model, state.n_downstream[b], new_len_b)
    change += _shift_change(model, state, a, pressure_a, new_pressure_a - pressure_a)
    change += _shift_change(model, state, b, pressure_b, new_pressure_b - pressure_b)
    return change
