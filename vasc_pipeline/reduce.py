"""Reduction: finished run stores -> ``summary.zarr``, comparison table, tree exports, figures.

A plain function of an output directory (no Hydra, no Dask)::

    from vasc_pipeline.reduce import reduce
    result = reduce("results/smoke")          # prints the comparison with Kassab 1993
    result.summary                            # the xarray.DataTree written to summary.zarr

Cells are the grid points without the seed: (tissue, n_terminals, m_b, steps). In every
cell the complete run with the lowest final annealed cost (``attrs["cost"]["total"]``)
is the cell's tree; its morphometry (:func:`vasc_pipeline.morphometry.morphometry`,
orders shifted so that the highest is 11) is compared with Kassab et al. 1993.

``<output_dir>/summary.zarr`` is an xarray DataTree (Zarr v3, consolidated). Cell dims are
``n_terminals`` and ``m_b`` always, ``steps`` when the sweep had a steps axis and
``tissue`` when the directory holds more than one tissue, ``method`` when it holds both
anneal and CCO runs (otherwise each is a scalar coordinate). Groups:

- ``/morphometry``  (cell..., scheme, order): element and segment diameter/length mean, SD,
  SE and counts of the best tree; per cell ``best_seed``, ``best_run_id``, ``best_cost``,
  ``n_seeds``.
- ``/asymmetry``    (cell..., scheme, order): D_s/D_p and D_l/D_p by parent order, and
  ``symmetric_ratio`` = 2^(-1/gamma) per cell.
- ``/costs``        (cell..., seed): final costs (annealed total and every unscaled term),
  steps, wall time and run id of every complete run; ``is_best``; ``cavity_share`` (the
  heart: share of the large vessels' length inside the ventricular cavities).
- ``/traces``       (cell..., seed, record): the cost traces of all complete runs,
  NaN-padded to the longest.
- ``/kassab``       (artery, level, order): :func:`vasc_pipeline.reference.kassab_dataset`.
- ``/comparison``   (cell..., artery, order) and (cell..., artery): model against Kassab,
  element level, diameter-defined orders; mean absolute log10 ratios.

Orders of cells with different N are aligned on the shifted order (highest = 11): a
smaller tree simply has NaN / 0 at the low orders it does not reach.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import shutil
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, TextIO

import numpy as np
import pandas as pd
import xarray as xr

from . import morphometry as _m
from .reference import ARTERIES, kassab_dataset
from .store import (
    RUNS_DIR,
    STATUS_COMPLETE,
    SWEEP_AXES,
    TRACE_FIELDS,
    RunStore,
    StoreError,
    identity_differences,
    verify_store,
)

__all__ = [
    "RunInfo",
    "Reduction",
    "ReductionError",
    "find_runs",
    "check_one_configuration",
    "best_runs",
    "build_summary",
    "write_summary",
    "comparison_frame",
    "format_comparison",
    "reduce",
    "SUMMARY_NAME",
    "COMPARISON_CSV",
    "COMPARISON_SUMMARY_CSV",
    "COMPARISON_SCHEME",
    "COMPARISON_LEVEL",
]

SUMMARY_NAME = "summary.zarr"
COMPARISON_CSV = "comparison.csv"
COMPARISON_SUMMARY_CSV = "comparison_summary.csv"
COMPARISON_SCHEME, COMPARISON_LEVEL = "diameter_defined", "element"
_COST_KEYS = ("total", "volume", "power", "supply", "exclusion", "pressure")
_TRACE_META = {name: (units, long_name) for name, _, units, long_name in TRACE_FIELDS}
_COST_META = {
    "total": _TRACE_META["total"],
    "volume": _TRACE_META["volume"],
    "power": _TRACE_META["power"],
    "supply": _TRACE_META["supply"],
    "exclusion": _TRACE_META["exclusion"],
    "pressure": _TRACE_META["pressure"],
}
_CELL_META = {
    "tissue": {"long_name": "tissue"},
    "method": {"long_name": "how the tree was grown (anneal, cco)"},
    "n_terminals": {"long_name": "number of terminal nodes N", "units": "1"},
    "m_b": {"long_name": "metabolic cost of blood m_b", "units": "W m-3"},
    "steps": {"long_name": "proposed moves per run", "units": "1"},
    "seed": {"long_name": "random seed", "units": "1"},
}


class ReductionError(RuntimeError):
    """Nothing to reduce (no complete run), or the summary could not be written."""


@dataclass
class RunInfo:
    """A complete run found in ``<output_dir>/runs``."""

    run_id: str
    path: Path
    tissue: str
    n_terminals: int
    m_b: float
    seed: int
    steps: int | None  # the sweep's steps coordinate (None without a steps axis)
    steps_done: int
    wall_seconds: float
    cost: dict[str, float]
    physics: dict[str, Any]
    statistics: dict[str, float] = field(default_factory=dict)  # engine.tree_statistics
    config: dict[str, Any] = field(default_factory=dict, repr=False)  # the run's stored config
    method: str = "anneal"  # "anneal" or "cco" (stores written before CCO existed are anneal runs)

    def cell(self, dims: Iterable[str]) -> tuple:
        return tuple(getattr(self, d) for d in dims)


@dataclass
class Reduction:
    """What :func:`reduce` produced."""

    output_dir: Path
    summary: xr.DataTree
    summary_path: Path
    best: dict[tuple, RunInfo]
    cell_dims: list[str]
    comparison: pd.DataFrame
    comparison_csv: Path
    comparison_summary_csv: Path
    trees: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)  # store -> why it was not used
    damaged: dict[str, str] = field(default_factory=dict)  # the skipped stores that fail their checks
    errors: dict[str, str] = field(default_factory=dict)  # stage (figures, ...) -> error text


# --------------------------------------------------------------------------------------------
# Finding runs and picking the best seed


def _float(value: Any) -> float:
    """Attribute value to float (store.py writes non-finite floats as strings)."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def find_runs(
    output_dir: str | os.PathLike, damaged: dict[str, str] | None = None
) -> tuple[list[RunInfo], dict[str, str]]:
    """Complete runs under ``<output_dir>/runs`` and, for every other store, why it is left out.

    Every store is checked whole (:func:`vasc_pipeline.store.verify_store`: root metadata,
    trace, and the final tree and trace against their checksums) before it is used.

    Returns
    -------
    runs : list of RunInfo
        Sorted by run id.
    skipped : dict
        Store path -> reason (still running, damaged, no final cost). The damaged ones are
        also put in ``damaged`` when given.
    """
    runs, skipped = [], {}
    root = Path(output_dir) / RUNS_DIR
    for path in sorted(root.glob("*.zarr")) if root.is_dir() else []:
        try:
            attrs = verify_store(path).attrs
        except StoreError as exc:
            skipped[str(path)] = str(exc)
            if damaged is not None:
                damaged[str(path)] = str(exc)
            continue
        if attrs.get("status") != STATUS_COMPLETE:
            skipped[str(path)] = f"status {attrs.get('status')!r} (not complete)"
            continue
        cost = {k: _float((attrs.get("cost") or {}).get(k)) for k in _COST_KEYS}
        if not math.isfinite(cost["total"]):
            skipped[str(path)] = "no finite final cost"
            continue
        coords = attrs.get("coords") or {}
        config = attrs.get("config") or {}
        runs.append(
            RunInfo(
                run_id=attrs["run_id"],
                path=path,
                tissue=str(coords.get("tissue", config.get("tissue", {}).get("name"))),
                n_terminals=int(coords.get("n_terminals", config.get("n_terminals"))),
                m_b=float(coords.get("m_b", config.get("physics", {}).get("m_b"))),
                seed=int(attrs["seed"]),
                steps=None if coords.get("steps") is None else int(coords["steps"]),
                steps_done=int(attrs.get("steps_done", 0)),
                wall_seconds=_float(attrs.get("wall_seconds")),
                cost=cost,
                physics=dict(attrs.get("physics") or {}),
                config=config,
                statistics={k: _float(v) for k, v in (attrs.get("statistics") or {}).items()},
                method=str(coords.get("method") or (config.get("method") or {}).get("name") or "anneal"),
            )
        )
    return sorted(runs, key=lambda r: r.run_id), skipped


