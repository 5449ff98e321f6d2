"""Run one job of a sweep into its store: start or resume, anneal in blocks, checkpoint, finish.

A plain function, no Dask inside (the orchestrator wraps it), usable on its own::

    from vasc_pipeline import config, job, sweep
    (j,) = sweep.expand(config.compose(["tissue=plane2d", "anneal.steps=200000", "output_dir=/tmp/r"]))
    job.run_job(j)          # {'run_id': ..., 'status': 'complete', ...}

The anneal is :func:`vasc_pipeline.engine.run` itself (blocks of ``anneal.trace_every``
proposals, one trace record per block), with the store's hook (:class:`StoreHook`: progress
and checkpoints) after every block; blocks start at multiples of ``trace_every`` from step 0
whether or not the run was resumed, so a resumed run ends with exactly the tree and trace
of an uninterrupted one. The job writes everything it produces to the store and returns a small
summary: results held in a dead worker's memory would be recomputed when the worker dies.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from .. import engine, kernel
from ..engine.parts import phase_ends
from ..store.run_store import STATUS_COMPLETE, Checkpoint, CheckpointWarning, RunStore, is_empty_leftover, run_lock
from ..store.trace import Trace
from .sweep import Job

__all__ = ["run_job", "ensure_store", "create_store", "StoreHook"]

Reporter = Callable[[Mapping[str, Any]], None]


def create_store(job: Job, total_steps: int) -> RunStore:
    """Create the job's store (status "running"); the one place a run store is made from a job.

    The orchestrator creates the stores of new runs before dispatch; :func:`ensure_store`
    creates one only when the job is run on its own.
    """
    if is_empty_leftover(job.store):  # a crash between mkdir and the store's zarr.json
        Path(job.store).rmdir()
    return RunStore.create(
        job.store,
        run_id=job.run_id,
        seed=job.coords["seed"],
        config=job.config,
        coords=job.coords,
        total_steps=total_steps,
    )


def ensure_store(job: Job, total_steps: int) -> RunStore:
    """Open the job's store, checking its config, or create it (status "running")."""
    if RunStore.exists(job.store):
        store = RunStore.open(job.store)
        store.check_config(job.config)
        return store
    return create_store(job, total_steps)


def _summary(
    job: Job,
    store: RunStore,
    status: str,
    resumed_from: int | None,
    session_steps: int,
    session_seconds: float,
    warnings_seen: list[str],
    cpu_seconds: float = 0.0,
) -> dict[str, Any]:
    attrs = store.attrs
    cost = attrs.get("cost") or {}
    recomputed = attrs.get("cost_recomputed") or {}
    return {
        "run_id": job.run_id,
        "cell": job.cell,
        "seed": job.coords["seed"],
        "status": status,
        "resumed_from": resumed_from,
        "steps_done": int(attrs["steps_done"]),
        "session_steps": int(session_steps),
        "session_seconds": float(session_seconds),
        "session_cpu_seconds": float(cpu_seconds),
        "wall_seconds": float(attrs["wall_seconds"]),
        "cost": cost.get("total"),
        "cost_recomputed": recomputed.get("total"),
        "store": job.store,
        "warnings": warnings_seen,
    }


def run_job(job: Job, report: Reporter | None = None, part_map: Callable = map) -> dict[str, Any]:
    """Run (or resume, or skip) one job and return a small summary dict.

    Parameters
    ----------
    job : Job
        From :func:`vasc_pipeline.pipeline.sweep.expand`.
    report : callable, optional
        Called after every block with ``{"run_id", "cell", "step", "total_steps", "cost"}``
        (``cost`` the annealed total, W-scaled): the orchestrator's progress line.
    part_map : callable, default map
        Runs the parts of an ``anneal.parts`` > 1 anneal (the orchestrator's: on the cluster's
        workers); it does not change the result.

    Returns
    -------
    dict
        ``run_id``, ``cell``, ``seed``, ``status`` ("complete" | "skipped": already complete),
        ``resumed_from`` (checkpoint step, or None for a fresh start or a skip), ``steps_done``,
        ``session_steps`` (proposals run in this call), ``session_seconds`` (wall) and
        ``session_cpu_seconds`` (CPU time of the process) of this call, ``wall_seconds``
        (all sessions), ``cost``, ``cost_recomputed`` (annealed totals), ``store``,
        ``warnings`` (checkpoint fallbacks, as text).
    """
    started, cpu_started = time.perf_counter(), time.process_time()
    problem = engine.build_problem(job.run_config())
    seen: list[str] = []
    with run_lock(job.store):
        store = ensure_store(job, problem.total_steps)
        if store.status == STATUS_COMPLETE:
            if not store.is_tidy():  # a crash between "complete" and tidying up
                store.tidy()
            return _summary(job, store, "skipped", None, 0, time.perf_counter() - started, seen)
        if problem.config.method.name == "cco":
            return _run_cco(job, problem, store, started, cpu_started, report)

        checkpoint = _load_checkpoint(store, seen)
        store.record_resume(checkpoint)
        if checkpoint is None:
            state = engine.initial_state(problem, job.coords["seed"])
            store.write_start(problem.tissue, problem.physics.as_attrs())
            trace_length, wall_before, resumed_from = 0, 0.0, None
        else:
            state = engine.restore_state(problem, checkpoint.arrays)
            trace_length, wall_before, resumed_from = checkpoint.trace_length, checkpoint.wall_seconds, checkpoint.step
            if not store.has_tissue():
                store.write_start(problem.tissue, problem.physics.as_attrs())
        store.set_trace_length(trace_length)  # cut records of a crashed session
        hook = StoreHook(job, problem, store, trace_length, wall_before, started, report)

        step0 = int(state.counters[kernel.COUNTER_STEP])
        result = engine.run(
            seed=job.coords["seed"], problem=problem, state=state, part_map=part_map, on_block=hook.on_block
        )
        _write_tree(
            store,
            problem,
            result.tree,
            cost=result.costs,
            cost_recomputed=result.costs_recomputed,
            steps_done=result.steps,
            trace_length=store.append_trace(result.trace, hook.trace_length),  # the records after the last checkpoint
            wall_seconds=hook.wall(),
            anneal=result.anneal,
            statistics=result.statistics,
        )
        return _summary(
            job,
            store,
            "complete",
            resumed_from,
            result.steps - step0,
            time.perf_counter() - started,
            seen,
            time.process_time() - cpu_started,
        )


