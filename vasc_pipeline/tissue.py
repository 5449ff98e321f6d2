"""Tissue domains as voxel grids (SPEC section 3).

A :class:`Tissue` is a binary voxel mask (z, y, x) with isotropic voxels, the position of
the centre of voxel [0, 0, 0], the inlet positions and its exclusion domain: the voxels
large vessels must not penetrate (the tissue itself plus, for the heart, the ventricular
cavities), with that domain's Euclidean distance transform (scipy), the map the
exclusion term uses. Builders return one for each named domain: ``sphere``, ``box``,
``plane2d``, ``heart`` (see :mod:`vasc_pipeline.heart`) and ``mask`` (a user's array).

The grid always extends beyond the tissue (at least one voxel, and a margin where large
vessels are expected to run outside the tissue) so that the distance transform sees a
boundary and bifurcations and inlets have room outside the tissue.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import ndimage

from .physics import supply_radius

__all__ = ["Tissue", "TissueError", "build_tissue", "voxelize", "default_voxel_size", "TISSUES"]

# Voxel edge = R_supply / VOXELS_PER_SUPPLY_RADIUS when a tissue does not fix it:
# ~270 voxels per supply sphere at every N (SPEC section 3).
VOXELS_PER_SUPPLY_RADIUS = 4.0
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
        1 = large vessels excluded (SPEC section 2, C_o). Given: the tissue plus these
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
    distance: np.ndarray = field(init=False, repr=False)

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
        if self.inlets.shape[1] != 3 or len(self.inlets) < 1:
            raise TissueError(
                f"tissue.inlets must be a list of [x, y, z] positions in metres, got {self.inlets.tolist()}"
            )
        if not self.inlet_names:
            self.inlet_names = tuple(f"inlet{k}" for k in range(len(self.inlets)))
        lo, hi = self.bounds
        for k, p in enumerate(self.inlets):
            if np.any(p < lo) or np.any(p > hi):
                raise TissueError(
                    f"inlet {k} ({self.inlet_names[k]}) at {p.tolist()} m lies outside the voxel grid "
                    f"[{lo.tolist()}, {hi.tolist()}] m; tissue.inlets must lie inside the grid"
                )
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
        # Distance to the nearest voxel outside the exclusion domain. The builders pad the
        # grid, but a user's mask may touch its edge: pad here so the grid edge counts as
        # outside, except where an open boundary reaches it (it continues past the edge).
        pad = 1 if self.ndim == 3 else ((0, 0), (1, 1), (1, 1))
        feature = np.pad(self.exclusion, pad).astype(bool)
        if self.open_boundary is not None:
            if self.open_boundary.shape != self.mask.shape:
                raise TissueError(
                    f"tissue '{self.name}': the open boundary has shape {self.open_boundary.shape}, "
                    f"the tissue mask {self.mask.shape}; they must be the same grid"
                )
            feature |= np.pad(np.asarray(self.open_boundary, dtype=bool), pad, mode="edge")
        dist = ndimage.distance_transform_edt(feature)
        inner = dist[1:-1, 1:-1, 1:-1] if self.ndim == 3 else dist[:, 1:-1, 1:-1]
        self.distance = np.ascontiguousarray(inner * self.exclusion, dtype=np.float32)

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

    def contains(self, points: np.ndarray) -> np.ndarray:
        """True where a point lies in a tissue voxel."""
        idx = self.voxel_index(points)
        inside = np.all((idx >= 0) & (idx < np.array(self.mask.shape)), axis=-1)
        out = np.zeros(inside.shape, dtype=bool)
        sel = idx[inside]
        out[inside] = self.mask[sel[:, 0], sel[:, 1], sel[:, 2]] == 1
        return out


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
    axes = [origin[a] + voxel_size * np.arange(counts[a]) for a in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return inside(x, y, z).astype(np.uint8), origin


def default_voxel_size(
    n_terminals: int, measure: float, ndim: int, q_required: float | None = None, total_flow: float | None = None
) -> float:
    """R_supply / 4 (SPEC section 3) for the given tissue measure (volume, or area in 2-D).

    R_supply is :func:`vasc_pipeline.physics.supply_radius`, the one formula the cost uses,
    so a given ``tissue.q_required`` sizes the voxels too.
    """
    return supply_radius(n_terminals, measure, ndim, q_required, total_flow) / VOXELS_PER_SUPPLY_RADIUS


def sphere(
    n_terminals: int,
    radius: float = 0.02,
    voxel_size: float | None = None,
    q_required: float | None = None,
    total_flow: float | None = None,
    **_,
) -> Tissue:
    """A ball of tissue centred at the origin; the inlet sits just above its north pole."""
    if not radius > 0:
        raise TissueError(f"tissue.radius must be a positive length in metres, got {radius}")
    h = voxel_size or default_voxel_size(n_terminals, 4.0 / 3.0 * math.pi * radius**3, 3, q_required, total_flow)
    mask, origin = voxelize(
        lambda x, y, z: x**2 + y**2 + z**2 <= radius**2, [-radius] * 3, [radius] * 3, h, margin=0.25 * radius
    )
    return Tissue("sphere", mask, h, origin, [[0.0, 0.0, radius + 0.1 * radius]], inlet_names=("root",))


def box(
    n_terminals: int,
    size: tuple[float, float, float] = (0.04, 0.04, 0.02),
    voxel_size: float | None = None,
    q_required: float | None = None,
    total_flow: float | None = None,
    **_,
) -> Tissue:
    """A rectangular block [0, size] of tissue; the inlet sits above the centre of its top face."""
    size = np.asarray(size, dtype=np.float64)
    if size.shape != (3,) or np.any(size <= 0):
        raise TissueError(f"tissue.size must be three positive lengths [x, y, z] in metres, got {size.tolist()}")
    h = voxel_size or default_voxel_size(n_terminals, float(np.prod(size)), 3, q_required, total_flow)
    mask, origin = voxelize(
        lambda x, y, z: (x >= 0) & (x <= size[0]) & (y >= 0) & (y <= size[1]) & (z >= 0) & (z <= size[2]),
        [0, 0, 0],
        size,
        h,
        margin=0.1 * size.min(),
    )
    inlet = [0.5 * size[0], 0.5 * size[1], size[2] + 0.05 * size.min()]
    return Tissue("box", mask, h, origin, [inlet], inlet_names=("root",))


def plane2d(n_terminals: int, side: float = 0.1, voxel_size: float | None = None, **_) -> Tissue:
    """The paper's convergence test: a side x side square in the plane z = 0, inlet at a corner."""
    if not side > 0:
        raise TissueError(f"tissue.side must be a positive length in metres, got {side}")
    h = voxel_size or default_voxel_size(n_terminals, side**2, 2)
    mask, origin = voxelize(
        lambda x, y, z: (x >= 0) & (x <= side) & (y >= 0) & (y <= side), [0, 0, 0], [side, side, 0], h, ndim=2
    )
    return Tissue("plane2d", mask, h, origin, [[0.0, 0.0, 0.0]], ndim=2, inlet_names=("root",))


