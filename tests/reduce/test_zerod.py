"""The 0D export (svZeroDSolver's input format): a hand-built tree's network by hand, the real
solver on an annealed tree against the package's own Poiseuille solution, and the exports the
reduction and ``python -m vasc_pipeline.reduce.zerod`` write."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from helpers import ENV, REPO

from vasc_pipeline import config, costs, engine, job, sweep
from vasc_pipeline.model.physics import Physics, cost_tables
from vasc_pipeline.model.tree import tree_from_arrays
from vasc_pipeline.reduce import zerod

svzerod = pytest.importorskip("svzerod", reason="svzerod (pip install -e '.[test]') runs the exported networks")

RELATIVE = 1e-6


def test_a_hand_built_tree_gives_the_network_by_hand():
    # inlet 0 -> bifurcation 3 -> terminals 1 and 2
    parent = np.array([-1, 3, 3, 0])
    position = np.array([[0.0, 0, 0], [0.01, 0.01, 0], [0.01, -0.01, 0], [0.01, 0, 0]])
    tree = tree_from_arrays(parent, position)
    physics = Physics(
        n_terminals=2, n_inlets=1, gamma=3.0, inlet_radius=1e-3, total_flow=2e-6, m_b=641.3, viscosity=3.6e-3,
        supply_radius=1e-3,
    )  # fmt: skip
    model = zerod.zero_d_model(tree, physics, ("root",))
    r_t = 1e-3 * 2 ** (-1 / 3)  # r_in N^(-1/gamma)
    resistance = {1: 8 * 3.6e-3 * 0.01 / (math.pi * r_t**4), 3: 8 * 3.6e-3 * 0.01 / (math.pi * 1e-3**4)}
    vessels = {v["vessel_id"]: v for v in model["vessels"]}
    assert sorted(vessels) == [0, 1, 2]  # vessel v is the segment ending at node v + 1
    assert vessels[2]["zero_d_element_values"]["R_poiseuille"] == pytest.approx(resistance[3], rel=1e-12)
    assert vessels[0]["zero_d_element_values"]["R_poiseuille"] == pytest.approx(resistance[1], rel=1e-12)
    assert vessels[2]["boundary_conditions"] == {"inlet": "INFLOW_root"}
    assert vessels[0]["boundary_conditions"] == {"outlet": "OUT_1"}
    assert model["junctions"] == [
        {"junction_name": "J3", "junction_type": "NORMAL_JUNCTION", "inlet_vessels": [2], "outlet_vessels": [0, 1]}
    ]
    bcs = {b["bc_name"]: b for b in model["boundary_conditions"]}
    assert bcs["INFLOW_root"]["bc_values"]["Q"] == [2e-6, 2e-6]
    p_terminal = 13.3e3 - 2e-6 * resistance[3] - 1e-6 * resistance[1]
    assert bcs["OUT_1"]["bc_values"]["P"][0] == pytest.approx(p_terminal, rel=1e-12)
    json.dumps(model)  # JSON-ready


@pytest.fixture(scope="module")
def annealed():
    """A heart tree (two inlets) after a short anneal."""
    return engine.run(config.compose(["tissue=heart", "n_terminals=1000", "anneal=fast_v1", "anneal.steps=1000000"]), 1)


def test_svzerod_reproduces_the_models_flows_pressures_and_pumping_power(annealed):
    tree, physics = annealed.tree, annealed.problem.physics
    result = svzerod.simulate(zerod.zero_d_model(tree, physics, annealed.problem.tissue.inlet_names))
    last = result[result.time == result.time.max()].set_index("name")
    k, n = tree.n_inlets, tree.n_downstream
    pressure = costs.node_pressures(tree, physics)
    flow = cost_tables(physics).flow
    power = 0.0
    for node in range(k, tree.n_nodes):
        v = last.loc[f"branch{node - k}_seg0"]
        assert v.flow_in == pytest.approx(flow[n[node]], rel=RELATIVE)
        assert v.pressure_out == pytest.approx(pressure[node], rel=RELATIVE)
        assert v.pressure_in == pytest.approx(pressure[tree.parent[node]], rel=RELATIVE)
        if tree.parent[node] < k:  # the inlets sit at the model's inlet pressure
            assert v.pressure_in == pytest.approx(physics.pressure_inlet, rel=RELATIVE)
        if tree.children[node, 0] < 0:  # every terminal carries Q0 / N
            assert v.flow_out == pytest.approx(physics.total_flow / physics.n_terminals, rel=RELATIVE)
        power += (v.pressure_in - v.pressure_out) * v.flow_in
    assert power == pytest.approx(annealed.costs_recomputed["power"], rel=RELATIVE)  # C_w


def test_the_reduction_and_the_command_write_the_network(tmp_path):
    out = tmp_path / "sweep"
    cfg = config.compose(
        ["+sweep=smoke", "sweep.n_terminals=[16]", "sweep.m_b=[641.3]", "sweep.seeds=[0]", "anneal.steps=5000"]
        + [f"output_dir={out}"]
    )
    (j,) = sweep.expand(cfg)
    job.run_job(j)
    from vasc_pipeline.reduce import reduce

    reduce(out)
    written = out / "trees" / f"{j.run_id}.0d.json"
    model = json.loads(written.read_text())
    assert len(model["vessels"]) == 2 * 16 - 1 and len(model["junctions"]) == 16 - 1
    by_command = subprocess.run(
        [sys.executable, "-m", "vasc_pipeline.reduce.zerod", j.store, str(tmp_path / "mine")],
        env=ENV, cwd=REPO, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert by_command.returncode == 0, by_command.stderr
    assert json.loads((tmp_path / "mine" / f"{j.run_id}.0d.json").read_text()) == model
    missing = subprocess.run(
        [sys.executable, "-m", "vasc_pipeline.reduce.zerod", str(tmp_path / "nope.zarr")],
        env=ENV, cwd=REPO, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert missing.returncode == 1 and missing.stderr.startswith("vasc_pipeline.reduce.zerod: "), missing.stderr
