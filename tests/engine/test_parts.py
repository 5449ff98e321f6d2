"""One tree annealed in parts (anneal.parts, engine.parts): the parts' changes add up to the
whole tree's exactly, frozen nodes stay put, the result does not depend on how the parts are
run, a killed run resumes to the same tree, and parts = 1 is the serial anneal."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from helpers import (
    TRUE_EXCLUSION_MAP,
    assert_killed_job_resumes_bit_identically,
    assert_running_equals_full,
    check_tree,
    make_problem,
    reference_swap,
)

from vasc_pipeline import config, costs, engine, kernel
from vasc_pipeline.config import ConfigError
from vasc_pipeline.engine import parts
from vasc_pipeline.kernel import margins
from vasc_pipeline.model.tree import Tree, children_from_parent, count_terminals

SPHERE = ["tissue=sphere", "n_terminals=400", "anneal.steps=2000000"]


# The terminal-pressure term on: a part's terminals see the whole tree's pressures.
PRESSURE = ["physics.A_p=1e-5"]


def _half_annealed(*overrides):
    """A sphere tree half-way through its anneal, its sums recomputed."""
    problem = make_problem(*SPHERE, *overrides)
    state = engine.initial_state(problem, 0)
    engine.run_block(problem, state, 1_000_000)
    kernel.initialise(problem.model, state)
    return problem, state


@pytest.fixture(scope="module")
def annealed():
    return _half_annealed()


@pytest.fixture(scope="module")
def annealed_with_pressure():
    return _half_annealed(*PRESSURE)


@pytest.mark.parametrize("radius", [0.0, 1.0, 2.5, 4.87, 6.0])
def test_the_margins_are_the_distance_transforms(radius):
    """kernel.mark_margins marks the voxels that one exact distance transform per part puts
    within the radius of another part, across non-tissue gaps and at the grid's faces too."""
    rng = np.random.default_rng(int(radius * 10))
    shape = (17, 23, 19)
    seeds = rng.integers(0, shape, size=(9, 3))
    grid = np.stack(np.meshgrid(*map(np.arange, shape), indexing="ij"), axis=-1)
    region = np.argmin(((grid[..., None, :] - seeds) ** 2).sum(axis=-1), axis=-1) % 3  # 3 parts
    region[rng.random(shape) < 0.2] = -1  # non-tissue, some of it between parts
    region[:, 11:13, :] = -1  # a gap two voxels wide
    marked = np.zeros(shape, dtype=bool)
    margins.mark_margins(region, radius, marked)
    np.testing.assert_array_equal(marked, margins.margins_reference(region, radius))
    assert marked.any() == (radius >= 1.0)
    one_part = np.where(region >= 0, 0, -1)
    margins.mark_margins(one_part, radius, marked)
    assert not marked.any()


@pytest.mark.parametrize("leaves", [False, True], ids=["subtrees", "terminals"])
def test_the_cut_partitions_the_tree_into_balanced_parts(annealed, leaves):
    problem, state = annealed
    k = 3
    cut = parts.make_parts(problem, state, k, np.array([0.1, 0.2, 0.3]), leaves)
    model = problem.model
    terminals = np.concatenate([p.nodes[p.n_inlets : p.n_inlets + p.n_terminals] for p in cut])
    assert np.unique(terminals).size == terminals.size  # disjoint
    everyone = np.arange(model.n_inlets, model.n_inlets + model.n_terminals)
    if leaves:  # the terminals free to move, their regions' interiors disjoint
        assert 0.15 * everyone.size < terminals.size < everyone.size
        cover = np.zeros(problem.tissue.shape, dtype=int)
        for p in cut:  # each mask on its box of the supply grid
            cover[p.box] += p.mask
            lo, hi = p.corner, p.corner + p.mask.shape  # the box holds every voxel its spheres reach
            reach, voxels = np.ceil(problem.model.supply_rho + parts.MARGIN_SLACK), np.argwhere(p.mask) + lo
            assert np.all((voxels.min(axis=0) - reach >= lo) | (lo == 0))
            assert np.all((voxels.max(axis=0) + reach < hi) | (hi == problem.tissue.shape))
        assert cover.max() <= 1
    else:
        assert np.array_equal(np.sort(terminals), everyone)
        assert max(p.n_terminals for p in cut) <= 1.5 * model.n_terminals / k
    for p in cut:  # one pseudo-inlet per parent of a root
        np.testing.assert_array_equal(p.nodes[: p.n_inlets], np.unique(state.parent[p.roots]))


