"""Overhead of the pipeline against calling the engine directly for the same jobs.

    python benchmarks/pipeline_overhead.py [--jobs 4] [--workers 2] [--steps 20000000]
    python benchmarks/pipeline_overhead.py --quick    # 2 tiny jobs on 1 worker (seconds)

Both sides run the same jobs (a small sphere sweep) with the same parallelism:

- direct: ``engine.run`` of every job in a process pool of ``--workers`` processes;
- pipeline: :func:`vasc_pipeline.pipeline.orchestrate.run_sweep` on a LocalCluster of ``--workers``
  process workers, checkpoints every 30 s (``--checkpoint-seconds``), traces, final stores.

Printed: wall time of each, the end-to-end overhead (cluster start-up, store creation,
checkpoints, trace and final writes, progress events), and the in-job part of it (job
session time against the engine's own time per run). Target: under 3 % end to end. The
numba kernels are compiled (or loaded from the cache) once before either side is timed.
"""

from __future__ import annotations

import argparse
import io
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

from vasc_pipeline import config, engine, sweep
from vasc_pipeline.pipeline import orchestrate, warmup


def _direct(job_config: dict, seed: int) -> float:
    start = time.perf_counter()
    engine.run(job_config, seed=seed)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", type=int, default=4, help="runs in the sweep (seeds)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--n-terminals", type=int, default=48)
    ap.add_argument(
        "--steps",
        type=int,
        default=20_000_000,
        help="proposed moves per run (default: jobs of ~30 s, so fixed start-up costs do not dominate)",
    )
    ap.add_argument("--checkpoint-seconds", type=float, default=30.0)
    ap.add_argument(
        "--quick", action="store_true", help="2 jobs of 20000 moves, N = 12, 1 worker: checks the script runs"
    )
    args = ap.parse_args(argv)
    if args.quick:
        args.jobs, args.workers, args.n_terminals, args.steps = 2, 1, 12, 20_000

    with tempfile.TemporaryDirectory() as out:
        cfg = config.compose(
            [
                "+sweep=smoke",
                f"sweep.n_terminals=[{args.n_terminals}]",
                "sweep.m_b=[641.3]",
                f"sweep.seeds=[{','.join(str(s) for s in range(args.jobs))}]",
                f"anneal.steps={args.steps}",
                "anneal.trace_every=100000",
                f"checkpoint.every_seconds={args.checkpoint_seconds}",
                f"cluster.n_workers={args.workers}",
                "cluster.dashboard_address=null",
                f"output_dir={out}",
            ]
        )
        jobs = sweep.expand(cfg)
        warmup.compile_kernels()

        def direct_run() -> tuple[float, list[float]]:
            start = time.perf_counter()
            with ProcessPoolExecutor(args.workers) as pool:
                seconds = list(pool.map(_direct, [j.config for j in jobs], [j.coords["seed"] for j in jobs]))
            return time.perf_counter() - start, seconds

        # direct, pipeline, direct: the mean of the two direct runs brackets the pipeline in
        # time, which cancels a slow drift of the machine's other load.
        direct_a, engine_a = direct_run()
        start = time.perf_counter()
        result = orchestrate.run_sweep(cfg, stream=io.StringIO())
        pipeline = time.perf_counter() - start
        assert not result.failed and len(result.complete) == len(jobs), result
        direct_b, engine_b = direct_run()
        direct = 0.5 * (direct_a + direct_b)
        engine_seconds = [0.5 * (a + b) for a, b in zip(engine_a, engine_b)]

    session = {r["run_id"]: r["session_seconds"] for r in result.runs}
    in_job = [session[j.run_id] / t - 1.0 for j, t in zip(jobs, engine_seconds)]
    print(
        f"{len(jobs)} runs of {args.steps:.3g} proposals, N = {args.n_terminals}, {args.workers} workers, "
        f"checkpoints every {args.checkpoint_seconds:g} s"
    )
    print(f"  direct engine.run (process pool): {direct:8.2f} s wall (mean of {direct_a:.2f} and {direct_b:.2f})")
    print(f"  pipeline (LocalCluster + stores): {pipeline:8.2f} s wall")
    print(f"  end-to-end overhead:              {100 * (pipeline / direct - 1):+8.2f} %  (target < 3 %)")
    print(
        f"  in-job overhead (median per run): {100 * statistics.median(in_job):+8.2f} %  "
        "(checkpoints, trace, store writes)"
    )


if __name__ == "__main__":
    main()
