"""geometry: optimal bifurcations of a fixed topology, polish, topology enumeration, swap descent."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import FAST_2026_12, assert_running_equals_full, make_problem, random_topology
from scipy.optimize import minimize

from vasc_pipeline import engine, kernel
from vasc_pipeline.engine import polish as finish
from vasc_pipeline.model import geometry, topology_search
from vasc_pipeline.model.tree import KIND_BIFURCATION, Tree, children_from_parent, count_terminals

# --------------------------------------------------------------------------------------
# Helpers


def _physics(n, ndim):
    """Real physics of n terminals (one inlet): plane2d (gamma 3) in 2-D, sphere (gamma 3 default) in 3-D."""
    return make_problem("tissue=plane2d" if ndim == 2 else "tissue=sphere", f"n_terminals={n}").physics


def _tree(parent, position):
    n = parent.size // 2
    return Tree(
        parent, children_from_parent(parent), np.array(position, dtype=np.float64), count_terminals(parent, n, 1), 1
    )


def _random_instance(n, ndim, rng):
    """A random tree: inlet and terminals uniform in a 5 cm box (z = 0 in 2-D), bifurcations anywhere in it."""
    position = rng.uniform(0.0, 0.05, (2 * n, 3))
    if ndim == 2:
        position[:, 2] = 0.0
    return _tree(random_topology(n, rng), position)


def _clustered_instance(n, ndim, rng):
    """A tree whose topology joins the nearest pair of subtrees first (few zero-length segments)."""
    tree = _random_instance(n, ndim, rng)
    parent = np.full(2 * n, -1, dtype=np.int64)
    centre = {t: tree.position[t].copy() for t in range(1, n + 1)}
    nxt = n + 1
    while len(centre) > 1:
        keys = list(centre)
        a, b = min(
            ((a, b) for i, a in enumerate(keys) for b in keys[i + 1 :]),
            key=lambda ab: np.linalg.norm(centre[ab[0]] - centre[ab[1]]),
        )
        parent[a] = parent[b] = nxt
        centre[nxt] = 0.5 * (centre.pop(a) + centre.pop(b))
        nxt += 1
    parent[nxt - 1] = 0
    return _tree(parent, tree.position)


def _scipy_optimum(tree, weights, rng, starts=4):
    """Independent optimum of sum_i w_i L_i over the bifurcation positions (scipy, several random starts).

    The cost has kinks where a segment has zero length, so L-BFGS-B minimises the smoothed
    sum w sqrt(L^2 + eps^2) with eps -> 1e-11 of the extent (continuation); the smoothing
    changes the cost by at most sum w eps. Returns the best true cost found and its positions.
    """
    parent = tree.parent
    free = np.flatnonzero(tree.kind == KIND_BIFURCATION)
    fixed = np.flatnonzero(tree.kind != KIND_BIFURCATION)
    ndim = 2 if np.all(tree.position[:, 2] == 0.0) else 3
    lo, hi = tree.position[fixed].min(axis=0), tree.position[fixed].max(axis=0)
    scale = float(np.max(hi - lo))
    wn = weights / weights.max()
    seg = np.flatnonzero(parent >= 0)
    base = tree.position[:, :ndim] / scale

    def unpack(v):
        x = base.copy()
        x[free] = v.reshape(-1, ndim)
        return x

    def smooth(v, eps):
        x = unpack(v)
        d = x[seg] - x[parent[seg]]
        r = np.sqrt(np.einsum("ij,ij->i", d, d) + eps * eps)
        g_nodes = np.zeros_like(x)
        pull = (wn[seg] / r)[:, None] * d
        np.add.at(g_nodes, seg, pull)
        np.add.at(g_nodes, parent[seg], -pull)
        return float(np.sum(wn[seg] * r)), g_nodes[free].ravel()

    best_cost, best_pos = np.inf, None
    for _ in range(starts):
        v = rng.uniform(lo[:ndim] / scale, hi[:ndim] / scale, (free.size, ndim)).ravel()
        for eps in (1e-2, 1e-4, 1e-6, 1e-8, 1e-11):
            v = minimize(
                smooth,
                v,
                args=(eps,),
                jac=True,
                method="L-BFGS-B",
                options={"ftol": 1e-16, "gtol": 1e-13, "maxiter": 20000, "maxcor": 30},
            ).x
        position = tree.position.copy()
        position[free, :ndim] = unpack(v)[free] * scale
        c = geometry.vascular_cost(position, parent, weights)
        if c < best_cost:
            best_cost, best_pos = c, position
    return best_cost, best_pos


def _assert_matches_scipy(tree, weights, res, rng):
    fixed = tree.kind != KIND_BIFURCATION
    # Inlets and terminals are not moved, and the reported cost is the cost of the reported positions.
    np.testing.assert_array_equal(res.position[fixed], tree.position[fixed])
    assert res.cost == pytest.approx(geometry.vascular_cost(res.position, tree.parent, weights), rel=1e-14)
    assert res.converged
    ref, _ = _scipy_optimum(tree, weights, rng)
    # scipy is the independent bound; at a kink (a segment of zero length) it stops short of
    # the optimum by up to ~1e-5, so it bounds from above and must only be close.
    assert res.cost <= ref * (1.0 + 1e-9)
    assert res.cost >= ref * (1.0 - 1e-3)
    return ref


def _unit_pull_sums(position, parent, weights, nodes):
    """Net pull sum_seg w_seg u_seg on each node from its segments (unit vectors away from the node)."""
    children = children_from_parent(parent)
    out = []
    for b in nodes:
        f = np.zeros(3)
        for other, w in [(parent[b], weights[b]), *((c, weights[c]) for c in children[b] if c >= 0)]:
            d = position[other] - position[b]
            f += w * d / np.linalg.norm(d)
        out.append(f)
    return np.array(out)


# --------------------------------------------------------------------------------------
# optimal_bifurcations


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("n", [3, 4, 5, 6])
def test_optimal_bifurcations_matches_an_independent_scipy_optimum(n, ndim):
    rng = np.random.default_rng(100 * n + ndim)
    physics = _physics(n, ndim)
    for _ in range(3):
        tree = _random_instance(n, ndim, rng)
        weights = geometry.vascular_weights(tree, physics)
        res = geometry.optimal_bifurcations(tree, weights)
        _assert_matches_scipy(tree, weights, res, rng)
        # The cost is convex: the start must not matter (all bifurcations piled on the inlet).
        piled = tree.copy()
        piled.position[tree.kind == KIND_BIFURCATION] = tree.position[0]
        again = geometry.optimal_bifurcations(piled, weights)
        assert again.cost == pytest.approx(res.cost, rel=1e-9)


@pytest.mark.parametrize("ndim", [2, 3])
def test_the_optimum_balances_the_pulls_on_every_bifurcation_it_keeps_apart(ndim):
    """First-order optimality: at a bifurcation with three segments of non-zero length the
    weighted unit vectors sum to zero (the Fermat-Weber condition behind Murray's angles)."""
    rng = np.random.default_rng(7 + ndim)
    n = 12
    physics = _physics(n, ndim)
    tree = _clustered_instance(n, ndim, rng)
    weights = geometry.vascular_weights(tree, physics)
    res = geometry.optimal_bifurcations(tree, weights)
    assert res.converged
    children = children_from_parent(tree.parent)
    bif = np.flatnonzero(tree.kind == KIND_BIFURCATION)
    apart = [b for b in bif if not res.collapsed[b] and not any(res.collapsed[c] for c in children[b] if c >= 0)]
    assert len(apart) >= 3
    pulls = _unit_pull_sums(res.position, tree.parent, weights, apart)
    scale = weights[apart]  # the parent segment carries the largest weight of the three
    assert np.all(np.linalg.norm(pulls, axis=1) <= 1e-6 * scale)


def test_contracting_at_the_first_sign_of_a_kink_reaches_the_same_optimum_in_far_fewer_iterations(monkeypatch):
    """An annealed heart tree has dozens of segments that are zero at the optimum. The
    solver contracts the short segments as soon as a line search shows a kink (a step below
    KINK_STEP), several at once; against the plain path (one shortest segment after a
    stalled Newton run) it must end at the same optimum, with the same contracted segments."""
    problem = make_problem("tissue=heart", "n_terminals=200", *FAST_2026_12, "anneal.steps=1000000")
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, state, 1_000_000)
    tree = engine.tree_of(problem, state)
    weights = geometry.vascular_weights(tree, problem.physics)
    fast = geometry.optimal_bifurcations(tree, weights, problem.tissue.bounds)
    monkeypatch.setattr(geometry, "KINK_STEP", 1e-12)  # a step must fail outright ...
    monkeypatch.setattr(geometry, "KINK_LENGTH", 0.0)  # ... and only the shortest segment goes
    plain = geometry.optimal_bifurcations(tree, weights, problem.tissue.bounds, max_rounds=100_000)
    assert fast.converged and plain.converged
    assert fast.collapsed.sum() >= 50
    np.testing.assert_array_equal(fast.collapsed, plain.collapsed)
    assert fast.cost == pytest.approx(plain.cost, rel=1e-12)
    # The optimum is flat to within rounding along some directions: positions agree to ~1e-7
    # of the heart's extent (1.5 nm on one coordinate of this tree).
    np.testing.assert_allclose(fast.position, plain.position, rtol=0, atol=1e-8)  # m
    assert fast.iterations * 4 < plain.iterations


