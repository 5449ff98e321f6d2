"""Fidelity measures of a tree against Kassab 1993 beyond the reduction's table.

Pure functions on a run store's tree arrays (``parent``, ``position`` [m], ``radius`` [m],
``kind``) and on :func:`vasc_pipeline.reduce.morphometry.morphometry` datasets, used by the
benchmarks (``benchmarks/time_to_quality.py``, ``benchmarks/fidelity.py``):

- :func:`terminal_aligned`: the orders shifted so that the lowest one sits on Kassab's order of
  nearest mean element diameter, instead of the trunk on order 11;
- :func:`inlet_shares`: each inlet's share of the terminals (near 0: an abandoned artery);
- :func:`per_artery_trees`: RCA, LAD and LCX as trees of their own, as Kassab ordered them;
- :func:`diameter_ratio_per_order` and :func:`kassab_diameter_ratio`: the element diameter's
  growth per order (Kassab's LAD, orders 5-11: 1.86).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..model.topology import KIND_TERMINAL, contract_short_segments, inlet_of
from .reference import kassab_dataset

__all__ = [
    "KASSAB_FIT_ORDERS",
    "KASSAB_TOP_ORDER",
    "terminal_aligned",
    "inlet_shares",
    "subtree",
    "per_artery_trees",
    "diameter_ratio_per_order",
    "kassab_diameter_ratio",
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


def inlet_shares(parent, kind, inlet_names) -> dict[str, float]:
    """Per inlet (in node order, named by ``inlet_names``) its share of the terminals."""
    parent, kind = np.asarray(parent), np.asarray(kind)
    terminals = inlet_of(parent)[kind == KIND_TERMINAL]
    return {name: float(np.mean(terminals == inlet)) for name, inlet in zip(inlet_names, np.flatnonzero(parent < 0))}


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
