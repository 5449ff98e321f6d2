"""CCO (vasc_pipeline.engine.cco): the local optimum, the incremental cost, the growth against a
plain NumPy twin, invariants, determinism, stored = recomputed costs, the exhaustive
optimum never above CCO, the pipeline and the reduction with both methods."""

from __future__ import annotations

import io
import itertools
import json
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
from helpers import REPO

from vasc_pipeline import cco, config, engine, job, store, sweep
from vasc_pipeline.config import ConfigError
from vasc_pipeline.model.costs import full_costs, voxel_pieces
from vasc_pipeline.model.geometry import optimal_bifurcations, vascular_cost, vascular_weights
from vasc_pipeline.model.physics import cost_tables
from vasc_pipeline.model.rng import seed_state
from vasc_pipeline.model.topology_search import best_topology
from vasc_pipeline.model.tree import Tree, check_tree, children_from_parent, count_terminals, random_terminal_sites
from vasc_pipeline.pipeline import orchestrate
from vasc_pipeline.pipeline.reduction import reduce_and_draw


def problem_of(*overrides: str):
    return engine.build_problem(config.compose(["method=cco", *overrides]))


# --------------------------------------------------------------------------------------------
# The local problem


def test_fermat_point_is_the_geometry_modules_optimum():
    """Three points, three weights: the kernel's point and cost equal optimal_bifurcations' on
    the tree inlet - b - (j, t), interior optima and collapsed ones (a heavy weight) alike."""
    gen = np.random.default_rng(5)
    out = np.empty(3)
    collapsed = 0
    for trial in range(200):
        pts = gen.normal(size=(3, 3)) * 1e-2
        if trial % 4 == 0:
            pts[:, 2] = 0.0  # planar
        w = gen.uniform(0.1, 1.0, 3)
        if trial % 5 == 0:
            w[trial % 3] = w.sum() * 1.2  # a vertex is optimal
        cost = cco.fermat_point(pts[0], pts[1], pts[2], w[0], w[1], w[2], out)
        parent = np.array([-1, 3, 3, 0])
        position = np.vstack([pts[0], pts[1], pts[2], pts.mean(axis=0)])
        tree = Tree(parent, children_from_parent(parent), position, count_terminals(parent, 2, 1), 1)
        weights = np.array([0.0, w[1], w[2], w[0]])
        ref = optimal_bifurcations(tree, weights)
        assert cost == pytest.approx(ref.cost, rel=1e-10) and cost <= ref.cost * (1 + 1e-13)
        assert cost == pytest.approx(vascular_cost(np.vstack([pts, out]), parent, weights), rel=1e-12)
        # geometry's Newton stops at a gradient of ~1e-8 W/m, ours at rounding: positions agree to ~1e-7
        np.testing.assert_allclose(out, ref.position[3], rtol=0, atol=1e-6 * 1e-2)
        collapsed += bool(ref.collapsed.any())
    assert collapsed >= 20  # the vertex branch was exercised


# --------------------------------------------------------------------------------------------
# The growth against a plain twin


def naive_crosses(forbidden, tissue, a, b):
    """Whether a -> b has a piece of positive length in a nonzero voxel of ``forbidden`` (exact traversal)."""
    u0 = (np.asarray(a) - tissue.origin) / tissue.voxel_size
    u1 = (np.asarray(b) - tissue.origin) / tissue.voxel_size
    idx, pieces = voxel_pieces(u0, u1, tissue.shape)
    return bool(np.any(forbidden[idx[:, 0], idx[:, 1], idx[:, 2]][pieces > 0]))