def _load_checkpoint(store: RunStore, seen: list[str]) -> Checkpoint | None:
    """The store's last good checkpoint (None: a fresh start); each fallback's warning is
    re-emitted for the caller's log, and its text kept in ``seen`` for the summary."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", CheckpointWarning)
        checkpoint = store.load_checkpoint()
    for w in caught:
        seen.append(str(w.message))
        warnings.warn(w.message, w.category, stacklevel=3)
    return checkpoint


class StoreHook:
    """The job's ``on_block`` for :func:`vasc_pipeline.engine.run`: the progress report after
    every block and, every ``checkpoint.every_seconds``, a checkpoint with the trace so far.

    ``trace_length`` is the store's trace records (committed with each checkpoint); ``wall``
    the run's wall time over all its sessions (``wall_before`` from the earlier ones).
    """

    def __init__(
        self,
        job: Job,
        problem: engine.Problem,
        store: RunStore,
        trace_length: int,
        wall_before: float,
        started: float,
        report: Reporter | None,
    ) -> None:
        self.job, self.problem, self.store, self.report = job, problem, store, report
        self.trace_length, self.wall_before, self.started = int(trace_length), float(wall_before), started
        self.every = float(problem.config.checkpoint.every_seconds)
        self.parts = int(problem.config.anneal.parts)
        self.ends = phase_ends(problem) if self.parts > 1 else None
        self.last_checkpoint = time.perf_counter()

    def wall(self) -> float:
        return self.wall_before + (time.perf_counter() - self.started)

    def on_block(self, step: int, state: kernel.State, trace: Trace) -> None:
        if self.report is not None:
            self.report(self.message(step, trace))
        if time.perf_counter() - self.last_checkpoint >= self.every and step < self.problem.total_steps:
            self.trace_length = self.store.append_trace(trace.take(), self.trace_length)
            self.store.write_checkpoint(
                engine.state_arrays(state), step=step, trace_length=self.trace_length, wall_seconds=self.wall()
            )
            self.last_checkpoint = time.perf_counter()

    def message(self, step: int, trace: Trace) -> dict[str, Any]:
        """The progress report: ``cost`` is the annealed total after the block (W-scaled)."""
        msg: dict[str, Any] = {
            "run_id": self.job.run_id,
            "cell": self.job.cell,
            "step": step,
            "total_steps": self.problem.total_steps,
            "cost": float(trace.last.total),
        }
        if self.ends is not None:  # phases done, phases, parts
            msg["phase"] = [int(np.searchsorted(self.ends, step, side="right")), len(self.ends), self.parts]
        return msg


def _write_tree(store: RunStore, problem: engine.Problem, tree, statistics: dict | None = None, **final) -> None:
    """The final tree of either method, with what follows from it (radii, kinds, statistics)."""
    store.write_final(
        parent=tree.parent,
        position=tree.position,
        radius=engine.node_radii(tree, problem.physics),
        kind=tree.kind,
        physics=problem.physics.as_attrs(),
        statistics=engine.tree_statistics(problem, tree) if statistics is None else statistics,
        **final,
    )


def _run_cco(
    job: Job, problem: engine.Problem, store: RunStore, started: float, cpu_started: float, report: Reporter | None
) -> dict[str, Any]:
    """A CCO run (``method=cco``): grow, then write the store as an anneal run writes it.

    Growth takes seconds, so there is no checkpoint: an interrupted CCO run starts again
    from its first terminal (the same tree: the run is a function of (config, seed)).
    The trace has one record per terminal added; ``steps_done`` is N.
    """
    from ..engine.cco import grow

    store.record_resume(None)
    store.write_start(problem.tissue, problem.physics.as_attrs())
    store.set_trace_length(0)
    result = grow(problem, job.coords["seed"])
    trace_length = store.append_trace(result.trace, 0)
    tree = result.tree
    n = problem.physics.n_terminals
    if report is not None:
        report({"run_id": job.run_id, "cell": job.cell, "step": n, "total_steps": n, "cost": result.costs["total"]})
    _write_tree(
        store,
        problem,
        tree,
        cost=result.costs,
        cost_recomputed=result.costs_recomputed,
        steps_done=n,
        trace_length=trace_length,
        wall_seconds=time.perf_counter() - started,
        anneal={"method": "cco", "sites_drawn": result.tries, "distance_factor": result.distance_factor},
    )
    return _summary(
        job, store, "complete", None, n, time.perf_counter() - started, [], time.process_time() - cpu_started
    )


def read_final_tree(path: str | Path) -> dict[str, np.ndarray]:
    """The final tree arrays of a complete run store (tests and tools)."""
    return RunStore.open(path, mode="r").read_tree()
