"""The move loop and whole-state passes: initialise the caches and sums, anneal a block, sample uphill moves.

:func:`anneal_block` runs a block of proposed moves from ``state`` and returns; the
temperature and every random draw depend only on the step number and the saved state, so
S steps in one block or any split of blocks give bit-identical trees.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit, jit_norc
from ..model.physics import TABLE_POWER, TABLE_VOLUME
from ..model.rng import next_below, next_double
from .cells import build_cells
from .exclusion import _distance3, recompute_exclusion
from .moves import _swap, _translate, swap_random, translate_node
from .pressure import pressure_cost
from .schedule import temperature, weighted_total
from .state import COUNTER_STEP, EXCLUSION, POWER, PRESSURE, SUPPLY, VOLUME, _add
from .supply import supply_sphere

__all__ = [
    "anneal_block",
    "initialise",
    "initialise_segments",
    "sample_uphill",
    "scaled_total_without_supply",
]


@jit  # once per run; np.count_nonzero needs the reference-counted runtime
def initialise(model, state):
    """Fill the per-segment caches, the supply map and the running sums from the tree."""
    initialise_segments(model, state)
    supply = state.supply
    nz, ny, nx = supply.shape
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                supply[k, j, i] = 0 if model.mask[k, j, i] != 0 else -1
    if model.supply_on:
        c_s = 10.0 * np.count_nonzero(model.mask)
        for t in range(model.n_inlets, model.n_inlets + model.n_terminals):
            c_s += supply_sphere(model, supply, state.position[t], 1)
        state.costs[SUPPLY] = c_s
    if model.pressure_on:
        state.costs[PRESSURE] = pressure_cost(model, state)


@jit
def initialise_segments(model, state):
    """:func:`initialise` but for the supply map, left as it is, and C_s and C_p, left at 0
    (a part of a tree takes its supply map and C_s from the whole tree: engine.parts)."""
    tables = model.tables
    pos = state.position
    state.costs[:] = 0.0
    state.compensation[:] = 0.0
    state.seg_length[:] = 0.0
    state.scratch_shell_frame[:, 3] = 0.0  # no shell of a grid this model may not share
    for i in range(model.n_inlets, state.parent.size):
        p = state.parent[i]
        n = state.n_downstream[i]
        length = _distance3(pos[i], pos[p])
        state.seg_length[i] = length
        _add(state.costs, state.compensation, VOLUME, tables[TABLE_VOLUME, n] * length)
        _add(state.costs, state.compensation, POWER, tables[TABLE_POWER, n] * length)
    recompute_exclusion(model, state)
    build_cells(model, state)


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