def heart(n_terminals: int, voxel_size: float | None = None, **params) -> Tissue:
    """The paper's coronary substrate; see :mod:`vasc_pipeline.heart`."""
    from . import heart as heart_model

    return heart_model.heart_tissue(n_terminals, voxel_size=voxel_size, **params)


def _load_mask_array(path: str, array: str | None, field: str) -> tuple[np.ndarray, dict]:
    """(data, attrs) of a ``.npy`` file or a Zarr array; errors name ``tissue.<field>``."""
    p = Path(path).expanduser()
    if not p.exists():
        raise TissueError(f"tissue.{field}: mask file {str(p)!r} does not exist")
    attrs: dict = {}
    try:
        if p.suffix == ".npy":
            with open(p, "rb") as fh:
                head = fh.read(64)
            if not head.startswith(b"\x93NUMPY"):  # np.load would call anything else "pickled data"
                kind = (
                    "a text file"
                    if head and all(32 <= b < 127 or b in b"\t\r\n" for b in head)
                    else "a binary file of another format"
                )
                raise TissueError(
                    f"tissue.{field}: {str(p)!r} is {kind}, not a NumPy .npy array (it starts with "
                    f"{head[:24]!r}); save the mask with numpy.save, or give a Zarr array"
                )
            data = np.load(p, allow_pickle=False)
        else:
            import zarr

            node = zarr.open(str(p), mode="r")
            if array:
                node = node[array]
            if not hasattr(node, "shape"):
                raise TissueError(f"tissue.{field}: {str(p)!r} is a Zarr group; name the mask's array in it")
            data = node[...]
            attrs = dict(node.attrs)
    except TissueError:
        raise
    except Exception as exc:  # unreadable file: say which and why
        raise TissueError(f"tissue.{field}: cannot read mask {str(p)!r}: {exc}") from exc
    if data.ndim not in (2, 3):
        raise TissueError(f"tissue.{field}: the mask must be 2-D (y, x) or 3-D (z, y, x), got shape {data.shape}")
    if np.issubdtype(data.dtype, np.inexact) and not np.all(np.isfinite(data)):
        bad = int(np.count_nonzero(~np.isfinite(data)))
        raise TissueError(
            f"tissue.{field}: the mask {str(p)!r} holds {bad} NaN or infinite voxels; every voxel must "
            "be a number (nonzero = tissue, 0 = outside)"
        )
    return data, attrs


