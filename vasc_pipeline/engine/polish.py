"""The end of a run: the final polish and, for small trees, single-swap descent.

Both drive the kernel on the final tree of an anneal (exact incremental deltas, then every
cache rebuilt with :func:`vasc_pipeline.kernel.initialise`) and use the pure geometry of
:mod:`vasc_pipeline.model.geometry` (the optimal bifurcation positions of a fixed topology).
Neither moves a terminal nor draws a random number, so a resumed run finishes identically.
:func:`vasc_pipeline.engine.finish` calls them when ``anneal.polish`` is on.
"""

from __future__ import annotations

import numpy as np

from .. import kernel
from ..model.geometry import optimal_bifurcations, vascular_cost, vascular_weights
from ..model.topology import inlet_of
from ..model.tree import KIND_BIFURCATION, Tree, children_from_parent, count_terminals
from .problem import running_costs, tree_of

__all__ = ["polish", "descend_swaps"]


# --------------------------------------------------------------------------------------
# Polish of an annealing state


def polish(problem, state: kernel.State) -> dict:
    """Move the state's bifurcations towards the vascular optimum where the total cost drops.

    The topology and the terminals are untouched. The optimum of C_v + C_w is applied whole
    when the total annealed cost (every active term) does not rise; otherwise the largest
    step old -> optimum, halving, that lowers the total is taken (the vascular part, being
    convex, is no worse anywhere on the way), and then single bifurcations are moved to
    their optimal positions one by one where that lowers the total (exact kernel deltas).
    Terminals never move, so the supply term is constant and the comparisons leave it out
    (its weight, 1e26 by default, would hide every other term in the rounding of the total).
    Every cache and running sum of ``state`` is then rebuilt from the tree
    (:func:`vasc_pipeline.kernel.initialise`); the generator state and the counters are
    left as they were, so polish draws no random numbers from the run.

    Returns
    -------
    dict with ``before`` and ``after`` (cost terms, recomputed from the tree, plus
    ``total``) [W], ``applied`` ("full", "partial" or "none") and ``moved`` (number of
    bifurcations moved).
    """

    model = problem.model
    rng_saved = state.rng.copy()
    counters_saved = state.counters.copy()
    kernel.initialise(model, state)  # fresh sums: compare against the tree's true cost
    before = running_costs(problem, state)
    reference = kernel.scaled_total_without_supply(model, state)
    tree = tree_of(problem, state)
    weights = vascular_weights(tree, problem.physics)
    opt = optimal_bifurcations(tree, weights, problem.tissue.bounds)
    bif = np.flatnonzero(tree.kind == KIND_BIFURCATION)
    old = tree.position[bif].copy()
    target = opt.position[bif]
    applied = "none"
    t = 1.0
    for _ in range(30):
        state.position[bif] = old + t * (target - old)
        kernel.initialise(model, state)
        if kernel.scaled_total_without_supply(model, state) <= reference:
            applied = "full" if t == 1.0 else "partial"
            break
        t *= 0.5
    else:
        state.position[bif] = old
        kernel.initialise(model, state)
    if applied != "full":
        # Single-node moves to the optimum, accepted only downhill (temperature ~0).
        new = np.empty(3)
        for _ in range(3):
            accepted = 0
            for k, i in enumerate(bif):
                if np.array_equal(state.position[i], target[k]):
                    continue
                new[:] = target[k]
                accepted += kernel.translate_node(model, state, int(i), new, 1e-300) == kernel.ACCEPTED
            if accepted == 0:
                break
        kernel.initialise(model, state)
        if kernel.scaled_total_without_supply(model, state) > reference:  # rounding of the running sums
            state.position[bif] = old
            kernel.initialise(model, state)
        elif not np.array_equal(state.position[bif], old):
            applied = "partial"
    state.rng[:] = rng_saved
    state.counters[:] = counters_saved
    after = running_costs(problem, state)
    moved = int(np.count_nonzero(np.any(state.position[bif] != old, axis=1)))
    return {"before": before, "after": after, "applied": applied, "moved": moved}