def check_one_configuration(output_dir: str | os.PathLike, runs: list[RunInfo]) -> None:
    """Refuse (ReductionError) runs of different configurations in one output_dir.

    The sweep refuses to write them (``orchestrate.check_one_configuration``); this catches
    directories mixed by hand or by an older version, whose best seed per cell would otherwise
    be picked across different physics or schedules.
    """
    first, problems = runs[0], []
    for r in runs[1:]:
        diff = identity_differences(r.config, first.config)
        if diff:
            problems.append(f"{r.run_id} differs from {first.run_id} in {'; '.join(diff)}")
    cells: dict[tuple, RunInfo] = {}
    for r in runs:
        other = cells.setdefault((r.tissue, r.n_terminals, r.m_b, r.steps, r.method), r)
        if other.steps_done != r.steps_done:
            problems.append(
                f"{r.run_id} ran {r.steps_done} proposed moves, {other.run_id} of the same cell {other.steps_done}"
            )
    if problems:
        raise ReductionError(
            f"output_dir {str(output_dir)!r} holds runs of different configurations, which are never reduced together "
            f"(every run of an output_dir shares its configuration except the sweep axes {', '.join(SWEEP_AXES)}, "
            f"and one cell's runs their step count): {'; '.join(problems)}. Move the runs of one configuration to "
            "an output_dir of their own and reduce each."
        )


