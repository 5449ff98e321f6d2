"""anneal=fast: calibrated temperatures, adapted steps, neighbour swaps, supply schedule, polish."""

import dataclasses
import math

import numpy as np
import pytest
from helpers import (
    FAST_2026_12,
    FAST_ONE_EXPONENTIAL,
    TRUE_EXCLUSION_MAP,
    assert_block_splits_bit_identical,
    assert_moves_of_every_kind_accepted_and_rejected,
    assert_running_equals_full,
    make_problem,
    reference_swap,
)

from vasc_pipeline import config, costs, engine, job, kernel, sweep
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model import topology_search
from vasc_pipeline.model.physics import cost_tables
from vasc_pipeline.model.tree import Tree, check_tree, children_from_parent, count_terminals
from vasc_pipeline.store import RunStore


def cells_consistent(problem, state):
    """Every non-inlet node sits, once, in the list of the cell of its position; links agree."""
    model = problem.model
    seen = np.zeros(state.parent.size, dtype=int)
    for c, head in enumerate(state.cell_head):
        x, prev = head, -1
        while x >= 0:
            assert state.cell_of[x] == c and state.cell_prev[x] == prev
            seen[x] += 1
            prev, x = x, state.cell_next[x]
    k = problem.physics.n_inlets
    assert np.all(seen[k:] == 1) and np.all(seen[:k] == 0)
    cxyz = np.clip(np.floor((state.position - model.cell_lo) / model.cell_size).astype(int), 0, model.cell_shape - 1)
    expected = (cxyz[:, 2] * model.cell_shape[1] + cxyz[:, 1]) * model.cell_shape[0] + cxyz[:, 0]
    np.testing.assert_array_equal(state.cell_of[k:], expected[k:])
    # The per-cell node counts that the partner draw reads follow the lists.
    np.testing.assert_array_equal(state.scratch_cell_count, np.bincount(expected[k:], minlength=state.cell_head.size))


@pytest.mark.parametrize(
    "overrides",
    [
        ("tissue=plane2d",),
        ("tissue=sphere", "n_terminals=120"),
        ("tissue=heart", "n_terminals=120"),
    ],
    ids=["plane2d", "sphere", "heart"],
)
def test_fast_running_sums_equal_full_recomputation_and_cells_follow_the_nodes(overrides):
    steps = 1_000_000
    problem = make_problem(*overrides, "anneal=fast", f"anneal.steps={steps}")
    state = engine.initial_state(problem, seed=5)
    engine.run_block(problem, state, steps)
    assert state.counters[kernel.COUNTER_STEP] == steps
    assert state.counters[kernel.COUNTER_LOCAL_SWAP_PROPOSED] > 0.8 * state.counters[kernel.COUNTER_SWAP_PROPOSED]
    assert_moves_of_every_kind_accepted_and_rejected(state)
    assert_running_equals_full(problem, state)
    cells_consistent(problem, state)
    # Steps adapted down from their caps as the temperature fell.
    assert np.all(state.step_size < 0.1 * problem.model.step_max)


def test_neighbour_partner_is_uniform_over_the_adjacent_cells_and_symmetric():
    problem = make_problem("tissue=sphere", "n_terminals=60", "anneal=fast", "anneal.neighbour_cell=1.5")
    state = engine.initial_state(problem, seed=2)
    model = problem.model
    k = problem.physics.n_inlets
    cell = np.clip(np.floor((state.position - model.cell_lo) / model.cell_size).astype(int), 0, model.cell_shape - 1)

    def neighbours(a):
        near = np.all(np.abs(cell - cell[a]) <= 1, axis=1)
        near[:k] = False
        near[a] = False
        return set(np.flatnonzero(near))

    rng = np.array(state.rng)
    for a in range(k, state.parent.size, 7):
        expected = neighbours(a)
        assert all(a in neighbours(b) for b in expected)  # the relation is symmetric
        draws = [kernel.neighbour_partner(model, state, a, rng) for _ in range(200 * max(len(expected), 1))]
        if not expected:
            assert set(draws) == {-1}
            continue
        values, counts = np.unique(draws, return_counts=True)
        assert set(values) == expected
        assert counts.min() > 0.6 * counts.mean()  # uniform: 200 expected draws each


