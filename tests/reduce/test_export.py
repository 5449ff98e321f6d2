"""Tree export: hand-built trees whose table, VTP and CSV are worked out by hand, and export_run."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from vasc_pipeline import config, job, store, sweep
from vasc_pipeline.reduce import zerod
from vasc_pipeline.reduce.export import export_paths, export_run, export_tree, terminals_downstream, tree_table

GAMMA = 3.0
R_T = 1e-4
Q0 = 1e-6
# anneal layout, K = 1, N = 2: node 0 inlet, 1-2 terminals, 3 bifurcation
PARENT = np.array([-1, 3, 3, 0])
KIND = np.array([0, 2, 2, 1], dtype=np.int8)
POSITION = np.array([[0.0, 0, 0], [2e-3, 1e-3, 0], [2e-3, -1e-3, 0], [1e-3, 0, 0]])
RADIUS = np.array([0.0, R_T, R_T, R_T * 2 ** (1 / GAMMA)])


def vtp_arrays(path):
    piece = ET.parse(path).getroot().find("PolyData/Piece")

    def read(section):
        return {a.get("Name"): np.array(a.text.split(), dtype=float) for a in piece.find(section)}

    return piece, read("PointData"), read("CellData"), read("Points")["Points"].reshape(-1, 3), read("Lines")


def test_terminals_downstream_of_a_tree_and_a_chain():
    assert terminals_downstream(PARENT, KIND).tolist() == [2, 1, 1, 2]
    # caterpillar, anneal layout N = 4: bifurcations 5 <- 6 <- 7 <- inlet 0; terminals 1..4
    parent = np.array([-1, 5, 5, 6, 7, 6, 7, 0])
    kind = np.array([0, 2, 2, 2, 2, 1, 1, 1])
    assert terminals_downstream(parent, kind).tolist() == [4, 1, 1, 1, 1, 2, 3, 4]


def test_tree_table_worked_out_by_hand():
    t = tree_table(PARENT, POSITION, RADIUS, KIND, total_flow=Q0)
    assert t.node.tolist() == [0, 1, 2, 3] and t.parent.tolist() == [-1, 3, 3, 0]
    assert t.loc[0, ["radius_m", "length_m", "flow_m3_s"]].isna().all() and pd.isna(t.order[0])
    np.testing.assert_allclose(t.length_m[1:], [math.sqrt(2) * 1e-3, math.sqrt(2) * 1e-3, 1e-3], rtol=1e-15)
    np.testing.assert_allclose(t.flow_m3_s[1:], [Q0 / 2, Q0 / 2, Q0], rtol=1e-15)
    assert t.order[1:].tolist() == [10, 10, 11] and t.strahler_order[1:].tolist() == [10, 10, 11]
    assert t.terminals_downstream[1:].tolist() == [1, 1, 2]
    assert "flow_m3_s" not in tree_table(PARENT, POSITION, RADIUS, KIND).columns


def test_vtp_and_csv_of_the_hand_built_tree(tmp_path):
    vtp, csv = export_tree(tmp_path, "t", PARENT, POSITION, RADIUS, KIND, total_flow=Q0)
    root = ET.parse(vtp).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "PolyData"
    piece, point, cell, points, lines = vtp_arrays(vtp)
    assert piece.get("NumberOfPoints") == "4" and piece.get("NumberOfLines") == "3"
    np.testing.assert_array_equal(points, POSITION)
    assert lines["connectivity"].tolist() == [3, 1, 3, 2, 0, 3] and lines["offsets"].tolist() == [2, 4, 6]
    np.testing.assert_array_equal(cell["radius"], RADIUS[1:])
    np.testing.assert_allclose(cell["flow"], [Q0 / 2, Q0 / 2, Q0], rtol=1e-15)
    assert cell["order"].tolist() == [10, 10, 11] and cell["node"].tolist() == [1, 2, 3]
    # point radius: the node's segment; at the inlet, its root segment (no pinched tube)
    np.testing.assert_array_equal(point["radius"], [RADIUS[3], RADIUS[1], RADIUS[2], RADIUS[3]])
    assert point["kind"].tolist() == [0, 2, 2, 1]
    back = pd.read_csv(csv)
    np.testing.assert_array_equal(back[["x_m", "y_m", "z_m"]].to_numpy(), POSITION)  # full precision
    np.testing.assert_array_equal(back.radius_m.to_numpy()[1:], RADIUS[1:])
    assert back.radius_m.isna().tolist() == [True, False, False, False]


def test_two_inlet_forest_lines_follow_the_parents(tmp_path):
    # K = 2, N = 3: inlets 0-1, terminals 2-4, bifurcation 5; inlet 0 -> 5 -> (2, 3); inlet 1 -> 4
    parent = np.array([-1, -1, 5, 5, 1, 0])
    kind = np.array([0, 0, 2, 2, 2, 1])
    pos = np.random.default_rng(1).normal(size=(6, 3)) * 1e-3
    radius = np.array([0, 0, 1, 1, 1, 2 ** (1 / 3)]) * 1e-4
    vtp, _ = export_tree(tmp_path, "forest", parent, pos, radius, kind, total_flow=3e-6)
    piece, point, cell, points, lines = vtp_arrays(vtp)
    assert piece.get("NumberOfLines") == "4"
    pairs = lines["connectivity"].reshape(-1, 2).astype(int).tolist()
    assert pairs == [[5, 2], [5, 3], [1, 4], [0, 5]]
    np.testing.assert_allclose(cell["flow"], [1e-6, 1e-6, 1e-6, 2e-6], rtol=1e-15)
    assert point["radius"][1] == radius[4] and point["radius"][0] == radius[5]


def test_export_run_of_a_complete_store_and_refusal_of_a_running_one(tmp_path):
    cfg = config.compose(
        [
            "+sweep=smoke",
            "sweep.n_terminals=[16]",
            "sweep.m_b=[641.3]",
            "sweep.seeds=[0]",
            "anneal.steps=5000",
            "anneal.trace_every=5000",
            f"output_dir={tmp_path}",
        ]
    )
    (j,) = sweep.expand(cfg)
    running = store.RunStore.create(
        tmp_path / "running.zarr", run_id="r", seed=0, config=j.config, coords=j.coords, total_steps=5000
    )
    with pytest.raises(store.StoreError, match="running"):
        export_run(running.path, tmp_path / "out")
    job.run_job(j)
    vtp, csv, network = export_run(j.store, tmp_path / "out")  # what the reduction writes, in one call
    assert vtp.name == f"{j.run_id}.vtp" and csv.name == f"{j.run_id}.csv"
    assert network == zerod.zero_d_path(tmp_path / "out", j.run_id)
    assert json.loads(network.read_text()) == json.loads(zerod.export_run(j.store, tmp_path / "zerod").read_text())
    assert export_run(j.store, tmp_path / "plain", zero_d=False) == export_paths(tmp_path / "plain", j.run_id)
    assert not zerod.zero_d_path(tmp_path / "plain", j.run_id).exists()
    tree = job.read_final_tree(j.store)
    piece, point, cell, points, lines = vtp_arrays(vtp)
    assert int(piece.get("NumberOfPoints")) == 32 and int(piece.get("NumberOfLines")) == 31
    np.testing.assert_array_equal(points, tree["position"])
    physics = store.RunStore.open(j.store, mode="r").attrs["physics"]
    root = np.flatnonzero(tree["parent"] == 0)[0]
    assert cell["flow"][list(cell["node"]).index(root)] == pytest.approx(physics["total_flow"], rel=1e-12)


def test_vtk_reads_the_vtp_when_vtk_is_installed(tmp_path):
    # VTK itself is not a dependency (a 100 MB wheel); where it is installed, its reader is the judge.
    vtk = pytest.importorskip("vtk")
    vtp, _ = export_tree(tmp_path, "t", PARENT, POSITION, RADIUS, KIND, total_flow=Q0)
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(vtp))
    reader.Update()
    poly = reader.GetOutput()
    assert reader.GetErrorCode() == 0
    assert poly.GetNumberOfPoints() == 4 and poly.GetNumberOfLines() == 3
    assert poly.GetCellData().GetArray("radius").GetValue(2) == RADIUS[3]
    assert poly.GetCellData().GetArray("flow").GetValue(2) == pytest.approx(Q0, rel=1e-15)
