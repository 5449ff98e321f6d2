"""The margins of a tree's parts: voxels within a distance of another part's region.

A part of terminals (engine.parts) owns the tissue voxels nearest to its terminals; its
terminals may move only where their supply spheres cannot reach a voxel of another part.
:func:`mark_margins` marks, for every tissue voxel, whether a voxel of another part lies
within a Euclidean radius: a scan of the ball around each tissue voxel, one row segment at a
time, each read in O(1) from the runs of one part along its row (a row of centres against
one row of the ball, so that both are read in order). It sees every other part's voxel, also
across a gap of non-tissue (a cavity thinner than the ball), which a test of adjacent voxels
would miss. :func:`margins_reference` is the same set from scipy's exact distance transform,
one per part, which tests compare against.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from .._jit import jit

__all__ = ["mark_margins", "margins_reference"]


@jit
def _row_runs(region):
    """Per row of ``region``: ``next_tissue[z, y, x]``, the first x' >= x of a tissue voxel (nx
    if none; index nx too), and for a tissue voxel ``change[z, y, x]``, the first x' > x of a
    tissue voxel of another part (nx if none), so that a row's segment is read in O(1)."""
    nz, ny, nx = region.shape
    next_tissue = np.empty((nz, ny, nx + 1), dtype=np.int32)
    change = np.empty((nz, ny, nx), dtype=np.int32)
    for z in range(nz):
        for y in range(ny):
            following = nx  # the nearest tissue voxel to the right
            next_tissue[z, y, nx] = nx
            for x in range(nx - 1, -1, -1):
                label = region[z, y, x]
                if label >= 0:
                    if following == nx:
                        change[z, y, x] = nx
                    elif region[z, y, following] != label:
                        change[z, y, x] = following
                    else:
                        change[z, y, x] = change[z, y, following]
                    following = x
                next_tissue[z, y, x] = following
    return next_tissue, change


@jit
def mark_margins(region, radius, out):
    """Set ``out[z, y, x]`` (bool (nz, ny, nx)) where ``region`` (int (nz, ny, nx): a part
    index per tissue voxel, -1 elsewhere) is >= 0 and some voxel within ``radius`` (voxel
    edges; squared distance <= radius²) holds another part's index."""
    nz, ny, nx = region.shape
    next_tissue, change = _row_runs(region)
    r = int(math.floor(radius))
    r2 = radius * radius
    out[...] = False
    for z0 in range(nz):
        for y0 in range(ny):
            # one row of centres against one row of the ball at a time: both read in order
            for dz in range(-r, r + 1):
                z = z0 + dz
                if z < 0 or z >= nz:
                    continue
                for dy in range(-r, r + 1):
                    y = y0 + dy
                    rest = r2 - dz * dz - dy * dy
                    if y < 0 or y >= ny or rest < 0.0:
                        continue
                    w = int(math.floor(math.sqrt(rest)))
                    for x0 in range(nx):
                        own = region[z0, y0, x0]
                        if own < 0 or out[z0, y0, x0]:
                            continue
                        hi = min(x0 + w, nx - 1)
                        first = next_tissue[z, y, max(x0 - w, 0)]  # the segment's first tissue voxel
                        if first <= hi and (region[z, y, first] != own or change[z, y, first] <= hi):
                            out[z0, y0, x0] = True


def margins_reference(region: np.ndarray, radius: float) -> np.ndarray:
    """:func:`mark_margins` from one Euclidean distance transform per part (scipy)."""
    out = np.zeros(region.shape, dtype=bool)
    tissue = region >= 0
    for part in np.unique(region[tissue]):
        foreign = tissue & (region != part)
        if foreign.any():
            near = ndimage.distance_transform_edt(~foreign) <= radius
            out |= near & (region == part)
    return out
