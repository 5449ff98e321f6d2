"""The ``mask`` tissue end to end (.npy and Zarr: voxel size, origin, inlets), and ``tissue.q_required``."""

from __future__ import annotations

import math

import numpy as np
import pytest
import zarr
from helpers import assert_running_equals_full, make_problem

from vasc_pipeline import config, engine, job, physics, store, sweep, tissue
from vasc_pipeline.model.tree import check_tree

H = 1e-3  # m
ORIGIN = [0.004, -0.002, 0.001]  # m: [x, y, z] of the centre of voxel [0, 0, 0]


def ball(n: int = 20) -> np.ndarray:
    """A ball of tissue filling an n^3 grid, (z, y, x), with values other than 1 (nonzero = tissue)."""
    z, y, x = np.indices((n, n, n)) - (n - 1) / 2
    return np.where(x**2 + y**2 + z**2 <= (n / 2 - 1) ** 2, 3, 0).astype(np.int16)


def inlet_on_top(data: np.ndarray) -> list[float]:
    """A tissue voxel's centre near the top of the ball, in metres."""
    z, y, x = np.argwhere(data)[np.argmax(np.argwhere(data)[:, 0])]
    return [float(ORIGIN[0] + H * x), float(ORIGIN[1] + H * y), float(ORIGIN[2] + H * z)]


def overrides(path, inlet, *extra: str) -> list[str]:
    return [
        "tissue=mask",
        f"tissue.path={path}",
        f"tissue.inlets=[[{inlet[0]!r},{inlet[1]!r},{inlet[2]!r}]]",
        "n_terminals=16",
        "anneal.steps=20000",
        "anneal.trace_every=10000",
        *extra,
    ]


def assert_grid(t: tissue.Tissue, data: np.ndarray, inlet) -> None:
    assert t.name == "mask" and t.voxel_size == H
    np.testing.assert_array_equal(t.origin, ORIGIN)
    np.testing.assert_array_equal(t.mask, (data != 0).astype(np.uint8))
    np.testing.assert_allclose(t.inlets, [inlet], rtol=0, atol=0)


def test_mask_from_npy_runs_a_job_into_its_store(tmp_path):
    data = ball()
    np.save(tmp_path / "tissue.npy", data)
    inlet = inlet_on_top(data)
    cfg = config.compose(
        overrides(
            tmp_path / "tissue.npy",
            inlet,
            f"tissue.voxel_size={H!r}",
            f"tissue.origin=[{ORIGIN[0]!r},{ORIGIN[1]!r},{ORIGIN[2]!r}]",
            f"output_dir={tmp_path / 'out'}",
        )
    )
    problem = engine.build_problem(cfg)
    assert_grid(problem.tissue, data, inlet)
    (j,) = sweep.expand(cfg)
    assert job.run_job(j)["status"] == "complete"
    run = store.RunStore.open(j.store, mode="r")
    tree = run.read_tree()
    assert tree["position"][0].tolist() == inlet  # the inlet as given, in metres
    n = problem.physics.n_terminals
    terminals = tree["position"][1 : 1 + n]
    assert problem.tissue.contains(terminals).all()
    # voxel indices of the terminals from the configured origin and voxel size: all tissue
    idx = np.floor((terminals - ORIGIN) / H + 0.5).astype(int)
    assert (data[idx[:, 2], idx[:, 1], idx[:, 0]] != 0).all()
    result = engine.run(cfg, seed=j.coords["seed"])
    np.testing.assert_array_equal(result.tree.parent, tree["parent"])  # the store holds the run
    np.testing.assert_array_equal(result.tree.position, tree["position"])


def test_mask_from_zarr_takes_voxel_size_and_origin_from_its_attrs(tmp_path):
    data = ball()
    root = zarr.open_group(str(tmp_path / "scan.zarr"), mode="w")
    arr = root.create_array("segmentation", shape=data.shape, dtype=data.dtype)
    arr[...] = data
    arr.attrs.update(voxel_size=H, origin=ORIGIN)
    inlet = inlet_on_top(data)
    o = overrides(
        tmp_path / "scan.zarr",
        inlet,
        "tissue.array=segmentation",
        "tissue.voxel_size=null",
        "tissue.origin=null",
    )
    problem = make_problem(*o)
    assert_grid(problem.tissue, data, inlet)
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, state, 20000)
    assert_running_equals_full(problem, state)
    check_tree(engine.tree_of(problem, state), problem.tissue)
    # the config wins over the attrs
    moved = make_problem(*o[:-2], "tissue.voxel_size=0.0015", "tissue.origin=[0.0,0.0,0.0]")
    assert moved.tissue.voxel_size == 0.0015 and moved.tissue.origin.tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(tissue.TissueError, match="Zarr group"):
        tissue.build_tissue("mask", 16, path=str(tmp_path / "scan.zarr"), inlets=[inlet])


