"""The reduction of the whole tree (vasc_pipeline.reduce.extended): pass-through nodes (the annealed
terminals, kind 3) read as no branch point everywhere, the lumped 0D network against the full
tree's Poiseuille solution, every fine terminal's pressure reported, and the outputs.

Hand-built trees first; then one small extension (a CCO heart of 40 terminals, 10 fine ones
below each) made once in this module.
"""

from __future__ import annotations

import io
import json
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest
import xarray as xr
from helpers import png_is_a_real_figure, random_topology

from vasc_pipeline import config, job, sweep
from vasc_pipeline.model.costs import node_pressures, poiseuille, tree_pressures
from vasc_pipeline.model.physics import Physics
from vasc_pipeline.model.topology import KIND_TERRITORY_ROOT, check_tree_arrays, terminals_downstream
from vasc_pipeline.model.tree import tree_from_arrays
from vasc_pipeline.pipeline.extend import extend_run
from vasc_pipeline.pipeline.reduction import reduce_and_draw
from vasc_pipeline.reduce import extended as extended_module
from vasc_pipeline.reduce import reduce, zerod
from vasc_pipeline.reduce.anatomy import crown_exponents, terminal_pressures
from vasc_pipeline.reduce.extended import (
    full_network,
    lumped_network,
    read_whole_tree,
    reduce_extended,
    territories,
    territory_table,
)
from vasc_pipeline.reduce.morphometry import morphometry, segment_lengths, strahler_orders
from vasc_pipeline.store.extended import ExtendedStore
from vasc_pipeline.store.layout import extended_path

GAMMA = 2.1


# --------------------------------------------------------------------------------------------
# Hand-built trees


def random_tree(n_terminals: int, seed: int):
    """A random binary tree in the anneal's layout (inlet 0, terminals 1..N, bifurcations after),
    positions uniform in a 10 mm cube, Murray radii from the terminals downstream."""
    rs = np.random.default_rng(seed)
    n = n_terminals
    parent = random_topology(n, rs)
    kind = np.full(2 * n, 1, dtype=np.int8)
    kind[0], kind[1 : n + 1] = 0, 2
    position = rs.uniform(0, 1e-2, (2 * n, 3))
    count = terminals_downstream(parent, kind)
    radius = np.where(parent >= 0, 1e-4 * count ** (1 / GAMMA), 0.0)
    return parent, position, radius, kind


def with_pass_through(parent, position, radius, kind, nodes, bend=0.0, seed=0):
    """The tree with a pass-through node (kind 3) inserted on the segment ending at each of
    ``nodes``, at its midpoint moved ``bend`` (m) off the chord: the whole tree's layout."""
    rs = np.random.default_rng(seed)
    nodes = np.asarray(nodes)
    new = np.arange(parent.size, parent.size + nodes.size)
    mid = 0.5 * (position[nodes] + position[parent[nodes]]) + bend * rs.normal(size=(nodes.size, 3))
    parent2 = np.concatenate([parent, parent[nodes]])
    parent2[nodes] = new
    return (
        parent2,
        np.concatenate([position, mid]),
        np.concatenate([radius, radius[nodes]]),
        np.concatenate([kind, np.full(nodes.size, KIND_TERRITORY_ROOT, np.int8)]),
    )


def test_a_pass_through_node_is_no_branch_point_for_the_orders_and_the_morphometry():
    tree = random_tree(60, seed=1)
    parent, position, radius, kind = tree
    segments = np.flatnonzero(parent >= 0)
    through = with_pass_through(*tree, segments[::3])  # on straight segments, at the midpoint
    check_tree_arrays(*through[:1], through[3], radius=through[2], position=through[1])
    n = parent.size
    np.testing.assert_array_equal(strahler_orders(through[0], through[3])[:n], strahler_orders(parent, kind))
    for reading in ("range", "confluence"):
        plain = morphometry(parent, position, radius, kind, reading=reading)
        ds = morphometry(*through, reading=reading)
        assert ds.attrs["n_pass_through"] == segments[::3].size and ds.attrs["n_segments"] == plain.attrs["n_segments"]
        for name, var in plain.drop_dims("node").data_vars.items():
            np.testing.assert_allclose(ds[name].values, var.values, rtol=1e-12, err_msg=f"{reading} {name}")
        order = ds.segment_order.values
        np.testing.assert_array_equal(order[:, :n], plain.segment_order.values)
        np.testing.assert_array_equal(order[:, n:], order[:, segments[::3]])  # the order of the vessel it lies on