# --------------------------------------------------------------------------------------
# Swap descent of small trees


def descend_swaps(problem, state: kernel.State, max_rounds: int = 20) -> int:
    """Single-swap descent with optimal geometry: the end of a small tree's anneal.

    Near the end of an anneal two topologies whose optima differ by little can be
    separated by a barrier (the geometry of one is poor for the other), and the chain may
    freeze in the worse. Here every legal swap of two non-inlet nodes is tried with the
    bifurcations at the swapped topology's optimum (:func:`optimal_bifurcations`); the
    best one that lowers C_v + C_w is applied if the total annealed cost (less the
    constant supply term) drops too, and the search repeats until no swap helps. O(N^2)
    geometry solves a round: meant for trees of a few dozen terminals. Terminals do not
    move and no random number is drawn. Returns the number of swaps applied.
    """
    model, physics = problem.model, problem.physics
    k, n = physics.n_inlets, physics.n_terminals
    bounds = problem.tissue.bounds
    applied = 0
    kernel.initialise(model, state)
    for _ in range(max_rounds):
        current = kernel.scaled_total_without_supply(model, state)
        parent = state.parent.copy()
        tree = Tree(parent, state.children.copy(), state.position.copy(), state.n_downstream.copy(), k)
        vascular = vascular_cost(tree.position, parent, vascular_weights(tree, physics))
        inlet = inlet_of(parent)
        candidates = []
        for a in range(k, parent.size):
            ancestors_a = _ancestors(parent, a)
            for b in range(a + 1, parent.size):
                if parent[a] == parent[b] or b in ancestors_a or a in _ancestors(parent, b):
                    continue
                if inlet[a] != inlet[b] and not _keeps_inlet_bounds(model, tree.n_downstream, inlet, a, b):
                    continue  # tissue.inlet_share (and its tolerance), as in the kernel's swap
                trial = parent.copy()
                trial[a], trial[b] = parent[b], parent[a]
                t = Tree(trial, children_from_parent(trial), tree.position.copy(), count_terminals(trial, n, k), k)
                opt = optimal_bifurcations(t, vascular_weights(t, physics), bounds)
                if opt.cost < vascular * (1.0 - 1e-12):
                    candidates.append((opt.cost, t, opt.position))
        improved = False
        for _, t, position in sorted(candidates, key=lambda c: c[0]):
            saved = (state.parent.copy(), state.children.copy(), state.n_downstream.copy(), state.position.copy())
            state.parent[:], state.children[:], state.n_downstream[:] = t.parent, t.children, t.n_downstream
            state.position[:] = position
            kernel.initialise(model, state)
            if kernel.scaled_total_without_supply(model, state) < current:
                applied += 1
                improved = True
                break
            state.parent[:], state.children[:], state.n_downstream[:], state.position[:] = saved
            kernel.initialise(model, state)
        if not improved:
            break
    return applied


def _keeps_inlet_bounds(model, n_downstream: np.ndarray, inlet: np.ndarray, a: int, b: int) -> bool:
    """Whether swapping a and b (in different inlet trees) keeps every inlet's terminal count
    as ``tissue.inlet_share`` asks: exactly, or within ``inlet_share_tolerance``'s bounds."""
    moved = n_downstream[a] - n_downstream[b]  # from a's inlet tree to b's
    if moved == 0:
        return True
    if model.fixed_inlet_counts:
        return False
    bounds = model.inlet_count_bounds
    if bounds.shape[0] == 0:
        return True
    ia, ib = inlet[a], inlet[b]
    new_a, new_b = n_downstream[ia] - moved, n_downstream[ib] + moved
    return bool(bounds[ia, 0] <= new_a <= bounds[ia, 1] and bounds[ib, 0] <= new_b <= bounds[ib, 1])


def _ancestors(parent: np.ndarray, i: int) -> set[int]:
    out = set()
    x = parent[i]
    while x >= 0:
        out.add(int(x))
        x = parent[x]
    return out
