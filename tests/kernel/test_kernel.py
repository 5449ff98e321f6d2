"""The annealing kernel: incremental costs equal full recomputation, legality, determinism."""

import numpy as np
import pytest
from helpers import (
    TRUE_EXCLUSION_MAP,
    ancestors,
    assert_block_splits_bit_identical,
    assert_moves_of_every_kind_accepted_and_rejected,
    assert_running_equals_full,
    make_problem,
    reference_swap,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from vasc_pipeline import costs, engine, kernel, physics
from vasc_pipeline.model.tree import count_terminals

COLD = ("anneal.T_start=1e-2", "anneal.T_end=1e-9")  # W: hot enough to accept, cold enough to reject


@pytest.mark.parametrize(
    "overrides",
    [
        ("tissue=plane2d",),
        ("tissue=sphere", "n_terminals=120"),
        ("tissue=box", "n_terminals=120"),
        ("tissue=heart", "n_terminals=120"),  # two inlets: subtrees move between LCA and RCA trees
        # the paper's radii from r_t = 0.215 mm: segments of 1-3 terminals on the exclusion ramp
        # (weights 0.07-0.9), viscosity by diameter
        (
            "tissue=heart",
            "n_terminals=120",
            "physics.r_cutoff=2e-4",
            "physics.r_cutoff_ramp=2e-4",
            "physics.viscosity_law=pries_in_vivo",
        ),
        # the terminal-pressure term, weighted to matter: ΔC_p of translations and of swaps
        # within and between the inlet trees
        ("tissue=heart", "n_terminals=120", "physics.A_p=1e-5"),
    ],
    ids=["plane2d", "sphere", "box", "heart", "heart-ramp-viscosity", "heart-pressure"],
)
def test_running_sums_equal_full_recomputation_after_a_million_moves(overrides):
    steps = 1_000_000
    problem = make_problem(*overrides, *COLD, f"anneal.steps={steps}")
    state = engine.initial_state(problem, seed=11)
    assert_running_equals_full(problem, state)
    inlet_split_before = state.n_downstream[: problem.physics.n_inlets].copy()
    engine.run_block(problem, state, steps)
    assert state.counters[kernel.COUNTER_STEP] == steps
    assert_moves_of_every_kind_accepted_and_rejected(state)
    assert_running_equals_full(problem, state)
    if problem.physics.n_inlets == 2:
        assert not np.array_equal(state.n_downstream[:2], inlet_split_before)


def test_pressure_term_incremental_when_enabled():
    problem = make_problem("tissue=box", "n_terminals=30", "physics.A_p=1e-9", *COLD, "anneal.steps=200000")
    assert problem.terms.pressure
    state = engine.initial_state(problem, seed=3)
    engine.run_block(problem, state, 200_000)
    assert_moves_of_every_kind_accepted_and_rejected(state)
    running = assert_running_equals_full(problem, state)
    assert running["pressure"] > 0


def test_pressure_change_of_every_move_equals_full_recomputation():
    """ΔC_p from the pressures along the move's paths and the drop moments of the subtrees
    that shift (below a translated node; the moved subtrees and those hanging off a swap's
    paths, within an inlet tree or between two): after each accepted move the running C_p
    equals a fresh sum over the whole tree, whatever the move's reach."""
    problem = make_problem("tissue=heart", "n_terminals=80", "physics.A_p=1e-5", "anneal.steps=10")
    model = problem.model
    state = engine.initial_state(problem, seed=7)
    rng = np.random.default_rng(0)
    k, n = model.n_inlets, model.n_terminals
    between_inlets = within_tree = 0
    for _ in range(400):
        if rng.random() < 0.5:
            a, b = rng.choice(np.arange(k, state.parent.size), size=2, replace=False)
            inlet_a, inlet_b = (ancestors(state.parent, x)[-1] for x in (a, b))
            outcome = kernel.swap_nodes(model, state, a, b, 1e300)
            between_inlets += outcome == kernel.ACCEPTED and inlet_a != inlet_b
            within_tree += outcome == kernel.ACCEPTED and inlet_a == inlet_b
        else:
            i = rng.integers(k + n, state.parent.size)  # a bifurcation: three segments change
            new = state.position[i] + rng.uniform(-2e-3, 2e-3, 3)
            outcome = kernel.translate_node(model, state, i, new, 1e300)
        if outcome == kernel.ACCEPTED:
            expected = kernel.pressure_cost(model, state)
            assert state.costs[kernel.PRESSURE] + state.compensation[kernel.PRESSURE] == pytest.approx(
                expected, rel=1e-12
            )
    assert between_inlets > 5 and within_tree > 5
    moments = state.scratch_drop_moment.copy()  # updated move by move: a fresh pass's, to the bit
    kernel.pressure_moments(model, state)
    np.testing.assert_array_equal(state.scratch_drop_moment, moments)
    terminal_pressures = costs.node_pressures(engine.tree_of(problem, state), problem.physics)[k : k + n]
    reference = np.sum((terminal_pressures - problem.physics.pressure_terminal) ** 2)
    assert engine.running_costs(problem, state)["pressure"] == pytest.approx(reference, rel=1e-9)


def test_fixed_terminals_never_move_and_supply_is_off(tmp_path):
    base = make_problem("tissue=sphere", "n_terminals=25", "anneal.steps=10")
    sites = engine.initial_state(base, seed=4).position[1:26]
    path = tmp_path / "sites.csv"
    np.savetxt(path, sites, delimiter=",", header="x,y,z", comments="")
    problem = make_problem(
        "tissue=sphere",
        "n_terminals=25",
        f"terminals.path={path}",
        "terminals.fixed=true",
        *COLD,
        "anneal.steps=300000",
    )
    assert not problem.terms.supply
    state = engine.initial_state(problem, seed=4)
    np.testing.assert_array_equal(state.position[1:26], sites)
    engine.run_block(problem, state, 300_000)
    np.testing.assert_array_equal(state.position[1:26], sites)
    assert state.counters[kernel.COUNTER_TERMINAL_PROPOSED] == 0
    assert_moves_of_every_kind_accepted_and_rejected(state, terminals_move=False)
    running = assert_running_equals_full(problem, state)
    assert running["supply"] == 0.0


def test_same_config_and_seed_give_identical_trees_and_block_splits_are_bit_identical():
    overrides = ("tissue=sphere", "n_terminals=60", *COLD, "anneal.steps=300000")
    problem = make_problem(*overrides)
    one = engine.initial_state(problem, seed=9)
    engine.run_block(problem, one, 300_000)

    split = engine.initial_state(make_problem(*overrides), seed=9)
    for n in (1, 99_999, 150_000, 50_000):
        engine.run_block(problem, split, n)
        split = engine.restore_state(problem, engine.state_arrays(split))  # checkpoint round trip
    for name in engine.CHECKPOINT_FIELDS:
        np.testing.assert_array_equal(getattr(one, name), getattr(split, name), err_msg=name)

    other = engine.initial_state(problem, seed=10)
    engine.run_block(problem, other, 300_000)
    assert not np.array_equal(one.position, other.position)


def test_block_splits_with_the_pressure_term_are_bit_identical():
    # The drop moments are not checkpointed: a restored state rebuilds them, to the bit.
    problem = make_problem("tissue=heart", "n_terminals=60", "physics.A_p=1e-5", *COLD, "anneal.steps=200000")
    assert_block_splits_bit_identical(problem, 6, (1, 49_999, 70_000, 80_000))


# --- swap legality -------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_problem():
    # Huge temperature: every legal proposal is accepted, so legality alone decides. The tests
    # call the kernel with problem.model, the true exclusion map, from the first move.
    return make_problem(
        "tissue=box",
        "n_terminals=12",
        "anneal.T_start=1e300",
        "anneal.T_end=1e299",
        "anneal.steps=10",
        *TRUE_EXCLUSION_MAP,
    )


def test_swap_rejects_ancestors_and_siblings(small_problem):
    problem = small_problem
    state = engine.initial_state(problem, seed=1)
    parent = state.parent
    k = problem.physics.n_inlets
    node = k  # a terminal: every node on its path up is its ancestor
    up = ancestors(parent, node)
    before = engine.state_arrays(state)
    for anc in up[:-1]:  # the last ancestor is the inlet, which never moves
        assert kernel.swap_nodes(problem.model, state, node, anc, 1e300) == kernel.ILLEGAL
        assert kernel.swap_nodes(problem.model, state, anc, node, 1e300) == kernel.ILLEGAL
    bif = up[0]
    c0, c1 = state.children[bif]
    assert kernel.swap_nodes(problem.model, state, c0, c1, 1e300) == kernel.ILLEGAL
    for name in ("parent", "children", "n_downstream", "costs"):
        np.testing.assert_array_equal(getattr(state, name), before[name])


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    pairs=st.lists(st.tuples(st.integers(1, 23), st.integers(1, 23)), min_size=1, max_size=60),
)
def test_random_swap_sequences_match_a_plain_reference(small_problem, seed, pairs):
    problem = small_problem
    state = engine.initial_state(problem, seed=seed % 1000)
    for a, b in pairs:
        expected = reference_swap(state.parent, a, b) if a != b else None
        if a == b:
            continue
        outcome = kernel.swap_nodes(problem.model, state, a, b, 1e300)
        if expected is None:
            assert outcome == kernel.ILLEGAL
        else:
            assert outcome == kernel.ACCEPTED
            np.testing.assert_array_equal(state.parent, expected)
        assert np.array_equal(state.n_downstream, count_terminals(state.parent, 12, 1))
    assert_running_equals_full(problem, state)


