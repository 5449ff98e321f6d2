"""The pressure term C_p: Poiseuille pressure drops down every inlet's tree, squared deviations at terminals."""

from __future__ import annotations

from .._jit import jit_norc, jit_norc_inline
from ..model.physics import TABLE_FLOW, TABLE_RESISTANCE

__all__ = [
    "pressure_cost",
]


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
