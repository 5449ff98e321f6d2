"""Config groups of the pipeline around the runs: the sweep grid and the cluster (Dask, SLURM, TLS).

Part of the schema of :class:`vasc_pipeline.config.RunConfig` (its ``sweep`` and ``cluster``
fields; :mod:`vasc_pipeline.config` re-exports these dataclasses), but not of a run's
identity (:mod:`vasc_pipeline.config.identity` leaves them out): they say how a sweep is organised,
not what a run computes. :mod:`vasc_pipeline.pipeline.sweep` expands the grid,
:mod:`vasc_pipeline.pipeline.dispatch` and :mod:`vasc_pipeline.pipeline.cluster` fan the jobs out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from .frozen import Settings

__all__ = ["SweepConfig", "TLSConfig", "SlurmConfig", "ClusterConfig"]


@dataclass
class SweepConfig(Settings):
    """A grid of runs; ``None`` on an axis means the single value of the base config.

    Run ids come from the grid coordinates (tissue, N, m_b, seed, and steps when the
    steps axis is given), so adding grid points to an output_dir adds runs.
    """

    name: str = "single"
    n_terminals: Optional[list[int]] = None  # N axis; None: [n_terminals]
    m_b: Optional[list[float]] = None  # W m^-3 axis; None: [physics.m_b]
    seeds: Optional[list[int]] = None  # None: [seed]
    steps: Optional[list[int]] = None  # proposed moves axis; None: anneal.steps (or the schedule's)


@dataclass
class TLSConfig(Settings):
    """Dask TLS settings (distributed.security.Security) for cluster=address / cluster=slurm."""

    ca_file: Optional[str] = None  # PEM file of the certificate authority
    cert: Optional[str] = None  # PEM client/worker certificate
    key: Optional[str] = None  # PEM private key (None: inside cert)
    require_encryption: bool = False  # refuse unencrypted connections


@dataclass
class SlurmConfig(Settings):
    """dask-jobqueue SLURMCluster options: one single-threaded worker per SLURM task slot."""

    queue: Optional[str] = None  # partition (-p)
    account: Optional[str] = None  # -A
    walltime: str = "04:00:00"  # per SLURM job (sbatch --time formats); workers retire before it
    cores: int = 1  # worker processes (one thread each) per SLURM job
    memory: str = "4GB"  # per SLURM job
    interface: Optional[str] = None  # network interface of the workers, e.g. ib0
    local_directory: Optional[str] = None  # node-local scratch for Dask
    log_directory: Optional[str] = None  # where SLURM writes the job logs
    job_extra_directives: list[str] = field(default_factory=list)  # extra '#SBATCH ...' lines
    job_script_prologue: list[str] = field(default_factory=list)  # e.g. module load / conda activate


@dataclass
class ClusterConfig(Settings):
    """Where the jobs run: ``local`` (LocalCluster), ``address`` (existing scheduler) or ``slurm``."""

    name: str = "local"
    n_workers: Optional[int] = None  # local: None = cores (at most one per job); slurm: workers to request
    address: Optional[str] = None  # tcp://host:8786 or tls://host:8786 of an existing scheduler
    dashboard_address: Optional[str] = "127.0.0.1:8787"  # local/slurm dashboard; None: no dashboard
    retries: int = 2  # resubmissions of a job whose worker died or that raised
    startup_timeout: float = 300.0  # s to wait for the first worker (and for the first job to start)
    allow_insecure: bool = False  # slurm without cluster.tls files: plain tcp instead of temporary TLS
    dry_run: bool = False  # print the planned runs (and the SLURM job script); run nothing
    tls: TLSConfig = field(default_factory=TLSConfig)
    slurm: SlurmConfig = field(default_factory=SlurmConfig)
