"""Warm starts against the plain anneal at equal moves, on the heart.

Each strategy spends the same number of proposals, ``--budget`` times the default of
``anneal=fast`` at N, and ends with the same polish:

- ``plain``: ``anneal=fast`` from the random initial tree (the reference), here and in every
  strategy on the true exclusion map throughout (``fast``'s coarse map early in a run, since
  2026-11-27, is left out, as when these strategies were measured);
- ``split`` (coarse to fine): ``anneal=fast`` on N/2 terminals with a share
  ``--coarse-share`` of the moves; every terminal then becomes a bifurcation whose two
  terminals lie ``--offset`` R_supply(N) to either side along a random direction (both in
  tissue), and the N-terminal tree is annealed with the remaining moves from a temperature
  calibrated on it (``anneal.accept_start``, ``--fine`` overrides);
- ``packed_cco``: the packing phase alone (supply only, terminal moves,
  ``--packing-per-terminal`` proposals each), the CCO tree grown on the packed sites
  (:func:`vasc_pipeline.engine.cco.grow_tree`), then the tree annealed with the remaining moves,
  the supply term at its true weight throughout (``anneal.supply_T_start=null``), so the
  terminals keep their packing while the tree is searched;
- ``late_exclusion``: ``anneal=fast`` with the exclusion term off (no traversals, the
  dearest part of a hot move) for the first ``--exclusion-off-share`` of the moves, then
  every segment's exclusion computed and the run continued on the true cost; one schedule,
  calibrated on the true cost. Each part is a Metropolis chain of its own cost.
- ``coarse_grid``: ``anneal=fast`` with the first ``--coarse-grid-share`` of the moves on
  the tissue voxelised ``--coarse-factor`` f times coarser (shorter traversals, fewer
  supply rows), with the exclusion weight times f^7 and the supply weight times f^3 so that
  the coarse costs approximate the true ones; then terminals are moved into the true
  tissue where the coarse one let them out, everything is rebuilt on the true grid and the
  run continues on the true cost. One schedule, calibrated on the true cost.
  (The exclusion term alone on a coarse map is a run option, ``anneal.coarse_exclusion_*``.)

One JSON line per (strategy, N, seed): C_s, the vascular cost C_v + C_w + (A_o/A_wv) C_o [W],
the wall seconds of each stage and the fine stage's calibrated T_start [W]. Results
measured with it: benchmarks/README.md, "What was tried for fewer moves", and
``benchmarks/results/warm_start_rows.jsonl``.

    python benchmarks/warm_starts.py --sizes 1000 --budget 0.5 --seeds 0 1
    python benchmarks/warm_starts.py --sizes 2000 --budget 0.25 --strategies packed_cco \\
        --packing-per-terminal 30000 --fine anneal.accept_start=0.5
    python benchmarks/warm_starts.py --sizes 1000 --budget 1 --seeds 0 1 2 3 \\
        --strategies plain late_exclusion --exclusion-off-share 0.2
    python benchmarks/warm_starts.py --quick                 # seconds: wiring only
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

STRATEGIES = ("plain", "split", "packed_cco", "late_exclusion", "coarse_grid")


def problem_of(n: int, steps: int, overrides: list[str]):
    from vasc_pipeline import config, engine

    # On the true exclusion map throughout, as the strategies were measured: `fast`'s own
    # coarse map early in a run is an early phase of its own, not stacked under theirs.
    true_map = ["anneal.coarse_exclusion_factor=null", "anneal.coarse_exclusion_phase=null"]
    overrides = ["anneal=fast", *true_map, f"n_terminals={n}", f"anneal.steps={steps}", *overrides]
    return engine.build_problem(config.compose(overrides))


def default_steps(n: int) -> int:
    from vasc_pipeline import config

    return config.scheduled_steps(config.compose(["anneal=fast", f"n_terminals={n}"]))


def anneal_to_end(problem, state) -> None:
    """The anneal from the state's step to ``problem.total_steps``, in blocks (no polish)."""
    from vasc_pipeline import engine

    for _ in engine.anneal_blocks(problem, state, engine.Trace(), 10_000_000):
        pass


