"""The reduction stage: finished run stores -> ``summary.zarr``, comparison tables, tree exports.

A plain function of an output directory (no Hydra, no Dask)::

    from vasc_pipeline.reduce import reduce
    result = reduce("results/smoke")          # prints the comparison with Kassab 1993
    result.summary                            # the xarray.DataTree written to summary.zarr

Cells are the grid points without the seed: (tissue, n_terminals, m_b, steps). In every
cell the complete run with the lowest final annealed cost (``attrs["cost"]["total"]``)
is the cell's tree (:mod:`vasc_pipeline.reduce.runs`); its morphometry
(:func:`vasc_pipeline.reduce.morphometry.morphometry`, orders shifted so that the highest is 11) is
compared with Kassab et al. 1993 when the tissue is a heart (``tissue.organ``; the comparison's
table, CSVs, summary groups and figure panels are left out otherwise). The summary's schema is
:mod:`vasc_pipeline.reduce.summary`'s; this module writes it, derives the tables (``comparison.csv``,
``comparison_summary.csv``, ``anatomy.csv`` and the printed tables) from it, and writes the exports.
The figures are drawn from the summary by :mod:`vasc_pipeline.figures`; the pipeline calls the two in
order (:func:`vasc_pipeline.pipeline.reduction.reduce_and_draw`).
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np
import pandas as pd
import xarray as xr

from ..store.layout import (
    ANATOMY_CSV,
    COMPARISON_CSV,
    COMPARISON_SUMMARY_CSV,
    EXTENDED_DIR,
    FIGURES_DIR,
    RUNS_DIR,
    SUMMARY_NAME,
    TREES_DIR,
    run_store_paths,
)
from ..store.sweep_lock import sweep_in_progress
from . import morphometry as _m
from .anatomy import ANATOMY_FIELDS, HUO_KASSAB_EXPONENTS, MMHG
from .extended import ExtendedReduction, reduce_extended
from .reference import ARTERIES
from .runs import ReductionError, RunInfo, best_runs, check_one_configuration, find_runs
from .summary import COMPARISON_LEVEL, COMPARISON_SCHEME, build_summary, write_summary

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
    "anatomy_frame",
    "format_comparison",
    "format_anatomy",
    "reduce",
    "SUMMARY_NAME",
    "COMPARISON_CSV",
    "COMPARISON_SUMMARY_CSV",
    "ANATOMY_CSV",
    "COMPARISON_SCHEME",
    "COMPARISON_LEVEL",
]


@dataclass
class Reduction:
    """What :func:`reduce` produced."""

    output_dir: Path
    summary: xr.DataTree
    summary_path: Path
    best: dict[tuple, RunInfo]
    cell_dims: list[str]
    comparison: pd.DataFrame | None  # None (and no CSVs) for a tissue that is no heart (tissue.organ)
    comparison_csv: Path | None
    comparison_summary_csv: Path | None
    anatomy_csv: Path
    trees: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)  # drawn by the pipeline (reduce_and_draw)
    removed: list[Path] = field(default_factory=list)  # superseded tree exports and figures
    skipped: dict[str, str] = field(default_factory=dict)  # store -> why it was not used
    damaged: dict[str, str] = field(default_factory=dict)  # the skipped stores that fail their checks
    errors: dict[str, str] = field(default_factory=dict)  # stage (figures, ...) -> error text
    # run id -> svZeroDSolver's largest relative inlet-pressure deviation on the exported network
    zero_d_check: dict[str, float] = field(default_factory=dict)
    # the whole trees of extended/ (vasc_pipeline.reduce.extended); None without extended/
    extended: ExtendedReduction | None = None


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


def anatomy_frame(summary: xr.DataTree) -> pd.DataFrame:
    """The ``/anatomy`` group as a table, one row per complete run: its cell, seed and run id, each
    inlet's share of the terminals (``inlet_share_<inlet>``) and the anatomy's fields, their unit
    in the column name (``terminal_pressure_min_Pa``)."""
    anatomy = summary["anatomy"].to_dataset()
    keys = list(summary.attrs["cell_dims"]) + ["seed"]
    frame = anatomy[[name for name, _, _ in ANATOMY_FIELDS]].to_dataframe().reset_index()
    frame = frame.rename(columns={name: _with_unit(name, units) for name, units, _ in ANATOMY_FIELDS})
    shares = anatomy["inlet_share"].to_dataframe().reset_index()
    shares = shares.pivot(index=keys, columns="inlet", values="inlet_share")
    shares.columns = [f"inlet_share_{inlet}" for inlet in shares.columns]
    frame = frame.merge(shares.reset_index(), on=keys)
    run_ids = summary["costs"]["run_id"].to_dataframe().reset_index()
    frame = frame.merge(run_ids[keys + ["run_id"]], on=keys)
    frame = frame[frame.run_id != ""]
    front = keys + ["run_id"] + list(shares.columns)
    return frame[front + [c for c in frame.columns if c not in front and c not in ("tissue", "method")]].reset_index(
        drop=True
    )


def _with_unit(name: str, units: str) -> str:
    return name if units == "1" else f"{name}_{units}"


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
    anatomy = anatomy_frame(summary).drop(columns=keys + ["seed"], errors="ignore")  # the best tree's, by run id
    frame = frame[keys + ["run_id", "artery"] + names].merge(anatomy, on="run_id", how="left")
    return frame.reset_index(drop=True)


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


def format_anatomy(summary: xr.DataTree) -> str:
    """Human-readable anatomy of every cell's best tree (:mod:`vasc_pipeline.reduce.anatomy`), a line each."""
    anatomy = summary["anatomy"].to_dataset()
    morph = summary["morphometry"].to_dataset()
    dims = list(summary.attrs["cell_dims"])
    lines = ["Anatomy of every cell's best tree (pressures from the inlet's, by Poiseuille):"]
    stacked = morph["best_run_id"].stack(cell=dims)
    for i in range(stacked.sizes["cell"]):
        point = {d: stacked["cell"].values[i][j] for j, d in enumerate(dims)}
        run_id = str(stacked.values[i])
        if run_id:
            seed = int(morph["best_seed"].sel(point))
            lines.append(f"{run_id}: {_anatomy_line(anatomy.sel(point).sel(seed=seed))}")
    return "\n".join(lines)


