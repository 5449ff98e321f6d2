"""The whole tree below a run (+stage=extend): the annealed part unchanged, the radius law over the
whole tree, a territory's subtree equal to a plain ``method=cco`` growth on that territory,
determinism whatever the batches, resume after SIGKILL, the voxel traversal against its twin,
the stage on a local Dask cluster, bad input.

Sources are tiny complete runs made in this process (a CCO heart of 24 terminals: cavities, and
an annealed sphere of 16).
"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO

from vasc_pipeline import cco, config, engine, job, store, sweep
from vasc_pipeline.engine import extend as ex
from vasc_pipeline.model.costs import voxel_pieces
from vasc_pipeline.model.topology import KIND_BIFURCATION, KIND_INLET, KIND_TERMINAL, segment_lengths
from vasc_pipeline.pipeline import orchestrate
from vasc_pipeline.pipeline.extend import extend_run
from vasc_pipeline.store.extended import ExtendedStore

HEART = ["tissue=heart", "n_terminals=24", "method=cco"]
SPHERE = ["tissue=sphere", "n_terminals=16", "anneal.steps=2000", "anneal.trace_every=500"]


def make_runs(out: Path, overrides: list[str], seeds=(0,)) -> list[sweep.Job]:
    jobs = sweep.expand(config.compose([*overrides, f"sweep.seeds={list(seeds)}", f"output_dir={out}"]))
    for j in jobs:
        job.run_job(j)
    return jobs


@pytest.fixture(scope="module")
def heart(tmp_path_factory):
    return make_runs(tmp_path_factory.mktemp("heart"), HEART, seeds=(0, 1))


@pytest.fixture(scope="module")
def sphere(tmp_path_factory):
    return make_runs(tmp_path_factory.mktemp("sphere"), SPHERE)


def extended(source: sweep.Job, path: Path, n: int, **kw) -> dict:
    extend_run(source.store, path, n, stream=io.StringIO(), **kw)
    s = ExtendedStore.open(path)
    return {"attrs": s.attrs, **s.read_tree(), "territory": s.read_territories()}


# --------------------------------------------------------------------------------------------
# The whole tree


@pytest.mark.parametrize("which", ["heart", "sphere"])
def test_annealed_part_unchanged_and_one_radius_law_over_the_whole_tree(which, request, tmp_path):
    (src, *_) = request.getfixturevalue(which)
    source = ex.read_source(src.store)
    n_annealed, m = source.n_terminals, 30
    e = extended(src, tmp_path / "x.zarr", n_annealed * m + 3)  # rounded to the nearest multiple of N
    attrs = e["attrs"]
    assert attrs["status"] == "complete" and attrs["config"]["n_terminals"] == n_annealed * m
    assert attrs["config"]["n_terminals_requested"] == n_annealed * m + 3
    old = slice(0, source.parent.size)
    np.testing.assert_array_equal(e["parent"][old], source.parent)  # topology
    np.testing.assert_array_equal(e["position"][old], source.position)  # positions, bit for bit
    terminals = source.terminals
    assert np.all(e["kind"][terminals] == ex.KIND_TERRITORY_ROOT)
    kept = np.ones(source.parent.size, bool)
    kept[terminals] = False
    np.testing.assert_array_equal(e["kind"][old][kept], source.kind[kept])
    # the tree: every node's children as its kind says (a territory's root has its subtree's root segment)
    parent, kind = e["parent"], e["kind"]
    assert parent.size == source.parent.size + n_annealed * (2 * m - 1)
    children = np.bincount(parent[parent >= 0], minlength=parent.size)
    expected = {KIND_INLET: 1, KIND_BIFURCATION: 2, KIND_TERMINAL: 0, ex.KIND_TERRITORY_ROOT: 1}
    for k, count in expected.items():
        assert np.all(children[kind == k] == count), k
    assert np.count_nonzero(kind == KIND_TERMINAL) == n_annealed * m
    # one radius law over the whole tree: r = r_in (m N)^(-1/gamma) n^(1/gamma)
    n = np.zeros(parent.size, np.int64)
    n[kind == KIND_TERMINAL] = 1
    depth = np.zeros(parent.size, np.int64)
    for v in range(parent.size):  # depths, then counts deepest first
        p, d = parent[v], 0
        while p >= 0:
            p, d = parent[p], d + 1
        depth[v] = d
    for v in np.argsort(-depth, kind="stable"):
        if parent[v] >= 0:
            n[parent[v]] += n[v]
    p = source.physics
    law = p.inlet_radius * (n / (n_annealed * m)) ** (1.0 / p.gamma)
    seg = parent >= 0
    np.testing.assert_allclose(e["radius"][seg], law[seg], rtol=1e-12)
    np.testing.assert_allclose(e["radius"][old][seg[old]], source.radius[seg[old]], rtol=1e-12)  # annealed radii
    assert np.all(n[source.parent.size :][kind[source.parent.size :] == KIND_BIFURCATION] >= 2)
    # the whole tree's C_v + C_w, recomputed, against the stored sums; the annealed part's is the run's
    whole = ex.plan_extension(source, n_annealed * m).whole_physics
    from vasc_pipeline.model.physics import segment_factors

    factors = segment_factors(whole, n[seg])
    length = segment_lengths(parent, e["position"])[seg]
    cost = attrs["cost"]
    assert cost["volume"] == pytest.approx(float(np.sum(factors[0] * length)), rel=1e-9)
    assert cost["power"] == pytest.approx(float(np.sum(factors[1] * length)), rel=1e-9)
    run_cost = store.RunStore.open(src.store, mode="r").attrs["cost_recomputed"]
    assert cost["annealed_volume"] == pytest.approx(run_cost["volume"], rel=1e-9)
    assert cost["annealed_power"] == pytest.approx(run_cost["power"], rel=1e-9)
    # the fine terminals lie in the tissue, in their own territory's voxels; no fine vessel in a cavity
    fine = np.flatnonzero(kind == KIND_TERMINAL)
    u = (e["position"][fine] - source.origin) / source.voxel_size
    zyx = np.floor(u[:, ::-1] + 0.5).astype(np.int64)
    assert np.all(source.mask[zyx[:, 0], zyx[:, 1], zyx[:, 2]] == 1)
    stats = attrs["statistics"]
    assert stats["cavity_segments"] == 0
    # the stored coverage counts a territory's own terminals only: a lower bound of the whole tree's
    from scipy.spatial import cKDTree

    from vasc_pipeline.model.rng import seed_state
    from vasc_pipeline.model.tree import sites_in_voxels

    voxels = np.flatnonzero(source.mask.reshape(-1))
    sample = sites_in_voxels(voxels, source.mask.shape, source.origin, source.voxel_size, 3, 20000, seed_state(9))
    near = cKDTree(e["position"][fine]).query(sample)[0]
    assert np.mean(near <= stats["coverage_reach"]) >= stats["coverage"] - 0.02
    if which == "sphere":  # annealed: territories of near-equal volume, so equal counts cover them
        assert stats["coverage"] >= 0.99
    assert attrs["source"]["digest"] == source.digest and attrs["source"]["run_id"] == src.run_id


def territory_problem(plan: ex.ExtensionPlan, t: ex.TerritoryInput, tmp_path: Path):
    """The plain ``method=cco`` problem of one territory: its voxels as a mask tissue (its box's
    cavities as the mask's exclusion domain), one inlet at the annealed terminal, m terminals, the
    radius and flow of an annealed terminal segment."""
    mask, cavity = tmp_path / f"t{t.index}.npy", tmp_path / f"c{t.index}.npy"
    np.save(mask, (t.box == ex.CODE_TERRITORY).astype(np.uint8))
    np.save(cavity, (t.box == ex.CODE_CAVITY).astype(np.uint8))
    tp = plan.growth.territory_physics

    def floats(values):
        return "[" + ",".join(repr(float(v)) for v in values) + "]"

    overrides = [
        "method=cco",
        "method.avoid_cavities=true",
        "tissue=mask",
        f"tissue.path={mask}",
        f"tissue.exclusion_path={cavity}",
        f"tissue.voxel_size={plan.source.voxel_size!r}",
        f"tissue.origin={floats(t.box_origin)}",
        f"tissue.inlets=[{floats(t.root)}]",
        f"n_terminals={plan.per_territory}",
        f"physics.inlet_radius={tp.inlet_radius!r}",
        f"physics.total_flow={tp.total_flow!r}",
        f"physics.gamma={tp.gamma!r}",
        f"physics.m_b={tp.m_b!r}",
        f"physics.viscosity={tp.viscosity!r}",
        f"physics.viscosity_law={tp.viscosity_law}",
    ]
    return engine.build_problem(config.compose(overrides))


def test_a_territorys_subtree_is_a_plain_cco_growth_on_that_territory(heart, tmp_path):
    src = heart[0]
    source = ex.read_source(src.store)
    m = 40
    e = extended(src, tmp_path / "x.zarr", source.n_terminals * m)
    plan = ex.plan_extension(source, source.n_terminals * m)
    inputs = plan.batch(0, source.n_terminals)
    with_cavity = [t for t in inputs if np.any(t.box == ex.CODE_CAVITY)]
    assert with_cavity  # the heart's territories reach its cavities: the constraint is exercised
    for t in [inputs[0], inputs[-1], *with_cavity[:2]]:
        grown = cco.grow(territory_problem(plan, t, tmp_path), rng=ex.growth_rng(plan.growth.seed, t.index))
        lo = plan.node_offset(t.index)
        block = slice(lo, lo + plan.growth.nodes_per_territory)
        # the plain growth's node k >= 1 is the block's node lo + k - 1; its inlet is the annealed terminal
        local = grown.tree.parent[1:]
        np.testing.assert_array_equal(e["parent"][block], np.where(local == 0, t.root_node, local + lo - 1))
        np.testing.assert_array_equal(e["position"][block], grown.tree.position[1:])
        row = e["territory"]
        assert row["volume"][t.index] == grown.costs["volume"] and row["power"][t.index] == grown.costs["power"]


def test_deterministic_whatever_the_batches_and_seeded_by_territory(heart, tmp_path):
    src = heart[0]
    n = 24 * 12
    one = extended(src, tmp_path / "a.zarr", n, batch_territories=1)
    seven = extended(src, tmp_path / "b.zarr", n, batch_territories=7)
    for name in ("parent", "position", "radius", "kind"):
        np.testing.assert_array_equal(one[name], seven[name], err_msg=name)
    for name in one["territory"]:
        np.testing.assert_array_equal(one["territory"][name], seven["territory"][name], err_msg=name)
    assert one["attrs"]["cost"] == seven["attrs"]["cost"]
    other = extended(src, tmp_path / "c.zarr", n, seed=5)
    assert not np.array_equal(one["position"], other["position"])
    # a complete store is skipped; another configuration is refused, naming the key
    summary = extend_run(src.store, tmp_path / "a.zarr", n, stream=io.StringIO())
    assert summary["status"] == "skipped"
    with pytest.raises(ex.ExtendError, match="per_territory"):
        extend_run(src.store, tmp_path / "a.zarr", 2 * n, stream=io.StringIO())


def test_resume_after_sigkill_ends_bit_identical(heart, tmp_path):
    src = heart[0]
    n, path = 24 * 300, tmp_path / "k.zarr"
    script = (
        "import sys, io; from vasc_pipeline.pipeline.extend import extend_run; "
        "extend_run(sys.argv[1], sys.argv[2], int(sys.argv[3]), batch_territories=1, stream=io.StringIO())"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-c", script, src.store, str(path), str(n)], cwd=REPO, env=env)
    done = 0
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                done = json.loads((path / "zarr.json").read_text())["attributes"].get("territories_done", 0)
            except (OSError, ValueError, KeyError):
                done = 0
            if done >= 2:
                break
            time.sleep(0.005)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert 2 <= done < 24, "the extension was not killed between batches"
    s = ExtendedStore.open(path, mode="r+")
    assert s.status == "running"
    # a crash between resize and commit: records past the committed length, cut back on resume
    for name in ("parent", "radius"):
        arr = s.group[f"tree/{name}"]
        arr.resize((s.nodes_committed + 50,))
        arr[s.nodes_committed :] = 7
    summary = extend_run(src.store, path, n, batch_territories=5, stream=io.StringIO())
    assert summary["status"] == "complete" and summary["resumed_from"] >= 2
    resumed = ExtendedStore.open(path)
    resumed.verify()
    assert [r["territories_done"] for r in resumed.attrs["sessions"]][1] >= 2
    reference = extended(src, tmp_path / "ref.zarr", n)
    for name, data in resumed.read_tree().items():
        np.testing.assert_array_equal(data, reference[name], err_msg=name)


# --------------------------------------------------------------------------------------------
# The traversal, the plan


def test_segment_voxel_lengths_equals_the_exact_traversal():
    gen = np.random.default_rng(3)
    box = gen.integers(0, 4, size=(7, 9, 11)).astype(np.uint8)
    origin, h = np.array([0.01, -0.02, 0.005]), 1e-3
    lo, hi = origin - 2 * h, origin + np.array([11, 9, 7]) * h + h
    p0, p1 = gen.uniform(lo, hi, (400, 3)), gen.uniform(lo, hi, (400, 3))
    p1[:50] = p0[:50] + gen.normal(size=(50, 3)) * 1e-4  # short ones, inside a voxel or two
    got = ex.segment_voxel_lengths(box, origin, h, p0, p1)
    for s in range(len(p0)):
        idx, pieces = voxel_pieces((p0[s] - origin) / h, (p1[s] - origin) / h, box.shape)
        want = np.bincount(box[idx[:, 0], idx[:, 1], idx[:, 2]], weights=pieces * h, minlength=4)
        np.testing.assert_allclose(got[s, :4], want, rtol=1e-9, atol=1e-15)
        assert got[s].sum() == pytest.approx(np.linalg.norm(p1[s] - p0[s]), rel=1e-12)


def test_territories_are_the_voxels_nearest_to_each_terminal(heart):
    source = ex.read_source(heart[0].store)
    plan = ex.plan_extension(source, source.n_terminals * 3)
    z, y, x = np.unravel_index(plan.voxels, source.mask.shape)
    centres = source.origin + source.voxel_size * np.stack([x, y, z], axis=1)
    d = np.linalg.norm(centres[:, None, :] - source.position[source.terminals][None], axis=2)
    label = np.repeat(np.arange(source.n_terminals), np.diff(plan.starts))
    np.testing.assert_allclose(d[np.arange(len(label)), label], d.min(axis=1), rtol=1e-12)
    assert plan.voxels.size == int(source.mask.sum())
    with pytest.raises(ex.ExtendError, match=r"extend\.n_terminals >= 12"):
        ex.plan_extension(source, source.n_terminals // 2 - 1)
    assert ex.plan_extension(source, source.n_terminals // 2).per_territory == 1  # rounded to the nearest multiple


def test_extend_keys_leave_the_runs_identity_alone(tmp_path):
    (a,) = sweep.expand(config.compose([f"output_dir={tmp_path}"]))
    (b,) = sweep.expand(
        config.compose([f"output_dir={tmp_path}", "extend.n_terminals=5e5", "extend.runs=all", "extend.zerod=full"])
    )
    assert "extend" not in a.config and a.config == b.config
    assert store.config_hash(a.config) == store.config_hash(b.config)


@pytest.mark.parametrize(
    "override, field",
    [
        ("extend.n_terminals=0", "extend.n_terminals"),
        ("extend.runs=worst", "extend.runs"),
        ("extend.batch_territories=0", "extend.batch_territories"),
        ("extend.seed=-1", "extend.seed"),
        ("extend.zerod=partial", "extend.zerod"),
    ],
)
def test_bad_extend_settings_name_the_field(override, field):
    with pytest.raises(config.ConfigError, match=field.replace(".", r"\.")):
        config.compose([override])


# --------------------------------------------------------------------------------------------
# The stage on a Dask cluster


@pytest.mark.integration
def test_extend_stage_on_a_local_cluster_best_seed_then_all_runs(heart, tmp_path):
    out = Path(heart[0].store).parent.parent
    common = [f"output_dir={out}", "cluster.n_workers=1", "cluster.dashboard_address=null"]
    costs = {j.run_id: store.RunStore.open(j.store, mode="r").attrs["cost"]["total"] for j in heart}
    best = min(costs, key=costs.get)
    stream = io.StringIO()
    cfg = config.compose(["+stage=extend", "extend.n_terminals=240", "extend.batch_territories=5", *common])
    assert orchestrate.main(cfg, stream) == 0, stream.getvalue()
    assert sorted(p.name for p in (out / "extended").glob("*.zarr")) == [f"{best}.zarr"]
    assert "territories 24/24" in stream.getvalue()
    serial = extended(next(j for j in heart if j.run_id == best), tmp_path / "s.zarr", 240)
    on_cluster = ExtendedStore.open(out / "extended" / f"{best}.zarr").read_tree()
    for name, data in on_cluster.items():
        np.testing.assert_array_equal(data, serial[name], err_msg=name)
    cfg = config.compose(["+stage=extend", "extend.n_terminals=240", "extend.runs=all", *common])
    assert orchestrate.main(cfg, io.StringIO()) == 0
    assert len(list((out / "extended").glob("*.zarr"))) == 2
    # bad input: refused before anything is written
    before = sorted(p.name for p in (out / "extended").iterdir())
    stream = io.StringIO()
    cfg = config.compose(["+stage=extend", "extend.n_terminals=10", "extend.runs=all", *common])
    assert orchestrate.main(cfg, stream) == 2
    assert "extend.n_terminals=10" in stream.getvalue() and ">= 12" in stream.getvalue()
    assert sorted(p.name for p in (out / "extended").iterdir()) == before
    stream = io.StringIO()
    assert orchestrate.main(config.compose(["+stage=extend", f"output_dir={tmp_path / 'none'}"]), stream) == 2
    assert "no runs/" in stream.getvalue()


@pytest.mark.integration
@pytest.mark.slow  # resume itself is covered by test_resume_after_sigkill_ends_bit_identical
def test_sigterm_ends_the_extension_with_a_message_and_the_rerun_resumes(heart, tmp_path):
    import shutil

    from helpers import cli, finish

    out = tmp_path / "out"  # a copy of the runs: the other tests' extended stores are not this one's
    shutil.copytree(Path(heart[0].store).parent, out / "runs")
    args = [
        "+stage=extend",
        f"output_dir={out}",
        "extend.n_terminals=7200",  # 300 per territory: a few seconds, one territory per batch
        "extend.batch_territories=1",
        "extend.seed=11",
        "cluster.n_workers=1",
        "cluster.dashboard_address=null",
    ]
    proc = cli(*args)
    path = out / "extended"
    try:
        deadline = time.monotonic() + 240
        done = 0
        while done < 1 and time.monotonic() < deadline and proc.poll() is None:
            for store_json in path.glob("*.zarr/zarr.json"):
                try:
                    done = max(done, json.loads(store_json.read_text())["attributes"].get("territories_done", 0))
                except (OSError, ValueError):
                    pass
            time.sleep(0.01)
        proc.send_signal(signal.SIGTERM)
        code, output = finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == 143, output
    assert "interrupted (Ctrl-C or SIGTERM)" in output and "Traceback" not in output, output
    (store_path,) = path.glob("*.zarr")
    assert ExtendedStore.open(store_path).status == "running"
    code, output = finish(cli(*args))
    assert code == 0, output
    resumed = ExtendedStore.open(store_path)
    assert resumed.status == "complete" and len(resumed.attrs["sessions"]) == 2
    source = next(j for j in heart if j.run_id == resumed.attrs["run_id"])
    reference = extended(source, tmp_path / "ref.zarr", 7200, seed=11)
    for name, data in resumed.read_tree().items():
        np.testing.assert_array_equal(data, reference[name], err_msg=name)
