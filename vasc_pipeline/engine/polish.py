"""The end of a run: the final polish, the prune-and-regraft descent and, for small trees,
single-swap descent.

Both drive the kernel on the final tree of an anneal (exact incremental deltas, then every
cache rebuilt with :func:`vasc_pipeline.kernel.initialise`) and use the pure geometry of
:mod:`vasc_pipeline.model.geometry` (the optimal bifurcation positions of a fixed topology).
Neither moves a terminal nor draws a random number, so a resumed run finishes identically.
:func:`vasc_pipeline.engine.finish` calls them when ``anneal.polish`` is on.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .. import kernel
from ..kernel.exclusion import segment_exclusion
from ..kernel.moves import legal_position
from ..model.geometry import optimal_bifurcations, vascular_cost, vascular_weights
from ..model.physics import TABLE_EXCLUSION, TABLE_POWER, TABLE_VOLUME
from ..model.topology import inlet_of
from ..model.tree import KIND_BIFURCATION, Tree, children_from_parent, count_terminals
from .problem import running_costs, tree_of

__all__ = ["polish", "descend_swaps", "descend_regrafts"]


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


# --------------------------------------------------------------------------------------
# Prune-and-regraft descent


def descend_regrafts(problem, state: kernel.State, neighbours: int = 8, max_rounds: int = 10) -> int:
    """Prune-and-regraft descent: the end of a large tree's anneal.

    The anneal's moves (subtree swaps, translations) cannot bring home a terminal or a small
    subtree left on a long segment, far from its relatives: an exchange with a node near it
    only strands that one instead. Moving the subtree alone onto a segment near it (its old
    bifurcation removed, a new one on that segment) can, and it is a move the anneal does not
    have. Here each node, the smallest subtrees first and among them the longest segments, is
    tried on the segments ending at the ``neighbours`` nodes nearest it (outside its subtree),
    the new bifurcation at the point of the segment nearest the node (where a bifurcation may
    lie); the best change of C_v + C_w + C_o, estimated from the segments it touches, is
    applied when negative and when the total annealed cost (less the constant supply term)
    recomputed from the tree drops. Rounds repeat until none applies. Terminals do not move
    and no random number is drawn. Returns the number of regrafts applied.
    """
    model, physics = problem.model, problem.physics
    k, n = physics.n_inlets, physics.n_terminals
    weight = _regraft_weights(problem)
    applied = 0
    kernel.initialise(model, state)
    nodes = state.parent.size - k
    for _ in range(max_rounds):
        nearest = (
            cKDTree(state.position[k:]).query(state.position[k:], min(neighbours + 1, nodes))[1].reshape(nodes, -1) + k
        )
        before = applied
        for x in k + np.lexsort((-state.seg_length[k:], state.n_downstream[k:])):
            best = _best_regraft(model, state, weight, int(x), nearest[x - k])
            if best is not None and _apply_regraft(model, state, int(x), *best, k, n):
                applied += 1
        if applied == before:
            break
    return applied


def _regraft_weights(problem) -> tuple[np.ndarray, np.ndarray]:
    """Per terminal count n: the annealed cost per metre (C_v + C_w) and per unit traversal
    sum ((A_o / A_wv) C_o) of a segment."""
    tables = problem.model.tables
    return tables[TABLE_VOLUME] + tables[TABLE_POWER], problem.physics.weights[0] * tables[TABLE_EXCLUSION]


def _sibling(state, x: int) -> int:
    b = state.parent[x]
    return int(state.children[b, 0] if state.children[b, 1] == x else state.children[b, 1])


def _best_regraft(model, state, weight, x: int, candidates: np.ndarray):
    """(segment j, new bifurcation position) of node x's best regraft onto the segment ending
    at one of ``candidates``, or None when none lowers the estimated cost."""
    parent = state.parent
    b = parent[x]
    if b < model.n_inlets:
        return None  # an inlet's root segment
    s = _sibling(state, x)
    best = None
    for j in candidates:
        if j in (x, b, s) or x in _ancestors(parent, int(j)):
            continue
        y = _nearest_on_segment(state.position[x], state.position[j], state.position[parent[j]])
        if not legal_position(model, False, y):
            continue
        change = _regraft_change(model, state, weight, x, int(j), y)
        if change is not None and change < 0.0 and (best is None or change < best[0]):
            best = (change, int(j), y)
    return None if best is None else best[1:]


def _nearest_on_segment(p: np.ndarray, a: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The point of segment a-c nearest p."""
    u = c - a
    uu = float(u @ u)
    t = 0.0 if uu == 0.0 else min(1.0, max(0.0, float((p - a) @ u) / uu))
    return a + t * u


