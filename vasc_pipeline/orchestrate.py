"""Fan a sweep's jobs out on Dask, follow them, and report.

:func:`main` is what ``python -m vasc_pipeline`` calls; :func:`run_sweep` is the plain
function behind it (tests call it with a config from :func:`vasc_pipeline.config.compose`
and, optionally, a Dask client of their own). The path of a sweep:

1. :func:`plan`: expand the grid (:func:`vasc_pipeline.sweep.expand`), build one problem
   per distinct N so that tissue and tree errors surface before anything runs. No writes.
2. :func:`output_dir_lock`: one sweep per output_dir at a time (an ``fcntl`` lock, released
   by the kernel even on SIGKILL). Existing stores are checked against the requested config
   (a changed config is refused, never mixed); stores of new runs are created here, before
   any job is dispatched.
3. The numba kernels are compiled (or loaded from the on-disk cache) once in this process,
   so that workers load them instead of racing to compile (SPEC section 8).
4. :func:`open_client`: a LocalCluster (process workers, one thread each, everything on
   127.0.0.1), an existing scheduler (``cluster.address``), or SLURM via dask-jobqueue.
5. One task per unfinished run (:func:`vasc_pipeline.job.run_job`); a job resumes from its
   store's last good checkpoint, so a task rescheduled after its worker died (up to
   ``cluster.retries`` times) continues rather than restarts. Workers publish progress
   events; the progress line shows runs done, steps/s, best cost per cell and an ETA.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import logging
import math
import os
import shutil
import socket
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, TextIO

from . import config as _config
from .config import ClusterConfig, ConfigError, RunConfig
from .store import (
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

__all__ = [
    "main",
    "run_sweep",
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

LOCK_NAME = ".vasc_pipeline.lock"
PROGRESS_TOPIC = "vasc_pipeline.progress"
log = logging.getLogger(__name__)


class OutputDirLocked(OSError):
    """Another sweep holds the output_dir."""


class SweepStartError(RuntimeError):
    """The cluster never started a worker, or the scheduler never started a job, within cluster.startup_timeout."""


# --------------------------------------------------------------------------------------------
# Planning (no writes)


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
    from . import engine

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
    for j in p.pending:
        if is_empty_leftover(j.store):  # a crash between mkdir and the store's zarr.json
            Path(j.store).rmdir()
        if not RunStore.exists(j.store):
            RunStore.create(
                j.store,
                run_id=j.run_id,
                seed=j.coords["seed"],
                config=j.config,
                coords=j.coords,
                total_steps=p.total_steps[j.run_id],
            )


# --------------------------------------------------------------------------------------------
# The output_dir lock


@contextlib.contextmanager
def output_dir_lock(output_dir: str | os.PathLike) -> Iterator[Path]:
    """Hold ``<output_dir>/.vasc_pipeline.lock`` for the duration of a sweep.

    Raises :class:`OutputDirLocked` (an OSError) if another sweep holds it, and OSError
    naming ``output_dir`` if the directory cannot be created or written.
    """
    import fcntl

    out = check_output_dir(output_dir)
    try:
        (out / RUNS_DIR).mkdir(exist_ok=True)
        fh = open(out / LOCK_NAME, "a+")
    except OSError as exc:
        raise OSError(
            f"output_dir: cannot create or write {str(out)!r} ({exc.strerror or exc}); choose a "
            "writable directory with output_dir=..."
        ) from exc
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            try:
                holder = json.loads(fh.read() or "{}")
            except ValueError:
                holder = {}
            raise OutputDirLocked(
                f"output_dir {str(out)!r} is in use by another sweep (pid {holder.get('pid', '?')} on "
                f"{holder.get('host', '?')}, started {holder.get('started', '?')}). Two sweeps never write "
                "into one output_dir at once: wait for that one to finish (or stop it; rerunning the same "
                "command resumes it), or choose another output_dir=..."
            ) from None
        fh.seek(0)
        fh.truncate()
        fh.write(
            json.dumps(
                {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "started": time.strftime("%Y-%m-%d %H:%M:%S"),
                    "argv": sys.argv,
                }
            )
        )
        fh.flush()
        yield out
    finally:
        fh.close()  # closing the descriptor releases the lock


def check_output_dir(output_dir: str | os.PathLike) -> Path:
    """Create ``output_dir`` if needed and prove it writable; OSError naming the field otherwise."""
    out = Path(output_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OSError(
            f"output_dir: cannot create or write {str(out)!r} ({exc.strerror or exc}); choose a "
            "writable directory with output_dir=..."
        ) from exc
    return out


class OutputDirCallback:
    """Hydra callback (conf/config.yaml ``hydra.callbacks``): check output_dir before Hydra writes its logs there.

    Hydra creates its run directory (under output_dir) before the task function runs, so an
    unwritable output_dir would otherwise surface as a bare traceback from Hydra.
    """

    def on_run_start(self, config: Any, **kwargs: Any) -> None:
        # An empty output_dir would put results in the working directory and Hydra's logs at the
        # filesystem root; a reduction must not create the directory it was asked to read.
        try:
            if not str(config.output_dir or "").strip():
                raise OSError("output_dir is empty: give the directory for the results with output_dir=...")
            if config.get("stage") == "reduce":
                if not (Path(config.output_dir) / RUNS_DIR).is_dir():
                    raise OSError(
                        f"output_dir {str(config.output_dir)!r} holds no runs/ directory: nothing to "
                        "reduce. Give the output_dir of a sweep (output_dir=...)"
                    )
            else:
                check_output_dir(config.output_dir)
        except OSError as exc:
            sys.stderr.write(f"vasc_pipeline: error: {exc}\nExisting results were left as they were.\n")
            sys.exit(2)

    # The rest of Hydra's callback interface: nothing to do.
    def on_run_end(self, config: Any, **kwargs: Any) -> None: ...
    def on_multirun_start(self, config: Any, **kwargs: Any) -> None: ...
    def on_multirun_end(self, config: Any, **kwargs: Any) -> None: ...
    def on_job_start(self, config: Any, **kwargs: Any) -> None: ...
    def on_job_end(self, config: Any, job_return: Any, **kwargs: Any) -> None: ...
    def on_compose_config(self, config: Any, config_name: Any, overrides: Any) -> None: ...


# --------------------------------------------------------------------------------------------
# Compilation and the Dask client


def compile_kernels() -> None:
    """Run a tiny problem for a few steps: compiles every kernel once, or loads the disk cache."""
    from . import engine

    cfg = _config.RunConfig(n_terminals=4)
    cfg.tissue.name = "sphere"
    cfg.anneal.steps = 16
    cfg.anneal.trace_every = 8
    engine.run(cfg, seed=0)
    from .cco import grow  # the CCO growth kernel too (method=cco, anneal.init=cco)

    cfg.method.name = "cco"
    grow(engine.build_problem(cfg), 0)


def _security(cluster: ClusterConfig, server: bool):
    """Dask TLS settings from ``cluster.tls`` (None when unset); ``server`` also for scheduler/workers."""
    tls = cluster.tls
    if not (tls.ca_file or tls.cert or tls.key or tls.require_encryption):
        return None
    if not (tls.ca_file and tls.cert):
        raise ConfigError(
            "cluster.tls needs both cluster.tls.ca_file and cluster.tls.cert (PEM files; "
            f"cluster.tls.key if the key is separate), got ca_file={tls.ca_file!r} cert={tls.cert!r}"
        )
    for name in ("ca_file", "cert", "key"):
        path = getattr(tls, name)
        if path and not Path(path).is_file():
            raise ConfigError(f"cluster.tls.{name}: file {path!r} does not exist")
    from distributed.security import Security

    kwargs = {"tls_ca_file": tls.ca_file, "tls_client_cert": tls.cert, "tls_client_key": tls.key}
    if server:
        kwargs.update(
            tls_scheduler_cert=tls.cert, tls_scheduler_key=tls.key, tls_worker_cert=tls.cert, tls_worker_key=tls.key
        )
    return Security(require_encryption=bool(tls.require_encryption), **kwargs)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def check_cluster(cluster: ClusterConfig) -> None:
    """Raise ConfigError naming the ``cluster.*`` field that is out of range."""
    if cluster.address == "???":  # cluster=address without cluster.address (a missing value)
        cluster.address = None
    if cluster.name not in ("local", "address", "slurm"):
        raise ConfigError(f"cluster.name must be one of local, address, slurm; got {cluster.name!r}")
    if cluster.n_workers is not None and cluster.n_workers < 1:
        raise ConfigError(f"cluster.n_workers must be an integer >= 1 (or null: one per core), got {cluster.n_workers}")
    if cluster.retries < 0:
        raise ConfigError(f"cluster.retries must be an integer >= 0, got {cluster.retries}")
    if cluster.name == "address" and not cluster.address:
        raise ConfigError(
            "cluster.address is required for cluster=address: the scheduler's tcp://host:8786 (or tls://host:8786)"
        )
    if cluster.address and "://" not in cluster.address:
        raise ConfigError(f"cluster.address must look like tcp://host:8786 or tls://host:8786, got {cluster.address!r}")
    if cluster.name == "slurm" and cluster.slurm.cores < 1:
        raise ConfigError(f"cluster.slurm.cores must be an integer >= 1, got {cluster.slurm.cores}")
    if not (cluster.startup_timeout > 0 and math.isfinite(cluster.startup_timeout)):
        raise ConfigError(
            f"cluster.startup_timeout must be a finite number of seconds > 0, got {cluster.startup_timeout}"
        )
    tls = _security(cluster, server=cluster.name == "slurm")
    if cluster.name == "slurm":  # what SLURM needs, before any store is created
        if importlib.util.find_spec("dask_jobqueue") is None:
            raise ConfigError("cluster=slurm needs dask-jobqueue: pip install 'vasc_pipeline[slurm]'")
        if tls is None and not cluster.allow_insecure and importlib.util.find_spec("cryptography") is None:
            raise ConfigError(
                "cluster=slurm encrypts the scheduler's connections with temporary TLS certificates, "
                "which need the cryptography package: pip install 'vasc_pipeline[slurm]' (or give "
                "cluster.tls.* PEM files, or cluster.allow_insecure=true on a trusted network)"
            )
        if not cluster.dry_run and shutil.which("sbatch") is None:
            raise ConfigError(
                "cluster=slurm submits jobs with sbatch, which is not on PATH here: run the sweep on "
                "a SLURM login node (cluster.dry_run=true prints the job script without submitting)"
            )


def has_bokeh() -> bool:
    """Dask's dashboard is drawn by bokeh (not a dependency): without it the link would be a 404."""
    return importlib.util.find_spec("bokeh") is not None