def _anatomy_line(a: xr.Dataset) -> str:
    """One tree's anatomy in one line."""
    pairs = zip(a.inlet.values, a.inlet_share.values)
    shares = " ".join(f"{str(i)} {float(v):.0%}" for i, v in pairs if np.isfinite(v))
    off = float(a.bifurcations_off_organ_share)
    hk = HUO_KASSAB_EXPONENTS
    return (
        f"terminals {shares} | bifurcations > 2 mm off the organ "
        + (f"{off:.1%}" if np.isfinite(off) else "-")
        + f" | terminal pressure min {float(a.terminal_pressure_min) / MMHG:.0f}, median "
        f"{float(a.terminal_pressure_median) / MMHG:.0f} mmHg, mean drop {float(a.pressure_drop_mean) / MMHG:.0f} mmHg "
        f"({int(a.terminals_below_zero)} below 0) | crowns D_s ~ L_c^{float(a.diameter_crown_length_exponent):.2f} "
        f"({hk['diameter_crown_length']:.2f}), V_c ~ D_s^{float(a.crown_volume_diameter_exponent):.2f} "
        f"({hk['crown_volume_diameter']:g})"
    )


# --------------------------------------------------------------------------------------------
# The stage


def remove_superseded_outputs(output_dir: str | os.PathLike, best: dict) -> list[Path]:
    """Delete the tree exports and tree figures of runs that are no longer their cell's best.

    A cell's best tree changes when a better seed finishes; the earlier reduction's
    ``trees/<run_id>.{vtp,csv,0d.json}`` and ``figures/tree_<run_id>.png`` would otherwise stay
    beside the new ones. Only files named after a store in ``runs/`` are touched.
    """
    from .export import export_paths
    from .zerod import zero_d_path

    out = Path(output_dir)
    current = {r.run_id for r in best.values()}
    removed = []
    for store_path in run_store_paths(out):
        run_id = store_path.name.removesuffix(".zarr")
        if run_id in current:
            continue
        # the tree figure's name is make_figures' (vasc_pipeline.figures, not imported here: matplotlib)
        stale = (*export_paths(out / TREES_DIR, run_id), zero_d_path(out / TREES_DIR, run_id))
        for path in (*stale, out / FIGURES_DIR / f"tree_{run_id}.png"):
            if path.is_file():
                path.unlink()
                removed.append(path)
    return removed


