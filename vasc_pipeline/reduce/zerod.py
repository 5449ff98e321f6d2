"""A tree as a 0D network for svZeroDSolver (``pip install svzerod``): the format blood-flow
simulations of generated trees start from.

One ``BloodVessel`` per segment with its Poiseuille resistance 8 μ L / (π r⁴) (μ = μ(2r) under
``physics.viscosity_law``; the model's,
from :func:`vasc_pipeline.model.physics.cost_tables`), one junction per bifurcation (mass
conservation, one pressure), a ``FLOW`` condition at each inlet's root segment with the model's
flow n Q0 / N, and a ``PRESSURE`` condition at each terminal: the terminal pressure of the
model's own Poiseuille solution (:func:`vasc_pipeline.model.costs.node_pressures`, from
``physics.pressure_inlet`` at the inlets). With these conditions the solver's steady solution
is the model's: every terminal carries Q0 / N, the inlets are at ``pressure_inlet`` and the
pumping power Σ Q ΔP is C_w. Swap the terminal conditions for your own (a ``RESISTANCE`` or
``CORONARY`` condition per outlet) to simulate the tree under other loads.

Units are SI throughout (Pa, m³ s⁻¹, Pa s m⁻³, m): svZeroDSolver takes any consistent units.

    from vasc_pipeline.reduce import zerod
    model = zerod.zero_d_model(tree, physics)        # a dict in svZeroDSolver's input format
    import svzerod; svzerod.simulate(model)          # pandas DataFrame: flow_in/out, pressure_in/out per vessel

:func:`export_run` writes ``<out_dir>/<run_id>.0d.json`` for a complete run store;
:func:`vasc_pipeline.reduce.export.export_run` writes it beside the tree's ``.vtp`` and ``.csv``
(the reduction's export of every cell's best tree), and ``python -m vasc_pipeline.reduce.zerod STORE
[OUT_DIR]`` does it for one run store.
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model.costs import node_pressures, segment_lengths
from ..model.physics import Physics, cost_tables
from ..model.topology import _child_lists
from ..model.tree import Tree, tree_from_arrays

__all__ = [
    "zero_d_model",
    "Lumped",
    "network",
    "steady_solution",
    "write_zero_d",
    "zero_d_path",
    "export_run",
    "solver_check",
]

# A steady model: conditions constant over one "cycle" of two time points (the solver needs a
# time axis; with no capacitance or inductance every point is the same algebraic solution).
_STEADY = {"number_of_cardiac_cycles": 1, "number_of_time_pts_per_cardiac_cycle": 2}


def zero_d_model(tree: Tree, physics: Physics, inlet_names: tuple[str, ...] | None = None) -> dict:
    """The tree as svZeroDSolver's input (a JSON-ready dict); see the module docstring.

    Vessel ``v`` is the segment ending at node ``v + K`` (K inlets), named ``branch<v>_seg0``;
    junction ``J<b>`` joins bifurcation node b's segment to its children's; the inlet
    conditions are ``INFLOW_<inlet name>``, the terminal ones ``OUT_<node>``.
    """
    tables = cost_tables(physics)
    n = tree.n_downstream
    lengths = segment_lengths(tree)
    pressure = node_pressures(tree, physics, lengths)
    return network(tree.parent, lengths, tables.resistance[n] * lengths, tables.flow[n], pressure, inlet_names)


@dataclass(frozen=True)
class Lumped:
    """Outlets of a network that stand for a whole subtree each: at node ``node[j]`` (a childless
    node of the network) one more ``BloodVessel`` named ``name[j]`` of resistance
    ``resistance[j]`` [Pa s m^-3] and length ``length[j]`` [m], ending at a ``PRESSURE``
    condition ``pressure[j]`` [Pa]."""

    node: np.ndarray
    name: list[str]
    resistance: np.ndarray
    length: np.ndarray
    pressure: np.ndarray


def network(
    parent: np.ndarray,
    length: np.ndarray,
    resistance: np.ndarray,
    flow: np.ndarray,
    pressure: np.ndarray,
    inlet_names: tuple[str, ...] | None = None,
    lumped: Lumped | None = None,
) -> dict:
    """svZeroDSolver's input for a tree given by its parent array and node-indexed segment values.

    Parameters
    ----------
    parent : int64 (node,)
        Any node layout; the inlets (parent -1) in node order are ``inlet_names``.
    length, resistance, flow : float64 (node,)
        Per segment (at its child node): length [m], resistance [Pa s m^-3], and the flow [m^3
        s^-1] of an inlet's root segment (its ``FLOW`` condition).
    pressure : float64 (node,)
        [Pa]: the ``PRESSURE`` condition of every childless node.
    inlet_names : tuple of str, optional
    lumped : Lumped, optional
        Childless nodes whose outlet is a lumped element instead (:class:`Lumped`).

    Returns
    -------
    dict
        Vessel ``i`` is the i-th segment in node order (``branch<i>_seg0``), then the lumped
        elements; junction ``J<node>`` at every node with children (one child at a
        pass-through node, or a lumped element); conditions ``INFLOW_<inlet>``,
        ``OUT_<node>`` and ``OUT_<lumped name>``.
    """
    parent = np.asarray(parent, dtype=np.int64)
    inlets = np.flatnonzero(parent < 0)
    names = tuple(inlet_names) if inlet_names else tuple(f"inlet{i}" for i in range(inlets.size))
    n_segments = int(np.count_nonzero(parent >= 0))
    extra = {}
    if lumped is not None:
        extra = {int(v): n_segments + j for j, v in enumerate(np.asarray(lumped.node).tolist())}
    segment_values = (length, resistance, flow, pressure)
    vessels, junctions, conditions = _segment_elements(parent, segment_values, dict(zip(inlets.tolist(), names)), extra)
    if lumped is not None:
        for j, name in enumerate(lumped.name):
            conditions.append(_steady_condition(f"OUT_{name}", "PRESSURE", "P", float(lumped.pressure[j])))
            vessels.append(
                {
                    "vessel_id": n_segments + j,
                    "vessel_name": name,
                    "vessel_length": float(lumped.length[j]),
                    "zero_d_element_type": "BloodVessel",
                    "zero_d_element_values": {"R_poiseuille": float(lumped.resistance[j])},
                    "boundary_conditions": {"outlet": f"OUT_{name}"},
                }
            )
    return {
        "description": {
            "description": "vasc_pipeline tree: Poiseuille vessels, inlet flows and terminal pressures of the model",
            "units": "SI (Pa, m^3/s, Pa s/m^3, m)",
        },
        "simulation_parameters": dict(_STEADY),
        "boundary_conditions": conditions,
        "junctions": junctions,
        "vessels": vessels,
    }


def _steady_condition(name: str, bc_type: str, key: str, value: float) -> dict:
    """A boundary condition held at ``value`` over the steady run's two time points."""
    return {"bc_name": name, "bc_type": bc_type, "bc_values": {key: [value, value], "t": [0.0, 1.0]}}


