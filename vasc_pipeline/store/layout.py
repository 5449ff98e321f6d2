"""The layout of an output_dir: every path the pipeline writes or reads under it, in one place.

::

    <output_dir>/
        .vasc_pipeline.lock        one sweep at a time (vasc_pipeline.pipeline.outdir)
        runs/<run_id>.zarr         one run store per run (vasc_pipeline.store.run_store)
        summary.zarr               the reduction's DataTree (vasc_pipeline.reduce.summary)
        comparison.csv             per order, model against Kassab 1993
        comparison_summary.csv     per cell, the mean errors
        trees/<run_id>.vtp, .csv   the best trees' exports (vasc_pipeline.reduce.export)
        figures/*.png              the figures (vasc_pipeline.figures)
        extended/<run_id>.zarr     the whole tree below a run (+stage=extend, vasc_pipeline.store.extended)
        extended_summary.zarr      the whole trees' reduction (vasc_pipeline.reduce.extended)
        extended_comparison.csv    per whole tree and order: model against Kassab 1993, pressures
        trees/<run_id>.extended.*  a whole tree's exports (.vtp, .csv, .0d.json)

A run's id names its store: :func:`run_id` = :func:`cell_id` (the grid point without the
seed, the reduction's cell) plus the seed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

__all__ = [
    "LOCK_NAME",
    "RUNS_DIR",
    "SLURM_LOG_DIR",
    "SUMMARY_NAME",
    "COMPARISON_CSV",
    "COMPARISON_SUMMARY_CSV",
    "ANATOMY_CSV",
    "TREES_DIR",
    "FIGURES_DIR",
    "EXTENDED_DIR",
    "EXTENDED_SUMMARY_NAME",
    "EXTENDED_COMPARISON_CSV",
    "cell_id",
    "coords_cell_id",
    "run_id",
    "run_path",
    "run_store_paths",
    "extended_path",
]

LOCK_NAME = ".vasc_pipeline.lock"
SLURM_LOG_DIR = ".slurm_logs"  # cluster=slurm: the worker jobs' logs (unless cluster.slurm.log_directory)
RUNS_DIR = "runs"
SUMMARY_NAME = "summary.zarr"
COMPARISON_CSV = "comparison.csv"
COMPARISON_SUMMARY_CSV = "comparison_summary.csv"
ANATOMY_CSV = "anatomy.csv"
TREES_DIR = "trees"
FIGURES_DIR = "figures"
EXTENDED_DIR = "extended"
EXTENDED_SUMMARY_NAME = "extended_summary.zarr"  # beside summary.zarr, never in extended/ (which holds stores)
EXTENDED_COMPARISON_CSV = "extended_comparison.csv"


def _number(value: float) -> str:
    """Compact, stable text of a grid value: 641.3 -> '641.3', 6413.0 -> '6413', 1e12 -> '1e12'."""
    return f"{value:.10g}".replace("e+", "e")


def cell_id(tissue: str, n_terminals: int, m_b: float, steps: int | None = None, method: str = "anneal") -> str:
    """``<tissue>-N<N>-mb<m_b>[-S<steps>][-<method>]``: the cell key, a grid point without the seed."""
    text = f"{tissue}-N{int(n_terminals)}-mb{_number(m_b)}"
    text = text if steps is None else f"{text}-S{int(steps)}"
    return text if method == "anneal" else f"{text}-{method}"  # anneal ids stay as they always were


def run_id(
    tissue: str, n_terminals: int, m_b: float, seed: int, steps: int | None = None, method: str = "anneal"
) -> str:
    """``<tissue>-N<N>-mb<m_b>[-S<steps>][-<method>]-s<seed>``: the grid coordinates (cell id + seed).

    The method appears only when it is not the anneal (``heart-N200-mb641.3-cco-s0``), so
    the ids of anneal runs are those of stores written before CCO existed.
    """
    return f"{cell_id(tissue, n_terminals, m_b, steps, method)}-s{int(seed)}"


def coords_cell_id(coords: Mapping[str, Any]) -> str:
    """:func:`cell_id` of a run's grid coordinates (a store's ``attrs["coords"]``)."""
    return cell_id(
        coords["tissue"], coords["n_terminals"], coords["m_b"], coords.get("steps"), coords.get("method") or "anneal"
    )


def run_path(output_dir: str | os.PathLike, run_id: str) -> Path:
    """The store of run ``run_id``: ``<output_dir>/runs/<run_id>.zarr``."""
    return Path(output_dir) / RUNS_DIR / f"{run_id}.zarr"


def run_store_paths(output_dir: str | os.PathLike) -> list[Path]:
    """Every run store under ``<output_dir>/runs``, sorted by name (none without the folder)."""
    root = Path(output_dir) / RUNS_DIR
    return sorted(root.glob("*.zarr")) if root.is_dir() else []


def extended_path(output_dir: str | os.PathLike, run_id: str) -> Path:
    """The whole tree below run ``run_id``: ``<output_dir>/extended/<run_id>.zarr``."""
    return Path(output_dir) / EXTENDED_DIR / f"{run_id}.zarr"