def test_a_bent_vessel_through_a_pass_through_node_is_as_long_as_its_two_pieces():
    tree = random_tree(30, seed=2)
    through = with_pass_through(*tree, np.flatnonzero(tree[3] == 2), bend=2e-3)
    ds = morphometry(*through, top=None)
    total = segment_lengths(through[0], through[1]).sum()  # every piece once: no vessel is cut short
    assert ds.attrs["n_segments"] == np.count_nonzero(tree[0] >= 0)
    for level in ("element", "segment"):
        summed = (ds[f"{level}_length_mean"] * ds[f"{level}_count"]).fillna(0).sum("order")
        np.testing.assert_allclose(summed.values, total, rtol=1e-12, err_msg=level)


def test_pass_through_nodes_leave_pressures_and_crown_exponents_as_they_were():
    parent, position, radius, kind = random_tree(50, seed=3)
    p = Physics(50, 1, GAMMA, 2e-3, 4e-6, 641.3, 3.6e-3, 1e-3)
    plain = node_pressures(tree_from_arrays(parent, position, 1), p)
    np.testing.assert_array_equal(tree_pressures(parent, position, p), plain)  # the same sums, bit for bit
    through = with_pass_through(parent, position, radius, kind, np.flatnonzero(kind == 2))
    pressure = tree_pressures(through[0], through[1], p)
    np.testing.assert_allclose(pressure[: parent.size], plain, rtol=1e-12)
    np.testing.assert_allclose(terminal_pressures(through[0], through[1], p), plain[kind == 2], rtol=1e-12)
    a, b = crown_exponents(parent, position, radius, kind), crown_exponents(*through)
    for name in a:
        assert b[name] == pytest.approx(a[name], rel=1e-9), name


@pytest.mark.parametrize(
    "change, message",
    [("two children", "pass-through node 1"), ("chained", "hangs from pass-through node")],
)
def test_pass_through_nodes_that_are_not_are_refused(change, message):
    tree = random_tree(8, seed=4)
    parent, position, radius, kind = with_pass_through(*tree, [1, 2])
    if change == "two children":
        parent[3] = parent[1]  # terminal 3 now hangs from the pass-through node above 1 too
    else:  # a pass-through node on the segment of another one
        parent, position, radius, kind = with_pass_through(parent, position, radius, kind, [parent[1]])
    with pytest.raises(ValueError, match=message):
        check_tree_arrays(parent, kind, radius=radius, position=position)


# --------------------------------------------------------------------------------------------
# A small whole tree: 40 annealed terminals (a CCO heart), 10 fine ones below each


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """(output_dir, job, the reduction of the runs and whole tree, printed text)."""
    out = tmp_path_factory.mktemp("whole")
    (j,) = sweep.expand(
        config.compose(["tissue=heart", "n_terminals=40", "method=cco", "sweep.seeds=[0]", f"output_dir={out}"])
    )
    job.run_job(j)
    extend_run(j.store, extended_path(out, j.run_id), 400, stream=io.StringIO())
    stream = io.StringIO()
    result = reduce_and_draw(out, stream=stream)
    return out, j, result, stream.getvalue()


