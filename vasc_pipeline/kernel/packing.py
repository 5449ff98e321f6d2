"""The packing phase: terminal sites placed by annealing the supply term alone.

The supply term weighs A_s/A_wv = 1e26 per voxel, so it orders trees before anything else,
and placing N supply spheres is a packing problem of its own that needs no tree. With
``anneal.packing_steps_per_terminal`` > 0, the first ``pack_steps`` proposals of a run
move terminals only and are accepted on ΔC_s alone, at a packing temperature falling
exponentially from ``anneal.packing_T_start`` (in voxels of one supply sphere) to
``anneal.packing_T_end`` (C_s units). A packing move costs only the supply sphere's
update: no segment, traversal or tree cache is touched, and those go stale while the
terminals move. At step ``pack_steps`` (:func:`end_packing`) every bifurcation moves to
the mean of its children, bottom-up (unless the mean is outside ``tissue.bifurcation_reach``:
then it stays), and the kernel's caches and running sums are rebuilt from the tree
(:func:`vasc_pipeline.initialise`); the tree anneal then runs its own schedule over
the remaining proposals (``Model.pack_steps`` is where it starts).

Everything lives in the kernel's ``State`` (positions, supply map, generator, counters,
the terminal step width), so a packing phase split into blocks, checkpointed and resumed
ends bit-identically. The trace's vascular and exclusion terms during packing are those of
the initial tree (stale); its supply term is exact.

:func:`pack_block_reference` is the plain NumPy twin the tests compare with.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_norc, jit_norc_inline
from ..model.costs import supply_cost, supply_counts
from ..model.rng import next_below, next_double
from .loop import initialise
from .moves import _adapt_step, legal_position
from .state import (
    ACCEPTED,
    COUNTER_STEP,
    COUNTER_TERMINAL_ACCEPTED,
    COUNTER_TERMINAL_PROPOSED,
    ILLEGAL,
    REJECTED,
    SUPPLY,
    _breadth_first,
)
from .supply import in_tissue, supply_move, supply_move_delta

__all__ = ["pack_block", "end_packing", "pack_block_reference", "packing_temperature"]


@jit_norc
def packing_temperature(model, step):
    """Packing temperature [C_s units] at ``step`` < ``model.pack_steps``."""
    frac = step / model.pack_steps
    return model.pack_T_start * math.exp(math.log(model.pack_T_end / model.pack_T_start) * frac)


@jit_norc_inline
def _pack_move(model, state, temp, new):
    """Propose moving one random terminal; accept on ΔC_s at ``temp``. Returns the outcome."""
    rng = state.rng
    pos = state.position
    i = model.n_inlets + next_below(rng, model.n_terminals)
    # As in the tree anneal: half of the moves keep the full width (supply is searched by
    # moves of voxel scale), the other half adapt theirs to the acceptance target.
    full_width = model.adapt_steps and next_double(rng) < 0.5
    half = model.step_max[0] if full_width else state.step_size[0]
    for a in range(3):
        new[a] = pos[i, a] + (2.0 * next_double(rng) - 1.0) * half
    if model.planar:
        new[2] = pos[i, 2]
    outcome = ILLEGAL
    if in_tissue(model, new):
        d = supply_move_delta(model, state.supply, pos[i], new)
        if d <= 0.0 or next_double(rng) < math.exp(-d / temp):
            supply_move(model, state.supply, pos[i], new)
            pos[i, 0], pos[i, 1], pos[i, 2] = new[0], new[1], new[2]
            state.costs[SUPPLY] += d  # integer-valued: exact in float64
            outcome = ACCEPTED
        else:
            outcome = REJECTED
    c = state.counters
    c[COUNTER_TERMINAL_PROPOSED] += 1
    if outcome == ACCEPTED:
        c[COUNTER_TERMINAL_ACCEPTED] += 1
    if model.adapt_steps and not full_width:
        _adapt_step(model, state, 0, outcome == ACCEPTED)
    return outcome


@jit
def end_packing(model, state):
    """Bifurcations to the means of their children (bottom-up) where that is legal, then every cache rebuilt."""
    n = _breadth_first(model, state)
    order = state.scratch_stack
    first_bif = model.n_inlets + model.n_terminals
    pos = state.position
    for idx in range(n - 1, -1, -1):
        b = order[idx]
        if b >= first_bif:
            c0, c1 = state.children[b, 0], state.children[b, 1]
            mean = 0.5 * (pos[c0] + pos[c1])
            if legal_position(model, False, mean):  # else it stays where it is (legal)
                pos[b] = mean
    initialise(model, state)


@jit_norc
def _pack_steps(model, state, n_steps, new):
    done = 0
    while done < n_steps and state.counters[COUNTER_STEP] < model.pack_steps:
        step = state.counters[COUNTER_STEP]
        _pack_move(model, state, packing_temperature(model, step), new)
        state.counters[COUNTER_STEP] = step + 1
        done += 1
    return done


@jit
def pack_block(model, state, n_steps):
    """Run up to ``n_steps`` packing proposals (not past ``model.pack_steps``); return how many.

    The block whose last proposal reaches ``pack_steps`` ends the phase (:func:`end_packing`).
    The loop runs without reference counting (``_jit.jit_norc``); this wrapper allocates.
    """
    done = _pack_steps(model, state, n_steps, np.empty(3))
    if done > 0 and state.counters[COUNTER_STEP] == model.pack_steps:
        end_packing(model, state)
    return done


def pack_block_reference(model, state, n_steps: int, tissue, supply_radius: float) -> None:
    """Plain twin of :func:`pack_block` for the tests: the same draws, C_s recomputed in full.

    Evaluates every proposal by recounting the supply spheres from scratch
    (:func:`vasc_pipeline.model.costs.supply_counts`), shares no supply code with the kernel, and
    ends the phase with :func:`end_packing`'s own definition (means bottom-up, rebuilt caches).
    """
    pos = state.position
    first, last = model.n_inlets, model.n_inlets + model.n_terminals
    current = supply_cost(supply_counts(pos[first:last], tissue, supply_radius), tissue.mask, tissue.supply_target)
    for _ in range(n_steps):
        step = int(state.counters[COUNTER_STEP])
        if step >= model.pack_steps:
            break
        temp = packing_temperature.py_func(model, step)
        rng = state.rng
        i = first + next_below(rng, model.n_terminals)
        full_width = model.adapt_steps and next_double(rng) < 0.5
        half = model.step_max[0] if full_width else state.step_size[0]
        new = np.array([pos[i, a] + (2.0 * next_double(rng) - 1.0) * half for a in range(3)])
        if model.planar:
            new[2] = pos[i, 2]
        accepted = False
        if tissue.contains(new[None])[0]:
            trial = pos[first:last].copy()
            trial[i - first] = new
            cost = supply_cost(supply_counts(trial, tissue, supply_radius), tissue.mask, tissue.supply_target)
            d = cost - current
            if d <= 0.0 or next_double(rng) < math.exp(-d / temp):
                pos[i] = new
                current = cost
                accepted = True
        state.counters[COUNTER_TERMINAL_PROPOSED] += 1
        state.counters[COUNTER_TERMINAL_ACCEPTED] += int(accepted)
        if model.adapt_steps and not full_width:
            _adapt_step.py_func(model, state, 0, accepted)
        state.counters[COUNTER_STEP] = step + 1
        if step + 1 == model.pack_steps:
            end_packing.py_func(model, state)
            return
    state.costs[SUPPLY] = current
    counts = supply_counts(pos[first:last], tissue, supply_radius)
    state.supply[...] = np.where(tissue.mask == 1, counts, -1)
