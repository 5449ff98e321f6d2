"""The voxel grid of a tissue: the :class:`Tissue` class and the helpers its builders share.

A :class:`Tissue` is a binary voxel mask (z, y, x) with isotropic voxels, the position of
the centre of voxel [0, 0, 0], the inlet positions and its exclusion domain: the voxels
large vessels must not penetrate (the tissue itself plus, for the heart, the ventricular
cavities), with that domain's Euclidean distance transform (scipy), the map the
exclusion term uses. :func:`voxelize` turns an ``inside(x, y, z)`` predicate into a mask
on a padded grid, :func:`default_voxel_size` is the voxel edge a tissue gets when its config
does not fix one (R_supply / 4, so a supply sphere spans ~270 voxels at every N), and
:func:`check_grid_memory` refuses a grid that would not fit in memory. The builders are in
:mod:`vasc_pipeline.model.tissue.shapes` and :mod:`vasc_pipeline.model.tissue.heart`.

The grid always extends beyond the tissue (at least one voxel, and a margin where large
vessels are expected to run outside the tissue) so that the distance transform sees a
boundary and bifurcations and inlets have room outside the tissue.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ..physics import supply_radius

__all__ = [
    "Tissue",
    "TissueError",
    "ExclusionGrid",
    "exclusion_distance",
    "resampled_exclusion_grid",
    "voxelize",
    "grid_axes",
    "default_voxel_size",
    "check_grid_memory",
    "check_voxel_scale",
    "VOXELS_PER_SUPPLY_RADIUS",
    "MASK_VOXEL_RANGE",
    "MASK_EXTENT_RANGE",
]

# Voxel edge = R_supply / VOXELS_PER_SUPPLY_RADIUS when a tissue does not fix it:
# ~270 voxels per supply sphere at every N.
VOXELS_PER_SUPPLY_RADIUS = 4.0
# The scale of a user's grid (tissue=mask): images of organs, micro-CT to clinical CT and MRI, have voxel
# edges of 1 um to 10 mm, and organs span 0.1 mm (a zebrafish heart) to 2 m (a whole human body). Outside
# these a voxel size is almost surely in another unit (millimetres given as metres, a header's unit wrong),
# which would run to the end and show only in the morphometry.
MASK_VOXEL_RANGE = (1e-6, 1e-2)  # m
MASK_EXTENT_RANGE = (1e-4, 2.0)  # m, the tissue's largest extent along x, y or z
# Peak bytes per voxel while a grid is built: three float64 coordinate grids, the boolean and
# uint8 masks, the distance transform (float64 distances and int32 feature indices per axis)
# and its float32 copy. An estimate that refuses a grid before it is allocated.
BUILD_BYTES_PER_VOXEL = 3 * 8 + 2 + 8 + 3 * 4 + 4


def _physical_memory() -> int:
    """Bytes of memory of this machine (the ceiling for one tissue grid)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not POSIX: no ceiling known
        return 2**62


def check_grid_memory(counts, voxel_size: float) -> None:
    """Refuse (TissueError) a grid whose construction would not fit in this machine's memory."""
    n = math.prod(int(c) for c in counts)
    need = n * BUILD_BYTES_PER_VOXEL
    have = _physical_memory()
    if need > have:
        shape = " x ".join(str(int(c)) for c in counts)
        raise TissueError(
            f"tissue.voxel_size={voxel_size:.4g} m gives a voxel grid of {shape} = {n:.3g} voxels, which needs about "
            f"{need / 2**30:.3g} GiB to build, more than the {have / 2**30:.3g} GiB of memory here; set a larger "
            "tissue.voxel_size (unset, it is R_supply / 4, so it shrinks as n_terminals grows: lower n_terminals)"
        )


class TissueError(ValueError):
    """A tissue configuration that cannot be built; the message names the field."""


