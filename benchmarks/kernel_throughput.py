"""Proposed moves per second of the annealing kernel on one core.

For the heart at N = 500, 1000, 2000, 6000 with every cost term of the paper on (volume,
power, supply, exclusion; pressure has weight 0 as in the paper), one JSON line per N with
two measurements:

- ``moves_per_second`` (the headline): the rate along a real trajectory. The schedule is run
  from the seed-0 initial tree to its end with a budget of ``--run-budget`` (0.1) times its
  default, timing the kernel only (not building the problem, not the polish); the
  temperatures are the full schedule's, so the states are those a run visits, only annealed
  less at each temperature. ``moves_per_second_by_third`` splits it over the schedule.
- ``moves_per_second_phases``: the older measurement, at three points of the schedule
  (start, middle, end) reached by setting the step counter on the initial tree and warming
  up there (``--warmup`` moves, then ``--moves`` timed; harmonic mean). Those states are
  barely annealed trees at low temperature, whose long segments cross deep tissue: no run
  visits them, and they are 1.5-3x slower than a run's.

Times are the measuring thread's CPU time (the kernel runs in it, releasing the GIL), so
other processes on the machine take their time slices without inflating the figures; they
still share caches and memory bandwidth, so measure on a quiet machine when you can.

Usage: python benchmarks/kernel_throughput.py [--sizes 500 1000] [--anneal fast|fast_v1|paper] [--run-budget 0.1]
           [--override anneal.coarse_exclusion_factor=2 --override anneal.coarse_exclusion_phase=0.5]
       python benchmarks/kernel_throughput.py --quick    # N = 20, a few thousand moves (seconds)
"""

from __future__ import annotations

import argparse
import json
import time

from vasc_pipeline import config, engine, kernel

# Every schedule preset in conf/anneal/ (fast_v1 too), for --anneal here and in kernel_profile.py.
ANNEAL_PRESETS = sorted(p.stem for p in (config.CONFIG_DIR / "anneal").glob("*.yaml"))


def trajectory_problem(base: list[str], run_budget: float):
    """The problem of ``base`` with ``run_budget`` times its schedule's default moves (at least 3),
    the same temperatures spread over fewer moves; returns (that problem, its moves, ``base``'s
    own problem)."""
    problem = engine.build_problem(config.compose(base))
    run_steps = max(3, round(run_budget * problem.total_steps))
    return engine.build_problem(config.compose([*base, f"anneal.steps={run_steps}"])), run_steps, problem


def trajectory_rates(problem, total_steps: int, pieces: int = 3) -> list[float]:
    """Moves per second over ``pieces`` equal parts of a run of ``total_steps`` (kernel time only)."""
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, engine.restore_state(problem, engine.state_arrays(state)), 1000)  # compile
    bounds = [round(total_steps * k / pieces) for k in range(pieces + 1)]
    rates = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        t = time.thread_time()
        engine.run_block(problem, state, hi - lo)
        rates.append((hi - lo) / (time.thread_time() - t))
    return rates


def phase_rates(problem, moves: int, warmup: int) -> dict[str, float]:
    """Moves per second at the start, middle and end of the schedule, reached by setting the step counter."""
    total = problem.total_steps
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, state, 1000)  # compile outside the timing
    rates = {}
    for phase, frac in (("start", 0.0), ("middle", 0.5), ("end", 1.0)):
        state.counters[kernel.COUNTER_STEP] = int(frac * total)
        # Segment sums on the map in force there (a jump can cross the coarse map's switch).
        kernel.recompute_exclusion(engine.model_at(problem, int(frac * total)), state)
        engine.run_block(problem, state, warmup)
        t = time.thread_time()
        engine.run_block(problem, state, moves)
        rates[phase] = moves / (time.thread_time() - t)
    return rates


def coarse_exclusion_ratio(problem) -> float | None:
    """With ``anneal.coarse_exclusion_*`` set: the exclusion cost of the seed-0 initial tree on
    the coarse map over its true one (how well the coarse map stands in for it); else None."""
    if problem.coarse_model is None:
        return None
    state = engine.initial_state(problem, seed=0)  # its running sums on the coarse map
    coarse = state.costs[kernel.EXCLUSION] + state.compensation[kernel.EXCLUSION]
    kernel.recompute_exclusion(problem.model, state)
    return float(coarse / (state.costs[kernel.EXCLUSION] + state.compensation[kernel.EXCLUSION]))


def harmonic_mean(rates) -> float:
    """The rate over equal step counts at each of ``rates``: their times add up."""
    rates = list(rates)
    return len(rates) / sum(1.0 / r for r in rates)


def measure(
    n_terminals: int, moves: int, warmup: int, anneal: str = "paper", run_budget: float = 0.1, overrides=()
) -> dict:
    base = ["tissue=heart", f"n_terminals={n_terminals}", f"anneal={anneal}", *overrides]
    run_problem, run_steps, problem = trajectory_problem(base, run_budget)
    total = problem.total_steps  # the schedule's budget: paper 1e9 (N/1000)^2, fast 6.25e7 (N/1000)^1.7
    thirds = trajectory_rates(run_problem, run_steps)
    phases = phase_rates(problem, moves, warmup)
    rate = harmonic_mean(thirds)
    return {
        "anneal": anneal,
        "overrides": list(overrides),
        "n_terminals": n_terminals,
        "moves_per_second": round(rate),
        "run_budget": run_budget,
        "run_steps": run_steps,
        "moves_per_second_by_third": [round(r) for r in thirds],
        "moves_per_second_phases": round(harmonic_mean(phases.values())),
        "moves_per_second_by_phase": {k: round(v) for k, v in phases.items()},
        "schedule_steps": total,
        "schedule_hours_extrapolated": round(total / rate / 3600, 2),
        "grid_voxels": int(problem.tissue.mask.size),
        "coarse_exclusion_ratio": coarse_exclusion_ratio(problem),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 1000, 2000, 6000])
    parser.add_argument("--moves", type=int, default=400_000)
    parser.add_argument("--warmup", type=int, default=2_000_000)
    parser.add_argument("--anneal", choices=ANNEAL_PRESETS, default="paper", help="schedule preset (default: paper)")
    parser.add_argument(
        "--run-budget", type=float, default=0.1, help="the trajectory's budget, times the schedule's default (0.1)"
    )
    parser.add_argument("--override", action="append", default=[], help="extra config override, e.g. anneal.p_swap=0.5")
    parser.add_argument("--quick", action="store_true", help="N = 20, 2000 moves per phase: checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.moves, args.warmup, args.run_budget = [20], 2000, 2000, 1e-3
    for n in args.sizes:
        print(json.dumps(measure(n, args.moves, args.warmup, args.anneal, args.run_budget, args.override)), flush=True)


if __name__ == "__main__":
    main()