def check_network_against_poiseuille(model, tree, solution, solved):
    """The network's solution (``solved``: name -> flow, pressure_in, pressure_out) against the full
    tree's Poiseuille solution: inlet flows and pressures, the annealed terminals' pressures and
    every territory's flow."""
    root = {
        f"INFLOW_{n}": int(np.flatnonzero(tree.parent == k)[0])
        for n, k in zip(tree.inlet_names, np.flatnonzero(tree.parent < 0))
    }
    fed = {
        v["vessel_name"]: v["boundary_conditions"]["inlet"]
        for v in model["vessels"]
        if "inlet" in v.get("boundary_conditions", {})
    }
    assert sorted(fed.values()) == sorted(root)
    for name, condition in fed.items():
        node = root[condition]
        flow, p_in, _ = solved[name]
        assert flow == pytest.approx(solution.flow[node], rel=1e-9)
        assert p_in == pytest.approx(tree.physics.pressure_inlet, rel=1e-9)
    table = territory_table(tree, solution)
    vessel = {v["vessel_name"]: v for v in model["vessels"]}
    for node, q in zip(table.node, table.flow):  # the annealed terminal's segment: its flow and end pressure
        junction = next(j for j in model["junctions"] if j["junction_name"] == f"J{node}")
        name = next(v for v in vessel.values() if v["vessel_id"] == junction["inlet_vessels"][0])["vessel_name"]
        flow, _, p_out = solved[name]
        assert flow == pytest.approx(q, rel=1e-9) and p_out == pytest.approx(solution.pressure[node], rel=1e-9)


@pytest.mark.parametrize("kind", ["lumped", "full"])
def test_the_0d_network_gives_the_full_trees_poiseuille_solution(whole, kind):
    out, j, _, _ = whole
    tree = read_whole_tree(extended_path(out, j.run_id), out)
    solution = poiseuille(tree.parent, tree.position, tree.physics)
    model = lumped_network(tree, solution) if kind == "lumped" else full_network(tree, solution)
    n_segments = int(np.count_nonzero(tree.parent >= 0))
    if kind == "lumped":  # the annealed segments and one element per territory
        assert len(model["vessels"]) == np.count_nonzero(territories(tree.parent, tree.kind)[1] < 0) - 2 + 40 + 40
    else:
        assert len(model["vessels"]) == n_segments
    s = zerod.steady_solution(model)
    solved = {n: (q, a, b) for n, q, a, b in zip(s["name"], s["flow"], s["pressure_in"], s["pressure_out"])}
    check_network_against_poiseuille(model, tree, solution, solved)
    if kind == "lumped":  # the lumped elements carry the territories' flows to their mean terminal pressure
        table = territory_table(tree, solution)
        for row in table.itertuples():
            flow, p_in, p_out = solved[f"territory{row.node}"]
            assert flow == pytest.approx(row.flow, rel=1e-9) and p_out == row.pressure_terminal_mean
            assert p_in == pytest.approx(row.pressure_root, rel=1e-9)
    svzerod = pytest.importorskip("svzerod")
    result = svzerod.simulate(model)
    last = result[result.time == result.time.max()].set_index("name")
    solved = {n: (r.flow_in, r.pressure_in, r.pressure_out) for n, r in last.iterrows()}
    check_network_against_poiseuille(model, tree, solution, solved)


def test_territory_resistances_by_hand(whole):
    out, j, _, _ = whole
    tree = read_whole_tree(extended_path(out, j.run_id), out)
    solution = poiseuille(tree.parent, tree.position, tree.physics)
    table = territory_table(tree, solution)
    roots, territory = territories(tree.parent, tree.kind)
    assert table.node.tolist() == roots.tolist() and (table.fine_terminals == 10).all()
    children = {}
    for v, p in enumerate(tree.parent.tolist()):
        children.setdefault(p, []).append(v)

    def below(v):  # series-parallel resistance under v with every terminal at one pressure
        kids = children.get(v, [])
        with np.errstate(divide="ignore"):  # a zero-length terminal segment: a short circuit
            return 0.0 if not kids else 1.0 / sum(1.0 / (solution.resistance[c] + below(c)) for c in kids)

    for row in table.iloc[[0, 17, 39]].itertuples():
        fine = np.flatnonzero((territory == territory[row.node]) & (tree.kind == 2))
        mean = solution.pressure[fine].mean()
        assert row.resistance_lumped == pytest.approx((solution.pressure[row.node] - mean) / row.flow, rel=1e-12)
        assert row.resistance_network == pytest.approx(below(row.node), rel=1e-12)
        assert row.flow == pytest.approx(10 * tree.physics.total_flow / tree.physics.n_terminals, rel=1e-12)