def _cell_dims(runs: list[RunInfo]) -> list[str]:
    dims = ["n_terminals", "m_b"]
    if any(r.steps is not None for r in runs):
        dims.append("steps")
    if len({r.tissue for r in runs}) > 1:
        dims.insert(0, "tissue")
    if len({r.method for r in runs}) > 1:  # anneal and CCO runs side by side
        dims.insert(0, "method")
    return dims


def _with_steps(runs: list[RunInfo], dims: list[str]) -> list[RunInfo]:
    """Runs without a steps coordinate get their own step count when others have one."""
    if "steps" not in dims:
        return runs
    for r in runs:
        if r.steps is None:
            r.steps = r.steps_done
    return runs


def best_runs(runs: list[RunInfo], dims: list[str]) -> dict[tuple, RunInfo]:
    """Per cell (tuple of ``dims`` values), the run with the lowest final total cost (ties: lowest seed)."""
    best: dict[tuple, RunInfo] = {}
    for r in runs:
        key = r.cell(dims)
        b = best.get(key)
        if b is None or (r.cost["total"], r.seed) < (b.cost["total"], b.seed):
            best[key] = r
    return dict(sorted(best.items()))


# --------------------------------------------------------------------------------------------
# Stacking per-cell datasets onto the cell grid


def _fill_for(dtype: np.dtype):
    if np.issubdtype(dtype, np.floating):
        return np.nan
    if np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.bool_):
        return 0
    return ""


def _stack(parts: dict[tuple, xr.Dataset], dims: list[str], coords: dict[str, list]) -> xr.Dataset:
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
    ds = xr.Dataset(out, coords={**{d: (d, _coord_values(coords[d]), _CELL_META[d]) for d in dims}, **inner})
    return ds


def _coord_values(values: list) -> np.ndarray:
    if values and isinstance(values[0], str):
        return np.array(values, dtype=object)
    return np.asarray(values)


def _cell_var(best: dict[tuple, RunInfo], getter, dtype, units: str | None, long_name: str):
    attrs = {"long_name": long_name, **({"units": units} if units else {})}
    return {k: xr.DataArray(np.asarray(getter(r), dtype=dtype), attrs=attrs) for k, r in best.items()}


# --------------------------------------------------------------------------------------------
# Building the summary


def _morphometry_of(run: RunInfo) -> xr.Dataset:
    tree = RunStore.open(run.path, mode="r").read_tree()
    return _m.morphometry(tree["parent"], tree["position"], tree["radius"], tree["kind"])


_ASYMMETRY_VARS = (
    "diameter_ratio_small_mean",
    "diameter_ratio_small_sd",
    "diameter_ratio_small_se",
    "diameter_ratio_large_mean",
    "diameter_ratio_large_sd",
    "diameter_ratio_large_se",
    "bifurcation_count",
)