@contextlib.contextmanager
def open_client(cluster: ClusterConfig, n_jobs: int, output_dir: str | os.PathLike | None = None) -> Iterator[Any]:
    """A Dask client for ``cluster`` (closed, with any cluster it started, on exit).

    ``output_dir`` (shared with the workers): where SLURM workers read temporary TLS certificates.
    """
    check_cluster(cluster)
    with _quiet_dask(), _client(cluster, n_jobs, output_dir) as client:
        yield client


@contextlib.contextmanager
def _quiet_dask() -> Iterator[None]:
    """Under Hydra the root logger prints INFO: keep Dask's routine chatter (workers starting,
    closing) out of the progress output; its warnings and errors still show."""
    dask_log = logging.getLogger("distributed")
    level = dask_log.level
    if dask_log.getEffectiveLevel() < logging.WARNING:
        dask_log.setLevel(logging.WARNING)
    try:
        yield
    finally:
        dask_log.setLevel(level)


# Dask's background duties sized for workers that each run one long, GIL-free task: no
# statistical profiler (a stack sample every 10 ms), slower event-loop ticks, system and
# memory monitors. Measured on 2 busy cores: the defaults cost a job ~20 % extra CPU.
_WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "500ms",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
}
# The same for SLURM workers, which read their config on the compute node.
_WORKER_ENV = [
    f"export DASK_{key.upper().replace('.', '__').replace('-', '_')}={value}" for key, value in _WORKER_CONFIG.items()
]