def check_voxel_scale(tissue: Tissue, supply_radius: float | None = None, n_terminals: int | None = None) -> None:
    """Refuse (TissueError) a voxel size the model cannot use: on a user's grid
    (:attr:`Tissue.voxel_size_from` set: ``tissue=mask``) voxels or a tissue at a scale no organ
    has (:data:`MASK_VOXEL_RANGE`, :data:`MASK_EXTENT_RANGE`), and, given the supply radius
    [m], one coarser than the supply sphere (the supply term counts the voxels within R_supply
    of a terminal: it needs several).

    A :class:`Tissue` checks the first itself, before its inlets (which a grid in the wrong unit
    misplaces); :func:`vasc_pipeline.engine.build_problem` checks both once R_supply is known.
    """
    h = float(tissue.voxel_size)
    given = tissue.voxel_size_from
    if given is not None:
        unit = (
            "tissue.voxel_size is in metres (1 mm is 0.001)"
            if given.startswith("tissue.voxel_size")
            else "is the header's unit right? (NIfTI's xyzt_units, NRRD's space units; unset means mm)"
        )
        lo, hi = MASK_VOXEL_RANGE
        if not lo <= h <= hi:
            raise TissueError(
                f"{given} gives voxels of {h * 1e3:.4g} mm, outside [{lo * 1e3:g}, {hi * 1e3:g}] mm, the voxel "
                f"edges of images of organs (micro-CT to clinical CT and MRI): {unit}"
            )
        voxels = 0
        for axis in range(3):  # the tissue's extent along each axis, from its projections (no copy per voxel)
            occupied = np.flatnonzero(tissue.mask.any(axis=tuple(a for a in range(3) if a != axis)))
            voxels = max(voxels, int(occupied[-1] - occupied[0]) + 1)
        extent = voxels * h
        lo, hi = MASK_EXTENT_RANGE
        if not lo <= extent <= hi:
            raise TissueError(
                f"{given} gives the tissue of {tissue.source!r} an extent of {extent * 1e3:.4g} mm ({voxels} voxels "
                f"of {h * 1e3:.4g} mm), outside [{lo * 1e3:g}, {hi * 1e3:g}] mm, the sizes of organs (a zebrafish "
                f"heart to a whole human body): {unit}"
            )
    if supply_radius is not None and supply_radius / h < 1.0:
        what = f"tissue.voxel_size={h:.4g} m" if given is None else f"{given}: voxels of {h * 1e3:.4g} mm"
        raise TissueError(
            f"{what} is coarser than the supply sphere (R_supply = {supply_radius:.4g} m at n_terminals="
            f"{n_terminals}; the grid is {tissue.shape[2]} x {tissue.shape[1]} x {tissue.shape[0]} voxels): the "
            "largest accepted voxel_size is R_supply. Set a smaller tissue.voxel_size, or leave it unset (R_supply / 4)"
        )


@dataclass(frozen=True, eq=False)
class ExclusionGrid:
    """The voxel grid the exclusion term C_o is summed on.

    By default the tissue's own grid; with ``tissue.exclusion_voxel_size`` a grid of its
    own, fixed in metres, so that the exclusion of a given tree does not change with N
    (on the supply grid, whose voxel follows N, it grows as voxel^-7). The coarse map of
    ``anneal.coarse_exclusion_*`` is this grid :meth:`coarsened`.

    Attributes
    ----------
    distance : float32 ndarray (nz, ny, nx)
        Depth D of each voxel of the exclusion domain, in this grid's voxel units (0 outside).
    origin : float64 ndarray (3,)
        [x, y, z] of the centre of voxel [0, 0, 0] [m].
    voxel_size : float
        Edge of the isotropic voxels [m].
    """

    distance: np.ndarray
    origin: np.ndarray
    voxel_size: float

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.distance.shape

    def coarsened(self, factor: int) -> ExclusionGrid:
        """This grid ``factor`` (an integer) times coarser (z is not coarsened in a one-layer
        grid), for a cheaper exclusion term: a traversal then crosses about 1/factor as many voxels.

        Each coarse voxel holds the largest depth (in this grid's voxel units) of the voxels it
        covers, so it is nowhere shallower than the tissue under it (a vessel cannot sink unseen
        into the tissue below a coarse voxel's centre), times factor^(1/6): a coarse voxel stands
        for about ``factor`` fine ones along a segment, and (factor^(1/6) D L)^6 = factor (D L)^6
        with L in coarse units, so the coarse sum approximates the fine one in its units and no
        weight changes.
        """
        f = int(factor)
        distance = self.distance
        fz = 1 if distance.shape[0] == 1 else f
        padded = np.pad(
            distance, [(0, -distance.shape[0] % fz), (0, -distance.shape[1] % f), (0, -distance.shape[2] % f)]
        )
        nz, ny, nx = padded.shape[0] // fz, padded.shape[1] // f, padded.shape[2] // f
        coarse = padded.reshape(nz, fz, ny, f, nx, f).max(axis=(1, 3, 5)) * np.float32(f ** (1.0 / 6.0))
        centre = 0.5 * (np.array([f, f, fz]) - 1) * self.voxel_size  # of a coarse voxel, from its first fine voxel's
        return ExclusionGrid(coarse, np.asarray(self.origin, dtype=np.float64) + centre, f * self.voxel_size)


