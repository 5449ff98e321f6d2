"""Medical-image label maps in and out: NIfTI (``.nii``, ``.nii.gz``) and NRRD (``.nrrd``,
``.nhdr``), the formats segmented hearts come in (``pip install 'vasc_pipeline[images]'``:
nibabel, pynrrd).

:func:`read_label_map` returns the labels as a (z, y, x) array with the isotropic voxel edge
and the [x, y, z] centre of voxel [0, 0, 0] in the image's world frame (NIfTI's RAS+; an NRRD
in LPS is turned into RAS, so one image gives one tissue in either format). Images stored
with flipped or permuted axes are reoriented to that frame; an oblique (rotated) grid or
anisotropic voxels are refused with the spacing in the message (resample it first, e.g. with
SimpleITK or 3D Slicer). :func:`write_label_map` writes a NIfTI label map the other way.

    python -m vasc_pipeline.model.tissue heart.nii.gz [N_TERMINALS]

writes the shipped heart as a label map (1 myocardium, 2 cavities, 3 the open space above the
base that the exclusion map looks through) and its ostia as ``heart.inlets.json``; feed it back
with ``tissue=mask tissue.path=heart.nii.gz tissue.labels.supply=[1] tissue.labels.exclusion=[2]
tissue.labels.open=[3] tissue.inlets_path=heart.inlets.json``: the same tissue.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from .grid import Tissue, TissueError

__all__ = [
    "LABEL_MAP_SUFFIXES",
    "MASK_FORMATS",
    "HEART_LABELS",
    "is_label_map",
    "read_label_map",
    "label_map_geometry",
    "write_label_map",
    "read_inlets",
    "write_heart",
]

LABEL_MAP_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".nhdr")
# What tissue.path (and tissue.exclusion_path) reads, for the messages that refuse anything else.
MASK_FORMATS = (
    "a NumPy .npy file, a Zarr array or group (a directory), or a NIfTI (.nii, .nii.gz) or NRRD (.nrrd, .nhdr) "
    "label map"
)
# The label values write_heart uses: myocardium (supply), cavities (excluded), open base.
HEART_LABELS = {"supply": 1, "exclusion": 2, "open": 3}
_ISOTROPY = 1e-4  # relative spread of the voxel edges accepted as isotropic
_ALIGNED = 1e-6  # off-axis part of a voxel axis, relative to its length, accepted as aligned


def is_label_map(path) -> bool:
    name = str(path).lower()
    return name.endswith(LABEL_MAP_SUFFIXES)


def _reoriented(affine: np.ndarray, shape: tuple, field: str, path) -> tuple[np.ndarray, np.ndarray, float]:
    """(nibabel orientation, voxel-to-world affine after it, voxel edge) of an image of ``shape``
    (i, j, k) with the voxel-to-world ``affine`` (RAS, m): its axes flipped and permuted onto +x,
    +y, +z; an oblique grid or anisotropic voxels refused."""
    from nibabel.orientations import inv_ornt_aff, io_orientation

    if len(shape) == 4 and shape[3] == 1:
        shape = shape[:3]
    if len(shape) != 3:
        raise TissueError(f"tissue.{field}: the label map {str(path)!r} must be 3-D, got shape {tuple(shape)}")
    ornt = io_orientation(affine)
    affine = affine @ inv_ornt_aff(ornt, shape)  # the shape before reorientation
    axes = affine[:3, :3]
    spacing = np.linalg.norm(axes, axis=0)
    off_axis = np.abs(axes - np.diag(np.diag(axes))).max(axis=0) / spacing
    if np.any(off_axis > _ALIGNED):
        raise TissueError(
            f"tissue.{field}: the label map {str(path)!r} has an oblique grid (its voxel axes are rotated "
            f"against x, y, z by up to {np.degrees(np.arcsin(min(off_axis.max(), 1.0))):.2g} degrees); resample "
            "it onto an axis-aligned grid first"
        )
    if spacing.max() - spacing.min() > _ISOTROPY * spacing.max():
        raise TissueError(
            f"tissue.{field}: the label map {str(path)!r} has anisotropic voxels, "
            f"{' x '.join(f'{s * 1e3:.4g}' for s in spacing)} mm (x, y, z); the model needs isotropic voxels: "
            "resample it to one edge first"
        )
    return ornt, affine, float(spacing.mean())


def _nrrd_affine(header: dict, field: str, path) -> np.ndarray:
    directions = np.asarray(header.get("space directions"), dtype=float)
    if directions.shape != (3, 3):
        raise TissueError(
            f"tissue.{field}: the NRRD file {str(path)!r} has no 3-D 'space directions' "
            f"(got {header.get('space directions')!r}); it must be a 3-D image with a spatial frame"
        )
    affine = np.eye(4)
    affine[:3, :3] = directions.T  # one column per index axis
    affine[:3, 3] = np.asarray(header.get("space origin", np.zeros(3)), dtype=float)
    space = str(header.get("space", "right-anterior-superior")).lower()
    if space in ("left-posterior-superior", "lps"):
        affine[:2] *= -1.0  # LPS -> RAS
    elif space not in ("right-anterior-superior", "ras"):
        raise TissueError(f"tissue.{field}: the NRRD file {str(path)!r} has space {space!r}; accepted: RAS or LPS")
    return affine


_UNITS = {"mm": 1e-3, "m": 1.0, "meter": 1.0, "micron": 1e-6, "um": 1e-6}


def _open(path, field: str, with_data: bool):
    """(data (i, j, k) or None, shape, voxel-to-world affine in metres) of a label map."""
    is_nrrd = str(path).lower().endswith((".nrrd", ".nhdr"))
    try:
        if is_nrrd:
            import nrrd

            data, header = nrrd.read(str(path)) if with_data else (None, nrrd.read_header(str(path)))
            affine = _nrrd_affine(header, field, path)
            unit = header.get("space units", ["mm"])[0]
            shape = tuple(int(n) for n in header["sizes"])
        else:
            import nibabel

            image = nibabel.load(str(path))
            data = np.asanyarray(image.dataobj) if with_data else None
            affine, shape = image.affine, image.shape
            unit = image.header.get_xyzt_units()[0]
            unit = unit if unit not in (None, "unknown") else "mm"  # unset: mm, as viewers read it
    except ImportError as exc:
        raise TissueError(
            f"tissue.{field}: reading {str(path)!r} needs {exc.name}: pip install 'vasc_pipeline[images]'"
        ) from exc
    except TissueError:
        raise
    except Exception as exc:  # a damaged or foreign file: the reader's own words only as detail
        kind, reader = ("NRRD", "pynrrd") if is_nrrd else ("NIfTI", "nibabel")
        raise TissueError(
            f"tissue.{field}: {str(path)!r} is not a readable {kind} label map: the file is damaged, truncated or "
            f"not {kind} ({reader}: {type(exc).__name__}: {exc}); write it again from the segmentation, or give "
            f"another of the formats read: {MASK_FORMATS}"
        ) from exc
    if str(unit).lower() not in _UNITS:
        raise TissueError(f"tissue.{field}: the label map {str(path)!r} is in {unit!r}; accepted: mm, m, um")
    affine = np.array(affine, dtype=float)
    affine[:3] *= _UNITS[str(unit).lower()]  # world in metres
    return data, shape, affine


def label_map_geometry(path, field: str = "path") -> tuple[float, np.ndarray]:
    """(voxel edge [m], origin [x, y, z] of voxel [0, 0, 0]'s centre [m]) of a label map, as
    :func:`read_label_map` gives them, from its header alone."""
    _, shape, affine = _open(path, field, with_data=False)
    _, affine, h = _reoriented(affine, shape, field, path)
    return h, affine[:3, 3].copy()


def read_label_map(path, field: str = "path") -> tuple[np.ndarray, float, np.ndarray]:
    """(labels (z, y, x), voxel edge [m], origin [x, y, z] of voxel [0, 0, 0]'s centre [m]) of a
    NIfTI or NRRD label map (header in mm unless it says otherwise), reoriented to +x, +y, +z."""
    from nibabel.orientations import apply_orientation

    data, shape, affine = _open(path, field, with_data=True)
    ornt, affine, h = _reoriented(affine, shape, field, path)
    data = apply_orientation(np.asarray(data).reshape(shape[:3]), ornt)
    return np.ascontiguousarray(data.transpose(2, 1, 0)), h, affine[:3, 3].copy()


def write_label_map(path, labels: np.ndarray, voxel_size: float, origin) -> Path:
    """Write ``labels`` (z, y, x; integers) as a NIfTI label map (uint8 below 256 labels) with
    the voxel edge ``voxel_size`` [m] and voxel [0, 0, 0]'s centre at ``origin`` ([x, y, z], m)."""
    import nibabel

    labels = np.asarray(labels)
    dtype = np.uint8 if labels.max() < 256 else np.int32
    affine = np.diag([voxel_size * 1e3] * 3 + [1.0])
    affine[:3, 3] = np.asarray(origin, dtype=float) * 1e3  # mm, NIfTI's unit
    image = nibabel.Nifti1Image(labels.transpose(2, 1, 0).astype(dtype), affine)
    image.header.set_xyzt_units("mm")
    image.set_qform(affine, code=1)
    image.set_sform(affine, code=1)
    nibabel.save(image, str(path))
    return Path(path)


def read_inlets(path) -> tuple[np.ndarray, tuple[str, ...]]:
    """Inlet positions [m] and names from ``tissue.inlets_path``: a JSON object {name: [x, y, z]}
    or list of [x, y, z], or a CSV with columns x, y, z (m) and optionally name."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise TissueError(f"tissue.inlets_path: {str(p)!r} does not exist")
    try:
        if p.suffix.lower() == ".json":
            raw = json.loads(p.read_text())
            names, points = (list(raw), list(raw.values())) if isinstance(raw, dict) else ([], raw)
        else:
            import pandas as pd

            frame = pd.read_csv(p)
            points = frame[["x", "y", "z"]].to_numpy(dtype=float).tolist()
            names = [str(v) for v in frame["name"]] if "name" in frame else []
        points = np.asarray(points, dtype=float)
    except Exception as exc:
        raise TissueError(
            f"tissue.inlets_path: cannot read inlets from {str(p)!r} ({exc}); give a JSON object "
            '{"name": [x, y, z], ...} or a CSV with columns x, y, z (metres) and optionally name'
        ) from exc
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 1 or not np.all(np.isfinite(points)):
        raise TissueError(f"tissue.inlets_path: {str(p)!r} must hold one or more finite [x, y, z] positions (m)")
    return points, tuple(names) or tuple(f"inlet{k}" for k in range(len(points)))


def write_heart(path, n_terminals: int = 200) -> tuple[Path, Path]:
    """The shipped heart at ``n_terminals``'s voxel as a NIfTI label map (:data:`HEART_LABELS`) and
    its ostia as ``<stem>.inlets.json``: what ``tissue=mask`` reads back into the same tissue."""
    from . import build_tissue

    heart: Tissue = build_tissue("heart", n_terminals)
    labels = np.zeros(heart.shape, dtype=np.uint8)
    labels[heart.cavity] = HEART_LABELS["exclusion"]
    labels[heart.open_boundary] = HEART_LABELS["open"]
    labels[heart.mask == 1] = HEART_LABELS["supply"]
    path = Path(path)
    write_label_map(path, labels, heart.voxel_size, heart.origin)
    stem = path.name.removesuffix(".gz").removesuffix(".nii")
    inlets = path.with_name(f"{stem}.inlets.json")
    inlets.write_text(json.dumps(dict(zip(heart.inlet_names, heart.inlets.tolist())), indent=1))
    return path, inlets


if __name__ == "__main__":  # the former command; runpy warns here, the package's own entry does not
    import runpy

    print("vasc_pipeline: the command is now python -m vasc_pipeline.model.tissue", file=sys.stderr)
    runpy.run_module("vasc_pipeline.model.tissue", run_name="__main__", alter_sys=True)
