"""The CCO growth kernel: one terminal at a time joined to the cheapest of its nearest segments (numba, nogil).

:func:`grow_terminals` adds terminals to flat tree arrays in place: for each new site (given,
or drawn uniformly in a voxel set under Schreiner's distance criterion) the ``n_candidates``
nearest segments are evaluated by :func:`connection_cost` (the new bifurcation at the weighted
Fermat-Weber point, :func:`~vasc_pipeline.kernel.fermat.fermat_point`) and the cheapest is
taken; with a forbidden voxel set, connections that :func:`crosses` it are refused. The
orchestration (inlets, the first K terminals, sites, the result) is
:mod:`vasc_pipeline.engine.cco`'s; the model and the cost are described there.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from ..model.rng import next_double
from .fermat import _norm3, fermat_point
from .state import _add

__all__ = ["MAX_FORBIDDEN_REFUSALS", "connection_cost", "crosses", "grow_terminals"]


@jit_inline
def _point_segment_distance(x, a, b):
    """Distance from point x to the segment a-b (all float64 (3,))."""
    e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    d0, d1, d2 = x[0] - a[0], x[1] - a[1], x[2] - a[2]
    ee = e0 * e0 + e1 * e1 + e2 * e2
    t = 0.0
    if ee > 0.0:
        t = min(max((d0 * e0 + d1 * e1 + d2 * e2) / ee, 0.0), 1.0)
    return _norm3(d0 - t * e0, d1 - t * e1, d2 - t * e2)


@jit
def connection_cost(parent, n_down, seg_length, position, w_vol, w_pow, j, site, out):
    """(dC_v, dC_w) of joining a terminal at ``site`` below segment ``j``; the new bifurcation into ``out``.

    ``w_vol``, ``w_pow``: cost tables by n [W m^-1]; ``seg_length`` [m] per node.
    """
    p = parent[j]
    n = n_down[j]
    w_up = w_vol[n + 1] + w_pow[n + 1]
    w_dn = w_vol[n] + w_pow[n]
    w_t = w_vol[1] + w_pow[1]
    fermat_point(position[p], position[j], site, w_up, w_dn, w_t, out)
    l_up = _norm3(out[0] - position[p, 0], out[1] - position[p, 1], out[2] - position[p, 2])
    l_dn = _norm3(out[0] - position[j, 0], out[1] - position[j, 1], out[2] - position[j, 2])
    l_t = _norm3(out[0] - site[0], out[1] - site[1], out[2] - site[2])
    d_vol = w_vol[n + 1] * l_up + w_vol[n] * l_dn + w_vol[1] * l_t - w_vol[n] * seg_length[j]
    d_pow = w_pow[n + 1] * l_up + w_pow[n] * l_dn + w_pow[1] * l_t - w_pow[n] * seg_length[j]
    a = p
    while parent[a] >= 0:  # every segment above j carries one more terminal
        m = n_down[a]
        d_vol += (w_vol[m + 1] - w_vol[m]) * seg_length[a]
        d_pow += (w_pow[m + 1] - w_pow[m]) * seg_length[a]
        a = parent[a]
    return d_vol, d_pow


@jit
def _draw_site(rng, voxels, shape, origin, voxel_size, planar, out):
    """One uniform tissue point: the draw of tree.random_terminal_sites for a single site."""
    u0 = next_double(rng)
    u1 = next_double(rng)
    u2 = next_double(rng)
    u3 = next_double(rng)
    k = np.int64(u0 * voxels.size)
    pick = voxels[min(k, voxels.size - 1)]
    nyx = shape[1] * shape[2]
    z = pick // nyx
    y = (pick - z * nyx) // shape[2]
    x = pick - z * nyx - y * shape[2]
    out[0] = origin[0] + voxel_size * x + (u1 - 0.5) * voxel_size
    out[1] = origin[1] + voxel_size * y + (u2 - 0.5) * voxel_size
    out[2] = origin[2] + voxel_size * z + ((u3 - 0.5) * voxel_size if not planar else 0.0)


@jit
def crosses(forbidden, origin, voxel_size, a, b):
    """Whether the segment a -> b [m] (float64 (3,)) passes through a voxel where ``forbidden``
    (uint8 (z, y, x), origin and voxel_size of its grid) is nonzero; voxels beyond the grid are allowed.

    A voxel walk (Amanatides & Woo) from a's voxel to b's, visiting every voxel the segment
    touches (one touched only at an edge or corner too: a conservative test).
    """
    nz, ny, nx = forbidden.shape
    u = np.empty(3)
    d = np.empty(3)
    cell = np.empty(3, dtype=np.int64)
    last = np.empty(3, dtype=np.int64)
    step = np.empty(3, dtype=np.int64)
    t_next = np.empty(3)
    t_delta = np.empty(3)
    walk = 1
    for k in range(3):
        u[k] = (a[k] - origin[k]) / voxel_size
        d[k] = (b[k] - origin[k]) / voxel_size - u[k]
        cell[k] = np.int64(math.floor(u[k] + 0.5))
        last[k] = np.int64(math.floor(u[k] + d[k] + 0.5))
        walk += abs(last[k] - cell[k])
        if d[k] > 0.0:
            step[k] = 1
            t_next[k] = (cell[k] + 0.5 - u[k]) / d[k]
            t_delta[k] = 1.0 / d[k]
        elif d[k] < 0.0:
            step[k] = -1
            t_next[k] = (cell[k] - 0.5 - u[k]) / d[k]
            t_delta[k] = -1.0 / d[k]
        else:
            step[k] = 0
            t_next[k] = math.inf
            t_delta[k] = math.inf
    for _ in range(walk):
        x, y, z = cell[0], cell[1], cell[2]
        if 0 <= x < nx and 0 <= y < ny and 0 <= z < nz and forbidden[z, y, x] != 0:
            return True
        k = 0
        if t_next[1] < t_next[k]:
            k = 1
        if t_next[2] < t_next[k]:
            k = 2
        if t_next[k] > 1.0:
            break
        cell[k] += step[k]
        t_next[k] += t_delta[k]
    return False


@jit_inline
def _joins_cross(forbidden, origin, voxel_size, bif, p, j, site):
    """Whether any of the three new segments b-p, b-j, b-t of a connection crosses a forbidden voxel."""
    return (
        crosses(forbidden, origin, voxel_size, bif, p)
        or crosses(forbidden, origin, voxel_size, bif, j)
        or crosses(forbidden, origin, voxel_size, bif, site)
    )


@jit_inline
def _cheapest_allowed(forbidden, origin, voxel_size, parent, position, cand, vol, pow_, bif, n_c, site, refused):
    """The cheapest of the ``n_c`` evaluated candidates whose connection crosses no forbidden
    voxel (ties: the nearer candidate, as without the test), or -1; ``refused`` is scratch."""
    refused[:n_c] = False
    for _ in range(n_c):
        c_min = -1
        for c in range(n_c):
            if not refused[c] and (c_min < 0 or vol[c] + pow_[c] < vol[c_min] + pow_[c_min]):
                c_min = c
        j = cand[c_min]
        if not _joins_cross(forbidden, origin, voxel_size, bif[c_min], position[parent[j]], position[j], site):
            return c_min
        refused[c_min] = True
    return -1


# Consecutive sites refused because each of their candidate connections crossed a forbidden voxel,
# after which a terminal takes its cheapest connection regardless (a growth always ends; the
# refused ones are counted in the trace's sites drawn)
MAX_FORBIDDEN_REFUSALS = 10_000


@jit
def grow_terminals(
    parent,
    children,
    position,
    n_down,
    seg_length,
    costs,
    compensation,
    rng,
    w_vol,
    w_pow,
    sites,
    random_sites,
    voxels,
    shape,
    origin,
    voxel_size,
    planar,
    measure,
    ndim,
    n_candidates,
    max_tries,
    shrink,
    factor,
    trace,
    first,
    forbidden,
    avoid,
):
    """Add terminals ``first`` .. N - 1 (in place). Returns (sites drawn, final distance factor).

    Node layout: inlets [0, K), terminal i at K + i, the bifurcation made by terminal i at
    N + i. ``trace`` float64 (N, 3): C_v, C_w after each terminal, and sites drawn for it.
    With ``avoid``, a connection whose new segments cross a nonzero voxel of ``forbidden`` (uint8,
    the sites' grid) is not made: the cheapest other candidate is, and a site with none is
    refused like one too close to the tree (without shrinking the distance criterion).
    """
    k_in = first  # the first K terminals (one per inlet) are in place
    n_total = parent.size // 2
    site = np.empty(3)
    bif = np.empty(3)
    best_bif = np.empty(3)
    cand = np.empty(n_candidates, dtype=np.int64)
    cand_d = np.empty(n_candidates)
    cand_vol = np.empty(n_candidates)
    cand_pow = np.empty(n_candidates)
    cand_bif = np.empty((n_candidates, 3))
    refused = np.zeros(n_candidates, dtype=np.bool_)
    drawn = 0
    for i in range(first, n_total):
        t = k_in + i
        n_segments = 2 * i - k_in  # non-inlet nodes: i terminals and i - K bifurcations
        tries = 0
        too_close = 0
        forbidden_refusals = 0
        while True:
            if random_sites:
                _draw_site(rng, voxels, shape, origin, voxel_size, planar, site)
            else:
                for c in range(3):
                    site[c] = sites[i, c]
            tries += 1
            d_crit = factor * (measure / i) ** (1.0 / ndim) if random_sites else -1.0
            n_c = 0
            ok = True
            # Segments are the non-inlet nodes built so far: terminals K..K+i-1, bifurcations N+K..N+i-1.
            for s in range(n_segments):
                node = k_in + s if s < i else n_total + k_in + (s - i)
                d = _point_segment_distance(site, position[parent[node]], position[node])
                if d < d_crit:
                    ok = False
                    break
                if n_c < n_candidates or d < cand_d[n_c - 1]:  # keep the nearest, sorted
                    pos = n_c if n_c < n_candidates else n_candidates - 1
                    while pos > 0 and cand_d[pos - 1] > d:
                        cand_d[pos] = cand_d[pos - 1]
                        cand[pos] = cand[pos - 1]
                        pos -= 1
                    cand_d[pos] = d
                    cand[pos] = node
                    if n_c < n_candidates:
                        n_c += 1
            if ok:
                best = -1
                best_vol = 0.0
                best_pow = 0.0
                for c in range(n_c):
                    d_vol, d_pow = connection_cost(
                        parent, n_down, seg_length, position, w_vol, w_pow, cand[c], site, bif
                    )
                    cand_vol[c], cand_pow[c] = d_vol, d_pow
                    cand_bif[c] = bif
                    if best < 0 or d_vol + d_pow < best_vol + best_pow:
                        best, best_vol, best_pow = cand[c], d_vol, d_pow
                        best_bif[:] = bif
                if not avoid or forbidden_refusals >= MAX_FORBIDDEN_REFUSALS:
                    break
                c = _cheapest_allowed(
                    forbidden,
                    origin,
                    voxel_size,
                    parent,
                    position,
                    cand,
                    cand_vol,
                    cand_pow,
                    cand_bif,
                    n_c,
                    site,
                    refused,
                )
                best = cand[c] if c >= 0 else -1
                if c >= 0:
                    best_vol, best_pow = cand_vol[c], cand_pow[c]
                    best_bif[:] = cand_bif[c]
                if best >= 0:
                    break
                forbidden_refusals += 1
                continue
            too_close += 1
            if too_close % max_tries == 0:
                factor *= shrink
        drawn += tries
        # Join t below ``best`` through the new bifurcation b.
        b = n_total + i
        p = parent[best]
        if children[p, 0] == best:
            children[p, 0] = b
        else:
            children[p, 1] = b
        parent[b] = p
        parent[best] = b
        parent[t] = b
        children[b, 0] = best
        children[b, 1] = t
        position[b] = best_bif
        position[t] = site
        n_down[t] = 1
        n_down[b] = n_down[best] + 1
        a = p
        while a >= 0:
            n_down[a] += 1
            a = parent[a]
        seg_length[b] = _norm3(best_bif[0] - position[p, 0], best_bif[1] - position[p, 1], best_bif[2] - position[p, 2])
        seg_length[best] = _norm3(
            best_bif[0] - position[best, 0], best_bif[1] - position[best, 1], best_bif[2] - position[best, 2]
        )
        seg_length[t] = _norm3(best_bif[0] - site[0], best_bif[1] - site[1], best_bif[2] - site[2])
        _add(costs, compensation, 0, best_vol)
        _add(costs, compensation, 1, best_pow)
        trace[i, 0] = costs[0] + compensation[0]
        trace[i, 1] = costs[1] + compensation[1]
        trace[i, 2] = tries
    return drawn, factor
