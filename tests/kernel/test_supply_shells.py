"""Supply shells (kernel.supply._shell_*): a small terminal move's supply change from the voxels near
its sphere's surface equals the row-by-row change and the NumPy reference, bit for bit, and a
run with shells is the run without them."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from helpers import FAST_2026_12, assert_block_splits_bit_identical, assert_running_equals_full, make_problem

from vasc_pipeline import costs, engine, kernel

NO_TARGET = np.zeros((0, 0, 0), dtype=np.uint8)  # the Model's coverage targets without a demand map


def _counts(shape=(24, 26, 28), seed=0):
    """A count map with counts 0-3 in tissue and -1 (no tissue) in a slab and a random tenth."""
    rng = np.random.default_rng(seed)
    supply = rng.integers(0, 4, size=shape).astype(np.int16)
    supply[:, :, :3] = -1
    supply[rng.random(shape) < 0.1] = -1
    return supply


def _brute_force_shell(supply, rho, centre, width):
    """Tissue voxels whose centre lies within ``width`` of the sphere's surface (x, y, z)."""
    k, j, i = np.nonzero(supply >= 0)
    distance = np.sqrt((i - centre[0]) ** 2 + (j - centre[1]) ** 2 + (k - centre[2]) ** 2)
    near = np.abs(distance - rho) <= width
    return {tuple(v) for v in np.stack([i, j, k], axis=1)[near]}


def _shell(supply, rho, centre, width):
    """(voxels, band ends, width) of the shell around ``centre``."""
    voxels = np.zeros((kernel.shell_capacity(rho, width), 3), dtype=np.int16)
    bands = np.zeros(kernel.SHELL_BANDS, dtype=np.int64)
    n = kernel.supply._shell_build(supply, rho, *centre, width, voxels, bands)
    assert n == bands[-1] >= 0
    return voxels, bands, width


@pytest.mark.parametrize("rho", [2.0, 3.997, 5.0])
def test_shell_lists_every_tissue_voxel_near_the_surface_band_by_band(rho):
    supply = _counts()
    rng = np.random.default_rng(1)
    for centre in [np.array([12.0, 13.0, 11.0]), np.array([3.5, 0.5, 20.25]), *rng.uniform(0, 24, (30, 3))]:
        for width in (0.05, 0.3):
            voxels, bands, _ = _shell(supply, rho, centre, width)
            listed = {tuple(v) for v in voxels[: bands[-1]].astype(int)}
            assert len(listed) == bands[-1]  # no voxel twice
            assert _brute_force_shell(supply, rho, centre, width) <= listed
            assert all(supply[k, j, i] >= 0 for i, j, k in listed)
            # "perhaps a few more": only those within rounding of the width
            assert listed <= _brute_force_shell(supply, rho, centre, width + 1e-5)
            # band b: distances to the surface from b width / B on (the last band up to the width)
            first = 0
            for b, end in enumerate(bands):
                i, j, k = voxels[first:end].T.astype(float)
                surface = np.abs(np.sqrt((i - centre[0]) ** 2 + (j - centre[1]) ** 2 + (k - centre[2]) ** 2) - rho)
                assert np.all(surface >= b * width / bands.size - 1e-12)
                assert np.all(surface <= (b + 1) * width / bands.size + 1e-12) or b == bands.size - 1
                first = end
    # more than fit: not a shell
    bands = np.zeros(kernel.SHELL_BANDS, dtype=np.int64)
    assert kernel.supply._shell_build(supply, rho, 12.0, 13.0, 11.0, 0.3, np.zeros((5, 3), dtype=np.int16), bands) == -1


def _change_both_ways(supply, rho, shell, centre, old, new):
    """(shell change, row change) of a sphere moved from ``old`` to ``new``, each also written
    into a copy of ``supply``; asserts that the written maps are equal, and that the shell's
    change is the same over the bands the move reaches and over all of them."""
    reach = np.linalg.norm(old - centre) + np.linalg.norm(new - old) + 1e-6
    by_shell, by_rows = supply.copy(), supply.copy()
    d_shell = kernel.supply._shell_change(by_shell, NO_TARGET, rho, *shell, reach, *old, *new, True)
    d_rows = kernel.supply._sphere_rows(by_rows, NO_TARGET, rho, *old, *new, True)
    np.testing.assert_array_equal(by_shell, by_rows)
    assert d_shell == kernel.supply._shell_change(supply, NO_TARGET, rho, *shell, shell[2], *old, *new, False)
    return d_shell, d_rows


