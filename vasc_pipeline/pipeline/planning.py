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
from ..config.identity import mixed_configuration
from ..config.schema import ConfigError, RunConfig
from ..store.layout import coords_cell_id, run_store_paths
from ..store.run_store import (
    STATUS_COMPLETE,
    SWEEP_AXES,
    RunStore,
    StoreError,
    is_empty_leftover,
    verify_store,
)
from .sweep import Job, expand

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
            engine.build_problem(j.run_config())
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

    The rule is :func:`vasc_pipeline.config.identity.mixed_configuration`'s (the reduction
    applies it too): the stored runs against the requested config and step counts. Unreadable
    stores are skipped here (see :func:`inspect_stores` and the reduction, which name them).
    """
    stored = []
    for path in run_store_paths(p.output_dir):
        try:
            attrs = RunStore.open(path, mode="r").attrs
        except StoreError:
            continue
        try:
            cell = coords_cell_id(attrs.get("coords") or {})
        except (KeyError, TypeError, ValueError):
            cell = None
        stored.append((path.name, attrs.get("config") or {}, cell, int(attrs.get("total_steps", -1))))
    requested = {j.cell: p.total_steps[j.run_id] for j in p.jobs}
    for name, diff, clash in mixed_configuration(stored, p.jobs[0].config, requested)[:1]:
        if clash:
            cell, steps, requested_steps, _ = clash
            diff.append(
                f"proposed moves of cell {cell}: {steps} (stored) vs {requested_steps} (requested; anneal.steps)"
            )
        raise ConfigError(
            f"output_dir {str(p.output_dir)!r} holds runs of another configuration, and runs are never mixed: "
            f"{name} differs in {'; '.join(diff)}. Every run in one output_dir shares its configuration "
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
