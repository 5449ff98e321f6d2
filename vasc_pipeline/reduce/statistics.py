"""Per-order statistics of a tree's vessels (:mod:`vasc_pipeline.reduce.morphometry` assembles them):
mean, SD, SE and count of element and segment diameters and lengths by order, and the asymmetry of
bifurcations, the daughter to parent diameter ratios by parent order.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import xarray as xr

from ..model.topology import KIND_BIFURCATION, _child_lists, _parent_array

__all__ = ["Asymmetry", "asymmetry_ratios", "asymmetry_statistics", "grouped_statistics", "order_statistics"]


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
