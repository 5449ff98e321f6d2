"""Export trees to VTK PolyData (``.vtp``, opens in ParaView) and CSV (and, for a run store, svZeroDSolver's 0D JSON).

Pure functions on a run store's tree arrays (``parent``, ``position`` [m],
``radius`` [m], ``kind``), plus :func:`export_run` for a finished run store::

    from vasc_pipeline.reduce.export import export_run
    export_run("results/smoke/runs/sphere-N16-mb641.3-s0.zarr", "trees/")
    # -> trees/sphere-N16-mb641.3-s0.vtp, .csv and .0d.json (svZeroDSolver, vasc_pipeline.reduce.zerod)

The VTP file is VTK XML PolyData written directly (ASCII, full float precision): every
node is a point, every segment a two-point line from the parent node to the node. No VTK
or meshio dependency is needed for a format this small, and ASCII keeps the files
diffable and readable by any VTK XML reader. Arrays (SI units throughout):

- cell data (one value per line = segment): ``radius`` [m], ``flow`` [m^3 s^-1] (when the
  total inflow is known), ``order`` (diameter-defined Strahler, shifted so the highest is
  11), ``strahler_order`` (conventional, shifted likewise), ``length`` [m],
  ``terminals_downstream``, ``node`` (index of the segment's child node);
- point data: ``radius`` [m] (of the segment ending at the node; at an inlet, of its
  root segment, so that ParaView's Tube filter gives a continuous tube), ``kind``
  (0 inlet, 1 bifurcation, 2 terminal, 3 pass-through: a whole tree's annealed terminal) and,
  when the table has a ``pressure_Pa`` column (a whole tree's export), ``pressure`` [Pa].

The CSV file has one row per node; the columns after ``z_m`` describe the segment (edge)
from the node to its ``parent`` and are empty at inlets, which have no segment. So one
file holds both the nodes and the edges (``parent`` -> ``node``).
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pandas as pd

from ..model.topology import KIND_TERMINAL, check_tree_arrays, segment_lengths, terminals_downstream
from . import morphometry as _m

__all__ = ["terminals_downstream", "tree_table", "write_vtp", "write_csv", "export_paths", "export_tree", "export_run"]


def tree_table(
    parent, position, radius, kind, *, total_flow: float | None = None, orders=None, strahler=None
) -> pd.DataFrame:
    """One row per node with its segment's properties.

    Parameters
    ----------
    parent : int64 (node,)
    position : float64 (node, 3), metres
    radius : float64 (node,), metres (0 at inlets)
    kind : int8 (node,)
    total_flow : float, optional
        Q0 [m^3 s^-1]; gives ``flow_m3_s = n_i Q0 / N`` (flow splits with the terminals). None: no flow column.
    orders, strahler : int (node,), optional
        Segment orders (0 at inlets); default: diameter-defined and conventional Strahler
        orders shifted so the highest is 11 (from :func:`vasc_pipeline.reduce.morphometry.morphometry`).

    Returns
    -------
    pandas.DataFrame
        Columns ``node, parent, kind, x_m, y_m, z_m, radius_m, length_m, flow_m3_s,
        order, strahler_order, terminals_downstream``; segment columns are NaN / <NA> at inlets.
    """
    parent = np.asarray(parent, dtype=np.int64)
    position = np.asarray(position, dtype=float)
    radius = np.asarray(radius, dtype=float)
    kind = np.asarray(kind, dtype=np.int64)
    check_tree_arrays(parent, kind, radius=radius, position=position)
    if orders is None or strahler is None:
        ds = _m.morphometry(parent, position, radius, kind)
        if orders is None:
            orders = ds.segment_order.sel(scheme="diameter_defined").values
        if strahler is None:
            strahler = ds.segment_order.sel(scheme="strahler").values
    seg = parent >= 0
    n_down = terminals_downstream(parent, kind)
    table = pd.DataFrame(
        {
            "node": np.arange(parent.size),
            "parent": parent,
            "kind": kind,
            "x_m": position[:, 0],
            "y_m": position[:, 1],
            "z_m": position[:, 2],
            "radius_m": np.where(seg, radius, np.nan),
            "length_m": np.where(seg, segment_lengths(parent, position), np.nan),
        }
    )
    if total_flow is not None:
        n_terminals = int((kind == KIND_TERMINAL).sum())
        table["flow_m3_s"] = np.where(seg, n_down * float(total_flow) / n_terminals, np.nan)
    for column, values in (("order", orders), ("strahler_order", strahler), ("terminals_downstream", n_down)):
        table[column] = pd.Series(np.asarray(values, dtype=np.int64), dtype="Int64").where(seg)
    return table


def _data_array(name: str, values: np.ndarray, components: int = 1) -> str:
    values = np.asarray(values)
    if np.issubdtype(values.dtype, np.floating):
        vtype, text = "Float64", " ".join(repr(float(v)) for v in values.reshape(-1))
    else:
        vtype, text = "Int64", " ".join(str(int(v)) for v in values.reshape(-1))
    comp = f' NumberOfComponents="{components}"' if components != 1 else ""
    return (
        f'        <DataArray type="{vtype}" Name={quoteattr(name)}{comp} format="ascii">\n'
        f"          {text}\n        </DataArray>\n"
    )


def write_vtp(path, table: pd.DataFrame) -> Path:
    """Write a :func:`tree_table` as VTK XML PolyData (ASCII); returns the path.

    Points are the table's nodes, lines its segments (parent -> node), in node order.
    The file is written to a temporary name and renamed, so a reader never sees half a file.
    """
    path = Path(path)
    seg = table["parent"].to_numpy() >= 0
    child = table["node"].to_numpy()[seg]
    parent = table["parent"].to_numpy()[seg]
    points = table[["x_m", "y_m", "z_m"]].to_numpy(dtype=float)
    radius = table["radius_m"].to_numpy(dtype=float)
    # An inlet's point radius is its root segment's, so tubes do not pinch to 0 at the ostium.
    point_radius = radius.copy()
    point_radius[parent] = np.where(np.isnan(point_radius[parent]), radius[child], point_radius[parent])
    cell = {"radius": radius[seg]}
    if "flow_m3_s" in table:
        cell["flow"] = table["flow_m3_s"].to_numpy(dtype=float)[seg]
    cell["order"] = table["order"].to_numpy(dtype=np.int64, na_value=0)[seg]
    cell["strahler_order"] = table["strahler_order"].to_numpy(dtype=np.int64, na_value=0)[seg]
    cell["length"] = table["length_m"].to_numpy(dtype=float)[seg]
    cell["terminals_downstream"] = table["terminals_downstream"].to_numpy(dtype=np.int64, na_value=0)[seg]
    cell["node"] = child
    connectivity = np.column_stack([parent, child]).reshape(-1)
    offsets = 2 * np.arange(1, child.size + 1)
    parts = [
        '<?xml version="1.0"?>\n',
        "<!-- vasc_pipeline tree. SI units: positions, radius, length in m; flow in m^3 s^-1. "
        "Lines are segments (parent node -> node); order = diameter-defined Strahler order "
        "shifted so the highest is 11. -->\n",
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n',
        "  <PolyData>\n",
        f'    <Piece NumberOfPoints="{len(table)}" NumberOfVerts="0" NumberOfLines="{child.size}" '
        'NumberOfStrips="0" NumberOfPolys="0">\n',
        '      <PointData Scalars="radius">\n',
        _data_array("radius", point_radius),
        _data_array("kind", table["kind"].to_numpy()),
        *([_data_array("pressure", table["pressure_Pa"].to_numpy(dtype=float))] if "pressure_Pa" in table else []),
        "      </PointData>\n",
        '      <CellData Scalars="radius">\n',
        *(_data_array(k, v) for k, v in cell.items()),
        "      </CellData>\n",
        "      <Points>\n",
        _data_array("Points", points, 3),
        "      </Points>\n",
        "      <Lines>\n",
        _data_array("connectivity", connectivity),
        _data_array("offsets", offsets),
        "      </Lines>\n",
        "    </Piece>\n  </PolyData>\n</VTKFile>\n",
    ]
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text("".join(parts), encoding="ascii")
    os.replace(tmp, path)
    return path


def write_csv(path, table: pd.DataFrame) -> Path:
    """Write a :func:`tree_table` as CSV (full precision; empty fields at inlets); returns the path."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    table.to_csv(tmp, index=False, float_format="%.17g")
    os.replace(tmp, path)
    return path