def _dashboard_options(cluster: ClusterConfig) -> dict:
    """Scheduler options: the dashboard at cluster.dashboard_address, or off (its HTTP server on loopback)."""
    if cluster.dashboard_address and has_bokeh():
        return {"dashboard": True, "dashboard_address": cluster.dashboard_address}
    return {"dashboard": False, "dashboard_address": "127.0.0.1:0"}


def slurm_cluster(cluster: ClusterConfig, n_jobs: int, output_dir: str | os.PathLike | None = None) -> Any:
    """The dask-jobqueue SLURMCluster of ``cluster`` (its scheduler started, no job submitted yet).

    Without cluster.tls files the scheduler and workers talk TLS with temporary certificates
    (``Security.temporary()``; the workers read them from ``output_dir``, a shared filesystem),
    unless ``cluster.allow_insecure``.
    """
    from dask_jobqueue import SLURMCluster
    from distributed.security import Security

    s = cluster.slurm
    security = _security(cluster, server=True)
    if security is None and not cluster.allow_insecure:
        security = Security.temporary()  # the scheduler listens beyond loopback: never in clear by default
    cl = SLURMCluster(
        queue=s.queue,
        account=s.account,
        walltime=s.walltime,
        cores=s.cores,
        processes=s.cores,
        memory=s.memory,
        interface=s.interface,
        local_directory=s.local_directory,
        log_directory=s.log_directory,
        job_extra_directives=list(s.job_extra_directives),
        job_script_prologue=[*s.job_script_prologue, *_WORKER_ENV],
        security=security,
        protocol="tls://" if security else None,
        scheduler_options=_dashboard_options(cluster),
        shared_temp_directory=str(Path(output_dir).resolve()) if output_dir is not None else None,
    )
    return cl


