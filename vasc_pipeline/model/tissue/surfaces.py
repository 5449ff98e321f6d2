"""Closed surface meshes as the organ: tissue ``surface`` (``pip install 'vasc_pipeline[mesh]'``).

What segmentation tools and svVascularize users hold is a surface, not a voxel map: the organ's
outer surface (``tissue.path``) and, optionally, inner surfaces of cavities (``tissue.cavity_paths``:
a heart's blood pools). :func:`read_surface` reads STL, OBJ and PLY with trimesh and VTK XML
PolyData (``.vtp``) with VTK's own reader, and refuses a surface that is not closed: the inside of
a surface with holes is not defined.

The supply grid is voxelised by ray parity: one ray along +z per column of voxel centres
(trimesh's ray engine), and a voxel is inside where an odd number of the surface's crossings lie
below its centre. Crossings one surface point yields twice (a ray through an edge or a vertex
shared by triangles) count once; a column left with an odd count (a ray grazing an edge) is cast
again a millionth of a voxel aside. One ray per column, not one per voxel: trimesh's
``contains`` took 26 s for 2e4 points, against 0.4 s for 1e4 columns.

Supply domain: inside the organ's surface and inside no cavity; exclusion domain: the organ with
its cavities. :func:`write_heart_surfaces` writes the shipped heart as such surfaces (marching
cubes of its analytic shapes, scikit-image), for ``tissue=surface`` to read back.

    python -m vasc_pipeline.model.tissue heart.stl

writes ``heart.stl`` (the heart's outer surface, closed at the base plane), ``heart.lv.stl`` and
``heart.rv.stl`` (the ventricular cavities) and ``heart.inlets.json`` (the ostia).
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from .grid import MASK_EXTENT_RANGE, Tissue, TissueError, default_voxel_size, grid_axes
from .shapes import given_inlets

__all__ = [
    "SURFACE_SUFFIXES",
    "SURFACE_FORMATS",
    "MESH_UNITS",
    "is_surface",
    "read_surface",
    "inside_surface",
    "surface",
    "write_surface",
    "write_heart_surfaces",
]

log = logging.getLogger(__name__)

SURFACE_SUFFIXES = {".stl": "STL", ".obj": "Wavefront OBJ", ".ply": "PLY", ".vtp": "VTK XML PolyData"}
SURFACE_FORMATS = "closed triangle surfaces as STL (.stl), Wavefront OBJ (.obj), PLY (.ply) or VTK XML PolyData (.vtp)"
# tissue.mesh_unit: the unit of the files' coordinates (STL, OBJ and PLY carry none; segmentation tools write mm).
MESH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6}
MARGIN_FRACTION = 0.12  # grid margin around the organ (and inlets), fraction of its largest extent: the heart's
_MERGE = 1e-9  # crossings of one column closer than this many voxels are one crossing (rounding: ~1e-13)
_OFF_LEVEL = 1e-3  # the heart's fields (1 at a shape's centre, 0 on its surface) kept this far off the level
_NUDGES = ((1e-6, 0.7e-6), (-0.8e-6, 1.3e-6), (0.9e-6, -1.1e-6))  # voxels: a grazing column's rays cast again


def is_surface(path) -> bool:
    return Path(str(path)).suffix.lower() in SURFACE_SUFFIXES


def _trimesh(field: str):
    try:
        import trimesh
    except ImportError as exc:
        raise TissueError(f"tissue.{field}: reading surfaces needs trimesh: pip install 'vasc_pipeline[mesh]'") from exc
    return trimesh


def _read_vtp(path: Path, field: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of a VTK XML PolyData file, polygons and strips cut into triangles."""
    try:
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkFiltersCore import vtkTriangleFilter
        from vtkmodules.vtkIOXML import vtkXMLPolyDataReader
    except ImportError as exc:
        raise TissueError(
            f"tissue.{field}: reading {str(path)!r} (VTK XML PolyData) needs vtk: pip install 'vasc_pipeline[mesh]'"
        ) from exc
    reader = vtkXMLPolyDataReader()
    if not reader.CanReadFile(str(path)):
        raise ValueError("VTK's reader does not recognise it as VTK XML PolyData")
    reader.SetFileName(str(path))
    reader.Update()
    triangles = vtkTriangleFilter()
    triangles.SetInputData(reader.GetOutput())
    triangles.PassVertsOff()
    triangles.PassLinesOff()
    triangles.Update()
    poly = triangles.GetOutput()
    if poly.GetNumberOfPoints() == 0 or poly.GetNumberOfPolys() == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vertices = vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    cells = vtk_to_numpy(poly.GetPolys().GetConnectivityArray()).astype(np.int64)
    return vertices, cells.reshape(-1, 3)


