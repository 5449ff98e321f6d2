"""Run a sweep: the Dask fan-out of its jobs, the sweep loop and the exit status.

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
   so that workers load them instead of racing to compile (and each compiling the same code).
4. :func:`vasc_pipeline.pipeline.cluster.open_client`: a LocalCluster (process workers, one thread
   each, everything on 127.0.0.1), an existing scheduler (``cluster.address``), or SLURM via
   dask-jobqueue.
5. One task per unfinished run (:func:`vasc_pipeline.pipeline.job.run_job`); a job resumes from its
   store's last good checkpoint, so a task rescheduled after its worker died (up to
   ``cluster.retries`` times) continues rather than restarts. Workers publish progress
   events; the progress line (:mod:`vasc_pipeline.pipeline.progress`) shows runs done, steps/s, best
   cost per cell and an ETA.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import sys
import time
import uuid
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

from .. import config as _config
from ..config.schema import ConfigError, RunConfig
from ..store.layout import LOCK_NAME, RUNS_DIR
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
    wait_for_workers,
)
from .outdir import OutputDirCallback
from .planning import Plan, check_one_configuration, create_stores, inspect_stores, plan
from .progress import PROGRESS_TOPIC, Progress, print_summary, runs_phrase
from .sweep import Job
from .sweep_result import SweepResult

__all__ = [  # with the planning, cluster, progress and outdir names it uses (re-exported: public API)
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

# --------------------------------------------------------------------------------------------
# Compilation and the Dask task


COMPILE_NOTICE_AFTER = 2.0  # seconds: loading the cached kernels takes about 1 s, compiling them minutes


def compile_kernels(jobs: list[Job] | None = None, stream: TextIO | None = None) -> None:
    """Compile the kernels once here (or load numba's disk cache), before workers need them.

    With ``jobs``, one job's own config per distinct supply dtype runs for a few steps: the
    kernels its schedule calls (the calibration of T_start, adapted steps, packing, CCO when the
    method or init uses it) and their argument types are those of the sweep, so workers compile
    nothing (a generic tiny problem left ``anneal=fast``'s calibration and moves to the workers,
    which then showed 0 steps/s while compiling). Without ``jobs``: a generic tiny problem.
    When that takes longer than :data:`COMPILE_NOTICE_AFTER`, ``stream`` is told what happens.

    The compilation runs in a helper thread while this one waits: numba compiles inside
    llvmlite's ctypes callbacks, which swallow an exception raised there, so a Ctrl-C or SIGTERM
    delivered into them was lost and the sweep ran on. Waiting here, the signal interrupts at
    once (the helper is a daemon thread: it ends with the process).
    """
    import threading

    failure: list[BaseException] = []

    def compile_all() -> None:
        try:
            if jobs:
                _warm_up(jobs)
            else:
                _warm_up_generic()
        except BaseException as exc:  # re-raised in the caller's thread
            failure.append(exc)

    started = time.monotonic()
    worker = threading.Thread(target=compile_all, name="vasc-compile", daemon=True)
    worker.start()
    worker.join(COMPILE_NOTICE_AFTER)
    slow = worker.is_alive()
    if slow and stream is not None:
        stream.write(
            "vasc_pipeline: compiling the numba kernels (first run only, about 1-2 min; cached for later runs)...\n"
        )
        stream.flush()
    while worker.is_alive():
        worker.join(0.2)
    if failure:
        raise failure[0]
    if slow and stream is not None:
        stream.write(f"vasc_pipeline: kernels compiled in {time.monotonic() - started:.0f} s\n")
        stream.flush()


@contextlib.contextmanager
def _tissue_reports_muted():
    """Drop the tissue builders' INFO reports (the heart's achieved mass) for a while: the
    warm-up builds the sweep's tissues again, which the plan has reported already."""
    from ..model.tissue import heart

    def drop(record: logging.LogRecord) -> bool:
        return record.levelno > logging.INFO

    heart.log.addFilter(drop)
    try:
        yield
    finally:
        heart.log.removeFilter(drop)