def test_every_fine_terminals_pressure_is_reported_and_the_pressures_by_order_add_up(whole):
    out, j, result, printed = whole
    tree = read_whole_tree(extended_path(out, j.run_id), out)
    pressure = tree_pressures(tree.parent, tree.position, tree.physics)
    table = pd.read_csv(out / "trees" / f"{j.run_id}.extended.csv")
    fine = table[table.kind == 2]
    assert len(fine) == 400 and fine.pressure_Pa.notna().all()
    np.testing.assert_allclose(fine.pressure_Pa.to_numpy(), pressure[fine.node.to_numpy()], rtol=1e-12)
    vtp = ET.parse(out / "trees" / f"{j.run_id}.extended.vtp").getroot()
    (points,) = [a for a in vtp.iter("DataArray") if a.get("Name") == "pressure"]
    assert len(points.text.split()) == tree.parent.size
    summary = result.extended.summary
    anatomy = summary["anatomy"].to_dataset().sel(run_id=j.run_id)
    assert float(anatomy.terminal_pressure_min) == pytest.approx(fine.pressure_Pa.min(), rel=1e-12)
    assert int(anatomy.n_fine_terminals) == 400 and int(anatomy.n_territories) == 40
    # pressures by order from the export's own rows: length-weighted mean along the vessels, lowest, highest
    parent_p = pressure[np.maximum(table.parent.fillna(-1).astype(int).to_numpy(), 0)]
    table["mid"] = 0.5 * (table.pressure_Pa + parent_p)
    by_order = summary["pressure"].to_dataset().sel(run_id=j.run_id, reading="range")
    for order, rows in table[table.order > 0].groupby("order"):
        p = by_order.sel(order=order)
        mean = np.sum(rows.mid * rows.length_m) / rows.length_m.sum()
        assert float(p.pressure_mean) == pytest.approx(mean, rel=1e-12)
        assert float(p.pressure_min) == rows.pressure_Pa.min()
        assert float(p.pressure_mean_fraction) == pytest.approx(mean / tree.physics.pressure_inlet, rel=1e-12)
    assert "vessels of 100-170 um" in printed and "Chilian" in printed


def test_outputs_of_the_whole_trees_reduction(whole):
    out, j, result, printed = whole
    ext = result.extended
    assert not result.errors and not ext.errors and ext.zerod == "lumped"
    summary = xr.open_datatree(out / "extended_summary.zarr", engine="zarr")
    assert set(summary.children) == {"morphometry", "comparison", "pressure", "anatomy", "territory"}
    for group in summary.children.values():
        for name, var in group.to_dataset().data_vars.items():
            assert "long_name" in var.attrs and "units" in var.attrs, name
    morph = summary["morphometry"].to_dataset()
    assert list(morph.reading.values) == ["range", "confluence"] and int(morph.order.max()) == 11
    present = morph.element_count.sel(run_id=j.run_id, scheme="diameter_defined") > 0
    assert bool(present.sel(order=11).all())
    # orders reach down as far as the tree is deep: every order from its lowest to 11 holds vessels
    for reading in ("range", "confluence"):
        orders = morph.order.values[present.sel(reading=reading).values]
        assert orders.tolist() == list(range(int(orders.min()), 12))
    csv = pd.read_csv(out / "extended_comparison.csv")
    assert set(csv.reading) == {"range", "confluence"} and set(csv.artery) == {"RCA", "LAD", "LCX"}
    kassab = csv[csv.kassab_count > 0]
    assert sorted(set(kassab.order)) == list(range(1, 12))  # Kassab's orders 1-11, beside the model's
    model = csv[(csv.element_count > 0) & (csv.reading == "range") & (csv.artery == "LAD")]
    assert model.pressure_mean_fraction.between(-1, 1).all() and model.order.max() == 11
    names = sorted(p.name for p in ext.figures)
    assert names == sorted(f"extended_{w}_{j.run_id}.png" for w in ("tree", "morphometry", "pressure"))
    for p in ext.figures:
        png_is_a_real_figure(p, min_shape=(300, 400))
    assert sorted(p.name for p in ext.trees) == sorted(f"{j.run_id}.extended.{x}" for x in ("vtp", "csv", "0d.json"))
    assert ext.zero_d_check[j.run_id] < 1e-9  # the written network gives the inlets the model's pressure
    assert ext.zero_d_solver[j.run_id] in ("svZeroDSolver", "steady_solution (NumPy)")
    assert f"reduced 1 whole tree of {out / 'extended'}" in printed


