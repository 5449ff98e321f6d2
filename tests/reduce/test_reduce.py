"""The reduction on finished sweeps: best seed per cell, summary.zarr schema and units, Kassab
values, the comparison table, figures, tree exports, the sweep hook and ``+stage=reduce``.

The sweeps are tiny (16/24 terminals, 5e4 proposals) and run in this process with
:func:`vasc_pipeline.pipeline.job.run_job`, which writes the same stores as a Dask sweep.
"""

from __future__ import annotations

import io
import itertools
import os
import shutil
import socket
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from helpers import REPO, png_is_a_real_figure

from vasc_pipeline import config, job, morphometry, store, sweep
from vasc_pipeline import reduce as reduce_mod
from vasc_pipeline.pipeline import orchestrate
from vasc_pipeline.pipeline.reduction import reduce_and_draw
from vasc_pipeline.reduce.reference import kassab_csv_path
from vasc_pipeline.reduce.summary import write_summary

pytestmark = pytest.mark.integration  # the pipeline end to end (tests/conftest.py)

GRID = [
    "+sweep=smoke",
    "sweep.n_terminals=[16,24]",
    "sweep.m_b=[641.3,6413.0]",
    "sweep.seeds=[0,1,2]",
    "anneal.steps=50000",
    "anneal.trace_every=10000",
    "cluster.dashboard_address=null",
]
GROUPS = ("morphometry", "asymmetry", "costs", "anatomy", "traces", "kassab", "comparison")


def run_all(out: Path, *overrides: str) -> list[sweep.Job]:
    jobs = sweep.expand(config.compose([*overrides, f"output_dir={out}"]))
    for j in jobs:
        job.run_job(j)
    return jobs


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    jobs = run_all(out, *GRID)
    stream = io.StringIO()
    result = reduce_and_draw(out, stream=stream)
    return out, jobs, result, stream.getvalue()


@pytest.fixture(scope="module")
def summary(swept):
    return xr.open_datatree(swept[0] / "summary.zarr", engine="zarr")


def test_lowest_cost_seed_is_chosen_in_every_cell(swept, summary):
    out, jobs, result, _ = swept
    costs: dict[tuple, dict[int, float]] = {}
    for j in jobs:
        total = store.RunStore.open(j.store, mode="r").attrs["cost"]["total"]
        costs.setdefault((j.coords["n_terminals"], j.coords["m_b"]), {})[j.coords["seed"]] = total
    morph, c = summary["morphometry"], summary["costs"]
    assert len(costs) == 4 and result.cell_dims == ["n_terminals", "m_b"]
    for (n, m_b), by_seed in costs.items():
        best_seed = min(by_seed, key=lambda s: (by_seed[s], s))
        point = {"n_terminals": n, "m_b": m_b}
        assert int(morph["best_seed"].sel(point)) == best_seed
        assert str(morph["best_run_id"].sel(point).values) == sweep.run_id("sphere", n, m_b, best_seed)
        assert float(morph["best_cost"].sel(point)) == by_seed[best_seed]
        assert int(morph["n_seeds"].sel(point)) == 3
        # every seed's final cost is stored, and is_best marks the minimum
        stored = c["cost_total"].sel(point)
        assert [float(stored.sel(seed=s)) for s in sorted(by_seed)] == [by_seed[s] for s in sorted(by_seed)]
        assert c["is_best"].sel(point).values.tolist() == [int(s == best_seed) for s in sorted(by_seed)]
    # the seeds really differ, so choosing is not trivial
    assert any(len(set(v.values())) > 1 for v in costs.values())


