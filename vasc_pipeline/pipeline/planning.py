"""Planning a sweep: its jobs, what is already on disk, and the stores of new runs.

:func:`plan` expands the grid (:func:`vasc_pipeline.pipeline.sweep.expand`) and builds one problem
per distinct N so that tissue and tree errors surface before anything runs (no writes).
:func:`inspect_stores` reads the existing stores (complete, started, damaged) and refuses a
changed configuration; :func:`create_stores` creates the stores of new runs before any job
is dispatched, never lazily by a worker.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import config as _config
from ..config.schema import ConfigError, RunConfig
from ..store.run_store import (
    RUNS_DIR,
    STATUS_COMPLETE,
    SWEEP_AXES,
    RunStore,
    StoreError,
    identity_differences,
    is_empty_leftover,
    verify_store,
)
from .sweep import Job, cell_id, expand

__all__ = ["Plan", "plan", "inspect_stores", "check_one_configuration", "create_stores"]


@dataclass
class Plan:
    """The sweep's jobs and what is already on disk."""

    config: RunConfig
    jobs: list[Job]
    total_steps: dict[str, int]  # run_id -> proposed moves of the run
    complete: set[str] = field(default_factory=set)  # run ids whose store is complete
    started: dict[str, int] = field(default_factory=dict)  # run_id -> committed steps of unfinished stores
    damaged: dict[str, str] = field(default_factory=dict)  # run_id -> what is wrong with its store (left out)

    @property
    def output_dir(self) -> Path:
        return Path(self.jobs[0].config["output_dir"])

    @property
    def pending(self) -> list[Job]:
        return [j for j in self.jobs if j.run_id not in self.complete and j.run_id not in self.damaged]


def plan(cfg: Any) -> Plan:
    """Expand and validate the sweep; build each distinct problem once to check the tissue.

    Raises ConfigError, TissueError or TreeError naming the field. Writes nothing.
    """
    from .. import engine

    cfg = _config.to_run_config(cfg)
    jobs = expand(cfg)
    total_steps: dict[str, int] = {}
    checked: dict[int, int] = {}
    for j in jobs:
        n = j.coords["n_terminals"]
        if n not in checked:  # everything but N is shared by the grid's tissues
            checked[n] = 1
            engine.build_problem(j.config)
        total_steps[j.run_id] = _config.scheduled_steps(j.run_config())
    return Plan(cfg, jobs, total_steps)


def inspect_stores(p: Plan) -> None:
    """Fill ``p.complete`` / ``p.started`` / ``p.damaged`` from existing stores (no writes).

    Refuses (ConfigError) a store of this sweep with a changed config, and any store of the
    output_dir whose configuration differs in more than the sweep axes (:func:`check_one_configuration`).
    A store that fails :func:`vasc_pipeline.store.verify_store` is left out, with the reason.
    """
    for j in p.jobs:
        if not Path(j.store).exists() or is_empty_leftover(j.store):
            continue
        try:
            store = verify_store(j.store)
        except StoreError as exc:
            p.damaged[j.run_id] = str(exc)
            continue
        store.check_config(j.config)
        if store.status == STATUS_COMPLETE:
            p.complete.add(j.run_id)
        else:
            p.started[j.run_id] = int(store.attrs.get("steps_done", 0))
    check_one_configuration(p)


def check_one_configuration(p: Plan) -> None:
    """Refuse a sweep whose runs would share an output_dir with runs of another configuration.

    Every store of an output_dir shares the configuration except the sweep axes
    (``store.SWEEP_AXES``; runs of another method share what both methods use), and the runs
    of one cell (grid point without the seed) share their number of proposed moves: otherwise
    the reduction's best seed of a cell would be picked across different physics or
    schedules. Unreadable stores are skipped here (see
    :func:`inspect_stores` and the reduction, which name them).
    """
    first = p.jobs[0]
    cell_steps = {j.cell: p.total_steps[j.run_id] for j in p.jobs}
    root = p.output_dir / RUNS_DIR
    for path in sorted(root.glob("*.zarr")) if root.is_dir() else []:
        try:
            attrs = RunStore.open(path, mode="r").attrs
        except StoreError:
            continue
        diff = identity_differences(attrs.get("config") or {}, first.config)
        coords = attrs.get("coords") or {}
        try:
            cell = cell_id(
                coords["tissue"],
                coords["n_terminals"],
                coords["m_b"],
                coords.get("steps"),
                coords.get("method") or "anneal",
            )
        except (KeyError, TypeError, ValueError):
            cell = None
        if cell in cell_steps and int(attrs.get("total_steps", -1)) != cell_steps[cell]:
            diff.append(
                f"proposed moves of cell {cell}: {attrs.get('total_steps')} (stored) vs "
                f"{cell_steps[cell]} (requested; anneal.steps)"
            )
        if diff:
            raise ConfigError(
                f"output_dir {str(p.output_dir)!r} holds runs of another configuration, and runs are never mixed: "
                f"{path.name} differs in {'; '.join(diff)}. Every run in one output_dir shares its configuration "
                f"except the sweep axes ({', '.join(SWEEP_AXES)}), and the runs of one cell share their "
                "anneal.steps. Restore those settings, or choose a new output_dir (output_dir=...) for the "
                "changed configuration."
            )


def create_stores(p: Plan) -> None:
    """Create the store of every job that has none (before dispatch: never lazily by a worker)."""
    from .job import create_store  # job imports the kernel, as plan() does: not at import time

    for j in p.pending:
        if not RunStore.exists(j.store):
            create_store(j, p.total_steps[j.run_id])