def mask(
    n_terminals: int,
    path: str | None = None,
    voxel_size: float | None = None,
    origin=None,
    inlets=None,
    array: str | None = None,
    exclusion_path: str | None = None,
    exclusion_array: str | None = None,
    **_,
) -> Tissue:
    """A user's voxel mask from a ``.npy`` file or a Zarr array (medical-image segmentations).

    ``path`` names a ``.npy`` file or a Zarr store (``array`` then names the array inside
    it, default the store's root array). The array is (z, y, x) or (y, x) for a 2-D tissue,
    nonzero = tissue. ``voxel_size`` [m] and ``origin`` (the [x, y, z] of the centre of voxel
    [0, 0, 0], m) come from the config, else from the Zarr array's attrs of the same names.
    ``inlets`` is a list of [x, y, z] positions [m]. ``exclusion_path`` (and
    ``exclusion_array``), optional: a second mask on the same grid whose nonzero voxels
    large vessels must not cross either, although they need no supply (cavities, bone).
    """
    if not path:
        raise TissueError("tissue.path is required for tissue=mask: a .npy file or a Zarr array")
    data, attrs = _load_mask_array(path, array, "path")
    if data.size == 0 or not np.any(data):
        raise TissueError(f"tissue.path: the mask {path!r} is empty (no nonzero voxel)")
    ndim = data.ndim
    h = voxel_size if voxel_size is not None else attrs.get("voxel_size")
    if h is None or not float(h) > 0:
        raise TissueError(f"tissue.voxel_size must be > 0 (metres) for tissue=mask, got {h}")
    org = origin if origin is not None else attrs.get("origin", [0.0, 0.0, 0.0])
    org = np.asarray(org, dtype=np.float64)
    if org.shape != (3,):
        raise TissueError(f"tissue.origin must be [x, y, z] in metres, got {org.tolist()}")
    if inlets is None:
        raise TissueError("tissue.inlets is required for tissue=mask: a list of [x, y, z] positions in metres")
    grid = (np.asarray(data) != 0).astype(np.uint8)
    extra = None
    if exclusion_path:
        extra, _ = _load_mask_array(exclusion_path, exclusion_array, "exclusion_path")
        if extra.shape != data.shape:
            raise TissueError(
                f"tissue.exclusion_path: the exclusion mask has shape {extra.shape}, the tissue mask "
                f"(tissue.path) {data.shape}; they must be the same grid"
            )
        extra = (np.asarray(extra) != 0).astype(np.uint8)
    if ndim == 2:
        grid = grid[None]
        extra = None if extra is None else extra[None]
    return Tissue("mask", grid, float(h), org, inlets, ndim=ndim, exclusion=extra)


TISSUES: dict[str, Callable[..., Tissue]] = {
    "heart": heart,
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
