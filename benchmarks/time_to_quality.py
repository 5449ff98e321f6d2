"""Time to quality on the heart: wall time, moves per second and final quality per run.

For every requested N, schedule (an ``anneal=`` preset), budget and seed, one run of the
heart (default tissue and physics) is grown as a pipeline job (:func:`vasc_pipeline.pipeline.job.run_job`
in a process pool, one core per run): checkpointed every minute, so an interrupted
benchmark resumes where it stopped, even in the middle of a long run, when the same
command is given again. Runs of schedule S at budget B live in ``--out/S/xB/runs/``.

One JSON line per finished run (also appended to ``--out/rows.jsonl``; rows already there
are not recomputed) with ``n_terminals``, ``anneal``, ``budget`` (times the schedule's
default), ``steps``, ``seed``, ``wall_seconds`` (all sessions of the run, building the
problem and the polish included), ``moves_per_second``, ``cost_supply`` (C_s, voxels),
``cost_vascular`` (C_v + C_w + A_o/A_wv C_o, W) and its parts ``cost_volume``, ``cost_power``,
``cost_exclusion_weighted`` (W), ``cost_total`` (the annealed C), ``cavity_share``, each inlet's
share of the terminals (``terminal_share_<inlet>``; near 0: an abandoned artery), ``parts`` and ``workers`` (the
threads that ran the parts; 1 for a serial run, which has one core) and the
morphometry against Kassab 1993 (diameter-defined Strahler, element level, orders shifted to
11): ``diameter_error_<artery>`` and ``length_error_<artery>`` (mean |log10 model/Kassab|
over the orders present in both), the same with the terminal order aligned on Kassab's order
of nearest diameter
(``..._terminal_aligned_<artery>``, shift in ``terminal_aligned_shift``), ``n_orders`` and
``orders`` (per order: elements, segments per element, mean diameter [um], length [mm]).
Then a table of mean ± SE per (N, schedule, budget). A variant of a preset
(``--override``) needs a ``--label`` of its own: it names the variant's directory and rows.

    python benchmarks/time_to_quality.py --out results/ttq                 # N = 500, 1000, 2000
    python benchmarks/time_to_quality.py --out results/ttq --sizes 4000 6000 --seeds 0 1
    python benchmarks/time_to_quality.py --out results/ttq --anneal fast_v1 --budgets 1 3
    python benchmarks/time_to_quality.py --out results/ttq --anneal fast --label pack \
        --override anneal.packing_steps_per_terminal=10000 --override anneal.supply_T_start=null
    python benchmarks/time_to_quality.py --out results/ttq --anneal fast --parts 2 --workers 2  # one tree in 2 parts
    python benchmarks/time_to_quality.py --quick                           # seconds: wiring only

Wall times are those of one core; two runs side by side on a 2-core machine share its
memory bandwidth, and anything else running on the machine inflates them.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from vasc_pipeline.reduce.fidelity import run_row
from vasc_pipeline.reduce.reference import ARTERIES

DEFAULT_SIZES = [500, 1000, 2000]
LARGE_SIZES = [4000, 6000]


def jobs_for(
    out: Path,
    schedule: str,
    budget: float,
    n: int,
    seeds: list[int],
    steps: int | None,
    extra: list[str],
    label: str | None = None,
):
    """The pipeline jobs of one (schedule, budget, N): one per seed, in ``out/<label>/x<budget>``."""
    from vasc_pipeline import config, sweep
    from vasc_pipeline.config import scheduled_steps, to_run_config

    base = [f"anneal={schedule}", f"n_terminals={n}", *extra]
    if steps is None:
        steps = int(round(budget * scheduled_steps(to_run_config(config.compose(base)))))
    # Quoted, so that a label may hold what Hydra's override grammar reserves ("p_swap=0.3").
    where = f"output_dir='{out / (label or schedule) / f'x{budget:g}'}'"
    return [
        j
        for seed in seeds
        for j in sweep.expand(config.compose([*base, f"anneal.steps={steps}", f"seed={seed}", where]))
    ]


def run_one(j) -> str:
    from vasc_pipeline import job

    job.run_job(j)
    return j.store


def run_in_parts(j, workers: int) -> str:
    """One run of ``anneal.parts`` > 1, its parts on ``workers`` threads (the kernel releases the
    GIL; the tree is the one any other way of running the parts gives)."""
    from concurrent.futures import ThreadPoolExecutor

    from vasc_pipeline import job

    with ThreadPoolExecutor(workers) as pool:
        job.run_job(j, part_map=pool.map)
    return j.store


def row_of(store_path: str, schedule: str, budget: float) -> dict:
    """The benchmark's row of a complete run store (:func:`vasc_pipeline.reduce.fidelity.run_row`)."""
    row = run_row(store_path)
    return {"n_terminals": row.pop("n_terminals"), "anneal": schedule, "budget": budget, **row}