def test_trunk_spread_measures_how_alike_the_seeds_trees_are(swept, summary):
    from vasc_pipeline.reduce.similarity import main_trunks, trunk_distance

    _, jobs, _, _ = swept
    spread = summary["morphometry"]["trunk_spread"]
    assert spread.attrs["units"] == "m"
    for (n, m_b), cell in itertools.groupby(
        sorted(jobs, key=lambda j: (j.coords["n_terminals"], j.coords["m_b"])),
        key=lambda j: (j.coords["n_terminals"], j.coords["m_b"]),
    ):
        trees = [store.RunStore.open(j.store, mode="r").read_tree() for j in cell]
        trunks = [main_trunks(t["parent"], t["position"], t["kind"])[0] for t in trees]  # one inlet (sphere)
        pairs = [trunk_distance(a, b) for a, b in itertools.combinations(trunks, 2)]
        value = float(spread.sel(n_terminals=n, m_b=m_b))
        assert value == pytest.approx(np.mean(pairs), rel=1e-12) and value > 0
    # the best tree's trunk: arc over chord, >= 1
    tortuosity = summary["morphometry"]["trunk_tortuosity"]
    best = store.RunStore.open(swept[2].best[(16, 641.3)].path, mode="r").read_tree()
    (trunk,) = main_trunks(best["parent"], best["position"], best["kind"])
    arc = np.sum(np.linalg.norm(np.diff(trunk, axis=0), axis=1))
    expected = arc / np.linalg.norm(trunk[-1] - trunk[0])
    assert float(tortuosity.sel(n_terminals=16, m_b=641.3)) == pytest.approx(expected, rel=1e-12)
    assert (tortuosity >= 1).all()


def test_morphometry_is_that_of_the_best_tree(swept, summary):
    out, _, result, _ = swept
    morph = summary["morphometry"].to_dataset()
    for key, run in result.best.items():
        tree = store.RunStore.open(run.path, mode="r").read_tree()
        direct = morphometry.morphometry(tree["parent"], tree["position"], tree["radius"], tree["kind"])
        point = dict(zip(result.cell_dims, key))
        for name in ("element_diameter_mean", "element_length_se", "element_count", "segment_diameter_mean"):
            stored = morph[name].sel(point).sel(order=direct.order)
            np.testing.assert_array_equal(stored.values, direct[name].transpose("scheme", "order").values)
        # orders of trees of different N are aligned on the shifted order: the top is 11
        counts = morph["element_count"].sel(point).sel(scheme="diameter_defined")
        assert int(counts.order[counts > 0].max()) == 11
        assert int(counts.sel(order=11)) >= 1
    # cells of different N share one order axis: absent orders hold count 0 and NaN statistics
    counts = morph["element_count"]
    assert (counts == 0).any() and morph.order.values.tolist() == list(range(int(morph.order.min()), 12))
    assert morph["element_diameter_mean"].where(counts == 0).isnull().all()
    assert morph["element_diameter_mean"].where(counts > 0).notnull().sum() == (counts > 0).sum()


def test_every_group_opens_with_open_zarr_and_has_units_and_long_names(swept):
    out = swept[0]
    tree = xr.open_datatree(out / "summary.zarr", engine="zarr")
    assert set(GROUPS) <= set(tree.children)
    assert tree.attrs["cell_dims"] == ["n_terminals", "m_b"] and tree.attrs["n_runs"] == 12
    expected_dims = {
        "morphometry": {"n_terminals": 2, "m_b": 2, "scheme": 2},
        "asymmetry": {"n_terminals": 2, "m_b": 2, "scheme": 2},
        "costs": {"n_terminals": 2, "m_b": 2, "seed": 3},
        "anatomy": {"n_terminals": 2, "m_b": 2, "seed": 3, "inlet": 1},
        "traces": {"n_terminals": 2, "m_b": 2, "seed": 3, "record": 6},
        "kassab": {"artery": 3, "level": 2, "order": 11},
        "comparison": {"n_terminals": 2, "m_b": 2, "artery": 3},
    }
    for group in GROUPS:
        ds = xr.open_zarr(out / "summary.zarr", group=group)
        for dim, size in expected_dims[group].items():
            assert ds.sizes[dim] == size, (group, dim)
        for name, var in ds.variables.items():
            assert "long_name" in var.attrs, (group, name)
            if var.dtype.kind in "fiu":
                assert "units" in var.attrs, (group, name)
    morph = xr.open_zarr(out / "summary.zarr", group="morphometry")
    assert morph["element_diameter_mean"].dims == ("n_terminals", "m_b", "scheme", "order")
    assert morph["element_diameter_mean"].attrs["units"] == "m"
    assert morph["m_b"].attrs["units"] == "W m-3"
    assert morph["order"].values.max() == 11
    assert str(morph["tissue"].values) == "sphere"
    assert xr.open_zarr(out / "summary.zarr", group="costs")["cost_total"].attrs["units"] == "W"