def test_translation_keeps_terminals_in_tissue_and_bifurcations_in_the_grid(small_problem):
    problem = small_problem
    state = engine.initial_state(problem, seed=2)
    lo, hi = problem.tissue.bounds
    terminal, bifurcation = 1, 1 + 12
    outside_tissue = np.array([lo[0] + 1e-4, lo[1] + 1e-4, lo[2] + 1e-4])  # in the grid margin
    assert kernel.translate_node(problem.model, state, terminal, outside_tissue, 1e300) == kernel.ILLEGAL
    assert kernel.translate_node(problem.model, state, bifurcation, outside_tissue, 1e300) == kernel.ACCEPTED
    assert kernel.translate_node(problem.model, state, bifurcation, hi + 1e-3, 1e300) == kernel.ILLEGAL
    assert_running_equals_full(problem, state)


def test_supply_map_is_int16_and_int32_checkpoints_resume_bit_identically():
    # The count map is int16 while no count can overflow it (a count is at most N); a
    # checkpoint written with the former int32 map resumes to the same state.
    assert engine.supply_dtype(32767) is np.int16 and engine.supply_dtype(32768) is np.int32
    problem = make_problem("tissue=sphere", "n_terminals=40", *COLD, "anneal.steps=100000")
    state = engine.initial_state(problem, seed=5)
    assert state.supply.dtype == np.int16
    engine.run_block(problem, state, 50_000)
    arrays = engine.state_arrays(state)
    old_style = engine.restore_state(problem, {**arrays, "supply": arrays["supply"].astype(np.int32)})
    assert old_style.supply.dtype == np.int16
    engine.run_block(problem, state, 50_000)
    engine.run_block(problem, old_style, 50_000)
    for name in engine.CHECKPOINT_FIELDS:
        np.testing.assert_array_equal(getattr(state, name), getattr(old_style, name), err_msg=name)
    assert_running_equals_full(problem, state)


