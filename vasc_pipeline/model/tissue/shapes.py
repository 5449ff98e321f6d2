"""The simple tissue domains: ``sphere``, ``box``, ``plane2d`` and a user's voxel ``mask``.

Each builder takes ``n_terminals`` and its ``tissue.*`` config keys (keys meant for other
tissues are ignored) and returns a :class:`~vasc_pipeline.model.tissue.grid.Tissue`; when the
config fixes no voxel size it is :func:`~vasc_pipeline.model.tissue.grid.default_voxel_size`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import images
from .grid import Tissue, TissueError, default_voxel_size, voxelize

__all__ = ["sphere", "box", "plane2d", "mask", "mask_geometry", "given_inlets"]


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


def given_inlets(inlets=None, inlets_path: str | None = None) -> tuple | None:
    """(positions [m], names, the words naming them in errors) of the inlets a config gives,
    ``tissue.inlets`` or ``tissue.inlets_path`` (read here); None when it gives none."""
    if inlets_path:
        if inlets is not None:
            raise TissueError("tissue.inlets and tissue.inlets_path both give the inlets: set one of them")
        points, names = images.read_inlets(inlets_path)
        return points, names, f"tissue.inlets_path ({inlets_path!r})"
    if inlets is None:
        return None
    return inlets, (), "tissue.inlets"


def mask_geometry(path: str | None, array: str | None = None, voxel_size=None, origin=None, stored=None) -> tuple:
    """(``tissue.voxel_size``, ``tissue.origin``) as a mask run takes them: the config's where set,
    else a label map's header or a Zarr array's attrs (``stored``, when already read); the origin
    at last [0, 0, 0], the voxel size None (the builder then refuses it). Reads headers and attrs
    only; a file that cannot be read keeps the config's values (the builder says why)."""
    if stored is None:
        stored = {}
        try:
            p = Path(path).expanduser()
            if images.is_label_map(p):
                h, o = images.label_map_geometry(p)
                stored = {"voxel_size": h, "origin": o.tolist()}
            elif p.suffix != ".npy":
                import zarr

                node = zarr.open(str(p), mode="r")
                stored = dict((node[array] if array else node).attrs)
        except Exception:  # noqa: BLE001 (reported by the builder, which reads the data)
            pass
    h = voxel_size if voxel_size is not None else stored.get("voxel_size")
    o = origin if origin is not None else stored.get("origin", [0.0, 0.0, 0.0])
    return h, o


