"""Grow one optimised tree: build the problem, initialise, anneal in blocks, report.

Usable without Hydra or Dask::

    from vasc_pipeline import config, engine
    result = engine.run(config.compose(["tissue=plane2d", "anneal.steps=200000"]), seed=1)
    result.costs["total"], result.costs_recomputed["total"]

The anneal loop is Python (schedule blocks, trace, progress); each block is one call of the
jitted kernel (:func:`vasc_pipeline.kernel.anneal_block`), so a caller can checkpoint
between blocks with :func:`state_arrays` / :func:`restore_state`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

import numpy as np

from .. import kernel
from ..kernel import packing
from ..model.costs import COST_TERMS, full_costs, vascular_cost
from ..model.rng import next_double
from ..model.tree import Tree
from ..store.trace import Trace, TraceRecord
from .parts import anneal_parts, make_parts, merge_parts, phase_ends
from .polish import descend_regrafts, descend_swaps, polish
from .problem import (
    Problem,
    build_problem,
    initial_state,
    model_at,
    node_radii,
    running_costs,
    tree_of,
    tree_statistics,
)

__all__ = [
    "RunResult",
    "Trace",
    "TraceRecord",
    "trace_record",
    "BlockHook",
    "run_block",
    "run_phase",
    "anneal_blocks",
    "finish",
    "run",
]


@dataclass
class RunResult:
    """The outcome of :func:`run`: the final tree and its costs (SI, W for costs)."""

    tree: Tree
    problem: Problem
    seed: int
    costs: dict[str, float]
    costs_recomputed: dict[str, float]
    steps: int
    wall_seconds: float
    trace: dict[str, np.ndarray] = field(repr=False)  # records not taken by run's on_block (all, without one)
    counters: np.ndarray = field(repr=False)
    anneal: dict[str, Any] = field(default_factory=dict)  # schedule as run, final step sizes, polish report
    statistics: dict[str, float] = field(default_factory=dict)  # tree_statistics of the final tree

    @property
    def radius(self) -> np.ndarray:
        """Radius [m] of the segment ending at every node (0 at inlets)."""
        return node_radii(self.tree, self.problem.physics)


def run_block(problem: Problem, state: kernel.State, n_steps: int) -> None:
    """Propose ``n_steps`` moves (in place): packing moves first while the packing phase
    lasts (:mod:`vasc_pipeline.kernel.packing`), then the tree anneal's; before
    ``problem.coarse_steps`` on the coarse exclusion map, and the block that reaches it
    recomputes every segment's exclusion on the true one. The GIL is released."""
    n = int(n_steps)
    coarse = min(n, problem.coarse_steps - int(state.counters[kernel.COUNTER_STEP]))
    if coarse > 0:
        _run_model(problem.coarse_model, state, coarse, problem.schedule.pack)
        n -= coarse
        if state.counters[kernel.COUNTER_STEP] == problem.coarse_steps:
            kernel.recompute_exclusion(problem.model, state)
    if n > 0:
        _run_model(problem.model, state, n, problem.schedule.pack)


def _run_model(model: kernel.Model, state: kernel.State, n: int, pack: int) -> None:
    if state.counters[kernel.COUNTER_STEP] < pack:
        n -= packing.pack_block(model, state, n)
    if n > 0:
        kernel.anneal_block(model, state, n)


