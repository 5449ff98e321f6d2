"""Tissue domains as voxel grids (isotropic voxels): the registry of named tissues and its builder.

:func:`build_tissue` returns a :class:`Tissue` for each named domain of :data:`TISSUES`:
``sphere``, ``box``, ``plane2d`` and ``mask`` (a user's array) from
:mod:`~vasc_pipeline.model.tissue.shapes`, ``surface`` (a user's closed surface meshes) from
:mod:`~vasc_pipeline.model.tissue.surfaces`, and ``heart``, the paper's coronary substrate, from
:mod:`~vasc_pipeline.model.tissue.heart`. Any of them may carry a perfusion demand map
(:mod:`~vasc_pipeline.model.tissue.demand`). The voxel grid itself (the :class:`Tissue` class, its
distance transform, :func:`voxelize`, :func:`default_voxel_size`) is
:mod:`~vasc_pipeline.model.tissue.grid`.
"""

from __future__ import annotations

from collections.abc import Callable

from . import heart
from .demand import apply_demand
from .grid import (
    VOXELS_PER_SUPPLY_RADIUS,
    ExclusionGrid,
    Tissue,
    TissueError,
    default_voxel_size,
    resampled_exclusion_grid,
    voxelize,
)
from .shapes import box, given_inlets, mask, plane2d, sphere
from .surfaces import surface

__all__ = [
    "Tissue",
    "TissueError",
    "ExclusionGrid",
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
    "surface": surface,
}
# The tissues drawn from shapes: on another grid they are voxelised anew (the user's mask is resampled).
SHAPED_TISSUES = ("heart", "plane2d", "sphere", "box", "surface")
# The tissues with no inlets of their own: their builder takes tissue.inlets or tissue.inlets_path.
OWN_INLETS_REQUIRED = ("mask", "surface")


def build_tissue(
    name: str,
    n_terminals: int,
    exclusion_voxel_size: float | None = None,
    inlets=None,
    inlets_path: str | None = None,
    demand_path: str | None = None,
    **params,
) -> Tissue:
    """Build the named tissue for ``n_terminals`` terminals (params: the tissue config).

    ``inlets`` ([x, y, z] positions [m], ``tissue.inlets``) or ``inlets_path`` (a JSON or CSV
    file, ``tissue.inlets_path``) replace a tissue's own inlets (the heart's ostia, the
    sphere's pole, ...) on its own grid, checked as its own are (inside the grid's box, not
    inside a cavity); ``tissue=mask``, which has none of its own, needs one of them.

    ``exclusion_voxel_size`` [m] (``tissue.exclusion_voxel_size``) gives the exclusion term a
    grid of its own (:attr:`Tissue.exclusion_grid`): a shaped tissue voxelised at that edge, over
    a box that does not depend on N, or a mask's exclusion domain resampled onto it. None, or
    the supply grid's own edge: the supply grid.

    ``demand_path`` (``tissue.demand_path``): a map of relative perfusion demand, sampled onto the
    supply grid and quantised to the supply term's coverage targets (:attr:`Tissue.supply_target`,
    :mod:`~vasc_pipeline.model.tissue.demand`).
    """
    if name not in TISSUES:
        raise TissueError(f"tissue.name: unknown tissue {name!r}; accepted: {', '.join(sorted(TISSUES))}")
    build = TISSUES[name]
    own = {"inlets": inlets, "inlets_path": inlets_path} if name in OWN_INLETS_REQUIRED else {}
    if own:
        tissue = build(n_terminals, **own, **params)
    else:
        tissue = build(n_terminals, **params)
        given = given_inlets(inlets, inlets_path)
        if given is not None:
            tissue.place_inlets(*given)
    if demand_path:
        apply_demand(tissue, demand_path)
    if exclusion_voxel_size is not None and exclusion_voxel_size != tissue.voxel_size:
        try:
            if name in SHAPED_TISSUES:
                # only its exclusion grid is used: the tissue it voxelises is not reported again
                twin = build(n_terminals, **own, **{**params, "voxel_size": exclusion_voxel_size}, report=False)
                tissue.exclusion_grid = twin.exclusion_grid
            else:
                tissue.exclusion_grid = resampled_exclusion_grid(tissue, exclusion_voxel_size)
        except TissueError as exc:
            raise TissueError(f"tissue.exclusion_voxel_size={exclusion_voxel_size:g} m: {exc}") from exc
    return tissue
