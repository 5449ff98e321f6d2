"""The Dask task of a sweep: one job on a worker, and the map that runs a tree's parts on the cluster.

:func:`run_job_task` wraps :func:`vasc_pipeline.pipeline.job.run_job` (progress events, the
failures Dask should retry and those it should not); :func:`cluster_map` is the ``part_map``
of a tree in parts (``anneal.parts`` > 1).
"""

from __future__ import annotations

import time

from .progress import PROGRESS_TOPIC
from .sweep import Job

__all__ = ["run_job_task", "cluster_map", "PartLost"]


def run_job_task(job: Job) -> dict:
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
        return run_job(job, report, cluster_map(cfg.cluster.retries))
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


def cluster_map(retries: int):
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