def test_shell_change_equals_rows_and_the_numpy_reference():
    base = _counts()
    mask = (base >= 0).astype(np.uint8)
    grid = SimpleNamespace(shape=base.shape, origin=np.zeros(3), voxel_size=1.0, mask=mask)
    rho, width = 3.997, 0.3
    rng = np.random.default_rng(2)
    changed = 0
    for _ in range(300):
        centre = rng.uniform(0, 25, 3)
        # drifted inside the shell, then moved by less than what the drift leaves
        old = centre + rng.uniform(-1, 1, 3) * 0.05
        new = old + rng.uniform(-1, 1, 3) * 0.1
        assert np.linalg.norm(old - centre) + np.linalg.norm(new - old) < width
        others = np.maximum(base, 0).astype(np.int64)  # the other spheres' coverage
        before = others + costs.supply_counts(old[None], grid, rho)
        supply = np.where(mask == 1, before, -1).astype(np.int16)
        d_shell, d_rows = _change_both_ways(supply, rho, _shell(supply, rho, centre, width), centre, old, new)
        assert d_shell == d_rows
        after = others + costs.supply_counts(new[None], grid, rho)
        assert d_shell == costs.supply_cost(after, mask) - costs.supply_cost(before, mask)
        changed += d_shell != 0
    assert changed > 100  # most moves change some voxel's coverage


def test_shell_change_on_exact_ties():
    """Voxel centres exactly on the sphere (integer centre, rho 5: 3-4-0 and 0-0-5 offsets):
    moves by 1e-9 and by nothing decide each of them as the NumPy reference does, on the shell
    and row by row (whose nearly tangent rows, the 0-0-5 ones, the exact test settles)."""
    base = np.maximum(_counts(seed=3), 0)
    mask = np.ones(base.shape, dtype=np.uint8)
    grid = SimpleNamespace(shape=base.shape, origin=np.zeros(3), voxel_size=1.0, mask=mask)
    rho = 5.0
    centre = np.array([12.0, 13.0, 11.0])
    before = base + costs.supply_counts(centre[None], grid, rho)
    supply = before.astype(np.int16)
    shell = _shell(supply, rho, centre, 0.05)
    changes = []
    for step in ([0, 0, 0], [1e-9, 0, 0], [-1e-9, 1e-9, 0], [0, 0, 1e-9], [3e-10, -4e-10, 1e-12]):
        new = centre + np.array(step)
        d_shell, d_rows = _change_both_ways(supply, rho, shell, centre, centre, new)
        after = base + costs.supply_counts(new[None], grid, rho)
        assert d_shell == d_rows == costs.supply_cost(after, mask) - costs.supply_cost(before, mask)
        changes.append(d_shell)
    assert changes[0] == 0 and any(changes[1:])


def _late_problem(*overrides):
    """A short run on FAST_2026_12 whose adapted terminal steps fall below the shells' width."""
    return make_problem(*overrides, *FAST_2026_12, "anneal.steps=300000")


@pytest.mark.parametrize(
    "overrides",
    [("tissue=heart", "n_terminals=150"), ("tissue=plane2d", "n_terminals=80")],
    ids=["heart", "plane2d"],
)
def test_run_with_shells_is_the_run_without(overrides):
    problem = _late_problem(*overrides)
    assert problem.model.supply_shell_width == kernel.SHELL_WIDTH
    final = {}
    for width in (kernel.SHELL_WIDTH, 0.0):
        p = dataclasses.replace(problem, model=problem.model._replace(supply_shell_width=width))
        state = engine.initial_state(p, seed=4)
        engine.run_block(p, state, problem.total_steps)
        if width:
            assert np.count_nonzero(state.scratch_shell_frame[:, 3] > 0) > problem.physics.n_terminals // 2  # in use
            assert_running_equals_full(p, state)
        final[width] = engine.state_arrays(state)
    for name, value in final[kernel.SHELL_WIDTH].items():
        np.testing.assert_array_equal(value, final[0.0][name], err_msg=name)


def test_shells_do_not_change_block_splits():
    """Restoring a state drops its shells (derived, never checkpointed): same run either way."""
    problem = _late_problem("tissue=heart", "n_terminals=150")
    n = problem.total_steps
    assert_block_splits_bit_identical(problem, 4, [n // 2, n // 8, n // 8, n - 3 * (n // 4)])