@pytest.mark.parametrize("ndim", [2, 3])
@pytest.mark.parametrize("flat", [False, True], ids=["spread", "fixed-nodes-in-a-plane"])
def test_terminals_a_hair_apart_converge_without_contracting_and_reopening_forever(ndim, flat):
    """Terminals in pairs 1e-6 of the extent apart (and, in ``flat``, every fixed node in
    one plane, a line in 2-D): a segment the optimality check reopens must not be contracted
    again at the next kink, nor a zero-length segment break the Newton system. Before that
    was so, a third of such instances crashed (singular factor) or ran to the round cap."""
    physics = _physics(21, ndim)
    for seed in range(6):
        rng = np.random.default_rng(seed)
        tree = _random_instance(21, ndim, rng)
        for k in range(1, 21, 2):
            d = rng.normal(size=3)
            d[2:] = d[2:] if ndim == 3 else 0.0
            tree.position[k + 1] = tree.position[k] + 5e-8 * d / np.linalg.norm(d)  # m, in a 5 cm box
        if flat:
            tree.position[tree.kind != KIND_BIFURCATION, 1] = 0.0
        weights = geometry.vascular_weights(tree, physics)
        res = geometry.optimal_bifurcations(tree, weights)
        assert res.converged and res.iterations < 200
        if seed < 2:
            _assert_matches_scipy(tree, weights, res, rng)


