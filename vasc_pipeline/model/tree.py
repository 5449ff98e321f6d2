"""The tree as flat arrays: layout, random initialisation, invariants.

Node layout (fixed for a run): inlets ``[0, K)``, terminals ``[K, K + N)``, bifurcations
``[K + N, 2N)``; 2N nodes in all. Every non-inlet node has one parent; a segment is
identified by its child node (the vessel from a node to its parent), so per-segment arrays
are indexed by node and hold 0 at inlets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import rng as _rng
from .tissue import Tissue
from .topology import KIND_BIFURCATION, KIND_INLET, KIND_TERMINAL, children_of, terminals_downstream

__all__ = [
    "KIND_INLET",
    "KIND_BIFURCATION",
    "KIND_TERMINAL",
    "Tree",
    "node_kinds",
    "random_tree",
    "inlet_counts",
    "tree_from_arrays",
    "inlet_count_bounds",
    "nearest_inlets",
    "count_terminals",
    "check_tree",
    "load_terminal_sites",
    "TreeError",
]


class TreeError(ValueError):
    """A tree that breaks an invariant, or bad terminal-site input."""


@dataclass
class Tree:
    """Topology and geometry of a tree (the mutable part of the anneal state).

    Attributes
    ----------
    parent : int64 (2N,)        parent node, -1 at inlets
    children : int64 (2N, 2)    child nodes, -1 where absent (inlets use slot 0 only)
    position : float64 (2N, 3)  [x, y, z] in metres
    n_downstream : int64 (2N,)  terminals downstream of the node (its segment's n)
    n_inlets : int              K
    """

    parent: np.ndarray
    children: np.ndarray
    position: np.ndarray
    n_downstream: np.ndarray
    n_inlets: int

    @property
    def n_nodes(self) -> int:
        return self.parent.size

    @property
    def n_terminals(self) -> int:
        return self.parent.size // 2

    @property
    def kind(self) -> np.ndarray:
        return node_kinds(self.n_terminals, self.n_inlets)

    def copy(self) -> "Tree":
        return Tree(
            self.parent.copy(), self.children.copy(), self.position.copy(), self.n_downstream.copy(), self.n_inlets
        )


def node_kinds(n_terminals: int, n_inlets: int) -> np.ndarray:
    """int8 (2N,) node kinds in the fixed layout."""
    kind = np.full(2 * n_terminals, KIND_BIFURCATION, dtype=np.int8)
    kind[:n_inlets] = KIND_INLET
    kind[n_inlets : n_inlets + n_terminals] = KIND_TERMINAL
    return kind


def children_from_parent(parent: np.ndarray) -> np.ndarray:
    """(2N, 2) child table from a parent array, children in increasing index order."""
    try:
        return children_of(parent)
    except ValueError as exc:
        raise TreeError(str(exc)) from exc


def count_terminals(parent: np.ndarray, n_terminals: int, n_inlets: int) -> np.ndarray:
    """Terminals downstream of every node, recounted from ``parent`` alone."""
    try:
        return terminals_downstream(parent, node_kinds(n_terminals, n_inlets))
    except ValueError as exc:  # a cycle, or an index out of range
        raise TreeError(str(exc)) from exc


def tree_from_arrays(parent: np.ndarray, position: np.ndarray, n_inlets: int | None = None) -> Tree:
    """A :class:`~vasc_pipeline.model.tree.Tree` from a run store's ``parent`` and ``position`` arrays
    (inlets first, then the N terminals, then the bifurcations)."""
    parent = np.asarray(parent, dtype=np.int64)
    k = int(np.count_nonzero(parent < 0)) if n_inlets is None else int(n_inlets)
    n = parent.size // 2  # K inlets + N terminals + (N - K) bifurcations
    return Tree(
        parent, children_from_parent(parent), np.asarray(position, dtype=np.float64), count_terminals(parent, n, k), k
    )


def random_terminal_sites(tissue: Tissue, n_terminals: int, state: np.ndarray) -> np.ndarray:
    """Uniform random points in the tissue: a random tissue voxel, then a uniform offset in it."""
    voxels = np.flatnonzero(tissue.mask.reshape(-1))
    return sites_in_voxels(voxels, tissue.shape, tissue.origin, tissue.voxel_size, tissue.ndim, n_terminals, state)


def sites_in_voxels(voxels, shape, origin, voxel_size: float, ndim: int, n: int, state: np.ndarray) -> np.ndarray:
    """float64 (n, 3) uniform random points [m] in a set of voxels of a grid (four uniforms a point).

    ``voxels``: flat (z, y, x) indices into a grid of ``shape`` whose voxel [0, 0, 0] is centred
    at ``origin`` [m]; a point is a random voxel of the set, then a uniform offset in it (none
    in z when ``ndim`` is 2). The draw of :func:`random_terminal_sites`, for any voxel set.
    """
    u = np.empty((n, 4))
    _rng.fill_uniform(state, u)
    pick = voxels[np.minimum((u[:, 0] * voxels.size).astype(np.int64), voxels.size - 1)]
    z, y, x = np.unravel_index(pick, shape)
    centre = origin + voxel_size * np.stack([x, y, z], axis=1)
    offset = (u[:, 1:] - 0.5) * voxel_size
    if ndim == 2:
        offset[:, 2] = 0.0
    return centre + offset


def random_tree(
    tissue: Tissue,
    n_terminals: int,
    state: np.ndarray,
    sites: np.ndarray | None = None,
    inlet_share: list[float] | None = None,
    inlet_assignment: str = "random",
) -> Tree:
    """Random initial tree (the paper's starting point).

    Terminals uniformly at random in the tissue (or at ``sites``), each assigned to a
    uniformly random inlet (every inlet gets at least one), a random topology per inlet
    by repeatedly joining two random subtrees, each bifurcation placed at the mean of its
    children. All randomness comes from ``state`` (advanced in place). With
    ``inlet_share`` (one fraction per inlet) inlet k gets :func:`inlet_counts` terminals,
    a random set of them. ``inlet_assignment="nearest"`` assigns the terminals by distance
    instead (:func:`nearest_inlets`, keeping those counts when ``inlet_share`` is given).
    """
    n_inlets = len(tissue.inlets)
    if n_terminals < max(2, n_inlets):
        raise TreeError(f"n_terminals must be >= max(2, number of inlets = {n_inlets}), got {n_terminals}")
    m = 2 * n_terminals
    parent = np.full(m, -1, dtype=np.int64)
    position = np.zeros((m, 3), dtype=np.float64)
    position[:n_inlets] = tissue.inlets
    terminals = np.arange(n_inlets, n_inlets + n_terminals)
    position[terminals] = random_terminal_sites(tissue, n_terminals, state) if sites is None else sites
    # Inlet of each terminal: the first K terminals (in random order) seed one inlet each.
    order = terminals.copy()
    for i in range(order.size - 1, 0, -1):  # Fisher-Yates with the run's generator
        j = _rng.next_below(state, i + 1)
        order[i], order[j] = order[j], order[i]
    inlet_of = np.empty(n_terminals, dtype=np.int64)
    if inlet_assignment == "nearest":
        counts = None if inlet_share is None else inlet_counts(inlet_share, n_terminals)
        inlet_of[:] = nearest_inlets(position[terminals], position[:n_inlets], counts)
    elif inlet_share is not None:
        inlet_of[order - n_inlets] = np.repeat(np.arange(n_inlets), inlet_counts(inlet_share, n_terminals))
    else:
        inlet_of[order[:n_inlets] - n_inlets] = np.arange(n_inlets)
        for t in order[n_inlets:]:
            inlet_of[t - n_inlets] = _rng.next_below(state, n_inlets)
    next_bif = n_inlets + n_terminals
    for k in range(n_inlets):
        roots = list(terminals[inlet_of == k])
        while len(roots) > 1:
            i = _rng.next_below(state, len(roots))
            a = roots.pop(i)
            j = _rng.next_below(state, len(roots))
            b = roots.pop(j)
            parent[a] = parent[b] = next_bif
            position[next_bif] = 0.5 * (position[a] + position[b])
            roots.append(next_bif)
            next_bif += 1
        parent[roots[0]] = k
    children = children_from_parent(parent)
    return Tree(parent, children, position, count_terminals(parent, n_terminals, n_inlets), n_inlets)


def nearest_inlets(points: np.ndarray, inlets: np.ndarray, counts: np.ndarray | None = None) -> np.ndarray:
    """Inlet index of every point, by distance: its nearest inlet, or with ``counts`` exactly
    ``counts[k]`` points for inlet k.

    With counts, inlet k (in order) takes, among the points not yet taken, the ``counts[k]``
    whose distance to inlet k exceeds their distance to the nearest later inlet the least
    (for two inlets: the points split by a hyperboloid between them). Without counts, an
    inlet that is nobody's nearest takes its nearest point, so that every inlet feeds one.
    Deterministic: ties go to the lower point index.
    """
    dist = np.linalg.norm(points[:, None, :] - inlets[None, :, :], axis=2)
    n_inlets = len(inlets)
    if counts is None:
        owner = np.argmin(dist, axis=1)
        for k in range(n_inlets):
            if not np.any(owner == k):
                shared = np.flatnonzero(np.bincount(owner, minlength=n_inlets)[owner] > 1)
                owner[shared[np.argmin(dist[shared, k])]] = k
        return owner
    owner = np.full(len(points), n_inlets - 1, dtype=np.int64)
    free = np.arange(len(points))
    for k in range(n_inlets - 1):
        margin = dist[free, k] - dist[free][:, k + 1 :].min(axis=1)
        take = free[np.argsort(margin, kind="stable")[: counts[k]]]
        owner[take] = k
        free = np.setdiff1d(free, take)
    return owner


def inlet_counts(inlet_share, n_terminals: int) -> np.ndarray:
    """Terminals per inlet for the fractions ``inlet_share``: largest remainders, at least one each.

    >>> inlet_counts([0.62, 0.38], 1000).tolist()
    [620, 380]
    """
    share = np.asarray(inlet_share, dtype=float)
    if share.ndim != 1 or share.size < 1 or (share <= 0).any() or n_terminals < share.size:
        raise TreeError(f"inlet_share: {share.tolist()} needs one fraction > 0 per inlet and n_terminals >= that")
    exact = share / share.sum() * n_terminals
    counts = np.maximum(np.floor(exact).astype(np.int64), 1)
    for i in np.argsort(-(exact - np.floor(exact)), kind="stable"):  # hand out what rounding left
        if counts.sum() >= n_terminals:
            break
        counts[i] += 1
    while counts.sum() > n_terminals:  # the minimum of one per inlet overshot
        counts[np.argmax(counts)] -= 1
    return counts


def inlet_count_bounds(inlet_share, tolerance: float | None, n_terminals: int) -> np.ndarray:
    """int64 (K, 2): the fewest and most terminals each inlet may feed when its share may stray
    ``tolerance`` from ``inlet_share`` (at least one, at most N - K + 1); shape (0, 2) when the
    share is free (no ``inlet_share``) or fixed (no ``tolerance``: :func:`inlet_counts` is kept).

    >>> inlet_count_bounds([0.62, 0.38], 0.1, 1000).tolist()
    [[520, 720], [280, 480]]
    """
    if inlet_share is None or tolerance is None:
        return np.zeros((0, 2), dtype=np.int64)
    share = np.asarray(inlet_share, dtype=float)
    k = share.size
    lo = np.clip(np.ceil((share - tolerance) * n_terminals - 1e-9), 1, n_terminals - k + 1)
    hi = np.clip(np.floor((share + tolerance) * n_terminals + 1e-9), 1, n_terminals - k + 1)
    return np.stack([lo, hi], axis=1).astype(np.int64)


def check_tree(tree: Tree, tissue: Tissue | None = None) -> None:
    """Raise :class:`TreeError` unless every structural invariant holds.

    Inlets have no parent and one child; bifurcations two children; terminals none; the
    child table mirrors ``parent``; every node reaches an inlet (no cycle); the stored
    downstream counts equal a recount. With ``tissue``: terminals lie in tissue and every
    node inside the grid's box (in the plane for a 2-D tissue).
    """
    n, k = tree.n_terminals, tree.n_inlets
    parent, kind = tree.parent, tree.kind
    if np.any(parent[:k] != -1):
        raise TreeError("an inlet has a parent")
    if np.any(parent[k:] < 0) or np.any(parent[k:] >= tree.n_nodes):
        raise TreeError("a non-inlet node has no valid parent")
    if np.any(kind[parent[k:]] == KIND_TERMINAL):
        raise TreeError("a terminal has a child")
    n_children = np.bincount(parent[k:], minlength=tree.n_nodes)
    expected = np.where(kind == KIND_INLET, 1, np.where(kind == KIND_BIFURCATION, 2, 0))
    bad = np.flatnonzero(n_children != expected)
    if bad.size:
        raise TreeError(f"node {bad[0]} (kind {kind[bad[0]]}) has {n_children[bad[0]]} children")
    if not np.array_equal(np.sort(tree.children, axis=1), np.sort(children_from_parent(parent), axis=1)):
        raise TreeError("child table does not mirror the parent array")
    counts = count_terminals(parent, n, k)  # raises on a cycle
    if not np.array_equal(counts, tree.n_downstream):
        node = np.flatnonzero(counts != tree.n_downstream)[0]
        raise TreeError(f"n_downstream[{node}] = {tree.n_downstream[node]} but {counts[node]} terminals are below it")
    if tissue is not None:
        term = tree.position[k : k + n]
        if not np.all(tissue.contains(term)):
            raise TreeError("a terminal lies outside the tissue")
        lo, hi = tissue.bounds
        if np.any(tree.position < lo - 1e-12) or np.any(tree.position > hi + 1e-12):
            raise TreeError("a node lies outside the voxel grid's box")


def load_terminal_sites(path: str, tissue: Tissue) -> np.ndarray:
    """Terminal sites from a CSV of x, y, z in metres (header optional), checked against the tissue."""
    import pandas as pd

    try:
        frame = pd.read_csv(path, comment="#")
        if not {"x", "y", "z"} <= set(frame.columns):
            frame = pd.read_csv(path, comment="#", header=None)
            if frame.shape[1] != 3:
                raise TreeError(f"terminals.path: {path!r} must have columns x, y, z (metres)")
            frame.columns = ["x", "y", "z"]
        sites = frame[["x", "y", "z"]].to_numpy(dtype=np.float64)
    except FileNotFoundError as exc:
        raise TreeError(f"terminals.path: file {path!r} does not exist") from exc
    except OSError as exc:  # a directory, no permission, ...
        raise TreeError(f"terminals.path: cannot read {path!r}: {exc.strerror or exc}") from exc
    except (ValueError, pd.errors.ParserError) as exc:
        raise TreeError(f"terminals.path: cannot read {path!r} as x, y, z in metres: {exc}") from exc
    if len(sites) < 2:
        raise TreeError(f"terminals.path: {path!r} holds {len(sites)} sites; at least 2 are needed")
    bad = np.flatnonzero(~np.isfinite(sites).all(axis=1))
    if bad.size:  # before the tissue test, which would call the site "outside" (and warn)
        raise TreeError(
            f"terminals.path: site {bad[0]} of {path!r} is {sites[bad[0]].tolist()}: every site needs three "
            f"finite coordinates x, y, z in metres ({bad.size} site(s) with a missing, NaN or infinite value)"
        )
    outside = np.flatnonzero(~tissue.contains(sites))
    if outside.size:
        raise TreeError(f"terminals.path: site {outside[0]} at {sites[outside[0]].tolist()} m lies outside the tissue")
    return sites


def check_duplicate_sites(sites: np.ndarray, path: str, fixed: bool) -> None:
    """Terminal sites given twice (the same x, y, z): refused for fixed terminals (two terminals
    would stay at one point), a warning otherwise (the anneal moves them apart)."""
    import warnings

    _, first, counts = np.unique(sites, axis=0, return_index=True, return_counts=True)
    if not (counts > 1).any():
        return
    k = int(first[np.argmax(counts > 1)])
    twin = int(np.flatnonzero((sites == sites[k]).all(axis=1))[1])
    text = (
        f"terminals.path: sites {k} and {twin} of {path!r} are the same point {sites[k].tolist()} m "
        f"({int((counts - 1).sum())} duplicate site(s) in all)"
    )
    if fixed:
        raise TreeError(f"{text}; with terminals.fixed=true they would stay at one point: remove the duplicates")
    warnings.warn(f"{text}; the anneal moves them apart (remove the duplicates to keep every site)", stacklevel=2)
