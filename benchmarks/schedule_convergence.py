"""Final cost against proposed moves: ``anneal=fast`` against the paper's schedule.

Runs every (schedule, moves, seed) of a case with :func:`vasc_pipeline.engine.run` in a
process pool, prints one JSON line per run (appended to ``--out``/runs.jsonl, and runs
already there are not run again: an interrupted benchmark resumes), then a table of mean ±
standard error per (schedule, moves), and writes ``table.csv`` and ``convergence.png``.
Schedules: ``paper`` (the literal T 1e10 -> 1e-5), ``paper_cold`` (the same shape ended at
T = 1e-9 W) and ``fast``. On two cores plane2d takes about 15 minutes, the heart about two
and a half hours (the paper's schedule at 1e9 moves is 50 minutes a run).

The annealed total C is A_s/A_wv C_s + (C_v + C_w) + A_o/A_wv C_o with A_s/A_wv = 1e26, so
it orders trees by supply first; the table shows the total and its two parts: the supply
cost C_s (voxel units) and the rest, C_v + C_w + A_o/A_wv C_o [W].

    python benchmarks/schedule_convergence.py --case plane2d --out results/bench_plane2d
    python benchmarks/schedule_convergence.py --case heart --out results/bench_heart
    python benchmarks/schedule_convergence.py --case heart --out results/bench_heart --schedules fast
    python benchmarks/schedule_convergence.py --quick    # plane2d, 2 seeds, 2000 and 5000 moves (seconds)
"""

from __future__ import annotations

import argparse
import json
import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

CASES = {
    # The paper's 2-D convergence test (tissue=plane2d sets 64 terminals, gamma 3, 2.4 mm root).
    "plane2d": {
        "overrides": ["tissue=plane2d"],
        "seeds": 8,
        "steps": {
            "paper": [1_000_000, 10_000_000, 100_000_000],
            "paper_cold": [1_000_000, 10_000_000],
            "fast": [10_000, 100_000, 1_000_000, 10_000_000],
        },
    },
    "heart": {
        "overrides": ["tissue=heart", "n_terminals=1000"],
        "seeds": 4,
        "steps": {
            "paper": [3_000_000, 10_000_000, 100_000_000, 1_000_000_000],
            "paper_cold": [3_000_000, 10_000_000, 100_000_000],
            "fast": [100_000, 300_000, 1_000_000, 3_000_000, 10_000_000],
        },
    },
}
SCHEDULES = {"paper": ["anneal=paper"], "paper_cold": ["anneal=paper", "anneal.T_end=1e-9"], "fast": ["anneal=fast"]}


def one_run(args: tuple[str, list[str], str, int, int]) -> dict:
    from vasc_pipeline import config, engine
    from vasc_pipeline.model.costs import vascular_cost, vascular_exclusion_cost

    case, overrides, schedule, steps, seed = args
    cfg = config.compose([*overrides, *SCHEDULES[schedule], f"anneal.steps={steps}", "anneal.trace_every=1000000"])
    result = engine.run(cfg, seed=seed)
    c = result.costs_recomputed
    w_o = result.problem.physics.weights[0]
    return {
        "case": case,
        "schedule": schedule,
        "steps": steps,
        "seed": seed,
        "total": c["total"],
        "supply": c["supply"],
        "vascular_exclusion": vascular_exclusion_cost(c, w_o),
        "vascular": vascular_cost(c),
        "wall_seconds": result.wall_seconds,
    }


def summarise(rows: list[dict]) -> list[dict]:
    table = []
    keys = sorted({(r["schedule"], r["steps"]) for r in rows}, key=lambda k: (list(SCHEDULES).index(k[0]), k[1]))
    for schedule, steps in keys:
        sel = [r for r in rows if r["schedule"] == schedule and r["steps"] == steps]
        entry = {"schedule": schedule, "steps": steps, "seeds": len(sel)}
        for name in ("total", "supply", "vascular_exclusion", "vascular", "wall_seconds"):
            v = np.array([r[name] for r in sel])
            entry[name] = float(v.mean())
            entry[name + "_se"] = float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else 0.0
        table.append(entry)
    return table


