"""The whole tree below an annealed run (``+stage=extend``): wall time, peak memory and the exponent in n.

For each fine count n below a committed annealed tree (default the best N = 6000 heart of the
size scan, ``results/studies/size_scan/runs/heart-N6000-mb641.3-s1.zarr``, restored from the history
as results/README.md says), one extension in a
fresh process (:func:`vasc_pipeline.pipeline.extend.extend_run`, serial, or on a LocalCluster of
``--workers``) into a temporary directory: wall time (planning, growth, finishing), the peak
resident memory of that process and its workers (sampled every 0.2 s), the whole tree's
C_v + C_w, the coverage and the fine segments in a cavity. Then the exponent alpha of growth
seconds ~ n^alpha (least squares in log-log) and the growth seconds per n log2 n.

``--sample K``: K territories spread over the tree, grown at the per-territory count m of each
size and timed in this process, scaled to all N territories (the growth's serial time at a size
too large to run here; no store, no memory figure).

    python benchmarks/extend_scaling.py --sizes 12000 24000 48000 96000
    python benchmarks/extend_scaling.py --sizes 1e5 2e5 5e5 1e6 --sample 60
    python benchmarks/extend_scaling.py --quick        # a small heart annealed here, n = 1000 and 2000

Prints one JSON line per size (and one for the fit), then a table.
"""

from __future__ import annotations

import argparse
import io
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RUNS = REPO / "results" / "studies" / "size_scan" / "runs"
SOURCE = RUNS / "heart-N6000-mb641.3-s1.zarr"


def quick_source(where: Path) -> str:
    """A small annealed heart (N = 500, a short anneal) grown into ``where``: --quick's source, so
    the wiring is exercised on a clone that holds no study's stores."""
    from vasc_pipeline import config, job, sweep

    (j,) = sweep.expand(config.compose(["n_terminals=500", "anneal.steps=100000", f"output_dir={where}"]))
    job.run_job(j)
    return j.store


def tree_rss(pid: int) -> int:
    """Resident bytes of a process and all its descendants (a LocalCluster's workers too)."""
    import psutil

    try:
        root = psutil.Process(pid)
        procs = [root, *root.children(recursive=True)]
    except psutil.Error:
        return 0
    total = 0
    for p in procs:
        try:
            total += p.memory_info().rss
        except psutil.Error:
            continue
    return total


