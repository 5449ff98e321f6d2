"""Fidelity measures of a tree against Kassab 1993 beyond the reduction's table.

Pure functions on a run store's tree arrays (``parent``, ``position`` [m], ``radius`` [m],
``kind``) and on :func:`vasc_pipeline.reduce.morphometry.morphometry` datasets, used by the
benchmarks (``benchmarks/time_to_quality.py``, ``benchmarks/fidelity.py``):

- :func:`terminal_aligned`: the orders shifted so that the lowest one sits on Kassab's order of
  nearest mean element diameter, instead of the trunk on order 11;
- :func:`per_artery_trees`: RCA, LAD and LCX as trees of their own, as Kassab ordered them;
- :func:`diameter_ratio_per_order` and :func:`kassab_diameter_ratio`: the element diameter's
  growth per order (Kassab's LAD, orders 5-11: 1.86);
- :func:`morphometry_errors` and :func:`run_row`: a run store scored in one flat row (costs,
  each inlet's share, the errors against Kassab under both alignments, the anatomy), the row
  of the benchmarks and studies.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..model.topology import contract_short_segments, inlet_of
from .anatomy import anatomy_of_store, inlet_shares
from .reference import ARTERIES, kassab_dataset

__all__ = [
    "KASSAB_FIT_ORDERS",
    "KASSAB_TOP_ORDER",
    "terminal_aligned",
    "subtree",
    "per_artery_trees",
    "diameter_ratio_per_order",
    "kassab_diameter_ratio",
    "morphometry_errors",
    "run_row",
]

KASSAB_FIT_ORDERS = slice(4, 11)  # orders 5-11: the range our trees span at N <= 6000
KASSAB_TOP_ORDER = {"RCA": 11, "LAD": 11, "LCX": 10}  # each artery's trunk order in Tables 1-3


def terminal_aligned(morph: xr.Dataset) -> tuple[xr.Dataset, int]:
    """``morph`` with its lowest diameter-defined order moved onto the Kassab (LAD) order of
    nearest mean element diameter instead of its trunk on order 11, and the shift (orders)."""
    dds = morph.sel(scheme="diameter_defined")
    lowest = int(dds.order.values[(dds.element_count > 0).values].min())
    lad = kassab_dataset().sel(artery="LAD", level="element")
    d_low = float(dds.element_diameter_mean.sel(order=lowest))
    shift = int(lad.order.values[np.nanargmin(np.abs(np.log10(lad.D_mean.values / d_low)))]) - lowest
    return morph.assign_coords(order=morph.order + shift), shift


def subtree(tree: dict, head: int) -> dict:
    """The tree below node ``head`` (a dict of tree arrays) with an inlet of its own at
    ``head``'s parent node (node 0 of the result)."""
    parent = tree["parent"].copy()
    up = int(parent[head])
    parent[head] = -1
    nodes = np.flatnonzero(inlet_of(parent) == head)
    new = np.full(parent.size, -1, dtype=np.int64)
    new[nodes] = np.arange(1, nodes.size + 1)
    return {
        "parent": np.concatenate(([-1], np.where(parent[nodes] >= 0, new[np.maximum(parent[nodes], 0)], 0))),
        "position": np.vstack([tree["position"][up], tree["position"][nodes]]),
        "radius": np.concatenate(([0.0], tree["radius"][nodes])),
        "kind": np.concatenate(([0], tree["kind"][nodes])).astype(np.int8),
    }


def per_artery_trees(tree: dict, inlet_names) -> dict[str, dict]:
    """RCA, LAD and LCX as separate trees: the LCA's two widest daughters at its first branch point.

    Kassab ordered each artery on its own; the LAD and LCX are the branches of the left
    main (the LCA's root segment, contracted when the first branch point is on the ostium).
    ``inlet_names`` must hold "LCA" and "RCA".
    """
    parent, kind = tree["parent"], tree["kind"]
    inlets = dict(zip(inlet_names, np.flatnonzero(parent < 0)))
    contracted, index = contract_short_segments(parent, tree["position"], kind)
    lca = int(np.flatnonzero(index == inlets["LCA"])[0])
    below = np.flatnonzero(contracted == lca)
    if below.size == 1:  # the left main: its children are the LAD and LCX
        below = np.flatnonzero(contracted == below[0])
    widest = below[np.argsort(-tree["radius"][index[below]], kind="stable")][:2]
    out = {"RCA": subtree(tree, int(np.flatnonzero(parent == inlets["RCA"])[0]))}
    out["LAD"], out["LCX"] = (subtree(tree, int(index[b])) for b in widest)
    return out


