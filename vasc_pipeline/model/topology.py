"""Parent-array topology of a tree or forest: checks, depth, order, children, lengths.

The home of the tree helpers every stage shares (NumPy only, no numba). Tree arrays as a run
store holds them:

- ``parent``   int64 (node,)     parent node, -1 at inlets
- ``position`` float64 (node, 3) metres
- ``radius``   float64 (node,)   radius of the segment from the node to its parent, metres
- ``kind``     int8 (node,)      0 inlet, 1 bifurcation, 2 terminal, 3 pass-through (the whole
                                 tree's annealed terminals: one child)

A segment is identified by its child node, so per-segment arrays are indexed by node and
hold a filler at inlets (0 for lengths). Several inlets make a forest; every function
handles all trees at once (use :func:`select_trees` for one artery's tree).

Nodes may be numbered in any order (the anneal's layout puts bifurcations after
terminals); a topological order is computed by pointer jumping, never by recursion, so
trees of any depth work, in O(n log n).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "KIND_INLET",
    "KIND_BIFURCATION",
    "KIND_TERMINAL",
    "KIND_TERRITORY_ROOT",
    "MIN_SEGMENT_LENGTH",
    "check_tree_arrays",
    "children_of",
    "node_depth",
    "topological_order",
    "path_sums",
    "inlet_of",
    "select_trees",
    "kept_tree",
    "contract_short_segments",
    "segment_lengths",
    "terminals_downstream",
]

KIND_INLET, KIND_BIFURCATION, KIND_TERMINAL = 0, 1, 2
# A pass-through node: one child, whose segment continues the node's own vessel (same radius and
# flow). The whole tree's annealed terminals, each the root of its territory's subtree
# (vasc_pipeline.engine.extend), are such nodes: no branch point, so no vessel ends there.
KIND_TERRITORY_ROOT = 3
# m: shorter segments between branch points are contracted. Below the radius of every vessel
# of the heart's trees (33 um at N = 6000), above what the final polish leaves where a branch
# point's optimum is its parent's (up to ~6 um; measured, see vasc_pipeline.reduce.morphometry).
MIN_SEGMENT_LENGTH = 1e-5


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


def path_sums(parent, weight, start=0.0) -> np.ndarray:
    """Values summed along the paths from the inlets: ``s[v] = s[parent[v]] + weight[v]``.

    Parameters
    ----------
    parent : int64 (node,)
    weight : float64 (node,)
        Added at every node (ignored at inlets).
    start : float or float64 (node,)
        The value at the inlets.

    Returns
    -------
    float64 (node,)
        One addition per node, parents first, a level of the tree at a time: a tree of any
        size in as many NumPy steps as it is deep.

    Examples
    --------
    >>> path_sums([-1, 0, 1, 1], [0.0, 1.0, 2.0, 3.0], 10.0).tolist()
    [10.0, 11.0, 13.0, 14.0]
    """
    parent = _parent_array(parent)
    weight = np.asarray(weight, dtype=float)
    out = np.zeros(parent.size)
    out[parent < 0] = np.broadcast_to(np.asarray(start, dtype=float), parent.shape)[parent < 0]
    for level in _levels(parent):
        out[level] = out[parent[level]] + weight[level]
    return out


def _levels(parent: np.ndarray) -> list[np.ndarray]:
    """The non-inlet nodes by depth (1, 2, ...), each level in increasing node order: a pass over
    a tree from its inlets (or toward them, reversed) in as many NumPy steps as it is deep."""
    depth = node_depth(parent)
    order = np.argsort(depth, kind="stable")
    bounds = np.searchsorted(depth[order], np.arange(1, int(depth.max(initial=0)) + 2)).tolist()
    return [order[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]


# The numpydoc blocks here repeat one another (parent, the shapes returned) on purpose: each
# public helper documents its own arguments.
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
        2 terminal (no children), 3 pass-through (:data:`KIND_TERRITORY_ROOT`: one child,
        which is no pass-through node itself).
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
    if not np.isin(kind, (KIND_INLET, KIND_BIFURCATION, KIND_TERMINAL, KIND_TERRITORY_ROOT)).all():
        raise ValueError("kind: accepted values are 0 (inlet), 1 (bifurcation), 2 (terminal), 3 (pass-through)")
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
    expected = np.choose(kind.astype(np.int64), (1, 2, 0, 1))
    through = kind == KIND_TERRITORY_ROOT
    bad = (
        ((n_children < expected) | ((kind == KIND_TERMINAL) & (n_children > 0)) | (through & (n_children != 1)))
        if multifurcations
        else n_children != expected
    )
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        need = "at least 1, a branching node at least 2" if multifurcations else "1, a bifurcation 2"
        raise ValueError(
            f"parent/kind: node {i} of kind {int(kind[i])} has {int(n_children[i])} children; an "
            f"inlet needs {need}, a pass-through node 1, a terminal 0"
        )
    chained = through & (parent >= 0) & through[np.maximum(parent, 0)]
    if chained.any():  # a vessel through two pass-through nodes: its length would need the whole path
        i = int(np.flatnonzero(chained)[0])
        raise ValueError(f"parent/kind: pass-through node {i} hangs from pass-through node {int(parent[i])}")
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
    return (
        kept_tree(parent, index),
        np.asarray(position)[index],
        np.asarray(radius)[index],
        np.asarray(kind)[index],
        index,
    )


def kept_tree(parent, index) -> np.ndarray:
    """The parent array of the nodes ``index`` (increasing; every kept node's parent kept too),
    renumbered 0.. in that order: a top part of a tree, or whole trees of a forest."""
    parent = _parent_array(parent)
    index = np.asarray(index, dtype=np.int64)
    new = np.full(parent.size, -1, dtype=np.int64)
    new[index] = np.arange(index.size)
    return np.where(parent[index] >= 0, new[np.maximum(parent[index], 0)], -1)


def contract_short_segments(parent, position, kind, min_length: float = MIN_SEGMENT_LENGTH, length=None):
    """Merge every branching node that sits on its parent node into that parent, and every
    pass-through node (kind 3) into its vessel.

    Parameters
    ----------
    parent : int64 (node,)
    position : float64 (node, 3), metres
    kind : int8 (node,)
    min_length : float
        Segments shorter than this (metres, >= 0) whose child is a branching node
        (kind 1) are contracted; 0 contracts none of them (pass-through nodes still go).
    length : float64 (node,), optional
        The length of the vessel ending at each node (metres); default the distance to its
        parent. A segment below a pass-through node is as long as its vessel from the branch
        point above: give that length here, or such a vessel may be taken for a short one.

    Returns
    -------
    parent : int64 (node_kept,)
        Parent array of the contracted tree over the kept nodes (renumbered; nodes keep
        their relative order). A node may now have more than two children; a pass-through
        node's child hangs from the branch point above it.
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
    kind = np.asarray(kind)
    length = segment_lengths(parent, position) if length is None else np.asarray(length, dtype=float)
    short = (kind == KIND_BIFURCATION) & (length < min_length)
    gone = (parent >= 0) & (short | (kind == KIND_TERRITORY_ROOT))
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


def terminals_downstream(parent, kind) -> np.ndarray:
    """int64 (node,) number of terminals downstream of every node (1 at terminals; an inlet counts its tree).

    Raises
    ------
    ValueError
        If the parent array is not a forest (bad index or a cycle).
    """
    parent = _parent_array(parent)
    count = (np.asarray(kind) == KIND_TERMINAL).astype(np.int64)
    for level in reversed(_levels(parent)):  # deepest first: each node adds its (finished) count to its parent's
        np.add.at(count, parent[level], count[level])
    return count
