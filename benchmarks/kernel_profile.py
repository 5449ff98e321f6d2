"""Where the kernel's time goes: nanoseconds per proposed move by move class and cost term.

For the heart at one N (default 1000), from the seed-0 initial tree placed at three points
of a schedule (start, middle, end: the temperature follows the step counter), runs blocks
of moves with the model restricted to one move class, or with one cost term switched off
(timing only: the running sums of such runs are meaningless), and prints one JSON line per
phase:

    ns_per_move: all moves; swap; translate (terminal + bifurcation); bifurcation
    translate; terminal translate (derived); translate without supply; translate
    without exclusion; plus the acceptance of each class.

Usage: python benchmarks/kernel_profile.py [--n-terminals 1000] [--moves 200000] [--anneal fast]
       python benchmarks/kernel_profile.py --quick    # tiny sizes, seconds (run by the tests)
"""

from __future__ import annotations

import argparse
import json
import time

from vasc_pipeline import config, engine, kernel


def ns_per_move(problem, base, model, frac: float, moves: int, warmup: int) -> tuple[float, dict]:
    state = engine.restore_state(problem, engine.state_arrays(base))
    state.counters[kernel.COUNTER_STEP] = int(frac * model.total_steps)
    kernel.anneal_block(model, state, warmup)
    before = state.counters.copy()
    start = time.perf_counter()
    kernel.anneal_block(model, state, moves)
    elapsed = time.perf_counter() - start
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


def profile(n_terminals: int, moves: int, warmup: int, anneal: str) -> list[dict]:
    problem = engine.build_problem(config.compose(["tissue=heart", f"n_terminals={n_terminals}", f"anneal={anneal}"]))
    base = engine.initial_state(problem, seed=0)
    engine.run_block(
        problem, engine.restore_state(problem, engine.state_arrays(base)), 1000
    )  # compile outside the timing
    m = problem.model
    variants = {
        "all": m,
        "swap": m._replace(p_swap=1.0),
        "translate": m._replace(p_swap=0.0),
        "bifurcation_translate": m._replace(p_swap=0.0, move_terminals=False),
        "translate_without_supply": m._replace(p_swap=0.0, supply_on=False),
        "translate_without_exclusion": m._replace(p_swap=0.0, exclusion_on=False),
    }
    rows = []
    for phase, frac in (("start", 0.0), ("middle", 0.5), ("end", 1.0)):
        ns, acc = {}, {}
        for name, model in variants.items():
            ns[name], acc[name] = ns_per_move(problem, base, model, frac, moves, warmup)
        # Translations pick terminals and bifurcations equally often.
        ns["terminal_translate"] = 2 * ns["translate"] - ns["bifurcation_translate"]
        rows.append(
            {
                "n_terminals": n_terminals,
                "anneal": anneal,
                "phase": phase,
                "temperature": kernel.temperature(m, base, int(frac * m.total_steps)),
                "ns_per_move": {k: round(v) for k, v in ns.items()},
                "acceptance_all_moves": acc["all"],
            }
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-terminals", type=int, default=1000)
    parser.add_argument("--moves", type=int, default=200_000)
    parser.add_argument("--warmup", type=int, default=20_000)
    parser.add_argument("--anneal", choices=["paper", "fast"], default="fast", help="schedule (default: fast)")
    parser.add_argument("--quick", action="store_true", help="tiny sizes (N = 20, 2000 moves): checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.n_terminals, args.moves, args.warmup = 20, 2000, 200
    for row in profile(args.n_terminals, args.moves, args.warmup, args.anneal):
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
