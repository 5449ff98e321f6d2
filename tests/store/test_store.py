"""The run store and one job in-process: layout, atomic checkpoints, fallback, resume, refusal.

Real Zarr stores in tmp_path; the job tests run the real engine on tiny problems.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import zarr

from vasc_pipeline import config, engine, job, store, sweep
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.tree import Tree, check_tree

TINY = [
    "tissue=plane2d",
    "n_terminals=12",
    "anneal.steps=60000",
    "anneal.trace_every=5000",
    "anneal.T_start=1e-2",
    "anneal.T_end=1e-9",
]


def tiny_job(tmp_path: Path, *extra: str) -> sweep.Job:
    (j,) = sweep.expand(config.compose([*TINY, f"output_dir={tmp_path / 'out'}", *extra]))
    return j


def new_store(tmp_path: Path, name: str = "r") -> store.RunStore:
    cfg = {"n_terminals": 4, "seed": 3, "output_dir": "/x", "anneal": {"T_end": 1e-9}, "checkpoint": {"every": 1}}
    return store.RunStore.create(
        tmp_path / f"{name}.zarr", run_id=name, seed=3, config=cfg, coords={"seed": 3}, total_steps=100
    )


def state_like(seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "parent": rng.integers(-1, 8, 8),
        "position": rng.random((8, 3)),
        "rng": rng.integers(0, 2**63, 4, dtype=np.uint64),
        "supply": rng.integers(0, 3, (2, 3, 4), dtype=np.int32),
    }


class Crash(Exception):
    """Raised from the progress callback: a job dying mid-run, in-process."""


def crash_after(blocks: int):
    seen = []

    def report(msg):
        seen.append(msg["step"])
        if len(seen) >= blocks:
            raise Crash(msg["step"])

    return report


# -- the store on its own -------------------------------------------------------------------


def test_create_refuses_to_overwrite_and_open_checks_format(tmp_path):
    s = new_store(tmp_path)
    assert s.status == "running" and s.attrs["steps_done"] == 0 and s.attrs["checkpoint"] is None
    with pytest.raises(store.StoreError, match="already exists"):
        new_store(tmp_path)
    zarr.open_group(str(tmp_path / "other.zarr"), mode="w")
    with pytest.raises(store.StoreError, match="not a vasc_pipeline run store"):
        store.RunStore.open(tmp_path / "other.zarr")
    with pytest.raises(store.StoreError, match="no zarr.json"):
        store.RunStore.open(tmp_path / "missing.zarr")


def test_config_hash_ignores_where_and_how_often_but_not_physics(tmp_path):
    s = new_store(tmp_path)
    base = dict(s.attrs["config"])
    s.check_config({**base, "output_dir": "/elsewhere", "checkpoint": {"every": 99}})
    with pytest.raises(ConfigError, match=r"anneal\.T_end: 1e-09 \(stored\) vs 1e-08 \(requested\)"):
        s.check_config({**base, "anneal": {"T_end": 1e-8}})


def test_trace_records_are_built_and_read_by_name_and_become_the_store_columns(tmp_path):
    trace = store.Trace()
    for k in range(3):
        values = {name: float(k) for name in store.TRACE_NAMES}
        trace.append(store.TraceRecord(**{**values, "step": 10 * k}))
    assert trace.last.step == 20 and trace.last.total == 2.0 and len(trace) == 3
    arrays = trace.arrays()
    assert list(arrays) == list(store.TRACE_NAMES) == [f[0] for f in store.TRACE_FIELDS]
    assert {name: str(a.dtype) for name, a in arrays.items()} == {f[0]: f[1] for f in store.TRACE_FIELDS}
    s = new_store(tmp_path)
    s.write_checkpoint(state_like(), step=20, trace_length=s.append_trace(arrays, 0), wall_seconds=1.0)
    np.testing.assert_array_equal(s.read_trace()["step"], [0, 10, 20])
    trace.clear()
    assert len(trace) == 0 and all(a.shape == (0,) for a in trace.arrays().values())


def test_trace_commit_and_cut_back_after_a_crash_between_resize_and_write(tmp_path):
    s = new_store(tmp_path)
    rows = {name: np.arange(3, dtype=dtype) for name, dtype, *_ in store.TRACE_FIELDS}
    n = s.append_trace(rows, 0)
    s.write_checkpoint(state_like(), step=10, trace_length=n, wall_seconds=1.0)
    # A crash after the resize of the next append: arrays longer than committed, fill values inside.
    for name, *_ in store.TRACE_FIELDS:
        s.group[f"trace/{name}"].resize((7,))
    reopened = store.RunStore.open(s.path)
    assert reopened.trace_length == 3
    reopened.set_trace_length(reopened.trace_length)
    ds = xr.open_zarr(s.path, group="trace", consolidated=False)
    assert ds.sizes["step"] == 3 and list(ds["step"].values) == [0, 1, 2]
    assert ds["total"].attrs["units"] == "W" and "long_name" in ds["temperature"].attrs


def test_checkpoints_rotate_and_load_the_newest(tmp_path):
    s = new_store(tmp_path)
    for k in range(4):
        s.write_checkpoint(state_like(k), step=10 * (k + 1), trace_length=k, wall_seconds=float(k))
    assert s._checkpoint_names() == ["c000000003", "c000000004"]  # current + previous good one
    cp = s.load_checkpoint()
    assert (cp.name, cp.step, cp.trace_length) == ("c000000004", 40, 3)
    for key, value in state_like(3).items():
        np.testing.assert_array_equal(cp.arrays[key], value)
        assert cp.arrays[key].dtype == value.dtype


def _chunk_files(group_path: Path, array: str) -> list[Path]:
    return [p for p in (group_path / array).rglob("*") if p.is_file() and p.name != "zarr.json"]


@pytest.mark.parametrize("damage", ["truncate", "delete", "flip"])
def test_corrupted_checkpoint_falls_back_to_the_previous_good_one(tmp_path, damage):
    s = new_store(tmp_path)
    s.write_checkpoint(state_like(1), step=10, trace_length=1, wall_seconds=1.0)
    s.write_checkpoint(state_like(2), step=20, trace_length=2, wall_seconds=2.0)
    (chunk,) = _chunk_files(s.path / "checkpoints" / "c000000002", "position")
    data = chunk.read_bytes()
    if damage == "truncate":
        chunk.write_bytes(data[: len(data) // 2])
    elif damage == "delete":  # reads back as fill values: only the checksum can tell
        chunk.unlink()
    else:
        chunk.write_bytes(data[:-9] + bytes([data[-9] ^ 0xFF]) + data[-8:])
    with pytest.warns(store.CheckpointWarning, match="c000000002 is truncated or corrupted"):
        cp = store.RunStore.open(s.path).load_checkpoint()
    assert (cp.name, cp.step, cp.trace_length) == ("c000000001", 10, 1)
    np.testing.assert_array_equal(cp.arrays["position"], state_like(1)["position"])
    # The session resumed from the fallback keeps it as its own fallback; the bad one goes.
    resumed = store.RunStore.open(s.path)
    resumed.record_resume(cp)
    resumed.write_checkpoint(state_like(3), step=30, trace_length=3, wall_seconds=3.0)
    assert resumed._checkpoint_names() == ["c000000001", "c000000003"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert store.RunStore.open(s.path).load_checkpoint().name == "c000000003"


def test_a_checkpoint_written_partially_is_never_used(tmp_path):
    s = new_store(tmp_path)
    s.write_checkpoint(state_like(1), step=10, trace_length=1, wall_seconds=1.0)
    # A crash while writing the next one: arrays present, no manifest, pointer not flipped.
    partial = s.group["checkpoints"].create_group("c000000002")
    partial.create_array("parent", data=np.zeros(8, dtype=np.int64))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the pointer still names a good checkpoint: no warning
        cp = store.RunStore.open(s.path).load_checkpoint()
    assert cp.name == "c000000001"
    s.write_checkpoint(state_like(3), step=30, trace_length=3, wall_seconds=3.0)
    assert s._checkpoint_names() == ["c000000001", "c000000003"]  # the stray partial one is pruned


def test_no_good_checkpoint_left_means_a_fresh_start_with_a_warning(tmp_path):
    s = new_store(tmp_path)
    s.write_checkpoint(state_like(1), step=10, trace_length=1, wall_seconds=1.0)
    (s.path / "checkpoints" / "c000000001" / "zarr.json").write_text("{ not json")
    with pytest.warns(store.CheckpointWarning) as record:
        assert store.RunStore.open(s.path).load_checkpoint() is None
    messages = [str(w.message) for w in record]
    assert any("c000000001 is truncated or corrupted" in m for m in messages)
    assert any("restarts from step 0" in m for m in messages)


def test_run_lock_is_exclusive(tmp_path):
    path = tmp_path / "runs" / "a.zarr"
    with store.run_lock(path):
        with pytest.raises(store.StoreError, match="being written by another process"):
            with store.run_lock(path, wait=False):
                pass
    with store.run_lock(path, wait=False):  # released
        pass


# -- one job, in-process ---------------------------------------------------------------------


def test_job_writes_the_documented_layout(tmp_path):
    j = tiny_job(tmp_path)
    summary = job.run_job(j)
    assert summary["status"] == "complete" and summary["resumed_from"] is None
    ref = engine.run(j.config, seed=j.coords["seed"])
    s = store.RunStore.open(j.store, mode="r")
    a = s.attrs
    assert a["run_id"] == j.run_id == "plane2d-N12-mb641.3-s0" and a["seed"] == 0 and a["status"] == "complete"
    assert a["steps_done"] == 60000 and a["wall_seconds"] > 0 and a["config_hash"] == store.config_hash(j.config)
    assert set(a["physics"]) >= {
        "n_terminals",
        "n_inlets",
        "gamma",
        "inlet_radius",
        "total_flow",
        "m_b",
        "viscosity",
        "supply_radius",
        "r_cutoff",
        "A_wv",
        "A_o",
        "A_p",
        "A_s",
    }
    keys = {"total", "volume", "power", "supply", "exclusion", "pressure"}
    assert set(a["cost"]) == set(a["cost_recomputed"]) == keys
    for k in keys:
        assert a["cost_recomputed"][k] == pytest.approx(a["cost"][k], rel=1e-9, abs=1e-300)
    assert a["cost"] == ref.costs
    tree = s.read_tree()
    assert tree["parent"].dtype == np.int64 and tree["position"].dtype == np.float64
    assert tree["kind"].dtype == np.int8 and tree["radius"].dtype == np.float64
    np.testing.assert_array_equal(tree["parent"], ref.tree.parent)
    np.testing.assert_array_equal(tree["position"], ref.tree.position)
    np.testing.assert_array_equal(tree["radius"], ref.radius)
    assert tree["radius"][0] == 0.0 and tree["kind"][0] == 0
    rebuilt = Tree(tree["parent"], ref.tree.children, tree["position"], ref.tree.n_downstream, 1)
    check_tree(rebuilt, ref.problem.tissue)
    mask = s.group["tissue/mask"]
    assert mask.dtype == np.uint8 and mask.attrs["voxel_size"] == ref.problem.tissue.voxel_size
    assert mask.attrs["origin"] == list(ref.problem.tissue.origin)
    assert s.group["tissue/distance"].dtype == np.float32
    assert s.group["tissue"].attrs["inlet_names"] == list(ref.problem.tissue.inlet_names) == ["root"]
    np.testing.assert_array_equal(s.group["tissue/exclusion"][...], ref.problem.tissue.exclusion)
    np.testing.assert_array_equal(s.group["tissue/distance"][...], ref.problem.tissue.distance)
    assert a["statistics"] == ref.statistics == {}  # plane2d has no cavity
    ds = xr.open_zarr(j.store, group="trace")
    np.testing.assert_array_equal(ds["step"].values, ref.trace["step"])
    np.testing.assert_array_equal(ds["total"].values, ref.trace["total"])
    assert "checkpoints" not in s.group  # a finished store keeps no checkpoint
    assert job.run_job(j)["status"] == "skipped"


def test_job_resumes_from_its_checkpoint_bit_identically(tmp_path):
    j = tiny_job(tmp_path, "checkpoint.every_seconds=1e-6")  # a checkpoint after every block
    with pytest.raises(Crash):
        job.run_job(j, report=crash_after(5))
    s = store.RunStore.open(j.store, mode="r")
    assert s.status == "running" and s.attrs["steps_done"] == 20000  # blocks 1-4 checkpointed
    summary = job.run_job(j)
    assert summary["resumed_from"] == 20000 and summary["session_steps"] == 40000
    ref = engine.run(j.config, seed=0)
    s = store.RunStore.open(j.store, mode="r")
    np.testing.assert_array_equal(s.read_tree()["position"], ref.tree.position)
    np.testing.assert_array_equal(s.read_tree()["parent"], ref.tree.parent)
    for name, values in ref.trace.items():
        np.testing.assert_array_equal(s.read_trace()[name], values)
    assert [r["step"] for r in s.attrs["resumes"]] == [0, 20000]


def test_job_falls_back_past_a_corrupted_checkpoint_and_still_ends_bit_identically(tmp_path):
    j = tiny_job(tmp_path, "checkpoint.every_seconds=1e-6")
    with pytest.raises(Crash):
        job.run_job(j, report=crash_after(5))
    newest = store.RunStore.open(j.store).attrs["checkpoint"]
    (chunk,) = _chunk_files(Path(j.store) / "checkpoints" / newest, "position")
    chunk.write_bytes(chunk.read_bytes()[:5])
    with pytest.warns(store.CheckpointWarning, match="falling back"):
        summary = job.run_job(j)
    assert summary["resumed_from"] == 15000 and any("corrupted" in w for w in summary["warnings"])
    ref = engine.run(j.config, seed=0)
    s = store.RunStore.open(j.store, mode="r")
    np.testing.assert_array_equal(s.read_tree()["position"], ref.tree.position)
    np.testing.assert_array_equal(s.read_trace()["total"], ref.trace["total"])


def test_job_refuses_a_changed_config_and_leaves_the_store_alone(tmp_path):
    j = tiny_job(tmp_path)
    job.run_job(j)
    before = (Path(j.store) / "zarr.json").read_bytes()
    changed = tiny_job(tmp_path, "anneal.T_end=1e-8")
    assert changed.run_id == j.run_id
    with pytest.raises(ConfigError, match=r"never mixed: anneal\.T_end: 1e-09 \(stored\) vs 1e-08"):
        job.run_job(changed)
    assert (Path(j.store) / "zarr.json").read_bytes() == before
    assert json.loads(before)["attributes"]["status"] == "complete"


def test_keys_added_later_at_their_neutral_value_keep_old_stores_valid(tmp_path):
    """A store written before a key existed resumes under a config holding the key's neutral value."""
    from vasc_pipeline.config import KEYS_ADDED_LATER

    j = tiny_job(tmp_path, "anneal=fast_v1")  # fast_v1 holds steps_exponent at its neutral 2 (fast: another)
    old = json.loads(json.dumps(j.config))
    del old["anneal"]["packing_steps_per_terminal"], old["tissue"]["exclusion_path"]  # as stored by older code
    assert old["anneal"].get("steps_exponent") == KEYS_ADDED_LATER["anneal.steps_exponent"]
    s = store.RunStore.create(j.store, run_id=j.run_id, seed=0, config=old, coords=j.coords, total_steps=10)
    s.check_config(j.config)  # same run
    changed = json.loads(json.dumps(j.config))
    changed["anneal"]["packing_steps_per_terminal"] = 5.0  # not neutral: a different run
    with pytest.raises(ConfigError, match=r"anneal\.packing_steps_per_terminal: '<absent>' \(stored\) vs 5\.0"):
        s.check_config(changed)
    assert "packing_steps_per_terminal" in j.config["anneal"]  # hashing never edits the caller's config


