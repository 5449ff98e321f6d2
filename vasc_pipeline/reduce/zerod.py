"""A tree as a 0D network for svZeroDSolver (``pip install svzerod``): the format blood-flow
simulations of generated trees start from.

One ``BloodVessel`` per segment with its Poiseuille resistance 8 μ L / (π r⁴) (the model's,
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
from pathlib import Path

import numpy as np

from ..model.costs import node_pressures, segment_lengths
from ..model.physics import Physics, cost_tables
from ..model.tree import Tree, tree_from_arrays

__all__ = ["zero_d_model", "write_zero_d", "zero_d_path", "export_run", "solver_check"]

# A steady model: conditions constant over one "cycle" of two time points (the solver needs a
# time axis; with no capacitance or inductance every point is the same algebraic solution).
_STEADY = {"number_of_cardiac_cycles": 1, "number_of_time_pts_per_cardiac_cycle": 2}


def zero_d_model(tree: Tree, physics: Physics, inlet_names: tuple[str, ...] | None = None) -> dict:
    """The tree as svZeroDSolver's input (a JSON-ready dict); see the module docstring.

    Vessel ``v`` is the segment ending at node ``v + K`` (K inlets), named ``branch<v>_seg0``;
    junction ``J<b>`` joins bifurcation node b's segment to its children's; the inlet
    conditions are ``INFLOW_<inlet name>``, the terminal ones ``OUT_<node>``.
    """
    k = tree.n_inlets
    names = tuple(inlet_names) if inlet_names else tuple(f"inlet{i}" for i in range(k))
    tables = cost_tables(physics)
    n = tree.n_downstream
    lengths = segment_lengths(tree)
    pressure = node_pressures(tree, physics, lengths)
    steady = [0.0, 1.0]
    vessels, junctions, conditions = [], [], []
    for node in range(k, tree.n_nodes):
        parent = int(tree.parent[node])
        vessel = {
            "vessel_id": node - k,
            "vessel_name": f"branch{node - k}_seg0",
            "vessel_length": float(lengths[node]),
            "zero_d_element_type": "BloodVessel",
            "zero_d_element_values": {"R_poiseuille": float(tables.resistance[n[node]] * lengths[node])},
        }
        ends = {}
        if parent < k:  # the root segment of inlet `parent`
            name = f"INFLOW_{names[parent]}"
            q = float(tables.flow[n[node]])
            conditions.append({"bc_name": name, "bc_type": "FLOW", "bc_values": {"Q": [q, q], "t": steady}})
            ends["inlet"] = name
        if tree.children[node, 0] < 0:  # a terminal
            name = f"OUT_{node}"
            p = float(pressure[node])
            conditions.append({"bc_name": name, "bc_type": "PRESSURE", "bc_values": {"P": [p, p], "t": steady}})
            ends["outlet"] = name
        else:
            junctions.append(
                {
                    "junction_name": f"J{node}",
                    "junction_type": "NORMAL_JUNCTION",
                    "inlet_vessels": [node - k],
                    "outlet_vessels": [int(c) - k for c in tree.children[node]],
                }
            )
        if ends:
            vessel["boundary_conditions"] = ends
        vessels.append(vessel)
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


def solver_check(model: dict, pressure_inlet: float) -> float | None:
    """The exported network run through svZeroDSolver: the largest relative deviation of its inlet
    pressures from ``pressure_inlet`` [Pa]. The network carries the model's inlet flows and
    terminal pressures, so a deviation near 0 confirms the model's Poiseuille pressures (the
    negative ones too) with an independent solver. None when svzerod is not installed."""
    try:
        import svzerod
    except ImportError:
        return None
    result = svzerod.simulate(model)
    last = result[result.time == result.time.max()].set_index("name")
    roots = [v["vessel_name"] for v in model["vessels"] if "inlet" in v.get("boundary_conditions", {})]
    return float(np.max(np.abs(last.loc[roots, "pressure_in"].to_numpy() / pressure_inlet - 1.0)))


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