@pytest.mark.parametrize(
    "overrides",
    [
        ("tissue=sphere", "n_terminals=60"),
        ("tissue=heart", "n_terminals=60"),
        ("tissue=heart", "n_terminals=60", "physics.A_p=1e-5"),  # ΔC_p in every bound
    ],
    ids=["sphere", "heart", "heart-pressure"],
)
def test_early_rejection_changes_no_decision(overrides):
    """The early-rejection shortcut skips work only: same states, bit for bit, without it."""
    import dataclasses

    steps = 200_000
    problem = make_problem(*overrides, *COLD, f"anneal.steps={steps}")
    assert problem.model.early_reject and problem.terms.exclusion
    final = {}
    for early in (True, False):
        p = dataclasses.replace(problem, model=problem.model._replace(early_reject=early))
        state = engine.initial_state(p, seed=5)
        engine.run_block(p, state, steps)
        assert_moves_of_every_kind_accepted_and_rejected(state)
        final[early] = engine.state_arrays(state)
    for name, value in final[True].items():
        np.testing.assert_array_equal(value, final[False][name], err_msg=name)


def test_new_segment_traversal_rejects_on_its_partial_sum_or_traverses_in_full():
    """kernel.moves._new_exclusion's two branches, forced: a cap far below the segment's sum stops
    the traversal; a bound that then rejects returns the partial sum with the rejection, one
    that does not (a downhill move) returns the full sum, as if no cap had been set."""
    problem = make_problem("tissue=sphere", "n_terminals=50", "anneal.steps=1000")
    model = problem.model
    n = model.n_terminals  # the trunk's n: its radius is above the exclusion cut-off
    assert model.w_exclusion * model.tables[physics.TABLE_EXCLUSION, n] > 0
    r = problem.tissue.inlets[0][2]
    p0, p1 = np.array([-0.6 * r, 0.0, 0.0]), np.array([0.6 * r, 0.1 * r, 0.0])
    full = kernel.segment_exclusion(model, p0, p1)
    assert full > 0
    rng = np.zeros(4, dtype=np.uint64)  # not drawn from: u is given
    temp, u = 1e-12, 0.5  # cap = T ln 2 / slope: a tiny fraction of the sum
    for vascular, rejected in ((1e-9, True), (-1e300, False)):
        s, was_rejected, u_out = kernel.moves._new_exclusion(
            model, p0, p1, n, temp, rng, u, 0.0, vascular, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False
        )
        assert was_rejected == rejected and u_out == u
        assert (0 < s < full) if rejected else (s == full)
