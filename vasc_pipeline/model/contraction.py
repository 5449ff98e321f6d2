"""The contracted problem of :mod:`vasc_pipeline.model.geometry`: clusters of nodes joined by
zero-length segments, which move as one, and the smooth objective over the free clusters with
its gradient, its tree-structured Hessian and their fill-in-free solve.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["Contraction", "node_levels", "objective", "gradient_hessian", "solve_spd", "spread"]

# --------------------------------------------------------------------------------------
# Tree bookkeeping


def node_levels(children: np.ndarray, roots: np.ndarray) -> list[np.ndarray]:
    """Nodes by depth below the roots (level 0 = roots), each level in breadth-first order.

    Not :func:`vasc_pipeline.model.topology.node_depth` grouped by depth: the order within a level
    fixes the order of the ``np.add.at`` sums in the geometry's ``_side_forces``, so results stay
    bit-identical with the trees this solver has always produced.
    """
    levels = []
    frontier = roots
    while frontier.size:
        levels.append(frontier)
        ch = children[frontier].ravel()
        frontier = ch[ch >= 0]
    return levels


class Contraction:
    """Clusters of nodes joined by zero-length ("collapsed") segments.

    A cluster is a connected subtree; its top node (the member whose own segment is not
    collapsed) represents it. A cluster holding an inlet or terminal is fixed.
    """

    def __init__(self, parent, levels, depth, fixed, collapsed):
        self.collapsed = collapsed
        self.fixed_node = fixed
        top = np.arange(parent.size)
        for lev in levels[1:]:  # parents before children
            top[lev] = np.where(collapsed[lev], top[parent[lev]], lev)
        self.top = top
        n_fixed = np.bincount(top, weights=fixed, minlength=parent.size)
        self.n_fixed = n_fixed
        tops = np.flatnonzero(top == np.arange(parent.size))
        free_tops = tops[n_fixed[tops] == 0]
        # Children-first order (deepest first): eliminating a cluster whose other
        # neighbours are already gone creates no fill-in in the tree-structured systems.
        self.free = free_tops[np.argsort(-depth[free_tops], kind="stable")]
        self.var = np.full(parent.size, -1, dtype=np.int64)
        self.var[self.free] = np.arange(self.free.size)
        # External segments: not collapsed; they join cluster a = i and b = top[parent[i]].
        seg = np.flatnonzero((parent >= 0) & ~collapsed)
        self.seg = seg
        self.a = seg
        self.b = top[parent[seg]]


def spread(x: np.ndarray, con: Contraction) -> None:
    """Every node takes its cluster's position: the fixed member's if it has one, else the top node's.

    A fixed cluster's top may be a bifurcation above its inlet or terminal (contracted
    while still a little apart); the fixed node must not move to it.
    """
    fixed = np.flatnonzero(con.fixed_node)
    x[con.top[fixed]] = x[fixed]
    x[:] = x[con.top]


# --------------------------------------------------------------------------------------
# Smooth objective of the contracted problem


def objective(x, con, w):
    d = x[con.a] - x[con.b]
    return float(np.sum(w[con.seg] * np.sqrt(np.einsum("ij,ij->i", d, d))))


def gradient_hessian(x, con, w, dim, with_hessian=True):
    """Gradient (n_free * dim,) and sparse Hessian of the contracted objective."""
    d = x[con.a] - x[con.b]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    ws = w[con.seg]
    u = d / length[:, None]
    va, vb = con.var[con.a], con.var[con.b]
    nf = con.free.size
    g = np.zeros((nf, dim))
    fa, fb = va >= 0, vb >= 0
    np.add.at(g, va[fa], ws[fa, None] * u[fa])
    np.add.at(g, vb[fb], -ws[fb, None] * u[fb])
    if not with_hessian:
        return g.ravel(), None
    # Per segment block h = w / L (I - u u^T); +h on both diagonal blocks, -h off-diagonal.
    h = (ws / length)[:, None, None] * (np.eye(dim)[None] - u[:, :, None] * u[:, None, :])
    ii, jj = np.meshgrid(np.arange(dim), np.arange(dim), indexing="ij")
    rows, cols, vals = [], [], []

    def block(vr, vc, hs, sign):
        rows.append((vr[:, None, None] * dim + ii[None]).ravel())
        cols.append((vc[:, None, None] * dim + jj[None]).ravel())
        vals.append((sign * hs).ravel())

    block(va[fa], va[fa], h[fa], 1.0)
    block(vb[fb], vb[fb], h[fb], 1.0)
    both = fa & fb
    block(va[both], vb[both], h[both], -1.0)
    block(vb[both], va[both], h[both], -1.0)
    n = nf * dim
    hess = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return g.ravel(), hess


def solve_spd(hess, rhs, scale):
    """Solve a tree-structured SPD system in its given (children-first) order: no fill-in."""
    n = hess.shape[0]
    diag = hess.diagonal()
    if n and float(np.max(diag)) <= 0.0:
        # Every segment lies along one line (fixed nodes collinear): the objective is
        # piecewise linear, without curvature. Step along the descent direction, length
        # ``scale``; the line search shortens it and the kinks are then contracted.
        return rhs * (scale / max(float(np.linalg.norm(rhs)), 1e-300))
    # A tiny ridge guards the exactly singular cases (all segments at a node collinear).
    ridge = 1e-13 * float(np.max(diag)) if n else 0.0
    a = (hess + sp.diags(np.full(n, ridge))).tocsc()
    lu = spla.splu(a, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return lu.solve(rhs)
