"""The exclusion term on a grid of its own, fixed in metres (tissue.exclusion_voxel_size): the
same sums whatever the supply grid, running sums against full recomputation, the store, the
default (null) unchanged bit for bit, and bad input."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import xarray as xr
from helpers import assert_running_equals_full, make_problem

from vasc_pipeline import config, costs, engine, job, kernel, sweep
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.physics import cost_tables
from vasc_pipeline.model.tissue import TissueError, build_tissue
from vasc_pipeline.model.tissue.grid import resampled_exclusion_grid
from vasc_pipeline.store import RunStore

BOX = (0.04, 0.04, 0.02)  # m
EXCLUSION_VOXEL = 1.5e-3  # m


def box_problem(supply_voxel: float, *extra: str):
    return make_problem(
        "tissue=box",
        "n_terminals=40",
        f"tissue.voxel_size={supply_voxel}",
        f"tissue.exclusion_voxel_size={EXCLUSION_VOXEL}",
        "anneal=fast_v1",
        *extra,
    )


def hand_exclusion(problem, i0: int, i1: int, j: int, k: int) -> float:
    """sum_v (D_v L_v)^6 of the segment from the centre of exclusion voxel (i0, j, k) to that of
    (i1, j, k), i0 < i1, by hand: the box's voxels are those whose centre lies in [0, size], a
    voxel's depth in a box is its distance to the nearest outside voxel along an axis, and the
    centre-line lies half a voxel in each end voxel and a whole one in the others."""
    h, origin = EXCLUSION_VOXEL, problem.tissue.exclusion_grid.origin
    shape = problem.tissue.exclusion_grid.shape[::-1]  # x, y, z
    inside = [
        np.flatnonzero((origin[a] + h * np.arange(shape[a]) >= 0) & (origin[a] + h * np.arange(shape[a]) <= BOX[a]))
        for a in range(3)
    ]

    def depth(index, axis):  # voxels to the first outside voxel, whichever side is nearer
        return min(index - inside[axis][0] + 1, inside[axis][-1] - index + 1)

    total = 0.0
    for i in range(i0, i1 + 1):
        d = min(depth(i, 0), depth(j, 1), depth(k, 2))
        piece = 0.5 if i in (i0, i1) else 1.0
        total += (d * piece) ** 6
    return total


def test_one_segment_sums_the_same_by_hand_on_two_supply_grids():
    coarse, fine = box_problem(2.0e-3), box_problem(1.0e-3)
    assert coarse.tissue.voxel_size != fine.tissue.voxel_size
    assert coarse.model.depth_voxel_size == fine.model.depth_voxel_size == EXCLUSION_VOXEL
    grid = coarse.tissue.exclusion_grid
    np.testing.assert_array_equal(grid.distance, fine.tissue.exclusion_grid.distance)
    i0, i1, j, k = 4, 20, grid.shape[1] // 2, grid.shape[0] // 2
    p0, p1 = (grid.origin + EXCLUSION_VOXEL * np.array([i, j, k]) for i in (i0, i1))
    expected = hand_exclusion(coarse, i0, i1, j, k)
    assert expected > 1e3  # deep voxels: the test would see a wrong depth
    for problem in (coarse, fine):
        assert kernel.segment_exclusion(problem.model, p0, p1) == pytest.approx(expected, rel=1e-12)
        assert costs.exclusion_sum(p0, p1, problem.tissue.exclusion_grid) == pytest.approx(expected, rel=1e-12)
    # And on the supply grids themselves (null: today's model) they differ, as h^-7 would have it.
    on_own_grids = [
        kernel.segment_exclusion(make_problem("tissue=box", f"tissue.voxel_size={h}").model, p0, p1)
        for h in (2e-3, 1e-3)
    ]
    assert on_own_grids[1] > 50 * on_own_grids[0]


DEFAULT_HEART_GRID = config.to_run_config(config.compose([])).tissue.exclusion_voxel_size


def test_the_heart_default_is_a_fixed_grid():
    assert DEFAULT_HEART_GRID == pytest.approx(build_tissue("heart", 500).voxel_size, rel=1e-12)


@pytest.mark.parametrize("fixed", [DEFAULT_HEART_GRID, 5.0e-4], ids=["default", "0.5mm"])
def test_a_fixed_tree_costs_the_same_exclusion_on_the_hearts_of_n_500_and_6000(fixed):
    """One tree, the tissues that N = 500 and N = 6000 build (supply voxels 1.15 and 0.50 mm):
    the same exclusion within 10 % on one fixed grid (the default's, and a finer one), against
    ~300x on the supply grids."""
    tissues = {n: build_tissue("heart", n, exclusion_voxel_size=fixed) for n in (500, 6000)}
    assert tissues[500].voxel_size > 2 * tissues[6000].voxel_size
    problem = make_problem("tissue=heart", "n_terminals=500", "anneal=fast_v1")
    tree = engine.tree_of(problem, engine.initial_state(problem, 0))
    tables = cost_tables(problem.physics)
    seg = [i for i in np.flatnonzero(tree.parent >= 0) if tables.exclusion[tree.n_downstream[i]] > 0]

    def exclusion(grid):
        return sum(
            tables.exclusion[tree.n_downstream[i]]
            * costs.exclusion_sum(tree.position[i], tree.position[tree.parent[i]], grid)
            for i in seg
        )

    fixed_grid = [exclusion(tissues[n].exclusion_grid) for n in (500, 6000)]
    supply_grid = [exclusion(tissues[n]) for n in (500, 6000)]
    assert fixed_grid[0] > 0 and abs(fixed_grid[1] / fixed_grid[0] - 1.0) < 0.10
    assert supply_grid[1] / supply_grid[0] > 100


def test_running_sums_equal_full_recomputation_after_a_million_moves_on_a_grid_of_its_own():
    steps = 1_000_000
    problem = make_problem(
        "tissue=heart",
        "n_terminals=120",
        "tissue.exclusion_voxel_size=3e-3",
        "anneal=fast_v1",
        "anneal.T_start=1e-2",
        "anneal.T_end=1e-9",
        f"anneal.steps={steps}",
    )
    assert problem.model.depth_voxel_size == 3e-3 != problem.tissue.voxel_size
    assert problem.model.depth_index.shape != problem.tissue.shape
    state = engine.initial_state(problem, seed=5)
    engine.run_block(problem, state, steps)
    assert state.counters[kernel.COUNTER_SWAP_ACCEPTED] > 0
    running = assert_running_equals_full(problem, state)
    assert running["exclusion"] > 0


def test_the_coarse_phase_coarsens_the_exclusion_grid():
    problem = box_problem(2.0e-3, "anneal.coarse_exclusion_factor=2", "anneal.coarse_exclusion_phase=0.4")
    assert problem.coarse_model.depth_voxel_size == 2 * EXCLUSION_VOXEL
    coarse = problem.tissue.exclusion_grid.coarsened(2)
    np.testing.assert_array_equal(
        problem.coarse_model.depth_values[problem.coarse_model.depth_index].clip(0), coarse.distance
    )


def test_a_mask_is_resampled_onto_the_exclusion_grid():
    """A user's mask exists only as voxels: its exclusion domain is sampled at the new grid's
    centres. Onto a grid twice as fine, each voxel becomes eight of the same value."""
    t = build_tissue("box", 40, voxel_size=2e-3)
    fine = resampled_exclusion_grid(t, 1e-3)
    assert fine.voxel_size == 1e-3 and fine.shape == tuple(2 * s for s in t.shape)
    lo, _ = t.bounds
    np.testing.assert_allclose(fine.origin, lo + 0.5e-3)
    domain = fine.distance > 0
    np.testing.assert_array_equal(domain, np.kron(t.exclusion, np.ones((2, 2, 2), dtype=np.uint8)) == 1)
    assert fine.distance.max() == pytest.approx(2 * t.distance.max(), abs=1.0)


def test_null_keeps_the_supply_grid_bit_for_bit():
    """The key at null (the neutral value old stores lack) runs today's model: the final state of
    a fixed-seed run equals the one recorded before the key existed."""
    overrides = [
        "tissue=heart",
        "tissue.exclusion_voxel_size=null",
        "n_terminals=80",
        "anneal=fast_v1",
        "anneal.coarse_exclusion_factor=2",
        "anneal.coarse_exclusion_phase=0.4",
        "anneal.steps=200000",
    ]
    assert config.to_run_config(config.compose(overrides)).tissue.exclusion_voxel_size is None
    problem = make_problem(*overrides)
    assert problem.tissue.exclusion_grid.distance is problem.tissue.distance
    state = engine.initial_state(problem, 3)
    engine.run_block(problem, state, 200_000)
    digest = hashlib.sha256()
    for name in engine.CHECKPOINT_FIELDS:
        digest.update(np.ascontiguousarray(getattr(state, name)).tobytes())
    # recorded with the code before tissue.exclusion_voxel_size existed
    assert digest.hexdigest() == "f4bf89479e97484849d4ef2c54e53fc692211dde2a68129094e2172345c0329c"


def test_the_store_keeps_the_exclusion_grid_it_used(tmp_path):
    cfg = config.compose(
        [
            "tissue=box",
            "n_terminals=12",
            f"tissue.exclusion_voxel_size={EXCLUSION_VOXEL}",
            "anneal=fast_v1",
            "anneal.steps=20000",
            f"output_dir={tmp_path}",
        ]
    )
    (j,) = sweep.expand(cfg)
    job.run_job(j)
    store = RunStore.open(j.store, mode="r")
    tissue = store.group["tissue"]
    assert tissue.attrs["exclusion_voxel_size"] == EXCLUSION_VOXEL != tissue.attrs["voxel_size"]
    distance = tissue["distance"]
    assert distance.attrs["voxel_size"] == EXCLUSION_VOXEL
    assert distance.shape != tissue["mask"].shape
    problem = engine.build_problem(cfg)
    np.testing.assert_array_equal(distance[...], problem.tissue.exclusion_grid.distance)
    ds = xr.open_zarr(j.store, group="tissue")
    assert ds["distance"].dims == ("z_exclusion", "y_exclusion", "x_exclusion")
    assert ds["mask"].dims == ("z", "y", "x")
    c = store.attrs["cost_recomputed"]
    assert c["exclusion"] == pytest.approx(store.attrs["cost"]["exclusion"], rel=1e-9)


@pytest.mark.parametrize("value", [0, -1e-3, "nan", "inf"])
def test_a_bad_exclusion_voxel_size_names_the_key(value):
    with pytest.raises(ConfigError, match=r"tissue\.exclusion_voxel_size must be a finite number"):
        make_problem("tissue=box", f"tissue.exclusion_voxel_size={value}")


def test_an_exclusion_grid_too_large_for_memory_names_the_key():
    with pytest.raises(TissueError, match=r"tissue\.exclusion_voxel_size=1e-06 m: .*GiB"):
        make_problem("tissue=heart", "tissue.exclusion_voxel_size=1e-6")
