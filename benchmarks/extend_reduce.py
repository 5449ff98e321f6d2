"""The whole tree's reduction (``reduce_extended``): wall time per step, peak memory, the output sizes
and the pressures by order, at n fine terminals below a committed annealed tree.

A temporary output_dir gets a copy of the run store (default the best N = 6000 heart of the size
scan, ``results/studies/size_scan/runs/heart-N6000-mb641.3-s1.zarr``) in ``runs/``; the whole tree
is grown below it (:func:`vasc_pipeline.pipeline.extend.extend_run`, serial) in one fresh process
and reduced (:func:`vasc_pipeline.reduce.extended.reduce_extended`, exports and figures on) in
another, whose resident memory is sampled every 0.2 s.

    python benchmarks/extend_reduce.py --n 100000                # 1e5 below the N = 6000 heart
    python benchmarks/extend_reduce.py --n 100000 --zerod full   # the full 0D network instead
    python benchmarks/extend_reduce.py --quick                   # a small heart annealed here, n = 1000

Prints one JSON line (times, memory, sizes, the anatomy, the pressures by order of the range
reading), then the pressures as a table.
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
MMHG = 133.322387415


def extend(source: str, out: str, n: int) -> None:
    """Grow the whole tree (its own process: the reduction's memory is measured alone)."""
    from vasc_pipeline.pipeline.extend import extend_run
    from vasc_pipeline.store.layout import extended_path
    from vasc_pipeline.store.run_store import RunStore

    run_id = RunStore.open(source, mode="r").run_id
    started = time.perf_counter()
    extend_run(source, extended_path(out, run_id), n, stream=io.StringIO(), compile_first=True)
    print(json.dumps({"extend_seconds": time.perf_counter() - started}))


def reduce_it(out: str, zerod: str) -> None:
    """Reduce the whole tree of ``out`` in this process; prints its row."""
    import os

    import psutil

    peak = [0]
    stop = threading.Event()

    def sample() -> None:
        while not stop.is_set():
            peak[0] = max(peak[0], psutil.Process(os.getpid()).memory_info().rss)
            stop.wait(0.2)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    from vasc_pipeline.reduce.extended import reduce_extended

    started = time.perf_counter()
    result = reduce_extended(out, zerod=zerod, stream=io.StringIO())
    wall = time.perf_counter() - started
    stop.set()
    sampler.join()
    (run_id,) = result.seconds
    from vasc_pipeline.reduce.extended import extended_stores
    from vasc_pipeline.store.extended import ExtendedStore

    (store,) = extended_stores(out)[0]
    physics = ExtendedStore.open(store).attrs["physics"]
    summary = result.summary
    anatomy = summary["anatomy"].to_dataset().sel(run_id=run_id)
    morph = summary["morphometry"].to_dataset().sel(run_id=run_id, reading="range", scheme="diameter_defined")
    press = summary["pressure"].to_dataset().sel(run_id=run_id, reading="range")
    comp = summary["comparison"].to_dataset().sel(run_id=run_id) if "comparison" in summary.children else None
    orders = [int(o) for o in morph.order.values if int(morph.element_count.sel(order=o)) > 0]
    row = {
        "run_id": run_id,
        "gamma": physics["gamma"],
        "viscosity_law": physics.get("viscosity_law", "constant"),
        "zerod": zerod,
        "n_terminals": int(anatomy.n_fine_terminals),
        "n_territories": int(anatomy.n_territories),
        "wall_seconds": wall,
        "seconds": result.seconds[run_id],
        "peak_rss_mb": peak[0] / 2**20,
        "errors": result.errors,
        "zero_d_check": result.zero_d_check.get(run_id),
        "zero_d_solver": result.zero_d_solver.get(run_id),
        "files_mb": {p.name[len(run_id) + 1 :]: p.stat().st_size / 2**20 for p in result.trees},
        "anatomy": {k: float(v) for k, v in anatomy.data_vars.items() if v.ndim == 0},
        "mean_abs_log10": None
        if comp is None
        else {
            r: {
                "D": {
                    a: float(comp.mean_abs_log10_ratio_diameter.sel(reading=r, artery=a)) for a in ("RCA", "LAD", "LCX")
                },
                "L": {
                    a: float(comp.mean_abs_log10_ratio_length.sel(reading=r, artery=a)) for a in ("RCA", "LAD", "LCX")
                },
                "orders": int(comp.n_orders_compared.sel(reading=r).isel(artery=0)),
            }
            for r in ("range", "confluence")
        },
        "orders": {
            o: {
                "elements": int(morph.element_count.sel(order=o)),
                "diameter_um": 1e6 * float(morph.element_diameter_mean.sel(order=o)),
                "length_mm": 1e3 * float(morph.element_length_mean.sel(order=o)),
                "diameter_min_um": 1e6 * float(press.diameter_min.sel(order=o)),
                "diameter_max_um": 1e6 * float(press.diameter_max.sel(order=o)),
                "pressure_mean_mmhg": float(press.pressure_mean.sel(order=o)) / MMHG,
                "pressure_min_mmhg": float(press.pressure_min.sel(order=o)) / MMHG,
                "pressure_mean_fraction": float(press.pressure_mean_fraction.sel(order=o)),
                "pressure_min_fraction": float(press.pressure_min_fraction.sel(order=o)),
            }
            for o in orders
        },
    }
    print(json.dumps(row))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", default=None, help="a complete run store (default the N = 6000 heart)")
    parser.add_argument("--n", type=float, default=100_000, help="fine terminals (extend.n_terminals)")
    parser.add_argument("--zerod", default="lumped", choices=("lumped", "full"))
    parser.add_argument("--out", default=None, help="keep the output_dir here (default: a temporary dir)")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        if args.child[0] == "extend":
            extend(args.child[1], args.child[2], int(args.child[3]))
        else:
            reduce_it(args.child[1], args.child[2])
        return 0
    n = 1000 if args.quick else int(args.n)
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="extend_reduce_"))
    try:
        if args.source or not args.quick:
            source = Path(args.source or SOURCE)
        else:  # the clone holds no study's stores: the same small heart as extend_scaling's --quick
            from extend_scaling import quick_source

            source = Path(quick_source(out / "quick_source"))
        (out / "runs").mkdir(parents=True, exist_ok=True)
        copy = out / "runs" / source.name
        if not copy.exists():
            shutil.copytree(source, copy)
        rows = {}
        for step, extra in (("extend", [str(copy), str(out), str(n)]), ("reduce", [str(out), args.zerod])):
            cmd = [sys.executable, __file__, "--child", step, *extra]
            done = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO)
            if done.returncode != 0:
                sys.stderr.write(done.stderr[-3000:])
                return 1
            rows.update(json.loads(done.stdout.strip().splitlines()[-1]))
        rows["source"] = str(source)
    finally:
        if not args.out:
            shutil.rmtree(out, ignore_errors=True)
    print(json.dumps(rows), flush=True)
    print("| order | elements | D [µm] (range of segments) | L [mm] | P mean [mmHg] | P min [mmHg] | mean % inlet |")
    print("|" + "---|" * 7)
    for o, r in sorted(rows["orders"].items(), key=lambda kv: -int(kv[0])):
        print(
            f"| {o} | {r['elements']} | {r['diameter_um']:.3g} ({r['diameter_min_um']:.3g}–{r['diameter_max_um']:.3g}) "
            f"| {r['length_mm']:.3g} | {r['pressure_mean_mmhg']:.1f} | {r['pressure_min_mmhg']:.1f} "
            f"| {100 * r['pressure_mean_fraction']:.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