@contextlib.contextmanager
def _client(cluster: ClusterConfig, n_jobs: int, output_dir: str | os.PathLike | None = None) -> Iterator[Any]:
    import dask
    from distributed import Client, LocalCluster

    # A task whose worker dies is rescheduled up to allowed-failures times (scheduler side;
    # an existing scheduler keeps its own setting). Workers started here inherit the config.
    # Work stealing rebalances short tasks every 100 ms; ours run for minutes to days.
    with dask.config.set(
        {
            "distributed.scheduler.allowed-failures": int(cluster.retries),
            "distributed.scheduler.work-stealing": False,
            **_WORKER_CONFIG,
        }
    ):
        if cluster.address:
            client = Client(cluster.address, security=_security(cluster, server=False), timeout="30s")
            try:
                yield client
            finally:
                client.close()
            return
        if cluster.name == "slurm":
            cl = slurm_cluster(cluster, n_jobs, output_dir)
            cl.scale(n=cluster.n_workers or n_jobs)
        else:
            n = cluster.n_workers or max(1, min(_cores(), n_jobs))
            cl = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=cluster.dashboard_address if has_bokeh() else None,
                silence_logs=logging.ERROR,
            )
        try:
            client = Client(cl)
            try:
                yield client
            finally:
                client.close()
        finally:
            cl.close()


# --------------------------------------------------------------------------------------------
# Progress


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
        return run_job(job, report)
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