def read_surface(path, field: str = "path", unit: str = "m"):
    """The closed surface of ``path`` as a ``trimesh.Trimesh`` in metres (coordinates times
    :data:`MESH_UNITS` [``unit``]), duplicate vertices merged; a TissueError naming
    ``tissue.<field>`` and the file when it is missing, of no format read, unreadable, empty or
    not closed."""
    trimesh = _trimesh(field)
    p = Path(str(path)).expanduser()
    if not p.is_file():
        what = "is a directory" if p.is_dir() else "does not exist"
        raise TissueError(f"tissue.{field}: surface file {str(p)!r} {what}; accepted: {SURFACE_FORMATS}")
    kind = SURFACE_SUFFIXES.get(p.suffix.lower())
    if kind is None:
        raise TissueError(f"tissue.{field}: {str(p)!r} is not a surface this reads; accepted: {SURFACE_FORMATS}")
    try:
        if p.suffix.lower() == ".vtp":
            vertices, faces = _read_vtp(p, field)
        else:
            loaded = trimesh.load(str(p), force="mesh", process=False)
            vertices, faces = np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces)
    except TissueError:
        raise
    except Exception as exc:  # a damaged or foreign file: the reader's words only as detail
        raise TissueError(
            f"tissue.{field}: {str(p)!r} is not a readable {kind} surface: the file is damaged, truncated or of "
            f"another format ({type(exc).__name__}: {exc}); accepted: {SURFACE_FORMATS}"
        ) from exc
    if len(faces) == 0:
        raise TissueError(
            f"tissue.{field}: {str(p)!r} holds no triangle (an empty file, or not {kind} at all); accepted: "
            f"{SURFACE_FORMATS}"
        )
    if not np.all(np.isfinite(vertices)):
        raise TissueError(f"tissue.{field}: {str(p)!r} holds NaN or infinite vertex coordinates")
    # STL stores every triangle with its own corners: merged, shared edges become shared
    mesh = trimesh.Trimesh(vertices * MESH_UNITS[unit], faces, process=True)
    if not mesh.is_watertight:
        edges = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)
        raise TissueError(
            f"tissue.{field}: the surface {str(p)!r} is not closed ({len(edges)} of its edges border one triangle "
            "only, or some border more than two): the inside of a surface is defined only for a closed (watertight) "
            "one; close its holes first (MeshLab: Close Holes; or export the segmentation as a closed surface)"
        )
    return mesh


def inside_surface(mesh, xs: np.ndarray, ys: np.ndarray, zs: np.ndarray, voxel_size: float) -> np.ndarray:
    """bool (nz, ny, nx): which voxel centres of the grid on axes ``xs``, ``ys``, ``zs`` [m] lie inside
    the closed ``mesh`` (ray parity along +z, one ray per column; module docstring)."""
    inside = np.zeros((zs.size, ys.size, xs.size), dtype=bool)
    lo, hi = mesh.bounds
    cols_x = np.flatnonzero((xs >= lo[0]) & (xs <= hi[0]))
    cols_y = np.flatnonzero((ys >= lo[1]) & (ys <= hi[1]))
    if cols_x.size == 0 or cols_y.size == 0:
        return inside
    jj, ii = (a.ravel() for a in np.meshgrid(cols_y, cols_x, indexing="ij"))
    start = lo[2] - 0.5 * (hi[2] - lo[2]) - voxel_size
    todo = np.arange(jj.size)
    offset = np.zeros(2)
    for attempt in range(len(_NUDGES) + 1):
        origins = np.column_stack([xs[ii[todo]] + offset[0], ys[jj[todo]] + offset[1], np.full(todo.size, start)])
        directions = np.tile([0.0, 0.0, 1.0], (todo.size, 1))
        hits, ray, _ = mesh.ray.intersects_location(origins, directions, multiple_hits=True)
        order = np.lexsort((hits[:, 2], ray))
        ray, z = ray[order], hits[order, 2]
        # one surface point hit through several triangles (an edge, a vertex) is one crossing
        keep = np.ones(ray.size, dtype=bool)
        keep[1:] = (ray[1:] != ray[:-1]) | (z[1:] - z[:-1] > _MERGE * voxel_size)
        ray, z = ray[keep], z[keep]
        odd = np.bincount(ray, minlength=todo.size) % 2 == 1
        ok = ~odd[ray]
        # each crossing toggles inside/outside for the voxel centres above it
        k = np.searchsorted(zs, z[ok], side="right")
        toggles = np.zeros((todo.size, zs.size + 1), dtype=np.int32)
        np.add.at(toggles, (ray[ok], k), 1)
        column = (np.cumsum(toggles, axis=1)[:, : zs.size] % 2 == 1) & ~odd[:, None]
        inside[:, jj[todo], ii[todo]] = column.T
        todo = todo[odd]
        if todo.size == 0:
            return inside
        if attempt < len(_NUDGES):
            offset = np.array(_NUDGES[attempt]) * voxel_size
    raise TissueError(
        f"{todo.size} columns of voxel centres cross the surface an odd number of times whatever their nudge: the "
        "surface is not closed where they pass"
    )


