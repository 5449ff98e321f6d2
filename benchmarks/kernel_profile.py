"""Where the kernel's time goes: nanoseconds per proposed move by move class and cost term.

For the heart at one N (default 1000), from a random initial tree placed at three points
of the paper's schedule (start, middle, end: the temperature follows the step counter),
runs blocks of moves with the model restricted to one move class, or with one cost term
switched off (timing only: the running sums of such runs are meaningless), and prints
one JSON line per phase:

    ns_per_move: all moves; swap; translate (terminal + bifurcation); bifurcation
    translate; terminal translate (derived); translate without supply; translate
    without exclusion; plus the acceptance of each class.

Usage: python benchmarks/kernel_profile.py [--n-terminals 1000] [--moves 200000]
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
    for name, proposed in (("terminal", kernel.COUNTER_TERMINAL_PROPOSED),
                           ("bifurcation", kernel.COUNTER_BIFURCATION_PROPOSED),
                           ("swap", kernel.COUNTER_SWAP_PROPOSED)):
        if c[proposed]:
            acceptance[name] = round(float(c[proposed + 1] / c[proposed]), 3)
    return elapsed / moves * 1e9, acceptance


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-terminals", type=int, default=1000)
    parser.add_argument("--moves", type=int, default=200_000)
    parser.add_argument("--warmup", type=int, default=20_000)
    args = parser.parse_args()
    problem = engine.build_problem(config.compose(["tissue=heart", f"n_terminals={args.n_terminals}", "anneal=paper"]))
    base = engine.initial_state(problem, seed=0)
    engine.run_block(problem, base, 1000)  # compile outside the timing
    m = problem.model
    variants = {
        "all": m,
        "swap": m._replace(p_swap=1.0),
        "translate": m._replace(p_swap=0.0),
        "bifurcation_translate": m._replace(p_swap=0.0, move_terminals=False),
        "translate_without_supply": m._replace(p_swap=0.0, supply_on=False),
        "translate_without_exclusion": m._replace(p_swap=0.0, exclusion_on=False),
    }
    for phase, frac in (("start", 0.0), ("middle", 0.5), ("end", 1.0)):
        ns, acc = {}, {}
        for name, model in variants.items():
            ns[name], acc[name] = ns_per_move(problem, base, model, frac, args.moves, args.warmup)
        # Translations pick terminals and bifurcations equally often.
        ns["terminal_translate"] = 2 * ns["translate"] - ns["bifurcation_translate"]
        print(json.dumps({"n_terminals": args.n_terminals, "phase": phase,
                          "temperature": kernel.temperature(m, int(frac * m.total_steps)),
                          "ns_per_move": {k: round(v) for k, v in ns.items()},
                          "acceptance_all_moves": acc["all"]}), flush=True)


if __name__ == "__main__":
    main()
