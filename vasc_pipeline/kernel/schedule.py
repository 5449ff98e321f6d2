"""The schedule and the acceptance test: temperature, supply weight, the weighted total, Metropolis.

:func:`temperature` depends only on the step and ``State.schedule``; the Metropolis tests
draw from ``State.rng``; :func:`weighted_total` is the kernel's one copy of
:func:`vasc_pipeline.model.costs.total_cost`.
"""

from __future__ import annotations

import math

from .._jit import jit_norc, jit_norc_inline
from ..model.rng import next_double
from .state import COUNTER_STEP

__all__ = [
    "supply_weight",
    "temperature",
    "weighted_total",
]


@jit_norc_inline
def weighted_total(model, vascular, exclusion, pressure, w_supply, supply):
    """The annealed total (or a change of it) from its terms: the kernel's one copy of
    :func:`vasc_pipeline.model.costs.total_cost`, C = (C_w + C_v) + w_o C_o + w_p C_p + w_s C_s,
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
    """Whether a move is checked on lower bounds of ΔC before its exclusion traversals
    (``Model.early_reject`` False turns them off to test)."""
    return model.early_reject


@jit_norc_inline
def _accept_with(d_cost, temp, rng, u):
    """:func:`_accept`, reusing the uniform ``u`` when :func:`_early_reject` drew one."""
    if d_cost <= 0.0:
        return True
    if u < 0.0:
        u = next_double(rng)
    return u < math.exp(-d_cost / temp)
