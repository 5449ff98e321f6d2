"""The length of segments inside each voxel code of a labelled box (the whole tree's extension).

The extension (:mod:`vasc_pipeline.engine.extend`) keeps its fine vessels out of cavities and
inside their territory by measuring, per candidate segment, how much of it lies in voxels of
each code. The NumPy reference is :func:`vasc_pipeline.model.costs.voxel_pieces`.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit

__all__ = ["voxel_code_lengths"]


@jit
def voxel_code_lengths(box, origin, voxel_size, p0, p1, out):
    """Per segment (rows of p0 -> p1, m), the length [m] inside each voxel code of ``box``.

    ``out`` float64 (n, 5): columns CODE_OUTSIDE .. CODE_CAVITY, and the last the length beyond
    the box. The exact traversal of :func:`vasc_pipeline.model.costs.voxel_pieces`: the segment is
    cut where it crosses a voxel face and each piece charged to the voxel of its midpoint.
    """
    nz, ny, nx = box.shape
    t = np.empty(256)
    u0 = np.empty(3)
    d = np.empty(3)
    for s in range(p0.shape[0]):
        for a in range(3):
            u0[a] = (p0[s, a] - origin[a]) / voxel_size
            d[a] = (p1[s, a] - origin[a]) / voxel_size - u0[a]
        length = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        for c in range(5):
            out[s, c] = 0.0
        if length == 0.0:
            continue
        count = 2
        t[0] = 0.0
        t[1] = 1.0
        for a in range(3):
            if d[a] != 0.0:
                lo = min(u0[a], u0[a] + d[a])
                hi = max(u0[a], u0[a] + d[a])
                first = math.ceil(lo - 0.5)
                last = math.floor(hi - 0.5)
                need = count + max(0, last - first + 1)
                if need > t.size:
                    grown = np.empty(2 * need)
                    grown[:count] = t[:count]
                    t = grown
                inv = 1.0 / d[a]
                for k in range(first, last + 1):
                    t[count] = min(max(((k + 0.5) - u0[a]) * inv, 0.0), 1.0)
                    count += 1
        ts = np.sort(t[:count])
        for j in range(count - 1):
            if ts[j + 1] <= ts[j]:
                continue
            mid = 0.5 * (ts[j] + ts[j + 1])
            x = int(math.floor(u0[0] + mid * d[0] + 0.5))
            y = int(math.floor(u0[1] + mid * d[1] + 0.5))
            z = int(math.floor(u0[2] + mid * d[2] + 0.5))
            piece = (ts[j + 1] - ts[j]) * length * voxel_size
            if 0 <= x < nx and 0 <= y < ny and 0 <= z < nz:
                out[s, box[z, y, x]] += piece
            else:
                out[s, 4] += piece
