"""Neighbour cells: swap partners biased towards spatial neighbours.

Linked lists of non-inlet nodes per cell of a grid over the box. They live in ``State`` (the
list order decides which partner a draw picks, so it is checkpointed, not rebuilt).
"""

from __future__ import annotations

import math

from .._jit import jit_norc, jit_norc_inline
from ..model.rng import next_below

__all__ = [
    "build_cells",
    "neighbour_partner",
]


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