def export_paths(out_dir, name: str) -> tuple[Path, Path]:
    """``<out_dir>/<name>.vtp`` and ``<out_dir>/<name>.csv``: where :func:`export_tree` writes."""
    out = Path(out_dir)
    return out / f"{name}.vtp", out / f"{name}.csv"


def export_tree(
    out_dir, name: str, parent, position, radius, kind, *, total_flow: float | None = None, orders=None, strahler=None
) -> tuple[Path, Path]:
    """Write ``<out_dir>/<name>.vtp`` and ``<out_dir>/<name>.csv`` for a tree; returns both paths.

    Parameters are those of :func:`tree_table`.
    """
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    table = tree_table(parent, position, radius, kind, total_flow=total_flow, orders=orders, strahler=strahler)
    vtp, csv = export_paths(out_dir, name)
    return write_vtp(vtp, table), write_csv(csv, table)


def export_run(store_path, out_dir, name: str | None = None, *, zero_d: bool = True) -> tuple[Path, ...]:
    """Export the final tree of a complete run store: ``.vtp``, ``.csv`` and ``.0d.json``.

    What the reduction writes for the best tree of every cell, in one call.

    Parameters
    ----------
    store_path : path
        ``<output_dir>/runs/<run_id>.zarr`` (status "complete").
    out_dir : path
        Created if needed.
    name : str, optional
        File stem; default the run id.
    zero_d : bool, default True
        Also write the svZeroDSolver network ``<name>.0d.json``
        (:func:`vasc_pipeline.reduce.zerod.zero_d_model`).

    Returns
    -------
    tuple of Path
        The ``.vtp``, ``.csv`` and (with ``zero_d``) ``.0d.json`` paths.

    Raises
    ------
    vasc_pipeline.store.StoreError
        If the store is not a readable run store or the run is not complete.
    """
    from ..store.run_store import STATUS_COMPLETE, RunStore, StoreError

    store = RunStore.open(store_path, mode="r")
    if store.status != STATUS_COMPLETE:
        raise StoreError(
            f"run store {str(store_path)!r} has status {store.status!r}: only complete runs have a final tree to export"
        )
    tree = store.read_tree()
    total_flow = (store.attrs.get("physics") or {}).get("total_flow")
    name = name or store.run_id
    paths = export_tree(
        out_dir,
        name,
        tree["parent"],
        tree["position"],
        tree["radius"],
        tree["kind"],
        total_flow=total_flow,
    )
    if not zero_d:
        return paths
    from . import zerod

    return (*paths, zerod.export_run(store_path, out_dir, name))