def figure(table: list[dict], case: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = {"paper": "paper (T 1e10 → 1e-5)", "paper_cold": "paper shape, T_end = 1e-9 W", "fast": "fast"}
    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.8), constrained_layout=True)
    for schedule, style in zip(SCHEDULES, ("s--", "o--", "D-")):
        sel = [t for t in table if t["schedule"] == schedule]
        if not sel:
            continue
        x = [t["steps"] for t in sel]
        for ax, name in zip(axes, ("supply", "vascular_exclusion")):
            ax.errorbar(
                x,
                [t[name] for t in sel],
                yerr=[t[name + "_se"] for t in sel],
                fmt=style,
                capsize=3,
                label=labels[schedule],
            )
    axes[0].set_ylabel("supply cost $C_s$ [voxel units]")
    axes[1].set_ylabel(r"$C_v + C_w + (A_o/A_{wv})\,C_o$ [W]")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("proposed moves per run")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{case}: mean final cost ± standard error over seeds")
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", choices=sorted(CASES), default="plane2d")
    parser.add_argument("--seeds", type=int, help="seeds per point (default: 8 for plane2d, 4 for heart)")
    parser.add_argument(
        "--schedules",
        nargs="+",
        choices=sorted(SCHEDULES),
        default=list(SCHEDULES),
        help="run only these schedules (the table holds every run in --out)",
    )
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--out", type=Path, help="directory for runs.jsonl, table.csv, convergence.png")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="2 seeds at 2000 and 5000 moves per schedule (seconds): checks the script runs",
    )
    args = parser.parse_args(argv)
    case = CASES[args.case]
    if args.quick:
        case = {**case, "seeds": 2, "steps": {schedule: [2_000, 5_000] for schedule in SCHEDULES}}
    seeds = range(args.seeds or case["seeds"])
    tasks = [
        (args.case, case["overrides"], schedule, steps, seed)
        for schedule, all_steps in case["steps"].items()
        if schedule in args.schedules
        for steps in all_steps
        for seed in seeds
    ]
    rows, done = [], set()
    runs_file = args.out / "runs.jsonl" if args.out else None
    if runs_file is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        if runs_file.exists():
            # One row per run: a run recorded twice (two invocations racing) must not shrink the SE.
            unique = {
                (r["schedule"], r["steps"], r["seed"]): r
                for r in map(json.loads, runs_file.read_text().splitlines())
                if r["seed"] in seeds
            }
            rows, done = list(unique.values()), set(unique)
    tasks = [t for t in tasks if (t[2], t[3], t[4]) not in done]
    tasks.sort(key=lambda t: -t[3])  # longest first: the pool finishes together
    with ProcessPoolExecutor(args.workers) as pool:
        for row in pool.map(one_run, tasks):
            rows.append(row)
            print(json.dumps(row), flush=True)
            if runs_file is not None:
                with runs_file.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    table = summarise(rows)
    print(
        f"\n{args.case}: mean ± SE over the seeds run (total = annealed C [W]; supply = C_s; "
        "rest = C_v + C_w + A_o/A_wv C_o [W])"
    )
    print(f"{'schedule':>11} {'moves':>11} {'total':>20} {'supply':>16} {'rest [W]':>22} {'wall s':>7} {'seeds':>5}")
    for t in table:
        print(
            f"{t['schedule']:>11} {t['steps']:>11.3g} {t['total']:>11.5g} ±{t['total_se']:<8.2g}"
            f"{t['supply']:>8.1f} ±{t['supply_se']:<6.1f}{t['vascular_exclusion']:>12.6g} ±"
            f"{t['vascular_exclusion_se']:<8.2g}{t['wall_seconds']:>7.1f} {t['seeds']:>5}"
        )
    if args.out:
        import pandas as pd

        pd.DataFrame(table).to_csv(args.out / "table.csv", index=False)
        figure(table, args.case, args.out / "convergence.png")
        print(f"written: {runs_file}, {args.out}/table.csv, {args.out}/convergence.png")


if __name__ == "__main__":
    main()