def exclusion_distance(exclusion: np.ndarray, open_boundary: np.ndarray | None, ndim: int) -> np.ndarray:
    """float32 (nz, ny, nx): each voxel's distance to the nearest voxel outside the exclusion
    domain (uint8 ``exclusion``), in voxel units, 0 outside it. The grid's edge counts as
    outside, except where ``open_boundary`` (voxels the map looks through) reaches it."""
    pad = 1 if ndim == 3 else ((0, 0), (1, 1), (1, 1))
    feature = np.pad(exclusion, pad).astype(bool)
    if open_boundary is not None:
        feature |= np.pad(np.asarray(open_boundary, dtype=bool), pad, mode="edge")
    dist = ndimage.distance_transform_edt(feature)
    inner = dist[1:-1, 1:-1, 1:-1] if ndim == 3 else dist[:, 1:-1, 1:-1]
    return np.ascontiguousarray(inner * exclusion, dtype=np.float32)


@dataclass
class Tissue:
    """A voxelised tissue domain.

    Attributes
    ----------
    name : str
    mask : uint8 ndarray (nz, ny, nx)
        1 = tissue.
    voxel_size : float
        Edge of the isotropic voxels [m].
    origin : float64 ndarray (3,)
        [x, y, z] of the centre of voxel [0, 0, 0] [m].
    inlets : float64 ndarray (K, 3)
        Inlet positions [m].
    ndim : int
        3, or 2 for a single voxel layer at z = origin[2] (all nodes stay in that plane).
    inlet_names : tuple of str
    exclusion : uint8 ndarray (nz, ny, nx), optional
        1 = large vessels excluded (the domain of C_o). Given: the tissue plus these
        voxels (e.g. cavities, which supply nothing but must not be crossed); default: the
        tissue only.
    open_boundary : bool ndarray (nz, ny, nx), optional
        Voxels outside the exclusion domain that are not part of its surface: the distance
        map looks through them (and past the grid's edge where they touch it). The heart's
        cavity openings above the base plane, so that the plane closing a ventricle is as
        deep as the cavity it closes, not a surface to run along.
    distance : float32 ndarray (nz, ny, nx)
        Distance of each voxel of the exclusion domain to the nearest voxel of its surface
        (outside it and not open), in voxel units (0 outside the domain).
    exclusion_grid : ExclusionGrid
        The grid the exclusion term is summed on: this grid's ``distance`` unless the builder
        (``tissue.exclusion_voxel_size``, :func:`vasc_pipeline.model.tissue.build_tissue`) set another.
    inlets_from : str
        Where the inlets came from (``tissue.inlets``, or ``tissue.inlets_path`` and its file),
        the words an error about them starts with.
    source : str, optional
        The file a user's grid was read from (``tissue.path``); None for a shape built in code.
    voxel_size_from : str, optional
        Where a user's voxel size came from (``tissue.voxel_size``, a label map's header, a Zarr
        attribute), the words :func:`check_voxel_scale` starts with; None for a shape built in code.
    supply_target : uint8 ndarray (nz, ny, nx), optional
        Each tissue voxel's coverage target t in 1..4 from a demand map (``tissue.demand_path``,
        :mod:`~vasc_pipeline.model.tissue.demand`; 0 outside the tissue): its supply cost is
        10 (t - b) below the target, else (b - t)^2. None: t = 1 everywhere.
    """

    name: str
    mask: np.ndarray
    voxel_size: float
    origin: np.ndarray
    inlets: np.ndarray
    ndim: int = 3
    inlet_names: tuple[str, ...] = ()
    exclusion: np.ndarray | None = field(default=None, repr=False)
    open_boundary: np.ndarray | None = field(default=None, repr=False)
    inlets_from: str = field(default="the tissue's own inlets", repr=False)
    source: str | None = field(default=None, repr=False)
    voxel_size_from: str | None = field(default=None, repr=False)
    supply_target: np.ndarray | None = field(default=None, repr=False)
    distance: np.ndarray = field(init=False, repr=False)
    exclusion_grid: ExclusionGrid = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.mask = np.ascontiguousarray(self.mask, dtype=np.uint8)
        self.origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        self.inlets = np.atleast_2d(np.asarray(self.inlets, dtype=np.float64))
        if self.mask.ndim != 3:
            raise TissueError(f"tissue mask must be 3-D (z, y, x) after loading, got shape {self.mask.shape}")
        if not self.mask.any():
            raise TissueError(f"tissue '{self.name}': the mask holds no tissue voxel")
        if not (self.voxel_size > 0 and math.isfinite(self.voxel_size)):
            raise TissueError(f"tissue.voxel_size must be a positive length in metres, got {self.voxel_size}")
        if self.ndim == 2 and self.mask.shape[0] != 1:
            raise TissueError("a 2-D tissue has exactly one voxel layer")
        if self.voxel_size_from is not None:
            check_voxel_scale(self)
        if self.exclusion is None:
            self.exclusion = self.mask.copy()
        else:
            extra = np.asarray(self.exclusion)
            if extra.shape != self.mask.shape:
                raise TissueError(
                    f"tissue '{self.name}': the exclusion mask has shape {extra.shape}, the tissue "
                    f"mask {self.mask.shape}; they must be the same grid"
                )
            self.exclusion = (self.mask | (extra != 0)).astype(np.uint8)
        if self.open_boundary is not None and self.open_boundary.shape != self.mask.shape:
            raise TissueError(
                f"tissue '{self.name}': the open boundary has shape {self.open_boundary.shape}, "
                f"the tissue mask {self.mask.shape}; they must be the same grid"
            )
        self._check_inlets()
        # The builders pad the grid, but a user's mask may touch its edge: the distance map
        # pads it so the grid edge counts as outside (but where an open boundary continues).
        self.distance = exclusion_distance(self.exclusion, self.open_boundary, self.ndim)
        self.exclusion_grid = ExclusionGrid(self.distance, self.origin, float(self.voxel_size))

    def place_inlets(self, inlets, names: tuple[str, ...] = (), source: str = "tissue.inlets") -> None:
        """Replace the tissue's own inlets with ``inlets`` [m] (``tissue.inlets`` or
        ``tissue.inlets_path``, named ``source`` in errors), checked as a builder's are; the grid
        stays the tissue's."""
        self.inlets = np.atleast_2d(np.asarray(inlets, dtype=np.float64))
        self.inlet_names = tuple(names)
        self.inlets_from = source
        self._check_inlets()

    def _check_inlets(self) -> None:
        """Refuse (TissueError starting with :attr:`inlets_from`) inlets that are not [x, y, z]
        positions inside the voxel grid's box, or that lie in a cavity (:attr:`cavity`).

        An inlet may lie in the tissue or outside it (the heart's ostia lie above its base, by the
        aortic root), but not in a voxel of the exclusion domain that is not tissue: its root
        segment would have to cross the cavity large vessels must not cross."""
        if self.inlets.ndim != 2 or self.inlets.shape[1] != 3 or len(self.inlets) < 1:
            raise TissueError(
                f"{self.inlets_from} must hold one or more [x, y, z] positions in metres, got {self.inlets.tolist()}"
            )
        if not self.inlet_names:
            self.inlet_names = tuple(f"inlet{k}" for k in range(len(self.inlets)))
        lo, hi = self.bounds
        for k, p in enumerate(self.inlets):
            if np.any(p < lo) or np.any(p > hi):
                box = ", ".join(f"{axis} [{a * 1e3:.4g}, {b * 1e3:.4g}]" for axis, a, b in zip("xyz", lo, hi))
                raise TissueError(
                    f"{self.inlets_from}: inlet {k} ({self.inlet_names[k]}) at {_mm(p)} lies outside the voxel "
                    f"grid's box, {box} mm"
                    + (" (the plane of a 2-D tissue)" if self.ndim == 2 else "")
                    + "; an inlet must lie inside it (positions in metres)"
                )
        for k in np.flatnonzero(self.contains(self.inlets, self.cavity)):
            if self._opens_outward(self.voxel_index(self.inlets[k])):
                continue  # at the cavity's opening, as the heart's ostia on its base plane may be
            raise TissueError(
                f"{self.inlets_from}: inlet {k} ({self.inlet_names[k]}) at {_mm(self.inlets[k])} lies inside a cavity "
                "of the exclusion domain (voxels large vessels must not cross although they are no tissue: "
                "tissue.labels.exclusion, tissue.exclusion_path, the heart's ventricles), which its root segment "
                "could not leave without crossing; an inlet (ostium) lies in the tissue or in the space outside it"
            )

    def _opens_outward(self, zyx) -> bool:
        """True when a face neighbour of voxel ``zyx`` lies outside the exclusion domain (the grid's
        edge counting as outside): the voxel is on the surface between a cavity and the outside."""
        for axis in range(1 if self.ndim == 2 else 0, 3):  # one layer: no neighbour across the plane
            for step in (-1, 1):
                n = np.array(zyx)
                n[axis] += step
                if np.any(n < 0) or np.any(n >= np.array(self.shape)) or not self.exclusion[tuple(n)]:
                    return True
        return False

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.mask.shape

    @property
    def cavity(self) -> np.ndarray:
        """bool (nz, ny, nx): voxels of the exclusion domain outside the tissue (the heart's cavities)."""
        return (self.exclusion == 1) & (self.mask == 0)

    @property
    def n_tissue_voxels(self) -> int:
        return int(np.count_nonzero(self.mask))

    @property
    def measure(self) -> float:
        """Tissue volume [m^3] (area [m^2] for a 2-D tissue) as voxelised."""
        return self.n_tissue_voxels * self.voxel_size**self.ndim

    @property
    def supply_measure(self) -> float:
        """The volume the N supply spheres fill [m^3] (area in 2-D): each voxel counted
        :attr:`supply_target` times, so R_supply follows the demand-weighted volume; without
        targets, :attr:`measure`."""
        if self.supply_target is None:
            return self.measure
        return float(np.sum(self.supply_target, dtype=np.int64)) * self.voxel_size**self.ndim

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper [x, y, z] corners of the voxel grid's box [m]."""
        nz, ny, nx = self.mask.shape
        half = 0.5 * self.voxel_size
        lo = self.origin - half
        hi = self.origin + np.array([nx - 1, ny - 1, nz - 1]) * self.voxel_size + half
        if self.ndim == 2:  # the plane itself: z is fixed
            lo[2] = hi[2] = self.origin[2]
        return lo, hi

    def voxel_index(self, points: np.ndarray) -> np.ndarray:
        """(z, y, x) integer voxel indices of points (..., 3) [m]; may lie outside the grid."""
        u = (np.asarray(points, dtype=np.float64) - self.origin) / self.voxel_size
        return np.floor(u[..., ::-1] + 0.5).astype(np.int64)

    def contains(self, points: np.ndarray, region: np.ndarray | None = None) -> np.ndarray:
        """True where a point lies in a tissue voxel (or a voxel of ``region``, same grid)."""
        grid = self.mask if region is None else region
        idx = self.voxel_index(points)
        inside = np.all((idx >= 0) & (idx < np.array(grid.shape)), axis=-1)
        out = np.zeros(inside.shape, dtype=bool)
        sel = idx[inside]
        out[inside] = grid[sel[:, 0], sel[:, 1], sel[:, 2]] != 0
        return out

    def distance_outside(self) -> np.ndarray:
        """float (nz, ny, nx): distance [m] of each voxel centre to the nearest voxel of the
        exclusion domain (0 inside it)."""
        return ndimage.distance_transform_edt(self.exclusion == 0) * self.voxel_size

    def bifurcation_region(self, reach: float) -> np.ndarray:
        """uint8 (nz, ny, nx): the voxels within ``reach`` [m] of the exclusion domain, the
        domain included (``tissue.bifurcation_reach``: where a bifurcation may lie).

        Distances are between voxel centres; ``reach`` = 0 is the exclusion domain itself.
        """
        return (self.distance_outside() <= reach).astype(np.uint8)

    def move_into(self, region: np.ndarray, points: np.ndarray) -> np.ndarray:
        """``points`` (n, 3) [m], each outside ``region`` (a uint8 grid of this tissue) moved
        to the centre of the nearest voxel of ``region``; the others unchanged."""
        points = np.array(points, dtype=np.float64)
        outside = ~self.contains(points, region)
        if outside.any():
            _, nearest = ndimage.distance_transform_edt(region == 0, return_indices=True)
            idx = self.voxel_index(points[outside])
            idx = np.clip(idx, 0, np.array(region.shape) - 1)
            zyx = nearest[:, idx[:, 0], idx[:, 1], idx[:, 2]]  # (3, n)
            moved = self.origin + zyx[::-1].T * self.voxel_size
            if self.ndim == 2:
                moved[:, 2] = points[outside, 2]
            points[outside] = moved
        return points


