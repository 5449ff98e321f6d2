"""Supply cost reached by the packing phase alone, against moves per terminal and N.

For organ-scale runs (N in the thousands): how many packing moves per terminal the heart's supply
term needs as N grows (the budget law). For each N, moves per terminal k and seed, the
packing phase (:mod:`vasc_pipeline.kernel.packing`) runs k N proposals from the run's random
initial tree and one JSON line reports C_s at its end and the CPU seconds it took.

    python benchmarks/packing_law.py                                # N = 500, 1000, 2000
    python benchmarks/packing_law.py --sizes 6000 --per-terminal 3000 10000 --seeds 0 1
    python benchmarks/packing_law.py --quick                        # seconds: wiring only

Measured 2026-11-23 (seed 0, one core, CPU seconds in ``benchmarks/results/packing_supply_vs_moves.jsonl``).
"""

from __future__ import annotations

import argparse
import json
import time


def measure(n: int, per_terminal: float, seed: int) -> dict:
    from vasc_pipeline import config, engine

    steps = int(round(per_terminal * n))
    problem = engine.build_problem(
        config.compose(
            [f"n_terminals={n}", f"anneal.packing_steps_per_terminal={per_terminal}", f"anneal.steps={steps + 1}"]
        )
    )
    state = engine.initial_state(problem, seed)
    start = time.process_time()
    engine.run_block(problem, state, steps)
    return {
        "n": n,
        "per_terminal": per_terminal,
        "seed": seed,
        "C_s": engine.running_costs(problem, state)["supply"],
        "cpu_s": time.process_time() - start,
        "tissue_voxels": problem.tissue.n_tissue_voxels,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 1000, 2000])
    parser.add_argument("--per-terminal", type=float, nargs="+", default=[3000, 10000, 30000, 100000])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--quick", action="store_true", help="N = 40, 100 moves per terminal: checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.per_terminal, args.seeds = [40], [100], [0]
    for n in args.sizes:
        for k in args.per_terminal:
            for seed in args.seeds:
                print(json.dumps(measure(n, k, seed)), flush=True)


if __name__ == "__main__":
    main()