def _segment_elements(parent: np.ndarray, segment_values, inlet_name: dict, extra: dict) -> tuple[list, list, list]:
    """(vessels, junctions, conditions) of the tree's segments in node order (:func:`network`);
    ``extra`` maps a childless node to the vessel id of the lumped element below it."""
    length, resistance, flow, pressure = segment_values
    segments = np.flatnonzero(parent >= 0)
    vessel_of = np.full(parent.size, -1, dtype=np.int64)
    vessel_of[segments] = np.arange(segments.size)
    start, child = _child_lists(parent)
    vessels, junctions, conditions = [], [], []
    parents, lengths, resistances = parent.tolist(), np.asarray(length).tolist(), np.asarray(resistance).tolist()
    starts, children, vessel_ids = start.tolist(), child.tolist(), vessel_of.tolist()
    for node in segments.tolist():
        up = parents[node]
        vessel = {
            "vessel_id": vessel_ids[node],
            "vessel_name": f"branch{vessel_ids[node]}_seg0",
            "vessel_length": float(lengths[node]),
            "zero_d_element_type": "BloodVessel",
            "zero_d_element_values": {"R_poiseuille": float(resistances[node])},
        }
        ends = {}
        if parents[up] < 0:  # the root segment of an inlet
            ends["inlet"] = f"INFLOW_{inlet_name[up]}"
            conditions.append(_steady_condition(ends["inlet"], "FLOW", "Q", float(flow[node])))
        below = [vessel_ids[c] for c in children[starts[node] : starts[node + 1]]]
        if node in extra:
            below = [extra[node]]
        if not below:  # a terminal
            ends["outlet"] = f"OUT_{node}"
            conditions.append(_steady_condition(ends["outlet"], "PRESSURE", "P", float(pressure[node])))
        else:
            junctions.append(
                {
                    "junction_name": f"J{node}",
                    "junction_type": "NORMAL_JUNCTION",
                    "inlet_vessels": [vessel_ids[node]],
                    "outlet_vessels": below,
                }
            )
        if ends:
            vessel["boundary_conditions"] = ends
        vessels.append(vessel)
    return vessels, junctions, conditions