def diameter_ratio_per_order(orders, diameters) -> float:
    """10 ** slope of log10(diameter) against order (least squares); NaN below two orders."""
    orders, diameters = np.asarray(orders, dtype=float), np.asarray(diameters, dtype=float)
    if orders.size < 2:
        return float("nan")
    return float(10 ** np.polyfit(orders, np.log10(diameters), 1)[0])


def kassab_diameter_ratio() -> float:
    """:func:`diameter_ratio_per_order` of Kassab's LAD elements over :data:`KASSAB_FIT_ORDERS`."""
    lad = kassab_dataset().sel(artery="LAD", level="element")
    return diameter_ratio_per_order(lad.order.values[KASSAB_FIT_ORDERS], lad.D_mean.values[KASSAB_FIT_ORDERS])


def morphometry_errors(morph: xr.Dataset) -> dict:
    """The morphometry part of a row: ``n_orders``, per order what the errors are made of, and
    ``diameter_error[_terminal_aligned]_<artery>`` / ``length_error...`` (mean |log10 model/Kassab|,
    element level) with the trunk on order 11 and with the terminal order aligned."""
    from .morphometry import compare_with_kassab

    dds = morph.sel(scheme="diameter_defined")
    present = dds["element_count"] > 0
    row = {"n_orders": int(present.sum())}
    row["orders"] = {  # per order (trunk = 11): what the errors are made of
        int(o): {
            "elements": int(dds["element_count"].sel(order=o)),
            "segments_per_element": float(dds["segment_count"].sel(order=o) / dds["element_count"].sel(order=o)),
            "diameter_um": float(dds["element_diameter_mean"].sel(order=o)) * 1e6,
            "length_mm": float(dds["element_length_mean"].sel(order=o)) * 1e3,
        }
        for o in dds.order.values[present.values]
    }
    realigned, row["terminal_aligned_shift"] = terminal_aligned(morph)
    for artery in ARTERIES:
        for suffix, ds in (("", morph), ("_terminal_aligned", realigned)):
            table = compare_with_kassab(ds, artery)
            row[f"diameter_error{suffix}_{artery}"] = table.attrs["mean_abs_log10_ratio_diameter"]
            row[f"length_error{suffix}_{artery}"] = table.attrs["mean_abs_log10_ratio_length"]
    return row


def run_row(store_path) -> dict:
    """A complete run store scored in one flat row: N, steps, seed, wall time, the costs (C_s;
    ``cost_vascular`` = C_v + C_w + (A_o/A_wv) C_o and its parts, W), ``cavity_share``,
    ``terminal_share_<inlet>``, :func:`morphometry_errors` and the anatomy
    (:func:`vasc_pipeline.reduce.anatomy.anatomy`, SI units), and the store's path."""
    from ..model.costs import vascular_exclusion_cost
    from ..store.run_store import RunStore
    from .morphometry import morphometry

    store = RunStore.open(store_path, mode="r")
    a = store.attrs
    c = a["cost_recomputed"]
    w_o = a["physics"]["A_o"] / a["physics"]["A_wv"]
    row = {
        "n_terminals": int(a["coords"]["n_terminals"]),
        "steps": int(a["steps_done"]),
        "seed": int(a["seed"]),
        "wall_seconds": float(a["wall_seconds"]),
        "moves_per_second": float(a["steps_done"]) / float(a["wall_seconds"]),
        "cost_supply": float(c["supply"]),
        "cost_vascular": float(vascular_exclusion_cost(c, w_o)),
        "cost_volume": float(c["volume"]),  # C_v, W
        "cost_power": float(c["power"]),  # C_w, W
        "cost_exclusion_weighted": float(w_o * c["exclusion"]),  # (A_o/A_wv) C_o, W
        "cost_total": float(c["total"]),
        "cavity_share": float((a.get("statistics") or {}).get("cavity_share", float("nan"))),
    }
    tree = store.read_tree()
    for name, share in inlet_shares(tree["parent"], tree["kind"], store.group["tissue"].attrs["inlet_names"]).items():
        row[f"terminal_share_{name}"] = share  # ~0: an abandoned artery
    row.update(morphometry_errors(morphometry(tree["parent"], tree["position"], tree["radius"], tree["kind"])))
    row.update({k: v for k, v in anatomy_of_store(store_path).items() if not k.startswith("inlet_share_")})
    row["store"] = str(store_path)
    return row