def _comparison_part(morph: xr.Dataset, reference: xr.Dataset, orders: np.ndarray) -> tuple[xr.Dataset, dict]:
    """Model vs Kassab for every artery: (artery, order) table and per-artery summary values."""
    per_order, summary = [], {}
    for artery in ARTERIES:
        table = _m.compare_with_kassab(
            morph, artery, scheme=COMPARISON_SCHEME, level=COMPARISON_LEVEL, reference=reference
        )
        per_order.append(xr.Dataset.from_dataframe(table).reindex(order=orders))
        summary[artery] = dict(table.attrs)
    ds = xr.concat(per_order, dim=xr.DataArray(list(ARTERIES), dims="artery", name="artery"))
    for name in ("model_count", "kassab_count"):
        ds[name] = ds[name].fillna(0).astype(np.int64)
    meta = {
        "model_diameter": ("m", f"model mean {COMPARISON_LEVEL} diameter"),
        "kassab_diameter": ("m", f"Kassab 1993 mean {COMPARISON_LEVEL} diameter"),
        "diameter_log10_ratio": ("1", "log10 of model over Kassab mean diameter"),
        "model_length": ("m", f"model mean {COMPARISON_LEVEL} length"),
        "kassab_length": ("m", f"Kassab 1993 mean {COMPARISON_LEVEL} length"),
        "length_log10_ratio": ("1", "log10 of model over Kassab mean length"),
        "model_count": ("1", f"model number of {COMPARISON_LEVEL}s"),
        "kassab_count": ("1", f"Kassab 1993 number of {COMPARISON_LEVEL}s measured"),
    }
    for name, (units, long_name) in meta.items():
        ds[name].attrs = {"units": units, "long_name": long_name}
    for name, long_name in (
        ("mean_abs_log10_ratio_diameter", "mean over orders of |log10 model/Kassab diameter|"),
        ("mean_abs_log10_ratio_length", "mean over orders of |log10 model/Kassab length|"),
        ("mean_abs_log10_ratio", "mean of the diameter and length mean |log10 ratio|"),
    ):
        ds[name] = ("artery", [summary[a][name] for a in ARTERIES], {"units": "1", "long_name": long_name})
    ds["n_orders_compared"] = (
        "artery",
        np.array([summary[a]["n_orders_compared"] for a in ARTERIES], dtype=np.int64),
        {"units": "1", "long_name": "orders present in both model and Kassab"},
    )
    return ds.drop_vars("artery"), summary