def _warm_up(jobs: list[Job]) -> None:
    """A few steps of each distinct kind of job (see :func:`compile_kernels`)."""
    with _tissue_reports_muted():
        _warm_up_jobs(jobs)


def _warm_up_jobs(jobs: list[Job]) -> None:
    from .. import engine

    seen = set()
    for j in jobs:
        cfg = j.run_config()
        kind = (engine.supply_dtype(cfg.n_terminals), cfg.method.name, cfg.anneal.init)
        if kind in seen:
            continue
        seen.add(kind)
        try:
            if cfg.method.name == "cco":
                from ..engine.cco import grow

                grow(engine.build_problem(cfg), 0)
                continue
            steps = _config.packing_steps(cfg) + 256  # every phase of the schedule, a few moves each
            few_moves = replace(cfg, anneal=replace(cfg.anneal, steps=steps, trace_every=64))
            result = engine.run(few_moves, seed=int(cfg.seed))
            _warm_up_translation(result)
        except Exception:  # the job itself fails the same way, and its run reports it
            continue


def _warm_up_translation(result: Any) -> None:
    """The polish's single translations (``kernel.translate_node``): a run of a few moves is
    usually polished in one piece and never calls them, a real run often does."""
    from .. import engine, kernel
    from ..model.rng import seed_state

    problem = result.problem
    state = engine.state_from_tree(problem, result.tree, seed_state(0))
    node = problem.model.n_inlets  # any node that may move; moved onto itself
    kernel.translate_node(problem.model, state, node, state.position[node].copy(), 1e-300)


def _warm_up_generic() -> None:
    from .. import engine

    cfg = _config.RunConfig(
        n_terminals=4,
        tissue=_config.TissueConfig(name="sphere", exclusion_voxel_size=None),
        anneal=_config.AnnealConfig(steps=16, trace_every=8),
    )
    engine.run(cfg, seed=0)
    from ..engine.cco import grow  # the CCO growth kernel too (method=cco, anneal.init=cco)

    grow(engine.build_problem(replace(cfg, method=_config.MethodConfig(name="cco"))), 0)


def _dask_run_job(job: Job) -> dict:
    """The task: run a job on a worker, publishing progress events at most once a second."""
    from distributed import get_worker

    from .job import run_job

    worker = get_worker()
    last = [0.0]
    worker.log_event(PROGRESS_TOPIC, {"run_id": job.run_id, "started": True})  # for the start-up watchdog

    def report(msg: dict) -> None:
        now = time.monotonic()
        if now - last[0] >= 1.0:
            last[0] = now
            worker.log_event(PROGRESS_TOPIC, msg)

    try:
        cfg = job.run_config()
        if cfg.anneal.parts == 1:
            return run_job(job, report)
        return run_job(job, report, _cluster_map(cfg.cluster.retries))
    except (OSError, MemoryError):
        raise  # the machine's (filesystem, memory, a store lock): Dask retries, the job resumes
    except Exception as exc:
        # A run is a pure function of (config, seed): any other exception recurs on every retry,
        # so it is returned, not raised (Dask would retry it cluster.retries times).
        return {
            "run_id": job.run_id,
            "status": "failed",
            "deterministic": True,
            "error": f"{type(exc).__name__}: {exc}",
        }


class PartLost(OSError):
    """A part of a tree in parts did not come back from the cluster (its worker died): the run
    is retried like a lost job, and resumes from its last checkpoint."""


def _cluster_map(retries: int):
    """A map for the parts of a tree in parts (``anneal.parts`` > 1): on the cluster's workers,
    results in part order. This task secedes while the parts run, so its slot takes one too."""
    from distributed import get_client, rejoin, secede

    client = get_client()

    def cluster_map(f, jobs):
        futures = client.map(f, list(jobs), pure=False, retries=retries)
        secede()
        try:
            return client.gather(futures)
        except Exception as exc:
            raise PartLost(f"a part of the tree was lost ({type(exc).__name__}: {exc})") from exc
        finally:
            rejoin()

    return cluster_map


