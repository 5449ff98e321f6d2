"""``tissue.inlet_share`` and ``tissue.inlet_assignment``: which terminals each inlet feeds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import assert_running_equals_full, make_problem

from vasc_pipeline import engine
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.topology import inlet_of
from vasc_pipeline.model.tree import TreeError, inlet_counts, nearest_inlets


def terminals_per_inlet(problem, state) -> list[int]:
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    return np.bincount(inlet_of(state.parent)[k : k + n], minlength=k).tolist()


def test_inlet_counts_round_by_largest_remainder_with_one_terminal_at_least():
    assert inlet_counts([0.62, 0.38], 1000).tolist() == [620, 380]
    assert inlet_counts([0.5, 0.5], 7).tolist() == [4, 3]
    assert inlet_counts([0.999, 0.001], 10).tolist() == [9, 1]  # rounding would give the RCA none
    assert inlet_counts([1 / 3, 1 / 3, 1 / 3], 3).tolist() == [1, 1, 1]
    with pytest.raises(TreeError, match="inlet_share"):
        inlet_counts([0.5, 0.5, 0.0], 10)


@pytest.mark.parametrize("share, expected", [(None, None), ("[0.7,0.3]", [42, 18])])
def test_a_fixed_share_survives_the_anneal_and_a_free_one_moves(share, expected):
    overrides = ["n_terminals=60", "anneal.steps=300000", "anneal.polish=false"]
    problem = make_problem(*overrides, *([f"tissue.inlet_share={share}"] if share else []))
    state = engine.initial_state(problem, 3)
    start = terminals_per_inlet(problem, state)
    assert expected is None or start == expected
    engine.run_block(problem, state, 300_000)
    end = terminals_per_inlet(problem, state)
    if expected is None:
        assert end != start  # swaps between the two inlet trees do move terminals
    else:
        assert end == expected
    assert_running_equals_full(problem, state)


@pytest.mark.parametrize(
    "overrides, error, message",
    [
        (["tissue.inlet_share=[0.7,0.4]"], ConfigError, "summing to 1"),
        (["tissue.inlet_share=[1.2,-0.2]"], ConfigError, "one fraction > 0 per inlet"),
        (["tissue.inlet_share=[0.6,0.4]", "method=cco"], ConfigError, "CCO growth"),
        (["tissue.inlet_share=[0.6,0.4]", "anneal.init=cco"], ConfigError, "CCO growth"),
        (["tissue.inlet_share=[0.5,0.3,0.2]"], TreeError, r"has 2 inlets \(LCA, RCA\)"),
    ],
)
def test_bad_shares_are_refused_naming_the_field(overrides, error, message):
    with pytest.raises(error, match=message):
        make_problem("n_terminals=20", *overrides)


def test_nearest_inlets_by_distance_with_and_without_counts():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [2.9, 0, 0]])
    inlets = np.array([[0.0, 0, 0], [3, 0, 0]])
    assert nearest_inlets(points, inlets).tolist() == [0, 0, 1, 1, 1]
    assert nearest_inlets(points, inlets, np.array([4, 1])).tolist() == [0, 0, 0, 1, 0]  # the 4 least far from inlet 0
    assert nearest_inlets(points, inlets, np.array([1, 4])).tolist() == [0, 1, 1, 1, 1]
    far = np.array([[10.0, 0, 0]])  # nobody's nearest: it still feeds the point nearest to it
    assert nearest_inlets(points, np.vstack([inlets, far])).tolist() == [0, 0, 1, 2, 1]


@pytest.mark.parametrize("share", [None, "[0.62,0.38]"])
def test_nearest_assignment_gives_each_inlet_its_side_of_the_heart(share):
    overrides = [
        "n_terminals=200",
        "tissue.inlet_assignment=nearest",
        *([f"tissue.inlet_share={share}"] if share else []),
    ]
    problem = make_problem(*overrides)
    state = engine.initial_state(problem, 0)
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    owner = inlet_of(state.parent)[k : k + n]
    pos = np.asarray(state.position)[k : k + n]
    inlets = problem.tissue.inlets
    if share:
        assert np.bincount(owner, minlength=k).tolist() == inlet_counts([0.62, 0.38], n).tolist()
    # every terminal of inlet 0 is at least as much nearer to inlet 0 (relative to inlet 1) as any of inlet 1's
    margin = np.linalg.norm(pos - inlets[0], axis=1) - np.linalg.norm(pos - inlets[1], axis=1)
    assert margin[owner == 0].max() <= margin[owner == 1].min()
    # still a pure function of (config, seed); the random assignment draws a different tree
    again = engine.initial_state(problem, 0)
    np.testing.assert_array_equal(again.parent, state.parent)
    random = engine.initial_state(make_problem(*[o for o in overrides if "assignment" not in o]), 0)
    assert not np.array_equal(inlet_of(random.parent)[k : k + n], owner)


def test_an_unknown_inlet_assignment_is_refused_naming_the_field():
    with pytest.raises(ConfigError, match=r"tissue\.inlet_assignment must be one of random, nearest, got 'closest'"):
        make_problem("n_terminals=20", "tissue.inlet_assignment=closest")


def test_a_share_band_keeps_every_inlet_inside_it_and_lets_the_trees_trade_subtrees():
    overrides = ["n_terminals=60", "anneal.steps=300000", "anneal.polish=false", "tissue.inlet_share=[0.5,0.5]"]
    problem = make_problem(*overrides, "tissue.inlet_share_tolerance=0.2")
    assert problem.model.inlet_count_bounds.tolist() == [[18, 42], [18, 42]]
    state = engine.initial_state(problem, 3)
    seen = set()
    for _ in range(30):
        engine.run_block(problem, state, 10_000)
        counts = terminals_per_inlet(problem, state)
        assert all(18 <= c <= 42 for c in counts), counts
        seen.add(tuple(counts))
    assert len(seen) > 1  # subtrees of unequal size do cross between the inlet trees
    assert_running_equals_full(problem, state)


def test_a_band_of_zero_width_is_the_fixed_share_bit_for_bit():
    problem = make_problem("n_terminals=60", "anneal.steps=200000", "tissue.inlet_share=[0.7,0.3]")
    counts = inlet_counts([0.7, 0.3], 60)
    banded = dataclasses.replace(
        problem,
        model=problem.model._replace(fixed_inlet_counts=False, inlet_count_bounds=np.stack([counts, counts], axis=1)),
    )
    fixed_state, banded_state = engine.initial_state(problem, 5), engine.initial_state(banded, 5)
    engine.run_block(problem, fixed_state, 200_000)
    engine.run_block(banded, banded_state, 200_000)
    np.testing.assert_array_equal(fixed_state.parent, banded_state.parent)
    np.testing.assert_array_equal(fixed_state.position, banded_state.position)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["tissue.inlet_share_tolerance=0.1"], "set the share too"),
        (["tissue.inlet_share=[0.6,0.4]", "tissue.inlet_share_tolerance=1.5"], r"must lie in \(0, 1\)"),
        (["tissue.inlet_share=[0.6,0.4]", "tissue.inlet_share_tolerance=0"], r"must lie in \(0, 1\)"),
    ],
)
def test_bad_tolerances_are_refused_naming_the_field(overrides, message):
    with pytest.raises(ConfigError, match=r"tissue.inlet_share_tolerance.*" + message):
        make_problem("n_terminals=20", *overrides)
