"""The weighted Fermat-Weber point of three points: the local problem of a CCO connection.

:func:`fermat_point` places the new bifurcation of the CCO growth (:mod:`~vasc_pipeline.kernel.growth`,
the optimum of joining a terminal below a segment); ``_norm3`` is the three-component norm the
growth kernel shares. Pure geometry, jitted, independent of the tree and the tissue.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline

__all__ = ["fermat_point"]


@jit_inline
def _norm3(a0, a1, a2):
    return math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)


@jit
def fermat_point(p, q, r, wp, wq, wr, out):
    """Minimiser of wp|x-p| + wq|x-q| + wr|x-r| (float64 (3,) each, weights > 0) into ``out``; returns the cost.

    A vertex is the optimum when the pull of the other two (weighted unit vectors) does
    not exceed its own weight (coinciding vertices pool their weights); otherwise the
    optimum is interior and Weiszfeld's iteration, started at the weighted centroid,
    converges to it; Newton steps (downhill only) then polish it to rounding.
    """
    pts = np.empty((3, 3))
    w = np.empty(3)
    for k in range(3):
        pts[0, k] = p[k]
        pts[1, k] = q[k]
        pts[2, k] = r[k]
    w[0], w[1], w[2] = wp, wq, wr
    scale = 0.0
    for a in range(3):
        for b in range(a + 1, 3):
            scale = max(scale, _norm3(pts[a, 0] - pts[b, 0], pts[a, 1] - pts[b, 1], pts[a, 2] - pts[b, 2]))
    tiny = 1e-14 * scale
    for v in range(3):
        own = 0.0
        f0 = f1 = f2 = 0.0
        for u in range(3):
            d0 = pts[u, 0] - pts[v, 0]
            d1 = pts[u, 1] - pts[v, 1]
            d2 = pts[u, 2] - pts[v, 2]
            d = _norm3(d0, d1, d2)
            if d <= tiny:
                own += w[u]
            else:
                f0 += w[u] * d0 / d
                f1 += w[u] * d1 / d
                f2 += w[u] * d2 / d
        if _norm3(f0, f1, f2) <= own:
            for k in range(3):
                out[k] = pts[v, k]
            return _cost3(pts, w, out)
    total = w[0] + w[1] + w[2]
    for k in range(3):
        out[k] = (w[0] * pts[0, k] + w[1] * pts[1, k] + w[2] * pts[2, k]) / total
    for _ in range(500):
        s = 0.0
        n0 = n1 = n2 = 0.0
        for u in range(3):
            d = _norm3(out[0] - pts[u, 0], out[1] - pts[u, 1], out[2] - pts[u, 2])
            if d <= tiny:  # landed on a vertex that is not optimal: nudge towards the centroid
                d = tiny
            c = w[u] / d
            s += c
            n0 += c * pts[u, 0]
            n1 += c * pts[u, 1]
            n2 += c * pts[u, 2]
        x0, x1, x2 = n0 / s, n1 / s, n2 / s
        step = _norm3(x0 - out[0], x1 - out[1], x2 - out[2])
        out[0], out[1], out[2] = x0, x1, x2
        if step <= 1e-10 * scale:
            break
    # Newton on the smooth interior problem finishes what Weiszfeld's linear rate leaves
    # (slow near a vertex): H = sum w_i / d_i (I - u_i u_i^T), steps only downhill.
    cost = _cost3(pts, w, out)
    hess = np.empty((3, 3))
    grad = np.empty(3)
    trial = np.empty(3)
    for _ in range(30):
        hess[:, :] = 0.0
        grad[:] = 0.0
        for u in range(3):
            d0 = out[0] - pts[u, 0]
            d1 = out[1] - pts[u, 1]
            d2 = out[2] - pts[u, 2]
            d = max(_norm3(d0, d1, d2), tiny)
            u0, u1, u2 = d0 / d, d1 / d, d2 / d
            grad[0] += w[u] * u0
            grad[1] += w[u] * u1
            grad[2] += w[u] * u2
            c = w[u] / d
            hess[0, 0] += c * (1.0 - u0 * u0)
            hess[1, 1] += c * (1.0 - u1 * u1)
            hess[2, 2] += c * (1.0 - u2 * u2)
            hess[0, 1] -= c * u0 * u1
            hess[0, 2] -= c * u0 * u2
            hess[1, 2] -= c * u1 * u2
        hess[1, 0], hess[2, 0], hess[2, 1] = hess[0, 1], hess[0, 2], hess[1, 2]
        if _norm3(grad[0], grad[1], grad[2]) <= 1e-13 * total:
            break
        det = (
            hess[0, 0] * (hess[1, 1] * hess[2, 2] - hess[1, 2] * hess[2, 1])
            - hess[0, 1] * (hess[1, 0] * hess[2, 2] - hess[1, 2] * hess[2, 0])
            + hess[0, 2] * (hess[1, 0] * hess[2, 1] - hess[1, 1] * hess[2, 0])
        )
        if not abs(det) > 0.0:
            break
        step = np.linalg.solve(hess, grad)
        t = 1.0
        improved = False
        for _ in range(20):
            for c in range(3):
                trial[c] = out[c] - t * step[c]
            new = _cost3(pts, w, trial)
            if new <= cost:
                improved = new < cost
                out[0], out[1], out[2] = trial[0], trial[1], trial[2]
                cost = new
                break
            t *= 0.5
        if not improved or t * _norm3(step[0], step[1], step[2]) <= 1e-15 * scale:
            break
    return cost


@jit_inline
def _cost3(pts, w, x):
    c = 0.0
    for u in range(3):
        c += w[u] * _norm3(x[0] - pts[u, 0], x[1] - pts[u, 1], x[2] - pts[u, 2])
    return c
