"""The whole tree reduced: every complete store of ``<output_dir>/extended/`` against the pig's orders
1-11 and the published microvascular pressures, with its exports and figures.

A plain function of an output directory (no Hydra, no Dask)::

    from vasc_pipeline.reduce.extended import reduce_extended
    result = reduce_extended("results/size_scan")     # prints the table below
    result.summary                                     # the DataTree of extended_summary.zarr

For every complete, checksummed extended store (:mod:`vasc_pipeline.store.extended`):

- **Morphometry** of the whole tree over all its orders, both readings of the diameter-defined
  ordering (:func:`~vasc_pipeline.reduce.morphometry.morphometry`, ``reading="range"`` and
  ``"confluence"``), orders shifted so that the trunk is 11; a heart's is compared with Kassab
  et al. 1993 over orders 1-11 (element level, as the runs' reduction). The annealed terminals
  (kind 3) are pass-through nodes: the annealed terminal segment and its subtree's root segment
  are one segment, as long as both (:mod:`vasc_pipeline.model.topology`).
- **Anatomy** (:func:`~vasc_pipeline.reduce.anatomy.anatomy`, the Huo-Kassab crown exponents
  among it) with the whole tree's physics: N the fine terminals, the run's Q0, r_in, gamma, so
  every radius and flow is the stored one.
- **Pressures by order** from the model's Poiseuille solution
  (:func:`~vasc_pipeline.model.costs.poiseuille`): per diameter-defined order, the mean pressure
  along its vessels (length-weighted: every point of a vessel counts alike), the lowest (at a
  vessel's distal end) and the highest, in Pa and as a fraction of the inlet pressure
  (``physics.pressure_inlet``, the model's aortic pressure); and the same over the vessels of
  :data:`PUBLISHED_PRESSURES`' diameters, beside the published fractions. Every fine terminal's
  pressure is in the tree's CSV and VTP export (column ``pressure_Pa``).
- **Territories**: per annealed terminal t, its subtree's flow Q_t, the pressure P_t at t, the
  mean P̄_t and the lowest of its fine terminals' pressures, its **lumped resistance**
  R_t = (P_t − P̄_t) / Q_t and, for comparison, the series-parallel resistance of its vessels
  with every fine terminal at one pressure (R_network; differs from R_t because the model fixes
  every fine terminal's flow at Q0 / N instead of their pressures).
- **0D network** (``extend.zerod``): ``lumped`` (default), one ``BloodVessel`` per annealed
  segment as in a run's network and per territory one more vessel ``territory<t>`` of resistance
  R_t from the annealed terminal to a ``PRESSURE`` outlet at P̄_t; or ``full``, every vessel of
  the whole tree with a ``PRESSURE`` outlet at every fine terminal. Either network carries the
  model's inlet flows, so its solution gives the inlets the model's pressure and every
  territory its flow Q_t (tests: against the full tree's Poiseuille solution, by svZeroDSolver
  and by :func:`~vasc_pipeline.reduce.zerod.steady_solution`). The written network is checked
  (:func:`~vasc_pipeline.reduce.zerod.solver_check`) by svZeroDSolver when it is installed and
  the network has at most :data:`SVZEROD_MAX_VESSELS` vessels, else by ``steady_solution``.

The territories, networks and pressures of one whole tree are computed by
:mod:`vasc_pipeline.reduce.whole_tree` (its names re-exported here).

Writes ``<output_dir>/extended_summary.zarr`` (a DataTree beside ``summary.zarr``, so that the
runs' summary and the whole trees' are written by their own stages; groups ``/morphometry``,
``/comparison`` (a heart's), ``/pressure``, ``/anatomy``, ``/territory``, dim ``run_id``),
``extended_comparison.csv`` (per run, reading, artery and order: model against Kassab and the
pressures), ``trees/<run_id>.extended.{vtp,csv,0d.json}`` and ``figures/extended_*.png``.

Published pressures (:data:`PUBLISHED_PRESSURES`), source lines:

- Chilian WM, Eastham CL, Marcus ML (1986) Microvascular distribution of coronary vascular
  resistance in beating left ventricle. Am J Physiol 251:H779-H788 (cat).
- Chilian WM, Layne SM, Klausner EC, Eastham CL, Marcus ML (1989) Redistribution of coronary
  microvascular resistance produced by dipyridamole. Am J Physiol 256:H383-H390 (dog).

The numbers, about 60-80 % of aortic pressure in coronary arterioles of about 100-170 µm, are
those papers' as secondary sources summarise them; they were not checked against the papers'
own tables here.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np
import pandas as pd
import xarray as xr

from ..config.schema import EXTEND_ZERODS as ZERODS
from ..model.costs import Poiseuille, poiseuille
from ..model.physics import Physics
from ..store.extended import ExtendedStore
from ..store.layout import (
    EXTENDED_COMPARISON_CSV,
    EXTENDED_DIR,
    EXTENDED_SUMMARY_NAME,
    TREES_DIR,
    run_path,
)
from ..store.run_store import STATUS_COMPLETE, RunStore, StoreError
from . import morphometry as _m
from .anatomy import anatomy
from .extended_summary import (
    PRESSURE_META,
    PUBLISHED_PRESSURES,
    TERRITORY_META,
    Reduced,
    build_extended_summary,
    comparison_frame,
    counts_as_ints,
    format_extended,
)
from .ordering import READINGS
from .summary import write_summary
from .whole_tree import (
    WholeTree,
    full_network,
    lumped_network,
    pressures_by_order,
    published_band,
    territories,
    territory_table,
)

__all__ = [
    "PUBLISHED_PRESSURES",
    "SVZEROD_MAX_VESSELS",
    "ZERODS",
    "WholeTree",
    "ExtendedReduction",
    "extended_stores",
    "read_whole_tree",
    "territories",
    "territory_table",
    "lumped_network",
    "full_network",
    "pressures_by_order",
    "reduce_whole_tree",
    "reduce_extended",
    "extended_export_name",
    "PRESSURE_META",
    "TERRITORY_META",
]

# The largest 0D network svZeroDSolver checks; a larger one is checked by zerod.steady_solution
# (svZeroDSolver took 30-47 s for 18 000 vessels on a busy machine, more than 19 minutes for 210 000)
SVZEROD_MAX_VESSELS = 50_000


@dataclass
class ExtendedReduction:
    """What :func:`reduce_extended` produced."""

    output_dir: Path
    summary: xr.DataTree | None
    summary_path: Path | None
    comparison_csv: Path | None
    zerod: str
    trees: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)  # drawn by the pipeline (reduce_and_draw)
    skipped: dict[str, str] = field(default_factory=dict)  # store -> why it was not reduced
    errors: dict[str, str] = field(default_factory=dict)  # stage -> error text
    zero_d_check: dict[str, float] = field(default_factory=dict)  # run id -> the 0D solution's inlet deviation
    zero_d_solver: dict[str, str] = field(default_factory=dict)  # run id -> which solver checked it
    # run id -> wall seconds of its steps: "reduce" (morphometry, anatomy, pressures, territories),
    # "exports" (VTP, CSV, 0D network), "solver_check" (svZeroDSolver)
    seconds: dict[str, dict[str, float]] = field(default_factory=dict)


def extended_export_name(run_id: str) -> str:
    """The file stem of a whole tree's exports: ``<run_id>.extended``."""
    return f"{run_id}.extended"


