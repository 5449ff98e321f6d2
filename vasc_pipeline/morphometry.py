"""Order-wise morphometry of a tree: diameter-defined Strahler orders, elements, statistics.

Pure functions on the tree arrays of SPEC section 7 (NumPy only, no numba):

- ``parent``   int64 (node,)     parent node, -1 at inlets
- ``position`` float64 (node, 3) metres
- ``radius``   float64 (node,)   radius of the segment from the node to its parent, metres
- ``kind``     int8 (node,)      0 inlet, 1 bifurcation, 2 terminal

A segment is identified by its child node, so per-segment arrays are indexed by node and
hold a filler at inlets (0 for orders and lengths, -1 for ids). Several inlets make a
forest; every function handles all trees at once, and diameter-defined orders pool the
segments of all trees (use :func:`select_trees` first for per-artery orders).

Nodes may be numbered in any order (the anneal's layout puts bifurcations after
terminals); a topological order is computed by pointer jumping, never by recursion, so
trees of any depth work. Everything is O(n log n) except the conventional Strahler pass,
a plain loop over nodes (~10 ms for 12000 nodes).

Diameter-defined Strahler ordering (Jiang, Kassab & Fung 1994; Kassab et al. 1993), the
"range" reading of ``reference/jiang1994_dd_strahler_algorithm.txt``: starting from
conventional Strahler orders, every segment gets the order whose diameter interval
``(B(n-1,n), B(n,n+1)]`` contains its diameter, with
``B(n,n+1) = [(D_n + SD_n) + (D_{n+1} - SD_{n+1})] / 2``, until fewer than ``tol`` of the
segments change order. Edge cases, decided here:

- SD is the sample SD (ddof=1); an order holding a single segment has SD 0 in the bounds
  (its interval is centred on that diameter). In the reported statistics such an SD is
  NaN, as Kassab leaves it blank.
- Bounds that are not monotone (heavily overlapping orders) are made non-decreasing by a
  running maximum; the squeezed order gets an empty interval.
- An order left empty after a pass drops out: bounds are always formed between
  consecutive non-empty orders, so an emptied order is never refilled, and at the end
  the surviving orders are renumbered 1..M in increasing diameter rank.
- A single order has no bounds: nothing changes.
- The iteration stops after ``max_iter`` passes even if not converged (``converged`` is
  then False and the last orders are returned).

Zero-length segments: the anneal's optimal branch points may coincide with their parent
branch point (the optimum of a three-point junction sits on a vertex), leaving a segment of
length zero between two bifurcations: a trifurcation written as two bifurcations. Ordered
as they stand, such a segment counts as a vessel of its own and, at an ostium, becomes a
spurious highest order of zero length that shifts every other order down by one.
:func:`morphometry` therefore contracts segments shorter than ``min_segment_length``
(default 1 nm, far below any vessel and far above round-off) whose child is a branching
node, and orders the resulting tree, which may have multifurcations: conventional Strahler
gives ``n + 1`` when the two highest daughter orders are both ``n``; asymmetry ratios use
the smallest and largest daughter. Zero-length *terminal* segments (a terminal on its
branch point) are kept: they are outlets with a diameter.

Elements: a segment joins its parent segment's element when both have the same order.
When several daughters of a branching node share their parent's order (possible with
diameter-defined orders), only the widest daughter (ties: the lower node index) continues
the element, so elements are always series runs; the other daughter starts a new element.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pandas as pd
import xarray as xr

__all__ = [
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

# Same codes as vasc_pipeline.tree; repeated here so this module depends on NumPy alone.
KIND_INLET, KIND_BIFURCATION, KIND_TERMINAL = 0, 1, 2
TOP_ORDER = 11  # order of the pig coronary trunks (RCA, LAD) in Kassab et al. 1993

SCHEMES = ("diameter_defined", "strahler")
MIN_SEGMENT_LENGTH = 1e-9  # m: shorter segments between branch points are contracted


# --------------------------------------------------------------------------- topology


def _parent_array(parent) -> np.ndarray:
    parent = np.asarray(parent)
    if parent.ndim != 1 or not np.issubdtype(parent.dtype, np.integer):
        raise ValueError(f"parent: expected a 1-D integer array, got dtype {parent.dtype} and shape {parent.shape}")
    parent = parent.astype(np.int64, copy=False)
    n = parent.size
    bad = (parent < -1) | (parent >= n) | (parent == np.arange(n))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"parent: node {i} has parent {int(parent[i])}; accepted values are -1 (inlet) or another "
            f"node index in [0, {n})"
        )
    return parent


def _pointer_jump_root(link: np.ndarray) -> np.ndarray:
    """Root of every node for a forest given as ``link`` (roots point to themselves)."""
    root = link.copy()
    for _ in range(max(1, root.size.bit_length()) + 2):
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt
    raise ValueError("parent: the parent array has a cycle (some nodes never reach an inlet)")


def node_depth(parent) -> np.ndarray:
    """Number of segments between every node and its inlet.

    Parameters
    ----------
    parent : int64 (node,)
        Parent index, -1 at inlets.

    Returns
    -------
    int64 (node,)
        0 at inlets, 1 at an inlet's child, ...

    Raises
    ------
    ValueError
        If the parent array has a cycle.

    Notes
    -----
    Pointer jumping: O(n log depth), no recursion.
    """
    parent = _parent_array(parent)
    anc = parent.copy()
    depth = (parent >= 0).astype(np.int64)
    for _ in range(max(1, parent.size.bit_length()) + 2):
        idx = np.flatnonzero(anc >= 0)
        if idx.size == 0:
            return depth
        a = anc[idx]
        depth[idx] += depth[a]  # right-hand sides are read before any write: a synchronous jump
        anc[idx] = anc[a]
    raise ValueError("parent: the parent array has a cycle (some nodes never reach an inlet)")


def topological_order(parent) -> np.ndarray:
    """int64 (node,) node indices sorted by depth: every parent comes before its children."""
    return np.argsort(node_depth(parent), kind="stable")


def inlet_of(parent) -> np.ndarray:
    """int64 (node,) the inlet (root) node of every node's tree; inlets map to themselves."""
    parent = _parent_array(parent)
    link = np.where(parent >= 0, parent, np.arange(parent.size))
    return _pointer_jump_root(link)