def _regraft_change(model, state, weight, x: int, j: int, y: np.ndarray) -> float | None:
    """The change of C_v + C_w + (A_o/A_wv) C_o when node x leaves its bifurcation b (its
    sibling s taking b's place) and joins segment j at y through b, from the segments whose
    ends or terminal counts change; None when the inlet counts forbid it."""
    per_metre, per_traversal = weight
    parent, pos, count = state.parent, state.position, state.n_downstream
    b, s, moved = parent[x], _sibling(state, x), count[x]
    g, pj = parent[b], parent[j]
    delta: dict[int, int] = {}
    a = g
    while a >= 0:  # x's old path loses its terminals ...
        delta[a] = delta.get(a, 0) - moved
        root_old, a = a, parent[a]
    a = pj
    while a >= 0:  # ... its new path gains them (s standing where b was)
        delta[a] = delta.get(a, 0) + moved
        root_new, a = a, (g if a == s else parent[a])
    if not _keeps_counts(model, count, root_old, root_new, moved):
        return None

    def cost(m: int, p0: np.ndarray, p1: np.ndarray, traversal: float | None = None) -> float:
        c = per_metre[m] * float(np.linalg.norm(p0 - p1))
        if per_traversal[m] > 0.0:
            c += per_traversal[m] * (segment_exclusion(model, p0, p1) if traversal is None else traversal)
        return c

    def old(a: int) -> float:
        return cost(count[a], pos[a], pos[parent[a]], state.seg_exclusion[a])

    m_s, m_j = count[s] + delta.get(s, 0), count[j] + delta.get(j, 0)
    change = cost(m_s, pos[s], pos[g]) - old(s) - old(b) - old(x) - old(j)
    change += cost(m_j, pos[j], y) + cost(m_j + moved, y, pos[pj]) + cost(moved, pos[x], y)
    for a, d in delta.items():
        if d and a not in (s, j) and parent[a] >= 0:
            m = count[a] + d
            change += (per_metre[m] - per_metre[count[a]]) * state.seg_length[a]
            change += (per_traversal[m] - per_traversal[count[a]]) * state.seg_exclusion[a]
    return change


def _apply_regraft(model, state, x: int, j: int, y: np.ndarray, k: int, n: int) -> bool:
    """Regraft node x onto segment j at y when the recomputed total (less C_s) drops;
    otherwise leave the state as it was. Returns whether it was applied."""
    current = kernel.scaled_total_without_supply(model, state)
    saved = (state.parent.copy(), state.children.copy(), state.n_downstream.copy(), state.position.copy())
    parent = state.parent.copy()
    b = parent[x]
    parent[_sibling(state, x)] = parent[b]
    parent[b] = parent[j]
    parent[j] = b
    state.parent[:] = parent
    state.children[:] = children_from_parent(parent)
    state.n_downstream[:] = count_terminals(parent, n, k)
    state.position[b] = y
    kernel.initialise(model, state)
    if kernel.scaled_total_without_supply(model, state) < current:
        return True
    state.parent[:], state.children[:], state.n_downstream[:], state.position[:] = saved
    kernel.initialise(model, state)
    return False


def _keeps_inlet_bounds(model, n_downstream: np.ndarray, inlet: np.ndarray, a: int, b: int) -> bool:
    """Whether swapping a and b (in different inlet trees) keeps every inlet's terminal count
    as ``tissue.inlet_share`` asks: exactly, or within ``inlet_share_tolerance``'s bounds."""
    return _keeps_counts(model, n_downstream, inlet[a], inlet[b], n_downstream[a] - n_downstream[b])


def _keeps_counts(model, n_downstream: np.ndarray, ia: int, ib: int, moved: int) -> bool:
    """Whether ``moved`` terminals from inlet ia's tree to inlet ib's keep the inlet counts."""
    if moved == 0 or ia == ib:
        return True
    if model.fixed_inlet_counts:
        return False
    bounds = model.inlet_count_bounds
    if bounds.shape[0] == 0:
        return True
    new_a, new_b = n_downstream[ia] - moved, n_downstream[ib] + moved
    return bool(bounds[ia, 0] <= new_a <= bounds[ia, 1] and bounds[ib, 0] <= new_b <= bounds[ib, 1])


def _ancestors(parent: np.ndarray, i: int) -> set[int]:
    out = set()
    x = parent[i]
    while x >= 0:
        out.add(int(x))
        x = parent[x]
    return out
