"""One tree annealed in parts (anneal.parts, engine.parts): the parts' changes add up to the
whole tree's exactly, frozen nodes stay put, the result does not depend on how the parts are
run, a killed run resumes to the same tree, and parts = 1 is the serial anneal."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from helpers import assert_killed_job_resumes_bit_identically, assert_running_equals_full, make_problem

from vasc_pipeline import config, engine, kernel
from vasc_pipeline.config import ConfigError
from vasc_pipeline.engine import parts

SPHERE = ["tissue=sphere", "n_terminals=400", "anneal.steps=2000000"]


@pytest.fixture(scope="module")
def annealed():
    """A sphere tree half-way through its anneal, its sums recomputed."""
    problem = make_problem(*SPHERE)
    state = engine.initial_state(problem, 0)
    engine.run_block(problem, state, 1_000_000)
    kernel.initialise(problem.model, state)
    return problem, state


def test_the_cut_partitions_the_terminals_into_balanced_parts(annealed):
    problem, state = annealed
    k = 3
    cut = parts.make_parts(problem, state, k, np.array([0.1, 0.2, 0.3]))
    model = problem.model
    terminals = np.concatenate([p.nodes[p.n_inlets : p.n_inlets + p.n_terminals] for p in cut])
    assert np.array_equal(np.sort(terminals), np.arange(model.n_inlets, model.n_inlets + model.n_terminals))
    sizes = [p.n_terminals for p in cut]
    assert max(sizes) <= 1.5 * model.n_terminals / k, sizes
    masks = np.array([p.mask for p in cut], dtype=int)
    assert masks.sum(axis=0).max() <= 1  # the regions' interiors are disjoint
    for p in cut:  # one pseudo-inlet per subtree root, at the root's parent
        assert p.nodes.size == 2 * p.n_terminals
        np.testing.assert_array_equal(p.nodes[: p.n_inlets], state.parent[p.roots])


@pytest.mark.parametrize("leaves", [False, True], ids=["subtrees", "terminals"])
def test_the_parts_changes_add_up_to_the_whole_trees_exactly(annealed, leaves):
    problem, whole = annealed
    state = engine.restore_state(problem, engine.state_arrays(whole))
    before = state.costs + state.compensation
    position = state.position.copy()
    cut = parts.make_parts(problem, state, 2, np.array([0.1, 0.2, 0.3]), leaves)
    start = [parts.part_state(problem, problem.model, state, p, state.rng.copy()) for p in cut]
    results = parts.anneal_parts(problem, problem.model, state, cut, 400_000, 7)
    expected = before.copy()
    for s0, s1 in zip(start, results):
        moved = (s1.costs + s1.compensation) - (s0.costs + s0.compensation)
        counter = kernel.COUNTER_TERMINAL_ACCEPTED if leaves else kernel.COUNTER_SWAP_ACCEPTED
        assert s1.counters[counter] > s0.counters[counter]  # the parts did work
        expected += moved
    parts.merge_parts(problem.model, state, cut, results)
    after = state.costs + state.compensation
    assert after[kernel.SUPPLY] == expected[kernel.SUPPLY]  # integer-valued: exact
    np.testing.assert_allclose(after, expected, rtol=1e-12)
    assert_running_equals_full(problem, state)
    # frozen: the top tree above the parts and every border terminal
    own = np.concatenate([p.nodes[p.n_inlets :] for p in cut])
    top = np.setdiff1d(np.arange(problem.model.n_inlets, state.parent.size), own)
    np.testing.assert_array_equal(state.position[top], position[top])
    for p in cut:
        terminals = p.nodes[p.n_inlets : p.n_inlets + p.n_terminals]
        x, y, z = np.floor((position[terminals] - problem.model.origin) / problem.model.voxel_size + 0.5).astype(int).T
        border = terminals[p.mask[z, y, x] == 0]
        assert border.size > 0
        np.testing.assert_array_equal(state.position[border], position[border])


def test_a_parts_run_does_not_depend_on_how_the_parts_are_run():
    overrides = [*SPHERE, "anneal.parts=2", "anneal.part_phases=8", "anneal.steps=400000", "anneal.trace_every=50000"]
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
        (["anneal.parts=2", "physics.A_p=1"], r"anneal\.parts=2 needs physics\.A_p = 0"),
        (["anneal.part_share=1"], r"anneal\.part_share must lie in \(0, 1\)"),
        (["anneal.part_phases=0"], r"anneal\.part_phases must be an integer in \[1, 100000\]"),
    ],
)
def test_bad_parts_settings_name_the_field(overrides, message):
    with pytest.raises(ConfigError, match=message):
        config.compose([*SPHERE, *overrides])


@pytest.mark.integration
def test_a_sweep_runs_one_tree_in_parts_on_the_clusters_workers(tmp_path):
    """Through the pipeline, on a local cluster of two workers: the parts go to the workers,
    progress names the phase, and the tree is the one the same run makes in one process."""
    import io

    from vasc_pipeline.pipeline import orchestrate
    from vasc_pipeline.store import RunStore

    overrides = [*SPHERE, "anneal.parts=2", "anneal.part_phases=4", "anneal.steps=200000", "anneal.trace_every=50000"]
    log = io.StringIO()
    cluster = ["cluster.n_workers=2", "cluster.dashboard_address=null"]
    cfg = config.compose([*overrides, f"output_dir={tmp_path}", *cluster])
    result = orchestrate.run_sweep(cfg, stream=log, progress_interval=0.0, reduce=False)
    assert result["complete"] and not result["failed"], log.getvalue()
    assert "phase " in log.getvalue() and " in 2 parts" in log.getvalue(), log.getvalue()
    (store,) = (tmp_path / "runs").glob("*.zarr")
    stored = RunStore.open(store, mode="r").read_tree()
    alone = engine.run(config.compose(overrides), seed=0)
    np.testing.assert_array_equal(stored["position"], alone.tree.position)