def extended_stores(output_dir: str | os.PathLike) -> tuple[list[Path], dict[str, str]]:
    """The complete, checksummed stores of ``<output_dir>/extended/`` and, for every other one,
    why it is left out."""
    root = Path(output_dir) / EXTENDED_DIR
    found, skipped = [], {}
    for path in sorted(root.glob("*.zarr")) if root.is_dir() else []:
        try:
            store = ExtendedStore.open(path)
            if store.status != STATUS_COMPLETE:
                skipped[str(path)] = (
                    f"status {store.status!r}: {store.territories_done} of {store.attrs['n_territories']} territories "
                    "grown (the same +stage=extend command resumes it)"
                )
                continue
            store.verify()
        except StoreError as exc:
            skipped[str(path)] = str(exc)
            continue
        found.append(path)
    return found, skipped


def read_whole_tree(path: str | os.PathLike, output_dir: str | os.PathLike | None = None) -> WholeTree:
    """An extended store's tree and physics, its source run (``<output_dir>/runs/<run_id>.zarr``,
    else where it was when extended) for the inlet names and the organ."""
    from ..config.schema import organ_of

    store = ExtendedStore.open(path)
    attrs = store.attrs
    tree = store.read_tree()
    run_id = str(attrs["run_id"])
    candidates = [run_path(output_dir, run_id)] if output_dir is not None else []
    candidates.append(Path((attrs.get("source") or {}).get("store", "")))
    source = next((p for p in candidates if str(p) and (p / "zarr.json").is_file()), None)
    physics = Physics(**attrs["physics"])
    inlet_names: tuple[str, ...] = ()
    organ = "heart"
    if source is not None:
        run = RunStore.open(source, mode="r")
        inlet_names = tuple(run.group["tissue"].attrs.get("inlet_names", ()))
        config = run.attrs.get("config") or {}
        tissue = config.get("tissue") or {}
        organ = organ_of(str(tissue.get("name")), tissue.get("organ"), physics.n_inlets)
    return WholeTree(
        run_id=run_id,
        path=Path(path),
        parent=np.asarray(tree["parent"], dtype=np.int64),
        position=np.asarray(tree["position"], dtype=np.float64),
        radius=np.asarray(tree["radius"], dtype=np.float64),
        kind=np.asarray(tree["kind"], dtype=np.int8),
        physics=physics,
        attrs=attrs,
        source=source,
        inlet_names=inlet_names or tuple(f"inlet{i}" for i in range(physics.n_inlets)),
        organ=organ,
    )


