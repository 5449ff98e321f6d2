"""The Dask fan-out of a sweep: one task per unfinished run, collected as they finish.

:func:`run_on_cluster` takes the plan's pending jobs to a Dask client (the caller's, or one
opened from ``cfg.cluster`` and closed after), shows their progress and records every
outcome in the :class:`~vasc_pipeline.pipeline.sweep_result.SweepResult`. A run in parts
takes the whole cluster for its parts, so such sweeps submit one run at a time.
"""

from __future__ import annotations

import contextlib
import time
import uuid
from typing import Any, TextIO

from ..config.schema import ClusterConfig, RunConfig
from .cluster import SweepStartError, has_bokeh, open_client, wait_for_workers
from .planning import Plan
from .progress import PROGRESS_TOPIC, Progress, runs_phrase
from .sweep import Job
from .sweep_result import SweepResult
from .task import run_job_task

__all__ = ["run_on_cluster"]


def run_on_cluster(
    cfg: RunConfig,
    p: Plan,
    client: Any,
    result: SweepResult,
    stream: TextIO,
    progress_interval: float | None,
) -> None:
    """Run ``p.pending`` on ``client`` (None: a cluster of ``cfg.cluster``, closed on return),
    with the live progress line; outcomes go into ``result``.

    Raises :class:`SweepStartError` when no worker, or no job, started within
    ``cluster.startup_timeout``.
    """
    pending = p.pending
    with contextlib.ExitStack() as stack:
        if client is None:
            client = stack.enter_context(open_client(cfg.cluster, len(pending), p.output_dir))
        wait_for_workers(client, cfg.cluster, len(pending))
        # An existing scheduler draws its own dashboard; ours only with bokeh here.
        dashboard = (
            getattr(client, "dashboard_link", None)
            if cfg.cluster.address or (cfg.cluster.dashboard_address and has_bokeh())
            else None
        )
        progress = Progress(p, stream, progress_interval)
        _announce_dashboard(dashboard, cfg.cluster, stream)
        client.subscribe_topic(PROGRESS_TOPIC, progress.event)
        try:
            _dispatch(client, cfg.cluster, pending, progress, result)
        finally:
            client.unsubscribe_topic(PROGRESS_TOPIC)
            progress.close()


def _announce_dashboard(dashboard: str | None, cluster: ClusterConfig, stream: TextIO) -> None:
    if dashboard:
        stream.write(f"vasc_pipeline: Dask dashboard at {dashboard}\n")
    elif cluster.dashboard_address and not cluster.address:
        stream.write(
            "vasc_pipeline: no Dask dashboard: it needs bokeh (pip install 'bokeh>=3.1'); progress is printed here\n"
        )


def _dispatch(client: Any, cluster: ClusterConfig, pending: list[Job], progress: Progress, result: SweepResult) -> None:
    """Submit the jobs (at most a window of them at a time), collect each as it finishes and
    submit the next; give up when none has started by ``cluster.startup_timeout``."""
    # Keys name the run (dashboard, logs) and this sweep, so that a client reused for a
    # second sweep never hands back a finished task of the first.
    token = uuid.uuid4().hex[:8]
    queue = list(pending)
    # A tree in parts takes the whole cluster for its parts: such runs go one at a time.
    window = 1 if any(j.run_config().anneal.parts > 1 for j in pending) else len(queue)
    futures = {_submit(client, cluster, token, j): j for j in queue[:window]}
    queue = queue[window:]
    remaining = set(futures)
    deadline = time.monotonic() + cluster.startup_timeout
    running = False
    while remaining:
        done, remaining = _wait_some(remaining, 1.0)
        for fut in done:
            _collect(fut, futures[fut], progress, result)
            if queue:
                j = queue.pop(0)
                nxt = _submit(client, cluster, token, j)
                futures[nxt] = j
                remaining.add(nxt)
        running = running or bool(done) or progress.any_started
        if not running and time.monotonic() > deadline:
            client.cancel(list(futures))
            raise SweepStartError(
                f"none of the {runs_phrase(len(futures))} started within cluster.startup_timeout="
                f"{cluster.startup_timeout:g} s: no worker began one (waited for a worker free to "
                "take a job; see any Dask error above)"
            )
        progress.tick()


def _submit(client: Any, cluster: ClusterConfig, token: str, j: Job) -> Any:
    try:
        key = f"vasc-run-{j.run_id}-{token}"
        return client.submit(run_job_task, j, key=key, pure=False, retries=cluster.retries)
    except Exception as exc:  # e.g. a job Dask cannot serialise: it would never start
        raise SweepStartError(
            f"the jobs could not be submitted to the Dask scheduler ({type(exc).__name__}: {exc})"
        ) from exc


def _wait_some(futures: set, timeout: float) -> tuple[set, set]:
    from distributed import wait

    try:
        done, not_done = wait(futures, timeout=timeout, return_when="FIRST_COMPLETED")
    except TimeoutError:
        return set(), futures
    return set(done), set(not_done)


def _collect(fut: Any, job: Job, progress: Progress, result: SweepResult) -> None:
    if fut.status == "finished" and fut.result().get("status") == "failed":  # raised: see run_job_task
        summary = fut.result()
        result.failed[job.run_id] = summary["error"]
        result.deterministic.add(job.run_id)
        progress.failed(job.run_id, f"{summary['error']} (deterministic: a rerun fails the same way)")
    elif fut.status == "finished":
        summary = fut.result()
        result.runs.append(summary)
        if summary["status"] == "skipped":
            result.skipped.append(job.run_id)
        else:
            result.complete.append(job.run_id)
            if summary["resumed_from"]:
                result.resumed.append(job.run_id)
        progress.finished(summary)
    else:
        exc = fut.exception()
        error = f"{type(exc).__name__}: {exc}"
        if type(exc).__name__ == "KilledWorker":
            error += " (its worker process died each time: a crash, or out of memory)"
        result.failed[job.run_id] = error
        progress.failed(job.run_id, error)
