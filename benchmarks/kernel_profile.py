"""Where the kernel's time goes: nanoseconds per proposed move by move class and cost term.

For the heart at one N (default 1000), the schedule is run from the seed-0 initial tree with
``--run-budget`` (0.1) times its default budget, as ``kernel_throughput.py`` runs it, and
stopped at three points (start, middle, end: 5, 50 and 95 % of its moves; ``--phases`` sets
others), so the states are those a run visits. From each, blocks of moves are run with the
model restricted to one move class, or with one cost term switched off (timing only: the
running sums of such runs are meaningless), and one JSON line per phase is printed:

    ns_per_move: all moves; swap; swap without exclusion (the two paths' walks and the
    rest, without the new segments' traversals); translate (terminal + bifurcation);
    bifurcation translate; terminal translate (derived); translate without supply;
    translate without exclusion; plus the acceptance of each class.

    exclusion_cost_over_temperature: quantiles (25, 50, 75, 90 %) over the tree's segments of
    a segment's weighted exclusion cost divided by the temperature. Where it is a sizeable
    fraction of T, a move's acceptance depends on its new segments' exact traversal sums, so
    no cheap upper bound of them could accept the move without traversing.

Times are the measuring thread's CPU time, as in ``kernel_throughput.py``.

Usage: python benchmarks/kernel_profile.py [--n-terminals 1000] [--moves 200000] [--anneal fast] [--run-budget 0.1]
                                          [--phases 0.05 0.5 0.95]
       python benchmarks/kernel_profile.py --quick    # tiny sizes, seconds (run by the tests)
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from kernel_throughput import ANNEAL_PRESETS, trajectory_problem

from vasc_pipeline import engine, kernel
from vasc_pipeline.model.physics import TABLE_EXCLUSION

PHASES = {0.05: "start", 0.5: "middle", 0.95: "end"}  # share of the trajectory's moves: name


def ns_per_move(problem, arrays, model, moves: int) -> tuple[float, dict]:
    state = engine.restore_state(problem, arrays)
    before = state.counters.copy()
    start = time.thread_time()
    kernel.anneal_block(model, state, moves)
    elapsed = time.thread_time() - start
    c = state.counters - before
    acceptance = {}
    for name, proposed in (
        ("terminal", kernel.COUNTER_TERMINAL_PROPOSED),
        ("bifurcation", kernel.COUNTER_BIFURCATION_PROPOSED),
        ("swap", kernel.COUNTER_SWAP_PROPOSED),
    ):
        if c[proposed]:
            acceptance[name] = round(float(c[proposed + 1] / c[proposed]), 3)
    return elapsed / moves * 1e9, acceptance


def exclusion_over_temperature(model, state, temp: float) -> dict[str, float]:
    """Quantiles over the tree's segments of (weighted exclusion cost) / temperature."""
    segments = np.arange(model.n_inlets, state.parent.size)
    weights = model.w_exclusion * model.tables[TABLE_EXCLUSION, state.n_downstream[segments]]
    costs = weights * state.seg_exclusion[segments]
    return {f"q{q}": float(np.quantile(costs / temp, q / 100)) for q in (25, 50, 75, 90)}


def profile(n_terminals: int, moves: int, anneal: str, run_budget: float, phases=tuple(PHASES)) -> list[dict]:
    base = ["tissue=heart", f"n_terminals={n_terminals}", f"anneal={anneal}"]
    problem, run_steps, _ = trajectory_problem(base, run_budget)
    state = engine.initial_state(problem, seed=0)
    engine.run_block(problem, engine.restore_state(problem, engine.state_arrays(state)), 1000)  # compile
    rows = []
    done = 0
    for frac in sorted(phases):
        step = int(frac * run_steps)
        engine.run_block(problem, state, step - done)
        done = step
        arrays = engine.state_arrays(state)
        m = engine.model_at(problem, step)  # the coarse exclusion map's early in a `fast` run
        variants = {
            "all": m,
            "swap": m._replace(p_swap=1.0),
            "swap_without_exclusion": m._replace(p_swap=1.0, exclusion_on=False),
            "translate": m._replace(p_swap=0.0),
            "bifurcation_translate": m._replace(p_swap=0.0, move_terminals=False),
            "translate_without_supply": m._replace(p_swap=0.0, supply_on=False),
            "translate_without_exclusion": m._replace(p_swap=0.0, exclusion_on=False),
        }
        ns, acc = {}, {}
        for name, model in variants.items():
            ns[name], acc[name] = ns_per_move(problem, arrays, model, moves)
        # Translations pick terminals and bifurcations equally often.
        ns["terminal_translate"] = 2 * ns["translate"] - ns["bifurcation_translate"]
        temp = kernel.temperature(m, state, step)
        rows.append(
            {
                "n_terminals": n_terminals,
                "anneal": anneal,
                "phase": PHASES.get(frac, f"{frac:g}"),
                "run_steps": run_steps,
                "step": step,
                "temperature": temp,
                "ns_per_move": {k: round(v) for k, v in ns.items()},
                "acceptance_all_moves": acc["all"],
                "exclusion_cost_over_temperature": exclusion_over_temperature(m, state, temp),
            }
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-terminals", type=int, default=1000)
    parser.add_argument("--moves", type=int, default=200_000)
    parser.add_argument("--anneal", choices=ANNEAL_PRESETS, default="fast", help="schedule preset (default: fast)")
    parser.add_argument(
        "--run-budget", type=float, default=0.1, help="the trajectory's budget, times the schedule's default (0.1)"
    )
    parser.add_argument(
        "--phases", type=float, nargs="+", default=list(PHASES), help="shares of the trajectory's moves to profile at"
    )
    parser.add_argument("--quick", action="store_true", help="tiny sizes (N = 20, 2000 moves): checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.n_terminals, args.moves, args.run_budget = 20, 2000, 1e-3
    if not all(0.0 <= f < 1.0 for f in args.phases):
        parser.error(f"--phases must lie in [0, 1), got {args.phases}")
    for row in profile(args.n_terminals, args.moves, args.anneal, args.run_budget, args.phases):
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
