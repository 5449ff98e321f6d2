"""The reduction's input: the complete runs of an output directory and the best seed of every cell.

:func:`find_runs` lists the complete, verified stores under ``<output_dir>/runs`` (and why
every other store is left out), :func:`check_one_configuration` refuses a directory mixed
from different configurations, and :func:`best_runs` picks, per cell (a grid point without
the seed), the run with the lowest final annealed cost.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from ..config.identity import mixed_configuration
from ..config.schema import organ_of
from ..model.costs import COST_TERMS
from ..store.layout import cell_id, run_store_paths
from ..store.run_store import STATUS_COMPLETE, SWEEP_AXES, StoreError, verify_store

__all__ = ["RunInfo", "ReductionError", "find_runs", "check_one_configuration", "best_runs", "as_float", "COST_KEYS"]

COST_KEYS = ("total", *COST_TERMS)  # a run's attrs["cost"]


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
    organ: str = "heart"  # tissue.organ as read (config.organ_of): only a heart's tree is compared with Kassab

    @property
    def cell_id(self) -> str:
        """The run's cell key (:func:`vasc_pipeline.store.layout.cell_id`)."""
        return cell_id(self.tissue, self.n_terminals, self.m_b, self.steps, self.method)

    def cell(self, dims: Iterable[str]) -> tuple:
        return tuple(getattr(self, d) for d in dims)


def as_float(value: Any) -> float:
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
    for path in run_store_paths(output_dir):
        try:
            attrs = verify_store(path).attrs
        except StoreError as exc:
            skipped[str(path)] = str(exc)
            if damaged is not None:
                damaged[str(path)] = str(exc)
            continue
        if attrs.get("status") != STATUS_COMPLETE:
            skipped[str(path)] = (
                f"status {attrs.get('status')!r} (not complete: {attrs.get('steps_done', 0)} of "
                f"{attrs.get('total_steps', '?')} proposed moves)"
            )
            continue
        cost = {k: as_float((attrs.get("cost") or {}).get(k)) for k in COST_KEYS}
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
                wall_seconds=as_float(attrs.get("wall_seconds")),
                cost=cost,
                physics=dict(attrs.get("physics") or {}),
                config=config,
                statistics={k: as_float(v) for k, v in (attrs.get("statistics") or {}).items()},
                method=str(coords.get("method") or (config.get("method") or {}).get("name") or "anneal"),
                organ=organ_of(
                    str(coords.get("tissue", config.get("tissue", {}).get("name"))),
                    (config.get("tissue") or {}).get("organ"),
                    int((attrs.get("physics") or {}).get("n_inlets", 2)),  # not recorded: compared, as before
                ),
            )
        )
    return sorted(runs, key=lambda r: r.run_id), skipped


def check_one_configuration(output_dir: str | os.PathLike, runs: list[RunInfo]) -> None:
    """Refuse (ReductionError) runs of different configurations in one output_dir.

    The sweep refuses to write them (:func:`vasc_pipeline.pipeline.planning.check_one_configuration`;
    the rule is :func:`vasc_pipeline.config.identity.mixed_configuration`); this catches
    directories mixed by hand or by an older version, whose best seed per cell would otherwise
    be picked across different physics or schedules.
    """
    problems = []
    for name, diff, clash in mixed_configuration((r.run_id, r.config, r.cell_id, r.steps_done) for r in runs):
        if diff:
            problems.append(f"{name} differs from {runs[0].run_id} in {'; '.join(diff)}")
        if clash:
            _, steps, other_steps, other = clash
            problems.append(f"{name} ran {steps} proposed moves, {other} of the same cell {other_steps}")
    if problems:
        raise ReductionError(
            f"output_dir {str(output_dir)!r} holds runs of different configurations, which are never reduced together "
            f"(every run of an output_dir shares its configuration except the sweep axes {', '.join(SWEEP_AXES)}, "
            f"and one cell's runs their step count): {'; '.join(problems)}. Move the runs of one configuration to "
            "an output_dir of their own and reduce each."
        )


def best_runs(runs: list[RunInfo], dims: list[str]) -> dict[tuple, RunInfo]:
    """Per cell (tuple of ``dims`` values), the run with the lowest final total cost (ties: lowest seed)."""
    best: dict[tuple, RunInfo] = {}
    for r in runs:
        key = r.cell(dims)
        b = best.get(key)
        if b is None or (r.cost["total"], r.seed) < (b.cost["total"], b.seed):
            best[key] = r
    return dict(sorted(best.items()))
