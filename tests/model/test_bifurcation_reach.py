"""``tissue.bifurcation_reach``: bifurcations kept within a distance of the exclusion domain."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import (
    TRUE_EXCLUSION_MAP,
    assert_moves_of_every_kind_accepted_and_rejected,
    assert_running_equals_full,
    make_problem,
)

from vasc_pipeline import engine, kernel
from vasc_pipeline.config import ConfigError, compose, to_run_config, validate
from vasc_pipeline.model.tree import KIND_BIFURCATION

COLD = ("anneal.T_start=1e-2", "anneal.T_end=1e-9")


def bifurcation_positions(problem, state):
    tree = engine.tree_of(problem, state)
    return tree.position[tree.kind == KIND_BIFURCATION]


def test_the_region_is_the_exclusion_domain_grown_by_the_reach():
    tissue = make_problem("tissue=heart", "n_terminals=100").tissue
    h = tissue.voxel_size
    assert np.array_equal(tissue.bifurcation_region(0.0), tissue.exclusion)
    one, three = tissue.bifurcation_region(1.01 * h), tissue.bifurcation_region(3.01 * h)
    assert np.all(one >= tissue.exclusion) and np.all(three >= one)
    assert one.sum() > tissue.exclusion.sum() and three.sum() > one.sum()
    # One voxel out: the region reaches exactly the face neighbours of the domain.
    grown = tissue.exclusion.astype(bool)
    for axis in range(3):
        for shift in (1, -1):
            grown |= np.roll(tissue.exclusion, shift, axis=axis).astype(bool)
    assert np.array_equal(one.astype(bool), grown)


def test_points_outside_a_region_move_to_its_nearest_voxel_and_the_others_stay():
    tissue = make_problem("tissue=sphere", "n_terminals=50").tissue
    region = tissue.bifurcation_region(0.0)
    lo, hi = tissue.bounds
    inside = tissue.origin + np.array(np.argwhere(region)[0][::-1]) * tissue.voxel_size
    corner = lo + 1e-6  # the grid's corner, far outside the sphere
    moved = tissue.move_into(region, np.array([inside, corner]))
    np.testing.assert_array_equal(moved[0], inside)
    assert tissue.contains(moved[1:], region).all()
    # The nearest region voxel to the corner: no region voxel centre is closer.
    centres = tissue.origin + np.argwhere(region)[:, ::-1] * tissue.voxel_size
    nearest = np.linalg.norm(centres - corner, axis=1).min()
    assert np.linalg.norm(moved[1] - corner) <= nearest + 1e-12


def test_bifurcations_start_and_stay_in_the_region_with_running_sums_exact():
    steps = 1_000_000
    problem = make_problem(
        "tissue=heart", "n_terminals=120", *COLD, f"anneal.steps={steps}", "tissue.bifurcation_reach=0"
    )
    region = problem.model.bifurcation_region
    assert np.array_equal(region, problem.tissue.exclusion)
    state = engine.initial_state(problem, seed=4)
    assert problem.tissue.contains(bifurcation_positions(problem, state), region).all()
    assert_running_equals_full(problem, state)
    engine.run_block(problem, state, steps)
    assert problem.tissue.contains(bifurcation_positions(problem, state), region).all()
    assert_moves_of_every_kind_accepted_and_rejected(state)
    assert_running_equals_full(problem, state)
    # Without the reach, the same seed puts bifurcations outside the heart: the option matters.
    free = make_problem("tissue=heart", "n_terminals=120", *COLD, f"anneal.steps={steps}")
    free_state = engine.initial_state(free, seed=4)
    engine.run_block(free, free_state, steps)
    assert not problem.tissue.contains(bifurcation_positions(free, free_state), region).all()


def test_a_bifurcation_move_out_of_the_region_is_illegal():
    problem = make_problem(
        "tissue=sphere",
        "n_terminals=12",
        "anneal.T_start=1e300",
        "anneal.T_end=1e299",
        "anneal.steps=10",
        "tissue.bifurcation_reach=0",
        *TRUE_EXCLUSION_MAP,  # the kernel is called below with problem.model
    )
    state = engine.initial_state(problem, seed=2)
    lo, _ = problem.tissue.bounds
    bifurcation = problem.model.n_inlets + problem.model.n_terminals
    corner = lo + 1e-6  # inside the grid's box, outside the sphere
    assert kernel.translate_node(problem.model, state, bifurcation, corner, 1e300) == kernel.ILLEGAL
    centre = lo + 0.5 * (problem.tissue.bounds[1] - lo)  # the sphere's centre
    assert kernel.translate_node(problem.model, state, bifurcation, centre, 1e300) == kernel.ACCEPTED
    assert_running_equals_full(problem, state)


def test_a_reach_covering_the_grid_changes_nothing():
    # Null and a reach larger than the grid allow the same positions: identical runs, bit for bit.
    overrides = ("tissue=heart", "n_terminals=60", *COLD, "anneal.steps=200000")
    runs = []
    for reach in ("null", "1.0"):
        problem = make_problem(*overrides, f"tissue.bifurcation_reach={reach}")
        state = engine.initial_state(problem, seed=3)
        engine.run_block(problem, state, 200_000)
        runs.append(state)
    assert runs[0].counters[kernel.COUNTER_STEP] == 200_000
    for name in engine.CHECKPOINT_FIELDS:
        np.testing.assert_array_equal(getattr(runs[0], name), getattr(runs[1], name), err_msg=name)


def test_the_packing_phase_leaves_bifurcations_in_the_region():
    problem = make_problem(
        "tissue=heart",
        "n_terminals=60",
        *COLD,
        "anneal.steps=100000",
        "anneal.packing_steps_per_terminal=500",
        "tissue.bifurcation_reach=0",
    )
    state = engine.initial_state(problem, seed=1)
    engine.run_block(problem, state, int(problem.model.pack_steps) + 1000)
    assert problem.tissue.contains(bifurcation_positions(problem, state), problem.model.bifurcation_region).all()
    assert_running_equals_full(problem, state)


@pytest.mark.parametrize(
    "overrides, message",
    [
        (["tissue.bifurcation_reach=-0.001"], "tissue.bifurcation_reach must be a length >= 0"),
        (["tissue.bifurcation_reach=.inf"], "tissue.bifurcation_reach"),
        (["method=cco", "tissue.bifurcation_reach=0.002"], "method=cco"),
        (["method=cco", "tissue.bifurcations_in_cavities=false"], "method.avoid_cavities"),
        (["tissue.bifurcations_in_cavities=maybe"], "tissue.bifurcations_in_cavities"),
    ],
)
def test_bad_reach_is_refused_naming_the_field(overrides, message):
    with pytest.raises(ConfigError, match=message):
        validate(to_run_config(compose(overrides)))


def test_without_cavities_no_bifurcation_starts_or_moves_into_a_ventricle():
    steps = 300_000
    overrides = ("tissue=heart", "n_terminals=120", *COLD, f"anneal.steps={steps}")
    problem = make_problem(*overrides, "tissue.bifurcation_reach=0", "tissue.bifurcations_in_cavities=false")
    tissue, region = problem.tissue, problem.model.bifurcation_region
    np.testing.assert_array_equal(region, tissue.bifurcation_region(0.0) & ~tissue.cavity)
    assert tissue.cavity.any()
    # The random start puts a bifurcation at its terminals' mean: most of them inside a ventricle
    # (90 of 118 here); with the cavities left out they start on the heart's wall.
    allowed = make_problem(*overrides, "tissue.bifurcation_reach=0")
    start = bifurcation_positions(allowed, engine.initial_state(allowed, seed=2))
    assert tissue.contains(start, tissue.cavity.astype(np.uint8)).mean() > 0.5
    state = engine.initial_state(problem, seed=2)
    engine.run_block(problem, state, steps)
    assert_moves_of_every_kind_accepted_and_rejected(state)
    at = bifurcation_positions(problem, state)
    assert tissue.contains(at, region).all() and not tissue.contains(at, tissue.cavity.astype(np.uint8)).any()
    assert_running_equals_full(problem, state)
    # With the reach unset the region is the whole box but the cavities.
    anywhere = make_problem(*overrides, "tissue.bifurcations_in_cavities=false").model.bifurcation_region
    np.testing.assert_array_equal(anywhere, (~tissue.cavity).astype(np.uint8))


def test_cavities_allowed_is_the_run_before_the_key():
    with_key = make_problem("tissue=heart", "n_terminals=60", "tissue.bifurcations_in_cavities=true")
    without = make_problem("tissue=heart", "n_terminals=60")
    assert with_key.model.bifurcation_region.shape == without.model.bifurcation_region.shape == (0, 0, 0)