def _load_mask_array(path: str, array: str | None, field: str, what: str = "mask") -> tuple[np.ndarray, dict]:
    """(data, attrs) of a ``.npy`` file or a Zarr array; errors name ``tissue.<field>`` and the file as ``what``."""
    p = Path(path).expanduser()
    if not p.exists():
        raise TissueError(f"tissue.{field}: {what} file {str(p)!r} does not exist")
    if images.is_label_map(p):  # NIfTI or NRRD: spacing and origin from the header
        data, h, origin = images.read_label_map(p, field)
        return data, {"voxel_size": h, "origin": origin.tolist()}
    if p.is_file() and p.suffix != ".npy":  # Zarr would call it "No group found in store"
        raise TissueError(f"tissue.{field}: {str(p)!r} is not a {what} this reads; accepted: {images.MASK_FORMATS}")
    if p.is_dir() and not any((p / name).is_file() for name in ("zarr.json", ".zarray", ".zgroup")):
        raise TissueError(
            f"tissue.{field}: {str(p)!r} is a directory but not a Zarr store (no zarr.json, .zarray or .zgroup in "
            f"it); accepted: {images.MASK_FORMATS}"
        )
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
                    f"{head[:24]!r}); save the {what} with numpy.save, or give a Zarr array"
                )
            data = np.load(p, allow_pickle=False)
        else:
            import zarr

            node = zarr.open(str(p), mode="r")
            if array:
                node = node[array]
            if not hasattr(node, "shape"):
                raise TissueError(
                    f"tissue.{field}: {str(p)!r} is a Zarr group; name the {what}'s array in it"
                    + (f" (as a path: {str(p / 'ARRAY')!r})" if field == "demand_path" else "")
                )
            data = node[...]
            attrs = dict(node.attrs)
    except TissueError:
        raise
    except Exception as exc:  # unreadable file: say which and why
        raise TissueError(f"tissue.{field}: cannot read {what} {str(p)!r}: {exc}") from exc
    if data.ndim not in (2, 3):
        raise TissueError(f"tissue.{field}: the {what} must be 2-D (y, x) or 3-D (z, y, x), got shape {data.shape}")
    if what == "mask" and np.issubdtype(data.dtype, np.inexact) and not np.all(np.isfinite(data)):
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
    labels: dict | None = None,
    inlets_path: str | None = None,
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

    ``path`` may also be a NIfTI (``.nii``, ``.nii.gz``) or NRRD label map
    (:mod:`vasc_pipeline.model.tissue.images`): voxel size and origin then come from its header.
    ``labels`` (``tissue.labels``) reads a label map by value: ``supply`` the tissue's labels
    (default: every nonzero label not named below), ``exclusion`` those large vessels must not
    cross although they need no supply (cavities), ``open`` those the exclusion map looks through
    (the space above a heart's base cut). ``inlets_path``: the inlets from a JSON or CSV file
    (:func:`~vasc_pipeline.model.tissue.images.read_inlets`), instead of ``inlets``.
    """
    if not path:
        raise TissueError("tissue.path is required for tissue=mask: a .npy file or a Zarr array")
    data, attrs = _load_mask_array(path, array, "path")
    if data.size == 0 or not np.any(data):
        raise TissueError(f"tissue.path: the mask {path!r} is empty (no nonzero voxel)")
    ndim = data.ndim
    h, org, voxel_size_from = _mask_placement(path, array, voxel_size, origin, attrs)
    given = given_inlets(inlets, inlets_path)
    if given is None:
        raise TissueError(
            "tissue.inlets (a list of [x, y, z] positions in metres) or tissue.inlets_path is required for tissue=mask"
        )
    inlets, names, inlets_from = given
    by_label = {k: v for k, v in (labels or {}).items() if v is not None}
    grid = (np.asarray(data) != 0).astype(np.uint8)
    extra = open_boundary = None
    if by_label:
        if exclusion_path:
            raise TissueError(
                "tissue.labels.exclusion and tissue.exclusion_path both give the exclusion domain: set one"
            )
        grid, extra, open_boundary = _label_domains(data, by_label, path)
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
    if ndim == 2 and open_boundary is not None:
        open_boundary = open_boundary[None]
    return Tissue(
        "mask",
        grid,
        float(h),
        org,
        inlets,
        ndim=ndim,
        inlet_names=names,
        exclusion=extra,
        open_boundary=open_boundary,
        inlets_from=inlets_from,
        source=str(path),
        voxel_size_from=voxel_size_from,
    )


def _mask_placement(path, array, voxel_size, origin, attrs) -> tuple[float, np.ndarray, str]:
    """(voxel size [m], origin [m], where the voxel size came from) of a mask: a label map's header,
    else the config, else the Zarr array's attrs; a config that contradicts a header is refused."""
    if images.is_label_map(path):  # the header places the image: a config that says otherwise is a mistake
        for key, given, stored in (
            ("voxel_size", voxel_size, attrs["voxel_size"]),
            ("origin", origin, attrs["origin"]),
        ):
            if given is not None and not np.allclose(given, stored, rtol=1e-9, atol=1e-12):
                raise TissueError(
                    f"tissue.{key}={given} contradicts the header of {path!r} ({stored}); leave it unset (null)"
                )
    h, org = mask_geometry(path, array, voxel_size, origin, stored=attrs)
    if h is None or not float(h) > 0:
        raise TissueError(f"tissue.voxel_size must be > 0 (metres) for tissue=mask, got {h}")
    if images.is_label_map(path):  # a config's voxel_size is the header's (a run records the value taken)
        voxel_size_from = f"the header of tissue.path ({path!r})"
    elif voxel_size is not None:
        voxel_size_from = f"tissue.voxel_size={float(h):.4g} (for tissue.path {path!r})"
    else:
        voxel_size_from = f"the voxel_size attribute of tissue.path ({path!r})"
    org = np.asarray(org, dtype=np.float64)
    if org.shape != (3,):
        raise TissueError(f"tissue.origin must be [x, y, z] in metres, got {org.tolist()}")
    return h, org, voxel_size_from


def _label_domains(data: np.ndarray, by_label: dict, path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(tissue uint8, exclusion uint8 or None, open bool or None) of a label map read by
    ``tissue.labels``; every label named must be in some voxel, and some tissue must be left."""
    present = set(np.unique(data).tolist())
    for role, values in by_label.items():  # a label in no voxel is a mistake in every role
        missing = [v for v in values if v not in present]
        if missing:
            raise TissueError(
                f"tissue.labels.{role}: no voxel of {path!r} holds the labels {missing} (its labels: "
                f"{sorted(present)[:20]}{', ...' if len(present) > 20 else ''})"
            )
    named = np.isin(data, [v for k in ("exclusion", "open") for v in by_label.get(k, [])])
    grid = (np.isin(data, by_label["supply"]) if "supply" in by_label else (data != 0) & ~named).astype(np.uint8)
    if not grid.any():
        raise TissueError(
            f"tissue.labels.supply: no voxel of {path!r} is left for the tissue: every nonzero label is named "
            f"exclusion or open (its labels: {sorted(present)[:20]})"
        )
    extra = np.isin(data, by_label["exclusion"]).astype(np.uint8) if "exclusion" in by_label else None
    open_boundary = np.isin(data, by_label["open"]) if "open" in by_label else None
    return grid, extra, open_boundary