def test_traces_are_the_stored_traces_of_every_seed(swept, summary):
    traces = summary["traces"].to_dataset()
    for j in swept[1]:
        stored = store.RunStore.open(j.store, mode="r").read_trace()
        t = traces.sel(n_terminals=j.coords["n_terminals"], m_b=j.coords["m_b"], seed=j.coords["seed"])
        k = int(t["trace_length"])
        assert k == len(stored["step"]) == 6  # step 0 and 5 blocks of 1e4
        np.testing.assert_array_equal(t["step"].values[:k], stored["step"])
        np.testing.assert_array_equal(t["total"].values[:k], stored["total"])


def test_stored_kassab_values_equal_the_csv(summary):
    text = kassab_csv_path().read_text()
    csv = pd.read_csv(io.StringIO(text), skiprows=1)
    kassab = summary["kassab"].to_dataset()
    assert len(csv) > 50
    for row in csv.itertuples():
        at = kassab.sel(artery=row.artery, level=row.level, order=row.order)
        assert float(at.D_mean) == pytest.approx(row.D_mean_um * 1e-6, rel=1e-12)
        assert float(at.L_mean) == pytest.approx(row.L_mean_mm * 1e-3, rel=1e-12)
        assert int(at.D_n) == row.D_n
    assert "Kassab" in kassab.attrs["source"]


def test_comparison_table_stored_printed_and_csv(swept, summary):
    out, _, result, printed = swept
    comp = summary["comparison"].to_dataset()
    morph = summary["morphometry"].to_dataset()
    kassab = summary["kassab"].to_dataset().sel(level="element")
    point = {"n_terminals": 24, "m_b": 641.3}
    model_d = morph["element_diameter_mean"].sel(point).sel(scheme="diameter_defined")
    model_l = morph["element_length_mean"].sel(point).sel(scheme="diameter_defined")
    for artery in ("RCA", "LAD", "LCX"):
        c = comp.sel(point).sel(artery=artery)
        both = (morph["element_count"].sel(point).sel(scheme="diameter_defined") > 0) & (
            kassab.D_n.sel(artery=artery) > 0
        ).reindex(order=model_d.order, fill_value=False)
        orders = model_d.order[both].values
        assert orders.size >= 2
        ratio_d = np.log10(model_d.sel(order=orders).values / kassab.D_mean.sel(artery=artery, order=orders).values)
        ratio_l = np.log10(model_l.sel(order=orders).values / kassab.L_mean.sel(artery=artery, order=orders).values)
        np.testing.assert_allclose(c.diameter_log10_ratio.sel(order=orders), ratio_d, rtol=1e-12)
        assert float(c.mean_abs_log10_ratio_diameter) == pytest.approx(np.abs(ratio_d).mean(), rel=1e-12)
        assert float(c.mean_abs_log10_ratio_length) == pytest.approx(np.abs(ratio_l).mean(), rel=1e-12)
        assert int(c.n_orders_compared) == orders.size
    # the CSV holds the same numbers
    csv = pd.read_csv(out / "comparison.csv")
    row = csv[(csv.n_terminals == 24) & (csv.m_b == 641.3) & (csv.artery == "LAD") & (csv.order == 11)]
    assert len(row) == 1
    assert row.model_diameter_m.iloc[0] == pytest.approx(float(model_d.sel(order=11)), rel=1e-5)
    assert row.run_id.iloc[0] == str(morph["best_run_id"].sel(point).values)
    summary_csv = pd.read_csv(out / "comparison_summary.csv")
    assert len(summary_csv) == 4 * 3  # cells x arteries
    assert {"inlet_share_root", "terminal_pressure_min_Pa", "bifurcations_off_organ_share"} <= set(summary_csv.columns)
    # printed: one block per cell with the mean |log10 ratio| line and the best tree's anatomy
    assert printed.count("mean |log10 model/Kassab|") == 4
    assert printed.count("bifurcations > 2 mm off the organ") == 4
    assert str(morph["best_run_id"].sel(point).values) in printed


