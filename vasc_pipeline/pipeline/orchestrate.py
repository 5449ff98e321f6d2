"""Run a sweep: the sweep's path from config to stored runs, and the exit status.

:func:`main` is what ``python -m vasc_pipeline`` calls; :func:`run_sweep` is the plain
function behind it (tests call it with a config from :func:`vasc_pipeline.config.compose`
and, optionally, a Dask client of their own). The path of a sweep:

1. :func:`vasc_pipeline.pipeline.planning.plan`: expand the grid, build one problem per distinct N
   so that tissue and tree errors surface before anything runs. No writes.
2. :func:`vasc_pipeline.store.sweep_lock.output_dir_lock`: one sweep per output_dir at a time (an
   ``fcntl`` lock, released by the kernel even on SIGKILL). Existing stores are checked
   against the requested config (a changed config is refused, never mixed); stores of new
   runs are created here, before any job is dispatched (:mod:`vasc_pipeline.pipeline.planning`).
3. The numba kernels are compiled (or loaded from the on-disk cache) once in this process,
   so that workers load them instead of racing to compile (and each compiling the same code):
   :mod:`vasc_pipeline.pipeline.warmup`.
4. :func:`vasc_pipeline.pipeline.cluster.open_client`: a LocalCluster (process workers, one thread
   each, everything on 127.0.0.1), an existing scheduler (``cluster.address``), or SLURM via
   dask-jobqueue.
5. One task per unfinished run (:mod:`vasc_pipeline.pipeline.dispatch`, the task
   :func:`vasc_pipeline.pipeline.task.run_job_task` around :func:`vasc_pipeline.pipeline.job.run_job`);
   a job resumes from its store's last good checkpoint, so a task rescheduled after its worker died
   (up to ``cluster.retries`` times) continues rather than restarts. Workers publish progress
   events; the progress line (:mod:`vasc_pipeline.pipeline.progress`) shows runs done, steps/s, best
   cost per cell and an ETA.
6. The summary (:class:`~vasc_pipeline.pipeline.sweep_result.SweepResult`) and, when every run is
   complete, the reduction (:mod:`vasc_pipeline.pipeline.reduction`, which holds ``+stage=reduce`` too).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from .. import config as _config
from ..config.schema import ConfigError, RunConfig
from ..store.layout import LOCK_NAME
from ..store.run_store import StoreError
from ..store.sweep_lock import OutputDirLocked, check_output_dir, output_dir_lock
from .cluster import (
    SweepStartError,
    check_cluster,
    has_bokeh,
    open_client,
    probe_scheduler,
    slurm_cluster,
    slurm_job_script,
)
from .dispatch import run_on_cluster
from .outdir import OutputDirCallback
from .planning import Plan, check_one_configuration, create_stores, inspect_stores, plan
from .progress import PROGRESS_TOPIC, print_summary, runs_phrase
from .reduction import reduce_and_draw, reduce_stage
from .sweep_result import SweepResult
from .warmup import compile_kernels

__all__ = [  # with the planning, cluster, progress, outdir, warm-up and reduction names (re-exported: public API)
    "main",
    "run_sweep",
    "SweepResult",
    "reduce_stage",
    "plan",
    "Plan",
    "output_dir_lock",
    "OutputDirLocked",
    "open_client",
    "check_cluster",
    "check_output_dir",
    "OutputDirCallback",
    "SweepStartError",
    "inspect_stores",
    "check_one_configuration",
    "slurm_cluster",
    "has_bokeh",
    "compile_kernels",
    "LOCK_NAME",
    "PROGRESS_TOPIC",
]


def run_sweep(
    cfg: Any,
    client: Any = None,
    *,
    stream: TextIO | None = None,
    progress_interval: float | None = None,
    reduce: bool = True,
) -> SweepResult:
    """Run every unfinished job of the sweep (or single run) described by ``cfg``.

    Parameters
    ----------
    cfg : RunConfig, dict or DictConfig
        A composed config (``sweep`` optional: without it, one job of the base config).
    client : distributed.Client, optional
        Use this client instead of opening one from ``cfg.cluster`` (the caller owns it).
    stream : text stream, default sys.stderr
        Where progress and the end summary go.
    progress_interval : float, optional
        Seconds between progress lines (default 1 on a terminal, 30 otherwise).
    reduce : bool, default True
        When every run of the sweep is complete, reduce the output_dir afterwards
        (:func:`vasc_pipeline.reduce.reduce`: summary.zarr, comparison, figures, trees).

    Returns
    -------
    SweepResult
        ``output_dir``, ``runs`` (job summaries of this call, see
        :func:`vasc_pipeline.pipeline.job.run_job`), ``complete``, ``resumed``, ``skipped`` (run ids),
        ``failed`` ({run_id: error text}), ``deterministic`` (the failed run ids whose job
        raised: a rerun fails the same way), ``damaged`` ({run_id: what is wrong with its
        store}, left out), ``wall_seconds``, ``reduction`` (a
        :class:`vasc_pipeline.reduce.Reduction`, or None when not reduced) and
        ``reduction_error`` (text, or None).

    Raises ConfigError / TissueError / TreeError / OSError (incl. :class:`OutputDirLocked`)
    before any job starts, and :class:`SweepStartError` when no worker, or no job, started
    within ``cluster.startup_timeout``. With ``cluster.dry_run`` it only prints the plan.
    """
    stream = stream or sys.stderr
    started = time.monotonic()
    cfg = _config.to_run_config(cfg)
    check_cluster(cfg.cluster)
    p = plan(cfg)
    if cfg.cluster.dry_run:
        return _dry_run(cfg, p, stream)
    if client is None and cfg.cluster.address:
        probe_scheduler(cfg.cluster)  # before any store is written: a wrong address is refused, never waited on
    with output_dir_lock(p.output_dir):
        result = _prepare_stores(cfg, p, stream)
        if p.pending:
            compile_kernels(p.pending, stream)
            run_on_cluster(cfg, p, client, result, stream, progress_interval)
    result.wall_seconds = time.monotonic() - started
    print_summary(result, p, stream)
    if reduce and len(result.done) == len(p.jobs):
        result.reduction, result.reduction_error = _reduce_after_sweep(p.output_dir, stream)
    return result


def _prepare_stores(cfg: RunConfig, p: Plan, stream: TextIO) -> SweepResult:
    """Under the output_dir lock: check the existing stores against the config, create those of
    new runs (before any job is dispatched), say what will run; the result so far."""
    inspect_stores(p)
    create_stores(p)
    name = cfg.sweep.name if cfg.sweep else "single run"
    pending = p.pending
    stream.write(
        f"vasc_pipeline: {name}: {runs_phrase(len(p.jobs))} into {p.output_dir} ({len(p.complete)} already "
        f"complete, {len(p.started)} to resume, {len(pending) - len(p.started)} new"
        + (f", {len(p.damaged)} left out: damaged store" if p.damaged else "")
        + ")\n"
    )
    for run_id, why in p.damaged.items():
        stream.write(f"  left out: {run_id}: {why}\n")
    return SweepResult(output_dir=str(p.output_dir), skipped=sorted(p.complete), damaged=dict(p.damaged))


def _dry_run(cfg: RunConfig, p: Plan, stream: TextIO) -> SweepResult:
    """cluster.dry_run: print the planned runs (and SLURM's job script); no store, no job, no output_dir lock."""
    inspect_stores(p)  # read-only: what a sweep would skip, resume or refuse
    lines = [f"vasc_pipeline: dry run: {runs_phrase(len(p.pending))} of {len(p.jobs)} would run into {p.output_dir}:"]
    for j in p.jobs:
        what = (
            "complete: skipped"
            if j.run_id in p.complete
            else f"left out: {p.damaged[j.run_id]}"
            if j.run_id in p.damaged
            else f"resumes from step {p.started[j.run_id]}"
            if j.run_id in p.started
            else "new"
        )
        lines.append(f"  {j.run_id} ({p.total_steps[j.run_id]} proposed moves; {what})")
    if cfg.cluster.name == "slurm":
        lines += [
            "SLURM job script (one per cluster.slurm.cores workers; not submitted; temporary TLS files it "
            "names exist only while a sweep runs):",
            slurm_job_script(cfg.cluster, check_output_dir(p.output_dir)),
        ]
    stream.write("\n".join(lines) + "\n")
    stream.flush()
    return SweepResult(output_dir=str(p.output_dir), dry_run=True)


def _reduce_after_sweep(output_dir: Path, stream: TextIO) -> tuple[Any, str | None]:
    """Reduce a finished sweep; a failure is reported, never raised: the runs are already stored."""
    try:
        return reduce_and_draw(output_dir, stream=stream), None
    except Exception as exc:
        error = f"{type(exc).__name__}: {exc}"
        stream.write(
            f"vasc_pipeline: reduction FAILED ({error}). Every run is stored; retry with "
            f"python -m vasc_pipeline +stage=reduce output_dir={output_dir}\n"
        )
        stream.flush()
        return None, error


@contextlib.contextmanager
def _terminate_as_interrupt(terminated: list[int]):
    """SIGTERM (a batch system's, ``kill``) ends the sweep as Ctrl-C does: the cluster is closed
    and the interruption reported; the status stays 143 (128 + SIGTERM). Main thread only."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        terminated.append(signum)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def main(cfg: Any, stream: TextIO | None = None) -> int:
    """Entry point behind ``python -m vasc_pipeline``: run the sweep, return the exit status.

    Bad input (ConfigError, TissueError, TreeError, OSError such as an unwritable or locked
    output_dir, StoreError) is reported as one paragraph on stderr with status 2, before any
    job starts; status 1 when runs failed, a damaged store was left out, a stage after the runs
    (reduction, figures, exports) failed, or the cluster started no worker or job within
    ``cluster.startup_timeout``; Ctrl-C gives 130 (rerun to resume). A finished sweep is
    reduced; ``stage="reduce"`` (``+stage=reduce``) only reduces the runs already in
    ``output_dir`` (:func:`reduce_stage`), ``stage="extend"`` (``+stage=extend``) grows the whole
    tree below them (:func:`vasc_pipeline.pipeline.extend.extend_stage`).
    """
    from ..model.tissue import TissueError
    from ..model.tree import TreeError

    stream = stream or sys.stderr
    if getattr(cfg, "stage", "run") == "reduce":
        return reduce_stage(cfg, stream)
    terminated: list[int] = []
    if getattr(cfg, "stage", "run") == "extend":
        from .extend import extend_stage

        with _terminate_as_interrupt(terminated):
            status = extend_stage(cfg, stream)
        return 128 + signal.SIGTERM if terminated and status == 130 else status
    try:
        with _terminate_as_interrupt(terminated):
            result = run_sweep(cfg, stream=stream)
    except (ConfigError, TissueError, TreeError, StoreError, OSError) as exc:
        stream.write(f"vasc_pipeline: error: {exc}\nExisting results were left as they were.\n")
        return 2
    except KeyboardInterrupt:
        stream.write(
            f"\nvasc_pipeline: {'terminated (SIGTERM)' if terminated else 'interrupted'}. Finished runs are "
            "stored; the others resume from their last checkpoint when the same command is run again.\n"
        )
        return 128 + signal.SIGTERM if terminated else 130
    except SweepStartError as exc:
        stream.write(
            f"vasc_pipeline: error: {exc}. Stores already created resume when the same command is run again.\n"
        )
        return 1
    if result.dry_run:
        return 0
    reduction = result.reduction
    reduction_failed = result.reduction_error or (reduction is not None and (reduction.errors or reduction.damaged))
    return 1 if result.failed or result.damaged or reduction_failed else 0