# --------------------------------------------------------------------------------------------
# The sweep


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
    from distributed import wait

    stream = stream or sys.stderr
    started = time.monotonic()
    cfg = _config.to_run_config(cfg)
    check_cluster(cfg.cluster)
    p = plan(cfg)
    name = cfg.sweep.name if cfg.sweep else "single run"
    if cfg.cluster.dry_run:
        return _dry_run(cfg, p, stream)
    if client is None and cfg.cluster.address:
        probe_scheduler(cfg.cluster)  # before any store is written: a wrong address is refused, never waited on
    with output_dir_lock(p.output_dir):
        inspect_stores(p)
        create_stores(p)
        pending = p.pending
        stream.write(
            f"vasc_pipeline: {name}: {runs_phrase(len(p.jobs))} into {p.output_dir} ({len(p.complete)} already "
            f"complete, {len(p.started)} to resume, {len(pending) - len(p.started)} new"
            + (f", {len(p.damaged)} left out: damaged store" if p.damaged else "")
            + ")\n"
        )
        for run_id, why in p.damaged.items():
            stream.write(f"  left out: {run_id}: {why}\n")
        result = SweepResult(output_dir=str(p.output_dir), skipped=sorted(p.complete), damaged=dict(p.damaged))
        if pending:
            compile_kernels(pending, stream)
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
                if dashboard:
                    stream.write(f"vasc_pipeline: Dask dashboard at {dashboard}\n")
                elif cfg.cluster.dashboard_address and not cfg.cluster.address:
                    stream.write(
                        "vasc_pipeline: no Dask dashboard: it needs bokeh (pip install 'bokeh>=3.1'); "
                        "progress is printed here\n"
                    )
                client.subscribe_topic(PROGRESS_TOPIC, progress.event)
                try:
                    # Keys name the run (dashboard, logs) and this sweep, so that a client reused
                    # for a second sweep never hands back a finished task of the first.
                    token = uuid.uuid4().hex[:8]
                    queue = list(pending)
                    # A tree in parts takes the whole cluster for its parts: such runs go one at a time.
                    window = 1 if any(j.run_config().anneal.parts > 1 for j in pending) else len(queue)

                    def submit(j: Job) -> Any:
                        try:
                            key = f"vasc-run-{j.run_id}-{token}"
                            return client.submit(_dask_run_job, j, key=key, pure=False, retries=cfg.cluster.retries)
                        except Exception as exc:  # e.g. a job Dask cannot serialise: it would never start
                            raise SweepStartError(
                                f"the jobs could not be submitted to the Dask scheduler ({type(exc).__name__}: {exc})"
                            ) from exc

                    futures = {submit(j): j for j in queue[:window]}
                    queue = queue[window:]
                    remaining = set(futures)
                    deadline = time.monotonic() + cfg.cluster.startup_timeout
                    running = False
                    while remaining:
                        done, remaining = _wait_some(wait, remaining, 1.0)
                        for fut in done:
                            _collect(fut, futures[fut], progress, result)
                            if queue:
                                j = queue.pop(0)
                                nxt = submit(j)
                                futures[nxt] = j
                                remaining.add(nxt)
                        running = running or bool(done) or progress.any_started
                        if not running and time.monotonic() > deadline:
                            client.cancel(list(futures))
                            raise SweepStartError(
                                f"none of the {runs_phrase(len(futures))} started within cluster.startup_timeout="
                                f"{cfg.cluster.startup_timeout:g} s: no worker began one (waited for a worker free to "
                                "take a job; see any Dask error above)"
                            )
                        progress.tick()
                finally:
                    client.unsubscribe_topic(PROGRESS_TOPIC)
                    progress.close()
    result.wall_seconds = time.monotonic() - started
    print_summary(result, p, stream)
    if reduce and len(result.done) == len(p.jobs):
        result.reduction, result.reduction_error = _reduce_after_sweep(p.output_dir, stream)
    return result


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
    from .reduction import reduce_and_draw

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


