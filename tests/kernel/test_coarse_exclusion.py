"""The exclusion term on a coarse depth map early in a run (anneal.coarse_exclusion_*): the
coarse map, how close its sums come to the true ones, running sums in both parts, the switch
across block splits, checkpoints and a SIGKILL, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    FAST_2026_12,
    TRUE_EXCLUSION_MAP,
    assert_block_splits_bit_identical,
    assert_killed_job_resumes_bit_identically,
    make_problem,
)

from vasc_pipeline import config, engine, kernel
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.tissue import ExclusionGrid

COARSE = ("anneal.coarse_exclusion_factor=2", "anneal.coarse_exclusion_phase=0.4")


@pytest.mark.parametrize("shape, factor", [((13, 22, 31), 2), ((9, 10, 20), 3), ((1, 37, 41), 2)], ids=str)
def test_coarse_map_holds_each_blocks_deepest_voxel(shape, factor):
    rs = np.random.default_rng(1)
    distance = np.where(rs.random(shape) < 0.5, np.sqrt(rs.integers(1, 200, shape)), 0.0).astype(np.float32)
    origin, h = np.array([0.1, -0.2, 0.3]), 0.5
    fields = kernel.exclusion_fields(ExclusionGrid(distance, origin, h).coarsened(factor))
    fz = 1 if shape[0] == 1 else factor
    got = np.maximum(fields["depth_values"][fields["depth_index"]], 0.0)  # leap markers are -1: outside
    assert got.shape == tuple(-(-s // f) for s, f in zip(shape, (fz, factor, factor)))
    for z, y, x in [(0, 0, 0), tuple(s - 1 for s in got.shape), (got.shape[0] // 2, 1, got.shape[2] // 2)]:
        block = distance[z * fz : (z + 1) * fz, y * factor : (y + 1) * factor, x * factor : (x + 1) * factor]
        assert got[z, y, x] == np.float32(block.max() * np.float32(factor ** (1 / 6)))
    assert fields["depth_voxel_size"] == factor * h
    # Coarse voxel [0, 0, 0]'s centre is the centre of the fine voxels it covers.
    np.testing.assert_allclose(fields["depth_origin"], origin + 0.5 * (np.array([factor, factor, fz]) - 1) * h)


@pytest.mark.parametrize("factor", [2, 3])
def test_coarse_sums_approximate_the_true_ones_on_the_heart(factor):
    """Long segments through the heart (an initial tree's): the coarse map's sums in the true
    units, with no weight changed. Each is within a small factor of the true sum, and over the
    tree within 30 % (the 6th power makes single segments scatter)."""
    problem = make_problem("tissue=heart", "n_terminals=300", *FAST_2026_12)
    state = engine.initial_state(problem, 0)
    coarse = problem.model._replace(**kernel.exclusion_fields(problem.tissue.exclusion_grid.coarsened(factor)))
    pos, k = state.position, problem.model.n_inlets
    sums = np.array(
        [
            (kernel.segment_exclusion(problem.model, pos[i], pos[p]), kernel.segment_exclusion(coarse, pos[i], pos[p]))
            for i, p in enumerate(state.parent)
            if i >= k
        ]
    )
    deep = sums[:, 0] > 1e6  # segments well inside the exclusion domain
    assert deep.sum() > 100
    ratio = sums[deep, 1] / sums[deep, 0]
    assert 0.5 < np.median(ratio) < 2.0
    assert 0.7 < sums[:, 1].sum() / sums[:, 0].sum() < 1.3


def _running_equals(problem, model, state):
    fresh = engine.restore_state(problem, engine.state_arrays(state))
    kernel.initialise(model, fresh)
    np.testing.assert_allclose(state.costs + state.compensation, fresh.costs + fresh.compensation, rtol=1e-9)
    np.testing.assert_array_equal(state.seg_exclusion, fresh.seg_exclusion)


def test_fast_sums_its_coarse_phase_on_a_coarser_map_and_the_other_schedules_never():
    steps = ("tissue=heart", "n_terminals=120", "anneal.steps=1000000")
    fast = make_problem(*steps, "anneal=fast")
    a = fast.config.anneal  # the preset's own phase and factor, whatever values it moves to
    assert fast.coarse_steps == round(a.coarse_exclusion_phase * 1_000_000)
    assert fast.coarse_model.depth_voxel_size == a.coarse_exclusion_factor * fast.model.depth_voxel_size
    for schedule in ("fast_v1", "paper"):
        other = make_problem(*steps, f"anneal={schedule}")
        assert other.coarse_model is None and other.coarse_steps == 0


def test_running_sums_follow_the_coarse_map_then_the_true_one():
    steps = 1_000_000
    problem = make_problem("tissue=heart", "n_terminals=120", *FAST_2026_12, f"anneal.steps={steps}", *COARSE)
    assert problem.coarse_steps == 400_000
    state = engine.initial_state(problem, 5)
    _running_equals(problem, problem.coarse_model, state)
    engine.run_block(problem, state, 399_999)
    _running_equals(problem, problem.coarse_model, state)
    assert state.costs[kernel.EXCLUSION] > 0
    engine.run_block(problem, state, 1)  # the proposal that ends the coarse part switches maps
    _running_equals(problem, problem.model, state)
    engine.run_block(problem, state, steps - 400_000)
    _running_equals(problem, problem.model, state)
    # The same run on the true map throughout: the same schedule, another trajectory.
    plain = make_problem("tissue=heart", "n_terminals=120", *FAST_2026_12, f"anneal.steps={steps}", *TRUE_EXCLUSION_MAP)
    reference = engine.initial_state(plain, 5)
    np.testing.assert_array_equal(reference.schedule, state.schedule)
    assert plain.coarse_model is None and plain.coarse_steps == 0


def test_block_splits_and_checkpoint_round_trips_across_the_switch_are_bit_identical():
    problem = make_problem("tissue=sphere", "n_terminals=40", *FAST_2026_12, "anneal.steps=60000", *COARSE)
    # The coarse part ends at 24_000, between blocks.
    assert_block_splits_bit_identical(problem, 5, (1, 9_999, 14_000, 0, 7_000, 2, 28_998))
    # With packing first the coarse part follows it: the same across a split inside either part.
    packed = make_problem(
        "tissue=sphere", "n_terminals=40", *FAST_2026_12, "anneal.steps=60000", *COARSE,
        "anneal.packing_steps_per_terminal=250",
    )  # fmt: skip
    assert packed.coarse_steps == 10_000 + 20_000
    assert_block_splits_bit_identical(packed, 2, (9_000, 2_000, 20_000, 29_000))


@pytest.mark.integration
@pytest.mark.slow  # ~18 s; the sweep-level SIGKILL test resumes in the default suite
def test_a_run_killed_in_the_coarse_part_resumes_bit_identically(tmp_path):
    overrides = [
        "tissue=sphere",
        "n_terminals=300",
        *FAST_2026_12,
        "anneal.steps=1000000",
        "anneal.coarse_exclusion_factor=3",
        "anneal.coarse_exclusion_phase=0.6",
        "anneal.trace_every=20000",
        "checkpoint.every_seconds=0.01",
        f"output_dir={tmp_path}",
    ]
    assert_killed_job_resumes_bit_identically(overrides, kill_before=600_000)


BOTH = "anneal.coarse_exclusion_factor and anneal.coarse_exclusion_phase"
PHASE = r"phase must lie in \(0, 1\)"


@pytest.mark.parametrize(
    "schedule, overrides, field",
    [
        ("fast", "anneal.coarse_exclusion_phase=null", BOTH),  # fast sets both (2, 0.4) ...
        ("fast", "anneal.coarse_exclusion_factor=null", BOTH),
        ("fast_v1", "anneal.coarse_exclusion_factor=2", BOTH),  # ... fast_v1 neither
        ("fast_v1", "anneal.coarse_exclusion_phase=0.3", BOTH),
        ("fast", "anneal.coarse_exclusion_factor=1", r"factor must be an integer in \[2, 8"),
        ("fast", "anneal.coarse_exclusion_factor=9", r"factor must be an integer in \[2, 8"),
        ("fast", "anneal.coarse_exclusion_factor=2.5", "anneal.coarse_exclusion_factor"),
        ("fast", "anneal.coarse_exclusion_phase=0", PHASE),
        ("fast_v1", "anneal.coarse_exclusion_factor=2 anneal.coarse_exclusion_phase=1.0", PHASE),
    ],
)
def test_bad_coarse_exclusion_settings_name_the_field(schedule, overrides, field):
    with pytest.raises(ConfigError, match=field.replace("anneal.", r"anneal\.")):
        config.compose([f"anneal={schedule}", *overrides.split()])