def child(source: str, n: int, out: str, workers: int, batch: int) -> None:
    """One extension in this process; prints its row as JSON."""
    import os

    peak = [0]
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            peak[0] = max(peak[0], tree_rss(os.getpid()))
            stop.wait(0.2)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    from vasc_pipeline.pipeline.extend import dask_mapper, extend_run

    started = time.perf_counter()
    kw = dict(batch_territories=batch, stream=io.StringIO(), compile_first=True)
    if workers:
        import distributed

        with (
            distributed.LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            summary = extend_run(source, out, n, mapper=dask_mapper(client), **kw)
    else:
        summary = extend_run(source, out, n, **kw)
    wall = time.perf_counter() - started
    stop.set()
    sampler.join()
    from vasc_pipeline.store.extended import ExtendedStore

    attrs = ExtendedStore.open(out).attrs
    stats = attrs["statistics"]
    row = {
        "n_requested": n,
        "n_terminals": summary["n_terminals"],
        "n_annealed": attrs["n_territories"],
        "per_territory": stats["per_territory"],
        "workers": workers,
        "wall_seconds": wall,
        **{k: attrs["timings"][k] for k in ("plan_seconds", "grow_seconds", "finish_seconds")},
        "peak_rss_mb": peak[0] / 2**20,
        "vascular_cost": summary["cost"]["volume"] + summary["cost"]["power"],
        "coverage": stats["coverage"],
        "cavity_segments": stats["cavity_segments"],
        "nodes": attrs["n_nodes"],
    }
    print(json.dumps(row))


def sampled(source: str, sizes: list[int], k: int) -> list[dict]:
    """K territories at each size's m, timed here and scaled to all territories."""
    import numpy as np

    from vasc_pipeline.engine.extend import grow_batch, plan_extension, read_source

    src = read_source(source)
    rows = []
    for n in sizes:
        plan = plan_extension(src, n)
        picks = np.linspace(0, plan.n_territories - 1, min(k, plan.n_territories)).astype(int)
        inputs = [plan.batch(int(i), int(i) + 1)[0] for i in picks]
        grow_batch(plan.growth, inputs[:1])  # compiled (or loaded) outside the timing
        started = time.perf_counter()
        grow_batch(plan.growth, inputs)
        per = (time.perf_counter() - started) / len(inputs)
        rows.append(
            {
                "mode": "sample",
                "n_requested": n,
                "n_terminals": plan.n_fine,
                "per_territory": plan.per_territory,
                "territories_timed": len(inputs),
                "seconds_per_territory": per,
                "grow_seconds": per * plan.n_territories,  # serial, projected to every territory
            }
        )
        print(json.dumps(rows[-1]), flush=True)
    return rows


def fit(rows: list[dict]) -> dict:
    """alpha of grow seconds ~ n^alpha, and grow seconds / (n log2 n) at each size."""
    import numpy as np

    n = np.array([r["n_terminals"] for r in rows], dtype=float)
    t = np.array([r["grow_seconds"] for r in rows], dtype=float)
    alpha = float(np.polyfit(np.log(n), np.log(t), 1)[0]) if len(rows) >= 2 else None
    return {"fit": "grow_seconds ~ n^alpha", "alpha": alpha, "per_n_log_n": (t / (n * np.log2(n))).tolist()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default=None, help="a complete run store (default the N = 6000 heart)")
    parser.add_argument("--sizes", type=float, nargs="+", default=[12000, 24000, 48000, 96000])
    parser.add_argument("--workers", type=int, default=0, help="LocalCluster workers (0: serial, in the process)")
    parser.add_argument("--batch", type=int, default=200, help="extend.batch_territories")
    parser.add_argument("--sample", type=int, default=0, help="time K territories per size instead (see above)")
    parser.add_argument("--out", default=None, help="keep the extended stores here (default: a temporary dir)")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        source, n, out, workers, batch = args.child
        child(source, int(n), out, int(workers), int(batch))
        return 0
    scratch = Path(tempfile.mkdtemp(prefix="extend_scaling_source_")) if args.quick and not args.source else None
    source = str(args.source or (quick_source(scratch) if scratch else SOURCE))
    sizes = [1000, 2000] if args.quick else [int(s) for s in args.sizes]
    if args.sample:
        rows = sampled(source, sizes, 4 if args.quick else args.sample)
    else:
        out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="extend_scaling_"))
        rows = []
        try:
            for n in sizes:
                path = out / f"n{n}.zarr"
                shutil.rmtree(path, ignore_errors=True)
                cmd = [sys.executable, __file__, "--child", source, str(n), str(path), str(args.workers)]
                done = subprocess.run([*cmd, str(args.batch)], capture_output=True, text=True, cwd=REPO)
                if done.returncode != 0:
                    sys.stderr.write(done.stderr[-3000:])
                    return 1
                rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
                print(json.dumps(rows[-1]), flush=True)
        finally:
            if not args.out:
                shutil.rmtree(out, ignore_errors=True)
    if scratch:
        shutil.rmtree(scratch, ignore_errors=True)
    summary = fit(rows)
    print(json.dumps(summary))
    if args.sample:
        print("| n (fine) | m | territories timed | ms per territory | grow s, projected to all (serial) |")
        print("|" + "---|" * 5)
        for r in rows:
            print(
                f"| {r['n_terminals']} | {r['per_territory']} | {r['territories_timed']} | "
                f"{1e3 * r['seconds_per_territory']:.2f} | {r['grow_seconds']:.1f} |"
            )
    else:
        print("| n (fine) | m | grow s | wall s | peak RSS MB | coverage | cavity segments |")
        print("|" + "---|" * 7)
        for r in rows:
            print(
                f"| {r['n_terminals']} | {r['per_territory']} | {r['grow_seconds']:.1f} | {r['wall_seconds']:.1f} | "
                f"{r['peak_rss_mb']:.0f} | {r['coverage']:.4f} | {r['cavity_segments']} |"
            )
    if summary["alpha"] is not None:
        print(f"alpha (grow seconds ~ n^alpha): {summary['alpha']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
