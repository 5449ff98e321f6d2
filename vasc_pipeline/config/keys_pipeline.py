"""The key table's entries of the pipeline around a run: ``extend.*``, ``checkpoint.*``, ``sweep.*``
and ``cluster.*`` (:mod:`vasc_pipeline.config.keys`)."""

from __future__ import annotations

from dataclasses import replace

from .keyspec import (
    Key,
    OneOf,
    Range,
    plural,
)
from .rules import MAX_TERMINALS, SWEPT_KEYS
from .schema import (
    EXTEND_RUNS,
    EXTEND_ZERODS,
    MAX_CHECKPOINT_SECONDS,
)

__all__ = ["PIPELINE_KEYS"]

PIPELINE_KEYS: tuple[Key, ...] = (
    Key(
        "extend.n_terminals",
        "1",
        ("fine terminals in all, rounded to the nearest multiple of the run's N (m = round(n / N) in every territory)"),
        accepted="{}, and at least N/2 of each run extended",
        check=Range(1, MAX_TERMINALS, integer=True, why=" (fine terminals in all, at least the run's N)"),
    ),
    Key(
        "extend.runs",
        "–",
        "the lowest-cost seed of each cell, or every complete run",
        accepted="{}",
        check=OneOf(EXTEND_RUNS),
    ),
    Key(
        "extend.batch_territories",
        "territories",
        "territories per Dask task and per commit (the result does not depend on it)",
        accepted="{}",
        check=Range(1, 10**7, integer=True),
    ),
    Key(
        "extend.seed",
        "–",
        "the territories' random streams",
        default="{}: the run's own seed",
        accepted="{}, or null",
        check=replace(SWEPT_KEYS["seeds"], null=True),
    ),
    Key(
        "extend.zerod",
        "–",
        (
            "the reduction's 0D network of the whole tree (`trees/<run_id>.extended.0d.json`): every "
            "territory's subtree one lumped resistance, or every vessel "
            "([Results](results.md#the-whole-tree-reduced)); not part of the extended store's identity "
            "either"
        ),
        accepted="{}",
        check=OneOf(
            EXTEND_ZERODS,
            why=" (the whole tree's 0D network: each territory's subtree one lumped resistance, or every vessel)",
        ),
    ),
    Key(
        "checkpoint.every_seconds",
        "s",
        "time between a job's checkpoints",
        default="{} (`+sweep=smoke`: 5)",
        accepted="{} (a week)",
        check=Range(0, MAX_CHECKPOINT_SECONDS, lo_open=True, why=" (s; at most a week)"),
    ),
    Key("sweep.name", "–", "the sweep's name", accepted="a label"),
    Key(
        "sweep.n_terminals",
        "1",
        "the N axis",
        default="{}: [`n_terminals`]",
        accepted="list of " + plural(SWEPT_KEYS["n_terminals"].doc),
    ),
    Key(
        "sweep.m_b",
        "W m⁻³",
        "the m_b axis",
        default="{}: [`physics.m_b`]",
        accepted="list of " + plural(SWEPT_KEYS["m_b"].doc),
    ),
    Key("sweep.seeds", "–", "the seeds", default="{}: [`seed`]", accepted="list of " + plural(SWEPT_KEYS["seeds"].doc)),
    Key(
        "sweep.steps",
        "moves",
        "a steps axis (run ids then carry `-S<steps>`)",
        default="{}: `anneal.steps` (or the schedule's budget)",
        accepted="list of " + plural(SWEPT_KEYS["steps"].doc),
    ),
    Key("cluster.name", "–", "where the jobs run", accepted="`local`, `address`, `slurm`"),
    Key(
        "cluster.n_workers",
        "workers",
        "workers to start or request; not used with `address`",
        default="{}: local one per core, slurm one per unfinished run (never more than the unfinished runs)",
        accepted="integer ≥ 1, or null",
    ),
    Key(
        "cluster.address",
        "URL",
        "an existing scheduler",
        default="{} (`cluster=address`: required)",
        accepted="`tcp://host:port` or `tls://host:port`",
    ),
    Key(
        "cluster.dashboard_address",
        "host:port",
        "the Dask dashboard (needs bokeh; without it no port is asked for)",
        default="{} (`address`: null)",
        accepted="host:port, or null (no dashboard)",
    ),
    Key(
        "cluster.retries",
        "1",
        "resubmissions of a job whose worker died or whose machine failed it",
        accepted="integer ≥ 0",
    ),
    Key(
        "cluster.startup_timeout",
        "s",
        "wait for the first worker, then for the first job to begin",
        default="{}",
        accepted="finite > 0",
    ),
    Key(
        "cluster.allow_insecure",
        "–",
        "slurm without `cluster.tls.*` files: plain tcp instead of temporary TLS certificates",
        accepted="true, false",
    ),
    Key(
        "cluster.dry_run",
        "–",
        "print the planned runs (and the SLURM job script); run and write nothing",
        accepted="true, false",
    ),
    Key("cluster.tls.ca_file", "path", "certificate authority", accepted="a PEM file"),
    Key("cluster.tls.cert", "path", "certificate for client, scheduler and workers", accepted="a PEM file"),
    Key("cluster.tls.key", "path", "private key", default="{}: inside `cert`", accepted="a PEM file"),
    Key("cluster.tls.require_encryption", "–", "refuse unencrypted connections", accepted="true, false"),
    Key("cluster.slurm.queue", "–", "`-p`", accepted="a partition"),
    Key("cluster.slurm.account", "–", "`-A`", accepted="an account"),
    Key(
        "cluster.slurm.walltime",
        "time",
        "per SLURM job; workers retire before it",
        accepted=("sbatch's `--time` formats (`04:00:00`, `1-12:00:00`, ...), at least 10 minutes; `UNLIMITED`"),
    ),
    Key(
        "cluster.slurm.cores",
        "workers",
        "single-threaded worker processes per SLURM job (1: ended jobs are reliably replaced)",
        accepted="integer ≥ 1",
    ),
    Key("cluster.slurm.memory", "bytes", "per SLURM job", accepted="an amount such as `4GB` or `500MB`"),
    Key(
        "cluster.slurm.interface",
        "–",
        "the workers' and scheduler's interface",
        accepted="one of this machine's network interfaces, e.g. `ib0`",
    ),
    Key("cluster.slurm.local_directory", "path", "node-local scratch for Dask", accepted="a directory"),
    Key(
        "cluster.slurm.log_directory",
        "path",
        "where SLURM writes the worker jobs' logs",
        default="{}: `<output_dir>/.slurm_logs`",
        accepted="a directory",
    ),
    Key(
        "cluster.slurm.job_extra_directives",
        "–",
        'extra `#SBATCH` lines, e.g. `["--qos=normal"]`',
        accepted="list of strings",
    ),
    Key(
        "cluster.slurm.job_script_prologue",
        "–",
        'e.g. `["module load python", "source ~/venv/bin/activate"]`',
        accepted="list of strings",
    ),
)