@pytest.mark.parametrize("partners", ["anneal.neighbour_cell=0.4", "anneal.p_local=0"], ids=["neighbours", "uniform"])
def test_swaps_at_a_fixed_temperature_sample_the_boltzmann_distribution(partners):
    """Detailed balance of the swap move with its partner draws: swaps alone, at a constant
    temperature, on a 4-terminal tree whose nodes never move, visit every tree they can reach
    with probability exp(-C/T)/Z. (A sampler 10 % off in temperature is 0.04 away in total
    variation; this one is ~0.01.)"""
    problem = make_problem("tissue=sphere", "n_terminals=4", "anneal=fast", partners, *TRUE_EXCLUSION_MAP)
    problem = dataclasses.replace(problem, model=problem.model._replace(p_swap=1.0))
    state = engine.initial_state(problem, seed=3)
    k = problem.physics.n_inlets
    w_o, w_p, _ = problem.physics.weights

    def energy(parent):  # the annealed total less the supply term, which no swap changes
        tree = Tree(parent, children_from_parent(parent), state.position, count_terminals(parent, 4, k), k)
        c = costs.full_costs(tree, problem.tissue, problem.physics, problem.terms)
        return c["volume"] + c["power"] + w_o * c["exclusion"] + w_p * c["pressure"]

    energies, todo = {}, [state.parent.copy()]
    while todo:  # every tree that swaps reach
        p = todo.pop()
        if p.tobytes() not in energies:
            energies[p.tobytes()] = energy(p)
            pairs = ((a, b) for a in range(k, p.size) for b in range(a + 1, p.size))
            todo.extend(q for q in (reference_swap(p, a, b) for a, b in pairs) if q is not None)
    e = np.array(list(energies.values()))
    temp = float(np.std(e))
    state.schedule[:] = temp  # T_start = T_end: a constant temperature
    index = {key: i for i, key in enumerate(energies)}
    visits = np.zeros(e.size)
    for _ in range(100_000):
        engine.run_block(problem, state, 30)  # ~2 accepted swaps between samples
        visits[index[state.parent.tobytes()]] += 1
    boltzmann = np.exp(-(e - e.min()) / temp)
    boltzmann /= boltzmann.sum()
    assert e.size >= 20 and boltzmann.max() < 0.5  # a distribution worth testing
    assert 0.5 * np.abs(visits / visits.sum() - boltzmann).sum() < 0.025


def test_calibrated_temperatures_follow_the_cost_scale_and_leave_the_random_stream_alone():
    problem = make_problem("tissue=plane2d", "anneal=fast", "anneal.steps=1000")
    a = problem.config.anneal
    state = engine.initial_state(problem, seed=4)
    t_start, t_end = state.schedule
    tables = cost_tables(problem.physics)
    assert t_end == pytest.approx(a.T_end_rel * (tables.volume[1] + tables.power[1]) * problem.physics.supply_radius)
    # The run's generator is the one random_tree left: calibration walked a copy.
    fresh = engine.initial_state(make_problem("tissue=plane2d", "anneal=paper", "anneal.steps=1000"), seed=4)
    np.testing.assert_array_equal(state.rng, fresh.rng)
    # On an independent sample of uphill moves from the same tree, acceptance at T_start is near accept_start.
    walker = engine.restore_state(problem, engine.state_arrays(state))
    walker.rng[:] = engine.seed_state(99)
    uphill = np.empty(4000)
    uphill = uphill[: kernel.sample_uphill(problem.model, walker, 4000, uphill)]
    assert uphill.size > 500
    assert np.mean(np.exp(-uphill / t_start)) == pytest.approx(a.accept_start, abs=0.05)
    assert t_start > 1e3 * t_end
    # Configured temperatures are kept as they are.
    kept = engine.initial_state(
        make_problem("tissue=plane2d", "anneal=fast", "anneal.T_start=1e-3", "anneal.T_end=1e-10"), seed=4
    )
    np.testing.assert_array_equal(kept.schedule, [1e-3, 1e-10])


def test_step_adaptation_by_hand():
    problem = make_problem("tissue=plane2d", "anneal=fast")
    model = problem.model
    state = engine.initial_state(problem, seed=0)
    c = state.counters
    width = state.step_size[1] = 0.5 * model.step_max[1]
    c[kernel.COUNTER_WINDOW_BIFURCATION_PROPOSED] = model.adapt_window - 1
    c[kernel.COUNTER_WINDOW_BIFURCATION_ACCEPTED] = model.adapt_window // 10 - 1
    kernel.moves._adapt_step(model, state, 1, True)  # the window's last proposal: acceptance 0.1
    assert state.step_size[1] == pytest.approx(width * math.exp(2 * (0.1 - model.acceptance_target)))
    assert c[kernel.COUNTER_WINDOW_BIFURCATION_PROPOSED] == c[kernel.COUNTER_WINDOW_BIFURCATION_ACCEPTED] == 0
    c[kernel.COUNTER_WINDOW_BIFURCATION_PROPOSED] = model.adapt_window - 1
    c[kernel.COUNTER_WINDOW_BIFURCATION_ACCEPTED] = model.adapt_window - 1
    kernel.moves._adapt_step(model, state, 1, True)  # acceptance 1 widens, up to the configured cap
    kernel.moves._adapt_step(model, state, 1, True)
    assert state.step_size[1] <= model.step_max[1]


