"""``tissue.inlet_share``: the terminals of every inlet fixed (issue 13: the free split can abandon an artery)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_running_equals_full, make_problem

from vasc_pipeline import engine
from vasc_pipeline.config import ConfigError
from vasc_pipeline.topology import inlet_of
from vasc_pipeline.tree import TreeError, inlet_counts


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