def build_summary(
    runs: list[RunInfo], *, morph: dict[tuple, xr.Dataset] | None = None, output_dir: str | os.PathLike | None = None
) -> tuple[xr.DataTree, dict[tuple, RunInfo], list[str]]:
    """The summary DataTree of complete ``runs`` (see the module docstring for the schema).

    Parameters
    ----------
    runs : list of RunInfo
        From :func:`find_runs`; at least one.
    morph : dict, optional
        Precomputed morphometry of the best runs by cell key.
    output_dir : path, optional
        Recorded in the root attributes.

    Returns
    -------
    (xarray.DataTree, dict of cell key -> best RunInfo, list of cell dims)
    """
    if not runs:
        raise ReductionError("no complete run to reduce")
    dims = _cell_dims(runs)
    runs = _with_steps(runs, dims)
    best = best_runs(runs, dims)
    cell_coords = {d: sorted({getattr(r, d) for r in runs}) for d in dims}
    morph = dict(morph or {})
    for key, r in best.items():
        if key not in morph:
            morph[key] = _morphometry_of(r)
    # One order axis for all cells: the union of the shifted orders (highest 11) and Kassab's 1..11.
    reference = kassab_dataset()
    lo = min([int(ds.order.min()) for ds in morph.values()] + [int(reference.order.min())])
    orders = np.arange(lo, _m.TOP_ORDER + 1, dtype=np.int64)

    morph_parts, asym_parts, comp_parts = {}, {}, {}
    for key, ds in morph.items():
        r = best[key]
        ds = ds.drop_dims("node").reindex(order=orders)
        for name, var in ds.data_vars.items():  # reindex turns absent counts into NaN: back to 0
            if name.endswith("_count"):
                ds[name] = var.fillna(0).astype(np.int64)
        ds["dds_iterations"] = (
            (),
            int(ds.attrs["dds_iterations"]),
            {"units": "1", "long_name": "diameter-defined Strahler passes"},
        )
        ds["dds_converged"] = (
            (),
            int(ds.attrs["dds_converged"]),
            {"units": "1", "long_name": "diameter-defined Strahler converged (1) or not (0)"},
        )
        ds.attrs = {}
        asym_parts[key] = ds[list(_ASYMMETRY_VARS)]
        morph_parts[key] = ds.drop_vars(list(_ASYMMETRY_VARS))
        comp, _ = _comparison_part(ds, reference, orders)
        comp_parts[key] = comp
    n_seeds = {k: sum(1 for r in runs if r.cell(dims) == k) for k in best}
    extra = {
        "best_seed": _cell_var(best, lambda r: r.seed, np.int64, "1", "seed of the lowest-cost run of the cell"),
        "best_run_id": _cell_var(best, lambda r: r.run_id, object, None, "run id of the lowest-cost run of the cell"),
        "best_cost": _cell_var(
            best,
            lambda r: r.cost["total"],
            np.float64,
            _COST_META["total"][0],
            "final annealed total cost C of the lowest-cost run",
        ),
        "n_seeds": {
            k: xr.DataArray(np.int64(n), attrs={"units": "1", "long_name": "complete runs (seeds) in the cell"})
            for k, n in n_seeds.items()
        },
    }
    for name, values in extra.items():
        for key in best:
            morph_parts[key][name] = values[key]
    for key, r in best.items():
        gamma = _float(r.physics.get("gamma"))
        asym_parts[key]["symmetric_ratio"] = xr.DataArray(
            2.0 ** (-1.0 / gamma), attrs={"units": "1", "long_name": "D_d/D_p at a symmetric bifurcation, 2^(-1/gamma)"}
        )

    morphometry = _stack(morph_parts, dims, cell_coords)
    morphometry.attrs.update(
        title="Order-wise morphometry of the lowest-cost tree of every cell",
        ordering="diameter_defined: Jiang, Kassab & Fung 1994 range reassignment; strahler: conventional. "
        f"Orders shifted so that the highest is {_m.TOP_ORDER} (Kassab's coronary trunk).",
    )
    asymmetry = _stack(asym_parts, dims, cell_coords)
    asymmetry.attrs.update(title="Daughter to parent diameter ratios by parent order (lowest-cost tree per cell)")
    comparison = _stack(comp_parts, dims, cell_coords)
    comparison = comparison.assign_coords(
        artery=("artery", np.array(ARTERIES, dtype=object), {"long_name": "coronary artery (Kassab 1993)"})
    )
    comparison["order"].attrs.update(long_name=f"vessel order (shifted: highest = {_m.TOP_ORDER})", units="1")
    comparison.attrs.update(
        title="Model (lowest-cost tree per cell) against Kassab et al. 1993",
        scheme=COMPARISON_SCHEME,
        level=COMPARISON_LEVEL,
    )
    costs = _costs(runs, best, dims, cell_coords)
    traces = _traces(runs, dims, cell_coords)
    kassab = _strings_as_objects(reference)

    tissues = sorted({r.tissue for r in runs})
    root = xr.Dataset(
        attrs={
            "title": "vasc_pipeline sweep summary",
            "Conventions": "CF-1.10",
            "history": f"{_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')}: vasc_pipeline.reduce",
            "output_dir": str(Path(output_dir).resolve()) if output_dir is not None else "",
            "cell_dims": list(dims),
            "n_runs": len(runs),
            "n_cells": len(best),
            "tissues": tissues,
            "comparison_scheme": COMPARISON_SCHEME,
            "comparison_level": COMPARISON_LEVEL,
        }
    )
    groups = {
        "/": root,
        "/morphometry": morphometry,
        "/asymmetry": asymmetry,
        "/costs": costs,
        "/traces": traces,
        "/kassab": kassab,
        "/comparison": comparison,
    }
    if "tissue" not in dims:  # one tissue: a scalar coordinate on the cell groups
        for name in ("/morphometry", "/asymmetry", "/costs", "/traces", "/comparison"):
            groups[name] = groups[name].assign_coords(tissue=((), tissues[0], _CELL_META["tissue"]))
    if "method" not in dims:  # one method: likewise
        method = runs[0].method
        for name in ("/morphometry", "/asymmetry", "/costs", "/traces", "/comparison"):
            groups[name] = groups[name].assign_coords(method=((), method, _CELL_META["method"]))
    for ds in groups.values():
        _strings_as_objects(ds, inplace=True)
    return xr.DataTree.from_dict(groups), best, dims


def _strings_as_objects(ds: xr.Dataset, inplace: bool = False) -> xr.Dataset:
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


