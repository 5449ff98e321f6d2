"""How alike two trees are: their main trunks' centre-lines and the mean distance between them.

Also the trunks' :func:`tortuosity` (the paper's "meandering trunks" at small m_b, a number).
The paper's consistency claim ("trees become similar as steps grow, with a main diagonal
artery") made a number: per inlet, the main trunk runs from the inlet down the child that
carries more terminals, while that child still carries at least ``fraction`` of the inlet's
terminals. Two trunks are compared by the symmetric mean distance of equally spaced points
on each to the other polyline. NumPy only; positions in metres.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..model.topology import terminals_downstream

__all__ = [
    "TRUNK_FRACTION",
    "TRUNK_POINTS",
    "main_trunks",
    "resample_polyline",
    "trunk_distance",
    "trunk_spread",
    "tortuosity",
]

TRUNK_FRACTION = 1.0 / 8.0  # the trunk ends where its larger branch carries less of the inlet's terminals
TRUNK_POINTS = 64  # points per resampled trunk


# Its Parameters block repeats topology.py's for the tree arrays on purpose: numpydoc documents
# them at every public function that takes them.
def main_trunks(parent, position, kind, fraction: float = TRUNK_FRACTION) -> list[np.ndarray]:
    """Per inlet (in node order), the main trunk's centre-line, float64 (M, 3).

    Parameters
    ----------
    parent : int64 (node,)
    position : float64 (node, 3), metres
    kind : int8 (node,)
    fraction : float
        The trunk follows the child with more terminals (ties: the lower node index) while
        it carries at least this fraction of the inlet's terminals; the inlet's own segment
        is always part of it.

    Examples
    --------
    >>> [t.tolist() for t in main_trunks([-1, 0, 1, 1, 3, 3], [[0, 0, 0], [1, 0, 0], [1, 1, 0],
    ...                                   [2, 0, 0], [3, 0, 0], [2, -1, 0]], [0, 1, 2, 1, 2, 2], 0.5)]
    [[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]]
    """
    parent = np.asarray(parent, dtype=np.int64)
    position = np.asarray(position, dtype=float)
    n_down = terminals_downstream(parent, kind)
    order = np.lexsort((np.arange(parent.size), -n_down))  # most terminals first, then lowest index
    best_child = np.full(parent.size, -1, dtype=np.int64)
    for c in order[::-1]:  # the last write per parent is its first child in that order
        if parent[c] >= 0:
            best_child[parent[c]] = c
    out = []
    for inlet in np.flatnonzero(parent < 0):
        path, node = [inlet], inlet
        while best_child[node] >= 0:
            nxt = best_child[node]
            if len(path) > 1 and n_down[nxt] < fraction * n_down[inlet]:
                break
            path.append(nxt)
            node = nxt
        out.append(position[path])
    return out


def resample_polyline(line, m: int = TRUNK_POINTS) -> np.ndarray:
    """``m`` points equally spaced by arc length along a polyline (M, 3)."""
    line = np.asarray(line, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
    if s[-1] == 0.0:
        return np.repeat(line[:1], m, axis=0)
    t = np.linspace(0.0, s[-1], m)
    return np.stack([np.interp(t, s, line[:, c]) for c in range(line.shape[1])], axis=1)


def tortuosity(line) -> float:
    """Arc length over chord of a centre-line (1: straight; the paper's "meandering" trunks are > 1).

    >>> tortuosity([[0, 0, 0], [1, 1, 0], [2, 0, 0]])
    1.4142135623730951
    """
    line = np.asarray(line, dtype=float)
    chord = float(np.linalg.norm(line[-1] - line[0]))
    arc = float(np.sum(np.linalg.norm(np.diff(line, axis=0), axis=1)))
    return arc / chord if chord > 0.0 else float("nan")


def _distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    a, b = line[:-1], line[1:]
    if len(a) == 0:
        return np.linalg.norm(points - line[0], axis=1)
    e = b - a
    ee = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    d = points[:, None, :] - a[None]
    t = np.clip(np.einsum("pij,ij->pi", d, e) / ee, 0.0, 1.0)
    return np.min(np.linalg.norm(d - t[..., None] * e[None], axis=2), axis=1)


def trunk_distance(a, b, m: int = TRUNK_POINTS) -> float:
    """Symmetric mean distance [m] between two centre-lines: m points on each, to the other.

    >>> trunk_distance([[0, 0, 0], [1, 0, 0]], [[0, 0.5, 0], [1, 0.5, 0]])
    0.5
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    there = np.mean(_distance_to_polyline(resample_polyline(a, m), b))
    back = np.mean(_distance_to_polyline(resample_polyline(b, m), a))
    return float(0.5 * (there + back))


def trunk_spread(trunks_per_tree: list[list[np.ndarray]], m: int = TRUNK_POINTS) -> np.ndarray:
    """Per pair of trees, the trunk distance averaged over the inlets, float64 (pairs,).

    ``trunks_per_tree``: one :func:`main_trunks` list per tree (same inlets in the same order).
    """
    return np.array(
        [
            np.mean([trunk_distance(ta, tb, m) for ta, tb in zip(a, b, strict=True)])
            for a, b in itertools.combinations(trunks_per_tree, 2)
        ]
    )
