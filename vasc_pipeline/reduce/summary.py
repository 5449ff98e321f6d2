"""The summary of a sweep: the xarray DataTree of ``summary.zarr``, built from the complete runs and written atomically.

:func:`build_summary` assembles it from :func:`vasc_pipeline.reduce.runs.find_runs`' runs (the best
seed of every cell, its morphometry and comparison with Kassab et al. 1993, the costs and
traces of every seed); :func:`write_summary` writes it beside the old one and swaps it in.

``<output_dir>/summary.zarr`` is an xarray DataTree (Zarr v3, consolidated). Cell dims are
``n_terminals`` and ``m_b`` always, ``steps`` when the sweep had a steps axis and
``tissue`` when the directory holds more than one tissue, ``method`` when it holds both
anneal and CCO runs (otherwise each is a scalar coordinate). Groups:

- ``/morphometry``  (cell..., scheme, order): element and segment diameter/length mean, SD,
  SE and counts of the best tree; per cell ``best_seed``, ``best_run_id``, ``best_cost``,
  ``n_seeds``, ``trunk_spread`` (how alike the seeds' trees are: mean distance between
  their main trunks, m) and ``trunk_tortuosity`` (the best tree's main trunks, arc length
  over chord).
- ``/asymmetry``    (cell..., scheme, order): D_s/D_p and D_l/D_p by parent order, and
  ``symmetric_ratio`` = 2^(-1/gamma) per cell.
- ``/costs``        (cell..., seed): final costs (annealed total and every unscaled term),
  steps, wall time and run id of every complete run; ``is_best``; ``cavity_share`` (the
  heart: share of the large vessels' length inside the ventricular cavities).
- ``/anatomy``      (cell..., seed) and (cell..., seed, inlet): what a physiologist looks at
  first in every complete run (:mod:`vasc_pipeline.reduce.anatomy`): each inlet's share of the
  terminals, bifurcations off the organ, terminal pressures, the crowns' scaling exponents.
- ``/traces``       (cell..., seed, record): the cost traces of all complete runs,
  NaN-padded to the longest.
- ``/kassab``       (artery, level, order): :func:`vasc_pipeline.reduce.reference.kassab_dataset`.
- ``/comparison``   (cell..., artery, order) and (cell..., artery): model against Kassab,
  element level, diameter-defined orders; mean absolute log10 ratios.

``/kassab`` and ``/comparison`` exist for a heart only (``tissue.organ``, decided by
:func:`vasc_pipeline.config.organ_of` when unset); the root attribute ``organ`` says which.

Orders of cells with different N are aligned on the shifted order (highest = 11): a
smaller tree simply has NaN / 0 at the low orders it does not reach.
"""

from __future__ import annotations

import datetime as _dt
import os
import shutil
import socket
import warnings
from pathlib import Path

import numpy as np
import psutil
import xarray as xr

from ..store.run_store import RunStore, file_lock
from . import morphometry as _m
from .cell_grid import CELL_META, COST_META, cell_dims, cell_var, stack_cells, strings_as_objects, with_steps
from .reference import ARTERIES, kassab_dataset
from .runs import ReductionError, RunInfo, as_float, best_runs
from .seed_groups import anatomy_group, cost_group, trace_group
from .similarity import main_trunks, tortuosity, trunk_spread

__all__ = ["build_summary", "write_summary", "COMPARISON_SCHEME", "COMPARISON_LEVEL"]

COMPARISON_SCHEME, COMPARISON_LEVEL = "diameter_defined", "element"


def _morphometry_of(run: RunInfo) -> xr.Dataset:
    tree = RunStore.open(run.path, mode="r").read_tree()
    return _m.morphometry(tree["parent"], tree["position"], tree["radius"], tree["kind"])


def _main_trunks_of(run: RunInfo) -> list[np.ndarray]:
    tree = RunStore.open(run.path, mode="r").read_tree()
    return main_trunks(tree["parent"], tree["position"], tree["kind"])