def _costs(runs, best, dims, cell_coords) -> xr.Dataset:
    seeds = sorted({r.seed for r in runs})
    shape = [len(cell_coords[d]) for d in dims] + [len(seeds)]
    index = {d: {v: i for i, v in enumerate(cell_coords[d])} for d in dims}
    sindex = {s: i for i, s in enumerate(seeds)}
    values = {k: np.full(shape, np.nan) for k in _COST_KEYS}
    steps_done = np.zeros(shape, dtype=np.int64)
    wall = np.full(shape, np.nan)
    run_id = np.full(shape, "", dtype=object)
    is_best = np.zeros(shape, dtype=np.int8)
    cavity = np.full(shape, np.nan)
    for r in runs:
        at = tuple(index[d][v] for d, v in zip(dims, r.cell(dims))) + (sindex[r.seed],)
        for k in _COST_KEYS:
            values[k][at] = r.cost[k]
        cavity[at] = r.statistics.get("cavity_share", np.nan)
        steps_done[at], wall[at], run_id[at] = r.steps_done, r.wall_seconds, r.run_id
        is_best[at] = best[r.cell(dims)] is r
    full = dims + ["seed"]
    data = {
        f"cost_{k}": (
            full,
            values[k],
            {
                "units": _COST_META[k][0],
                "long_name": "final " + _COST_META[k][1] + ("" if k == "total" else " (unscaled)"),
            },
        )
        for k in _COST_KEYS
    }
    data["steps_done"] = (full, steps_done, {"units": "1", "long_name": "proposed moves done (0: no run)"})
    data["wall_seconds"] = (full, wall, {"units": "s", "long_name": "wall-clock time of the run, all sessions"})
    data["run_id"] = (full, run_id, {"long_name": "run id (empty: no complete run)"})
    data["is_best"] = (full, is_best, {"units": "1", "long_name": "1 for the lowest-cost run of the cell"})
    data["cavity_share"] = (
        full,
        cavity,
        {
            "units": "1",
            "long_name": "share of the large vessels' length (r >= r_max/4) inside the tissue's cavities "
            "(NaN: no cavity, e.g. not the heart)",
        },
    )
    coords = {d: (d, _coord_values(cell_coords[d]), _CELL_META[d]) for d in dims}
    coords["seed"] = ("seed", np.asarray(seeds, dtype=np.int64), _CELL_META["seed"])
    return xr.Dataset(data, coords=coords, attrs={"title": "Final costs of every complete run"})


def _traces(runs, dims, cell_coords) -> xr.Dataset:
    seeds = sorted({r.seed for r in runs})
    traces = {r.run_id: RunStore.open(r.path, mode="r").read_trace() for r in runs}
    n_rec = max((len(t["step"]) for t in traces.values()), default=0)
    shape = [len(cell_coords[d]) for d in dims] + [len(seeds), n_rec]
    index = {d: {v: i for i, v in enumerate(cell_coords[d])} for d in dims}
    sindex = {s: i for i, s in enumerate(seeds)}
    names = [f[0] for f in TRACE_FIELDS]
    # step as float64 with NaN padding: exact for step counts below 2^53, and plots need no mask
    arrays = {n: np.full(shape, np.nan) for n in names}
    length = np.zeros(shape[:-1], dtype=np.int64)
    for r in runs:
        t = traces[r.run_id]
        at = tuple(index[d][v] for d, v in zip(dims, r.cell(dims))) + (sindex[r.seed],)
        k = len(t["step"])
        length[at] = k
        for n in names:
            arrays[n][at + (slice(0, k),)] = t[n]
    full = dims + ["seed", "record"]
    data = {n: (full, arrays[n], {"units": _TRACE_META[n][0], "long_name": _TRACE_META[n][1]}) for n in names}
    data["trace_length"] = (
        dims + ["seed"],
        length,
        {"units": "1", "long_name": "trace records of the run (0: no run)"},
    )
    coords = {d: (d, _coord_values(cell_coords[d]), _CELL_META[d]) for d in dims}
    coords["seed"] = ("seed", np.asarray(seeds, dtype=np.int64), _CELL_META["seed"])
    coords["record"] = ("record", np.arange(n_rec, dtype=np.int64), {"units": "1", "long_name": "trace record"})
    return xr.Dataset(data, coords=coords, attrs={"title": "Cost traces of every complete run (NaN-padded)"})


# --------------------------------------------------------------------------------------------
# Writing