def _two_terminal_tree(inlet, a, b):
    """Inlet 0, terminals 1 and 2, bifurcation 3 (started off the optimum)."""
    parent = np.array([-1, 3, 3, 0])
    position = np.array([inlet, a, b, [0.3e-2, 0.7e-2, 0.0]], dtype=np.float64)
    return _tree(parent, position)


def test_a_terminal_on_the_way_to_its_sibling_becomes_the_branch_point():
    # Collinear inlet, A, B: with Murray weights (w_parent < w_A + w_B) the optimum is at A
    # itself, a kink the solver must contract rather than creep towards.
    a, b = [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]
    tree = _two_terminal_tree([0.0, 0.0, 0.0], a, b)
    weights = geometry.vascular_weights(tree, _physics(2, 2))
    assert weights[3] < weights[1] + weights[2]
    res = geometry.optimal_bifurcations(tree, weights)
    assert res.converged
    np.testing.assert_allclose(res.position[3], a, atol=1e-12)
    assert res.collapsed[1] and not res.collapsed[2] and not res.collapsed[3]
    assert res.cost == pytest.approx(weights[3] * 0.01 + weights[2] * 0.01, rel=1e-12)


def test_collinear_terminals_have_a_piecewise_linear_cost_and_are_still_solved():
    # All fixed nodes on one line: no curvature anywhere, every bifurcation ends on a node.
    rng = np.random.default_rng(5)
    physics = _physics(5, 2)
    for _ in range(3):
        tree = _random_instance(5, 2, rng)
        tree.position[:, 1] = 0.0
        weights = geometry.vascular_weights(tree, physics)
        res = geometry.optimal_bifurcations(tree, weights)
        _assert_matches_scipy(tree, weights, res, rng)


def test_opposite_terminals_branch_at_the_inlet():
    # Equal pulls from terminals on opposite sides cancel: the parent segment has zero length.
    tree = _two_terminal_tree([0.05, 0.05, 0.0], [0.02, 0.05, 0.0], [0.08, 0.05, 0.0])
    weights = geometry.vascular_weights(tree, _physics(2, 2))
    res = geometry.optimal_bifurcations(tree, weights)
    assert res.converged
    np.testing.assert_allclose(res.position[3], tree.position[0], atol=1e-12)
    assert res.collapsed[3] and not res.collapsed[1] and not res.collapsed[2]
    assert res.cost == pytest.approx(weights[1] * 0.03 + weights[2] * 0.03, rel=1e-12)


def test_a_2d_optimum_stays_in_its_plane_and_inside_the_bounds():
    rng = np.random.default_rng(3)
    problem = make_problem("tissue=plane2d", "n_terminals=10")
    tree = _random_instance(10, 2, rng)
    tree.position[tree.kind == KIND_BIFURCATION, 2] = 0.0
    res = geometry.optimal_bifurcations(tree, geometry.vascular_weights(tree, problem.physics), problem.tissue.bounds)
    assert np.all(res.position[:, 2] == 0.0)
    lo, hi = problem.tissue.bounds
    assert np.all(res.position >= lo) and np.all(res.position <= hi)


