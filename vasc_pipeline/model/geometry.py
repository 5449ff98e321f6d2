"""Optimal bifurcation positions for a fixed topology (a weighted Steiner problem).

For a fixed topology the radii and flows are fixed (they depend on the downstream terminal
counts only), so the vascular cost is a weighted sum of segment lengths,

    C_v + C_w = sum_i w(n_i) L_i,   w(n) = volume[n] + power[n]   [W m^-1],

a weighted Steiner (Fermat-Weber) problem in the free (bifurcation) positions with the
inlets and terminals fixed. Each term is a norm of an affine function of the positions, so
the cost is convex (the paper's appendix); it is smooth except where a segment has zero
length, and such degenerate optima (a bifurcation collapsed onto its parent, a child or a
terminal) are common.

:func:`optimal_bifurcations` finds the minimiser in three stages: a few Weiszfeld-type
iterations (Smith's global form: every iteration solves the weighted Laplacian system of
all bifurcations at once; a majorise-minimise step, so it is a safe start from any
geometry), then Newton's method on the smooth problem in which the zero-length segments
are contracted (nodes joined by them move as one "cluster"), and an optimality check of
every contracted segment: a segment may stay at zero length only while the net pull of
the rest of the tree on the side that would move is no larger than its weight (the
subgradient condition). Violated segments are reopened and Newton resumes; segments that
Newton drives to zero length are contracted, and so, once a line search shows a kink, is
every segment shorter than ``KINK_LENGTH`` of the fixed nodes' extent. The Newton systems are tree-structured and
are factorised in children-first order, which creates no fill-in, so each is O(N).

:mod:`vasc_pipeline.engine.polish` applies the optimum to an annealed state (the polish);
:mod:`vasc_pipeline.model.topology_search` applies it to every topology of a small
fixed-terminal instance for the global optimum that the tests compare against. The contracted
problem (clusters, the smooth objective and its Newton systems) is :mod:`vasc_pipeline.model.contraction`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .contraction import Contraction, gradient_hessian, node_levels, objective, solve_spd, spread
from .physics import Physics, cost_tables
from .topology import node_depth, segment_lengths
from .tree import KIND_BIFURCATION, Tree

__all__ = [
    "BifurcationOptimum",
    "vascular_weights",
    "vascular_cost",
    "optimal_bifurcations",
]


@dataclass
class BifurcationOptimum:
    """Result of :func:`optimal_bifurcations`.

    Attributes
    ----------
    position : float64 (2N, 3)
        Node positions [m]: inlets and terminals as given, bifurcations at the optimum.
    cost : float
        Vascular cost sum_i w_i L_i at ``position`` [W].
    collapsed : bool (2N,)
        Segments of zero length at the optimum (False at inlets).
    converged : bool
        Newton converged and every zero-length segment passed the optimality check.
    iterations : int
        Weiszfeld plus Newton iterations.
    """

    position: np.ndarray
    cost: float
    collapsed: np.ndarray
    converged: bool
    iterations: int


def vascular_weights(tree: Tree, physics: Physics) -> np.ndarray:
    """float64 (2N,): w = volume + power cost per unit length of each node's segment [W m^-1], 0 at inlets."""
    tables = cost_tables(physics)
    w = tables.volume[tree.n_downstream] + tables.power[tree.n_downstream]
    w[tree.parent < 0] = 0.0
    return w


def vascular_cost(position: np.ndarray, parent: np.ndarray, weights: np.ndarray) -> float:
    """sum_i w_i |x_i - x_parent(i)| over segments [W]."""
    seg = parent >= 0
    return float(np.sum(weights[seg] * segment_lengths(parent, position)[seg]))


# --------------------------------------------------------------------------------------
# Stages


