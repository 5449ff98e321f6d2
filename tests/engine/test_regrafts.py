"""The prune-and-regraft descent at the end of a run, and the start temperature's floor."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_running_equals_full, make_problem

from vasc_pipeline import engine, kernel
from vasc_pipeline.engine import polish as finish
from vasc_pipeline.model import costs
from vasc_pipeline.model.topology import inlet_of
from vasc_pipeline.model.tree import Tree, children_from_parent, count_terminals

PHYSIOLOGICAL_HEART = ("model=physiological", "tissue=heart", "n_terminals=60")


def _hot_state(*overrides, steps=20_000, seed=0):
    """A state part-way through an anneal: far from any local optimum, full of strays."""
    problem = make_problem(*overrides, "anneal=paper", "anneal.steps=1000000")
    state = engine.initial_state(problem, seed=seed)
    engine.run_block(problem, state, steps)
    kernel.initialise(problem.model, state)
    return problem, state


def _regrafted(problem, state, x: int, j: int, y: np.ndarray) -> Tree:
    """The tree with node x moved, through its own bifurcation placed at y, onto segment j."""
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    parent, position = state.parent.copy(), state.position.copy()
    b = parent[x]
    (sibling,) = [c for c in np.flatnonzero(parent == b) if c != x]
    parent[sibling], parent[b], parent[j] = parent[b], parent[j], b
    position[b] = y
    return Tree(parent, children_from_parent(parent), position, count_terminals(parent, n, k), k)


def _annealed_without_supply(problem, tree: Tree) -> float:
    full = costs.full_costs(tree, problem.tissue, problem.physics, problem.terms)
    return full["volume"] + full["power"] + problem.physics.weights[0] * full["exclusion"]


def test_the_estimated_change_of_a_regraft_is_the_recomputed_one():
    """Every case the estimate distinguishes (j in the sibling's subtree, j on the old path,
    across the inlets, large vessels paying the exclusion term) against the NumPy reference."""
    problem, state = _hot_state(*PHYSIOLOGICAL_HEART)
    weight = finish._regraft_weights(problem)
    before = _annealed_without_supply(problem, engine.tree_of(problem, state))
    rng = np.random.default_rng(0)
    k = problem.physics.n_inlets
    inlet = inlet_of(state.parent)
    checked = crossing = 0
    for _ in range(400):
        x, j = (int(v) for v in rng.integers(k, state.parent.size, 2))
        b = state.parent[x]
        if b < k or j in (x, b, finish._sibling(state, x)) or x in finish._ancestors(state.parent, j):
            continue
        y = finish._nearest_on_segment(state.position[x], state.position[j], state.position[state.parent[j]])
        change = finish._regraft_change(problem.model, state, weight, x, j, y)
        if change is None:
            continue  # the inlet band forbids it
        after = _annealed_without_supply(problem, _regrafted(problem, state, x, j, y))
        assert change == pytest.approx(after - before, rel=1e-7, abs=1e-12 * abs(before))
        checked += 1
        crossing += inlet[x] != inlet[j]
    assert checked > 100 and crossing > 10


def test_descend_regrafts_only_lowers_the_cost_and_keeps_terminals_and_inlet_band():
    problem, state = _hot_state(*PHYSIOLOGICAL_HEART)
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    terminals = state.position[k : k + n].copy()
    rng, counters = state.rng.copy(), state.counters.copy()
    before = kernel.scaled_total_without_supply(problem.model, state)
    applied = finish.descend_regrafts(problem, state)
    assert applied > 0  # a hot state is full of strays
    assert kernel.scaled_total_without_supply(problem.model, state) < before
    assert_running_equals_full(problem, state)  # a valid tree, and every cache rebuilt
    np.testing.assert_array_equal(state.position[k : k + n], terminals)
    np.testing.assert_array_equal(state.rng, rng)
    np.testing.assert_array_equal(state.counters, counters)
    lo, hi = problem.model.inlet_count_bounds.T
    assert np.all((lo <= state.n_downstream[:k]) & (state.n_downstream[:k] <= hi))
    assert finish.descend_regrafts(problem, state) == 0  # a local minimum under single regrafts


def test_a_fixed_split_keeps_every_inlet_count():
    problem, state = _hot_state("tissue=heart", "n_terminals=40", "tissue.inlet_share=[0.62,0.38]")
    counts = state.n_downstream[: problem.physics.n_inlets].copy()
    assert finish.descend_regrafts(problem, state) > 0
    np.testing.assert_array_equal(state.n_downstream[: problem.physics.n_inlets], counts)


def test_finish_reports_the_regrafts_and_the_physiological_model_asks_for_them():
    problem, state = _hot_state(*PHYSIOLOGICAL_HEART, "anneal.polish=true", "anneal.polish_regrafts=true")
    report = engine.finish(problem, state)
    assert report["polish"]["regrafts"] > 0
    assert report["polish"]["vascular_after"] < report["polish"]["vascular_before"]
    assert make_problem(*PHYSIOLOGICAL_HEART).config.anneal.polish_regrafts
    assert not make_problem("tissue=heart", "n_terminals=60").config.anneal.polish_regrafts  # the paper's


def test_the_start_temperature_is_raised_to_its_floor_and_only_raised():
    problem = make_problem("tissue=heart", "n_terminals=60")
    state = engine.initial_state(problem, seed=0)
    calibrated, t_end = engine.calibrate_schedule(problem, state)
    for floor, expected in ((10.0 * calibrated, 10.0 * calibrated), (0.1 * calibrated, calibrated)):
        raised = make_problem("tissue=heart", "n_terminals=60", f"anneal.T_start_min={floor}")
        assert engine.calibrate_schedule(raised, state) == (pytest.approx(expected, rel=1e-12), t_end)
    assert make_problem(*PHYSIOLOGICAL_HEART).config.anneal.T_start_min == 100.0


def test_a_tree_with_fewer_nodes_than_neighbours_is_searched_whole():
    problem, state = _hot_state("model=physiological", "tissue=heart", "n_terminals=4", steps=2_000)
    before = kernel.scaled_total_without_supply(problem.model, state)
    finish.descend_regrafts(problem, state, neighbours=8)  # 6 non-inlet nodes
    assert kernel.scaled_total_without_supply(problem.model, state) <= before
    assert_running_equals_full(problem, state)