def _mm(point) -> str:
    """A position [m] as an error message gives it: in millimetres, four significant digits."""
    return "[" + ", ".join(f"{v * 1e3:.4g}" for v in np.asarray(point, dtype=np.float64)) + "] mm"


def voxelize(
    inside: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    lo,
    hi,
    voxel_size: float,
    margin: float = 0.0,
    ndim: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Mask of voxels whose centre satisfies ``inside(x, y, z)`` over the box [lo, hi].

    The grid covers the box plus ``margin`` [m] and at least one voxel on every side
    (in-plane only for ``ndim == 2``). Returns (mask uint8 (z, y, x), origin [x, y, z]).
    """
    origin, counts = grid_axes(lo, hi, voxel_size, margin, ndim)
    axes = [origin[a] + voxel_size * np.arange(counts[a]) for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return inside(x, y, z).astype(np.uint8), origin


def grid_axes(lo, hi, voxel_size: float, margin: float = 0.0, ndim: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(origin [x, y, z] of voxel [0, 0, 0]'s centre [m], voxel counts [x, y, z]) of the grid
    :func:`voxelize` lays over the box [lo, hi] plus ``margin`` and a voxel on every side; refuses
    (TissueError) one that would not fit in memory."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    pad = margin + voxel_size
    counts = np.ceil((hi - lo + 2 * pad) / voxel_size).astype(int)
    centre = 0.5 * (lo + hi)
    origin = centre - 0.5 * (counts - 1) * voxel_size
    if ndim == 2:
        counts[2] = 1
        origin[2] = lo[2]
    check_grid_memory(counts, voxel_size)
    return origin, counts


def default_voxel_size(
    n_terminals: int, measure: float, ndim: int, q_required: float | None = None, total_flow: float | None = None
) -> float:
    """R_supply / 4 (~270 voxels per supply sphere) for the given tissue measure (volume, or area in 2-D).

    R_supply is :func:`vasc_pipeline.model.physics.supply_radius`, the one formula the cost uses,
    so a given ``tissue.q_required`` sizes the voxels too.
    """
    return supply_radius(n_terminals, measure, ndim, q_required, total_flow) / VOXELS_PER_SUPPLY_RADIUS


def resampled_exclusion_grid(tissue: Tissue, voxel_size: float) -> ExclusionGrid:
    """The exclusion domain of ``tissue`` (and its open boundary) sampled at the centres of a
    grid of ``voxel_size`` [m] over the same box (nearest voxel), with its distance map: the
    exclusion grid of a tissue that only exists as voxels (a user's mask)."""
    lo, hi = tissue.bounds
    counts = np.maximum(np.ceil((hi - lo) / voxel_size - 1e-9), 1).astype(int)
    origin = lo + 0.5 * voxel_size
    if tissue.ndim == 2:
        counts[2], origin[2] = 1, tissue.origin[2]
    check_grid_memory(counts, voxel_size)
    axes = [origin[a] + voxel_size * np.arange(counts[a]) for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    idx = np.clip(tissue.voxel_index(np.stack([x, y, z], axis=-1)), 0, np.array(tissue.shape) - 1)

    def sample(grid: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(grid[idx[..., 0], idx[..., 1], idx[..., 2]])

    exclusion = sample(tissue.exclusion).astype(np.uint8)
    open_boundary = None if tissue.open_boundary is None else sample(np.asarray(tissue.open_boundary, dtype=bool))
    return ExclusionGrid(exclusion_distance(exclusion, open_boundary, tissue.ndim), origin, float(voxel_size))