def _weiszfeld(x, parent, w, free, depth, scale, iterations):
    """Smith's global Weiszfeld iteration: solve sum_j w_ij / L_ij (x_i - x_j) = 0 for all free i."""
    m = parent.size
    var = np.full(m, -1, dtype=np.int64)
    order = np.flatnonzero(free)
    order = order[np.argsort(-depth[order], kind="stable")]
    var[order] = np.arange(order.size)
    seg = np.flatnonzero(parent >= 0)
    i, j = seg, parent[seg]
    vi, vj = var[i], var[j]
    floor = 1e-14 * scale
    cost = np.inf
    for it in range(iterations):
        length = np.linalg.norm(x[i] - x[j], axis=1)
        new_cost = float(np.sum(w[seg] * length))
        if new_cost > cost * (1.0 - 1e-4):  # slow (linear) from here on: Newton takes over
            return x, it
        cost = new_cost
        a = w[seg] / np.maximum(length, floor)
        fi, fj = vi >= 0, vj >= 0
        both = fi & fj
        n = order.size
        diag = np.bincount(vi[fi], a[fi], n) + np.bincount(vj[fj], a[fj], n)
        lap = sp.csc_matrix(
            (
                np.concatenate([diag, -a[both], -a[both]]),
                (
                    np.concatenate([np.arange(n), vi[both], vj[both]]),
                    np.concatenate([np.arange(n), vj[both], vi[both]]),
                ),
            ),
            shape=(n, n),
        )
        rhs = np.zeros((n, x.shape[1]))
        np.add.at(rhs, vi[fi & ~fj], a[fi & ~fj, None] * x[j[fi & ~fj]])
        np.add.at(rhs, vj[fj & ~fi], a[fj & ~fi, None] * x[i[fj & ~fi]])
        lu = spla.splu(lap, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
        x[order] = lu.solve(rhs)
    return x, iterations


# Near a kink the damped Newton steps shrink to ~2^-26 and make no progress (measured on
# annealed hearts: 20 such iterations of ~27 line-search trials each, then one segment
# contracted, hundreds of times over). A step cut below KINK_STEP already shows the kink,
# and contracting every segment under KINK_LENGTH x the fixed nodes' extent at once (the
# optimality check reopens wrong ones) reaches the same optimum to the last digit in a
# fraction of the rounds: N = 1000 0.7 s instead of 12 s, N = 6000 7 s instead of 230 s.
# KINK_LENGTH = 1e-2 left 5 of 18 small annealed trees unconverged; 1e-4 and 1e-3 converged
# on all of them and on the N = 200 to 6000 hearts.
KINK_STEP = 1e-3
KINK_LENGTH = 1e-4


def _newton(x, con, w, dim, scale, collapse_tol, max_iter, reopened, stall=20):
    """Damped Newton on the contracted objective. Returns (x, iterations, segments to contract).

    On a smooth problem Newton converges in a few iterations from the Weiszfeld start. A
    segment heading for zero length (a kink of the objective) is approached only
    linearly, and once it is short its w/L curvature spoils the Newton direction: then
    the line search cuts the step below ``KINK_STEP`` or ``stall`` iterations pass without
    convergence, and the segments touching a free cluster that are shorter than
    ``KINK_LENGTH * scale`` (at least the shortest one) are returned for contraction (the
    caller's optimality check reopens any that the optimum does not keep). Segments in
    ``reopened`` (bool, per node) were reopened by that check: they are contracted only as
    the shortest, since a short segment the optimum keeps would otherwise be contracted
    and reopened round after round.
    """
    movable = (con.var[con.a] >= 0) | (con.var[con.b] >= 0)  # two fixed nodes may never merge

    def short_segments():
        seg = con.seg[movable]
        length = np.linalg.norm(x[con.a] - x[con.b], axis=1)[movable]
        return seg[((length <= KINK_LENGTH * scale) & ~reopened[seg]) | (length == length.min())]

    def degenerate(length):
        # A segment of no measurable length has no direction (its w/L curvature is
        # infinite): contract it, whatever its history.
        return (length <= 1e-14 * scale) & movable

    if con.free.size == 0:
        return x, 0, None
    contract = degenerate(np.linalg.norm(x[con.a] - x[con.b], axis=1))
    if np.any(contract):
        return x, 0, con.seg[contract]
    f = objective(x, con, w)
    for it in range(max_iter):
        if it >= stall:
            return x, it, short_segments()
        g, hess = gradient_hessian(x, con, w, dim)
        step = solve_spd(hess, -g, scale)
        slope = float(g @ step)
        if -slope <= 1e-15 * f:  # Newton decrement: the remaining decrease is below rounding
            return x, it, None
        step = step.reshape(-1, dim)
        t = 1.0
        while True:
            trial = x.copy()
            trial[con.free] += t * step
            f_trial = objective(trial, con, w)
            if f_trial <= f + 1e-4 * t * slope:
                break
            t *= 0.5
            if t < KINK_STEP:  # a kink is within reach: short segments spoil the direction
                return x, it, short_segments()
        x, f = trial, f_trial
        length = np.linalg.norm(x[con.a] - x[con.b], axis=1)
        contract = degenerate(length) | ((length < collapse_tol * scale) & movable & ~reopened[con.seg])
        if np.any(contract):
            return x, it + 1, con.seg[contract]
    return x, max_iter, None


def _push_off(x, side, unit, con, w, cost, push, scale):
    """Move the nodes in ``side`` along ``unit`` as far as the cost keeps dropping.

    A crude line search on a convex function: from ``push``, halve until the cost drops
    (down to ~1e-6 of ``push``, where the drop is below rounding), then double while it
    keeps dropping (up to ``scale``). Returns the new positions and their cost.
    """

    def pushed(by):
        trial = x.copy()
        trial[side] += by * unit
        return trial, objective(trial, con, w)

    for _ in range(20):
        best, best_cost = pushed(push)
        if best_cost < cost:
            break
        push *= 0.5
    else:
        return best, best_cost  # no measurable drop: a push this small is harmless
    while push < scale:
        push *= 2.0
        trial, trial_cost = pushed(push)
        if trial_cost >= best_cost:
            break
        best, best_cost = trial, trial_cost
    return best, best_cost


def _side_forces(x, parent, w, levels, con):
    """Net external pull on the movable side of every collapsed segment, and its weight.

    For a collapsed segment i, the side that may split off is the part of its cluster
    that holds no fixed node. Splitting that side off by a small distance along the pull
    lowers the cost iff |pull| > w_i.
    """
    m = parent.size
    dim = x.shape[1]
    ext = np.zeros((m, dim))
    d = x[con.b] - x[con.a]
    length = np.linalg.norm(d, axis=1)
    pull = w[con.seg, None] * d / length[:, None]
    np.add.at(ext, con.a, pull)
    np.add.at(ext, parent[con.seg], -pull)
    below = ext.copy()
    has_fixed = con.fixed_node.astype(np.float64)
    for lev in levels[:0:-1]:  # children first
        c = lev[con.collapsed[lev]]
        np.add.at(below, parent[c], below[c])
        np.add.at(has_fixed, parent[c], has_fixed[c])
    idx = np.flatnonzero(con.collapsed)
    total = below[con.top[idx]]
    force = np.where((has_fixed[idx] > 0)[:, None], total - below[idx], below[idx])
    return idx, force, has_fixed[idx] > 0


def optimal_bifurcations(
    tree: Tree,
    weights: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    *,
    collapse_tol: float = 1e-10,
    max_newton: int = 400,
    max_rounds: int = 1000,
) -> BifurcationOptimum:
    """Bifurcation positions minimising sum_i w_i L_i for the tree's fixed topology.

    Parameters
    ----------
    tree : Tree
        Topology and current positions [m]; inlets and terminals stay where they are, the
        current bifurcation positions are the starting point.
    weights : float64 (2N,)
        Cost per unit length of each node's segment [W m^-1] (see :func:`vascular_weights`).
    bounds : (lo, hi) float64 (3,), optional
        The grid's box [m]. The optimum lies in the convex hull of the fixed nodes, so this
        only clips rounding; a 2-D tissue's plane (lo[2] == hi[2]) is kept exactly.
    collapse_tol : float
        Segments shorter than this times the extent of the fixed nodes are contracted
        (then kept only if the optimality check passes); at a kink, those shorter than
        ``KINK_LENGTH`` times it as well.

    Returns
    -------
    BifurcationOptimum

    Examples
    --------
    >>> res = optimal_bifurcations(tree, vascular_weights(tree, physics), tissue.bounds)  # doctest: +SKIP
    >>> res.cost <= vascular_cost(tree.position, tree.parent, vascular_weights(tree, physics))  # doctest: +SKIP
    True
    """
    parent = tree.parent
    w = np.asarray(weights, dtype=np.float64)
    m = parent.size
    fixed = tree.kind != KIND_BIFURCATION
    free = ~fixed
    centre, basis, scale = _affine_frame(tree.position[fixed])
    x = (tree.position - centre) @ basis.T
    iterations = 0
    converged = True
    if basis.shape[0] > 0 and np.any(free):
        x, iterations, converged = _solve(x, tree, w, scale, collapse_tol, max_newton, max_rounds)
    position = tree.position.copy()
    position[free] = centre + x[free] @ basis
    if bounds is not None:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
        position[free] = np.clip(position[free], lo, hi)
    seg = parent >= 0
    final = np.zeros(m, dtype=bool)
    final[seg] = segment_lengths(parent, position)[seg] <= collapse_tol * scale
    return BifurcationOptimum(position, vascular_cost(position, parent, w), final, converged, iterations)


def _affine_frame(p_fixed: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(centre, basis (dim, 3), scale) of the affine hull of the fixed nodes.

    The solver works in it: the optimum lies in the fixed nodes' convex hull, and dropping the
    flat directions (a 2-D tissue's z) keeps the Newton systems regular.
    """
    centre = p_fixed.mean(axis=0)
    _, sv, vt = np.linalg.svd(p_fixed - centre, full_matrices=False)
    scale = float(np.max(np.linalg.norm(p_fixed - centre, axis=1))) or 1.0
    basis = vt[sv > 1e-12 * max(float(sv[0]), 1e-300)]
    return centre, basis, scale


def _solve(x, tree: Tree, w, scale, collapse_tol, max_newton, max_rounds) -> tuple[np.ndarray, int, bool]:
    """The three stages (module docstring) from positions ``x`` in the affine frame:
    Weiszfeld, then rounds of Newton on the contracted problem and the optimality check.
    Returns (x, iterations, converged)."""
    parent = tree.parent
    fixed = tree.kind != KIND_BIFURCATION
    levels = node_levels(tree.children, np.flatnonzero(parent < 0))
    depth = node_depth(parent)
    dim = x.shape[1]
    reopened = np.zeros(parent.size, dtype=bool)
    x, iterations = _weiszfeld(x, parent, w, ~fixed, depth, scale, 30)
    seg = parent >= 0
    length = segment_lengths(parent, x)
    collapsed = _admissible(seg & (length < collapse_tol * scale), parent, levels, depth, fixed)
    for _ in range(max_rounds):
        con = Contraction(parent, levels, depth, fixed, collapsed)
        spread(x, con)
        x, its, short = _newton(x, con, w, dim, scale, collapse_tol, max_newton, reopened)
        spread(x, con)  # Newton moves only the clusters' top nodes
        iterations += its
        if short is not None:
            candidate = collapsed.copy()
            candidate[short] = True
            collapsed = _admissible(candidate, parent, levels, depth, fixed)
            continue
        idx, force, _ = _side_forces(x, parent, w, levels, con)
        if idx.size == 0:
            return x, iterations, its < max_newton
        excess = np.linalg.norm(force, axis=1) - w[idx]
        bad = excess > 1e-9 * w[idx]
        if not np.any(bad):
            return x, iterations, its < max_newton
        topology = (parent, levels, depth, fixed)
        x = _reopen(x, idx[bad], force[bad], excess[bad], con, collapsed, reopened, topology, w, scale)
    return x, iterations, False


def _reopen(x, idx, force, excess, con, collapsed, reopened, topology, w, scale) -> np.ndarray:
    """Reopen the worst violated segment of each cluster (``collapsed`` and ``reopened`` in place);
    push its movable side off along the pull so Newton starts on the side where the segment has length.

    A push of fixed length can overshoot a node closer than it (terminals a hair apart), or leave
    the reopened segment the shortest (collinear nodes, where Newton has no curvature to go on):
    either way the next round contracts a segment the check then reopens, round after round.
    Hence the line search (:func:`_push_off`).
    """
    parent, levels, depth, fixed = topology
    order = np.argsort(-excess)
    cand, dirs = idx[order], force[order]
    _, first = np.unique(con.top[cand], return_index=True)
    cand, dirs = cand[first], dirs[first]
    collapsed[cand] = False
    reopened[cand] = True
    split = Contraction(parent, levels, depth, fixed, collapsed)
    cost = objective(x, split, w)
    for i, f in zip(cand, dirs):
        # The side without a fixed node is the one the pull acts on.
        side = split.top == (i if split.n_fixed[i] == 0 else split.top[parent[i]])
        unit = f / np.linalg.norm(f)
        x, cost = _push_off(x, side, unit, split, w, cost, 1e-7 * scale, scale)
    return x


def _admissible(collapsed, parent, levels, depth, fixed):
    """Drop collapsed segments that would join two fixed nodes into one cluster."""
    collapsed = collapsed.copy()
    while True:
        con = Contraction(parent, levels, depth, fixed, collapsed)
        bad = con.n_fixed[con.top] > 1
        if not np.any(bad & collapsed):
            return collapsed
        # Reopen the collapsed segments of over-fixed clusters nearest their tops first.
        cand = np.flatnonzero(bad & collapsed)
        collapsed[cand[np.argmin(depth[cand])]] = False