def test_figures_exist_and_are_not_blank(swept):
    out, _, result, _ = swept
    assert not result.errors
    names = {p.name for p in result.figures}
    expected = {"morphometry_vs_kassab.png", "asymmetry.png", "mb_effect.png", "cost_traces.png", "anatomy.png"}
    expected |= {"size_scan.png", "agreement_vs_n.png"}  # two N
    expected |= {f"tree_{r.run_id}.png" for r in result.best.values()}
    assert names == expected  # no steps axis: no convergence or consistency figure
    for p in result.figures:
        assert p.parent == out / "figures"
        png_is_a_real_figure(p)


def test_best_trees_are_exported_as_vtp_csv_and_0d_json(swept):
    out, _, result, _ = swept
    assert len(result.trees) == 3 * len(result.best)
    assert {p.name for p in result.trees} == {
        f"{r.run_id}{suffix}" for r in result.best.values() for suffix in (".vtp", ".csv", ".0d.json")
    }
    for run in result.best.values():
        tree = store.RunStore.open(run.path, mode="r").read_tree()
        n_nodes, n_inlets = tree["parent"].size, int((tree["parent"] < 0).sum())
        root = ET.parse(out / "trees" / f"{run.run_id}.vtp").getroot()
        assert root.get("type") == "PolyData"
        piece = root.find("PolyData/Piece")
        assert int(piece.get("NumberOfPoints")) == n_nodes == 2 * run.n_terminals
        assert int(piece.get("NumberOfLines")) == n_nodes - n_inlets
        cell = {a.get("Name"): np.array(a.text.split(), dtype=float) for a in piece.find("CellData")}
        assert set(cell) >= {"radius", "flow", "order"}
        seg = np.flatnonzero(tree["parent"] >= 0)
        np.testing.assert_array_equal(cell["radius"], tree["radius"][seg])
        assert cell["order"].max() == 11
        table = pd.read_csv(out / "trees" / f"{run.run_id}.csv")
        assert len(table) == n_nodes and table.radius_m.notna().sum() == n_nodes - n_inlets


def test_exports_of_a_superseded_best_tree_are_removed(swept, tmp_path):
    # As when a better seed finishes after a first reduction: that reduction's exports and
    # tree figure of the former best stay behind unless the next reduction removes them.
    out = tmp_path / "sweep"
    shutil.copytree(swept[0] / "runs", out / "runs")
    first = reduce_mod.reduce(out, stream=io.StringIO())
    best = {r.run_id for r in first.best.values()}
    former = sorted({p.name.removesuffix(".zarr") for p in (out / "runs").glob("*.zarr")} - best)[0]
    stale = [out / "trees" / f"{former}.vtp", out / "trees" / f"{former}.csv", out / "figures" / f"tree_{former}.png"]
    (out / "figures").mkdir()
    for path in stale:
        path.write_text("from an earlier reduction")
    mine = out / "trees" / "notes.txt"
    mine.write_text("not named after a run")
    stream = io.StringIO()
    second = reduce_mod.reduce(out, stream=stream)
    assert sorted(second.removed) == sorted(stale) and not any(p.exists() for p in stale)
    assert mine.exists() and all((out / "trees" / f"{b}.vtp").exists() for b in best)
    assert "removed 3 exports and figures" in stream.getvalue()