def test_identity_differences_allow_sweep_axes_and_a_second_method_only(tmp_path):
    def cfg(*overrides):
        (j,) = sweep.expand(config.compose([*overrides, "tissue=sphere", f"output_dir={tmp_path}"]))
        return j.config

    base = cfg("n_terminals=16")
    assert store.identity_differences(base, cfg("n_terminals=24", "seed=3", "physics.m_b=6413")) == []
    assert store.identity_differences(base, cfg("n_terminals=16", "method=cco")) == []  # the method comparison
    assert store.identity_differences(base, cfg("n_terminals=16", "anneal.p_swap=0.7")) == [
        "anneal.p_swap: 0.3 (stored) vs 0.7 (requested)"
    ]
    assert store.identity_differences(base, cfg("method=cco", "physics.gamma=3.0")) == [
        "physics.gamma: 2.3333333333333335 (stored) vs 3.0 (requested)"
    ]  # but nothing the two methods share


def test_the_method_comparison_ignores_the_tissue_keys_only_the_anneal_reads(tmp_path):
    def heart(*overrides):
        (j,) = sweep.expand(config.compose([*overrides, "n_terminals=16", f"output_dir={tmp_path}"]))
        return j.config

    anneal, cco = heart(), heart("method=cco")  # the default model sets them for the anneal only
    assert anneal["tissue"]["inlet_share"] == [0.62, 0.38] and anneal["tissue"]["bifurcation_reach"] == 0.0
    assert cco["tissue"].get("inlet_share") is None and cco["tissue"].get("bifurcation_reach") is None
    assert store.identity_differences(anneal, cco) == []
    assert store.identity_differences(anneal, heart("tissue.bifurcation_reach=0.001")) == [
        "tissue.bifurcation_reach: 0.0 (stored) vs 0.001 (requested)"
    ]  # between two anneals they count