def write_summary(tree: xr.DataTree, path: str | os.PathLike) -> Path:
    """Write the DataTree to Zarr (v3, consolidated) at ``path``, replacing any previous one.

    Written to a temporary directory beside ``path`` and swapped in by renames, so a crash
    leaves either the old or the new summary readable, never a mix.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    old = path.with_name(f".{path.name}.old-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    with warnings.catch_warnings():  # "consolidated metadata is not part of the v3 spec"
        warnings.simplefilter("ignore", UserWarning)
        tree.to_zarr(tmp, mode="w", consolidated=True, zarr_format=3)
    if path.exists():
        os.replace(path, old)
    os.replace(tmp, path)
    shutil.rmtree(old, ignore_errors=True)
    return path


def comparison_frame(summary: xr.DataTree) -> pd.DataFrame:
    """The ``/comparison`` group as a long table, one row per (cell, artery, order) present in either."""
    comp = summary["comparison"].to_dataset()
    per_order = [n for n, v in comp.data_vars.items() if "order" in v.dims]
    frame = comp[per_order].to_dataframe().reset_index()
    frame = frame[(frame.model_count > 0) | (frame.kassab_count > 0)]
    run_ids = summary["morphometry"]["best_run_id"].to_dataframe().reset_index()
    keys = [d for d in summary.attrs["cell_dims"]]
    frame = frame.merge(run_ids[keys + ["best_run_id"]], on=keys, how="inner")
    frame = frame[frame.best_run_id != ""]
    frame = frame.rename(
        columns={
            "best_run_id": "run_id",
            "model_diameter": "model_diameter_m",
            "kassab_diameter": "kassab_diameter_m",
            "model_length": "model_length_m",
            "kassab_length": "kassab_length_m",
        }
    )
    front = keys + ["run_id", "artery", "order"]
    drop = [c for c in ("tissue", "method") if c in frame.columns and c not in keys]
    frame = frame.drop(columns=drop)
    return frame[front + [c for c in frame.columns if c not in front]].reset_index(drop=True)


def _comparison_summary_frame(summary: xr.DataTree) -> pd.DataFrame:
    comp = summary["comparison"].to_dataset()
    names = [
        "mean_abs_log10_ratio_diameter",
        "mean_abs_log10_ratio_length",
        "mean_abs_log10_ratio",
        "n_orders_compared",
    ]
    frame = comp[names].to_dataframe().reset_index()
    keys = list(summary.attrs["cell_dims"])
    run_ids = summary["morphometry"]["best_run_id"].to_dataframe().reset_index()
    frame = frame.merge(run_ids[keys + ["best_run_id"]], on=keys).rename(columns={"best_run_id": "run_id"})
    frame = frame[frame.run_id != ""].drop(
        columns=[c for c in ("tissue", "method") if c in frame.columns and c not in keys]
    )
    return frame[keys + ["run_id", "artery"] + names].reset_index(drop=True)


def _write_csv(frame: pd.DataFrame, path: Path) -> Path:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    frame.to_csv(tmp, index=False, float_format="%.6g")
    os.replace(tmp, path)
    return path


def _fmt(value: float, scale: float, width: int = 7) -> str:
    return f"{value * scale:{width}.4g}" if np.isfinite(value) else " " * (width - 1) + "-"


def format_comparison(summary: xr.DataTree) -> str:
    """Human-readable comparison table: per cell, per order, model vs Kassab RCA/LAD/LCX.

    Diameters in micrometres, lengths in millimetres (as in Kassab's tables); the last line
    of every cell gives the mean absolute log10 ratio over the orders present in both.
    """
    comp = summary["comparison"].to_dataset()
    morph = summary["morphometry"].to_dataset()
    dims = list(summary.attrs["cell_dims"])
    lines = [
        f"Model vs Kassab et al. 1993 (pig coronary arteries): mean {COMPARISON_LEVEL} diameter D [um] and "
        f"length L [mm] per order ({COMPARISON_SCHEME.replace('_', '-')} Strahler, highest order = "
        f"{_m.TOP_ORDER}); lowest-cost seed of every cell."
    ]
    stacked = morph["best_run_id"].stack(cell=dims) if dims else morph["best_run_id"]
    for i in range(stacked.sizes["cell"]):
        point = {d: stacked["cell"].values[i][j] for j, d in enumerate(dims)}
        run_id = str(stacked.values[i])
        if not run_id:
            continue
        c = comp.sel(point)
        cost = float(morph["best_cost"].sel(point))
        lines.append("")
        lines.append(f"{run_id} (best of {int(morph['n_seeds'].sel(point))} seeds, cost {cost:.6g})")
        head = (
            f"{'order':>5} {'D model':>7} " + " ".join(f"{'D ' + a:>7}" for a in ARTERIES) + "   "
            f"{'L model':>7} " + " ".join(f"{'L ' + a:>7}" for a in ARTERIES) + f" {'n model':>7}"
        )
        lines.append(head)
        for o in c.order.values[::-1]:
            row = c.sel(order=o)
            n_model = int(row.model_count.isel(artery=0))
            if n_model == 0 and not (row.kassab_count > 0).any():
                continue
            md = float(row.model_diameter.isel(artery=0))
            ml = float(row.model_length.isel(artery=0))
            lines.append(
                f"{int(o):>5} {_fmt(md, 1e6)} "
                + " ".join(_fmt(float(row.kassab_diameter.sel(artery=a)), 1e6) for a in ARTERIES)
                + f"   {_fmt(ml, 1e3)} "
                + " ".join(_fmt(float(row.kassab_length.sel(artery=a)), 1e3) for a in ARTERIES)
                + f" {n_model:>7}"
            )
        mad = " ".join(f"{a} {float(c.mean_abs_log10_ratio_diameter.sel(artery=a)):.3f}" for a in ARTERIES)
        mal = " ".join(f"{a} {float(c.mean_abs_log10_ratio_length.sel(artery=a)):.3f}" for a in ARTERIES)
        n = int(c.n_orders_compared.isel(artery=0))
        lines.append(f"mean |log10 model/Kassab| over {n} orders: D {mad} | L {mal}")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------
# The stage


def reduce(
    output_dir: str | os.PathLike, *, figures: bool = True, exports: bool = True, stream: TextIO | None = None
) -> Reduction:
    """Reduce every complete run of ``output_dir``: summary, comparison, tree exports, figures.

    Parameters
    ----------
    output_dir : path
        A sweep's output directory (``runs/<run_id>.zarr`` inside).
    figures : bool
        Write the PNG figures into ``<output_dir>/figures/``.
    exports : bool
        Write ``<output_dir>/trees/<run_id>.vtp`` and ``.csv`` for the best tree of every cell.
    stream : text stream, optional
        Where the comparison table and the list of outputs are printed (default stdout).

    Returns
    -------
    Reduction

    Raises
    ------
    ReductionError
        If ``output_dir`` holds no complete run. A failure while drawing figures or
        exporting trees is reported in ``Reduction.errors`` (and printed) instead: the
        summary and tables are written first and stay valid.
    """
    stream = stream or sys.stdout
    out = Path(output_dir)
    damaged: dict[str, str] = {}
    runs, skipped = find_runs(out, damaged)
    if not runs:
        why = "".join(f"\n  left out: {why}" for why in skipped.values())
        raise ReductionError(
            f"output_dir {str(out)!r}: no complete run under {str(out / RUNS_DIR)!r}; run the sweep "
            f"first (python -m vasc_pipeline +sweep=NAME output_dir=...){why}"
        )
    check_one_configuration(out, runs)
    morph = {}
    summary, best, dims = build_summary(runs, morph=morph, output_dir=out)
    summary_path = write_summary(summary, out / SUMMARY_NAME)
    frame = comparison_frame(summary)
    csv = _write_csv(frame, out / COMPARISON_CSV)
    csv_summary = _write_csv(_comparison_summary_frame(summary), out / COMPARISON_SUMMARY_CSV)
    result = Reduction(
        out, summary, summary_path, best, dims, frame, csv, csv_summary, skipped=skipped, damaged=damaged
    )
    stream.write(format_comparison(summary) + "\n")
    if exports:
        from .export import export_run

        try:
            for r in best.values():
                result.trees.extend(export_run(r.path, out / "trees"))
        except Exception as exc:  # an export problem must not hide the summary already written
            result.errors["exports"] = f"{type(exc).__name__}: {exc}"
    if figures:
        try:
            from .figures import make_figures

            result.figures = make_figures(summary, out)
        except Exception as exc:
            result.errors["figures"] = f"{type(exc).__name__}: {exc}"
    lines = [
        f"vasc_pipeline: reduced {len(runs)} complete runs in {len(best)} cells ({len(skipped)} stores left out)",
        f"  summary: {summary_path} (xarray.open_datatree(path, engine='zarr'))",
        f"  comparison: {csv}, {csv_summary}",
    ]
    if result.trees:
        lines.append(f"  trees: {out / 'trees'} ({len(result.trees)} files: .vtp for ParaView, .csv)")
    if result.figures:
        lines.append(f"  figures: {out / 'figures'} ({len(result.figures)} PNG)")
    for path, why in skipped.items():
        lines.append(f"  left out: {why if path in damaged else f'{path}: {why}'}")
    for stage, error in result.errors.items():
        lines.append(f"  {stage} FAILED: {error}")
    stream.write("\n".join(lines) + "\n")
    stream.flush()
    return result