# --------------------------------------------------------------------------------------
# Topology enumeration


@pytest.mark.parametrize("n, count", [(2, 1), (3, 3), (4, 15), (5, 105), (6, 945)])
def test_topologies_are_every_rooted_binary_tree_once(n, count):
    seen = set()
    for parent in topology_search.topologies(n):
        assert parent[0] == -1 and np.all(parent[1:] >= 0)
        downstream = count_terminals(parent, n, 1)
        assert downstream[0] == n and np.all(downstream[1 : n + 1] == 1)
        children = children_from_parent(parent)
        assert np.all(children[n + 1 :] >= 0)  # every bifurcation has two children
        # A tree is its set of clusters (terminal sets below each bifurcation).
        clusters = frozenset(frozenset(t for t in range(1, n + 1) if _below(parent, t, b)) for b in range(n + 1, 2 * n))
        seen.add(clusters)
    assert len(seen) == count


def _below(parent, node, ancestor):
    while node >= 0:
        if node == ancestor:
            return True
        node = parent[node]
    return False


def test_best_topology_beats_random_topologies_and_matches_its_own_list():
    rng = np.random.default_rng(11)
    problem = make_problem("tissue=plane2d", "n_terminals=5")
    sites = np.c_[rng.uniform(0.01, 0.09, (5, 2)), np.zeros(5)]
    inlet = problem.tissue.inlets[0]
    best, tree, each = topology_search.best_topology(inlet, sites, problem.physics, problem.tissue.bounds)
    assert len(each) == 105 and best == min(each)
    assert geometry.vascular_cost(
        tree.position, tree.parent, geometry.vascular_weights(tree, problem.physics)
    ) == pytest.approx(best, rel=1e-12)
    for _ in range(5):
        position = np.zeros((10, 3))
        position[0], position[1:6] = inlet, sites
        position[6:] = rng.uniform(0.0, 0.1, (4, 3)) * [1, 1, 0]
        other = _tree(random_topology(5, rng), position)
        res = geometry.optimal_bifurcations(other, geometry.vascular_weights(other, problem.physics))
        assert best <= res.cost * (1.0 + 1e-12)


# --------------------------------------------------------------------------------------
# polish and descend_swaps on annealing states


def _hot_state(*overrides, steps=20_000, seed=0):
    """A state part-way through a paper anneal: far from the vascular optimum."""
    problem = make_problem(*overrides, "anneal=paper", "anneal.steps=1000000")
    state = engine.initial_state(problem, seed=seed)
    engine.run_block(problem, state, steps)
    return problem, state


@pytest.mark.parametrize(
    "overrides", [("tissue=plane2d", "n_terminals=30"), ("tissue=heart", "n_terminals=40")], ids=["plane2d", "heart"]
)
def test_polish_never_raises_the_cost_and_leaves_the_topology_and_terminals_alone(overrides):
    problem, state = _hot_state(*overrides)
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    topology = (state.parent.copy(), state.children.copy(), state.n_downstream.copy())
    fixed = state.position[: k + n].copy()
    rng, counters = state.rng.copy(), state.counters.copy()
    report = finish.polish(problem, state)
    before, after = report["before"], report["after"]
    assert after["total"] <= before["total"]
    assert after["volume"] + after["power"] < before["volume"] + before["power"]  # it did something
    assert report["moved"] > 0 and report["applied"] in ("full", "partial")
    for old, new in zip(topology, (state.parent, state.children, state.n_downstream)):
        np.testing.assert_array_equal(old, new)
    np.testing.assert_array_equal(state.position[: k + n], fixed)
    np.testing.assert_array_equal(state.rng, rng)
    np.testing.assert_array_equal(state.counters, counters)
    assert after == assert_running_equals_full(problem, state)
    # A second polish has nothing left to gain.
    again = finish.polish(problem, state)
    assert again["after"]["total"] <= after["total"] * (1.0 + 1e-12)


def test_descend_swaps_only_lowers_the_cost_and_keeps_a_valid_tree():
    problem, state = _hot_state("tissue=plane2d", "n_terminals=7", steps=5_000, seed=3)
    finish.polish(problem, state)
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    fixed = state.position[: k + n].copy()
    before = kernel.scaled_total_without_supply(problem.model, state)
    applied = finish.descend_swaps(problem, state)
    assert_running_equals_full(problem, state)
    assert applied > 0  # a hot state's topology is far from the best
    assert kernel.scaled_total_without_supply(problem.model, state) < before
    np.testing.assert_array_equal(state.position[: k + n], fixed)
    assert finish.descend_swaps(problem, state) == 0  # a local minimum under single swaps