def _trunk_spread_of(cell_trunks: list[list[np.ndarray]]) -> float:
    """Mean over pairs of seeds of the trunk distance (:mod:`vasc_pipeline.reduce.similarity`); NaN for one seed."""
    if len(cell_trunks) < 2:
        return float("nan")
    return float(np.mean(trunk_spread(cell_trunks)))


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
    runs: list[RunInfo], *, output_dir: str | os.PathLike | None = None
) -> tuple[xr.DataTree, dict[tuple, RunInfo], list[str]]:
    """The summary DataTree of complete ``runs`` (see the module docstring for the schema).

    Parameters
    ----------
    runs : list of RunInfo
        From :func:`find_runs`; at least one.
    output_dir : path, optional
        Recorded in the root attributes.

    Returns
    -------
    (xarray.DataTree, dict of cell key -> best RunInfo, list of cell dims)
    """
    if not runs:
        raise ReductionError("no complete run to reduce")
    dims = cell_dims(runs)
    runs = with_steps(runs, dims)
    best = best_runs(runs, dims)
    cell_coords = {d: sorted({getattr(r, d) for r in runs}) for d in dims}
    morph = {key: _morphometry_of(r) for key, r in best.items()}
    # Kassab's pig coronary arteries are the yardstick of a heart's trees only (tissue.organ)
    heart = all(r.organ == "heart" for r in runs)
    # One order axis for all cells: the union of the shifted orders (highest 11) and Kassab's 1..11.
    reference = kassab_dataset() if heart else None
    lo = min([int(ds.order.min()) for ds in morph.values()] + ([int(reference.order.min())] if heart else []))
    orders = np.arange(lo, _m.TOP_ORDER + 1, dtype=np.int64)

    morph_parts, asym_parts, comp_parts = _cell_parts(morph, orders, reference)
    for name, values in _cell_extras(runs, best, dims).items():
        for key in best:
            morph_parts[key][name] = values[key]
    for key, r in best.items():
        gamma = as_float(r.physics.get("gamma"))
        asym_parts[key]["symmetric_ratio"] = xr.DataArray(
            2.0 ** (-1.0 / gamma), attrs={"units": "1", "long_name": "D_d/D_p at a symmetric bifurcation, 2^(-1/gamma)"}
        )

    morphometry = stack_cells(morph_parts, dims, cell_coords)
    morphometry.attrs.update(
        title="Order-wise morphometry of the lowest-cost tree of every cell",
        ordering="diameter_defined: Jiang, Kassab & Fung 1994 range reassignment; strahler: conventional. "
        f"Orders shifted so that the highest is {_m.TOP_ORDER} (Kassab's coronary trunk).",
    )
    asymmetry = stack_cells(asym_parts, dims, cell_coords)
    asymmetry.attrs.update(title="Daughter to parent diameter ratios by parent order (lowest-cost tree per cell)")
    groups = {
        "/": _root(runs, best, dims, output_dir, heart),
        "/morphometry": morphometry,
        "/asymmetry": asymmetry,
        "/costs": cost_group(runs, best, dims, cell_coords),
        "/anatomy": anatomy_group(runs, dims, cell_coords),
        "/traces": trace_group(runs, dims, cell_coords),
    }
    if heart:
        groups["/kassab"] = strings_as_objects(reference)
        groups["/comparison"] = _comparison_group(comp_parts, dims, cell_coords)
    _scalar_cell_coords(groups, dims, runs)
    for ds in groups.values():
        strings_as_objects(ds, inplace=True)
    return xr.DataTree.from_dict(groups), best, dims


def _cell_parts(morph: dict, orders: np.ndarray, reference: xr.Dataset | None) -> tuple[dict, dict, dict]:
    """Per cell, its best tree's morphometry on the common ``orders`` split into the ``/morphometry``
    and ``/asymmetry`` parts, and (a heart's, with ``reference``) its comparison with Kassab."""
    morph_parts, asym_parts, comp_parts = {}, {}, {}
    for key, ds in morph.items():
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
        if reference is not None:
            comp_parts[key], _ = _comparison_part(ds, reference, orders)
    return morph_parts, asym_parts, comp_parts


def _cell_extras(runs: list[RunInfo], best: dict, dims: list[str]) -> dict[str, dict]:
    """The per-cell scalars of ``/morphometry``: the best run, the seeds, the trunks' spread and tortuosity."""
    n_seeds = {k: sum(1 for r in runs if r.cell(dims) == k) for k in best}
    trunks = {r.path: _main_trunks_of(r) for r in runs}  # read once: the spread and the tortuosity use them
    return {
        "best_seed": cell_var(best, lambda r: r.seed, np.int64, "1", "seed of the lowest-cost run of the cell"),
        "best_run_id": cell_var(best, lambda r: r.run_id, object, None, "run id of the lowest-cost run of the cell"),
        "best_cost": cell_var(
            best,
            lambda r: r.cost["total"],
            np.float64,
            COST_META["total"][0],
            "final annealed total cost C of the lowest-cost run",
        ),
        "n_seeds": {
            k: xr.DataArray(np.int64(n), attrs={"units": "1", "long_name": "complete runs (seeds) in the cell"})
            for k, n in n_seeds.items()
        },
        "trunk_spread": {
            k: xr.DataArray(
                _trunk_spread_of([trunks[r.path] for r in runs if r.cell(dims) == k]),
                attrs={
                    "units": "m",
                    "long_name": "mean distance between the main trunks of two seeds, over pairs of seeds "
                    "(vasc_pipeline.reduce.similarity; NaN with one seed)",
                },
            )
            for k in best
        },
        "trunk_tortuosity": cell_var(
            best,
            lambda r: np.mean([tortuosity(t) for t in trunks[r.path]]),
            np.float64,
            "1",
            "main trunk arc length over chord, mean over inlets, of the best tree (1: straight)",
        ),
    }