def reduce(
    output_dir: str | os.PathLike,
    *,
    exports: bool = True,
    stream: TextIO | None = None,
    extended_zerod: str = "lumped",
) -> Reduction:
    """Reduce every complete run of ``output_dir``: summary, comparison, anatomy, tree exports;
    then, when there is an ``extended/``, its complete whole trees
    (:func:`vasc_pipeline.reduce.extended.reduce_extended`, with ``extended_zerod`` its 0D network).

    Parameters
    ----------
    output_dir : path
        A sweep's output directory (``runs/<run_id>.zarr`` inside).
    exports : bool
        Write ``<output_dir>/trees/<run_id>.vtp``, ``.csv`` and ``.0d.json`` (svZeroDSolver's
        input, :mod:`vasc_pipeline.reduce.zerod`) for the best tree of every cell.
    stream : text stream, optional
        Where the comparison table and the list of outputs are printed (default stdout).

    Returns
    -------
    Reduction

    Raises
    ------
    ReductionError
        If ``output_dir`` holds no complete run. A failure while exporting trees is reported
        in ``Reduction.errors`` (and printed) instead: the summary and tables are written first
        and stay valid.
    """
    stream = stream or sys.stdout
    out = Path(output_dir)
    damaged: dict[str, str] = {}
    runs, skipped = find_runs(out, damaged)
    sweep = sweep_in_progress(out)  # a sweep holding the output_dir: its unfinished runs are left out
    if not runs:
        raise _nothing_to_reduce(out, skipped, damaged, sweep)
    check_one_configuration(out, runs)
    summary, best, dims = build_summary(runs, output_dir=out)
    summary_path = write_summary(summary, out / SUMMARY_NAME)
    frame, csv, csv_summary = _write_comparison(summary, out, stream)
    csv_anatomy = _write_csv(anatomy_frame(summary), out / ANATOMY_CSV)
    stream.write(format_anatomy(summary) + "\n")
    result = Reduction(
        out, summary, summary_path, best, dims, frame, csv, csv_summary, csv_anatomy, skipped=skipped, damaged=damaged
    )
    result.removed = remove_superseded_outputs(out, best)
    if exports:
        _export_best(result, out)
    stream.write("\n".join(_report(result, len(runs), sweep)) + "\n")
    stream.flush()
    if (out / EXTENDED_DIR).is_dir():  # the whole trees: reduce_extended says which it leaves out
        try:
            result.extended = reduce_extended(out, zerod=extended_zerod, exports=exports, stream=stream)
            result.errors.update({f"extended {k}": v for k, v in result.extended.errors.items()})
        except Exception as exc:  # the runs' summary is written and valid: report, go on
            result.errors["extended"] = f"{type(exc).__name__}: {exc}"
            stream.write(f"  the whole trees' reduction FAILED: {result.errors['extended']}\n")
    return result


def _left_out(path: str, why: str, damaged: dict[str, str]) -> str:
    """A store left out, as the report says it (a damaged store's message names its path)."""
    return why if path in damaged else f"{path}: {why}"