def children_of(parent) -> np.ndarray:
    """Child table of a tree.

    Parameters
    ----------
    parent : int64 (node,)
        Parent index, -1 at inlets.

    Returns
    -------
    int64 (node, 2)
        Children of every node in increasing index order, -1 where absent (terminals
        have none, inlets one).

    Raises
    ------
    ValueError
        If a node has more than two children.
    """
    parent = _parent_array(parent)
    child = np.flatnonzero(parent >= 0)
    p = parent[child]
    order = np.argsort(p, kind="stable")  # stable: children stay in increasing index order
    child, p = child[order], p[order]
    pos = np.arange(p.size)
    first = np.ones(p.size, dtype=bool)
    first[1:] = p[1:] != p[:-1]
    slot = pos - np.maximum.accumulate(np.where(first, pos, 0))
    if (slot > 1).any():
        node = int(p[np.flatnonzero(slot > 1)[0]])
        raise ValueError(f"parent: node {node} has more than two children")
    table = np.full((parent.size, 2), -1, dtype=np.int64)
    table[p, slot] = child
    return table


def _child_lists(parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Children of every node, any number: node v's are ``child[start[v]:start[v + 1]]``."""
    child = np.flatnonzero(parent >= 0)
    child = child[np.argsort(parent[child], kind="stable")]  # stable: increasing index per node
    count = np.bincount(parent[child], minlength=parent.size)
    return np.concatenate(([0], np.cumsum(count))), child


def check_tree_arrays(parent, kind, radius=None, position=None, *, multifurcations: bool = False) -> None:
    """Check the tree-array contract; raise ValueError naming the field otherwise.

    Parameters
    ----------
    parent : int64 (node,)
    kind : int8 (node,)
        0 inlet (exactly one child, parent -1), 1 bifurcation (two children),
        2 terminal (no children).
    radius : float64 (node,), optional
        Must be finite and > 0 on every segment (every non-inlet node).
    position : float64 (node, 3), optional
        Must be finite.
    multifurcations : bool
        Accept contracted trees (:func:`contract_short_segments`): inlets with one or
        more children, branching nodes (kind 1) with two or more.
    """
    parent = _parent_array(parent)
    n = parent.size
    kind = np.asarray(kind)
    if kind.shape != (n,):
        raise ValueError(f"kind: expected shape ({n},) like parent, got {kind.shape}")
    if not np.isin(kind, (KIND_INLET, KIND_BIFURCATION, KIND_TERMINAL)).all():
        raise ValueError("kind: accepted values are 0 (inlet), 1 (bifurcation), 2 (terminal)")
    if n == 0 or not (kind == KIND_INLET).any():
        raise ValueError("kind: the tree needs at least one inlet (kind 0)")
    mismatch = (kind == KIND_INLET) != (parent < 0)
    if mismatch.any():
        i = int(np.flatnonzero(mismatch)[0])
        raise ValueError(
            f"parent/kind: node {i} has kind {int(kind[i])} and parent {int(parent[i])}; inlets "
            f"(kind 0) and only inlets have parent -1"
        )
    n_children = np.bincount(parent[parent >= 0], minlength=n)
    expected = np.choose(kind.astype(np.int64), (1, 2, 0))
    bad = (
        ((n_children < expected) | ((kind == KIND_TERMINAL) & (n_children > 0)))
        if multifurcations
        else n_children != expected
    )
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        need = "at least 1, a branching node at least 2" if multifurcations else "1, a bifurcation 2"
        raise ValueError(
            f"parent/kind: node {i} of kind {int(kind[i])} has {int(n_children[i])} children; an "
            f"inlet needs {need}, a terminal 0"
        )
    node_depth(parent)  # raises on cycles
    if radius is not None:
        radius = np.asarray(radius, dtype=float)
        if radius.shape != (n,):
            raise ValueError(f"radius: expected shape ({n},) like parent, got {radius.shape}")
        seg = parent >= 0
        if not (np.isfinite(radius[seg]).all() and (radius[seg] > 0).all()):
            raise ValueError("radius: every segment (non-inlet node) needs a finite radius > 0 (metres)")
    if position is not None:
        position = np.asarray(position, dtype=float)
        if position.shape != (n, 3):
            raise ValueError(f"position: expected shape ({n}, 3), got {position.shape}")
        if not np.isfinite(position).all():
            raise ValueError("position: all coordinates must be finite (metres)")


def select_trees(parent, position, radius, kind, inlets):
    """The sub-forest of the given inlets, renumbered compactly.

    Parameters
    ----------
    parent, position, radius, kind
        Tree arrays (see module docstring).
    inlets : int or sequence of int
        Inlet node indices whose trees to keep.

    Returns
    -------
    parent, position, radius, kind : arrays of the sub-forest
        Nodes keep their relative order; parent indices are renumbered.
    index : int64 (node_sub,)
        Original index of every kept node.
    """
    parent = _parent_array(parent)
    inlets = np.atleast_1d(np.asarray(inlets, dtype=np.int64))
    if ((inlets < 0) | (inlets >= parent.size)).any() or (parent[inlets] != -1).any():
        raise ValueError(f"inlets: {inlets.tolist()} are not all inlet nodes (parent -1)")
    index = np.flatnonzero(np.isin(inlet_of(parent), inlets))
    new = np.full(parent.size, -1, dtype=np.int64)
    new[index] = np.arange(index.size)
    sub_parent = np.where(parent[index] >= 0, new[np.maximum(parent[index], 0)], -1)
    return (sub_parent, np.asarray(position)[index], np.asarray(radius)[index], np.asarray(kind)[index], index)


def contract_short_segments(parent, position, kind, min_length: float = MIN_SEGMENT_LENGTH):
    """Merge every branching node that sits on its parent node into that parent.

    Parameters
    ----------
    parent : int64 (node,)
    position : float64 (node, 3), metres
    kind : int8 (node,)
    min_length : float
        Segments shorter than this (metres, >= 0) whose child is a branching node
        (kind 1) are contracted; 0 contracts nothing.

    Returns
    -------
    parent : int64 (node_kept,)
        Parent array of the contracted tree over the kept nodes (renumbered; nodes keep
        their relative order). A node may now have more than two children.
    index : int64 (node_kept,)
        Original index of every kept node (take position, radius and kind with it).

    Examples
    --------
    >>> parent, index = contract_short_segments(
    ...     [-1, 0, 1, 2, 2, 1], [[0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 1, 0], [2, -1, 0], [1, 1, 0]],
    ...     [0, 1, 1, 2, 2, 2])
    >>> parent.tolist(), index.tolist()
    ([-1, 0, 1, 1, 1], [0, 1, 3, 4, 5])
    """
    parent = _parent_array(parent)
    if not (np.isfinite(min_length) and min_length >= 0):
        raise ValueError(f"min_length: must be a finite length >= 0 (metres), got {min_length}")
    gone = (parent >= 0) & (np.asarray(kind) == KIND_BIFURCATION) & (segment_lengths(parent, position) < min_length)
    # every contracted node points to its parent, every kept one to itself: the root of a
    # node in that forest is its nearest kept ancestor (or itself)
    kept_ancestor = _pointer_jump_root(np.where(gone, parent, np.arange(parent.size)))
    index = np.flatnonzero(~gone)
    new = np.full(parent.size, -1, dtype=np.int64)
    new[index] = np.arange(index.size)
    up = parent[index]
    return np.where(up >= 0, new[kept_ancestor[np.maximum(up, 0)]], -1), index


def segment_lengths(parent, position) -> np.ndarray:
    """Length of every segment.

    Parameters
    ----------
    parent : int64 (node,)
    position : float64 (node, 3), metres

    Returns
    -------
    float64 (node,)
        Distance from every node to its parent, metres; 0 at inlets.
    """
    parent = _parent_array(parent)
    position = np.asarray(position, dtype=float)
    length = np.zeros(parent.size)
    seg = np.flatnonzero(parent >= 0)
    length[seg] = np.linalg.norm(position[seg] - position[parent[seg]], axis=-1)
    return length


# --------------------------------------------------------------------------- orders


def strahler_orders(parent, kind) -> np.ndarray:
    """Conventional Strahler order of every segment.

    Terminal segments have order 1; at a branching node, the parent segment has order
    n + 1 if the two highest daughter orders are both n, else the highest daughter order
    (for a bifurcation: n + 1 if both daughters have order n). An inlet's child segments
    are ordinary segments. Multifurcations (contracted trees) are accepted.

    Parameters
    ----------
    parent : int64 (node,)
    kind : int8 (node,)

    Returns
    -------
    int64 (node,)
        Order of the segment ending at each node; 0 at inlets (no segment).

    Examples
    --------
    >>> strahler_orders([-1, 0, 1, 1], [0, 1, 2, 2]).tolist()
    [0, 2, 1, 1]
    """
    parent = _parent_array(parent)
    check_tree_arrays(parent, kind, multifurcations=True)
    start, child = _child_lists(parent)
    start, child = start.tolist(), child.tolist()
    kinds = np.asarray(kind).tolist()
    order = [0] * parent.size
    # Children before parents; a plain loop on Python lists beats per-level NumPy
    # passes on deep (caterpillar-like) trees and costs ~1 us per node.
    for v in reversed(topological_order(parent).tolist()):
        k = kinds[v]
        if k == KIND_TERMINAL:
            order[v] = 1
        elif k == KIND_BIFURCATION:
            top = second = 0
            for c in child[start[v] : start[v + 1]]:
                o = order[c]
                if o > top:
                    top, second = o, top
                elif o > second:
                    second = o
            order[v] = top + 1 if second == top else top
    return np.array(order, dtype=np.int64)


def _dds_pass(diameter: np.ndarray, order: np.ndarray) -> np.ndarray:
    """One range reassignment of diameter-defined orders (segments only, no fillers)."""
    labels, inv = np.unique(order, return_inverse=True)
    if labels.size < 2:
        return order.copy()
    count = np.bincount(inv)
    mean = np.bincount(inv, weights=diameter) / count
    ss = np.bincount(inv, weights=(diameter - mean[inv]) ** 2)
    sd = np.sqrt(ss / np.maximum(count - 1, 1))  # sample SD; 0 for a single-segment order
    bounds = ((mean[:-1] + sd[:-1]) + (mean[1:] - sd[1:])) / 2
    bounds = np.maximum.accumulate(bounds)  # non-monotone bounds: the squeezed order empties
    # order k holds bounds[k-1] < D <= bounds[k]
    return labels[np.searchsorted(bounds, diameter, side="left")]


class DDSResult(NamedTuple):
    """Result of :func:`diameter_defined_strahler`.

    Attributes
    ----------
    orders : int64 (node,)
        Diameter-defined order of every segment, 1..M; 0 at inlets.
    n_iter : int
        Reassignment passes performed.
    converged : bool
        True when the last pass changed fewer than ``tol`` of the segments.
    changed : float64 (n_iter,)
        Fraction of segments that changed order in each pass.
    """

    orders: np.ndarray
    n_iter: int
    converged: bool
    changed: np.ndarray


def diameter_defined_strahler(parent, radius, kind, max_iter: int = 100, tol: float = 0.01, initial=None) -> DDSResult:
    """Diameter-defined Strahler orders (Jiang, Kassab & Fung 1994).

    Parameters
    ----------
    parent : int64 (node,)
    radius : float64 (node,)
        Segment radii, metres (the orders are scale-free; any unit works).
    kind : int8 (node,)
    max_iter : int
        Maximum number of reassignment passes (>= 1).
    tol : float
        Stop when the fraction of segments changing order in a pass is below this
        (SPEC: 1 %).
    initial : int (node,), optional
        Starting orders; default the conventional Strahler orders.

    Returns
    -------
    DDSResult
        ``orders`` int64 (node,) (0 at inlets), ``n_iter``, ``converged``, ``changed``.
        See the module docstring for the edge-case rules (single-segment orders,
        non-monotone bounds, emptied orders).

    Examples
    --------
    >>> res = diameter_defined_strahler([-1, 0, 1, 1], [0, 2.0, 1.0, 1.0], [0, 1, 2, 2])
    >>> res.orders.tolist(), res.n_iter, res.converged
    ([0, 2, 1, 1], 1, True)
    """
    parent = _parent_array(parent)
    check_tree_arrays(parent, kind, radius=radius, multifurcations=True)
    if max_iter < 1:
        raise ValueError(f"max_iter: must be >= 1, got {max_iter}")
    if not 0 <= tol <= 1:
        raise ValueError(f"tol: must be a fraction in [0, 1], got {tol}")
    seg = np.flatnonzero(parent >= 0)
    diameter = 2.0 * np.asarray(radius, dtype=float)[seg]
    start = strahler_orders(parent, kind) if initial is None else np.asarray(initial, dtype=np.int64)
    if start.shape != parent.shape:
        raise ValueError(f"initial: expected shape {parent.shape} like parent, got {start.shape}")
    order = start[seg]
    changed = []
    converged = False
    for _ in range(max_iter):
        new = _dds_pass(diameter, order)
        changed.append(np.count_nonzero(new != order) / max(order.size, 1))
        order = new
        if changed[-1] < tol:
            converged = True
            break
    out = np.zeros(parent.size, dtype=np.int64)
    out[seg] = np.unique(order, return_inverse=True)[1].reshape(-1) + 1  # renumber 1..M
    return DDSResult(out, len(changed), converged, np.array(changed))


def shift_orders(orders, top: int = TOP_ORDER, mask=None) -> np.ndarray:
    """Shift orders so that the highest equals ``top``.

    Parameters
    ----------
    orders : int (node,) or (k,)
        Orders, e.g. from :func:`strahler_orders` (0 at inlets).
    top : int
        Target highest order (11: Kassab's coronary trunk).
    mask : bool array like ``orders``, optional
        Entries to shift; default ``orders > 0`` (leaves the inlets' 0 filler alone).

    Returns
    -------
    int64, shape of ``orders``
        Shifted copy. With trees deeper than ``top`` orders the lowest shifted orders
        are <= 0; they are kept (and match no Kassab order).

    Examples
    --------
    >>> shift_orders([0, 1, 2, 3]).tolist()
    [0, 9, 10, 11]
    """
    orders = np.asarray(orders, dtype=np.int64)
    mask = orders > 0 if mask is None else np.asarray(mask, dtype=bool)
    out = orders.copy()
    if mask.any():
        out[mask] += int(top) - int(orders[mask].max())
    return out


# --------------------------------------------------------------------------- elements


class Elements(NamedTuple):
    """Elements of a tree (result of :func:`elements`); ``n_el`` elements.

    Attributes
    ----------
    segment_element : int64 (node,)
        Element id of every segment, -1 at inlets. Ids are 0..n_el-1, in increasing
        node index of the element's head.
    order : int64 (n_el,)
        Order of the element (of all its segments).
    diameter : float64 (n_el,)
        Mean diameter of its segments (units of the input).
    length : float64 (n_el,)
        Summed length of its segments (units of the input).
    n_segments : int64 (n_el,)
        Number of segments.
    head : int64 (n_el,)
        Most proximal segment (its node index).
    parent_element : int64 (n_el,)
        Element of the head's parent segment; -1 when the head hangs from an inlet.
    """

    segment_element: np.ndarray
    order: np.ndarray
    diameter: np.ndarray
    length: np.ndarray
    n_segments: np.ndarray
    head: np.ndarray
    parent_element: np.ndarray


def elements(parent, orders, diameter, length) -> Elements:
    """Group segments into elements: maximal series runs of same-order segments.

    Parameters
    ----------
    parent : int64 (node,)
    orders : int (node,)
        Order of every segment (inlet entries are ignored).
    diameter : float64 (node,)
        Segment diameters (2 * radius), metres.
    length : float64 (node,)
        Segment lengths, metres (:func:`segment_lengths`).

    Returns
    -------
    Elements
        A segment continues its parent segment's element when both have the same order;
        if both daughters qualify, the wider one (ties: lower node index) continues and
        the other starts a new element.

    Examples
    --------
    >>> el = elements([-1, 0, 1, 1], [0, 1, 1, 1], [0, 3.0, 2.0, 1.0], [0, 1.0, 1.0, 1.0])
    >>> el.segment_element.tolist(), el.diameter.tolist(), el.length.tolist()
    ([-1, 0, 0, 1], [2.5, 1.0], [2.0, 1.0])
    """
    parent = _parent_array(parent)
    orders = np.asarray(orders, dtype=np.int64)
    diameter = np.asarray(diameter, dtype=float)
    length = np.asarray(length, dtype=float)
    n = parent.size
    for name, arr in (("orders", orders), ("diameter", diameter), ("length", length)):
        if arr.shape != (n,):
            raise ValueError(f"{name}: expected shape ({n},) like parent, got {arr.shape}")
    seg = np.flatnonzero(parent >= 0)
    # candidates: segments whose parent node is itself a segment of the same order
    s = seg[parent[parent[seg]] >= 0]
    s = s[orders[s] == orders[parent[s]]]
    p = parent[s]
    rank = np.lexsort((s, -diameter[s], p))  # per parent: widest first, then lowest index
    s, p = s[rank], p[rank]
    first = np.ones(s.size, dtype=bool)
    first[1:] = p[1:] != p[:-1]
    cont = s[first]
    link = np.arange(n)
    link[cont] = parent[cont]
    head_of = _pointer_jump_root(link)
    head, eid = np.unique(head_of[seg], return_inverse=True)
    eid = eid.reshape(-1)
    segment_element = np.full(n, -1, dtype=np.int64)
    segment_element[seg] = eid
    n_segments = np.bincount(eid, minlength=head.size)
    el_diameter = np.bincount(eid, weights=diameter[seg], minlength=head.size) / n_segments
    el_length = np.bincount(eid, weights=length[seg], minlength=head.size)
    up = parent[head]
    parent_element = np.where(up >= 0, segment_element[np.maximum(up, 0)], -1)
    return Elements(
        segment_element,
        orders[head].copy(),
        el_diameter,
        el_length,
        n_segments.astype(np.int64),
        head.astype(np.int64),
        parent_element,
    )


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
    max_iter, tol
        Passed to :func:`diameter_defined_strahler`.
    min_segment_length : float
        Segments between branch points shorter than this (metres) are contracted before
        ordering (:func:`contract_short_segments`; 0 keeps the tree as it is).

    Returns
    -------
    xarray.Dataset
        Dims ``scheme`` ("diameter_defined", "strahler"), ``order`` (contiguous, union
        of both schemes; NaN / 0 where a scheme has no vessel) and ``node``.
        Per (scheme, order): the variables of :func:`order_statistics` and
        :func:`asymmetry_statistics`. Per scheme: ``order_shift`` (added to the raw
        orders) and ``n_elements``. Per (scheme, node): ``segment_order`` (shifted; 0 at
        inlets and contracted segments) and ``element_id`` (-1 there). Per node:
        ``segment_diameter`` and ``segment_length`` (m, 0 at inlets). Attrs:
        ``dds_iterations``, ``dds_changed_fraction``, ``dds_converged`` (0/1, netCDF-safe),
        ``dds_tol``, ``n_inlets``, ``n_terminals``, ``n_segments`` (after contraction),
        ``n_contracted_segments``, ``min_segment_length``, ``top_order`` (-1 when
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
    full_diameter = np.where(full_parent >= 0, 2.0 * np.asarray(radius, dtype=float), 0.0)
    full_length = segment_lengths(full_parent, position)
    parent, kept = contract_short_segments(full_parent, position, kind, min_segment_length)
    radius = np.asarray(radius, dtype=float)[kept]
    kind = np.asarray(kind)[kept]
    seg = np.flatnonzero(parent >= 0)
    diameter = full_diameter[kept]
    length = segment_lengths(parent, np.asarray(position, dtype=float)[kept])
    dds = diameter_defined_strahler(parent, radius, kind, max_iter=max_iter, tol=tol)
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
        n_contracted_segments=int(full_parent.size - kept.size),
        min_segment_length=float(min_segment_length),
        top_order=-1 if top is None else int(top),
        ordering="diameter_defined: Jiang, Kassab & Fung 1994 range reassignment (see vasc_pipeline.morphometry); "
        "strahler: conventional Strahler",
    )
    return ds


def compare_with_kassab(
    ds: xr.Dataset,
    artery: str,
    *,
    scheme: str = "diameter_defined",
    level: str = "element",
    reference: xr.Dataset | None = None,
) -> pd.DataFrame:
    """Model against Kassab 1993: mean diameter and length per order.

    Parameters
    ----------
    ds : xarray.Dataset
        From :func:`morphometry` (orders shifted to 11), with or without the ``scheme``
        dim.
    artery : {"RCA", "LAD", "LCX"}
    scheme : {"diameter_defined", "strahler"}
        Used when ``ds`` has a ``scheme`` dim.
    level : {"element", "segment"}
    reference : xarray.Dataset, optional
        Default :func:`vasc_pipeline.reference.kassab_dataset`.

    Returns
    -------
    pandas.DataFrame
        Index ``order`` (union of model and Kassab orders). Columns ``model_diameter``,
        ``kassab_diameter``, ``diameter_log10_ratio`` (log10 model/Kassab), the same for
        ``length`` (metres), ``model_count``, ``kassab_count``. ``attrs`` hold
        ``mean_abs_log10_ratio_diameter``, ``mean_abs_log10_ratio_length`` (over the
        orders present in both, NaN if none), their mean ``mean_abs_log10_ratio``,
        ``n_orders_compared``, ``artery``, ``scheme`` and ``level``.
    """
    if reference is None:
        from .reference import kassab_dataset

        reference = kassab_dataset()
    if artery not in reference.artery.values:
        raise ValueError(f"artery: {artery!r} is not one of {list(reference.artery.values)}")
    if level not in ("element", "segment"):
        raise ValueError(f"level: {level!r} is not 'element' or 'segment'")
    if "scheme" in ds.dims:
        if scheme not in ds.scheme.values:
            raise ValueError(f"scheme: {scheme!r} is not one of {list(ds.scheme.values)}")
        ds = ds.sel(scheme=scheme)
    ref = reference.sel(artery=artery, level=level)
    model = pd.DataFrame(
        {
            "model_diameter": ds[f"{level}_diameter_mean"].to_series(),
            "model_length": ds[f"{level}_length_mean"].to_series(),
            "model_count": ds[f"{level}_count"].to_series(),
        }
    )
    model = model[model.model_count > 0]
    kassab = pd.DataFrame(
        {
            "kassab_diameter": ref.D_mean.to_series(),
            "kassab_length": ref.L_mean.to_series(),
            "kassab_count": ref.D_n.to_series(),
        }
    )
    kassab = kassab[kassab.kassab_count > 0]
    table = model.join(kassab, how="outer").sort_index()
    table.index = table.index.astype(np.int64)
    table.index.name = "order"
    table["model_count"] = table.model_count.fillna(0).astype(np.int64)
    table["kassab_count"] = table.kassab_count.fillna(0).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        table["diameter_log10_ratio"] = np.log10(table.model_diameter / table.kassab_diameter)
        table["length_log10_ratio"] = np.log10(table.model_length / table.kassab_length)
    table = table[
        [
            "model_diameter",
            "kassab_diameter",
            "diameter_log10_ratio",
            "model_length",
            "kassab_length",
            "length_log10_ratio",
            "model_count",
            "kassab_count",
        ]
    ]
    both = (table.model_count > 0) & (table.kassab_count > 0)
    mad = float(table.diameter_log10_ratio[both].abs().mean()) if both.any() else float("nan")
    mal = float(table.length_log10_ratio[both].abs().mean()) if both.any() else float("nan")
    table.attrs.update(
        mean_abs_log10_ratio_diameter=mad,
        mean_abs_log10_ratio_length=mal,
        mean_abs_log10_ratio=(mad + mal) / 2,
        n_orders_compared=int(both.sum()),
        artery=artery,
        scheme=scheme,
        level=level,
    )
    return table