def _check_extent(mesh, field: str, path, unit: str) -> None:
    """Refuse a surface at a scale no organ has: the coordinates are almost surely in another unit."""
    lo, hi = MASK_EXTENT_RANGE
    extent = float(np.max(mesh.extents))
    if not lo <= extent <= hi:
        raise TissueError(
            f"tissue.{field}: the surface {str(path)!r} is {extent:.4g} m across with tissue.mesh_unit={unit}, "
            f"outside [{lo * 1e3:g}, {hi * 1e3:g}] mm, the sizes of organs: its coordinates are in another unit; "
            f"set tissue.mesh_unit to theirs ({', '.join(MESH_UNITS)})"
        )


def surface(
    n_terminals: int,
    path: str | None = None,
    cavity_paths: list[str] | None = None,
    mesh_unit: str = "m",
    voxel_size: float | None = None,
    inlets=None,
    inlets_path: str | None = None,
    q_required: float | None = None,
    total_flow: float | None = None,
    *,
    report: bool = True,
    **_,
) -> Tissue:
    """An organ given by its closed outer surface (``path``) and closed cavity surfaces (``cavity_paths``).

    The grid covers the organ's box and the inlets plus a margin of 12 % of the organ's largest
    extent (the heart's); ``voxel_size`` [m] defaults to R_supply / 4 of the supply volume (the
    organ's enclosed volume less its cavities', from the surfaces). Supply: voxel centres inside
    the organ and inside no cavity; exclusion: the organ and its cavities. Inlets from
    ``inlets`` or ``inlets_path`` (required: a surface has none of its own). Logs the voxelised
    volumes at INFO (with ``report=False``, the exclusion grid's twin, at DEBUG).
    """
    if not path:
        raise TissueError(f"tissue.path is required for tissue=surface: a closed surface file ({SURFACE_FORMATS})")
    if mesh_unit not in MESH_UNITS:
        raise TissueError(f"tissue.mesh_unit must be one of {', '.join(MESH_UNITS)}, got {mesh_unit!r}")
    organ = read_surface(path, "path", mesh_unit)
    _check_extent(organ, "path", path, mesh_unit)
    cavities = []
    for i, cavity_path in enumerate(cavity_paths or []):
        cavities.append(read_surface(cavity_path, f"cavity_paths[{i}]", mesh_unit))
    given = given_inlets(inlets, inlets_path)
    if given is None:
        raise TissueError(
            "tissue.inlets (a list of [x, y, z] positions in metres) or tissue.inlets_path is required for "
            "tissue=surface: a surface has no inlets of its own"
        )
    points, names, inlets_from = given
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    volume = abs(float(organ.volume)) - sum(abs(float(c.volume)) for c in cavities)
    if not volume > 0:
        raise TissueError(
            f"tissue.cavity_paths: the cavities enclose {sum(abs(c.volume) for c in cavities) * 1e6:.4g} ml, the "
            f"organ's surface {str(path)!r} {abs(organ.volume) * 1e6:.4g} ml: no tissue is left between them"
        )
    h = voxel_size if voxel_size is not None else default_voxel_size(n_terminals, volume, 3, q_required, total_flow)
    origin, counts = _grid_of(organ, points, h)
    solid, cavity = _voxelised(organ, cavities, origin, counts, h, path, cavity_paths)
    tissue = Tissue(
        "surface",
        (solid & ~cavity).astype(np.uint8),
        float(h),
        origin,
        points,
        inlet_names=names,
        exclusion=solid.astype(np.uint8),
        inlets_from=inlets_from,
        source=str(path),
        voxel_size_from=f"tissue.voxel_size={float(h):.4g} (for tissue.path {str(path)!r})"
        if voxel_size is not None
        else None,
    )
    log.log(
        logging.INFO if report else logging.DEBUG,
        "surface tissue: %.4g ml as voxelised (the surfaces enclose %.4g ml, %+.2f%%), cavities %.4g ml, %d voxels "
        "of %.3g mm, grid %s",
        tissue.measure * 1e6,
        volume * 1e6,
        100.0 * (tissue.measure / volume - 1.0),
        np.count_nonzero(cavity) * h**3 * 1e6,
        tissue.n_tissue_voxels,
        h * 1e3,
        "x".join(map(str, tissue.shape)),
    )
    return tissue