@pytest.mark.parametrize("tree", ["annealed", "annealed_with_pressure"])
@pytest.mark.parametrize("leaves", [False, True], ids=["subtrees", "terminals"])
def test_the_parts_changes_add_up_to_the_whole_trees_exactly(tree, leaves, request):
    problem, whole = request.getfixturevalue(tree)
    state = engine.restore_state(problem, engine.state_arrays(whole))
    before = state.costs + state.compensation
    position = state.position.copy()
    cut = parts.make_parts(problem, state, 2, np.array([0.1, 0.2, 0.3]), leaves)
    expected, results = before.copy(), []
    for index, part in enumerate(cut):
        sub = parts.part_state(problem, problem.model, state, part, engine.initial_state(problem, index).rng)
        start = sub.costs + sub.compensation
        accepted = int(sub.counters[kernel.COUNTER_TERMINAL_ACCEPTED if leaves else kernel.COUNTER_SWAP_ACCEPTED])
        results.append(parts.anneal_part((parts.part_model(problem.model, part), sub, 200_000, 400_000)))
        expected += (sub.costs + sub.compensation) - start
        assert sub.counters[kernel.COUNTER_TERMINAL_ACCEPTED if leaves else kernel.COUNTER_SWAP_ACCEPTED] > accepted
    parts.merge_parts(problem.model, state, cut, results)
    after = state.costs + state.compensation
    assert after[kernel.SUPPLY] == expected[kernel.SUPPLY]  # integer-valued: exact
    np.testing.assert_allclose(after, expected, rtol=1e-12)
    assert (after[kernel.PRESSURE] != before[kernel.PRESSURE]) == problem.model.pressure_on
    assert_running_equals_full(problem, state)
    check_tree(engine.tree_of(problem, state), problem.tissue)
    # frozen: the top tree above the parts, and every terminal outside a part of terminals
    own = np.concatenate([p.nodes[p.n_inlets :] for p in cut])
    still = np.setdiff1d(np.arange(problem.model.n_inlets, state.parent.size), own)
    if not leaves:
        still = np.union1d(still, np.arange(problem.model.n_inlets, problem.model.n_inlets + problem.model.n_terminals))
    np.testing.assert_array_equal(state.position[still], position[still])


def test_a_parts_run_does_not_depend_on_how_the_parts_are_run():
    overrides = [
        *SPHERE,
        *PRESSURE,
        "anneal.parts=2",
        "anneal.part_phases=8",
        "anneal.steps=400000",
        "anneal.trace_every=50000",
    ]
    serial = engine.run(config.compose(overrides), seed=3)
    with ThreadPoolExecutor(2) as pool:
        threaded = engine.run(config.compose(overrides), seed=3, part_map=pool.map)
    np.testing.assert_array_equal(serial.tree.position, threaded.tree.position)
    np.testing.assert_array_equal(serial.tree.parent, threaded.tree.parent)
    assert serial.costs == threaded.costs
    assert serial.costs["total"] == pytest.approx(serial.costs_recomputed["total"], rel=1e-9)
    assert serial.steps == 400_000


def test_parts_of_one_is_the_serial_anneal():
    overrides = [*SPHERE, "anneal.steps=200000"]
    one = engine.run(config.compose([*overrides, "anneal.parts=1", "anneal.part_phases=5"]), seed=1)
    serial = engine.run(config.compose(overrides), seed=1)
    np.testing.assert_array_equal(one.tree.position, serial.tree.position)
    assert one.costs == serial.costs


@pytest.mark.integration
@pytest.mark.slow  # ~19 s; a parts run independent of how its parts run stays in the default suite
def test_a_killed_parts_run_resumes_to_the_same_tree(tmp_path):
    overrides = [
        *SPHERE,
        "anneal.parts=2",
        "anneal.part_phases=16",
        "anneal.steps=1000000",
        "checkpoint.every_seconds=0.01",
        f"output_dir={tmp_path}",
    ]
    assert_killed_job_resumes_bit_identically(overrides, kill_before=1_000_000)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["anneal.parts=0"], r"anneal\.parts must be an integer in \[1, n_terminals / 16 = 25\]"),
        (["anneal.parts=26"], r"anneal\.parts must be an integer in \[1, n_terminals / 16 = 25\]"),
        (["anneal.part_share=1"], r"anneal\.part_share must lie in \(0, 1\)"),
        (["anneal.part_phases=0"], r"anneal\.part_phases must be an integer in \[1, 100000\]"),
    ],
)
def test_bad_parts_settings_name_the_field(overrides, message):
    with pytest.raises(ConfigError, match=message):
        config.compose([*SPHERE, *overrides])


@pytest.mark.integration
@pytest.mark.slow  # ~50 s; the parts' own tests run in the default suite
def test_a_sweep_runs_one_tree_in_parts_on_the_clusters_workers(tmp_path):
    """Through the pipeline, on a local cluster of two workers: the runs go one at a time, their
    parts to the workers, progress names the phase, and each tree is the one the same run
    makes in one process."""
    import io

    from vasc_pipeline.pipeline import orchestrate
    from vasc_pipeline.store import RunStore

    overrides = [*SPHERE, "anneal.parts=2", "anneal.part_phases=4", "anneal.steps=200000", "anneal.trace_every=50000"]
    log = io.StringIO()
    cluster = ["cluster.n_workers=2", "cluster.dashboard_address=null", "sweep.seeds=[0,1]"]
    cfg = config.compose([*overrides, f"output_dir={tmp_path}", *cluster])
    result = orchestrate.run_sweep(cfg, stream=log, progress_interval=0.0, reduce=False)
    assert len(result.complete) == 2 and not result.failed, log.getvalue()
    assert "phase " in log.getvalue() and " in 2 parts" in log.getvalue(), log.getvalue()
    for seed in (0, 1):
        (store,) = (tmp_path / "runs").glob(f"*-s{seed}.zarr")
        alone = engine.run(config.compose(overrides), seed=seed)
        np.testing.assert_array_equal(RunStore.open(store, mode="r").read_tree()["position"], alone.tree.position)


