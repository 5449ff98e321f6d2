"""Order-wise morphometry of a tree: diameter-defined Strahler orders, elements, statistics.

Pure functions on a run store's tree arrays (NumPy only, no numba); the
topology helpers live in :mod:`vasc_pipeline.model.topology`, the orders in
:mod:`vasc_pipeline.reduce.ordering` and the comparison with Kassab 1993 in
:mod:`vasc_pipeline.reduce.reference` (all re-exported here):

- ``parent``   int64 (node,)     parent node, -1 at inlets
- ``position`` float64 (node, 3) metres
- ``radius``   float64 (node,)   radius of the segment from the node to its parent, metres
- ``kind``     int8 (node,)      0 inlet, 1 bifurcation, 2 terminal, 3 pass-through (an extended
                                 store's annealed terminals: one child, no branch point)

A segment is identified by its child node, so per-segment arrays are indexed by node and
hold a filler at inlets (0 for orders and lengths, -1 for ids). Several inlets make a
forest; every function handles all trees at once, and diameter-defined orders pool the
segments of all trees (use :func:`select_trees` first for per-artery orders).

Everything is O(n log n) except the conventional Strahler pass (~10 ms for 12000 nodes).
Diameter-defined Strahler ordering and its edge cases: see :mod:`vasc_pipeline.reduce.ordering`.

Zero-length segments: the anneal's optimal branch points may coincide with their parent
branch point (the optimum of a three-point junction sits on a vertex), leaving a segment of
length zero between two bifurcations: a trifurcation written as two bifurcations. The final
polish converges to such a vertex only to within a few micrometres: of over a hundred heart
trees of N = 500-6000 (several schedules and options), 14 have a root segment (ostium to
first branch point) shorter than 10 µm (9 under 1 nm; 0.57, 1.2, 2.2, 5.7 and 6.2 µm), the
next shortest is 0.39 mm, and N = 6000 trees hold ~50 segments of 0.1-1 µm between
branch points. Ordered as they stand, such a segment counts
as a vessel of its own and, at an ostium, becomes a spurious highest order of zero length
that shifts every other order down by one. :func:`morphometry` therefore contracts
segments shorter than ``min_segment_length`` (default 10 µm: shorter than the radius of
every vessel of the heart's trees up to N ~ 20 000, so no such segment can be a vessel a
cast would show) whose child is a branching
node, and orders the resulting tree, which may have multifurcations: conventional Strahler
gives ``n + 1`` when the two highest daughter orders are both ``n``; asymmetry ratios use
the smallest and largest daughter. Zero-length *terminal* segments (a terminal on its
branch point) are kept: they are outlets with a diameter.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import xarray as xr

from ..model.topology import (
    KIND_BIFURCATION,
    KIND_INLET,
    KIND_TERMINAL,
    KIND_TERRITORY_ROOT,
    MIN_SEGMENT_LENGTH,
    _child_lists,
    _parent_array,
    check_tree_arrays,
    children_of,
    contract_short_segments,
    inlet_of,
    node_depth,
    segment_lengths,
    select_trees,
    topological_order,
)
from .ordering import (
    TOP_ORDER,
    DDSResult,
    Elements,
    diameter_defined_strahler,
    elements,
    shift_orders,
    strahler_orders,
)
from .reference import compare_with_kassab

__all__ = [  # the topology, ordering and reference names stay importable from here (public API)
    "KIND_INLET",
    "KIND_BIFURCATION",
    "KIND_TERMINAL",
    "TOP_ORDER",
    "check_tree_arrays",
    "children_of",
    "node_depth",
    "topological_order",
    "inlet_of",
    "select_trees",
    "contract_short_segments",
    "segment_lengths",
    "strahler_orders",
    "DDSResult",
    "diameter_defined_strahler",
    "Elements",
    "elements",
    "grouped_statistics",
    "order_statistics",
    "Asymmetry",
    "asymmetry_ratios",
    "asymmetry_statistics",
    "shift_orders",
    "morphometry",
    "compare_with_kassab",
]


SCHEMES = ("diameter_defined", "strahler")


# --------------------------------------------------------------------------- statistics


def grouped_statistics(values, groups, levels):
    """Mean, SD, SE and count of ``values`` per group.

    Parameters
    ----------
    values : float (k,)
    groups : int (k,)
        Group label of every value.
    levels : int (m,)
        Group labels to report, in this order (labels not in ``groups`` get count 0).

    Returns
    -------
    mean, sd, se : float64 (m,)
        Sample SD (ddof=1); SE = SD / sqrt(count). NaN where undefined (mean for count
        0, SD and SE for count < 2).
    count : int64 (m,)

    Examples
    --------
    >>> m, sd, se, n = grouped_statistics([1.0, 3.0, 5.0], [1, 1, 2], [1, 2, 3])
    >>> m.tolist(), n.tolist()
    ([2.0, 5.0, nan], [2, 1, 0])
    """
    values = np.asarray(values, dtype=float)
    groups = np.asarray(groups, dtype=np.int64)
    levels = np.asarray(levels, dtype=np.int64)
    m = levels.size
    if m == 0:
        empty = np.zeros(0)
        return empty, empty.copy(), empty.copy(), np.zeros(0, dtype=np.int64)
    sorter = np.argsort(levels, kind="stable")
    pos = np.minimum(np.searchsorted(levels, groups, sorter=sorter), m - 1)
    idx = sorter[pos]
    valid = levels[idx] == groups  # values whose group is not reported are dropped
    idx, vals = idx[valid], values[valid]
    count = np.bincount(idx, minlength=m)[:m]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.bincount(idx, weights=vals, minlength=m)[:m] / count
        ss = np.bincount(idx, weights=(vals - mean[idx]) ** 2, minlength=m)[:m]
        sd = np.where(count >= 2, np.sqrt(ss / np.maximum(count - 1, 1)), np.nan)
        se = sd / np.sqrt(count)
    mean = np.where(count > 0, mean, np.nan)
    return mean, sd, se, count.astype(np.int64)


def _stat_vars(prefix: str, what: str, values, groups, levels, units: str) -> dict:
    mean, sd, se, count = grouped_statistics(values, groups, levels)
    return {
        f"{prefix}_mean": ("order", mean, {"units": units, "long_name": f"mean {what}"}),
        f"{prefix}_sd": ("order", sd, {"units": units, "long_name": f"standard deviation of {what}"}),
        f"{prefix}_se": ("order", se, {"units": units, "long_name": f"standard error of mean {what}"}),
    }, count


def _order_range(*arrays) -> np.ndarray:
    vals = [np.asarray(a, dtype=np.int64) for a in arrays if np.size(a)]
    if not vals:
        return np.zeros(0, dtype=np.int64)
    lo = min(int(v.min()) for v in vals)
    hi = max(int(v.max()) for v in vals)
    return np.arange(lo, hi + 1, dtype=np.int64)


def _order_coord(levels) -> dict:
    return {"order": ("order", np.asarray(levels, dtype=np.int64), {"long_name": "vessel order", "units": "1"})}


def order_statistics(
    element_order,
    element_diameter,
    element_length,
    segment_order=None,
    segment_diameter=None,
    segment_length=None,
    orders=None,
) -> xr.Dataset:
    """Per-order statistics of element (and segment) diameter and length.

    Parameters
    ----------
    element_order : int (n_el,)
    element_diameter, element_length : float64 (n_el,), metres
    segment_order : int (n_seg,), optional
        One entry per segment, inlets excluded (not node-indexed).
    segment_diameter, segment_length : float64 (n_seg,), metres, optional
    orders : int (m,), optional
        Order coordinate; default every integer from the lowest to the highest order.

    Returns
    -------
    xarray.Dataset
        Dim ``order``. ``element_diameter_{mean,sd,se}``, ``element_length_{mean,sd,se}``
        (m), ``element_count``; with segments also ``segment_diameter_*``,
        ``segment_length_*``, ``segment_count`` and ``segments_per_element`` (Kassab's
        S/E ratio). SD is the sample SD (NaN for a single vessel).
    """
    levels = (
        _order_range(element_order, *(() if segment_order is None else (segment_order,)))
        if orders is None
        else np.asarray(orders, dtype=np.int64)
    )
    data = {}
    v, count = _stat_vars("element_diameter", "element diameter", element_diameter, element_order, levels, "m")
    data.update(v)
    v, _ = _stat_vars("element_length", "element length", element_length, element_order, levels, "m")
    data.update(v)
    data["element_count"] = ("order", count, {"units": "1", "long_name": "number of elements"})
    if segment_order is not None:
        v, seg_count = _stat_vars("segment_diameter", "segment diameter", segment_diameter, segment_order, levels, "m")
        data.update(v)
        v, _ = _stat_vars("segment_length", "segment length", segment_length, segment_order, levels, "m")
        data.update(v)
        data["segment_count"] = ("order", seg_count, {"units": "1", "long_name": "number of segments"})
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(count > 0, seg_count / np.maximum(count, 1), np.nan)
        data["segments_per_element"] = ("order", ratio, {"units": "1", "long_name": "segments per element (S/E ratio)"})
    return xr.Dataset(data, coords=_order_coord(levels))


class Asymmetry(NamedTuple):
    """Daughter-to-parent diameter ratios, one entry per bifurcation (``n_bif``).

    Attributes
    ----------
    node : int64 (n_bif,)
        Bifurcation node (its segment is the parent vessel).
    order : int64 (n_bif,)
        Order of the parent segment.
    small : float64 (n_bif,)
        D_s / D_p, smaller daughter diameter over parent diameter.
    large : float64 (n_bif,)
        D_l / D_p, larger daughter diameter over parent diameter.
    """

    node: np.ndarray
    order: np.ndarray
    small: np.ndarray
    large: np.ndarray


def asymmetry_ratios(parent, radius, kind, orders) -> Asymmetry:
    """Per bifurcation: D_s/D_p and D_l/D_p with the parent segment's order.

    At a multifurcation (contracted trees) D_s and D_l are the smallest and the largest
    daughter.

    Parameters
    ----------
    parent : int64 (node,)
    radius : float64 (node,), metres
    kind : int8 (node,)
    orders : int (node,)
        Segment orders (any scheme; the parent segment's order is reported).

    Returns
    -------
    Asymmetry

    Examples
    --------
    >>> a = asymmetry_ratios([-1, 0, 1, 1], [0, 2.0, 1.0, 1.5], [0, 1, 2, 2], [0, 2, 1, 1])
    >>> a.small.tolist(), a.large.tolist(), a.order.tolist()
    ([0.5], [0.75], [2])
    """
    parent = _parent_array(parent)
    radius = np.asarray(radius, dtype=float)
    orders = np.asarray(orders, dtype=np.int64)
    start, child = _child_lists(parent)
    has_children = np.flatnonzero(start[1:] > start[:-1])  # reduceat needs non-empty runs
    r_min = np.minimum.reduceat(radius[child], start[has_children]) if child.size else np.zeros(0)
    r_max = np.maximum.reduceat(radius[child], start[has_children]) if child.size else np.zeros(0)
    branching = np.asarray(kind)[has_children] == KIND_BIFURCATION
    node = has_children[branching]
    rp = radius[node]
    return Asymmetry(node.astype(np.int64), orders[node].copy(), r_min[branching] / rp, r_max[branching] / rp)


def asymmetry_statistics(asym: Asymmetry, orders=None) -> xr.Dataset:
    """Asymmetry ratios grouped by the parent's order.

    Parameters
    ----------
    asym : Asymmetry
        From :func:`asymmetry_ratios`.
    orders : int (m,), optional
        Order coordinate; default the range of parent orders.

    Returns
    -------
    xarray.Dataset
        Dim ``order``: ``diameter_ratio_small_{mean,sd,se}``,
        ``diameter_ratio_large_{mean,sd,se}`` (dimensionless) and ``bifurcation_count``.
    """
    levels = _order_range(asym.order) if orders is None else np.asarray(orders, dtype=np.int64)
    data = {}
    v, count = _stat_vars(
        "diameter_ratio_small", "smaller daughter to parent diameter ratio D_s/D_p", asym.small, asym.order, levels, "1"
    )
    data.update(v)
    v, _ = _stat_vars(
        "diameter_ratio_large", "larger daughter to parent diameter ratio D_l/D_p", asym.large, asym.order, levels, "1"
    )
    data.update(v)
    data["bifurcation_count"] = (
        "order",
        count,
        {"units": "1", "long_name": "number of bifurcations (by parent order)"},
    )
    return xr.Dataset(data, coords=_order_coord(levels))


# --------------------------------------------------------------------------- assembly


def _bends(parent: np.ndarray, kind: np.ndarray) -> np.ndarray:
    """int64 (node,): where the chord from a vessel's start ends: the pass-through node above a
    segment that continues its vessel (kind 3 parent), else the node itself."""
    bend = np.arange(parent.size)
    below = np.flatnonzero(parent >= 0)
    below = below[kind[parent[below]] == KIND_TERRITORY_ROOT]
    bend[below] = parent[below]
    return bend


def _contracted_lengths(parent: np.ndarray, kept: np.ndarray, position: np.ndarray, bend: np.ndarray) -> np.ndarray:
    """Length of every segment of a contracted tree (``parent`` over the original nodes ``kept``):
    from its new parent's position to its bend, then to its own node (0 at inlets). Without a
    pass-through node the bend is the node: the plain distance, bit for bit."""
    length = np.zeros(kept.size)
    s = np.flatnonzero(parent >= 0)
    node, start, b = kept[s], kept[parent[s]], bend[kept[s]]
    length[s] = np.linalg.norm(position[b] - position[start], axis=-1) + np.linalg.norm(
        position[node] - position[b], axis=-1
    )
    return length


def morphometry(
    parent,
    position,
    radius,
    kind,
    *,
    top: int | None = TOP_ORDER,
    max_iter: int = 100,
    tol: float = 0.01,
    min_segment_length: float = MIN_SEGMENT_LENGTH,
    reading: str = "range",
) -> xr.Dataset:
    """Order-wise morphometry of a tree (or forest) as a labelled dataset.

    Parameters
    ----------
    parent : int64 (node,)
    position : float64 (node, 3), metres
    radius : float64 (node,), metres
    kind : int8 (node,)
    top : int or None
        Both order schemes are shifted so that their highest order equals ``top``
        (Kassab's trunk order 11); None keeps raw orders (1 = terminal).
    max_iter, tol, reading
        Passed to :func:`diameter_defined_strahler` (``reading``: "range", the default, or
        "confluence").
    min_segment_length : float
        Segments between branch points shorter than this (metres) are contracted before
        ordering (:func:`contract_short_segments`; 0 keeps the tree as it is). A pass-through
        node (kind 3, the whole tree's annealed terminals) is no branch point: the segments
        above and below it are one segment, its length theirs together.

    Returns
    -------
    xarray.Dataset
        Dims ``scheme`` ("diameter_defined", "strahler"), ``order`` (contiguous, union
        of both schemes; NaN / 0 where a scheme has no vessel) and ``node``.
        Per (scheme, order): the variables of :func:`order_statistics` and
        :func:`asymmetry_statistics`. Per scheme: ``order_shift`` (added to the raw
        orders) and ``n_elements``. Per (scheme, node): ``segment_order`` (shifted; 0 at
        inlets and contracted segments; a pass-through node's that of the segment it
        continues in) and ``element_id`` (-1 where the order is 0). Per node:
        ``segment_diameter`` and ``segment_length`` (m, 0 at inlets). Attrs:
        ``dds_iterations``, ``dds_changed_fraction``, ``dds_converged`` (0/1, netCDF-safe),
        ``dds_tol``, ``n_inlets``, ``n_terminals``, ``n_segments`` (after contraction),
        ``n_contracted_segments``, ``n_pass_through``, ``min_segment_length``, ``top_order`` (-1 when
        unshifted). Every variable has ``units`` and ``long_name``.

    Examples
    --------
    >>> ds = morphometry([-1, 0, 1, 1], [[0, 0, 0], [1, 0, 0], [2, 1, 0], [2, -1, 0]],
    ...                  [0, 1.0, 0.7, 0.7], [0, 1, 2, 2])
    >>> ds.element_count.sel(scheme="strahler").values.tolist(), ds.order.values.tolist()
    ([2, 1], [10, 11])
    """
    full_parent = _parent_array(parent)
    check_tree_arrays(full_parent, kind, radius=radius, position=position)
    position = np.asarray(position, dtype=float)
    full_kind = np.asarray(kind)
    full_diameter = np.where(full_parent >= 0, 2.0 * np.asarray(radius, dtype=float), 0.0)
    full_length = segment_lengths(full_parent, position)
    bend = _bends(full_parent, full_kind)
    vessel_length = full_length + np.where(bend != np.arange(bend.size), full_length[bend], 0.0)
    parent, kept = contract_short_segments(full_parent, position, full_kind, min_segment_length, vessel_length)
    radius = np.asarray(radius, dtype=float)[kept]
    kind = full_kind[kept]
    seg = np.flatnonzero(parent >= 0)
    diameter = full_diameter[kept]
    length = _contracted_lengths(parent, kept, position, bend)
    through = np.flatnonzero(full_kind == KIND_TERRITORY_ROOT)
    through_child = np.flatnonzero((full_parent >= 0) & (bend != np.arange(bend.size)))
    dds = diameter_defined_strahler(parent, radius, kind, max_iter=max_iter, tol=tol, reading=reading)
    raw = {"diameter_defined": dds.orders, "strahler": strahler_orders(parent, kind)}
    shifted = {k: (shift_orders(v, top, mask=parent >= 0) if top is not None else v) for k, v in raw.items()}
    levels = _order_range(*(v[seg] for v in shifted.values()))
    parts = []
    for scheme in SCHEMES:
        orders = shifted[scheme]
        el = elements(parent, orders, diameter, length)
        stats = order_statistics(
            el.order, el.diameter, el.length, orders[seg], diameter[seg], length[seg], orders=levels
        )
        asym = asymmetry_statistics(asymmetry_ratios(parent, radius, kind, orders), orders=levels)
        part = xr.merge([stats, asym])
        part["order_shift"] = (
            (),
            int(orders[seg][0] - raw[scheme][seg][0]) if seg.size else 0,
            {"units": "1", "long_name": "shift added to the raw orders (1 = terminal)"},
        )
        part["n_elements"] = ((), int(el.order.size), {"units": "1", "long_name": "number of elements"})
        node_order = np.zeros(full_parent.size, dtype=np.int64)
        node_order[kept] = orders
        node_element = np.full(full_parent.size, -1, dtype=np.int64)
        node_element[kept] = el.segment_element
        node_order[full_parent[through_child]] = node_order[through_child]  # the segment it continues in
        node_element[full_parent[through_child]] = node_element[through_child]
        part["segment_order"] = (
            "node",
            node_order,
            {"units": "1", "long_name": "order of the segment ending at the node"},
        )
        part["element_id"] = (
            "node",
            node_element,
            {"units": "1", "long_name": "element of the segment ending at the node"},
        )
        parts.append(part)
    ds = xr.concat(
        parts,
        dim=xr.DataArray(list(SCHEMES), dims="scheme", name="scheme"),
        data_vars="all",
        coords="minimal",
        compat="equals",
        join="outer",
    )
    ds["scheme"].attrs.update(long_name="ordering scheme")
    ds["order"].attrs.update(
        long_name="vessel order" + (f" (shifted: highest = {top})" if top is not None else ""), units="1"
    )
    ds["segment_diameter"] = ("node", full_diameter, {"units": "m", "long_name": "segment diameter"})
    ds["segment_length"] = ("node", full_length, {"units": "m", "long_name": "segment length"})
    ds.attrs.update(
        dds_iterations=int(dds.n_iter),
        dds_converged=int(bool(dds.converged)),
        dds_tol=float(tol),
        dds_changed_fraction=[float(x) for x in dds.changed],
        n_inlets=int((kind == KIND_INLET).sum()),
        n_terminals=int((kind == KIND_TERMINAL).sum()),
        n_segments=int(seg.size),
        n_contracted_segments=int(full_parent.size - kept.size - through.size),
        n_pass_through=int(through.size),
        min_segment_length=float(min_segment_length),
        top_order=-1 if top is None else int(top),
        ordering=f"diameter_defined: Jiang, Kassab & Fung 1994 {reading} reassignment "
        "(vasc_pipeline.reduce.morphometry); strahler: conventional Strahler",
    )
    return ds