def anneal_and_finish(problem, state) -> None:
    from vasc_pipeline import engine

    anneal_to_end(problem, state)
    engine.finish(problem, state)


def two_stage_row(start: float, middle: float, first_stage: str, problem, state, **handover) -> dict:
    """A two-stage strategy's result, now: the wall seconds in all and of the first stage
    (``wall_seconds_<first_stage>``), the calibrated T_start, the costs at the hand-over
    (``handover``) and the final costs."""
    return {
        "wall_seconds": time.perf_counter() - start,
        f"wall_seconds_{first_stage}": middle - start,
        "T_start": float(state.schedule[0]),
        **handover,
        **costs(problem, state),
    }


def costs(problem, state) -> dict[str, float]:
    from vasc_pipeline import engine
    from vasc_pipeline.model.costs import vascular_exclusion_cost

    c = engine.running_costs(problem, state)
    return {"C_s": c["supply"], "vascular_W": vascular_exclusion_cost(c, problem.physics.weights[0])}


def split_tree(coarse, problem, offset: float, seed: int):
    """The tree of ``problem`` (2M terminals) made from the M-terminal tree ``coarse``: coarse
    terminal j becomes a bifurcation at its position with terminals 2j and 2j + 1 at
    ±``offset`` R_supply along a random direction (the first of 100 draws that puts both in
    tissue; at the bifurcation if none does). Coarse bifurcations keep their positions (clipped
    into the finer grid's box)."""
    from vasc_pipeline import kernel
    from vasc_pipeline.model.tree import Tree, check_tree, children_from_parent, count_terminals

    k, m = coarse.n_inlets, coarse.n_terminals
    n = 2 * m
    draw = np.random.default_rng(seed)
    fine = np.empty(2 * m, dtype=np.int64)  # coarse node -> fine node
    fine[:k] = np.arange(k)
    fine[k + m :] = k + n + np.arange(m - k)  # coarse bifurcations first, ...
    fine[k : k + m] = k + n + (m - k) + np.arange(m)  # ... then the coarse terminals, now bifurcations
    parent = np.full(2 * n, -1, dtype=np.int64)
    position = np.zeros((2 * n, 3))
    position[:k] = problem.tissue.inlets
    parent[fine[k:]] = fine[coarse.parent[k:]]
    lo, hi = problem.tissue.bounds  # the finer grid's box can be a fraction of a voxel smaller
    position[fine[k:]] = np.clip(coarse.position[k:], lo, hi)
    d = offset * problem.physics.supply_radius
    # A coarse terminal on the border of the coarse grid may lie just outside the finer one:
    # into it, so that the fallback (both children at the centre) is a legal place too.
    centres = problem.tissue.move_into(problem.tissue.mask, coarse.position[k:])
    for j in range(m):
        centre = centres[j]
        pair = (centre, centre)
        for _ in range(100):
            u = draw.normal(size=3)
            if problem.tissue.ndim == 2:
                u[2] = 0.0
            u *= d / np.linalg.norm(u)
            if kernel.legal_position(problem.model, True, centre + u) and kernel.legal_position(
                problem.model, True, centre - u
            ):
                pair = (centre + u, centre - u)
                break
        for t, p in zip((k + 2 * j, k + 2 * j + 1), pair):
            parent[t] = fine[k + j]
            position[t] = p
    tree = Tree(parent, children_from_parent(parent), position, count_terminals(parent, n, k), k)
    check_tree(tree, problem.tissue)
    return tree


def run_plain(n, seed, total, args):
    from vasc_pipeline import engine

    start = time.perf_counter()
    problem = problem_of(n, total, [])
    state = engine.initial_state(problem, seed)
    anneal_and_finish(problem, state)
    return {"wall_seconds": time.perf_counter() - start, "T_start": float(state.schedule[0]), **costs(problem, state)}