def test_full_width_terminal_moves_stop_after_their_phase_and_leave_the_stream_alone():
    """Before ``full_width_phase`` the run is the whole-run setting's (``fast_v1``'s) move for
    move; after it no terminal move is wider than the adapted step (held tiny here), though
    full-width ones are drawn."""
    base = ["tissue=plane2d", "n_terminals=30", "anneal=fast", "anneal.steps=20000", "anneal.adapt_window=1000000"]
    whole_run = make_problem(*base, "anneal.full_width_phase=1.0")
    cut = make_problem(*base, "anneal.full_width_phase=0.5")
    assert cut.model.full_width_steps == 10000 and whole_run.model.full_width_steps == 20000
    fast = make_problem(*base)  # fast's own phase, read from the preset (it moves when it is retuned)
    assert fast.model.full_width_steps == round(fast.config.anneal.full_width_phase * 20000)
    assert make_problem(*base[:2], "anneal=fast_v1", *base[3:]).model.full_width_steps == 20000
    states = {}
    for name, problem in (("whole_run", whole_run), ("cut", cut)):
        state = engine.initial_state(problem, seed=2)
        engine.run_block(problem, state, 10000)
        states[name] = state
    np.testing.assert_array_equal(states["whole_run"].position, states["cut"].position)
    np.testing.assert_array_equal(states["whole_run"].rng, states["cut"].rng)
    k = whole_run.model.n_inlets
    terminals = slice(k, k + whole_run.model.n_terminals)
    for name, problem in (("whole_run", whole_run), ("cut", cut)):
        state = states[name]
        state.step_size[0] = 1e-6 * problem.model.step_max[0]
        widest = 0.0
        for _ in range(5000):
            before = state.position[terminals].copy()
            engine.run_block(problem, state, 1)
            widest = max(widest, np.abs(state.position[terminals] - before).max())
        if name == "cut":
            assert widest <= state.step_size[0]
        else:  # the full-width moves, accepted at this temperature, are what the cut removes
            assert widest > 100 * state.step_size[0]


def test_a_cold_part_changes_the_cooling_rate_once_where_it_starts():
    """``anneal.cold_from`` / ``cold_share``: log T falls linearly in the step on each side of the
    point cold_from of the way from T_start to T_end, reached when 1 - cold_share of the tree
    anneal's steps are done (after the packing phase); without them, the one exponential."""
    base = ["tissue=plane2d", "n_terminals=30", "anneal=fast", "anneal.steps=100000"]
    base.append("anneal.packing_steps_per_terminal=1000")
    problem = make_problem(*base, "anneal.cold_from=0.6", "anneal.cold_share=0.25")
    model = problem.model
    state = engine.initial_state(problem, seed=1)
    t_start, t_end = state.schedule
    pack, end = model.pack_steps, model.total_steps
    knee = pack + 0.75 * (end - pack)
    assert (pack, model.cold_steps, model.cold_path) == (30_000, 52_500, 0.6)

    def path(step):
        return math.log(kernel.temperature(model, state, step) / t_start) / math.log(t_end / t_start)

    assert path(0) == path(pack) == 0.0
    assert path(knee) == pytest.approx(0.6, abs=1e-12)
    assert path(end) == path(2 * end) == pytest.approx(1.0, abs=1e-12)
    for a, b in ((pack, knee), (knee, end)):
        assert path((a + b) / 2) == pytest.approx((path(a) + path(b)) / 2, abs=1e-12)

    plain = make_problem(*base, "anneal.cold_from=null", "anneal.cold_share=null")
    plain_state = engine.initial_state(plain, seed=1)
    np.testing.assert_array_equal(plain_state.schedule, state.schedule)  # calibration is the same
    for step in (0, pack, pack + 12_345, knee, end, 2 * end):
        exponential = t_start * math.exp(math.log(t_end / t_start) * min(max(step - pack, 0) / (end - pack), 1.0))
        assert kernel.temperature(plain.model, plain_state, step) == exponential  # to the bit