def naive_grow(problem, rng):
    """Plain NumPy twin of cco.grow_tree: full recomputation of the vascular cost for every
    candidate, sites from tree.random_terminal_sites one at a time, the same rules (with
    method.avoid_cavities, the cheapest connection whose new segments cross no cavity voxel)."""
    physics, tissue, m = problem.physics, problem.tissue, problem.config.method
    n, k = physics.n_terminals, physics.n_inlets
    tables = cost_tables(physics)
    cavity = tissue.cavity if m.avoid_cavities else np.zeros(tissue.shape, dtype=bool)
    parent = np.full(2 * n, -1, dtype=np.int64)
    position = np.zeros((2 * n, 3))
    position[:k] = tissue.inlets
    sites = cco._site_order(problem, rng)
    first = random_terminal_sites(tissue, k, rng) if sites is None else sites[:k]
    while sites is None and any(naive_crosses(cavity, tissue, tissue.inlets[j], first[j]) for j in range(k)):
        first = random_terminal_sites(tissue, k, rng)
    perm = min(
        itertools.permutations(range(k)),
        key=lambda p: sum(np.linalg.norm(first[p[j]] - tissue.inlets[j]) for j in range(k)),
    )
    for j in range(k):
        parent[k + j] = j
        position[k + j] = first[perm[j]]

    def cost_of(par, pos):
        nd = count_terminals(par, n, k)  # terminals not yet placed have no parent: count 0 paths
        w = tables.volume[nd] + tables.power[nd]
        w[par < 0] = 0.0
        return vascular_cost(pos, par, w), nd

    factor = 1.0
    for i in range(k, n):
        segs = np.array([s for s in range(2 * n) if parent[s] >= 0])
        too_close = 0
        while True:
            site = random_terminal_sites(tissue, 1, rng)[0] if sites is None else sites[i]
            a, b = position[parent[segs]], position[segs]
            e = b - a
            ee = np.einsum("ij,ij->i", e, e)
            t = np.clip(np.einsum("ij,ij->i", site - a, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
            d = np.linalg.norm(site - a - t[:, None] * e, axis=1)
            d_crit = factor * (tissue.measure / i) ** (1.0 / tissue.ndim) if sites is None else -1.0
            if not np.all(d >= d_crit):
                too_close += 1
                if too_close % m.max_tries == 0:
                    factor *= m.shrink
                continue
            before, nd = cost_of(parent, position)
            trials = []
            for j in segs[np.argsort(d, kind="stable")[: m.candidates]]:
                trial_par, trial_pos = parent.copy(), position.copy()
                b_node, t_node = n + i, k + i
                trial_par[b_node], trial_par[j], trial_par[t_node] = parent[j], b_node, b_node
                trial_pos[t_node] = site
                pj = position[parent[j]]
                wv = tables.volume + tables.power
                out = np.empty(3)
                cco.fermat_point(pj, position[j], site, wv[nd[j] + 1], wv[nd[j]], wv[1], out)
                trial_pos[b_node] = out
                clear = not any(naive_crosses(cavity, tissue, out, q) for q in (pj, position[j], site))
                trials.append((cost_of(trial_par, trial_pos)[0] - before, trial_par, trial_pos, clear))
            best = None
            while trials:
                pick = None
                for trial in trials:  # the cheapest left, the nearer candidate on a tie
                    if pick is None or trial[0] < pick[0] - 1e-12 * before:
                        pick = trial
                if pick[3]:
                    best = pick
                    break
                trials = [tr for tr in trials if tr is not pick]
            if best is not None:
                break
        parent, position = best[1], best[2]
    return parent, position


@pytest.mark.parametrize(
    "overrides",
    [
        ["tissue=plane2d", "n_terminals=30"],
        ["tissue=heart", "n_terminals=40"],
        ["tissue=sphere", "n_terminals=25", "method.candidates=4"],
        ["tissue=heart", "n_terminals=60", "method.avoid_cavities=true"],
    ],
)
def test_growth_equals_its_numpy_twin(overrides):
    problem = problem_of(*overrides)
    tree, trace, _, _ = cco.grow_tree(problem, seed_state(3))
    parent, position = naive_grow(problem, seed_state(3))
    np.testing.assert_array_equal(tree.parent, parent)
    np.testing.assert_allclose(tree.position, position, rtol=0, atol=1e-12)
    w = vascular_weights(tree, problem.physics)
    assert trace[-1, 0] + trace[-1, 1] == pytest.approx(vascular_cost(tree.position, tree.parent, w), rel=1e-10)


@pytest.mark.parametrize(
    "overrides",
    [
        ["tissue=plane2d", "n_terminals=64"],
        ["tissue=heart", "n_terminals=300"],
        ["tissue=box", "n_terminals=100"],
        ["tissue=sphere", "n_terminals=80"],
    ],
)
def test_invariants_determinism_and_stored_equals_recomputed(overrides):
    problem = problem_of(*overrides)
    a, b, c = cco.grow(problem, 0), cco.grow(problem, 0), cco.grow(problem, 1)
    check_tree(a.tree, problem.tissue)
    for name in ("parent", "position", "n_downstream"):
        np.testing.assert_array_equal(getattr(a.tree, name), getattr(b.tree, name))
    assert not np.array_equal(a.tree.position, c.tree.position)
    recomputed = full_costs(a.tree, problem.tissue, problem.physics, problem.terms)
    for key, value in recomputed.items():
        assert a.costs[key] == pytest.approx(value, rel=1e-9, abs=1e-300), key
        assert a.costs_recomputed[key] == value
    assert a.trace["volume"][-1] == a.costs["volume"] and a.trace["step"][-1] == problem.physics.n_terminals
    assert np.all(np.diff(a.trace["volume"] + a.trace["power"]) > 0)  # every terminal adds vessel
    assert a.tries >= problem.physics.n_terminals


def test_heart_terminals_join_both_inlets_and_distance_criterion_spaces_sites():
    problem = problem_of("tissue=heart", "n_terminals=400")
    r = cco.grow(problem, 2)
    k = problem.physics.n_inlets
    assert k == 2 and np.all(r.tree.n_downstream[:k] > 10)
    # Random sites without the criterion come much closer to each other than CCO's.
    sites = r.tree.position[k : k + 400]
    rand = random_terminal_sites(problem.tissue, 400, seed_state(2))
    from scipy.spatial import cKDTree

    def nearest(p):
        return np.median(cKDTree(p).query(p, 2)[0][:, 1])

    assert nearest(sites) > 1.2 * nearest(rand)


def test_given_sites_in_file_order_and_in_random_order(tmp_path):
    problem = problem_of("tissue=sphere", "n_terminals=30")
    grown = cco.grow(problem, 4)
    k = problem.physics.n_inlets
    csv = tmp_path / "sites.csv"
    np.savetxt(csv, grown.tree.position[k : k + 30], delimiter=",", header="x,y,z", comments="")
    again = cco.grow(problem_of("tissue=sphere", "n_terminals=30", f"terminals.path={csv}"), 99)
    np.testing.assert_array_equal(again.tree.parent, grown.tree.parent)  # the same tree: file order = grown order
    np.testing.assert_allclose(again.tree.position, grown.tree.position, atol=1e-15)
    shuffled = [
        cco.grow(problem_of("tissue=sphere", "n_terminals=30", f"terminals.path={csv}", "method.order=random"), s)
        for s in (0, 1)
    ]
    assert not np.array_equal(shuffled[0].tree.parent, shuffled[1].tree.parent)
    for s in shuffled:
        np.testing.assert_array_equal(
            np.sort(s.tree.position[k : k + 30], axis=0), np.sort(grown.tree.position[k : k + 30], axis=0)
        )


# --------------------------------------------------------------------------------------------
# The anneal's optimum is never above CCO


@pytest.mark.parametrize("n, trials", [(4, 3), (5, 2), pytest.param(6, 2, marks=pytest.mark.slow)])  # 945 topologies
def test_exhaustive_optimum_and_fixed_terminal_anneal_never_above_cco(n, trials, tmp_path):
    """The exact optimum over every topology (topology_search.best_topology) and the anneal (with its
    single-swap descent) on the same 4-6 fixed terminals are never above CCO's C_v + C_w."""
    for trial in range(trials):
        sites = random_terminal_sites(
            engine.build_problem(config.compose(["tissue=plane2d"])).tissue, n, seed_state(100 * n + trial)
        )
        csv = tmp_path / f"s{trial}.csv"
        np.savetxt(csv, sites, delimiter=",", header="x,y,z", comments="")
        common = ["tissue=plane2d", f"n_terminals={n}", f"terminals.path={csv}", "terminals.fixed=true"]
        problem = problem_of(*common)
        grown = cco.grow(problem, 0)
        c_cco = grown.costs["volume"] + grown.costs["power"]
        best, _, _ = best_topology(problem.tissue.inlets[0], sites, problem.physics, problem.tissue.bounds)
        assert best <= c_cco * (1 + 1e-12)
        if trial == 0:
            annealed = engine.run(config.compose([*common, "anneal.steps=200000"]), seed=trial)
            c_anneal = annealed.costs_recomputed["volume"] + annealed.costs_recomputed["power"]
            assert c_anneal <= c_cco * (1 + 1e-9)


# --------------------------------------------------------------------------------------------
# Config, ids, the anneal's warm start


def test_anneal_ids_and_stored_configs_are_unchanged_and_cco_ids_name_the_method(tmp_path):
    (a,) = sweep.expand(config.compose(["model=paper", f"output_dir={tmp_path}"]))
    assert a.run_id == "heart-N200-mb641.3-s0" and a.cell == "heart-N200-mb641.3"
    assert "method" not in a.config and a.config["anneal"]["init"] == "random"
    before_cco = {**a.config, "anneal": {k: v for k, v in a.config["anneal"].items() if k != "init"}}
    assert store.config_hash(before_cco) == store.config_hash(a.config)  # stores from before CCO still resume
    (c,) = sweep.expand(config.compose(["model=paper", "method=cco", f"output_dir={tmp_path}"]))
    assert c.run_id == "heart-N200-mb641.3-cco-s0" and c.coords["method"] == "cco"
    assert c.config["method"]["name"] == "cco" and "anneal" not in c.config
    (c2,) = sweep.expand(config.compose(["model=paper", "method=cco", "anneal=paper", f"output_dir={tmp_path}"]))
    assert store.config_hash(c2.config) == store.config_hash(c.config)
    (w,) = sweep.expand(config.compose(["model=paper", "anneal.init=cco", f"output_dir={tmp_path}"]))
    assert w.run_id == a.run_id and w.config["anneal"]["init"] == "cco"
    assert store.config_hash(w.config) != store.config_hash(a.config)  # a warm start is a different run


@pytest.mark.parametrize(
    "override, field",
    [
        ("method.name=foo", "method.name"),
        ("anneal.init=tree", "anneal.init"),
        ("method.candidates=0", "method.candidates"),
        ("method.shrink=1.5", "method.shrink"),
        ("method.order=backwards", "method.order"),
    ],
)
def test_bad_method_settings_name_the_field(override, field):
    with pytest.raises(ConfigError, match=field.replace(".", r"\.")):
        config.compose([override])


def test_steps_axis_is_refused_for_cco(tmp_path):
    with pytest.raises(ConfigError, match="sweep.steps"):
        sweep.expand(config.compose(["method=cco", "+sweep=smoke", "sweep.steps=[1000]", f"output_dir={tmp_path}"]))


def test_anneal_init_cco_starts_from_the_cco_tree():
    overrides = ["tissue=sphere", "n_terminals=40", "anneal.init=cco", "anneal.steps=20000", "anneal.trace_every=10000"]
    problem = engine.build_problem(config.compose(overrides))
    state = engine.initial_state(problem, 7)
    grown = cco.grow(problem, 7)
    np.testing.assert_array_equal(state.parent, grown.tree.parent)
    np.testing.assert_array_equal(state.position, grown.tree.position)
    r1, r2 = engine.run(config.compose(overrides), seed=7), engine.run(config.compose(overrides), seed=7)
    np.testing.assert_array_equal(r1.tree.position, r2.tree.position)
    assert r1.trace["volume"][0] == pytest.approx(grown.costs["volume"], rel=1e-9)


# --------------------------------------------------------------------------------------------
# The pipeline: run stores, resume, reduction with both methods


@pytest.mark.integration
@pytest.mark.slow  # ~25 s; the CCO growth and its reduction have unit tests in the default suite
def test_pipeline_with_cco_then_reduction_with_both_methods(tmp_path):
    out = tmp_path / "both"
    grid = [
        "tissue=sphere",
        "+sweep=smoke",
        "sweep.n_terminals=[16,24]",
        "sweep.m_b=[641.3]",
        "sweep.seeds=[0,1]",
        "cluster.dashboard_address=null",
        "cluster.n_workers=1",
        f"output_dir={out}",
    ]
    cfg = config.compose([*grid, "method=cco"])
    result = orchestrate.run_sweep(cfg, stream=io.StringIO())
    jobs = sweep.expand(cfg)
    assert sorted(result.complete) == sorted(j.run_id for j in jobs) and result.failed == {}
    assert result.reduction_error is None
    again = orchestrate.run_sweep(cfg, stream=io.StringIO())  # the same command skips every complete run
    assert again.runs == [] and len(again.skipped) == len(jobs)
    for j in jobs:
        assert j.run_id.endswith(f"-cco-s{j.coords['seed']}")
        s = store.RunStore.open(j.store, mode="r")
        attrs = s.attrs
        assert attrs["status"] == "complete" and attrs["steps_done"] == j.coords["n_terminals"]
        for key, value in attrs["cost_recomputed"].items():
            assert attrs["cost"][key] == pytest.approx(value, rel=1e-9), key
        grown = cco.grow(engine.build_problem(j.config), j.coords["seed"])
        np.testing.assert_array_equal(s.read_tree()["parent"], grown.tree.parent)
        trace = xr.open_zarr(j.store, group="trace")
        assert trace.sizes["step"] == j.coords["n_terminals"] and int(trace.step[-1]) == j.coords["n_terminals"]
        check_tree(
            Tree(
                grown.tree.parent,
                grown.tree.children,
                s.read_tree()["position"],
                grown.tree.n_downstream,
                grown.tree.n_inlets,
            )
        )
    before = {j.run_id: store.RunStore.open(j.store, mode="r").attrs["wall_seconds"] for j in jobs}
    summary = job.run_job(jobs[0])  # a finished CCO run is skipped, as an anneal run is
    assert summary["status"] == "skipped"
    assert store.RunStore.open(jobs[0].store, mode="r").attrs["wall_seconds"] == before[jobs[0].run_id]
    # Anneal runs of the same grid into the same directory, then one reduction over both.
    for j in sweep.expand(config.compose([*grid, "anneal.steps=20000", "anneal.trace_every=10000"])):
        job.run_job(j)
    red = reduce_and_draw(out, stream=io.StringIO())
    assert red.cell_dims[0] == "method"
    costs = xr.open_zarr(out / "summary.zarr", group="costs")
    assert list(costs.method.values) == ["anneal", "cco"]
    assert costs.cost_total.sel({"method": "cco"}).notnull().all()
    assert costs.cost_total.sel({"method": "anneal"}).notnull().all()
    morph = xr.open_zarr(out / "summary.zarr", group="morphometry")
    assert "-cco-" in str(morph.best_run_id.sel({"method": "cco", "n_terminals": 16}).values)
    assert red.figures and not red.errors
    assert set(red.comparison["method"]) == {"anneal", "cco"}


# --------------------------------------------------------------------------------------------
# The benchmark cannot rot


@pytest.mark.integration
def test_comparison_benchmark_quick(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "cco_comparison.py"),
            "--quick",
            "--workers",
            "1",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr
    rows = [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()]
    assert {r["method"] for r in rows} == {"cco", "anneal", "cco_grown"}
    tables = json.loads((tmp_path / "tables.json").read_text())
    assert {e["n"] for e in tables["energy"]} == {12, 20} and tables["order"] and tables["asymmetry"]
    assert "trunk" in proc.stdout


# --------------------------------------------------------------------------------------------
# Cavities (method.avoid_cavities)


def test_voxel_walk_equals_the_exact_traversal():
    """cco.crosses (the kernel's voxel walk) against the exact traversal of the exclusion term, on
    random segments of every length over the heart's cavities, inside and beyond the grid."""
    tissue = problem_of("tissue=heart", "n_terminals=200").tissue
    cavity = tissue.cavity.astype(np.uint8)
    lo, hi = tissue.bounds
    gen = np.random.default_rng(1)
    hits = 0
    for trial in range(3000):
        a = gen.uniform(lo - 0.01, hi + 0.01)
        b = a + gen.normal(size=3) * (10.0 ** gen.uniform(-4, -1.5))
        got = cco.crosses(cavity, tissue.origin, tissue.voxel_size, a, b)
        assert got == naive_crosses(cavity, tissue, a, b), trial
        hits += got
    assert 100 < hits < 2900


def test_avoid_cavities_keeps_every_segment_out_of_the_cavities():
    plain = cco.grow(problem_of("tissue=heart", "n_terminals=300"), 4)
    problem = problem_of("tissue=heart", "n_terminals=300", "method.avoid_cavities=true")
    kept = cco.grow(problem, 4)
    check_tree(kept.tree, problem.tissue)

    def in_cavity(tree):
        seg = np.flatnonzero(tree.parent >= 0)
        return sum(
            naive_crosses(problem.tissue.cavity, problem.tissue, tree.position[i], tree.position[tree.parent[i]])
            for i in seg
        )

    assert in_cavity(plain.tree) > 0 and in_cavity(kept.tree) == 0
    assert kept.costs["volume"] + kept.costs["power"] >= 0.9 * (plain.costs["volume"] + plain.costs["power"])
    (j,) = sweep.expand(config.compose(["method=cco", "method.avoid_cavities=false"]))
    (d,) = sweep.expand(config.compose(["method=cco"]))
    assert store.config_hash(j.config) == store.config_hash(d.config)  # stores from before the key keep resuming