def _nothing_to_reduce(out: Path, skipped: dict, damaged: dict, sweep) -> ReductionError:
    """The error of an output_dir with no complete run: what to do, and every store left out."""
    why = "".join(f"\n  left out: {_left_out(path, why, damaged)}" for path, why in skipped.items())
    return ReductionError(
        f"output_dir {str(out)!r}: no complete run under {str(out / RUNS_DIR)!r}; "
        + (
            f"a sweep is running in this output_dir ({sweep}) and none of its runs is complete yet: wait for "
            "it (it reduces the output_dir itself once its runs are complete)"
            if sweep
            else "run the sweep first (python -m vasc_pipeline +sweep=NAME output_dir=...)"
        )
        + why
    )


def _write_comparison(summary: xr.DataTree, out: Path, stream: TextIO) -> tuple:
    """A heart's comparison with Kassab: (frame, CSV, summary CSV), printed; else (None, None, None)
    and an earlier reduction's comparison files removed."""
    if "comparison" not in summary.children:
        for stale in (out / COMPARISON_CSV, out / COMPARISON_SUMMARY_CSV):  # an earlier reduction's, not of these runs
            stale.unlink(missing_ok=True)
        stream.write(
            "No comparison with Kassab et al. 1993 (pig coronary arteries): tissue.organ is other (set so, or a "
            "mask with one inlet); tissue.organ=heart compares the trees with them.\n"
        )
        return None, None, None
    frame = comparison_frame(summary)
    csv = _write_csv(frame, out / COMPARISON_CSV)
    csv_summary = _write_csv(_comparison_summary_frame(summary), out / COMPARISON_SUMMARY_CSV)
    stream.write(format_comparison(summary) + "\n")
    return frame, csv, csv_summary


def _export_best(result: Reduction, out: Path) -> None:
    """The best tree of every cell as .vtp, .csv and .0d.json, its 0D network checked (into ``result``).
    An export problem is recorded in ``result.errors``: it must not hide the summary already written."""
    from . import zerod
    from .export import export_run

    try:
        for r in result.best.values():
            vtp, table, network = export_run(r.path, out / TREES_DIR)
            result.trees.extend((vtp, table, network))
            deviation = zerod.solver_check(json.loads(network.read_text()), r.physics["pressure_inlet"])
            if deviation is not None:
                result.zero_d_check[r.run_id] = deviation
    except Exception as exc:
        result.errors["exports"] = f"{type(exc).__name__}: {exc}"


def _report(result: Reduction, n_runs: int, sweep) -> list[str]:
    """The lines printed after a reduction: what was written, what was left out, what failed."""
    out, skipped = result.output_dir, result.skipped
    lines = [
        f"vasc_pipeline: reduced {n_runs} complete runs in {len(result.best)} cells ({len(skipped)} stores left out)",
        f"  summary: {result.summary_path} (xarray.open_datatree(path, engine='zarr'))",
    ]
    if result.comparison_csv is not None:
        lines.append(f"  comparison: {result.comparison_csv}, {result.comparison_summary_csv}")
    lines.append(f"  anatomy: {result.anatomy_csv}")
    if result.trees:
        lines.append(
            f"  trees: {out / 'trees'} ({len(result.trees)} files: .vtp for ParaView, .csv, .0d.json for svZeroDSolver)"
        )
    if result.zero_d_check:
        worst = max(result.zero_d_check.values())
        lines.append(
            f"  0D check: svZeroDSolver on the exported networks gives the inlet pressure to {worst:.1e} (relative): "
            "the terminal pressures above are the networks' own"
        )
    if result.removed:
        lines.append(f"  removed {len(result.removed)} exports and figures of trees no longer their cell's best")
    for path, why in skipped.items():
        lines.append(f"  left out: {_left_out(path, why, result.damaged)}")
    if sweep:
        lines.append(
            f"  a sweep is running in this output_dir ({sweep}): its unfinished runs are left out; it reduces "
            "the output_dir again once its runs are complete"
        )
    for stage, error in result.errors.items():
        lines.append(f"  {stage} FAILED: {error}")
    return lines