def test_block_splits_across_the_start_of_the_cold_part_are_bit_identical():
    overrides = ("tissue=plane2d", "n_terminals=30", "anneal=fast", "anneal.steps=40000")
    problem = make_problem(*overrides, "anneal.cold_from=0.5", "anneal.cold_share=0.5")
    # The cold part starts at 20 000, inside a block.
    assert_block_splits_bit_identical(problem, 4, (1, 19_998, 3, 19_998))


def test_fast_runs_its_hot_half_move_for_move_as_the_one_exponential_over_the_old_budget():
    """``fast``'s cold part (the second half of the path in a fifth of 0.625 of the old budget)
    leaves the hot half as it was: the one exponential over 1.6 times the moves, with the old
    supply and full-width phases, reaches the knee in the same state, to the bit. On ``fast`` as
    of 2026-12 (``FAST_2026_12``), whose cold share and phases these step counts are."""
    base = ["tissue=plane2d", "n_terminals=30", *FAST_2026_12]
    two_part = make_problem(*base, "anneal.steps=50000")
    old = make_problem(*base, "anneal.steps=80000", *FAST_ONE_EXPONENTIAL)
    assert two_part.model.cold_steps == 40_000 and old.model.cold_steps == 80_000
    states = []
    for problem in (two_part, old):
        state = engine.initial_state(problem, seed=6)
        engine.run_block(problem, state, 40_000)
        states.append(state)
    for name in engine.CHECKPOINT_FIELDS:
        np.testing.assert_array_equal(getattr(states[0], name), getattr(states[1], name), err_msg=name)
    assert states[0].counters[kernel.COUNTER_SWAP_ACCEPTED] > 0


def test_supply_weight_follows_its_schedule_then_is_the_true_weight():
    problem = make_problem("tissue=plane2d", "anneal=fast", "anneal.steps=1000000", "anneal.supply_phase=0.5")
    model = problem.model
    state = engine.initial_state(problem, seed=0)
    rho = problem.physics.supply_radius / problem.tissue.voxel_size
    assert model.supply_T_start == pytest.approx(problem.config.anneal.supply_T_start * math.pi * rho**2)
    assert model.supply_steps == 500_000
    temp = 1e-6
    assert kernel.supply_weight(model, state, temp) == pytest.approx(temp / model.supply_T_start)
    state.counters[kernel.COUNTER_STEP] = 250_000
    t_s = math.sqrt(model.supply_T_start * model.supply_T_end)
    assert kernel.supply_weight(model, state, temp) == pytest.approx(temp / t_s)
    state.counters[kernel.COUNTER_STEP] = 500_000
    assert kernel.supply_weight(model, state, temp) == model.w_supply
    paper = make_problem("tissue=plane2d", "anneal=paper")
    assert kernel.supply_weight(paper.model, state, temp) == paper.model.w_supply


def test_fast_is_deterministic_across_block_splits_and_checkpoint_round_trips():
    problem = make_problem("tissue=heart", "n_terminals=60", "anneal=fast", "anneal.steps=300000")
    assert_block_splits_bit_identical(problem, 8, (1, 99_999, 50_000, 123_456, 300_000 - 273_456))


def test_fast_steps_are_exact_and_polish_keeps_the_running_costs_true():
    cfg = config.compose(
        ["tissue=sphere", "n_terminals=40", "anneal=fast", "anneal.steps=200000", "anneal.trace_every=50000"]
    )
    result = engine.run(cfg, seed=1)
    assert result.steps == 200_000
    check_tree(result.tree, result.problem.tissue)
    polish = result.anneal["polish"]
    assert (polish["applied"] == "none") == (polish["moved"] == 0)
    assert polish["total_after"] <= polish["total_before"]
    for term in ("volume", "power", "exclusion", "total"):
        assert result.costs[term] == pytest.approx(result.costs_recomputed[term], rel=1e-9)
    assert result.costs["supply"] == result.costs_recomputed["supply"]