def _runs(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


class Progress:
    """Runs done / total, steps per second, best cost per cell, ETA: one line, updated in place on a TTY."""

    def __init__(self, p: Plan, stream: TextIO, interval: float | None, dashboard: str | None) -> None:
        jobs = [j for j in p.jobs if j.run_id not in p.damaged]  # damaged stores are left out
        self.total_runs = len(jobs)
        self.totals = {j.run_id: p.total_steps[j.run_id] for j in jobs}
        self.cells = {j.run_id: j.cell for j in jobs}
        self.steps = {
            j.run_id: (self.totals[j.run_id] if j.run_id in p.complete else p.started.get(j.run_id, 0)) for j in jobs
        }
        self.steps_at_start = sum(self.steps.values())
        self.best: dict[str, float] = {}
        self.done = len(p.complete)
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self.interval = interval if interval is not None else (1.0 if self.tty else 30.0)
        self.dashboard = dashboard
        self.started = time.monotonic()
        self.last_print = 0.0
        self.lock = threading.Lock()
        self.any_started = False  # a job of this sweep began on a worker
        for j in jobs:
            if j.run_id in p.complete:
                cost = RunStore.open(j.store, mode="r").attrs.get("cost", {}).get("total")
                self._cost(j.run_id, cost)

    def _cost(self, run_id: str, cost: float | None) -> None:
        if cost is not None and math.isfinite(cost):
            cell = self.cells[run_id]
            self.best[cell] = min(cost, self.best.get(cell, math.inf))

    def event(self, event: Any) -> None:
        """Handler of worker progress events (runs on the client's event-loop thread)."""
        msg = event[1] if isinstance(event, tuple) else event
        with self.lock:
            if msg.get("started"):
                self.any_started = True
            elif msg.get("run_id") in self.steps:
                self.steps[msg["run_id"]] = int(msg["step"])
                self._cost(msg["run_id"], msg.get("cost"))

    def finished(self, summary: dict) -> None:
        with self.lock:
            self.done += 1
            self.steps[summary["run_id"]] = self.totals[summary["run_id"]]
            self._cost(summary["run_id"], summary.get("cost"))
        how = f"resumed from step {summary['resumed_from']}" if summary["resumed_from"] else "from step 0"
        if summary["status"] == "skipped":
            how = "already complete"
        cost = "?" if summary.get("cost") is None else f"{summary['cost']:.6g}"
        self._write(f"[{self.done}/{self.total_runs}] {summary['run_id']} complete ({how}), cost {cost}", newline=True)
        for text in summary.get("warnings", ()):  # checkpoint fallbacks happen on the worker: say so here
            self._write(f"    warning: {text}", newline=True)

    def failed(self, run_id: str, error: str) -> None:
        with self.lock:
            self.done += 1
        self._write(f"[{self.done}/{self.total_runs}] {run_id} FAILED: {error}", newline=True)

    def line(self) -> str:
        with self.lock:
            elapsed = max(time.monotonic() - self.started, 1e-9)
            done_steps = sum(self.steps.values())
            rate = (done_steps - self.steps_at_start) / elapsed
            remaining = sum(self.totals.values()) - done_steps
            best = ", ".join(f"{c} {v:.4g}" for c, v in sorted(self.best.items()))
            done = self.done
        eta = remaining / rate if rate > 0 else math.inf
        return (
            f"runs {done}/{self.total_runs} | {rate:.3g} steps/s | ETA {_duration(eta)} | "
            f"best cost per cell: {best or '-'}"
        )

    def tick(self, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self.last_print >= self.interval:
            self.last_print = now
            self._write(self.line(), newline=not self.tty)

    def close(self) -> None:
        """The last progress line, ended: whatever is written next starts on a line of its own."""
        self.tick(force=True)
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def _write(self, text: str, newline: bool) -> None:
        if self.tty:
            width = max(40, _terminal_width() - 1)
            # Clear the live line, then either leave a permanent line or redraw the live one.
            self.stream.write("\r\x1b[2K" + (text + "\n" if newline else text[:width]))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def _terminal_width() -> int:
    try:
        return os.get_terminal_size().columns
    except OSError:
        return 120


# --------------------------------------------------------------------------------------------
# The sweep


def run_sweep(
    cfg: Any,
    client: Any = None,
    *,
    stream: TextIO | None = None,
    progress_interval: float | None = None,
    reduce: bool = True,
) -> dict[str, Any]:
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
    dict
        ``output_dir``, ``runs`` (job summaries of this call, see
        :func:`vasc_pipeline.job.run_job`), ``complete``, ``resumed``, ``skipped`` (run ids),
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
    with output_dir_lock(p.output_dir):
        inspect_stores(p)
        create_stores(p)
        pending = p.pending
        stream.write(
            f"vasc_pipeline: {name}: {_runs(len(p.jobs))} into {p.output_dir} ({len(p.complete)} already "
            f"complete, {len(p.started)} to resume, {len(pending) - len(p.started)} new"
            + (f", {len(p.damaged)} left out: damaged store" if p.damaged else "")
            + ")\n"
        )
        for run_id, why in p.damaged.items():
            stream.write(f"  left out: {run_id}: {why}\n")
        result: dict[str, Any] = {
            "output_dir": str(p.output_dir),
            "runs": [],
            "complete": [],
            "resumed": [],
            "skipped": sorted(p.complete),
            "failed": {},
            "deterministic": set(),
            "damaged": dict(p.damaged),
        }
        if pending:
            compile_kernels()
            with contextlib.ExitStack() as stack:
                if client is None:
                    client = stack.enter_context(open_client(cfg.cluster, len(pending), p.output_dir))
                _wait_for_workers(client, cfg.cluster, len(pending))
                # An existing scheduler draws its own dashboard; ours only with bokeh here.
                dashboard = (
                    getattr(client, "dashboard_link", None)
                    if cfg.cluster.address or (cfg.cluster.dashboard_address and has_bokeh())
                    else None
                )
                progress = Progress(p, stream, progress_interval, dashboard)
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
                    try:
                        futures = {
                            client.submit(
                                _dask_run_job,
                                j,
                                key=f"vasc-run-{j.run_id}-{token}",
                                pure=False,
                                retries=cfg.cluster.retries,
                            ): j
                            for j in pending
                        }
                    except Exception as exc:  # e.g. a job Dask cannot serialise: it would never start
                        raise SweepStartError(
                            f"the jobs could not be submitted to the Dask scheduler ({type(exc).__name__}: {exc})"
                        ) from exc
                    remaining = set(futures)
                    deadline = time.monotonic() + cfg.cluster.startup_timeout
                    running = False
                    while remaining:
                        done, remaining = _wait_some(wait, remaining, 1.0)
                        for fut in done:
                            _collect(fut, futures[fut], progress, result)
                        running = running or bool(done) or progress.any_started
                        if not running and time.monotonic() > deadline:
                            client.cancel(list(futures))
                            raise SweepStartError(
                                f"none of the {_runs(len(futures))} started within cluster.startup_timeout="
                                f"{cfg.cluster.startup_timeout:g} s: no worker began one (waited for a worker free to "
                                "take a job; see any Dask error above)"
                            )
                        progress.tick()
                finally:
                    client.unsubscribe_topic(PROGRESS_TOPIC)
                    progress.close()
    result["wall_seconds"] = time.monotonic() - started
    _print_summary(result, p, stream)
    result["reduction"], result["reduction_error"] = None, None
    if reduce and len(set(result["complete"]) | set(result["skipped"])) == len(p.jobs):
        result["reduction"], result["reduction_error"] = _reduce_after_sweep(p.output_dir, stream)
    return result


def _wait_for_workers(client: Any, cluster: ClusterConfig, n_jobs: int) -> None:
    """Wait up to cluster.startup_timeout for a first worker; :class:`SweepStartError` saying what for."""
    try:
        client.wait_for_workers(1, timeout=cluster.startup_timeout)
        return
    except (TimeoutError, OSError):
        pass
    if cluster.name == "slurm":
        what = (
            f"the workers of {cluster.n_workers or n_jobs} requested SLURM worker(s) (squeue -u $USER shows "
            "whether the jobs are queued; their logs go to cluster.slurm.log_directory)"
        )
    elif cluster.address:
        what = (
            f"a worker of the scheduler at {cluster.address} (start one with: dask worker {cluster.address} "
            "--nthreads 1)"
        )
    else:
        what = "the local cluster's worker processes"
    raise SweepStartError(
        f"no Dask worker started within cluster.startup_timeout={cluster.startup_timeout:g} s; "
        f"waited for {what}. Raise cluster.startup_timeout if they are merely slow to start"
    )


def _dry_run(cfg: RunConfig, p: Plan, stream: TextIO) -> dict[str, Any]:
    """cluster.dry_run: print the planned runs (and SLURM's job script); no store, no job, no output_dir lock."""
    inspect_stores(p)  # read-only: what a sweep would skip, resume or refuse
    lines = [f"vasc_pipeline: dry run: {_runs(len(p.pending))} of {len(p.jobs)} would run into {p.output_dir}:"]
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
        with _quiet_dask():
            cl = slurm_cluster(cfg.cluster, len(p.jobs), check_output_dir(p.output_dir))
            try:
                lines += [
                    "SLURM job script (one per cluster.slurm.cores workers; not submitted; temporary TLS files it "
                    "names exist only while a sweep runs):",
                    cl.job_script(),
                ]
            finally:
                cl.close()
    stream.write("\n".join(lines) + "\n")
    stream.flush()
    return {
        "output_dir": str(p.output_dir),
        "runs": [],
        "complete": [],
        "resumed": [],
        "skipped": [],
        "failed": {},
        "deterministic": set(),
        "damaged": {},
        "wall_seconds": 0.0,
        "reduction": None,
        "reduction_error": None,
        "dry_run": True,
    }


def _reduce_after_sweep(output_dir: Path, stream: TextIO) -> tuple[Any, str | None]:
    """Reduce a finished sweep; a failure is reported, never raised: the runs are already stored."""
    from .reduce import reduce

    try:
        return reduce(output_dir, stream=stream), None
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
    from .reduce import ReductionError, reduce

    stream = stream or sys.stderr
    output_dir = Path(cfg.output_dir)
    if not (output_dir / RUNS_DIR).is_dir():
        stream.write(
            f"vasc_pipeline: error: output_dir {str(output_dir)!r} holds no runs/ directory: nothing to "
            "reduce. Give the output_dir of a sweep (output_dir=...).\n"
        )
        return 2
    try:
        reduction = reduce(output_dir, stream=stream)
    except (ReductionError, OSError) as exc:
        stream.write(f"vasc_pipeline: error: {exc}\n")
        return 2
    return 1 if reduction.errors or reduction.damaged else 0


def _wait_some(wait, futures: set, timeout: float) -> tuple[set, set]:
    try:
        done, not_done = wait(futures, timeout=timeout, return_when="FIRST_COMPLETED")
    except TimeoutError:
        return set(), futures
    return set(done), set(not_done)


def _collect(fut: Any, job: Job, progress: Progress, result: dict) -> None:
    if fut.status == "finished" and fut.result().get("status") == "failed":  # raised: see _dask_run_job
        summary = fut.result()
        result["failed"][job.run_id] = summary["error"]
        result["deterministic"].add(job.run_id)
        progress.failed(job.run_id, f"{summary['error']} (deterministic: a rerun fails the same way)")
    elif fut.status == "finished":
        summary = fut.result()
        result["runs"].append(summary)
        if summary["status"] == "skipped":
            result["skipped"].append(job.run_id)
        else:
            result["complete"].append(job.run_id)
            if summary["resumed_from"]:
                result["resumed"].append(job.run_id)
        progress.finished(summary)
    else:
        exc = fut.exception()
        error = f"{type(exc).__name__}: {exc}"
        if type(exc).__name__ == "KilledWorker":
            error += " (its worker process died each time: a crash, or out of memory)"
        result["failed"][job.run_id] = error
        progress.failed(job.run_id, error)


def _print_summary(result: dict, p: Plan, stream: TextIO) -> None:
    n_failed = len(result["failed"])
    lines = [
        f"vasc_pipeline: finished in {_duration(result['wall_seconds'])}: {_runs(len(p.jobs))}: "
        f"{len(result['complete'])} completed now ({len(result['resumed'])} resumed from a checkpoint), "
        f"{len(result['skipped'])} already complete, {n_failed} failed"
        + (f", {len(result['damaged'])} left out (damaged store)" if result.get("damaged") else "")
        + "."
    ]
    deterministic = result.get("deterministic", set())
    for run_id, error in result["failed"].items():
        lines.append(f"  failed: {run_id}: {error}")
    if deterministic:
        lines.append(
            f"  {_runs(len(deterministic))} failed deterministically ({', '.join(sorted(deterministic))}): a run "
            "is a pure function of its configuration and seed, so rerunning fails the same way. Change the "
            "configuration (the error above says what failed) or report it as a bug."
        )
    if n_failed > len(deterministic):
        lines.append(
            f"  Rerun the same command to retry the {'other ' if deterministic else ''}failed runs (finished "
            "runs are skipped; the others resume from their last checkpoint)."
        )
    for run_id, why in result.get("damaged", {}).items():
        lines.append(f"  left out: {run_id}: {why}")
    lines.append(
        f"Results: {p.output_dir / RUNS_DIR}/<run_id>.zarr (xarray.open_zarr(path, group='trace'); "
        "tree/ and tissue/ groups; attrs cost, cost_recomputed, config)"
    )
    stream.write("\n".join(lines) + "\n")
    stream.flush()


def main(cfg: Any, stream: TextIO | None = None) -> int:
    """Entry point behind ``python -m vasc_pipeline``: run the sweep, return the exit status.

    Bad input (ConfigError, TissueError, TreeError, OSError such as an unwritable or locked
    output_dir, StoreError) is reported as one paragraph on stderr with status 2, before any
    job starts; status 1 when runs failed, a damaged store was left out, a stage after the runs
    (reduction, figures, exports) failed, or the cluster started no worker or job within
    ``cluster.startup_timeout``; Ctrl-C gives 130 (rerun to resume). A finished sweep is
    reduced; ``stage="reduce"`` (``+stage=reduce``) only reduces the runs already in
    ``output_dir`` (:func:`reduce_stage`).
    """
    from .tissue import TissueError
    from .tree import TreeError

    stream = stream or sys.stderr
    if getattr(cfg, "stage", "run") == "reduce":
        return reduce_stage(cfg, stream)
    try:
        result = run_sweep(cfg, stream=stream)
    except (ConfigError, TissueError, TreeError, StoreError, OSError) as exc:
        stream.write(f"vasc_pipeline: error: {exc}\nExisting results were left as they were.\n")
        return 2
    except KeyboardInterrupt:
        stream.write(
            "\nvasc_pipeline: interrupted. Finished runs are stored; the others resume from their last "
            "checkpoint when the same command is run again.\n"
        )
        return 130
    except SweepStartError as exc:
        stream.write(
            f"vasc_pipeline: error: {exc}. Stores already created resume when the same command is run again.\n"
        )
        return 1
    if result.get("dry_run"):
        return 0
    reduction = result["reduction"]
    reduction_failed = result["reduction_error"] or (reduction is not None and (reduction.errors or reduction.damaged))
    return 1 if result["failed"] or result["damaged"] or reduction_failed else 0