def test_grid_with_a_steps_axis_gets_a_steps_dim_and_a_convergence_figure(tmp_path):
    run_all(
        tmp_path,
        "tissue=plane2d",
        "+sweep=convergence",
        "sweep.n_terminals=[16]",
        "sweep.seeds=[0,1]",
        "sweep.steps=[10000,30000]",
        "anneal.trace_every=10000",
        "cluster.dashboard_address=null",
    )
    result = reduce_and_draw(tmp_path, stream=io.StringIO())
    assert result.cell_dims == ["n_terminals", "m_b", "steps"]
    costs = xr.open_zarr(tmp_path / "summary.zarr", group="costs")
    assert costs.sizes["steps"] == 2 and costs.sizes["seed"] == 2
    assert costs.steps_done.sel(steps=30000).values.ravel().tolist() == [30000, 30000]
    conv, consistency = tmp_path / "figures" / "convergence.png", tmp_path / "figures" / "consistency.png"
    assert conv in result.figures and consistency in result.figures
    png_is_a_real_figure(conv)
    png_is_a_real_figure(consistency, min_shape=(400, 400))  # 2 x 2 small panels
    spread = xr.open_zarr(tmp_path / "summary.zarr", group="morphometry")["trunk_spread"]
    assert spread.notnull().all()  # the number printed on each row of consistency.png
    assert not (tmp_path / "figures" / "mb_effect.png").exists()  # a single m_b
    assert not (tmp_path / "figures" / "size_scan.png").exists()  # a single N

    # several sweeps' convergence on one plot, from the command line
    cli = [sys.executable, "-m", "vasc_pipeline.figures", "convergence"]
    both = tmp_path / "both.png"
    done = subprocess.run([*cli, str(both), f"paper={tmp_path}", f"fast={tmp_path}"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    png_is_a_real_figure(both)
    bad = subprocess.run([*cli, str(both), f"x={tmp_path / 'nowhere'}"], capture_output=True, text=True)
    assert bad.returncode == 2 and "reduce the sweep first" in bad.stderr


def test_unfinished_stores_are_left_out_and_empty_dirs_refused(tmp_path):
    with pytest.raises(reduce_mod.ReductionError, match="no complete run"):
        reduce_mod.reduce(tmp_path)
    (j,) = run_all(
        tmp_path,
        *GRID[:1],
        "sweep.n_terminals=[16]",
        "sweep.m_b=[641.3]",
        "sweep.seeds=[0]",
        "anneal.steps=20000",
        "anneal.trace_every=10000",
    )
    running = store.run_path(tmp_path, "sphere-N16-mb641.3-s9")
    store.RunStore.create(
        running,
        run_id="sphere-N16-mb641.3-s9",
        seed=9,
        config=j.config,
        coords={**j.coords, "seed": 9},
        total_steps=20000,
    )
    result = reduce_mod.reduce(tmp_path, exports=False, stream=io.StringIO())
    assert list(result.skipped) == [str(running)] and "running" in result.skipped[str(running)]
    costs = xr.open_zarr(tmp_path / "summary.zarr", group="costs")
    assert costs.seed.values.tolist() == [0]
    # a second reduction replaces the summary in place
    reduce_mod.reduce(tmp_path, exports=False, stream=io.StringIO())
    # the swap leaves no copy behind, only its (hidden) lock file
    left = sorted(p.name for p in tmp_path.iterdir() if "summary.zarr" in p.name)
    assert left == [".summary.zarr.lock", "summary.zarr"]


def test_sweep_reduces_at_the_end_and_a_failed_reduction_loses_no_run(tmp_path, monkeypatch):
    from distributed import Client, LocalCluster

    cfg = config.compose(
        [
            *GRID,
            "sweep.n_terminals=[16]",
            "sweep.m_b=[641.3]",
            "sweep.seeds=[0,1]",
            "anneal.steps=20000",
            f"output_dir={tmp_path}",
        ]
    )

    def broken(*args, **kwargs):
        raise RuntimeError("figure backend exploded")

    monkeypatch.setattr(reduce_mod, "reduce", broken)
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl,
        Client(cl) as client,
    ):
        stream = io.StringIO()
        result = orchestrate.run_sweep(cfg, client=client, stream=stream)
    assert sorted(result.complete) == [j.run_id for j in sweep.expand(cfg)]
    assert result.reduction is None and "figure backend exploded" in result.reduction_error
    assert "+stage=reduce" in stream.getvalue()
    assert not (tmp_path / "summary.zarr").exists()
    monkeypatch.undo()
    # rerun: every run is complete (none re-run), and the reduction now succeeds
    result = orchestrate.run_sweep(cfg, stream=io.StringIO())
    assert result.complete == [] and len(result.skipped) == 2
    assert result.reduction_error is None and result.reduction.summary_path == tmp_path / "summary.zarr"
    assert xr.open_zarr(tmp_path / "summary.zarr", group="morphometry")["n_seeds"].values.tolist() == [[2]]


def test_stage_reduce_on_the_command_line(swept, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}

    def reduce_stage(output_dir):
        return subprocess.run(
            [sys.executable, "-m", "vasc_pipeline", "+stage=reduce", f"output_dir={output_dir}"],
            env=env,
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=300,
        )

    out = swept[0]
    before = (out / "runs").stat().st_mtime_ns
    proc = reduce_stage(out)
    assert proc.returncode == 0, proc.stderr
    assert "mean |log10 model/Kassab|" in proc.stdout + proc.stderr
    assert (out / "runs").stat().st_mtime_ns == before  # no run was touched
    assert xr.open_datatree(out / "summary.zarr", engine="zarr").attrs["n_runs"] == 12
    # nothing to reduce: a clear error and status 2
    proc = reduce_stage(tmp_path / "x")
    assert proc.returncode == 2 and "nothing to reduce" in proc.stderr


def test_anatomy_of_every_run_is_stored_in_csv_and_matches_the_stores(swept, summary):
    from vasc_pipeline.reduce.anatomy import anatomy_of_store

    out, jobs, result, _ = swept
    anatomy = summary["anatomy"].to_dataset()
    frame = pd.read_csv(out / "anatomy.csv")
    assert len(frame) == len(jobs) == 12 and result.anatomy_csv == out / "anatomy.csv"
    for j in jobs[:3]:
        expected = anatomy_of_store(j.store)
        at = {k: j.coords[k] for k in ("n_terminals", "m_b", "seed")}
        row = frame[frame.run_id == j.run_id].iloc[0]
        assert float(anatomy["terminal_pressure_min"].sel(at)) == pytest.approx(expected["terminal_pressure_min"])
        assert row.terminal_pressure_min_Pa == pytest.approx(expected["terminal_pressure_min"], rel=1e-5)
        assert float(anatomy["inlet_share"].sel(at).sel(inlet="root")) == 1.0  # one inlet feeds them all
        assert row.inlet_share_root == 1.0
    # svZeroDSolver, on every exported network, returns the inlet pressure the terminal pressures imply
    assert set(result.zero_d_check) == {r.run_id for r in result.best.values()}
    assert max(result.zero_d_check.values()) < 1e-6


def test_cavity_share_of_every_heart_run_is_in_the_costs_group(tmp_path, summary):
    assert np.isnan(summary["costs"]["cavity_share"].values).all()  # spheres have no cavity
    jobs = run_all(
        tmp_path,
        "n_terminals=16",
        "anneal.steps=20000",
        "anneal.trace_every=10000",
        "+sweep=smoke",
        "sweep.n_terminals=[16]",
        "sweep.m_b=[641.3]",
        "sweep.seeds=[0,1]",
        "tissue=heart",
    )
    result = reduce_mod.reduce(tmp_path, exports=False, stream=io.StringIO())
    shares = result.summary["costs"]["cavity_share"]
    for j in jobs:
        stored = store.RunStore.open(j.store, mode="r").attrs["statistics"]["cavity_share"]
        assert 0.0 <= stored <= 1.0
        assert float(shares.sel(n_terminals=16, m_b=641.3, seed=j.coords["seed"])) == stored


def test_figures_leave_the_callers_matplotlib_state_alone(swept):
    """Importing the figures module or drawing changes neither the backend nor rcParams."""
    code = (
        "import matplotlib; matplotlib.use('svg'); matplotlib.rcParams['font.size'] = 13.0; "
        "from vasc_pipeline import figures, reduce; import xarray as xr, sys; "
        "figures.make_figures(xr.open_datatree(sys.argv[1] + '/summary.zarr', engine='zarr'), sys.argv[1]); "
        "print(matplotlib.get_backend(), matplotlib.rcParams['font.size'], matplotlib.rcParams['savefig.bbox'])"
    )
    out = subprocess.run([sys.executable, "-c", code, str(swept[0])], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["svg", "13.0", "None"]


def test_a_summary_over_several_tissues_gets_a_tissue_dim(tmp_path):
    """Runs of two tissues (one output_dir each, as a sweep writes them) reduced together."""
    tiny = ["+sweep=smoke", "sweep.n_terminals=[16]", "sweep.m_b=[641.3]", "sweep.seeds=[0,1]"]
    tiny += ["anneal.steps=20000", "anneal.trace_every=10000", "cluster.dashboard_address=null"]
    jobs = []
    for name in ("sphere", "plane2d"):
        jobs += run_all(tmp_path / name, *tiny, f"tissue={name}")
    runs = reduce_mod.find_runs(tmp_path / "sphere")[0] + reduce_mod.find_runs(tmp_path / "plane2d")[0]
    summary, best, dims = reduce_mod.build_summary(runs)
    assert dims == ["tissue", "n_terminals", "m_b"]
    assert summary.attrs["tissues"] == ["plane2d", "sphere"] and len(best) == 2
    c = summary["costs"]
    assert c["cost_total"].sizes == {"tissue": 2, "n_terminals": 1, "m_b": 1, "seed": 2}
    for j in jobs:
        stored = store.RunStore.open(j.store, mode="r").attrs["cost"]["total"]
        point = {"tissue": j.coords["tissue"], "n_terminals": 16, "m_b": 641.3, "seed": j.coords["seed"]}
        assert float(c["cost_total"].sel(point)) == stored
    morph = summary["morphometry"]
    for (name, n, m_b), r in best.items():
        assert r.tissue == name
        assert str(morph["best_run_id"].sel(tissue=name, n_terminals=n, m_b=m_b).values) == r.run_id
    frame = reduce_mod.comparison_frame(summary)
    assert set(frame["tissue"]) == {"plane2d", "sphere"}
    with pytest.raises(reduce_mod.ReductionError, match="different configurations"):
        reduce_mod.check_one_configuration(tmp_path, runs)  # one output_dir never mixes them


def test_write_summary_swaps_in_the_new_summary_and_removes_a_crashed_write_s_leftovers(tmp_path):
    path = tmp_path / "summary.zarr"
    first = xr.DataTree(xr.Dataset({"x": ("i", np.arange(3.0), {"units": "1", "long_name": "x"})}))
    write_summary(first, path)
    # A crash between the two renames of an earlier reduction: no summary.zarr, the old one
    # hidden beside it, and a partial temporary one of another crashed writer. A reduction
    # still running beside this one (the test process's parent stands for it) keeps its files.
    # Another host's writer is never judged from here.
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = socket.gethostname()
    os.replace(path, tmp_path / f".summary.zarr.old-{host}-{dead.pid}")
    (tmp_path / f".summary.zarr.tmp-{host}-{dead.pid}").mkdir()
    kept = [f".summary.zarr.tmp-{host}-{os.getppid()}", f".summary.zarr.tmp-{host}x-{dead.pid}"]
    for name in kept:
        (tmp_path / name).mkdir()
    second = xr.DataTree(xr.Dataset({"x": ("i", np.arange(4.0), {"units": "1", "long_name": "x"})}))
    write_summary(second, path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([".summary.zarr.lock", "summary.zarr", *kept])
    assert xr.open_datatree(path, engine="zarr")["x"].size == 4


# -- tissue.organ: the comparison with the pig heart only for a heart ---------------------------

ONE_RUN = ["+sweep=smoke", "sweep.m_b=[641.3]", "sweep.seeds=[0]", "anneal.steps=5000"]


def test_a_tissue_that_is_not_a_heart_is_reduced_without_the_kassab_comparison(tmp_path):
    out = tmp_path / "shell"
    run_all(out, *ONE_RUN, "sweep.n_terminals=[16,24]", "tissue.organ=other")
    (out / "comparison.csv").write_text("left by an earlier reduction\n")  # not this configuration's: removed
    stream = io.StringIO()
    result = reduce_and_draw(out, stream=stream)
    printed = stream.getvalue()
    assert not result.errors, result.errors
    assert "Kassab" in printed and "tissue.organ is other" in printed, printed  # one line saying why not
    assert "mean |log10 model/Kassab|" not in printed and "D LAD" not in printed, printed
    assert result.comparison is None and result.comparison_csv is None and result.comparison_summary_csv is None
    assert not (out / "comparison.csv").exists() and not (out / "comparison_summary.csv").exists()
    summary = xr.open_datatree(out / "summary.zarr", engine="zarr")
    assert {"morphometry", "asymmetry", "costs", "traces"} <= set(summary.children)
    assert not {"comparison", "kassab"} & set(summary.children)
    assert summary.attrs["organ"] == "other"
    names = {p.name for p in result.figures}
    assert {"morphometry.png", "asymmetry.png", "cost_traces.png", "size_scan.png"} <= names, names
    assert not {"morphometry_vs_kassab.png", "agreement_vs_n.png"} & names, names
    for p in result.figures:
        png_is_a_real_figure(p, min_shape=(200, 300))
    assert len(result.trees) == 3 * len(result.best)  # the rest as for a heart


def test_which_tissues_are_compared_with_the_pig_heart():
    organ = config.organ_of
    assert [organ(t, None, 2) for t in ("heart", "sphere", "box", "plane2d")] == ["heart"] * 4
    assert organ("mask", None, 2) == "heart" and organ("mask", None, 3) == "heart"  # ostia: a heart's map
    assert organ("mask", None, 1) == "other"  # one inlet: an organ of another kind
    assert organ("mask", "heart", 1) == "heart" and organ("heart", "other", 2) == "other"  # as told
    with pytest.raises(config.ConfigError, match=r"tissue\.organ must be one of heart, other, or null .*got 'liver'"):
        config.compose(["tissue.organ=liver"])
    stored = asdict(config.compose([]))
    del stored["tissue"]["organ"]  # a store written before the key
    assert store.config_hash(stored) == store.config_hash(asdict(config.compose([])))
    assert store.config_hash(asdict(config.compose(["tissue.organ=other"]))) != store.config_hash(stored)


def test_a_mask_with_one_inlet_is_reduced_without_the_comparison(tmp_path):
    z, y, x = np.indices((16, 16, 16)) - 7.5
    np.save(tmp_path / "organ.npy", (x**2 + y**2 + z**2 <= 49).astype(np.uint8))
    out = tmp_path / "mask"
    mask = ["tissue=mask", f"tissue.path={tmp_path / 'organ.npy'}", "tissue.voxel_size=0.001"]
    run_all(out, *ONE_RUN, "sweep.n_terminals=[16]", *mask, "tissue.inlets=[[0.0075,0.0075,0.015]]")
    result = reduce_mod.reduce(out, stream=io.StringIO())
    assert result.comparison is None and not (out / "comparison.csv").exists()