def test_the_runs_reduction_is_unchanged_by_the_whole_trees_and_without_them(whole, tmp_path):
    out, j, result, printed = whole
    bare = tmp_path / "bare"
    shutil.copytree(out / "runs", bare / "runs")
    stream = io.StringIO()
    plain = reduce(bare, stream=stream)
    assert plain.extended is None and not plain.errors
    assert not (bare / "extended_summary.zarr").exists() and not (bare / "extended_comparison.csv").exists()
    assert not list((bare / "trees").glob("*.extended.*")) and not list((bare / "figures").glob("extended_*"))
    assert "whole tree" not in stream.getvalue()
    with_whole = xr.open_datatree(out / "summary.zarr", engine="zarr")
    without = xr.open_datatree(bare / "summary.zarr", engine="zarr")
    for name in with_whole.children:
        a, b = with_whole[name].to_dataset(), without[name].to_dataset()
        xr.testing.assert_identical(a, b)
    assert printed.startswith(stream.getvalue().split("vasc_pipeline: reduced")[0])  # the same tables first


def test_the_whole_trees_reduction_refuses_an_unknown_network_and_skips_unfinished_stores(whole, tmp_path):
    out, j, _, _ = whole
    with pytest.raises(ValueError, match=r"extend\.zerod must be one of lumped, full"):
        reduce_extended(out, zerod="partial")
    partial = tmp_path / "partial"
    shutil.copytree(out / "runs", partial / "runs")
    path = extended_path(partial, j.run_id)
    shutil.copytree(extended_path(out, j.run_id), path)
    s = ExtendedStore.open(path, mode="r+")
    s.group.update_attributes({"status": "running"})
    ext = reduce_extended(partial, stream=io.StringIO())
    assert ext.summary is None and str(path) in ext.skipped and "resumes it" in ext.skipped[str(path)]
    assert not (partial / "extended_summary.zarr").exists()


def test_a_network_too_large_for_svzerod_is_checked_by_the_sparse_solution(whole, tmp_path, monkeypatch):
    out, j, _, _ = whole
    copy = tmp_path / "copy"
    shutil.copytree(out / "runs", copy / "runs")
    shutil.copytree(out / "extended", copy / "extended")
    monkeypatch.setattr(extended_module, "SVZEROD_MAX_VESSELS", 10)
    stream = io.StringIO()
    ext = reduce_extended(copy, zerod="full", stream=stream)
    assert ext.zero_d_solver == {j.run_id: "steady_solution (NumPy)"} and ext.zero_d_check[j.run_id] < 1e-9
    model = json.loads((copy / "trees" / f"{j.run_id}.extended.0d.json").read_text())
    assert len(model["vessels"]) == 2 * 40 + 40 * (2 * 10 - 1) - 2  # every segment: the full network
    assert "0D check: steady_solution (NumPy)" in stream.getvalue()
