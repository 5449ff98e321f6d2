"""A whole tree (an extended store's) and what its Poiseuille solution says of it: territories, their
lumped resistances and 0D networks, pressures by order and in the published diameter band.

:mod:`vasc_pipeline.reduce.extended` reads the stores (:func:`~vasc_pipeline.reduce.extended.read_whole_tree`)
and runs the stage; the quantities are described in its module docstring.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from ..model.costs import Poiseuille
from ..model.physics import Physics
from ..model.topology import (
    KIND_TERMINAL,
    KIND_TERRITORY_ROOT,
    _levels,
    _pointer_jump_root,
    kept_tree,
    path_sums,
)
from .extended_summary import PRESSURE_META, PUBLISHED_PRESSURES

__all__ = [
    "WholeTree",
    "territories",
    "territory_table",
    "lumped_network",
    "full_network",
    "pressures_by_order",
    "published_band",
]


@dataclass
class WholeTree:
    """An extended store's whole tree with what its reduction needs (SI)."""

    run_id: str
    path: Path
    parent: np.ndarray
    position: np.ndarray
    radius: np.ndarray
    kind: np.ndarray
    physics: Physics  # the whole tree's: N = the fine terminals
    attrs: dict[str, Any]
    source: Path | None  # the run store it was grown below (tissue, inlet names), if still there
    inlet_names: tuple[str, ...]
    organ: str  # "heart" (compared with Kassab) or "other": the source run's tissue.organ


# --------------------------------------------------------------------------------------------
# Territories and their lumped resistances