def run_split(n, seed, total, args):
    from vasc_pipeline import engine
    from vasc_pipeline.model.rng import seed_state

    start = time.perf_counter()
    coarse_steps = int(round(args.coarse_share * total))
    coarse = problem_of(n // 2, coarse_steps, [])
    state = engine.initial_state(coarse, seed)
    anneal_and_finish(coarse, state)
    coarse_costs = costs(coarse, state)
    middle = time.perf_counter()
    problem = problem_of(n, total - coarse_steps, args.fine)
    tree = split_tree(engine.tree_of(coarse, state), problem, args.offset, seed)
    state = engine.state_from_tree(problem, tree, seed_state(seed + 1))
    split_costs = costs(problem, state)
    anneal_and_finish(problem, state)
    return two_stage_row(start, middle, "coarse", problem, state, coarse=coarse_costs, after_split=split_costs)


def run_packed_cco(n, seed, total, args):
    from vasc_pipeline import engine
    from vasc_pipeline.engine.cco import grow_tree
    from vasc_pipeline.model.rng import seed_state

    start = time.perf_counter()
    pack_steps = int(round(args.packing_per_terminal * n))
    packing_only = [f"anneal.packing_steps_per_terminal={args.packing_per_terminal}", "anneal.supply_T_start=null"]
    packing = problem_of(n, pack_steps + 1, packing_only)
    state = engine.initial_state(packing, seed)
    engine.run_block(packing, state, pack_steps)
    k = packing.model.n_inlets
    sites = state.position[k : k + n].copy()
    middle = time.perf_counter()
    problem = problem_of(n, total - pack_steps, ["anneal.supply_T_start=null", *args.fine])
    problem = dataclasses.replace(problem, sites=sites)
    rng = seed_state(seed + 1)
    state = engine.state_from_tree(problem, grow_tree(problem, rng)[0], rng)
    cco_costs = costs(problem, state)
    anneal_and_finish(problem, state)
    return two_stage_row(start, middle, "packing", problem, state, cco=cco_costs)


def run_late_exclusion(n, seed, total, args):
    from vasc_pipeline import engine, kernel

    start = time.perf_counter()
    problem = problem_of(n, total, [])
    state = engine.initial_state(problem, seed)  # the schedule calibrated on the true cost
    switch = int(round(args.exclusion_off_share * total))
    blind = dataclasses.replace(
        problem,
        model=problem.model._replace(exclusion_on=False),
        schedule=dataclasses.replace(problem.schedule, total=switch),
    )
    kernel.initialise(blind.model, state)  # running sums without the exclusion term
    anneal_to_end(blind, state)
    middle = time.perf_counter()
    kernel.initialise(problem.model, state)  # every segment's traversal, then the true cost to the end
    at_switch = costs(problem, state)
    anneal_and_finish(problem, state)
    return two_stage_row(start, middle, "exclusion_off", problem, state, at_switch=at_switch)


def moved_state(source, state, target):
    """``state`` (of problem ``source``) carried to problem ``target`` (the same tree on
    another voxel grid): terminals moved into ``target``'s tissue where they lie outside it,
    bifurcations clipped into its box; step counter, generator, step sizes and schedule
    kept; supply map, neighbour cells, caches and running sums rebuilt."""
    from vasc_pipeline import engine, kernel

    arrays = engine.state_arrays(state)
    k, n = target.model.n_inlets, target.model.n_terminals
    position = arrays["position"]
    position[k : k + n] = target.tissue.move_into(target.tissue.mask, position[k : k + n])
    lo, hi = target.tissue.bounds
    position[k + n :] = np.clip(position[k + n :], lo, hi)
    m = position.shape[0]
    arrays.update(
        supply=np.zeros(target.tissue.shape),
        cell_of=np.zeros(m),
        cell_head=np.zeros(int(np.prod(target.model.cell_shape))),
        cell_next=np.zeros(m),
        cell_prev=np.zeros(m),
    )
    moved = engine.restore_state(target, arrays)
    kernel.initialise(target.model, moved)
    return moved


def run_coarse_grid(n, seed, total, args):
    from vasc_pipeline import engine

    start = time.perf_counter()
    problem = problem_of(n, total, [])
    state = engine.initial_state(problem, seed)  # the schedule calibrated on the true cost
    f = args.coarse_factor
    coarse = problem_of(n, total, [f"tissue.voxel_size={f * problem.tissue.voxel_size!r}"])
    m = problem.model
    coarse_model = coarse.model._replace(
        tables=m.tables,
        supply_rho=problem.physics.supply_radius / coarse.tissue.voxel_size,
        w_exclusion=m.w_exclusion * f**7,  # sum of (D L)^6 over 1/f as many voxels, each f^-6 of the fine one
        w_supply=m.w_supply * f**3,
        step_max=m.step_max,
    )
    switch = int(round(args.coarse_grid_share * total))
    shortened = dataclasses.replace(coarse.schedule, total=switch)
    coarse = dataclasses.replace(coarse, model=coarse_model, schedule=shortened)
    state = moved_state(problem, state, coarse)
    anneal_to_end(coarse, state)
    middle = time.perf_counter()
    state = moved_state(coarse, state, problem)
    at_switch = costs(problem, state)
    anneal_and_finish(problem, state)
    return two_stage_row(start, middle, "coarse_grid", problem, state, at_switch=at_switch)


RUNNERS = {
    "plain": run_plain,
    "split": run_split,
    "packed_cco": run_packed_cco,
    "late_exclusion": run_late_exclusion,
    "coarse_grid": run_coarse_grid,
}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--strategies", nargs="+", choices=STRATEGIES, default=list(STRATEGIES))
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--budget", type=float, default=0.5, help="moves, in multiples of anneal=fast's default")
    parser.add_argument("--coarse-share", type=float, default=0.5, help="split: share of the moves for N/2")
    parser.add_argument("--offset", type=float, default=0.63, help="split: terminals' offset, in R_supply(N)")
    parser.add_argument("--packing-per-terminal", type=float, default=30000.0, help="packed_cco: packing moves")
    parser.add_argument(
        "--exclusion-off-share", type=float, default=0.2, help="late_exclusion: share of the moves without exclusion"
    )
    parser.add_argument("--coarse-factor", type=float, default=2.0, help="coarse_grid: voxel edge factor")
    parser.add_argument(
        "--coarse-grid-share", type=float, default=0.3, help="coarse_grid: share of the moves on the coarse grid"
    )
    parser.add_argument("--fine", nargs="*", default=[], help="config overrides of the last stage (split, packed_cco)")
    parser.add_argument("--quick", action="store_true", help="N = 40, 2e4 moves: checks the script runs")
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.seeds, args.packing_per_terminal = [40], [0], 100.0
    if "split" in args.strategies and any(n % 2 for n in args.sizes):
        parser.error("--strategies split halves N: every --sizes value must be even")
    for n in args.sizes:
        total = 20_000 if args.quick else int(round(args.budget * default_steps(n)))
        for strategy in args.strategies:
            for seed in args.seeds:
                row = {"strategy": strategy, "n_terminals": n, "seed": seed, "budget": args.budget, "steps": total}
                if strategy == "split":
                    row.update(coarse_share=args.coarse_share, offset=args.offset)
                if strategy == "packed_cco":
                    row["packing_per_terminal"] = args.packing_per_terminal
                if strategy == "late_exclusion":
                    row["exclusion_off_share"] = args.exclusion_off_share
                if strategy == "coarse_grid":
                    row.update(coarse_factor=args.coarse_factor, coarse_grid_share=args.coarse_grid_share)
                if strategy in ("split", "packed_cco"):
                    row["fine"] = args.fine
                print(json.dumps({**row, **RUNNERS[strategy](n, seed, total, args)}), flush=True)


if __name__ == "__main__":
    main()
