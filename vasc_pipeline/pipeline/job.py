"""Run one job of a sweep into its store: start or resume, anneal in blocks, checkpoint, finish.

A plain function, no Dask inside (the orchestrator wraps it), usable on its own::

    from vasc_pipeline import config, job, sweep
    (j,) = sweep.expand(config.compose(["tissue=plane2d", "anneal.steps=200000", "output_dir=/tmp/r"]))
    job.run_job(j)          # {'run_id': ..., 'status': 'complete', ...}

The anneal loop is the engine's (blocks of ``anneal.trace_every`` proposals, one trace
record per block); blocks start at multiples of ``trace_every`` from step 0 whether or not
the run was resumed, so a resumed run ends with exactly the tree and trace of an
uninterrupted one. The job writes everything it produces to the store and returns a small
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
from ..model.costs import full_costs
from ..store.run_store import STATUS_COMPLETE, CheckpointWarning, RunStore, is_empty_leftover, run_lock
from .sweep import Job

__all__ = ["run_job", "ensure_store", "create_store"]

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

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CheckpointWarning)
            checkpoint = store.load_checkpoint()
        for w in caught:  # re-emit for the caller's log, and keep the text for the summary
            seen.append(str(w.message))
            warnings.warn(w.message, w.category, stacklevel=2)
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

        trace = engine.Trace()
        if checkpoint is None:
            trace.append(engine.trace_record(problem, state, 0, 0))
        total = problem.total_steps
        block = int(problem.config.anneal.trace_every)
        every = float(problem.config.checkpoint.every_seconds)
        step0 = int(state.counters[kernel.COUNTER_STEP])
        last_checkpoint = time.perf_counter()

        def wall() -> float:
            return wall_before + (time.perf_counter() - started)

        parts = int(problem.config.anneal.parts)
        ends = phase_ends(problem) if parts > 1 else None
        for step in engine.anneal_blocks(problem, state, trace, block, part_map):
            if report is not None:
                msg = {
                    "run_id": job.run_id,
                    "cell": job.cell,
                    "step": step,
                    "total_steps": total,
                    "cost": float(trace.last.total),
                }
                if ends is not None:  # phases done, phases, parts
                    msg["phase"] = [int(np.searchsorted(ends, step, side="right")), len(ends), parts]
                report(msg)
            if time.perf_counter() - last_checkpoint >= every and step < total:
                trace_length = store.append_trace(trace.arrays(), trace_length)
                trace.clear()  # the same Trace: anneal_blocks records into it
                store.write_checkpoint(
                    engine.state_arrays(state), step=step, trace_length=trace_length, wall_seconds=wall()
                )
                last_checkpoint = time.perf_counter()

        trace_length = store.append_trace(trace.arrays(), trace_length)
        anneal_report = engine.finish(problem, state)
        tree = engine.tree_of(problem, state)
        _write_tree(
            store,
            problem,
            tree,
            cost=engine.running_costs(problem, state),
            cost_recomputed=full_costs(tree, problem.tissue, problem.physics, problem.terms),
            steps_done=int(state.counters[kernel.COUNTER_STEP]),
            trace_length=trace_length,
            wall_seconds=wall(),
            anneal=anneal_report,
        )
        session_steps = int(state.counters[kernel.COUNTER_STEP]) - step0
        return _summary(
            job,
            store,
            "complete",
            resumed_from,
            session_steps,
            time.perf_counter() - started,
            seen,
            time.process_time() - cpu_started,
        )


def _write_tree(store: RunStore, problem: engine.Problem, tree, **final) -> None:
    """The final tree of either method, with what follows from it (radii, kinds, statistics)."""
    store.write_final(
        parent=tree.parent,
        position=tree.position,
        radius=engine.node_radii(tree, problem.physics),
        kind=tree.kind,
        physics=problem.physics.as_attrs(),
        statistics=engine.tree_statistics(problem, tree),
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