# --------------------------------------------------------------------------------------------
# One whole tree


@dataclass
class WholeTreeResult:
    """:func:`reduce_whole_tree`'s datasets (no node dim) and what the exports need."""

    tree: WholeTree
    solution: Poiseuille
    morphometry: xr.Dataset  # (reading, scheme, order)
    segment_orders: dict[str, np.ndarray]  # reading -> diameter-defined / Strahler node orders (range)
    pressure: xr.Dataset  # (reading, order)
    anatomy: dict[str, float]
    territory: pd.DataFrame
    seconds: float


def reduce_whole_tree(path: str | os.PathLike, output_dir: str | os.PathLike | None = None) -> WholeTreeResult:
    """Morphometry (both readings), anatomy, pressures by order and territories of one extended store."""
    started = time.monotonic()
    tree = read_whole_tree(path, output_dir)
    solution = poiseuille(tree.parent, tree.position, tree.physics)
    parts, pressure, orders_of = [], [], {}
    for reading in READINGS:
        ds = _m.morphometry(tree.parent, tree.position, tree.radius, tree.kind, reading=reading)
        order = ds.segment_order.sel(scheme="diameter_defined").values
        orders_of[reading] = order
        if reading == READINGS[0]:
            orders_of["strahler"] = ds.segment_order.sel(scheme="strahler").values
        pressure.append(pressures_by_order(tree, solution, order, ds.order.values))
        dds = {"dds_iterations": int(ds.attrs["dds_iterations"]), "dds_converged": int(ds.attrs["dds_converged"])}
        ds = ds.drop_dims("node")
        for name, value in dds.items():
            ds[name] = ((), value, {"units": "1", "long_name": name.replace("_", " ")})
        ds.attrs = {}
        parts.append(ds)
    reading_dim = xr.DataArray(list(READINGS), dims="reading", name="reading")
    morph = counts_as_ints(xr.concat(parts, dim=reading_dim, join="outer"))
    pressure_ds = xr.concat(pressure, dim=reading_dim, join="outer")
    organ = voxel = origin = None
    if tree.source is not None:
        tissue = RunStore.open(tree.source, mode="r").group["tissue"]
        organ = tissue["exclusion"][...] > 0
        voxel, origin = float(tissue.attrs["voxel_size"]), np.asarray(tissue.attrs["origin"], dtype=np.float64)
    found = anatomy(
        tree.parent, tree.position, tree.radius, tree.kind, tree.physics, tree.inlet_names, organ, voxel, origin
    )
    found.update(published_band(tree, solution))
    table = territory_table(tree, solution)
    found["lumped_over_network_median"] = float(np.median(table.resistance_lumped / table.resistance_network))
    return WholeTreeResult(tree, solution, morph, orders_of, pressure_ds, found, table, time.monotonic() - started)


# --------------------------------------------------------------------------------------------
# The stage


def _export(result: WholeTreeResult, trees: Path, zerod: str) -> tuple[list[Path], dict]:
    """``trees/<run_id>.extended.{vtp,csv,0d.json}``; returns the paths and the 0D network."""
    from .export import export_paths, tree_table, write_csv, write_vtp
    from .zerod import write_zero_d, zero_d_path

    tree, s = result.tree, result.solution
    name = extended_export_name(tree.run_id)
    trees.mkdir(parents=True, exist_ok=True)
    table = tree_table(
        tree.parent,
        tree.position,
        tree.radius,
        tree.kind,
        total_flow=tree.physics.total_flow,
        orders=result.segment_orders["range"],
        strahler=result.segment_orders["strahler"],
    )
    table["pressure_Pa"] = s.pressure
    vtp, csv = export_paths(trees, name)
    paths = [write_vtp(vtp, table), write_csv(csv, table)]
    del table
    model = lumped_network(tree, s, result.territory) if zerod == "lumped" else full_network(tree, s)
    paths.append(write_zero_d(zero_d_path(trees, name), model))
    return paths, model