SUMMARY_FIELDS = [  # what summarise averages over seeds
    "wall_seconds",
    "moves_per_second",
    "cost_supply",
    "cost_vascular",
    "cavity_share",
    "n_orders",
    *(f"{q}_error_{a}" for q in ("diameter", "length") for a in ARTERIES),
]


def seed_groups(rows: list[dict], keys: tuple[str, ...]) -> list[tuple[tuple, list[dict]]]:
    """The rows grouped by their values of ``keys`` (the runs of one configuration over seeds),
    in sorted order of those values."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in keys), []).append(r)
    return sorted(groups.items())


def seed_stats(group: list[dict], names) -> dict:
    """Mean over a group's runs of each name, and its standard error as name + "_se" (NaN for one run)."""
    entry = {}
    for name in names:
        v = np.array([r[name] for r in group], dtype=float)
        entry[name] = float(v.mean())
        entry[name + "_se"] = float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")
    return entry


def summarise(rows: list[dict]) -> list[dict]:
    """Mean and standard error over seeds per (N, schedule, budget)."""
    keys = ("n_terminals", "anneal", "budget")
    return [
        {**dict(zip(keys, key)), "steps": sel[0]["steps"], "seeds": len(sel), **seed_stats(sel, SUMMARY_FIELDS)}
        for key, sel in seed_groups(rows, keys)
    ]