def test_swaps_inside_a_part_sample_the_whole_trees_boltzmann_distribution():
    """Detailed balance inside one part with the rest of the tree frozen: swaps alone, at a
    constant temperature, in a part of subtrees (its pseudo-inlets' terminal counts kept) visit
    every tree they can reach with probability exp(-C/T)/Z, C the whole tree's cost."""
    problem = make_problem("tissue=sphere", "n_terminals=16", "anneal=fast", *TRUE_EXCLUSION_MAP)
    state = engine.initial_state(problem, seed=3)
    k, n = problem.physics.n_inlets, problem.physics.n_terminals
    w_o, w_p, _ = problem.physics.weights
    cut = parts.make_parts(problem, state, 4, np.array([0.1, 0.2, 0.3]))
    part = max(cut, key=lambda p: (p.n_terminals <= 5, p.n_terminals))
    model = parts.part_model(problem.model, part)._replace(p_swap=1.0)
    sub = parts.part_state(problem, model, state, part, engine.initial_state(problem, 7).rng)
    k_in, own = part.n_inlets, part.nodes[part.n_inlets :]

    def counts(local):  # terminals under each pseudo-inlet
        return count_terminals(local, part.n_terminals, k_in)[:k_in]

    def energy(local):  # the whole tree's annealed total less the supply term, which no swap changes
        parent = state.parent.copy()
        parent[own] = part.nodes[local[k_in:]]
        tree = Tree(parent, children_from_parent(parent), state.position, count_terminals(parent, n, k), k)
        c = costs.full_costs(tree, problem.tissue, problem.physics, problem.terms)
        return c["volume"] + c["power"] + w_o * c["exclusion"] + w_p * c["pressure"]

    start, energies, todo = counts(sub.parent), {}, [sub.parent.copy()]
    while todo:  # every tree of the part that swaps keeping the counts reach
        p = todo.pop()
        if p.tobytes() not in energies:
            energies[p.tobytes()] = energy(p)
            pairs = ((a, b) for a in range(k_in, p.size) for b in range(a + 1, p.size))
            todo.extend(q for q in (reference_swap(p, a, b) for a, b in pairs) if q is not None)
            todo = [q for q in todo if np.array_equal(counts(q), start)]
    e = np.array(list(energies.values()))
    temp = float(np.std(e))
    sub.schedule[:] = temp
    index = {key: i for i, key in enumerate(energies)}
    visits = np.zeros(e.size)
    for _ in range(50_000):
        kernel.anneal_block(model, sub, 30)
        visits[index[sub.parent.tobytes()]] += 1
    boltzmann = np.exp(-(e - e.min()) / temp)
    boltzmann /= boltzmann.sum()
    assert e.size >= 10 and boltzmann.max() < 0.5, (e.size, part.n_terminals, part.n_inlets)
    assert 0.5 * np.abs(visits / visits.sum() - boltzmann).sum() < 0.03


def test_a_parts_moves_follow_the_whole_rounds_schedule(monkeypatch):
    """A part proposing n moves while the round runs ``span`` steps starts each leg where the
    whole tree's schedule stands at that share of the span, and ends with n steps counted."""
    starts = []

    def record(model, state, n):
        starts.append((int(state.counters[kernel.COUNTER_STEP]), n))
        state.counters[kernel.COUNTER_STEP] += n

    monkeypatch.setattr(kernel, "anneal_block", record)
    problem = make_problem("tissue=sphere", "n_terminals=16", "anneal=fast")
    state = engine.initial_state(problem, seed=3)
    state.counters[kernel.COUNTER_STEP] = 1_000
    part = max(parts.make_parts(problem, state, 2, np.array([0.1, 0.2, 0.3])), key=lambda p: p.n_terminals)
    sub = parts.part_state(problem, problem.model, state, part, engine.initial_state(problem, 7).rng)
    counters = parts.anneal_part((parts.part_model(problem.model, part), sub, 6_400, 64_000))[4]
    assert len(starts) == parts.SCHEDULE_LEGS
    assert [s for s, _ in starts] == [1_000 + 1_000 * leg for leg in range(parts.SCHEDULE_LEGS)]
    assert sum(n for _, n in starts) == 6_400
    assert counters[kernel.COUNTER_STEP] == 1_000 + 6_400