def reduce_extended(
    output_dir: str | os.PathLike,
    *,
    zerod: str = "lumped",
    exports: bool = True,
    stream: TextIO | None = None,
) -> ExtendedReduction:
    """Reduce every complete store of ``<output_dir>/extended/`` (module docstring).

    Parameters
    ----------
    output_dir : path
    zerod : {"lumped", "full"}
        The 0D network written (``extend.zerod``).
    exports : bool
        Write ``trees/<run_id>.extended.*``. The figures (``figures/extended_*.png``) are drawn from
        the result by :func:`vasc_pipeline.figures.extended.draw_extended`.
    stream : text stream, optional
        Where the table and the outputs are printed (default stdout).

    Returns
    -------
    ExtendedReduction
        ``summary`` None when no store is complete (nothing is written then). A failure in one
        tree's reduction or its exports is reported in ``errors``; the others go on.
    """
    if zerod not in ZERODS:
        raise ValueError(f"extend.zerod must be one of {', '.join(ZERODS)}, got {zerod!r}")
    stream = stream or sys.stdout
    out = Path(output_dir)
    paths, skipped = extended_stores(out)
    result = ExtendedReduction(out, None, None, None, zerod, skipped=skipped)
    from .zerod import solver_check

    reduced: list[Reduced] = []
    for path in paths:
        try:
            whole = reduce_whole_tree(path, out)
        except Exception as exc:  # one tree's failure must not hide the others'
            result.errors[f"reduce {path.name}"] = f"{type(exc).__name__}: {exc}"
            continue
        run_id = whole.tree.run_id
        seconds = result.seconds[run_id] = {"reduce": whole.seconds}
        table = whole.territory
        if exports:
            try:
                started = time.monotonic()
                written, model = _export(whole, out / TREES_DIR, zerod)
                result.trees.extend(written)
                seconds["exports"] = time.monotonic() - started
                p_in, small = whole.tree.physics.pressure_inlet, len(model["vessels"]) <= SVZEROD_MAX_VESSELS
                deviation = solver_check(model, p_in) if small else None
                result.zero_d_solver[run_id] = "svZeroDSolver"
                if deviation is None:  # too large for svZeroDSolver's time, or not installed
                    deviation = solver_check(model, p_in, solver="numpy")
                    result.zero_d_solver[run_id] = "steady_solution (NumPy)"
                seconds["solver_check"] = time.monotonic() - started - seconds["exports"]
                del model
                result.zero_d_check[run_id] = deviation
            except Exception as exc:
                result.errors[f"exports {run_id}"] = f"{type(exc).__name__}: {exc}"
        t = whole.tree
        reduced.append(Reduced(run_id, t.organ, t.physics, whole.morphometry, whole.pressure, whole.anatomy, table))
        del whole
    if not reduced:
        _report(result, stream)
        return result
    result.summary = build_extended_summary(reduced, out, zerod)
    result.summary_path = write_summary(result.summary, out / EXTENDED_SUMMARY_NAME)
    frame = comparison_frame(result.summary)
    tmp = out / f".{EXTENDED_COMPARISON_CSV}.tmp-{os.getpid()}"
    frame.to_csv(tmp, index=False, float_format="%.6g")
    os.replace(tmp, out / EXTENDED_COMPARISON_CSV)
    result.comparison_csv = out / EXTENDED_COMPARISON_CSV
    stream.write(format_extended(result.summary) + "\n")
    _report(result, stream)
    return result


def _report(result: ExtendedReduction, stream: TextIO) -> None:
    out = result.output_dir
    n = len(result.seconds)
    lines = [f"vasc_pipeline: reduced {n} whole tree{'' if n == 1 else 's'} of {out / EXTENDED_DIR}"]
    if result.summary_path is not None:
        lines.append(f"  summary: {result.summary_path}; table: {result.comparison_csv}")
    if result.trees:
        lines.append(
            f"  trees: {len(result.trees)} files in {out / TREES_DIR} (<run_id>.extended.vtp, .csv, .0d.json: "
            f"{result.zerod})"
        )
    for run_id, deviation in result.zero_d_check.items():
        lines.append(
            f"  0D check: {result.zero_d_solver[run_id]} gives {run_id}'s network the inlet pressure to "
            f"{deviation:.1e} (relative)"
        )
    for path, why in result.skipped.items():
        lines.append(f"  left out: {path}: {why}")
    for stage, error in result.errors.items():
        lines.append(f"  {stage} FAILED: {error}")
    stream.write("\n".join(lines) + "\n")
    stream.flush()
