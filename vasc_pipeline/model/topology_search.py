"""Exhaustive topology search on small instances: the global optimum the tests compare against.

Every rooted binary topology on a few fixed terminals (:func:`topologies`), each with its
bifurcations at the optimum of :func:`vasc_pipeline.model.geometry.optimal_bifurcations`; the
best of them is the global minimum of C_v + C_w (:func:`best_topology`). Pure geometry;
the count of topologies, (2n - 3)!!, keeps it to small n.
"""

from __future__ import annotations

import numpy as np

from .geometry import optimal_bifurcations, vascular_weights
from .physics import Physics
from .tree import Tree, children_from_parent, count_terminals

__all__ = ["topologies", "best_topology"]


def topologies(n_terminals: int):
    """Yield the parent array (2n,) of every rooted binary tree on n labelled terminals.

    Layout as :class:`~vasc_pipeline.model.tree.Tree` with one inlet: inlet 0, terminals 1..n,
    bifurcations n+1..2n-1. Terminal k is inserted into every segment of each tree on the
    first k - 1 terminals, giving (2n - 3)!! trees (15, 105, 945 for n = 4, 5, 6).
    """
    if n_terminals < 2:
        raise ValueError(f"n_terminals must be >= 2, got {n_terminals}")
    m = 2 * n_terminals

    def grow(parent, k, next_bif):
        if k > n_terminals:
            yield parent.copy()
            return
        for seg in [i for i in range(1, m) if parent[i] >= 0]:
            p = parent[seg]
            parent[next_bif] = p
            parent[seg] = next_bif
            parent[k] = next_bif
            yield from grow(parent, k + 1, next_bif + 1)
            parent[seg] = p
            parent[k] = -1
            parent[next_bif] = -1

    parent = np.full(m, -1, dtype=np.int64)
    parent[1] = 0
    yield from grow(parent, 2, n_terminals + 1)


def best_topology(
    inlet: np.ndarray, terminals: np.ndarray, physics: Physics, bounds: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[float, Tree, list[float]]:
    """The global minimum of C_v + C_w over every topology on fixed terminals, one inlet.

    Parameters
    ----------
    inlet : float64 (3,) [m]
    terminals : float64 (n, 3) [m]
    physics : Physics
        Gives the per-length weights (n_terminals must equal n, one inlet).

    Returns
    -------
    (cost [W], optimal Tree, the optimal cost of every topology in enumeration order)
    """
    terminals = np.atleast_2d(np.asarray(terminals, dtype=np.float64))
    n = len(terminals)
    if physics.n_terminals != n or physics.n_inlets != 1:
        raise ValueError(f"physics must describe {n} terminals and one inlet")
    best, best_tree, costs = np.inf, None, []
    for parent in topologies(n):
        position = np.zeros((2 * n, 3))
        position[0] = inlet
        position[1 : n + 1] = terminals
        tree = Tree(parent, children_from_parent(parent), position, count_terminals(parent, n, 1), 1)
        _place_from_children(tree)
        res = optimal_bifurcations(tree, vascular_weights(tree, physics), bounds)
        costs.append(res.cost)
        if res.cost < best:
            best, best_tree = res.cost, Tree(tree.parent, tree.children, res.position, tree.n_downstream, 1)
    return best, best_tree, costs


def _place_from_children(tree: Tree) -> None:
    """Start each bifurcation at the mean of its terminals (a point inside their hull)."""
    k, n = tree.n_inlets, tree.n_terminals
    sums = np.zeros((tree.n_nodes, 3))
    for t in range(k, k + n):
        node = tree.parent[t]
        while node >= k + n:
            sums[node] += tree.position[t]
            node = tree.parent[node]
    bif = np.arange(k + n, tree.n_nodes)
    tree.position[bif] = sums[bif] / tree.n_downstream[bif, None]