def test_the_job_stores_how_the_schedule_ran(tmp_path):
    cfg = config.compose(
        [
            "tissue=plane2d",
            "n_terminals=12",
            "anneal=fast",
            "anneal.steps=50000",
            "anneal.trace_every=10000",
            f"output_dir={tmp_path}",
        ]
    )
    (j,) = sweep.expand(cfg)
    summary = job.run_job(j)
    attrs = RunStore.open(j.store, mode="r").attrs
    report = attrs["anneal"]
    problem = engine.build_problem(j.config)  # the calibrated schedule the run used, stored as run
    assert (report["T_start"], report["T_end"]) == tuple(engine.initial_state(problem, 0).schedule)
    assert report["polish"]["total_after"] <= report["polish"]["total_before"] + 1e-12 * abs(
        report["polish"]["total_before"]
    )
    assert summary["cost"] == pytest.approx(summary["cost_recomputed"], rel=1e-9)


@pytest.mark.parametrize(
    "override, field",
    [
        ("anneal.accept_start=1.5", "anneal.accept_start"),
        ("anneal.acceptance_target=0", "anneal.acceptance_target"),
        ("anneal.p_local=-0.1", "anneal.p_local"),
        ("anneal.neighbour_cell=0", "anneal.neighbour_cell"),
        ("anneal.adapt_window=0", "anneal.adapt_window"),
        ("anneal.supply_T_end=10", "anneal.supply_T_end"),
        ("anneal.supply_phase=0", "anneal.supply_phase"),
        ("anneal.full_width_phase=1.5", "anneal.full_width_phase"),
        ("anneal.T_end_rel=-1", "anneal.T_end_rel"),
        ("anneal.cold_share=null", "anneal.cold_share"),
        ("anneal.cold_from=1.0 anneal.cold_share=0.2", "anneal.cold_from"),
        ("anneal.cold_from=0.5 anneal.cold_share=0", "anneal.cold_share"),
    ],
)
def test_bad_fast_settings_name_the_field(override, field):
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        config.compose(["anneal=fast", *override.split()])


def _fixed_sites(tmp_path, n, seed):
    rng = np.random.default_rng(seed)
    sites = np.c_[rng.uniform(0.01, 0.09, (n, 2)), np.zeros(n)]
    path = tmp_path / f"sites{n}_{seed}.csv"
    np.savetxt(path, sites, delimiter=",", header="x,y,z", comments="")
    return path, sites


@pytest.mark.parametrize("n", [4, 5, pytest.param(6, marks=pytest.mark.slow)])
def test_fast_with_polish_reaches_the_exhaustive_global_optimum(tmp_path, n):
    path, sites = _fixed_sites(tmp_path, n, seed=n)
    overrides = [
        "model=physiological",  # the default, for the search and the runs alike
        "physics.A_p=0",  # the exhaustive search's cost is C_v + C_w
        "tissue=plane2d",
        f"n_terminals={n}",
        f"terminals.path={path}",
        "terminals.fixed=true",
        "anneal=fast",
        "anneal.steps=1000000",
    ]
    problem = make_problem(*overrides)
    best, _, _ = topology_search.best_topology(problem.tissue.inlets[0], sites, problem.physics, problem.tissue.bounds)
    for seed in range(4):
        result = engine.run(config.compose(overrides), seed=seed)
        c = result.costs_recomputed
        assert (c["volume"] + c["power"]) == pytest.approx(best, rel=1e-6), seed


def test_the_schedule_is_computed_once_and_the_kernel_model_copies_it():
    # FAST_2026_12: every phase on, at values the phase ends below are worked out from
    problem = make_problem(
        "tissue=sphere", "n_terminals=40", *FAST_2026_12, "anneal.steps=60000", "anneal.packing_steps_per_terminal=250"
    )
    s, m, a = problem.schedule, problem.model, problem.config.anneal
    assert (s.total, s.pack, s.tree) == (60_000, 10_000, 50_000) == (problem.total_steps, m.pack_steps, 50_000)
    kernel_steps = (m.total_steps, m.cold_steps, m.supply_steps, m.full_width_steps)
    assert kernel_steps == (s.total, s.cold, s.supply, s.full_width)
    assert s.cold == round((1 - a.cold_share) * s.tree) and s.full_width == round(a.full_width_phase * s.tree)
    assert problem.coarse_steps == s.coarse == s.pack + round(a.coarse_exclusion_phase * s.tree)
    assert s == config.Schedule.of(problem.config, exclusion=True)
    assert config.Schedule.of(problem.config, exclusion=False).coarse == 0  # the coarse map serves exclusion alone
    four = dataclasses.replace(s, part_phases=4)
    np.testing.assert_array_equal(four.phase_ends(), [22_500, 30_000, 35_000, 47_500, 60_000])