def reduce_stage(cfg: Any, stream: TextIO | None = None) -> int:
    """``+stage=reduce``: reduce the complete runs already in ``cfg.output_dir``; returns the exit status."""
    from ..reduce import ReductionError
    from .reduction import reduce_and_draw

    stream = stream or sys.stderr
    try:  # the same checks as a run: a typo'd value is reported, not silently ignored
        _config.validate(_config.to_run_config(cfg))
    except ConfigError as exc:
        stream.write(f"vasc_pipeline: error: {exc}\nNothing was reduced; existing results were left as they were.\n")
        return 2
    output_dir = Path(cfg.output_dir)
    if not (output_dir / RUNS_DIR).is_dir():
        stream.write(
            f"vasc_pipeline: error: output_dir {str(output_dir)!r} holds no runs/ directory: nothing to "
            "reduce. Give the output_dir of a sweep (output_dir=...).\n"
        )
        return 2
    ignored = _overrides_unlike_the_runs(cfg, output_dir)
    if ignored:
        stream.write(
            f"vasc_pipeline: error: +stage=reduce reduces the runs of {str(output_dir)!r} as they were made, and "
            f"they were made with other values: {'; '.join(ignored)}. Drop those overrides (or run a sweep with "
            "them into a new output_dir=...). Nothing was reduced.\n"
        )
        return 2
    try:
        reduction = reduce_and_draw(output_dir, stream=stream, extended_zerod=cfg.extend.zerod)
    except (ReductionError, OSError) as exc:
        stream.write(f"vasc_pipeline: error: {exc}\n")
        return 2
    return 1 if reduction.errors or reduction.damaged else 0


def _overrides_unlike_the_runs(cfg: Any, output_dir: Path) -> list[str]:
    """The command-line ``key=value`` overrides (Hydra's, when it runs) of keys the stored runs
    hold with another value: ``+stage=reduce physics.gamma=3`` on runs made with 2.1 would
    otherwise be ignored without a word. Sweep axes, output_dir, stage, sweep, cluster and
    checkpoint keys, and group choices, are not compared."""
    from omegaconf import OmegaConf

    from ..store import SWEEP_AXES, RunStore

    try:
        from hydra.core.hydra_config import HydraConfig

        overrides = list(HydraConfig.get().overrides.task)
    except (ImportError, ValueError):  # not under Hydra (a test, a script): nothing typed
        return []
    stored = None
    for path in sorted((output_dir / RUNS_DIR).glob("*.zarr")):
        try:
            stored = RunStore.open(path, mode="r").attrs.get("config") or {}
            break
        except StoreError:
            continue
    out = []
    for o in overrides:
        key = o.lstrip("+~").partition("=")[0]
        if "." not in key or key in SWEEP_AXES or key.split(".")[0] in ("sweep", "cluster", "checkpoint", "hydra"):
            continue
        node: Any = stored
        for part in key.split("."):
            node = node.get(part, KeyError) if isinstance(node, dict) else KeyError
        requested = OmegaConf.select(cfg, key, default=KeyError) if OmegaConf.is_config(cfg) else KeyError
        if node is not KeyError and requested is not KeyError and node != requested:
            out.append(f"{key}={requested} (the runs: {node})")
    return out


def _wait_some(wait, futures: set, timeout: float) -> tuple[set, set]:
    try:
        done, not_done = wait(futures, timeout=timeout, return_when="FIRST_COMPLETED")
    except TimeoutError:
        return set(), futures
    return set(done), set(not_done)


def _collect(fut: Any, job: Job, progress: Progress, result: SweepResult) -> None:
    if fut.status == "finished" and fut.result().get("status") == "failed":  # raised: see _dask_run_job
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
