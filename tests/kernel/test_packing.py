"""The packing phase (vasc_pipeline.kernel.packing): kernel against its NumPy twin, the end of the
phase, determinism across block splits, checkpoints and a SIGKILL, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    FAST_2026_12,
    assert_block_splits_bit_identical,
    assert_killed_job_resumes_bit_identically,
    assert_running_equals_full,
    make_problem,
)

from vasc_pipeline import config, engine, kernel
from vasc_pipeline.config import ConfigError
from vasc_pipeline.kernel import packing

PACKED = (
    "tissue=sphere",
    "n_terminals=40",
    *FAST_2026_12,
    "anneal.packing_steps_per_terminal=500",
    "anneal.steps=60000",
    "anneal.trace_every=5000",
)


def test_pack_block_equals_its_numpy_twin_move_for_move():
    problem = make_problem(
        "tissue=sphere", "n_terminals=12", *FAST_2026_12, "anneal.packing_steps_per_terminal=100", "anneal.steps=5000"
    )
    fast, slow = engine.initial_state(problem, 3), engine.initial_state(problem, 3)
    p = problem.physics
    for n in (700, 300):  # within the phase: stale tree caches, exact supply
        assert packing.pack_block(problem.model, fast, n) == n
        packing.pack_block_reference(problem.model, slow, n, problem.tissue, p.supply_radius)
        for name in ("position", "rng", "counters", "step_size", "supply"):
            np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
        assert fast.costs[kernel.SUPPLY] == slow.costs[kernel.SUPPLY]
    c = fast.counters
    assert 0 < c[kernel.COUNTER_TERMINAL_ACCEPTED] < c[kernel.COUNTER_TERMINAL_PROPOSED] == 1000
    assert c[kernel.COUNTER_SWAP_PROPOSED] == c[kernel.COUNTER_BIFURCATION_PROPOSED] == 0
    # the rest of the phase: it ends at step 1200 exactly, whatever the block asked for
    assert packing.pack_block(problem.model, fast, 10_000) == 200
    packing.pack_block_reference(problem.model, slow, 10_000, problem.tissue, p.supply_radius)
    for name in engine.CHECKPOINT_FIELDS:
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
    assert c[kernel.COUNTER_STEP] == problem.model.pack_steps == 1200


def test_the_phase_packs_then_hands_a_consistent_tree_to_the_anneal():
    problem = make_problem(*PACKED)
    state = engine.initial_state(problem, 0)
    before = engine.running_costs(problem, state)["supply"]
    engine.run_block(problem, state, int(problem.model.pack_steps))  # exactly the phase
    assert assert_running_equals_full(problem, state)["supply"] < 0.6 * before
    tree = engine.tree_of(problem, state)
    # every bifurcation at the mean of its children
    first = problem.physics.n_inlets + problem.physics.n_terminals
    for b in range(first, tree.n_nodes):
        c0, c1 = tree.children[b]
        np.testing.assert_allclose(tree.position[b], 0.5 * (tree.position[c0] + tree.position[c1]), rtol=1e-15)
    # then the tree anneal: swaps and bifurcation moves happen, the sums stay exact
    engine.run_block(problem, state, 20_000)
    assert state.counters[kernel.COUNTER_SWAP_ACCEPTED] > 0
    assert state.counters[kernel.COUNTER_BIFURCATION_ACCEPTED] > 0
    assert_running_equals_full(problem, state)


def test_tree_schedule_starts_after_the_phase():
    problem = make_problem(*PACKED)
    state = engine.initial_state(problem, 0)
    pack = int(problem.model.pack_steps)
    t_start, t_end = state.schedule
    assert kernel.temperature(problem.model, state, 0) == kernel.temperature(problem.model, state, pack) == t_start
    assert kernel.temperature(problem.model, state, problem.total_steps) == pytest.approx(t_end, rel=1e-12)
    assert packing.packing_temperature(problem.model, 0) == pytest.approx(problem.model.pack_T_start)


def test_block_splits_and_checkpoint_round_trips_across_the_phase_are_bit_identical():
    problem = make_problem(*PACKED)
    # The phase ends at 20_000, inside a block.
    assert_block_splits_bit_identical(problem, 5, (1, 9_999, 9_999, 2, 17_000, 22_999))


@pytest.mark.integration
@pytest.mark.slow  # ~20 s; the sweep-level SIGKILL test resumes in the default suite
def test_a_run_killed_during_the_phase_resumes_bit_identically(tmp_path):
    overrides = [
        "tissue=sphere",
        "n_terminals=300",
        *FAST_2026_12,
        "anneal.packing_steps_per_terminal=3000",
        "anneal.steps=1000000",
        "anneal.trace_every=20000",
        "checkpoint.every_seconds=0.01",
        f"output_dir={tmp_path}",
    ]
    assert_killed_job_resumes_bit_identically(overrides, kill_before=3000 * 300)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (
            ["anneal.packing_steps_per_terminal=1000", "anneal.steps=1000"],
            r"anneal\.packing_steps_per_terminal=1000 "
            r"gives 16000 packing proposals",
        ),
        (["anneal.packing_steps_per_terminal=-1"], r"anneal\.packing_steps_per_terminal must be a finite number >= 0"),
        (["anneal.packing_steps_per_terminal=10", "anneal.packing_T_end=0"], r"anneal\.packing_T_end must be"),
        (["anneal.steps_exponent=5"], r"anneal\.steps_exponent must lie in \[0, 4\]"),
    ],
)
def test_bad_packing_settings_name_the_field(overrides, message):
    with pytest.raises(ConfigError, match=message):
        make_problem("tissue=sphere", "n_terminals=16", *overrides)


def test_budget_law_exponent():
    cfg = config.to_run_config(config.compose(["n_terminals=2000", *FAST_2026_12, "anneal.steps_exponent=1.5"]))
    assert config.scheduled_steps(cfg) == round(6.25e7 * 2.0**1.5)
