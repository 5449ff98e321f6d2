"""The supply term: the count map of terminal spheres and its changes when a terminal moves.

C_s = sum over tissue voxels of s(b), b the number of supply spheres covering the voxel
(s(0) = 10, s(b) = (b - 1)^2). A move's change is computed row by row over both spheres or,
while a terminal stays near the centre of its shell, over the shell's voxels only (the same
sums either way).

With a demand map (``tissue.demand_path``) each voxel has a coverage target t in 1..4, the
``Model``'s ``supply_target``, and s(b) = 10 (t - b) below the target, (b - t)^2 at or above
it: each missing layer costs what an uncovered voxel of target 1 costs, so a deficit weighs
alike at every level (at t = 1 it is s without a map). Without one that array is empty
and the loops of t = 1 run, reading no target: a run without a map is the run before the map
existed, in its trees and its speed.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit_norc, jit_norc_inline, prefetch

__all__ = [
    "SHELL_BANDS",
    "SHELL_WIDTH",
    "in_tissue",
    "shell_capacity",
    "supply_move",
    "supply_move_delta",
    "supply_sphere",
]


@jit_norc_inline
def _inside(i, u, d2, e2, rho2):
    """The coverage test of voxel i, written exactly as the NumPy reference writes it."""
    dx = i - u
    return (dx * dx + d2) + e2 <= rho2


_ROUNDING = 1e-9  # an interval end this close to a voxel centre is settled by the exact test ...
_TANGENT = 1e-12  # ... and every voxel of a row this close to tangent (r^2 below it times rho^2)


@jit_norc_inline
def _row_interval(u, d2, e2, rho2, n):
    """Voxels i of one grid row whose centre lies within a sphere, clipped to [0, n).

    ``d2``, ``e2``: squared offsets of the row from the centre in the other two axes; ``u``
    the centre's coordinate along the row. The square root gives the ends; where an end
    falls within rounding of a voxel centre, or the row is nearly tangent to the sphere, the
    exact test settles it, so the result equals a voxel-by-voxel test. Returns (lo, hi),
    empty when lo > hi.
    """
    rem = (rho2 - e2) - d2
    if rem < -_ROUNDING * rho2:
        return 1, 0
    r = math.sqrt(max(rem, 0.0))
    # The test's sums round by under 1e-15 rho^2, which moves an end by under 1e-15 rho^2 / (2 r):
    # within the window below unless the row is nearly tangent (r < 1e-6 rho).
    window = _ROUNDING * (1.0 + rho2)
    tangent = rem < _TANGENT * rho2
    x = u - r
    lo = math.ceil(x)
    if tangent or lo - x < window or x - (lo - 1) < window:
        c = math.floor(u + 0.5)  # nearest voxel centre: inside if any is
        if not _inside(c, u, d2, e2, rho2):
            return 1, 0
        lo = min(lo, c)
        while _inside(lo - 1, u, d2, e2, rho2):
            lo -= 1
        while not _inside(lo, u, d2, e2, rho2):
            lo += 1
    x = u + r
    hi = math.floor(x)
    if tangent or x - hi < window or (hi + 1) - x < window:
        c = math.floor(u + 0.5)
        if not _inside(c, u, d2, e2, rho2):
            return 1, 0
        hi = max(hi, c)
        while _inside(hi + 1, u, d2, e2, rho2):
            hi += 1
        while not _inside(hi, u, d2, e2, rho2):
            hi -= 1
    return max(lo, 0), min(hi, n - 1)


@jit_norc_inline
def _voxel_coords(model, x, y, z):
    h = model.voxel_size
    return (x - model.origin[0]) / h, (y - model.origin[1]) / h, (z - model.origin[2]) / h


@jit_norc_inline
def _in_voxels(model, grid, p):
    """True when the point p [m] lies in a nonzero voxel of ``grid`` (a uint8 map of the tissue's grid)."""
    nz, ny, nx = grid.shape
    ux, uy, uz = _voxel_coords(model, p[0], p[1], p[2])
    ix = math.floor(ux + 0.5)
    iy = math.floor(uy + 0.5)
    iz = math.floor(uz + 0.5)
    return 0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz and grid[iz, iy, ix] != 0


@jit_norc_inline
def in_tissue(model, p):
    """True when the point p [m] lies in a tissue voxel (where a terminal may be)."""
    return _in_voxels(model, model.mask, p)


@jit_norc_inline
def _gain_change(b):
    """C_s change when a tissue voxel covered b times gains a sphere: s(0) = 10,
    s(b) = (b - 1)^2, so s(b + 1) - s(b) = 2b - 1 - 9 [b = 0]."""
    return (2 * b - 1) - 9 * (b == 0)


@jit_norc_inline
def _loss_change(b):
    """C_s change when a tissue voxel covered b times loses a sphere: s(b - 1) - s(b) = 3 - 2b + 9 [b = 1]."""
    return (3 - 2 * b) + 9 * (b == 1)


@jit_norc_inline
def _gain_change_to(b, t):
    """:func:`_gain_change` for a voxel of coverage target t: s(b) = 10 (t - b) for b < t, else
    (b - t)^2, so s(b + 1) - s(b) = -10 below the target and 2 (b - t) + 1 from it on; equal to
    it at t = 1."""
    return -10 if b < t else 2 * (b - t) + 1


@jit_norc_inline
def _loss_change_to(b, t):
    """:func:`_loss_change` for a voxel of coverage target t: s(b - 1) - s(b) = 10 up to the
    target and 1 - 2 (b - t) above it."""
    return 10 if b <= t else 1 - 2 * (b - t)


@jit_norc_inline
def _range_change(supply, target, k, j, lo, hi, sign, write):
    """C_s change when voxels lo..hi of row (k, j) gain ``sign`` (:func:`_gain_change`,
    :func:`_loss_change`, or with coverage targets ``target`` :func:`_gain_change_to`,
    :func:`_loss_change_to`); non-tissue voxels hold -1 and contribute 0."""
    # The loops exit early on a count below -1 (none is): LLVM does not vectorise loops
    # with two exits, and these are a few voxels long, where a vectorised loop's set-up
    # and remainder cost more than they save (measured: -25 % time per supply delta).
    delta = 0
    if target.shape[0] != 0:  # a demand map: each voxel's own target
        if sign > 0:
            for i in range(lo, hi + 1):
                b = np.int64(supply[k, j, i])
                if b < -1:
                    break
                delta += (b >= 0) * _gain_change_to(b, np.int64(target[k, j, i]))
        else:
            for i in range(lo, hi + 1):
                b = np.int64(supply[k, j, i])
                if b < -1:
                    break
                delta += (b >= 0) * _loss_change_to(b, np.int64(target[k, j, i]))
    elif sign > 0:
        for i in range(lo, hi + 1):
            b = np.int64(supply[k, j, i])
            if b < -1:
                break
            delta += (b >= 0) * _gain_change(b)
    else:
        for i in range(lo, hi + 1):
            b = np.int64(supply[k, j, i])
            if b < -1:
                break
            delta += (b >= 0) * _loss_change(b)
    if write:
        for i in range(lo, hi + 1):
            if supply[k, j, i] >= 0:
                supply[k, j, i] += sign
    return delta


@jit_norc_inline
def _row_change(supply, target, k, j, lo, hi, other_lo, other_hi, sign, write):
    """C_s change when voxels lo..hi of row (k, j), except other_lo..other_hi, gain ``sign``."""
    if other_lo > other_hi or other_hi < lo or other_lo > hi:  # nothing to exclude
        return _range_change(supply, target, k, j, lo, hi, sign, write)
    return _range_change(supply, target, k, j, lo, other_lo - 1, sign, write) + _range_change(
        supply, target, k, j, other_hi + 1, hi, sign, write
    )


@jit_norc_inline
def _sphere_change(model, supply, old, new, write):
    """Change of C_s when a supply sphere moves from ``old`` to ``new`` (either may be NaN: absent).

    Only voxels in one sphere but not the other change; with ``write`` the counts are
    updated. ``supply`` holds -1 outside tissue.
    """
    ox, oy, oz = _voxel_coords(model, old[0], old[1], old[2])  # NaN stays NaN: absent
    nx_, ny_, nz_ = _voxel_coords(model, new[0], new[1], new[2])
    return _sphere_rows(supply, model.supply_target, model.supply_rho, ox, oy, oz, nx_, ny_, nz_, write)


@jit_norc
def _sphere_rows(supply, target, rho, ox, oy, oz, nx_, ny_, nz_, write):
    """:func:`_sphere_change` on the spheres' centres in voxel coordinates: a call passes a
    few words, not the whole ``Model`` (numba passes a named tuple field by field)."""
    nz, ny, nx = supply.shape
    rho2 = rho * rho
    has_old = not math.isnan(ox)
    has_new = not math.isnan(nx_)
    z_lo = nz
    z_hi = -1
    if has_old:
        z_lo = min(z_lo, math.floor(oz - rho))
        z_hi = max(z_hi, math.ceil(oz + rho))
    if has_new:
        z_lo = min(z_lo, math.floor(nz_ - rho))
        z_hi = max(z_hi, math.ceil(nz_ + rho))
    delta = 0
    for k in range(max(z_lo, 0), min(z_hi, nz - 1) + 1):
        do2 = (k - oz) * (k - oz) if has_old else np.inf
        dn2 = (k - nz_) * (k - nz_) if has_new else np.inf
        if do2 > rho2 and dn2 > rho2:
            continue
        y_lo = ny
        y_hi = -1
        if do2 <= rho2:
            ry = math.sqrt(rho2 - do2)
            y_lo = min(y_lo, math.floor(oy - ry) - 1)
            y_hi = max(y_hi, math.ceil(oy + ry) + 1)
        if dn2 <= rho2:
            ry = math.sqrt(rho2 - dn2)
            y_lo = min(y_lo, math.floor(ny_ - ry) - 1)
            y_hi = max(y_hi, math.ceil(ny_ + ry) + 1)
        for j in range(max(y_lo, 0), min(y_hi, ny - 1) + 1):
            o_lo, o_hi = 1, 0
            n_lo, n_hi = 1, 0
            if do2 <= rho2:
                o_lo, o_hi = _row_interval(ox, (j - oy) * (j - oy), do2, rho2, nx)
            if dn2 <= rho2:
                n_lo, n_hi = _row_interval(nx_, (j - ny_) * (j - ny_), dn2, rho2, nx)
            if o_lo <= o_hi:
                delta += _row_change(supply, target, k, j, o_lo, o_hi, n_lo, n_hi, -1, write)
            if n_lo <= n_hi:
                delta += _row_change(supply, target, k, j, n_lo, n_hi, o_lo, o_hi, 1, write)
    return float(delta)


_NO_SPHERE = np.array([np.nan, np.nan, np.nan])


@jit_norc
def supply_sphere(model, supply, p, sign):
    """Add (sign = +1) or remove (-1) one supply sphere centred at p; return the change of C_s."""
    if sign > 0:
        return _sphere_change(model, supply, _NO_SPHERE, p, True)
    return _sphere_change(model, supply, p, _NO_SPHERE, True)


@jit_norc_inline
def supply_move_delta(model, supply, old, new):
    """Change of C_s if a sphere moved from ``old`` to ``new``; reads only voxels that change."""
    return _sphere_change(model, supply, old, new, False)


@jit_norc_inline
def supply_move(model, supply, old, new):
    """Move a sphere from ``old`` to ``new`` in the count map."""
    _sphere_change(model, supply, old, new, True)


# Supply shells. Once the adapted terminal steps are a small fraction of a voxel (the second
# half of a run), a move changes the coverage of only the few voxels whose centres lie that
# close to the sphere's surface, yet the rows of both spheres cost ~1 us to compute. So a
# terminal keeps its shell: the tissue voxels within a width of its sphere's surface, listed
# once around a centre, in bands of their distance to the surface. While the terminal and its
# proposed position both stay closer to that centre than the width (less a margin far above
# the distances' rounding), no voxel outside the shell can change coverage, nor any of a band
# farther from the surface than the two positions' distance to the centre; testing the
# others with the row code's own expression gives the same change, bit for bit
# (benchmarks/README.md, "Supply shells").
SHELL_WIDTH = 0.3  # the widest shell, voxels: ~120 voxels at the default supply radius of 4 voxels
SHELL_BANDS = 8
_SHELL_STEPS = 4.0  # a new shell's width, in the longest adapted terminal step (sqrt(3) half-widths)
_SHELL_MARGIN = 1e-6  # voxels


def shell_capacity(rho, width):
    """Voxels a terminal's shell array holds: 1.5 times a shell's volume (8 pi rho^2 width), plus 32.
    Lattice points in such shells stay within 1.2 times it (rho 2 to 6, width 0.3); a shell
    that does not fit is not used (its supply changes are computed row by row)."""
    return int(math.ceil(1.5 * 8.0 * math.pi * rho * rho * width)) + 32


@jit_norc
def _shell_voxels(supply, rho, cx, cy, cz, width, voxels, bands, place):
    """Visit every tissue voxel whose centre lies within ``width`` of the sphere's surface (and
    perhaps a few more), in row order, each in band min(B |distance - rho| / width, B - 1) of
    the B = ``bands.size``. Counting (``place`` False): adds each to its band's count in ``bands``.
    Placing: writes [x, y, z] to ``voxels`` at its band's entry of ``bands`` and advances it.
    Returns the number visited."""
    nz, ny, nx = supply.shape
    n_bands = bands.size
    inner2 = max(rho - width, 0.0) ** 2
    outer = rho + width
    outer2 = outer * outer
    n = 0
    for k in range(max(math.floor(cz - outer), 0), min(math.ceil(cz + outer), nz - 1) + 1):
        e2 = (k - cz) * (k - cz)
        for j in range(max(math.floor(cy - outer), 0), min(math.ceil(cy + outer), ny - 1) + 1):
            q = (j - cy) * (j - cy) + e2
            if q > outer2:
                continue
            # |i - cx| in [a, b]: a run on either side of the centre (one run where a <= 0)
            a = math.sqrt(max(inner2 - q, 0.0)) - _SHELL_MARGIN
            b = math.sqrt(outer2 - q) + _SHELL_MARGIN
            left_hi = min(math.floor(cx - a), nx - 1)
            for lo, hi in (
                (max(math.ceil(cx - b), 0), left_hi),
                (max(math.ceil(cx + a), left_hi + 1, 0), min(math.floor(cx + b), nx - 1)),
            ):
                for i in range(lo, hi + 1):
                    if supply[k, j, i] < 0:
                        continue
                    dx = i - cx
                    band = min(int(abs(math.sqrt(dx * dx + q) - rho) * n_bands / width), n_bands - 1)
                    if place:
                        slot = bands[band]
                        voxels[slot, 0] = i
                        voxels[slot, 1] = j
                        voxels[slot, 2] = k
                        bands[band] = slot + 1
                    else:
                        bands[band] += 1
                    n += 1
    return n


@jit_norc
def _shell_build(supply, rho, cx, cy, cz, width, voxels, bands):
    """List into ``voxels`` (int16 (capacity, 3), [x, y, z]) every tissue voxel of ``supply``
    whose centre lies within ``width`` of the surface of the sphere of radius ``rho`` centred
    at (cx, cy, cz) (all in voxel units), and perhaps a few more, band by band: band b (of
    B = ``bands.size``, distances to the surface from b width / B) ends before ``bands[b]``.
    Returns their number, or -1 when they do not fit (or the grid is too large for int16)."""
    if max(supply.shape) > 32767:
        return -1
    bands[:] = 0
    if _shell_voxels(supply, rho, cx, cy, cz, width, voxels, bands, False) > voxels.shape[0]:
        return -1
    total = 0
    for b in range(bands.size):  # counts to each band's first entry
        count = bands[b]
        bands[b] = total
        total += count
    _shell_voxels(supply, rho, cx, cy, cz, width, voxels, bands, True)  # each band's entry to its end
    return total


@jit_norc
def _shell_change(supply, target, rho, voxels, bands, width, reach, ox, oy, oz, px, py, pz, write):
    """:func:`_sphere_rows` for a sphere moving from o to p (voxel coordinates) when no voxel
    can change coverage but those of the shell (``voxels``, ``bands``, ``width``) within
    ``reach`` of the surface: each voxel of the bands that reach is tested as the row code
    tests a voxel (:func:`_inside`), and its count change is the rows' (:func:`_gain_change`,
    :func:`_loss_change`, or with coverage targets :func:`_gain_change_to`, :func:`_loss_change_to`)."""
    rho2 = rho * rho
    n_bands = bands.size
    targets = target.shape[0] != 0
    delta = 0
    first = 0
    for band in range(n_bands):
        if band * width / n_bands > reach:  # this band's voxels and the later ones lie farther
            break
        for t in range(first, bands[band]):
            i = np.int64(voxels[t, 0])
            j = np.int64(voxels[t, 1])
            k = np.int64(voxels[t, 2])
            was = _inside(i, ox, (j - oy) * (j - oy), (k - oz) * (k - oz), rho2)
            now = _inside(i, px, (j - py) * (j - py), (k - pz) * (k - pz), rho2)
            if was == now:
                continue
            b = np.int64(supply[k, j, i])
            if targets:
                t = np.int64(target[k, j, i])
                delta += _gain_change_to(b, t) if now else _loss_change_to(b, t)
            else:
                delta += _gain_change(b) if now else _loss_change(b)
            if write:
                supply[k, j, i] += 1 if now else -1
        first = bands[band]
    return float(delta)


@jit_norc_inline
def _shell_reach(model, state, t, ox, oy, oz, px, py, pz):
    """How far from its sphere's surface a voxel may lie and still change coverage when terminal
    t moves from o to p (voxel coordinates), if its shell can evaluate the move; else -1.

    A shell around centre c of width w lists every voxel whose centre's distance to the sphere's
    surface is at most w; with the sphere at o or p that distance changes by at most |o - c| +
    |p - o|, the reach, and a voxel farther than that from the surface keeps its coverage. A
    new shell, around o, is listed when the adapted terminal steps allow one no wider than
    ``supply_shell_width`` (or the present one is twice as wide as they need).
    """
    if model.supply_shell_width <= 0.0:
        return -1.0
    step = math.sqrt((px - ox) ** 2 + (py - oy) ** 2 + (pz - oz) ** 2)
    width = _SHELL_STEPS * math.sqrt(3.0) * state.step_size[0] / model.voxel_size
    frame = state.scratch_shell_frame[t]  # centre, width (0: no shell)
    if frame[3] <= 2.0 * width:
        reach = math.sqrt((ox - frame[0]) ** 2 + (oy - frame[1]) ** 2 + (oz - frame[2]) ** 2) + step
        if reach < frame[3] - _SHELL_MARGIN:
            return reach + _SHELL_MARGIN
    if width > model.supply_shell_width or step >= width - _SHELL_MARGIN:
        return -1.0
    n = _shell_build(
        state.supply, model.supply_rho, ox, oy, oz, width, state.scratch_shell_voxels[t], state.scratch_shell_bands[t]
    )
    frame[0] = ox
    frame[1] = oy
    frame[2] = oz
    frame[3] = width if n >= 0 else 0.0
    return step + _SHELL_MARGIN if n >= 0 else -1.0


@jit_norc_inline
def _terminal_supply_change(model, state, t, ox, oy, oz, px, py, pz, reach, write):
    """C_s change of terminal t's sphere moving from o to p (voxel coordinates): on its shell
    when :func:`_shell_reach` gave a reach (>= 0), else row by row; with ``write`` the counts
    are updated."""
    if reach >= 0.0:
        voxels, bands, width = (
            state.scratch_shell_voxels[t],
            state.scratch_shell_bands[t],
            state.scratch_shell_frame[t, 3],
        )
        target, rho = model.supply_target, model.supply_rho
        return _shell_change(state.supply, target, rho, voxels, bands, width, reach, ox, oy, oz, px, py, pz, write)
    if model.prefetch_supply and not write:  # the rows' cache misses in flight together, not one by one
        _prefetch_sphere(state.supply, model.supply_rho, ox, oy, oz)
        _prefetch_sphere(state.supply, model.supply_rho, px, py, pz)
    return _sphere_rows(state.supply, model.supply_target, model.supply_rho, ox, oy, oz, px, py, pz, write)


@jit_norc
def _prefetch_sphere(supply, rho, cx, cy, cz):
    """Prefetch the count map's rows under the sphere of radius ``rho`` at (cx, cy, cz) (voxel
    coordinates): both ends of each row, so all of it while a row's counts fit in 64 bytes."""
    nz, ny, nx = supply.shape
    flat = supply.reshape(-1)
    x_lo = max(math.floor(cx - rho), 0)
    x_hi = min(math.ceil(cx + rho), nx - 1)
    if x_lo > x_hi:
        return
    rho2 = rho * rho
    for k in range(max(math.floor(cz - rho), 0), min(math.ceil(cz + rho), nz - 1) + 1):
        e2 = (k - cz) * (k - cz)
        if e2 > rho2:
            continue
        ry = math.sqrt(rho2 - e2)
        for j in range(max(math.floor(cy - ry), 0), min(math.ceil(cy + ry), ny - 1) + 1):
            row = (k * ny + j) * nx
            prefetch(flat, row + x_lo)
            prefetch(flat, row + x_hi)
