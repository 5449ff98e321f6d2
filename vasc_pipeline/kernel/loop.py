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
from .moves import _adapt_step, _translate_node, _translation
from .pressure import pressure_cost, pressure_moments
from .schedule import temperature, weighted_total
from .state import ACCEPTED, COUNTER_STEP, EXCLUSION, ILLEGAL, POWER, PRESSURE, SUPPLY, VOLUME, _add
from .supply import supply_sphere
from .swaps import _swap

__all__ = [
    "anneal_block",
    "initialise",
    "initialise_segments",
    "sample_uphill",
    "scaled_total_without_supply",
    "translate_node",
]

# What :func:`_moves` does with its moves.
_ANNEAL, _SAMPLE, _TRANSLATE = 0, 1, 2


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
        # every voxel uncovered: s(0) = 10 t, t = 1 without a demand map
        c_s = 10.0 * (np.count_nonzero(model.mask) if model.supply_target.shape[0] == 0 else _target_sum(model))
        for t in range(model.n_inlets, model.n_inlets + model.n_terminals):
            c_s += supply_sphere(model, supply, state.position[t], 1)
        state.costs[SUPPLY] = c_s
    if model.pressure_on:
        pressure_moments(model, state)
        state.costs[PRESSURE] = pressure_cost(model, state)


@jit_norc
def _target_sum(model):
    """Sum of the tissue voxels' coverage targets (the demand map's)."""
    total = 0
    target = model.supply_target
    for k in range(target.shape[0]):
        for j in range(target.shape[1]):
            for i in range(target.shape[2]):
                total += np.int64(target[k, j, i]) * (model.mask[k, j, i] != 0)
    return total


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
    _moves(model, state, n_steps, np.empty(3), np.int64(_ANNEAL), np.int64(-1), 0.0, np.empty(0))


@jit
def translate_node(model, state, i, new, temp):
    """Propose moving node i to ``new``; Metropolis at ``temp``. Returns ILLEGAL, REJECTED or ACCEPTED.

    A terminal must land in tissue, a bifurcation inside the grid's box and its region.
    """
    return _moves(model, state, np.int64(1), new, np.int64(_TRANSLATE), np.int64(i), np.float64(temp), np.empty(0))


@jit_norc
def _moves(model, state, n_steps, new, mode, node, temp_given, out):
    """Every proposal of moves, in one function: numba inlines a move's body where it is called,
    and inlining the two moves once here, not once per caller (the loop, the calibration, the
    polish), cut the first run's compilation by a quarter. Callers pass every integer as
    ``np.int64``: a literal constant would make numba compile one copy per value. Compiled
    without reference counting (see ``_jit.jit_norc``), as is every function it calls.
    ``new``: scratch (3,), or the target of a single translation.

    - ``_ANNEAL``: ``n_steps`` moves of the schedule (:func:`anneal_block`).
    - ``_SAMPLE``: ``n_steps`` moves at infinite temperature, swaps and bifurcation
      translations alike; the uphill ΔC go to ``out``; returns how many (:func:`sample_uphill`).
    - ``_TRANSLATE``: node ``node`` to ``new`` at ``temp_given``; returns the outcome
      (:func:`translate_node`).
    """
    rng = state.rng
    first_bif = model.n_inlets + model.n_terminals
    n_bif = state.parent.size - first_bif
    stored = 0
    outcome = ILLEGAL
    for _ in range(n_steps):
        step = 0
        before = 0.0
        if mode == _ANNEAL:
            step = state.counters[COUNTER_STEP]
            temp = temperature(model, state, step)
            swap = next_double(rng) < model.p_swap
        elif mode == _SAMPLE:
            before = scaled_total_without_supply(model, state)
            temp = np.inf
            swap = n_bif == 0 or next_double(rng) < 0.5
        else:
            temp = temp_given
            swap = False
        if swap:
            outcome = _swap(model, state, temp)
        else:
            i = node
            cls = 1
            adapt = False
            if mode == _ANNEAL:
                i, cls, adapt = _translation(model, state, new)
            elif mode == _SAMPLE:
                i = first_bif + next_below(rng, n_bif)
                half = state.step_size[1]
                for a in range(3):
                    new[a] = state.position[i, a] + (2.0 * next_double(rng) - 1.0) * half
                if model.planar:
                    new[2] = state.position[i, 2]
            outcome = _translate_node(model, state, i, new, temp) if i >= 0 else ILLEGAL
            if adapt:
                _adapt_step(model, state, cls, outcome == ACCEPTED)
        if mode == _ANNEAL:
            state.counters[COUNTER_STEP] = step + 1
        elif mode == _SAMPLE:
            d = scaled_total_without_supply(model, state) - before
            if d > 0.0 and stored < out.size:
                out[stored] = d
                stored += 1
    return stored if mode == _SAMPLE else outcome


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
    return _moves(model, state, n_samples, np.empty(3), np.int64(_SAMPLE), np.int64(-1), 0.0, out)
