"""The sweep's cell grid in the summary: which dims a sweep's cells have, and per-cell datasets
stacked on that grid (absent cells filled), as :mod:`vasc_pipeline.reduce.summary` writes them.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..store.trace import TRACE_META
from .runs import RunInfo

__all__ = [
    "CELL_META",
    "COST_META",
    "cell_dims",
    "cell_var",
    "coord_values",
    "stack_cells",
    "strings_as_objects",
    "with_steps",
]

# The summary's cost variables: units and long names of the trace's columns
COST_META = {
    "total": TRACE_META["total"],
    "volume": TRACE_META["volume"],
    "power": TRACE_META["power"],
    "supply": TRACE_META["supply"],
    "exclusion": TRACE_META["exclusion"],
    "pressure": TRACE_META["pressure"],
}
# The cell dims' (and the seed's) coordinate attributes
CELL_META = {
    "tissue": {"long_name": "tissue"},
    "method": {"long_name": "how the tree was grown (anneal, cco)"},
    "n_terminals": {"long_name": "number of terminal nodes N", "units": "1"},
    "m_b": {"long_name": "metabolic cost of blood m_b", "units": "W m-3"},
    "steps": {"long_name": "proposed moves per run", "units": "1"},
    "seed": {"long_name": "random seed", "units": "1"},
}


def cell_dims(runs: list[RunInfo]) -> list[str]:
    """The cell dims of ``runs``: N and m_b always; steps, tissue and method where the runs differ in them."""
    dims = ["n_terminals", "m_b"]
    if any(r.steps is not None for r in runs):
        dims.append("steps")
    if len({r.tissue for r in runs}) > 1:
        dims.insert(0, "tissue")
    if len({r.method for r in runs}) > 1:  # anneal and CCO runs side by side
        dims.insert(0, "method")
    return dims


def with_steps(runs: list[RunInfo], dims: list[str]) -> list[RunInfo]:
    """Runs without a steps coordinate get their own step count when others have one."""
    if "steps" not in dims:
        return runs
    for r in runs:
        if r.steps is None:
            r.steps = r.steps_done
    return runs


def _fill_for(dtype: np.dtype):
    if np.issubdtype(dtype, np.floating):
        return np.nan
    if np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.bool_):
        return 0
    return ""


def stack_cells(parts: dict[tuple, xr.Dataset], dims: list[str], coords: dict[str, list]) -> xr.Dataset:
    """Place per-cell datasets (identical inner shapes) on the grid ``dims``; absent cells get fillers.

    Fillers: NaN (floats), 0 (integers, counts), "" (strings).
    """
    first = next(iter(parts.values()))
    index = {d: {v: i for i, v in enumerate(coords[d])} for d in dims}
    grid_shape = [len(coords[d]) for d in dims]
    out = {}
    for name, var in first.data_vars.items():
        dtype = var.dtype if var.dtype.kind in "fiub" else object
        arr = np.full(grid_shape + list(var.shape), _fill_for(np.dtype(dtype)), dtype=dtype)
        for key, ds in parts.items():
            value = ds[name].values
            # a 0-d object array would be stored as an element itself: take its item
            arr[tuple(index[d][k] for d, k in zip(dims, key))] = value[()] if value.ndim == 0 else value
        out[name] = (dims + list(var.dims), arr, dict(var.attrs))
    inner = {k: v for k, v in first.coords.items() if set(v.dims) <= set(first.dims)}
    ds = xr.Dataset(out, coords={**{d: (d, coord_values(coords[d]), CELL_META[d]) for d in dims}, **inner})
    return ds


def coord_values(values: list) -> np.ndarray:
    if values and isinstance(values[0], str):
        return np.array(values, dtype=object)
    return np.asarray(values)


def cell_var(best: dict[tuple, RunInfo], getter, dtype, units: str | None, long_name: str):
    attrs = {"long_name": long_name, **({"units": units} if units else {})}
    return {k: xr.DataArray(np.asarray(getter(r), dtype=dtype), attrs=attrs) for k, r in best.items()}


def strings_as_objects(ds: xr.Dataset, inplace: bool = False) -> xr.Dataset:
    """Fixed-width unicode -> object arrays: Zarr v3 stores those as its spec'd ``string`` type."""
    if not inplace:
        ds = ds.copy()
    for name in list(ds.variables):
        var = ds.variables[name]
        if var.dtype.kind == "U":
            if name in ds.coords:
                ds.coords[name] = var.copy(data=var.values.astype(object))
            else:
                ds[name] = var.copy(data=var.values.astype(object))
    return ds