def print_table(table: list[dict]) -> None:
    print(
        "\nmean ± SE over seeds (C_s voxels; vascular = C_v + C_w + A_o/A_wv C_o [W]; diameter error = "
        "mean |log10 model/Kassab| RCA/LAD/LCX)"
    )
    print(
        f"{'N':>5} {'anneal':>8} {'x':>4} {'moves':>8} {'seeds':>5} {'wall s':>13} {'moves/s':>8} "
        f"{'C_s':>20} {'vascular W':>19} {'cavity':>7} {'diameter error':>16} {'orders':>6}"
    )
    for t in table:
        diam = "/".join(f"{t[f'diameter_error_{a}']:.3f}" for a in ARTERIES)
        print(
            f"{t['n_terminals']:>5} {t['anneal']:>8} {t['budget']:>4g} {t['steps']:>8.2g} {t['seeds']:>5} "
            f"{t['wall_seconds']:>7.0f} ±{t['wall_seconds_se']:<5.0f}{t['moves_per_second']:>8.3g} "
            f"{t['cost_supply']:>10.0f} ±{t['cost_supply_se']:<8.0f}{t['cost_vascular']:>9.4g} "
            f"±{t['cost_vascular_se']:<8.2g}{t['cavity_share']:>7.4f} {diam:>16} {t['n_orders']:>6.1f}"
        )


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", help=f"N values (default {DEFAULT_SIZES})")
    parser.add_argument("--large", action="store_true", help=f"add N = {LARGE_SIZES}")
    parser.add_argument(
        "--anneal", nargs="+", default=["fast_v1", "fast"], help="anneal presets (default: fast_v1 fast)"
    )
    parser.add_argument(
        "--budgets",
        type=float,
        nargs="+",
        default=[1.0],
        help="budgets in multiples of each schedule's default moves (default: 1)",
    )
    parser.add_argument("--steps", type=int, help="exact moves per run instead of --budgets")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="seeds (default: 0)")
    parser.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count(),
        help="runs side by side (one core each); with --parts, the threads that run one tree's parts",
    )
    parser.add_argument(
        "--parts", type=int, default=1, help="anneal.parts: one tree in this many parts (default 1: serial)"
    )
    parser.add_argument("--out", type=Path, help="directory of the run stores and rows.jsonl")
    parser.add_argument("--override", action="append", default=[], help="extra config override, e.g. m_b=6413")
    parser.add_argument(
        "--label",
        help="name of this variant (default: the anneal preset); runs of a label share "
        "one output directory, so a variant with --override needs its own label",
    )
    parser.add_argument("--quick", action="store_true", help="tiny runs (N = 40, 20000 moves) in a temporary dir")
    args = parser.parse_args(argv)
    if args.label and len(args.anneal) > 1:
        parser.error("--label names one variant: give one --anneal preset with it")
    if args.parts > 1:  # one tree at a time, its parts on the workers
        args.override = [*args.override, f"anneal.parts={args.parts}"]
        if args.label is None and len(args.anneal) == 1:
            args.label = f"{args.anneal[0]}-parts{args.parts}-w{args.workers}"  # one store per worker count
        elif args.label is None:
            parser.error("--parts with several --anneal presets needs runs of one preset (or a --label)")
    sizes = args.sizes or DEFAULT_SIZES
    if args.large:
        sizes = sorted(set(sizes) | set(LARGE_SIZES))
    steps = args.steps
    if args.quick:
        sizes, steps, args.budgets = [40], 20_000, [1.0]
        args.override = [*args.override, "anneal.trace_every=10000"]
    tmp = tempfile.TemporaryDirectory() if args.out is None else None
    out = args.out if args.out is not None else Path(tmp.name)
    out.mkdir(parents=True, exist_ok=True)
    rows_file = out / "rows.jsonl"
    done = {}
    if rows_file.exists():
        done = {r["store"]: r for r in map(json.loads, rows_file.read_text().splitlines())}
    wanted = []  # (job, schedule, budget)
    for schedule in args.anneal:
        for budget in [1.0] if steps else args.budgets:
            for n in sizes:
                label = args.label or schedule
                wanted += [
                    (j, label, budget)
                    for j in jobs_for(out, schedule, budget, n, args.seeds, steps, args.override, args.label)
                ]
    todo = [w for w in wanted if w[0].store not in done]
    # longest first: the pool finishes together (a CCO run's config has no anneal section: N additions)
    todo.sort(key=lambda w: -w[0].config.get("anneal", {}).get("steps", w[0].coords["n_terminals"]))
    by_store = {w[0].store: w for w in todo}
    if args.parts > 1:
        finished = (run_in_parts(w[0], args.workers) for w in todo)
    else:
        pool = ProcessPoolExecutor(args.workers)
        finished = pool.map(run_one, [w[0] for w in todo])
    try:
        for store in finished:
            _, schedule, budget = by_store[store]
            row = row_of(store, schedule, budget)
            row["parts"], row["workers"] = args.parts, args.workers if args.parts > 1 else 1
            done[store] = row
            print(json.dumps(row), flush=True)
            with rows_file.open("a") as f:
                f.write(json.dumps(row) + "\n")
    finally:
        if args.parts == 1:
            pool.shutdown()
    rows = [done[w[0].store] for w in wanted]
    table = summarise(rows)
    print_table(table)
    if tmp is not None:
        tmp.cleanup()
    return table


if __name__ == "__main__":
    main()
