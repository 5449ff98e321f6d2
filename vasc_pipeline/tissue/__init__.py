"""Tissue domains as voxel grids (SPEC section 3): the registry of named tissues and its builder.

:func:`build_tissue` returns a :class:`Tissue` for each named domain of :data:`TISSUES`:
``sphere``, ``box``, ``plane2d`` and ``mask`` (a user's array) from
:mod:`~vasc_pipeline.tissue.shapes`, and ``heart``, the paper's coronary substrate, from
:mod:`~vasc_pipeline.tissue.heart`. The voxel grid itself (the :class:`Tissue` class, its
distance transform, :func:`voxelize`, :func:`default_voxel_size`) is
:mod:`~vasc_pipeline.tissue.grid`.
"""

from __future__ import annotations

from collections.abc import Callable

from . import heart
from .grid import VOXELS_PER_SUPPLY_RADIUS, Tissue, TissueError, default_voxel_size, voxelize
from .shapes import box, mask, plane2d, sphere

__all__ = [
    "Tissue",
    "TissueError",
    "build_tissue",
    "voxelize",
    "default_voxel_size",
    "VOXELS_PER_SUPPLY_RADIUS",
    "TISSUES",
]

TISSUES: dict[str, Callable[..., Tissue]] = {
    "heart": heart.heart_tissue,
    "plane2d": plane2d,
    "sphere": sphere,
    "box": box,
    "mask": mask,
}


def build_tissue(name: str, n_terminals: int, **params) -> Tissue:
    """Build the named tissue for ``n_terminals`` terminals (params: the tissue config)."""
    if name not in TISSUES:
        raise TissueError(f"tissue.name: unknown tissue {name!r}; accepted: {', '.join(sorted(TISSUES))}")
    return TISSUES[name](n_terminals, **params)