def test_q_required_sets_the_supply_radius_and_the_voxel_size():
    base = make_problem("tissue=sphere", "n_terminals=100")
    q0 = base.physics.total_flow
    volume = base.tissue.measure  # m^3, of the voxelised ball
    # q_required = Q0 / V: the default (the N supply spheres fill the tissue)
    fill = make_problem("tissue=sphere", "n_terminals=100", f"tissue.q_required={q0 / volume!r}")
    assert fill.physics.supply_radius == pytest.approx(base.physics.supply_radius, rel=1e-12)
    # twice the demand: half the volume per terminal
    q = 2.0 * q0 / volume
    p = make_problem("tissue=sphere", "n_terminals=100", f"tissue.q_required={q!r}")
    expected = (3.0 * (q0 / 100 / q) / (4.0 * math.pi)) ** (1.0 / 3.0)
    assert p.physics.supply_radius == pytest.approx(expected, rel=1e-12)
    assert p.physics.supply_radius == pytest.approx(base.physics.supply_radius / 2 ** (1 / 3), rel=1e-9)
    assert p.tissue.voxel_size == pytest.approx(p.physics.supply_radius / tissue.VOXELS_PER_SUPPLY_RADIUS, rel=1e-12)
    assert p.physics.supply_radius == physics.supply_radius(100, p.tissue.measure, 3, q, q0)
    assert p.model.supply_rho == pytest.approx(tissue.VOXELS_PER_SUPPLY_RADIUS, rel=1e-12)
    with pytest.raises(config.ConfigError, match="tissue.q_required"):
        make_problem("tissue=sphere", "tissue.q_required=-1")


def test_inlets_may_be_written_as_whole_numbers():
    """``[[0,0,0.019]]`` is as good as ``[[0.0,0.0,0.019]]`` (Hydra types a bare 0 as an int)."""
    cfg = config.compose(["tissue=mask", "tissue.path=/nonexistent.npy", "tissue.inlets=[[0,0,0.019]]"], check=False)
    assert config.validate(cfg).tissue.inlets == [[0.0, 0.0, 0.019]]


def test_a_terminal_sites_path_that_is_a_directory_names_the_field(tmp_path):
    from vasc_pipeline.model.tree import TreeError, load_terminal_sites

    with pytest.raises(TreeError, match=r"terminals\.path: cannot read .*Is a directory"):
        load_terminal_sites(str(tmp_path), tissue=None)


@pytest.mark.parametrize(
    "shape, voxel, message",
    [
        # a voxel edge given in millimetres where metres are meant: a 20 m organ
        ((20, 20, 20), 1.0, r"tissue\.voxel_size=1 \(for tissue\.path '.*tissue\.npy'\) gives voxels of 1000 mm, "),
        ((20, 20, 20), 2e-8, r"gives voxels of 2e-05 mm, outside \[0\.001, 10\] mm"),
        # plausible voxels, but an organ 3 m long
        ((3, 3, 600), 5e-3, r"the tissue of .*tissue\.npy. an extent of 3000 mm \(600 voxels of 5 mm\), outside "),
        ((2, 2, 2), 4e-5, r"an extent of 0\.08 mm \(2 voxels of 0\.04 mm\), outside \[0\.1, 2000\] mm"),
    ],
)
def test_a_mask_at_a_scale_no_organ_has_is_refused(tmp_path, shape, voxel, message):
    data = np.ones(shape, dtype=np.uint8)
    np.save(tmp_path / "tissue.npy", data)
    inlet = [0.0, 0.0, 0.0]
    with pytest.raises(tissue.TissueError, match=message):
        make_problem(*overrides(tmp_path / "tissue.npy", inlet, f"tissue.voxel_size={voxel!r}", "n_terminals=4"))


def test_a_sphere_with_a_voxel_wider_than_the_supply_sphere_is_still_refused():
    with pytest.raises(tissue.TissueError, match=r"tissue\.voxel_size=0\.05 m is coarser than the supply sphere"):
        make_problem("tissue=sphere", "tissue.voxel_size=0.05")