def steady_solution(model: dict) -> dict[str, np.ndarray]:
    """The steady solution of a network of this module's kind, by one sparse linear solve: the
    NumPy twin of ``svzerod.simulate`` for resistances, junctions, ``FLOW`` and ``PRESSURE``
    conditions (constant in time), for checks where svZeroDSolver is not installed.

    Returns
    -------
    dict
        ``name`` (vessel names, in the model's order), ``flow``, ``pressure_in`` and
        ``pressure_out`` (float64, one per vessel; SI).
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.linalg import spsolve

    vessels = model["vessels"]
    index = {v["vessel_id"]: i for i, v in enumerate(vessels)}
    conditions = {c["bc_name"]: c for c in model["boundary_conditions"]}
    m = len(vessels)
    rows, cols, vals, rhs = [], [], [], []

    def equation(terms, value):  # terms: (unknown, coefficient); unknowns Q, P_in, P_out of vessel i at 3i..3i+2
        r = len(rhs)
        for col, coefficient in terms:
            rows.append(r)
            cols.append(col)
            vals.append(coefficient)
        rhs.append(value)

    for i, v in enumerate(vessels):
        equation([(3 * i + 1, 1.0), (3 * i + 2, -1.0), (3 * i, -v["zero_d_element_values"]["R_poiseuille"])], 0.0)
        for end, unknown in (("inlet", 3 * i + 1), ("outlet", 3 * i + 2)):
            name = v.get("boundary_conditions", {}).get(end)
            if name is None:
                continue
            c = conditions[name]
            if c["bc_type"] == "FLOW":
                equation([(3 * i, 1.0)], c["bc_values"]["Q"][0])
            elif c["bc_type"] == "PRESSURE":
                equation([(unknown, 1.0)], c["bc_values"]["P"][0])
            else:
                raise ValueError(f"condition {name!r}: type {c['bc_type']!r} is not one this solution knows")
    for j in model["junctions"]:
        ins = [index[v] for v in j["inlet_vessels"]]
        outs = [index[v] for v in j["outlet_vessels"]]
        equation([(3 * i, 1.0) for i in ins] + [(3 * o, -1.0) for o in outs], 0.0)  # mass
        first = 3 * ins[0] + 2
        for unknown in [3 * i + 2 for i in ins[1:]] + [3 * o + 1 for o in outs]:  # one pressure
            equation([(unknown, 1.0), (first, -1.0)], 0.0)
    if len(rhs) != 3 * m:
        raise ValueError(f"the network has {len(rhs)} equations for {3 * m} unknowns: not a closed network")
    x = spsolve(csr_matrix((vals, (rows, cols)), shape=(3 * m, 3 * m)), np.asarray(rhs))
    return {
        "name": [v["vessel_name"] for v in vessels],
        "flow": x[0::3],
        "pressure_in": x[1::3],
        "pressure_out": x[2::3],
    }


def solver_check(model: dict, pressure_inlet: float, solver: str = "svzerod") -> float | None:
    """The exported network run through svZeroDSolver: the largest relative deviation of its inlet
    pressures from ``pressure_inlet`` [Pa]. The network carries the model's inlet flows and
    terminal pressures, so a deviation near 0 confirms the model's Poiseuille pressures (the
    negative ones too) with an independent solver. None when svzerod is not installed.

    ``solver="numpy"``: :func:`steady_solution` instead (for networks too large for svZeroDSolver's
    time: 18 000 vessels took it 30-47 s on a busy machine, 210 000 more than 19 minutes)."""
    roots = [v["vessel_name"] for v in model["vessels"] if "inlet" in v.get("boundary_conditions", {})]
    if solver == "numpy":
        s = steady_solution(model)
        pressure = dict(zip(s["name"], s["pressure_in"]))
        at_inlets = np.array([pressure[name] for name in roots])
    else:
        try:
            import svzerod
        except ImportError:
            return None
        result = svzerod.simulate(model)
        last = result[result.time == result.time.max()].set_index("name")
        at_inlets = last.loc[roots, "pressure_in"].to_numpy()
    return float(np.max(np.abs(at_inlets / pressure_inlet - 1.0)))


def zero_d_path(out_dir, name: str) -> Path:
    """``<out_dir>/<name>.0d.json``: where :func:`write_zero_d` puts a run's network."""
    return Path(out_dir) / f"{name}.0d.json"


def write_zero_d(path, model: dict) -> Path:
    """Write ``model`` as JSON to ``path`` atomically (a temporary file, then a rename)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(model, indent=1))
    os.replace(tmp, path)
    return path


def export_run(store_path, out_dir, name: str | None = None) -> Path:
    """``<out_dir>/<name or run id>.0d.json`` of a complete run store (its tree and physics)."""
    from ..store import STATUS_COMPLETE, RunStore, StoreError

    store = RunStore.open(store_path, mode="r")
    if store.status != STATUS_COMPLETE:
        raise StoreError(
            f"run store {str(store_path)!r} has status {store.status!r}: only complete runs have a final tree to export"
        )
    arrays = store.read_tree()
    physics = Physics(**store.attrs["physics"])
    tree = tree_from_arrays(arrays["parent"], arrays["position"], physics.n_inlets)
    inlet_names = tuple(store.group["tissue"].attrs.get("inlet_names", ())) or None
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    return write_zero_d(zero_d_path(out_dir, name or store.run_id), zero_d_model(tree, physics, inlet_names))


def main(argv: list[str] | None = None) -> int:
    """``python -m vasc_pipeline.reduce.zerod STORE [OUT_DIR]``: the 0D network of one run store
    (default OUT_DIR: the store's output_dir's ``trees/``)."""
    args = sys.argv[1:] if argv is None else argv
    if not 1 <= len(args) <= 2 or args[0] in ("-h", "--help"):
        print(main.__doc__.split("\n\n")[0].replace("``", ""), file=sys.stderr)
        return 2
    store = Path(args[0])
    out = Path(args[1]) if len(args) > 1 else store.resolve().parent.parent / "trees"
    try:
        print(export_run(store, out))
    except Exception as exc:  # a missing, damaged or unfinished store: one line, not a traceback
        print(f"vasc_pipeline.reduce.zerod: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