def territories(parent: np.ndarray, kind: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(roots, territory): the pass-through nodes (the annealed terminals, in node order: root i
    is territory i's) and, per node, the territory whose subtree holds it (its root included;
    -1 for the annealed part above)."""
    roots = np.flatnonzero(kind == KIND_TERRITORY_ROOT)
    top = _pointer_jump_root(np.where((kind == KIND_TERRITORY_ROOT) | (parent < 0), np.arange(parent.size), parent))
    territory = np.where(kind[top] == KIND_TERRITORY_ROOT, np.searchsorted(roots, top), -1)
    return roots, territory


def _equal_pressure_resistance(parent: np.ndarray, resistance: np.ndarray) -> np.ndarray:
    """Per node, the resistance of the vessels below it when every terminal is at one pressure
    (series and parallel, from the terminals up; 0 at a terminal)."""
    conductance = np.zeros(parent.size)
    below = np.zeros(parent.size)
    for level in reversed(_levels(parent)):
        fed = conductance[level] > 0
        below[level[fed]] = 1.0 / conductance[level[fed]]
        with np.errstate(divide="ignore"):  # a zero-length terminal segment: a short circuit, below = 0
            np.add.at(conductance, parent[level], 1.0 / (resistance[level] + below[level]))
    return below


def territory_table(tree: WholeTree, solution: Poiseuille) -> pd.DataFrame:
    """One row per territory: its root node, flow Q_t, pressure P_t at the root, its fine terminals'
    mean P̄_t and lowest pressure, the lumped resistance R_t = (P_t − P̄_t) / Q_t, the
    series-parallel resistance of its vessels (terminals at one pressure), and the mean path
    length from the root to its fine terminals (SI)."""
    roots, territory = territories(tree.parent, tree.kind)
    fine = np.flatnonzero((tree.kind == KIND_TERMINAL) & (territory >= 0))
    label = territory[fine]
    count = np.bincount(label, minlength=roots.size)
    p = solution.pressure
    mean = np.bincount(label, weights=p[fine], minlength=roots.size) / np.maximum(count, 1)
    lowest = np.full(roots.size, np.inf)
    np.minimum.at(lowest, label, p[fine])
    path = path_sums(tree.parent, solution.length)
    depth = np.bincount(label, weights=path[fine], minlength=roots.size) / np.maximum(count, 1) - path[roots]
    flow = solution.flow[roots]
    return pd.DataFrame(
        {
            "node": roots,
            "fine_terminals": count,
            "flow": flow,
            "pressure_root": p[roots],
            "pressure_terminal_mean": mean,
            "pressure_terminal_min": lowest,
            "resistance_lumped": (p[roots] - mean) / flow,
            "resistance_network": _equal_pressure_resistance(tree.parent, solution.resistance)[roots],
            "path_length_mean": depth,
        }
    )


def lumped_network(tree: WholeTree, solution: Poiseuille, table: pd.DataFrame | None = None) -> dict:
    """The whole tree's 0D network with every territory's subtree one lumped resistance (module
    docstring): the annealed part's vessels, and per territory ``territory<root node>``."""
    from .zerod import Lumped, network

    table = territory_table(tree, solution) if table is None else table
    _, territory = territories(tree.parent, tree.kind)
    keep = np.flatnonzero((territory < 0) | (tree.kind == KIND_TERRITORY_ROOT))  # the annealed part
    parent = kept_tree(tree.parent, keep)
    roots = table["node"].to_numpy()
    lumped = Lumped(
        node=np.searchsorted(keep, roots),
        name=[f"territory{r}" for r in roots.tolist()],
        resistance=table["resistance_lumped"].to_numpy(),
        length=table["path_length_mean"].to_numpy(),
        pressure=table["pressure_terminal_mean"].to_numpy(),
    )
    s = solution
    model = network(
        parent, s.length[keep], s.resistance[keep], s.flow[keep], s.pressure[keep], tree.inlet_names, lumped
    )
    model["description"]["description"] = (
        "vasc_pipeline whole tree, lumped: the annealed tree's Poiseuille vessels; below every annealed terminal "
        "one vessel territory<node> of resistance (P_t - mean fine terminal pressure) / Q_t to that mean pressure"
    )
    return model


def full_network(tree: WholeTree, solution: Poiseuille) -> dict:
    """The whole tree's 0D network with every vessel, a ``PRESSURE`` outlet at every fine terminal."""
    from .zerod import network

    s = solution
    return network(tree.parent, s.length, s.resistance, s.flow, s.pressure, tree.inlet_names)


# --------------------------------------------------------------------------------------------
# Pressures by order


def _pressure_stats(select: np.ndarray, groups: np.ndarray, levels: np.ndarray, tree, solution) -> dict:
    """Per group (of ``levels``) of the segments ``select`` (child nodes): the PRESSURE_META values."""
    parent, p = tree.parent, solution.pressure
    seg = select
    index = np.searchsorted(levels, groups)
    m = levels.size
    length = solution.length[seg]
    along = 0.5 * (p[seg] + p[parent[seg]]) * length  # a uniform vessel's pressure falls linearly along it
    total = np.bincount(index, weights=length, minlength=m)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(index, weights=along, minlength=m) / total
    out = {"pressure_mean": mean}
    for name, values, fill, reduce in (
        ("pressure_min", p[seg], np.inf, np.minimum),
        ("pressure_max", p[parent[seg]], -np.inf, np.maximum),
        ("diameter_min", 2.0 * tree.radius[seg], np.inf, np.minimum),
        ("diameter_max", 2.0 * tree.radius[seg], -np.inf, np.maximum),
    ):
        acc = np.full(m, fill)
        reduce.at(acc, index, values)
        out[name] = np.where(np.isfinite(acc), acc, np.nan)
    out["pressure_mean_fraction"] = out["pressure_mean"] / tree.physics.pressure_inlet
    out["pressure_min_fraction"] = out["pressure_min"] / tree.physics.pressure_inlet
    out["vessel_length"] = total
    return out


def pressures_by_order(tree: WholeTree, solution: Poiseuille, segment_order: np.ndarray, orders) -> xr.Dataset:
    """Pressures (``PRESSURE_META``) per diameter-defined order (dim ``order``) from the
    node-indexed ``segment_order`` of a morphometry (0: a contracted segment, left out)."""
    orders = np.asarray(orders, dtype=np.int64)
    seg = np.flatnonzero((tree.parent >= 0) & np.isin(segment_order, orders))
    values = _pressure_stats(seg, segment_order[seg], orders, tree, solution)
    data = {
        k: ("order", v, {"units": PRESSURE_META[k][0], "long_name": PRESSURE_META[k][1]}) for k, v in values.items()
    }
    return xr.Dataset(data, coords={"order": ("order", orders, {"long_name": "vessel order", "units": "1"})})


def published_band(tree: WholeTree, solution: Poiseuille) -> dict[str, float]:
    """The pressures of the vessels with a diameter in :data:`PUBLISHED_PRESSURES`' range."""
    d = 2.0 * tree.radius
    band = PUBLISHED_PRESSURES
    seg = np.flatnonzero((tree.parent >= 0) & (d >= band["diameter_min"]) & (d <= band["diameter_max"]))
    values = _pressure_stats(seg, np.zeros(seg.size, np.int64), np.zeros(1, np.int64), tree, solution)
    return {f"band_{k}": float(v[0]) for k, v in values.items()}
