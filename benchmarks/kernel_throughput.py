"""Proposed moves per second of the annealing kernel on one core (issue 2 benchmark).

For the heart at N = 500, 1000, 2000, 6000 with every cost term of the paper on (volume,
power, supply, exclusion; pressure has weight 0 as in the paper), the kernel runs blocks
of moves at three temperatures of the paper's schedule (start, middle, end) from a state
that has been annealed to that point, and prints one JSON line per N:

    n_terminals, moves_per_second (over the schedule phases, weighted by steps), per-phase rates,
    the paper's step budget for N and its extrapolated wall time on one core.

Usage: python benchmarks/kernel_throughput.py [--sizes 500 1000] [--moves 400000] [--anneal fast]
       python benchmarks/kernel_throughput.py --quick    # N = 20, a few thousand moves (seconds)
"""

from __future__ import annotations

import argparse
import json
import time

from vasc_pipeline import config, engine, kernel


def measure(n_terminals: int, moves: int, warmup: int, anneal: str = "paper") -> dict:
    cfg = config.compose(["tissue=heart", f"n_terminals={n_terminals}", f"anneal={anneal}"])
    problem = engine.build_problem(cfg)
    total = problem.total_steps  # the schedule's budget: paper 1e9 (N/1000)^2, fast 1e8 (N/1000)^2
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, state, 1000)  # compile outside the timing
    rates = {}
    # Phases of the schedule: the kernel is placed at a fraction of the paper's budget by
    # setting its step counter (the temperature follows the step), then warmed up there.
    for phase, frac in (("start", 0.0), ("middle", 0.5), ("end", 1.0)):
        state.counters[kernel.COUNTER_STEP] = int(frac * total)
        engine.run_block(problem, state, warmup)
        t = time.perf_counter()
        engine.run_block(problem, state, moves)
        rates[phase] = moves / (time.perf_counter() - t)
    # Harmonic mean: the schedule spends equal step counts in each phase, so time adds up.
    mean_rate = len(rates) / sum(1.0 / r for r in rates.values())
    return {
        "anneal": anneal,
        "n_terminals": n_terminals,
        "moves_per_second": round(mean_rate),
        "moves_per_second_by_phase": {k: round(v) for k, v in rates.items()},
        "schedule_steps": total,
        "schedule_hours_extrapolated": round(total / mean_rate / 3600, 2),
        "grid_voxels": int(problem.tissue.mask.size),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 1000, 2000, 6000])
    parser.add_argument("--moves", type=int, default=400_000)
    parser.add_argument("--warmup", type=int, default=2_000_000)
    parser.add_argument("--anneal", choices=["paper", "fast"], default="paper", help="schedule (default: paper)")
    parser.add_argument("--quick", action="store_true", help="N = 20, 2000 moves per phase: checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.moves, args.warmup = [20], 2000, 2000
    for n in args.sizes:
        print(json.dumps(measure(n, args.moves, args.warmup, args.anneal)), flush=True)


if __name__ == "__main__":
    main()
