"""The Dask cluster of a sweep: checking ``cluster.*``, and a client on a local, an existing or a SLURM cluster.

:func:`check_cluster` refuses a bad ``cluster.*`` setting (ConfigError naming the field)
before any store is created. :func:`open_client` yields a client on a ``LocalCluster``
(process workers, one thread each, everything on 127.0.0.1), on an existing scheduler
(``cluster.address``, TLS from ``cluster.tls.*``), or on SLURM via dask-jobqueue
(:func:`slurm_cluster`, temporary TLS certificates unless ``cluster.allow_insecure``);
:func:`slurm_job_script` is what ``cluster.dry_run`` prints. :func:`wait_for_workers`
waits for a first worker and says what it waited for when none came.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import math
import os
import shutil
import time
from pathlib import Path
from typing import Any, Iterator

from ..config.pipeline import ClusterConfig
from ..config.schema import ConfigError
from ..store.layout import SLURM_LOG_DIR

__all__ = [
    "check_cluster",
    "open_client",
    "slurm_cluster",
    "slurm_job_script",
    "has_bokeh",
    "wait_for_workers",
    "probe_scheduler",
    "SweepStartError",
]


class SweepStartError(RuntimeError):
    """The cluster never started a worker, or the scheduler never started a job, within cluster.startup_timeout."""


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
    address = None if cluster.address == "???" else cluster.address  # cluster=address without one: missing
    if cluster.name not in ("local", "address", "slurm"):
        raise ConfigError(f"cluster.name must be one of local, address, slurm; got {cluster.name!r}")
    if cluster.n_workers is not None and cluster.n_workers < 1:
        raise ConfigError(f"cluster.n_workers must be an integer >= 1 (or null: one per core), got {cluster.n_workers}")
    if cluster.retries < 0:
        raise ConfigError(f"cluster.retries must be an integer >= 0, got {cluster.retries}")
    if cluster.name == "address" and not address:
        raise ConfigError(
            "cluster.address is required for cluster=address: the scheduler's tcp://host:8786 (or tls://host:8786)"
        )
    if address and "://" not in address:
        raise ConfigError(f"cluster.address must look like tcp://host:8786 or tls://host:8786, got {address!r}")
    if cluster.name == "slurm":
        _check_slurm_resources(cluster.slurm)
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


PROBE_SECONDS = 10.0  # at most this long (and at most cluster.startup_timeout) for each step of the probe


def probe_scheduler(cluster: ClusterConfig) -> None:
    """Refuse (ConfigError, one line) a ``tcp://`` ``cluster.address`` where no Dask scheduler answers.

    Before any store is written: connect with a timeout and read the greeting a Dask scheduler
    sends first (its comm handshake: an 8-byte length, a frame count, msgpack). Something else
    on the port is named: a server that sends another greeting (an SSH banner: Dask would read
    its bytes as a frame length), one that waits for the client (an HTTP server such as the
    dashboard, asked once with ``GET /``), or nothing at all. ``tls://`` addresses are only
    connected to (their greeting is encrypted).
    """
    import socket
    import struct
    from urllib.parse import urlsplit

    address = cluster.address
    scheme = address.partition("://")[0].lower()
    if scheme not in ("tcp", "tls"):
        return
    try:
        parts = urlsplit(address)
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise ConfigError(f"cluster.address must look like tcp://host:8786 or tls://host:8786, got {address!r}")
    wait = min(float(cluster.startup_timeout), PROBE_SECONDS)
    expected = "expected a Dask scheduler (dask scheduler prints its 'Scheduler at: tcp://host:port'; 8786 by default)"
    try:
        sock = socket.create_connection((host, port), timeout=wait)
    except OSError as exc:
        why = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise ConfigError(f"cluster.address {address}: cannot connect ({why} within {wait:g} s); {expected}") from None
    with sock:
        if scheme == "tls":
            return
        data = b""
        deadline = time.monotonic() + wait
        try:
            while len(data) < 16 and time.monotonic() < deadline:
                sock.settimeout(max(deadline - time.monotonic(), 0.01))
                chunk = sock.recv(256)
                if not chunk:
                    break
                data += chunk
        except (TimeoutError, OSError):
            pass
        if len(data) >= 16:
            total, frames = struct.unpack("<QQ", data[:16])
            if 0 < total < 2**20 and 1 <= frames <= 64:
                return  # a Dask comm handshake
        if data:
            raise ConfigError(
                f"cluster.address {address}: the server there answered {_first_line(data)!r}, which is not the "
                f"greeting of a Dask scheduler; {expected}"
            )
        reply = b""
        try:  # silent so far: servers that wait for the client, HTTP above all, answer a request
            sock.settimeout(wait)
            sock.sendall(f"GET / HTTP/1.0\r\nHost: {host}\r\n\r\n".encode())
            reply = sock.recv(256)
        except OSError:
            pass
    if reply.startswith(b"HTTP/"):
        raise ConfigError(
            f"cluster.address {address}: an HTTP server answered ({_first_line(reply)!r}; a Dask dashboard's "
            f"port, 8787 by default?), not a Dask scheduler; {expected}"
        )
    raise ConfigError(
        f"cluster.address {address}: something accepted the connection but sent no Dask greeting within "
        f"{wait:g} s" + (f" (it answered {_first_line(reply)!r} to a request)" if reply else "") + f"; {expected}"
    )


def _first_line(data: bytes) -> str:
    return data.splitlines()[0][:80].decode("ascii", "backslashreplace") if data.strip() else repr(data[:32])


def _check_slurm_resources(s: Any) -> None:
    """cluster.slurm's cores, walltime, memory and interface, which dask-jobqueue would only reject
    with a traceback once the scheduler starts (the interface is the scheduler's too, so it must
    exist here)."""
    import psutil
    from dask.utils import parse_bytes

    if s.cores < 1:
        raise ConfigError(f"cluster.slurm.cores must be an integer >= 1, got {s.cores}")
    worker_lifetime(s.walltime)  # raises for a walltime SLURM would not take, or one too short
    try:
        memory = parse_bytes(s.memory)
    except (ValueError, TypeError):
        memory = 0
    if memory <= 0:
        raise ConfigError(f"cluster.slurm.memory must be an amount per job such as 4GB or 500MB, got {s.memory!r}")
    interfaces = psutil.net_if_addrs()
    if s.interface is not None and s.interface not in interfaces:
        raise ConfigError(
            f"cluster.slurm.interface {s.interface!r} is not a network interface of this machine (the "
            f"scheduler's); accepted: {', '.join(sorted(interfaces))}, or null"
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
    """Scheduler options: the dashboard at cluster.dashboard_address, or off (its HTTP server on loopback).

    Off, the HTTP server (health checks, metrics) takes any free port: given no address, Dask
    would ask for its dashboard's 8787 and, that port taken, announce a "dashboard" elsewhere.
    """
    if cluster.dashboard_address and has_bokeh():
        return {"dashboard": True, "dashboard_address": cluster.dashboard_address}
    return {"dashboard": False, "dashboard_address": "127.0.0.1:0"}


MIN_WALLTIME_SECONDS = 600.0  # a worker must outlive its start-up and a checkpoint interval or two
NO_TIME_LIMIT = ("UNLIMITED", "INFINITE")  # sbatch --time values without a limit of their own


def walltime_seconds(walltime: str) -> float:
    """Seconds of a SLURM time limit: minutes, minutes:seconds, hours:minutes:seconds, days-hours,
    days-hours:minutes or days-hours:minutes:seconds (``sbatch --time``'s formats); infinite for
    UNLIMITED or INFINITE (the partition's own limit then applies, unknown here)."""
    if str(walltime).strip().upper() in NO_TIME_LIMIT:
        return math.inf
    days, _, clock = str(walltime).strip().rpartition("-")
    parts = clock.split(":")
    if not 1 <= len(parts) <= 3 or not all(p.isdigit() for p in parts) or (days and not days.isdigit()):
        raise ConfigError(
            f"cluster.slurm.walltime must be a SLURM time limit such as 04:00:00 or 1-12:00:00, got {walltime!r}"
        )
    values = [int(p) for p in parts]
    if days:  # days-hours[:minutes[:seconds]]
        hours, minutes, seconds = (values + [0, 0])[:3]
        hours += 24 * int(days)
    elif len(values) == 3:
        hours, minutes, seconds = values
    else:  # minutes[:seconds]
        hours, (minutes, seconds) = 0, (values + [0])[:2]
    return float((hours * 60 + minutes) * 60 + seconds)


def worker_lifetime(walltime: str) -> tuple[str, str] | None:
    """``dask worker`` ``--lifetime`` and ``--lifetime-stagger`` for SLURM jobs of ``walltime``
    (None for UNLIMITED: workers then run until the partition's limit ends their job).

    A worker retires gracefully a lead of 10 % of the walltime (2 to 15 minutes) before SLURM
    would kill its job, give or take a quarter of the lead so that workers do not all leave at
    once. A retired worker's run is rescheduled without counting as a failure (against
    ``cluster.retries``) and resumes from its last checkpoint on a worker of a new job, which
    adaptive scaling submits to keep ``n_workers`` workers (measured with a LocalCluster:
    ``tests/pipeline/test_reliability.py``).
    """
    total = walltime_seconds(walltime)
    if math.isinf(total):
        return None
    if total < MIN_WALLTIME_SECONDS:
        raise ConfigError(
            f"cluster.slurm.walltime must be at least {MIN_WALLTIME_SECONDS / 60:g} minutes, got {walltime!r}"
        )
    lead = min(max(0.1 * total, 120.0), 900.0)
    return f"{round(total - lead)}s", f"{round(lead / 4)}s"


def slurm_cluster(cluster: ClusterConfig, output_dir: str | os.PathLike | None = None) -> Any:
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
    lifetime = worker_lifetime(s.walltime)
    # One keyword per cluster.slurm key: the config uses dask-jobqueue's own names.
    cl = SLURMCluster(
        queue=s.queue,
        account=s.account,
        walltime=s.walltime,
        cores=s.cores,
        processes=s.cores,
        memory=s.memory,
        interface=s.interface,
        local_directory=s.local_directory,
        # unset: with the sweep's results, not as slurm-<id>.out in whatever directory it was started from
        log_directory=s.log_directory or (str(Path(output_dir).resolve() / SLURM_LOG_DIR) if output_dir else None),
        job_extra_directives=list(s.job_extra_directives),
        job_script_prologue=[*s.job_script_prologue, *_WORKER_ENV],
        security=security,
        protocol="tls://" if security else None,
        scheduler_options=_dashboard_options(cluster),
        shared_temp_directory=str(Path(output_dir).resolve()) if output_dir is not None else None,
        # None keeps any jobqueue.slurm.worker-extra-args of the user's dask config.
        worker_extra_args=["--lifetime", lifetime[0], "--lifetime-stagger", lifetime[1]] if lifetime else None,
    )
    return cl


def slurm_job_script(cluster: ClusterConfig, output_dir: str | os.PathLike) -> str:
    """The job script SLURM would run for ``cluster`` (nothing submitted; the cluster's scheduler
    is closed again, and the log directory dask-jobqueue creates is removed if it was not there)."""
    logs = Path(output_dir).resolve() / SLURM_LOG_DIR
    created = [d for d in (logs.parent, logs) if not d.exists()]
    with _quiet_dask():
        cl = slurm_cluster(cluster, output_dir)
        try:
            return cl.job_script()
        finally:
            cl.close()
            for d in reversed(created):
                with contextlib.suppress(OSError):  # not empty: something else wrote there
                    d.rmdir()


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
            cl = slurm_cluster(cluster, output_dir)
            # Adaptive with minimum = maximum: a job that ends (its workers retire before the
            # walltime, see worker_lifetime) is replaced by a new one, where a plain scale() is not.
            # Counted in whole jobs, so that adapt never cancels part of a job of several workers.
            jobs = math.ceil((cluster.n_workers or n_jobs) / cluster.slurm.cores)
            cl.adapt(minimum_jobs=jobs, maximum_jobs=jobs)
        else:
            n = cluster.n_workers or max(1, min(_cores(), n_jobs))
            dashboard = _dashboard_options(cluster)
            cl = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=dashboard["dashboard_address"],
                scheduler_kwargs={"dashboard": dashboard["dashboard"]},  # LocalCluster's own: address given
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


def wait_for_workers(client: Any, cluster: ClusterConfig, n_jobs: int) -> None:
    """Wait up to cluster.startup_timeout for a first worker; :class:`SweepStartError` saying what for."""
    try:
        client.wait_for_workers(1, timeout=cluster.startup_timeout)
        return
    except (TimeoutError, OSError):
        pass
    if cluster.name == "slurm":
        what = (
            f"the workers of {cluster.n_workers or n_jobs} requested SLURM worker(s) (squeue -u $USER shows "
            f"whether the jobs are queued; their logs go to cluster.slurm.log_directory, by default "
            f"<output_dir>/{SLURM_LOG_DIR})"
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
