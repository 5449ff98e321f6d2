"""A perfusion demand map (``tissue.demand_path``, every tissue): where the tissue needs more terminals.

The map is a float image of relative demand, > 0 in every tissue voxel, in any format
``tissue.path`` reads (.npy, Zarr, NIfTI, NRRD). With a geometry (a label map's header, or a
Zarr array's ``voxel_size`` and ``origin`` attributes) it is sampled at the supply grid's voxel
centres, nearest voxel (no interpolation: a map of regions keeps its levels, and no level is
made up between two regions); without one (.npy, a Zarr array without those attributes) it must
be on the supply grid itself, shape for shape.

:func:`demand_targets` quantises it to the supply term's coverage targets: t_v = round(d_v / min d)
(halves up), capped at :data:`DEMAND_LEVELS`, so a voxel of twice the least demand is to be
covered by two supply spheres. :func:`apply_demand` gives a :class:`~vasc_pipeline.model.tissue.Tissue`
those targets (``Tissue.supply_target``), which the supply term and R_supply then read.
"""

from __future__ import annotations

import logging

import numpy as np

from .grid import Tissue, TissueError

__all__ = ["DEMAND_LEVELS", "read_demand", "demand_targets", "apply_demand"]

log = logging.getLogger(__name__)

# The largest coverage target: a demand range of 4:1. The cost charges each missing layer alike
# at every target (10 per layer), so nothing in it stops at 4; the density is measured at 2:1
# only (docs/findings/demand.md), and wider ranges wait for a measurement.
DEMAND_LEVELS = 4


def _mm_box(lo, hi) -> str:
    return ", ".join(f"{a} [{u * 1e3:.4g}, {v * 1e3:.4g}]" for a, u, v in zip("xyz", lo, hi)) + " mm"


def read_demand(path: str, tissue: Tissue) -> np.ndarray:
    """float64 (nz, ny, nx): the demand of ``path`` at each tissue voxel of ``tissue`` (0 elsewhere),
    sampled nearest voxel when the file gives its geometry, else read as on the supply grid."""
    from .shapes import _load_mask_array

    data, attrs = _load_mask_array(path, None, "demand_path", what="demand map")
    data = np.asarray(data)
    if data.dtype == bool or not np.issubdtype(data.dtype, np.number):
        data = data.astype(np.float64)
    if data.ndim == 2:
        data = data[None]
    zyx = np.argwhere(tissue.mask != 0)
    if "voxel_size" in attrs:
        h = float(attrs["voxel_size"])
        origin = np.asarray(attrs.get("origin", [0.0, 0.0, 0.0]), dtype=np.float64)
        if not (h > 0 and np.isfinite(h)) or origin.shape != (3,):
            raise TissueError(
                f"tissue.demand_path: the demand map {path!r} gives voxel_size={attrs['voxel_size']!r} and "
                f"origin={attrs.get('origin')!r}; need a length > 0 in metres and [x, y, z] in metres"
            )
        centres = tissue.origin + zyx[:, ::-1] * tissue.voxel_size
        idx = np.floor((centres - origin) / h + 0.5).astype(np.int64)[:, ::-1]
        if data.shape[0] == 1:  # a 2-D map: one layer, whatever the height
            idx[:, 0] = 0
        inside = np.all((idx >= 0) & (idx < np.array(data.shape)), axis=1)
        if not inside.all():
            lo = origin - 0.5 * h
            hi = origin + (np.array(data.shape[::-1]) - 0.5) * h
            raise TissueError(
                f"tissue.demand_path: {int(np.count_nonzero(~inside))} of the tissue's {len(zyx)} voxel centres lie "
                f"outside the demand map {path!r} ({data.shape[2]} x {data.shape[1]} x {data.shape[0]} voxels of "
                f"{h * 1e3:.4g} mm, {_mm_box(lo, hi)}): the map must cover the tissue (sampled nearest voxel)"
            )
        values = data[idx[:, 0], idx[:, 1], idx[:, 2]]
    else:
        if data.shape != tissue.shape:
            raise TissueError(
                f"tissue.demand_path: the demand map {path!r} has shape {data.shape} and no geometry (voxel_size, "
                f"origin), so it must be on the supply grid, shape {tissue.shape} (z, y, x) at n_terminals and "
                f"voxel {tissue.voxel_size * 1e3:.4g} mm; or give it as a NIfTI or NRRD image, or a Zarr array with "
                "voxel_size and origin attributes (m), which is sampled at the supply grid's voxel centres"
            )
        values = data[zyx[:, 0], zyx[:, 1], zyx[:, 2]]
    values = values.astype(np.float64)
    bad = ~(np.isfinite(values) & (values > 0))
    if bad.any():
        finite = values[np.isfinite(values)]
        least = f"; the least is {finite.min():.4g}" if finite.size else ""
        raise TissueError(
            f"tissue.demand_path: {int(np.count_nonzero(bad))} of the tissue's {len(zyx)} voxels have a demand that is "
            f"not a number > 0 in {path!r}{least}: every tissue voxel needs a relative demand > 0 (1 the least, 2 "
            "twice as many terminals per volume)"
        )
    out = np.zeros(tissue.shape, dtype=np.float64)
    out[zyx[:, 0], zyx[:, 1], zyx[:, 2]] = values
    return out


def demand_targets(demand: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """uint8 (nz, ny, nx): each tissue voxel's coverage target, round(d / min d) (halves up) capped at
    :data:`DEMAND_LEVELS`; 0 outside the tissue. ``demand`` > 0 in every tissue voxel."""
    tissue = mask != 0
    least = float(demand[tissue].min())
    targets = np.zeros(mask.shape, dtype=np.uint8)
    levels = np.floor(demand[tissue] / least + 0.5)
    targets[tissue] = np.clip(levels, 1, DEMAND_LEVELS).astype(np.uint8)
    return targets


def apply_demand(tissue: Tissue, path: str) -> None:
    """Read ``path`` (``tissue.demand_path``) onto ``tissue``'s supply grid and set its coverage
    targets (``Tissue.supply_target``); a uniform map leaves none (the model without a map)."""
    demand = read_demand(path, tissue)
    targets = demand_targets(demand, tissue.mask)
    levels = np.bincount(targets[tissue.mask != 0], minlength=DEMAND_LEVELS + 1)[1:]
    capped = int(np.count_nonzero(demand[tissue.mask != 0] / demand[tissue.mask != 0].min() >= DEMAND_LEVELS + 0.5))
    log.info(
        "demand map %s: tissue voxels by coverage target 1..%d: %s%s",
        path,
        DEMAND_LEVELS,
        ", ".join(str(int(v)) for v in levels),
        f" ({capped} capped at {DEMAND_LEVELS})" if capped else "",
    )
    tissue.supply_target = None if levels[1:].sum() == 0 else targets