def run_phase(problem: Problem, state: kernel.State, n_steps: int, map: Callable = map) -> None:
    """One phase of ``n_steps`` proposals from the state's step on, in place: ``anneal.part_share``
    of them in ``anneal.parts`` parts (:mod:`vasc_pipeline.engine.parts`), half in parts of
    subtrees (bifurcations and swaps; a subtree's territory is rarely compact, so its terminals
    stay put), half in parts of terminals grouped by place (terminal moves, parents traded);
    each cut's placement and its parts' seeds drawn from the whole tree's generator, ``map``
    running the parts; then the rest on the whole tree (:func:`run_block`)."""
    a = problem.config.anneal
    step = int(state.counters[kernel.COUNTER_STEP])
    model = model_at(problem, step)
    for leaves in (False, True):  # subtrees (their bifurcations and topology), then terminals by place
        shift = np.array([next_double(state.rng) for _ in range(3)])
        phase_seed = int(next_double(state.rng) * 2.0**53)
        cut = make_parts(problem, state, a.parts, shift, leaves)
        results = anneal_parts(problem, model, state, cut, int(n_steps * a.part_share) // 2, phase_seed, map)
        merge_parts(model, state, cut, results)
    rest = step + int(n_steps) - int(state.counters[kernel.COUNTER_STEP])
    if rest > 0:
        run_block(problem, state, rest)


def trace_record(problem: Problem, state: kernel.State, proposed: int, accepted: int) -> TraceRecord:
    """The trace record of the state after a block of ``proposed`` proposals, ``accepted`` of them taken."""
    step = int(state.counters[kernel.COUNTER_STEP])
    costs = running_costs(problem, state)
    return TraceRecord(
        step=step,
        temperature=kernel.temperature(problem.model, state, max(step - 1, 0)),
        **{term: costs[term] for term in COST_TERMS},
        total=costs["total"],
        acceptance=accepted / proposed if proposed else 0.0,
    )


def accepted_moves(state: kernel.State) -> int:
    c = state.counters
    return int(
        c[kernel.COUNTER_TERMINAL_ACCEPTED] + c[kernel.COUNTER_BIFURCATION_ACCEPTED] + c[kernel.COUNTER_SWAP_ACCEPTED]
    )


def anneal_blocks(
    problem: Problem, state: kernel.State, trace: Trace, block: int, part_map: Callable = map
) -> Iterator[int]:
    """Anneal ``state`` to the end of the schedule in blocks, recording one trace row per block.

    Blocks end on multiples of ``block`` (a resumed state starts on one), so a resumed run
    has exactly the trace of an uninterrupted one. Yields the step count after every block
    (the caller reports progress or checkpoints there). With ``anneal.parts`` > 1 the tree
    anneal's blocks are its phases (:func:`run_phase`), whose parts
    ``part_map`` runs (any order-preserving map: the builtin, a pool's, a cluster's).
    """
    total = problem.total_steps
    ends = phase_ends(problem) if problem.config.anneal.parts > 1 else None
    while (step := int(state.counters[kernel.COUNTER_STEP])) < total:
        before = accepted_moves(state)
        if ends is not None and step >= problem.schedule.pack:
            n = int(ends[np.searchsorted(ends, step, side="right")]) - step
            run_phase(problem, state, n, part_map)
        else:
            n = min(block - step % block, total - step)
            if ends is not None:  # the packing phase's last block ends where the phases begin
                n = min(n, problem.schedule.pack - step)
            run_block(problem, state, n)
        trace.append(trace_record(problem, state, n, accepted_moves(state) - before))
        yield step + n


def finish(problem: Problem, state: kernel.State) -> dict[str, Any]:
    """After the last step: polish the geometry when ``anneal.polish``; report how the anneal ran.

    Deterministic and draws no random number, so a resumed run finishes identically.
    Returns the ``anneal`` report stored with a run: the schedule's temperatures [W], the
    final translation half-widths [m] and, with polish, its before/after costs.
    """
    report: dict[str, Any] = {
        "T_start": float(state.schedule[0]),
        "T_end": float(state.schedule[1]),
        "step_terminal": float(state.step_size[0]),
        "step_bifurcation": float(state.step_size[1]),
    }
    a = problem.config.anneal
    if a.polish:
        rng_saved, counters_saved = state.rng.copy(), state.counters.copy()
        result = polish(problem, state)
        swaps = descend_swaps(problem, state) if problem.physics.n_terminals <= a.polish_swaps_max_terminals else 0
        regrafts = descend_regrafts(problem, state) if a.polish_regrafts else 0
        if swaps or regrafts:
            polish(problem, state)  # exclusion may leave the new optimum only partly taken
        state.rng[:], state.counters[:] = rng_saved, counters_saved
        after = running_costs(problem, state)
        report["polish"] = {
            "applied": result["applied"],
            "moved": result["moved"],
            "swaps": swaps,
            "regrafts": regrafts,
            "total_before": result["before"]["total"],
            "total_after": after["total"],
            "vascular_before": vascular_cost(result["before"]),
            "vascular_after": vascular_cost(after),
        }
    return report


BlockHook = Callable[[int, kernel.State, Trace], None]


def run(
    config: Any = None,
    seed: int | None = None,
    *,
    block_steps: int | None = None,
    progress: Callable[[int, int, dict], None] | None = None,
    part_map: Callable = map,
    on_block: BlockHook | None = None,
    problem: Problem | None = None,
    state: kernel.State | None = None,
) -> RunResult:
    """Grow one tree from (config, seed) and return it with running and recomputed costs.

    ``seed`` defaults to ``config.seed``. ``block_steps`` (default ``anneal.trace_every``)
    sets the trace resolution; it does not change the result. ``progress(step, total,
    costs)`` is called after every block. ``part_map`` runs the parts of an ``anneal.parts`` > 1
    anneal (:func:`anneal_blocks`); it does not change the result.

    ``on_block(step, state, trace)`` is called after every block too, with the step count,
    the state and the trace (its last record the block's): a caller that checkpoints there
    takes the trace's records (:meth:`~vasc_pipeline.store.trace.Trace.take`), and the
    result's ``trace`` then holds only the records after the last one taken. ``problem``
    is ``build_problem(config)`` when the caller has it already (``config`` is then not
    needed); ``state`` continues a restored state (:func:`restore_state`) instead of starting
    from ``initial_state(problem, seed)``. The trace's first record is that of the state
    before any proposal, so a state past step 0 (resumed) adds none: its store has it.
    """
    start = time.perf_counter()
    problem = build_problem(config) if problem is None else problem
    seed = problem.config.seed if seed is None else int(seed)
    state = initial_state(problem, seed) if state is None else state
    block = int(block_steps or problem.config.anneal.trace_every)
    trace = Trace()
    if int(state.counters[kernel.COUNTER_STEP]) == 0:
        trace.append(trace_record(problem, state, 0, 0))
    for step in anneal_blocks(problem, state, trace, block, part_map):
        if progress is not None:
            progress(step, problem.total_steps, running_costs(problem, state))
        if on_block is not None:
            on_block(step, state, trace)
    report = finish(problem, state)
    tree = tree_of(problem, state)
    return RunResult(
        tree=tree,
        problem=problem,
        seed=seed,
        costs=running_costs(problem, state),
        costs_recomputed=full_costs(tree, problem.tissue, problem.physics, problem.terms),
        steps=int(state.counters[kernel.COUNTER_STEP]),
        wall_seconds=time.perf_counter() - start,
        trace=trace.arrays(),
        counters=state.counters.copy(),
        anneal=report,
        statistics=tree_statistics(problem, tree),
    )
