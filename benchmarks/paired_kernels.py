"""An exact kernel shortcut measured against the kernel without it, chunk by chunk along one run.

A shortcut that changes no decision (``Model.supply_shell_width``, ``Model.early_reject``,
``Model.prefetch_lead``, ``Model.prefetch_supply``) is best measured inside one process, where
both kernels see the same machine state: the trajectory of ``kernel_throughput.py`` (the heart,
seed-0 initial tree, ``--run-budget`` of the schedule's default moves) is cut into ``--chunks`` pieces, and
each piece is run from the same state by the kernel as built and by the one with the
``--variant`` fields of its ``Model`` changed, alternating which goes first, each restored
just before it runs from the checkpoint arrays of the state the pieces before reached (as a
resume would: scratch arrays, such as supply shells, start empty). The two states must then
be equal (checked after every piece, else the script fails). Times are thread times, summed
over each third of the run. A variant equal to the built kernel measures the method's own
spread: within 3 % per third at N = 1000 (4-6 % when the two states were allocated in a
fixed order, a memory-layout bias; benchmarks/README.md, "Supply shells"). One JSON line per N:

    moves_per_second: {"built": ..., "variant": ...} over the run; ..._by_third: the same per third;
    speedup: built over variant, over the run and per third; median_chunk_speedup.

Usage: python benchmarks/paired_kernels.py --variant supply_shell_width=0 [--sizes 1000] [--anneal fast]
                                           [--run-budget 0.1] [--chunks 60]
       python benchmarks/paired_kernels.py --quick    # tiny sizes, seconds (run by the tests)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np
from kernel_throughput import ANNEAL_PRESETS, trajectory_problem

from vasc_pipeline import engine


def variant_problem(problem, fields: dict):
    """``problem`` with ``fields`` of its kernel Model (and of its coarse model, if any) replaced."""
    coarse = problem.coarse_model._replace(**fields) if problem.coarse_model is not None else None
    return dataclasses.replace(problem, model=problem.model._replace(**fields), coarse_model=coarse)


def parse_variant(model, items: list[str]) -> dict:
    """NAME=VALUE pairs, each VALUE of the type of the Model field it replaces."""
    fields = {}
    for item in items:
        name, _, text = item.partition("=")
        if name not in model._fields or not text:
            raise SystemExit(f"--variant {item!r}: expected NAME=VALUE with NAME a field of kernel.Model")
        old = getattr(model, name)
        if isinstance(old, (bool, np.bool_)):
            if text.lower() not in ("true", "false", "1", "0"):
                raise SystemExit(f"--variant {item!r}: {name} takes true or false")
            fields[name] = text.lower() in ("true", "1")
        elif isinstance(old, (int, float, np.number)):
            fields[name] = type(old)(float(text))
        else:
            raise SystemExit(f"--variant {item!r}: {name} is not a number or a flag")
    return fields


def paired(n_terminals: int, anneal: str, run_budget: float, chunks: int, variant: list[str]) -> dict:
    base = ["tissue=heart", f"n_terminals={n_terminals}", f"anneal={anneal}"]
    built, run_steps, _ = trajectory_problem(base, run_budget)
    other = variant_problem(built, parse_variant(built.model, variant))
    state = engine.initial_state(built, seed=0)
    for p in (built, other):  # compile outside the timing
        engine.run_block(p, engine.restore_state(p, engine.state_arrays(state)), 1000)
    bounds = np.linspace(0, run_steps, chunks + 1).round().astype(int)
    seconds = np.zeros((2, chunks))
    for c, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        arrays = engine.state_arrays(state)
        states = [None, None]
        for which in (0, 1) if c % 2 == 0 else (1, 0):
            states[which] = engine.restore_state(built if which == 0 else other, arrays)
            t = time.thread_time()
            engine.run_block(built if which == 0 else other, states[which], hi - lo)
            seconds[which, c] = time.thread_time() - t
        state = states[0]
        for name, value in engine.state_arrays(states[1]).items():
            if not np.array_equal(value, getattr(state, name)):
                raise SystemExit(f"N = {n_terminals}: the variant's {name} differs after moves {lo}-{hi}")
    thirds = np.array_split(np.arange(chunks), 3)
    moves = np.diff(bounds)

    def rates(which, part):
        return float(moves[part].sum() / seconds[which, part].sum())

    every = np.arange(chunks)
    return {
        "n_terminals": n_terminals,
        "anneal": anneal,
        "variant": variant,
        "run_budget": run_budget,
        "run_steps": run_steps,
        "moves_per_second": {"built": round(rates(0, every)), "variant": round(rates(1, every))},
        "moves_per_second_by_third": {
            "built": [round(rates(0, t)) for t in thirds],
            "variant": [round(rates(1, t)) for t in thirds],
        },
        "speedup": round(rates(0, every) / rates(1, every), 3),
        "speedup_by_third": [round(rates(0, t) / rates(1, t), 3) for t in thirds],
        "median_chunk_speedup": round(float(np.median(seconds[1] / seconds[0])), 3),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", nargs="+", default=["supply_shell_width=0"], help="Model fields: NAME=VALUE")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000])
    parser.add_argument("--anneal", choices=ANNEAL_PRESETS, default="fast")
    parser.add_argument(
        "--run-budget", type=float, default=0.1, help="the trajectory's budget, times the default (0.1)"
    )
    parser.add_argument("--chunks", type=int, default=60)
    parser.add_argument("--quick", action="store_true", help="N = 20, a tiny trajectory: checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.run_budget, args.chunks = [20], 1e-3, 6
    for n in args.sizes:
        print(json.dumps(paired(n, args.anneal, args.run_budget, args.chunks, args.variant)), flush=True)


if __name__ == "__main__":
    main()