def _grid_of(organ, points: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(origin, counts) of the grid: the organ's box and the inlets near it, plus the margin."""
    lo, hi = organ.bounds
    lo_all, hi_all = lo, hi
    if points.ndim == 2 and points.shape[1] == 3 and np.all(np.isfinite(points)):
        # The grid holds the inlets near the organ too (a heart's ostia lie above its base); one farther
        # than the organ's extent from its centre is refused by the Tissue, naming the grid's box.
        near = points[np.all(np.abs(points - 0.5 * (lo + hi)) <= (hi - lo), axis=1)]
        if len(near):
            lo_all, hi_all = np.minimum(lo, near.min(axis=0)), np.maximum(hi, near.max(axis=0))
    return grid_axes(lo_all, hi_all, h, MARGIN_FRACTION * float(np.max(hi - lo)))


def _voxelised(organ, cavities: list, origin, counts, h: float, path, cavity_paths) -> tuple[np.ndarray, np.ndarray]:
    """(solid, cavity) bool (z, y, x): voxel centres inside the organ, and inside one of its cavities;
    refused when none is inside the organ, a cavity reaches outside it, or no tissue is left."""
    xs, ys, zs = (origin[a] + h * np.arange(counts[a]) for a in range(3))
    solid = inside_surface(organ, xs, ys, zs, h)
    if not solid.any():
        raise TissueError(
            f"tissue.path: no voxel centre lies inside the surface {str(path)!r} ({np.max(organ.extents) * 1e3:.4g} mm "
            f"across) at voxels of {h * 1e3:.4g} mm: set a smaller tissue.voxel_size"
        )
    cavity = np.zeros_like(solid)
    for i, mesh in enumerate(cavities):
        inner = inside_surface(mesh, xs, ys, zs, h)
        outside = int(np.count_nonzero(inner & ~solid))
        if outside:
            raise TissueError(
                f"tissue.cavity_paths[{i}]: the cavity {str(cavity_paths[i])!r} reaches outside the organ's surface "
                f"{str(path)!r} ({outside} of its {int(np.count_nonzero(inner))} voxels lie outside it): a cavity "
                "must lie inside the organ (cut it at the organ's surface, or give the mesh in the organ's frame)"
            )
        cavity |= inner
    if not (solid & ~cavity).any():
        raise TissueError(
            f"tissue.cavity_paths: the cavities fill every voxel inside {str(path)!r}: no tissue is left to supply"
        )
    return solid, cavity


def write_surface(path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """Write a triangle surface: STL, OBJ or PLY with trimesh, VTP with VTK's writer (by suffix)."""
    path = Path(path)
    if path.suffix.lower() == ".vtp":
        from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
        from vtkmodules.vtkCommonCore import vtkPoints
        from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
        from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

        points = vtkPoints()
        points.SetData(numpy_to_vtk(np.ascontiguousarray(vertices, dtype=np.float64), deep=True))
        cells = vtkCellArray()
        offsets = np.arange(0, 3 * len(faces) + 1, 3, dtype=np.int64)
        cells.SetData(
            numpy_to_vtkIdTypeArray(offsets, deep=True),
            numpy_to_vtkIdTypeArray(np.ascontiguousarray(faces, dtype=np.int64).ravel(), deep=True),
        )
        poly = vtkPolyData()
        poly.SetPoints(points)
        poly.SetPolys(cells)
        writer = vtkXMLPolyDataWriter()
        writer.SetFileName(str(path))
        writer.SetInputData(poly)
        if not writer.Write():
            raise OSError(f"VTK could not write {str(path)!r}")
        return path
    import trimesh

    trimesh.Trimesh(vertices, faces, process=False).export(str(path))
    return path


def _marching_cubes(field: np.ndarray, origin: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices [m] as x, y, z, outward triangles) of the zero level of ``field`` (z, y, x; > 0 inside)."""
    try:
        from skimage.measure import marching_cubes
    except ImportError as exc:
        raise TissueError("writing the heart's surfaces needs scikit-image: pip install 'vasc_pipeline[mesh]'") from exc
    import trimesh

    # A sample on (or within rounding of) the level puts several triangles' corners at one point, slivers that
    # leave edges of three or more triangles: keep every sample a thousandth of the field's unit off it.
    field = np.where(np.abs(field) < _OFF_LEVEL, np.where(field > 0, _OFF_LEVEL, -_OFF_LEVEL), field)
    verts, faces, _, _ = marching_cubes(field, level=0.0, spacing=(spacing,) * 3, allow_degenerate=False)
    mesh = trimesh.Trimesh(verts[:, ::-1] + origin, faces, process=True)
    if mesh.volume < 0:
        mesh.invert()
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def write_heart_surfaces(path, spacing: float = 6e-4, **heart_options) -> tuple[Path, list[Path], Path]:
    """The shipped heart (:mod:`~vasc_pipeline.model.tissue.heart`, ``heart_options`` as its
    ``mass_g``, ``density``, ...) as closed surfaces, by marching cubes of its analytic shapes
    sampled every ``spacing`` [m]: the outer surface at ``path`` (the ventricles' outer surfaces
    cut by the base plane, which closes it), the LV and RV cavities (closed at the base plane too)
    beside it as ``<stem>.lv<suffix>`` and ``<stem>.rv<suffix>``, and the ostia as
    ``<stem>.inlets.json``. Returns (organ, [lv, rv], inlets). The format follows the suffix."""
    from . import heart

    if not (math.isfinite(spacing) and spacing > 0):
        raise TissueError(f"spacing must be a positive length in metres, got {spacing}")
    d = heart._dimensions(
        float(heart_options.get("mass_g", heart.DEFAULT_MASS_G)),
        float(heart_options.get("density", heart.DEFAULT_DENSITY)),
    )
    p = heart.RV_EXPONENT
    lo, hi = np.array(d["bbox_lo"]), np.array(d["bbox_hi"])
    pad = 3 * spacing
    counts = np.ceil((hi - lo + 2 * pad) / spacing).astype(int) + 1
    origin = lo - pad
    x, y, z = (origin[a] + spacing * np.arange(counts[a]) for a in range(3))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    length = float(d["lv_outer_half_length"])  # the base plane's field on the scale of the others

    def ellipsoid(a, c):
        return 1.0 - (X**2 + Y**2) / a**2 - (Z - d["lv_center_z"]) ** 2 / c**2

    def super_ellipsoid(axes):
        ax, ay, az = axes
        dx, dz = np.abs(X - d["rv_center_x"]), np.abs(Z - d["rv_center_z"])
        return 1.0 - (dx / ax) ** p - (np.abs(Y) / ay) ** p - (dz / az) ** p

    base = -Z / length
    lv_outer = ellipsoid(d["lv_outer_radius"], d["lv_outer_half_length"])
    fields = {
        "": np.minimum(np.maximum(lv_outer, super_ellipsoid(d["rv_outer_semi_axes"])), base),
        "lv": np.minimum(ellipsoid(d["lv_inner_radius"], d["lv_inner_half_length"]), base),
        "rv": np.minimum(np.minimum(super_ellipsoid(d["rv_inner_semi_axes"]), -lv_outer), base),
    }
    path = Path(path)
    suffix = path.suffix
    stem = path.name[: -len(suffix)] if suffix else path.name
    out = {}
    for name, field in fields.items():
        target = path if not name else path.with_name(f"{stem}.{name}{suffix}")
        out[name] = write_surface(target, *_marching_cubes(field, origin, spacing))
    inlets = path.with_name(f"{stem}.inlets.json")
    inlets.write_text(json.dumps(dict(zip(d["inlet_names"], [list(v) for v in d["inlets"]])), indent=1))
    return out[""], [out["lv"], out["rv"]], inlets