def _root(runs: list[RunInfo], best: dict, dims: list[str], output_dir, heart: bool) -> xr.Dataset:
    """The root group: what the summary is of (its attributes only)."""
    return xr.Dataset(
        attrs={
            "title": "vasc_pipeline sweep summary",
            "Conventions": "CF-1.10",
            "history": f"{_dt.datetime.now(_dt.timezone.utc).isoformat(timespec='seconds')}: vasc_pipeline.reduce",
            "output_dir": str(Path(output_dir).resolve()) if output_dir is not None else "",
            "cell_dims": list(dims),
            "n_runs": len(runs),
            "n_cells": len(best),
            "tissues": sorted({r.tissue for r in runs}),
            "comparison_scheme": COMPARISON_SCHEME,
            "comparison_level": COMPARISON_LEVEL,
            "organ": "heart" if heart else "other",
        }
    )


def _scalar_cell_coords(groups: dict, dims: list[str], runs: list[RunInfo]) -> None:
    """One tissue or one method in the whole sweep: a scalar coordinate on every cell group (in place)."""
    cell_groups = [name for name in groups if name not in ("/", "/kassab")]
    if "tissue" not in dims:
        tissue = sorted({r.tissue for r in runs})[0]
        for name in cell_groups:
            groups[name] = groups[name].assign_coords(tissue=((), tissue, CELL_META["tissue"]))
    if "method" not in dims:
        method = runs[0].method
        for name in cell_groups:
            groups[name] = groups[name].assign_coords(method=((), method, CELL_META["method"]))


def _comparison_group(comp_parts: dict, dims: list[str], cell_coords: dict) -> xr.Dataset:
    """The ``/comparison`` group from the cells' :func:`_comparison_part` datasets."""
    comparison = stack_cells(comp_parts, dims, cell_coords)
    comparison = comparison.assign_coords(
        artery=("artery", np.array(ARTERIES, dtype=object), {"long_name": "coronary artery (Kassab 1993)"})
    )
    comparison["order"].attrs.update(long_name=f"vessel order (shifted: highest = {_m.TOP_ORDER})", units="1")
    comparison.attrs.update(
        title="Model (lowest-cost tree per cell) against Kassab et al. 1993",
        scheme=COMPARISON_SCHEME,
        level=COMPARISON_LEVEL,
    )
    return comparison


def write_summary(tree: xr.DataTree, path: str | os.PathLike) -> Path:
    """Write the DataTree to Zarr (v3, consolidated) at ``path``, replacing any previous one.

    Written to a temporary directory beside ``path`` and swapped in by renames, so a crash
    leaves either the old or the new summary readable, never a mix (between the two renames
    the old one is readable only as ``.<name>.old-<host>-<pid>``). The swap holds a lock, as
    ``+stage=reduce`` may run beside a sweep's own reduction; leftovers of writers on this
    host that no longer run are removed (the output_dir may be shared with other hosts).
    """
    path = Path(path)
    writer = f"{socket.gethostname()}-{os.getpid()}"
    tmp = path.with_name(f".{path.name}.tmp-{writer}")
    old = path.with_name(f".{path.name}.old-{writer}")
    _remove_leftovers(path, "tmp")
    with warnings.catch_warnings():  # "consolidated metadata is not part of the v3 spec"
        warnings.simplefilter("ignore", UserWarning)
        tree.to_zarr(tmp, mode="w", consolidated=True, zarr_format=3)
    with file_lock(path.with_name(f".{path.name}.lock")):
        if path.exists():
            os.replace(path, old)
        os.replace(tmp, path)
    shutil.rmtree(old, ignore_errors=True)
    _remove_leftovers(path, "old")
    return path


def _remove_leftovers(path: Path, kind: str) -> None:
    """Remove ``.<name>.<kind>-<host>-<pid>`` directories of this host whose process has ended."""
    for leftover in path.parent.glob(f".{path.name}.{kind}-{socket.gethostname()}-*"):
        pid = leftover.name.rpartition("-")[2]
        if pid.isdigit() and not psutil.pid_exists(int(pid)):
            shutil.rmtree(leftover, ignore_errors=True)
